"""Helpers for the emulated-bench tests of tests/fitting: write an instrument config (the
sim-serial example with its [sim] section replaced) and a plan, and scan it with --sim."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "instruments" / "sim-serial.toml"


def toml_value(value: object) -> str:
    """A TOML literal for the simple values these configs use."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + " }"
    return repr(float(value)) if isinstance(value, float) else str(value)


#: The example's [optics], and the [sim] geometry keys a test's tables give that move there.
OPTICS = {"wavelength_nm": 632.8, "bandwidth_nm": 0.002, "beam_diameter_mm": 2.0,
          "divergence_deg": 0.03, "aperture_diameter_mm": 10.0, "aperture_distance_mm": 500.0,
          "aperture_diameter_tolerance_mm": 0.0}
#: The emulated meter's figures ([sim.detector] has no gain errors or non-linearity unless a
#: test gives them): what the configs state, so that a budget weighs what this bench does.
EXACT_METER = {"linearity_rel": 0.0, "range_gain_rel": 0.0}
OPTICS_FROM_SIM = {"source": {"wavelength_nm": "wavelength_nm",
                              "beam_diameter_mm": "beam_diameter_mm",
                              "divergence_deg": "divergence_deg"},
                   "aperture": {"diameter_mm": "aperture_diameter_mm",
                                "distance_mm": "aperture_distance_mm"}}
#: The plans' default [sample]: Walter's glass hemisphere, lit from the air side.
GLASS = {"id": "test-glass", "kind": "hemisphere", "eta": 1.51}


def table(name: str, values: dict) -> str:
    return f"[{name}]\n" + "".join(f"{k} = {toml_value(v)}\n" for k, v in values.items())


def set_keys(text: str, name: str, values: dict) -> str:
    """TOML text with the keys of its table `name` set to `values` (replaced or added)."""
    lines = text.split("\n")
    start = next(i for i, ln in enumerate(lines) if ln.split("#")[0].strip() == f"[{name}]")
    end = next(i for i in range(start + 1, len(lines)) if lines[i].startswith("["))
    lines = [ln for i, ln in enumerate(lines)
             if not (start < i < end and ln.split("=")[0].strip() in values)]
    lines[start + 1:start + 1] = [f"{key} = {toml_value(v)}" for key, v in values.items()]
    return "\n".join(lines)


def instrument(tmp: Path, sim: dict[str, dict], detector: dict | None = None,
               seed: int = 1, time_scale: float | str = "inf", optics: dict | None = None
               ) -> Path:
    """The example config with `[detector]` stating EXACT_METER and updated by `detector`, the
    stages' repeatability_deg that of [sim.alignment] (0 unless given), `[optics]` from the sim
    tables' geometry (OPTICS_FROM_SIM) and `optics` (which wins), and `[sim]`
    replaced by `sim` tables (the bench's defaults otherwise: multiple scattering "auto", so on
    for Walter's ground and etched glass). A drifting source drifts on the run's virtual clock,
    the clock of its t_s, at any time_scale."""
    text = EXAMPLE.read_text().split("\n[sim]")[0].replace("timeout_s = 1.0", "timeout_s = 20.0")
    text = set_keys(text, "detector", {**EXACT_METER, **(detector or {})})
    alignment = sim.get("alignment", {})
    for role in ("sample", "arm"):  # the stages scatter as [sim.alignment] makes them
        text = set_keys(text, f"axes.{role}", {
            "repeatability_deg": alignment.get(f"{role}_repeatability_deg", 0.0)})
    described = dict(OPTICS)
    for name, keys in OPTICS_FROM_SIM.items():  # the geometry is the bench's description
        for key, theirs in keys.items():
            if key in sim.get(name, {}):
                described[theirs] = sim[name][key]
    described.update(optics or {})
    sim = {name: {k: v for k, v in values.items() if k not in OPTICS_FROM_SIM.get(name, {})}
           for name, values in sim.items()}
    head, _, rest = text.partition("\n[optics]")
    text = head + "\n" + table("optics", described) + "\n[" + rest.split("\n[", 1)[1]
    text += "\n" + table("sim", {"time_scale": time_scale, "seed": seed})
    for name, values in sim.items():
        text += "\n" + table(f"sim.{name}", values)
    path = tmp / f"instrument-{len(list(tmp.glob('instrument-*.toml')))}.toml"
    path.write_text(text)
    return path


def plan(tmp: Path, name: str, grids: list[dict], repeats: int = 1, dark_every: int = 20,
         beam_every: int = 20, averaging: int = 4, dwell_s: float = 0.0,
         sample: dict | None = None) -> Path:
    """A plan file of [[grid]] tables with dark and beam readings interleaved; its [sample]
    is `sample` (default GLASS)."""
    text = (f'name = "{name}"\nrepeats = {repeats}\naveraging = {averaging}\n'
            f'order = "as-written"\ndwell_s = {dwell_s}\n\n' + table("sample", sample or GLASS))
    for g in grids:
        text += "\n[[grid]]\n" + "".join(f"{k} = {toml_value(v)}\n" for k, v in g.items())
    text += f"\n[dark]\nevery = {dark_every}\n\n[beam]\nevery = {beam_every}\n"
    path = tmp / f"{name}.toml"
    path.write_text(text)
    return path


def scan(plan_path: Path, instrument_path: Path, out: Path) -> Path:
    """Run the plan on the emulated bench; returns the run directory."""
    from gonio.runner import new_scan

    result = new_scan(plan_path, instrument_path, sim=True, out=out, progress=False)
    assert result.outcome.status == "completed", result.outcome
    return result.path


def metered_bsdf(bench, positions: list[tuple[float, float]], seed: int, averaging: int = 16,
                 wavelength_nm: float = 632.8):
    """(wi, wo, bsdf, sigma) of readings at (sample, arm) positions: the bench's true power
    read by the photodiode model (noise, ranges, quantisation; dark level zeroed, as a run's
    [dark] readings subtract it) and divided as reduction divides; sigma is the detector's."""
    import numpy as np

    from model.optics.exit_face import exit_view
    from sim.bench.geometry import sample_frame_directions
    from sim.devices.photodiode import PhotodiodeModel

    meter = PhotodiodeModel(None, seed=seed)
    meter.zero(wavelength_nm)
    wi, wo, bsdf, sigma = [], [], [], []
    for s, arm in positions:
        position = {"sample": float(s), "arm": float(arm)}
        i, o = sample_frame_directions(position)
        power = bench.power_w(position)
        m = meter.measure(power, None, averaging, wavelength_nm)
        _, factor = exit_view(bench.sample.spec, i, o)
        scale = bench.source.power_w * bench.integral.solid_angle_sr * factor * abs(o[2])
        wi.append(i)
        wo.append(o)
        bsdf.append(m.reading_w / scale)
        sigma.append(meter.expected_sigma_w(power, m.range_w, averaging, wavelength_nm) / scale)
    return np.array(wi), np.array(wo), np.array(bsdf), np.array(sigma)
