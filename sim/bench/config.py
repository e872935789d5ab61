"""The [sim] section of an instrument config -> the emulated bench and its PowerSource.

Reads the tables this package owns, [sim.source], [sim.sample] and the cabinet of samples
[sim.samples.<id>] (a plan mounts the one named by its [sample] id; a sample of a model family
beside the microfacet interface: sim.bench.family_table), [sim.aperture],
[sim.alignment], [sim.stray] and [sim.room] (docs/bench.md has the schema); every bad field
raises one SimConfigError naming it. [sim.detector] belongs to sim.devices.photodiode, the
other keys to the emulators.

The bench's geometry comes from what the experimenter describes, the instrument config's
[optics] and the plan's [sample] (passed in as plain tables); a key [sim] states itself wins
(an emulated bench that differs from its description), and the defaults fill the rest.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Mapping

from model.bsdf.distributions import DISTRIBUTION_NAMES, WALKABLE
from model.bsdf.masking import MASKINGS
from sim.bench.family_sample import FamilySample
from sim.bench.family_table import FAMILY_CHOICES, FAMILY_KEYS, family_fields
from sim.bench.sample import KINDS, LIT_FROM, MICROFACET, Sample, SampleSpec
from sim.bench.scene import Alignment, Bench, BenchPowerSource
from sim.bench.source import Dip, Source
from sim.bench.stray import InstrumentScatter
from sim.devices.photodiode import PhotodiodeModel, SimConfigError

Check = Callable[[str, object], object]


def _number(low: float = -math.inf, high: float = math.inf, *, open_low: bool = False) -> Check:
    def check(where: str, value: object) -> float:
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        if ok:
            ok = math.isfinite(value) and value <= high and (value > low if open_low
                                                              else value >= low)
        if not ok:
            bound = f"> {low:g}" if open_low else f">= {low:g}"
            limit = bound if high == math.inf else f"{bound} and <= {high:g}"
            raise SimConfigError(f"{where}: must be a number {limit}, got {value!r}")
        return float(value)
    return check


def _choice(options: tuple[str, ...]) -> Check:
    def check(where: str, value: object) -> str:
        if value not in options:
            raise SimConfigError(f"{where}: must be one of {', '.join(options)}; got {value!r}")
        return value
    return check


ALPHA_RANGE = (1e-4, 4.0)  # the roughness range model.bsdf's extreme-case tests cover
#: Sample index: glasses and a conductor's real part (silver's is ~0.05); far below it,
#: refraction ratios of order 1/eta overflow the bench's optics.
ETA_RANGE = (0.01, 10.0)
MAX_WALKS = 1 << 25  # [sim.sample] ms_walks: walks per multiple-scattering table build


def _alpha(where: str, value: object) -> tuple[float, float]:
    pair = value if isinstance(value, (list, tuple)) else [value, value]
    if len(pair) != 2:
        raise SimConfigError(f"{where}: must be a number or [alpha_x, alpha_y], got {value!r}")
    in_range = _number(ALPHA_RANGE[0], ALPHA_RANGE[1])  # where model.bsdf is verified
    return in_range(where, pair[0]), in_range(where, pair[1])


def _switch(where: str, value: object) -> bool | str:
    if not (isinstance(value, bool) or value == "auto"):
        raise SimConfigError(f'{where}: must be true, false or "auto", got {value!r}')
    return value


def _family_value(where: str, value: object) -> object:
    """A family parameter or setting: checked by the family (sim.bench.family_table)."""
    return value


def _optional(check: Check) -> Check:
    def optional(where: str, value: object) -> object:
        return None if value is None else check(where, value)
    return optional


def _walks(where: str, value: object) -> int:
    # walks per incidence table (HigherOrderLobe): 2^25 takes minutes per table the first time
    # on a machine (then read from the disk, plane_store); more would take an hour
    if isinstance(value, bool) or not isinstance(value, int) or not 2 <= value <= MAX_WALKS:
        raise SimConfigError(f"{where}: must be an integer in [2, {MAX_WALKS}], got {value!r}")
    return value


def _order(where: str, value: object) -> tuple[int, int] | None:
    if value == "auto":
        return None
    if (isinstance(value, (list, tuple)) and len(value) == 2 and all(
            isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= 64 for v in value)):
        return int(value[0]), int(value[1])
    raise SimConfigError(f'{where}: must be "auto" or [n_beam, n_aperture] (integers 0..64), '
                         f"got {value!r}")


def _dip(where: str, value: object) -> Dip | None:
    """[sim.source] dip = {start_s, duration_s, depth}: the power falls by the share depth."""
    if value is None:
        return None
    keys = {"start_s": _number(0.0), "duration_s": _number(0.0, open_low=True),
            "depth": _number(0.0, 1.0)}
    if not isinstance(value, Mapping) or set(value) != set(keys):
        raise SimConfigError(f"{where} must be a table {{start_s, duration_s, depth}}, "
                             f"got {value!r}")
    return Dip(**{key: check(f"{where}.{key}", value[key]) for key, check in keys.items()})


SCHEMA: dict[str, dict[str, tuple[object, Check]]] = {
    "source": {
        "wavelength_nm": (632.8, _number(100.0, 20000.0)),
        "power_w": (1e-3, _number(0.0, open_low=True)),
        "beam_diameter_mm": (2.0, _number(0.0, open_low=True)),
        "divergence_deg": (0.0, _number(0.0, 10.0)),
        "drift_fraction": (0.0, _number(0.0, 0.5)),
        "drift_period_s": (3600.0, _number(0.0, open_low=True)),
        "dip": (None, _dip),
    },
    "sample": {
        "kind": ("hemisphere", _choice(KINDS)),
        "distribution": ("ggx", _choice(DISTRIBUTION_NAMES)),
        "alpha": (0.394, _alpha),
        "eta": (1.51, _number(*ETA_RANGE)),
        "k": (0.0, _number(0.0, 20.0)),
        "masking": ("separable", _choice(MASKINGS)),
        "lit_from": ("air", _choice(LIT_FROM)),
        "retracted_beyond_deg": (89.0, _number(45.0, 90.0)),
        "multiple_scattering": ("auto", _switch),
        "diffraction": ("auto", _switch),
        "rms_height_nm": (None, _optional(_number(0.0, 1e6, open_low=True))),
        "correlation_length_um": (None, _optional(_number(0.0, 1e6, open_low=True))),
        "psd_exponent": (2.0, _number(1.0, 10.0, open_low=True)),
        "ms_walks": (1 << 16, _walks),
        # informational (INFORMATIONAL): what a single-scattering fit of this bench returns
        "single_scattering_alpha": (None, _optional(_number(*ALPHA_RANGE))),
        "single_scattering_alpha_u": (None, _optional(_number(0.0, open_low=True))),
        # a model family's sample (sim.bench.family_table): its name, its own parameters
        "family": (MICROFACET, _choice(FAMILY_CHOICES)),
        **{key: (None, _family_value) for key in FAMILY_KEYS},
    },
    "aperture": {
        "diameter_mm": (10.0, _number(0.0, open_low=True)),
        "distance_mm": (500.0, _number(0.0, open_low=True)),
        "rtol": (1e-3, _number(1e-10, 0.1)),
        "order": ("auto", _order),
    },
    "alignment": {
        "sample_offset_deg": (0.0, _number(-10.0, 10.0)),
        "arm_offset_deg": (0.0, _number(-10.0, 10.0)),
        "sample_repeatability_deg": (0.0, _number(0.0, 1.0)),
        "arm_repeatability_deg": (0.0, _number(0.0, 1.0)),
    },
    "room": {  # sim.bench.room: the air the environment sensors read (drift per hour)
        "temperature_c": (21.0, _number(-40.0, 60.0)),
        "humidity_rel": (0.45, _number(0.0, 1.0)),
        "temperature_drift_c_per_h": (0.0, _number(-100.0, 100.0)),
        "humidity_drift_rel_per_h": (0.0, _number(-1.0, 1.0)),
    },
    "stray": {  # sim.bench.stray: the instrument's own scatter (default: none)
        "halo_fraction": (0.0, _number(0.0, 0.1)),
        "halo_width_deg": (1.0, _number(0.1, 30.0)),
        "halo_slope": (3.0, _number(1.0, 6.0)),
        "arm_fraction": (0.0, _number(0.0, 1e-2)),
        "arm_variation": (0.0, _number(0.0, 1.0)),
    },
}


#: [sim.sample] keys that document the emulator's truth and change nothing it does: the alpha a
#: single-scattering fit (Walter's: normal incidence, `gonio fit RUN`) returns on this bench,
#: where multiple scattering widens the lobe beyond the microsurface alpha, and its standard
#: uncertainty (docs/bench.md, "Walter's samples").
INFORMATIONAL = ("single_scattering_alpha", "single_scattering_alpha_u")


#: [sim.<table>] key <- the key of the experimenter's description ([optics] or [sample]) that
#: gives it when [sim] does not state it.
DESCRIBED: dict[str, tuple[str, dict[str, str]]] = {
    "source": ("optics", {"wavelength_nm": "wavelength_nm",
                          "beam_diameter_mm": "beam_diameter_mm",
                          "divergence_deg": "divergence_deg"}),
    "aperture": ("optics", {"diameter_mm": "aperture_diameter_mm",
                            "distance_mm": "aperture_distance_mm"}),
    "sample": ("sample", {"kind": "kind", "eta": "eta", "k": "k", "lit_from": "lit_from"}),
}


def mounted_sample(sim_config: Mapping, described: Mapping | None = None
                   ) -> tuple[str, Mapping]:
    """(where, table) of the emulated sample on the bench: the cabinet's [sim.samples.<id>]
    whose key is the described [sample] id, else [sim.sample]. Every table of the cabinet is
    checked here, so a bad one is named whichever sample a plan mounts."""
    cabinet = sim_config.get("samples", {})
    if not isinstance(cabinet, Mapping):
        raise SimConfigError(f"[sim.samples]: must be a table of sample tables, got {cabinet!r}")
    for sample_id, table in cabinet.items():
        _validated(table, f"sim.samples.{sample_id}", "sample")
    sample_id = (described or {}).get("id")
    if isinstance(sample_id, str) and sample_id in cabinet:
        return f"sim.samples.{sample_id}", cabinet[sample_id]
    return "sim.sample", sim_config.get("sample", {})


def read_table(sim_config: Mapping, name: str, described: Mapping | None = None
               ) -> dict[str, object]:
    """Validated [sim.<name>] table (for "sample", the mounted one: mounted_sample): its own
    keys, else the description's (`described`: the [optics] or [sample] table DESCRIBED maps it
    from), else the defaults."""
    if name == "sample":
        where, table = mounted_sample(sim_config, described)
    else:
        where, table = f"sim.{name}", sim_config.get(name, {})
    return _validated(table, where, name, described)


def _validated(table: object, where: str, name: str, described: Mapping | None = None
               ) -> dict[str, object]:
    """The table [<where>] checked against SCHEMA[name], filled as read_table says."""
    if not isinstance(table, Mapping):
        raise SimConfigError(f"[{where}]: must be a table, got {table!r}")
    fields = SCHEMA[name]
    unknown = sorted(set(table) - set(fields))
    if unknown:
        raise SimConfigError(
            f"[{where}]: unknown key {unknown[0]!r}; known: {', '.join(fields)}")
    source, keys = DESCRIBED.get(name, ("", {}))
    base = _described(name, described)
    out = {}
    for key, (default, check) in fields.items():
        field = f"[{where}] {key}" if key in table or key not in base \
            else f"[{source}] {keys[key]}"
        out[key] = check(field, table.get(key, base.get(key, default)))
    return out


def _described(name: str, described: Mapping | None) -> dict[str, object]:
    """[sim.<name>] keys the experimenter's description states (DESCRIBED; a None, such as a
    diffuse sample's absent eta, states nothing)."""
    _, keys = DESCRIBED.get(name, ("", {}))
    return {key: described[theirs] for key, theirs in keys.items()
            if described is not None and described.get(theirs) is not None}


