"""The BiRD universal BRDF JSON schema (v1.0) from its snapshot (third_party's
`bird-brdf-json-schema`), as a jsonschema validator with every format checked (uri, email,
date-time): the snapshot's files registered under their `$id`s, so its `$ref`s resolve
offline. The snapshot's sample_holder schema is not JSON and no other file refers to it: it is
left out."""

from __future__ import annotations

import json
from pathlib import Path

from third_party import third_party

TOP = "brdf_json_schema_v1.0.json"


def schema_folder() -> Path:
    """The snapshot's schema folder (may be absent)."""
    return third_party("bird-brdf-json-schema") / "BRDF_JSON_schema"


def bird_validator():  # -> jsonschema.Draft202012Validator
    """A validator of whole BiRD files against the snapshot."""
    import jsonschema
    import referencing
    from referencing.jsonschema import DRAFT202012

    resources = []
    for path in sorted(schema_folder().glob("*.json")):
        try:
            schema = json.loads(path.read_text())
        except ValueError:
            continue  # sample_holder_json_schema_v1.0.json (see the module docstring)
        resources.append((schema["$id"], referencing.Resource.from_contents(
            schema, default_specification=DRAFT202012)))
    registry = referencing.Registry().with_resources(resources)
    top = json.loads((schema_folder() / TOP).read_text())
    return jsonschema.Draft202012Validator(
        top, registry=registry, format_checker=jsonschema.Draft202012Validator.FORMAT_CHECKER)
