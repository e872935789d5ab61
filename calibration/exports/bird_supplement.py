"""Facts given at export time for a BiRD file (`gonio export RUN --format bird --provenance
FILE`): a TOML file with the tables the instrument config and the plan take for what BiRD
requires and a run may not have recorded (a run older than those blocks, or measured with them
left out): config [provenance], plan [environment], the source's and the detector range's keys
of config [optics] (gonio.optics.DESCRIPTIVE_KEYS) and the shape keys of plan [sample]. Each
table is checked by the parser the config or plan uses, on the run's recorded values with the
file's over them; the file fills only what the record lacks, a value contradicting one the run
recorded is refused naming its key, and the record then names the file, its sha256 and the
keys it gave (`export_supplement`), which the BiRD file states in its provenance comments.
"""

from __future__ import annotations

import hashlib
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from calibration.values import CalibrationError
from drivers.user_file import SETTINGS_FILE_CAP, read_user_file, user_text
from gonio.environment import parse_environment
from gonio.fields import Fields
from gonio.optics import DESCRIPTIVE_KEYS, parse_descriptive
from gonio.provenance import parse_provenance
from gonio.sample import DIMENSIONS, parse_sample

#: The record's key for what the file gave.
SUPPLEMENT_KEY = "export_supplement"
#: The [sample] keys the file may give: what the sample looks like, never what reduction
#: reads (id, kind, index, lit side).
SHAPE_KEYS = ("shape", "azimuth_reference", *(f"{name}_mm" for name in DIMENSIONS))


def _descriptive(f: Fields) -> dict[str, Any]:
    """The optics' descriptive keys of a table holding only them."""
    out = parse_descriptive(f)
    f.done()
    return out


#: Per table: where the config or plan holds it, the keys the file may give (None: all the
#: parser takes) and the parser, which returns the table's values as the record holds them.
TABLES: dict[str, tuple[str, tuple[str, ...] | None, Callable[[Fields], dict[str, Any]]]] = {
    "provenance": ("config", None, lambda f: parse_provenance(f).to_json()),
    "environment": ("plan", None, lambda f: parse_environment(f).to_json()),
    "optics": ("config", DESCRIPTIVE_KEYS, _descriptive),
    "sample": ("plan", SHAPE_KEYS, lambda f: parse_sample(f).to_json()),
}


@dataclass(frozen=True)
class Supplement:
    """The file as read: its resolved path, the sha256 of its bytes and its tables."""

    path: Path
    sha256: str
    tables: dict[str, dict[str, Any]]


def read_supplement(path: str | Path) -> Supplement:
    """The file at `path`, its tables and keys checked against TABLES (one CalibrationError
    naming the file and the table or key that is wrong)."""
    what = "export-time provenance file"
    data = read_user_file(path, what, SETTINGS_FILE_CAP, CalibrationError)
    try:
        tables = tomllib.loads(user_text(data, path, what, CalibrationError))
    except tomllib.TOMLDecodeError as exc:
        raise CalibrationError(f"{path}: not valid TOML ({exc})") from None
    if not tables:
        raise CalibrationError(f"{path}: gives none of the tables [{'], ['.join(TABLES)}]")
    for name, table in tables.items():
        if name not in TABLES:
            raise CalibrationError(f"{path}: [{name}] cannot be given at export time (only "
                                   f"[{'], ['.join(TABLES)}])")
        if not isinstance(table, dict):
            raise CalibrationError(f"{path}: {name} must be a table ([{name}])")
        allowed = TABLES[name][1]
        wrong = sorted(set(table) - set(allowed)) if allowed is not None else []
        if wrong:
            raise CalibrationError(f"{path}: [{name}] {wrong[0]}: cannot be given at export "
                                   f"time, only {', '.join(allowed)} (the run's {TABLES[name][0]}"
                                   " holds the rest, which its reduction read)")
    return Supplement(Path(path).resolve(), hashlib.sha256(data).hexdigest(), tables)


def _recorded(record: Mapping[str, Any], name: str) -> dict[str, Any] | None:
    """The record's values of one table (None: the run has no such block)."""
    if name == "optics":
        return {**(record.get("light_source") or {}),
                "detector_spectral_range_nm": record.get("detector_spectral_range_nm")}
    return record.get(name)


def _stored(record: dict[str, Any], name: str, values: dict[str, Any]) -> None:
    """Put one table's values back where the record holds them."""
    if name == "optics":
        spectral = values.pop("detector_spectral_range_nm")
        record["light_source"] = values
        record["detector_spectral_range_nm"] = None if spectral is None else list(spectral)
    else:
        record[name] = values


def _same(a: Any, b: Any) -> bool:
    """Equal as the record stores values (a pair as a list)."""
    return (list(a) if isinstance(a, tuple) else a) == (list(b) if isinstance(b, tuple) else b)


def supplemented(record: Mapping[str, Any], supplement: Supplement) -> dict[str, Any]:
    """The record with the file's values where the record lacks them, and `export_supplement`
    (file, sha256, the keys it gave as `[table] key`); a CalibrationError naming the first
    key whose value contradicts the record's, or a table its parser refuses."""
    out = dict(record)
    source = str(supplement.path)
    gave: list[str] = []
    for name, table in supplement.tables.items():
        recorded = _recorded(record, name)
        if recorded is None and name == "sample":
            raise CalibrationError(f"{source}: [sample]: the run records no sample (its id, "
                                   "kind and index, which its reduction read); only its shape "
                                   "can be given at export time")
        known = {k: v for k, v in (recorded or {}).items() if v not in (None, "")}
        values = TABLES[name][2](Fields({**known, **table}, source, CalibrationError, name))
        for key in table:
            if key in known and not _same(known[key], values[key]):
                raise CalibrationError(
                    f"{source}: [{name}] {key}: {values[key]!r} contradicts the run's "
                    f"recorded {known[key]!r}; an export-time file only fills what the run "
                    "lacks")
            if key not in known and values[key] not in (None, ""):
                gave.append(f"[{name}] {key}")
        _stored(out, name, values)
    out[SUPPLEMENT_KEY] = {"file": source, "sha256": supplement.sha256, "gave": gave}
    return out


def supplement_sentence(record: Mapping[str, Any]) -> str | None:
    """What the export-time file gave, as a sentence for the BiRD file's comments (None
    when none was given)."""
    given = record.get(SUPPLEMENT_KEY)
    if not given:
        return None
    what = (f"gave {', '.join(given['gave'])}, which the run had not recorded" if given["gave"]
            else "gave nothing the run had not recorded")
    return (f"Given at export time (gonio export --provenance), not recorded by the run: the "
            f"file {given['file']} (sha256 {given['sha256']}) {what}.")