def read_sample(sim_config: Mapping, described: Mapping | None = None
                ) -> tuple[str, SampleSpec, float, dict[str, object]]:
    """(where, the SampleSpec, retracted_beyond_deg, the INFORMATIONAL keys stated) of the
    mounted sample (mounted_sample) on the [sample] the experimenter describes."""
    where, mounted = mounted_sample(sim_config, described)
    table = _validated(mounted, where, "sample", described)
    retracted = table.pop("retracted_beyond_deg")
    stated = informational(table, where)
    spec = SampleSpec(**family_fields(mounted, table, where, _described("sample", described)))
    if spec.kind != "hemisphere" and spec.lit_from != "air":
        raise SimConfigError(f'[{where}] lit_from: "hemisphere" needs kind = "hemisphere", '
                             f"not {spec.kind!r}")
    if spec.kind != "conductor" and spec.k != 0.0:
        raise SimConfigError(f"[{where}] k: the extinction applies to kind = \"conductor\" "
                             f"only, not {spec.kind!r}")
    _check_switches(spec, where)
    return where, spec, retracted, stated


def _warn_polarisation(optics: Mapping | None) -> None:
    """The model's Fresnel is unpolarised: say so (once) when the bench is described polarised."""
    states = {key: (optics or {}).get(key, "unpolarised")
              for key in ("source_polarisation", "analyser_polarisation")}
    polarised = {key: state for key, state in states.items() if state != "unpolarised"}
    if polarised:
        listed = ", ".join(f"{key} = {state!r}" for key, state in polarised.items())
        warnings.warn(f"[optics] {listed}: the emulated bench models unpolarised light only "
                      f"(the state is recorded, not emulated)", UserWarning, stacklevel=3)


def build_bench(sim_config: Mapping, optics: Mapping | None = None,
                sample: Mapping | None = None) -> Bench:
    """The Bench of a [sim] table on the bench the experimenter describes: the instrument
    config's [optics] and the plan's [sample] tables (see DESCRIBED); missing keys take the
    defaults."""
    _warn_polarisation(optics)
    source = Source(**read_table(sim_config, "source", optics))
    _, spec, retracted, _ = read_sample(sim_config, sample)
    aperture = read_table(sim_config, "aperture", optics)
    if aperture["diameter_mm"] >= aperture["distance_mm"]:
        raise SimConfigError("[sim.aperture] diameter_mm: must be smaller than distance_mm")
    kind = Sample if spec.family == MICROFACET else FamilySample
    sample = kind(spec, source.wavelength_nm, _visible_fraction(sim_config, source, aperture),
                  seed=int(sim_config.get("seed", 0) or 0))
    return Bench(
        source=source, sample=sample,
        aperture_diameter_mm=aperture["diameter_mm"], distance_mm=aperture["distance_mm"],
        rtol=aperture["rtol"], order=aperture["order"],
        alignment=Alignment(**read_table(sim_config, "alignment"),
                            seed=int(sim_config.get("seed", 0) or 0)),
        retracted_beyond_deg=retracted,
        stray=InstrumentScatter(**read_table(sim_config, "stray")),
    )


def informational(sample_table: dict[str, object], where: str = "sim.sample"
                  ) -> dict[str, object]:
    """Take the INFORMATIONAL keys out of a read sample table (in place; `where` names it in
    errors): those stated (None: not stated); the uncertainty needs the value it belongs to."""
    stated = {key: sample_table.pop(key) for key in INFORMATIONAL}
    value, u = (stated[key] for key in INFORMATIONAL)
    if u is not None and value is None:
        raise SimConfigError(f"[{where}] single_scattering_alpha_u: needs "
                             "single_scattering_alpha (the value it is the uncertainty of)")
    return {key: value for key, value in stated.items() if value is not None}


def _check_switches(spec: SampleSpec, where: str) -> None:
    """What multiple_scattering = true and diffraction = true need from the rest of the table."""
    if spec.multiple_scattering is True and spec.distribution not in WALKABLE:
        walkable = " or ".join(f'"{name}"' for name in WALKABLE)
        raise SimConfigError(f"[{where}] multiple_scattering: true needs distribution "
                             f"{walkable} (the random walk has no {spec.distribution} "
                             f"microsurface)")
    surface = {"rms_height_nm": spec.rms_height_nm,
               "correlation_length_um": spec.correlation_length_um}
    missing = [key for key, value in surface.items() if value is None]
    if len(missing) == 1:
        raise SimConfigError(f"[{where}] {missing[0]}: needed with "
                             f"{({*surface} - {missing[0]}).pop()} (the nano-roughness PSD)")
    if spec.diffraction is True and missing:
        raise SimConfigError(f"[{where}] rms_height_nm: needed, with correlation_length_um, "
                             "by diffraction = true (the nano-roughness PSD)")


def _visible_fraction(sim_config: Mapping, source: Source, aperture: Mapping) -> float:
    """Share of the incident power, spread like a Lambertian lobe, whose part in the aperture
    equals the detector's noise floor (one sample at zero light on its most sensitive range):
    the "auto" switches compute no effect smaller than this."""
    meter = PhotodiodeModel(sim_config.get("detector"), seed=0)
    floor_w = meter.expected_sigma_w(0.0, meter.ranges_w[0], 1, source.wavelength_nm)
    cap = (0.5 * aperture["diameter_mm"] / aperture["distance_mm"]) ** 2  # Omega_d / pi
    return floor_w / (source.power_w * cap)


def build_power_source(
    sim_config: Mapping,
    positions: Callable[[], Mapping[str, float]],
    clock: Callable[[], float] | None = None,
    optics: Mapping | None = None,
    sample: Mapping | None = None,
) -> BenchPowerSource:
    """PowerSource for detector emulators: the bench of sim_config (the [sim] table; optics and
    sample as in build_bench) at the stage positions positions() returns ({"sample", "arm",
    "azimuth", "elevation"}, degrees), at the time clock() returns (virtual seconds; default:
    real seconds since now)."""
    return BenchPowerSource(build_bench(sim_config, optics, sample), positions, clock)
