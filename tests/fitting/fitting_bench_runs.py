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


def table(name: str, values: dict) -> str:
    return f"[{name}]\n" + "".join(f"{k} = {toml_value(v)}\n" for k, v in values.items())


def instrument(tmp: Path, sim: dict[str, dict], detector: dict | None = None,
               seed: int = 1, time_scale: float | str = "inf", optics: dict | None = None
               ) -> Path:
    """The example config with `[detector]` updated, an `[optics]` table if given, and `[sim]`
    replaced by `sim` tables (the bench's defaults otherwise: multiple scattering "auto", so on
    for Walter's ground and etched glass). A drifting source drifts in wall seconds since the
    bench started, the clock of the run's t_s, at any time_scale."""
    text = EXAMPLE.read_text().split("\n[sim]")[0].replace("timeout_s = 1.0", "timeout_s = 20.0")
    if detector:
        for key, value in detector.items():
            lines = text.split("\n")
            start = lines.index("[detector]")
            end = next(i for i in range(start + 1, len(lines)) if lines[i].startswith("["))
            lines = [ln for i, ln in enumerate(lines)
                     if not (start < i < end and ln.split("=")[0].strip() == key)]
            lines.insert(start + 1, f"{key} = {toml_value(value)}")
            text = "\n".join(lines)
    if optics:
        text += "\n" + table("optics", optics)
    text += "\n" + table("sim", {"time_scale": time_scale, "seed": seed})
    for name, values in sim.items():
        text += "\n" + table(f"sim.{name}", values)
    path = tmp / f"instrument-{len(list(tmp.glob('instrument-*.toml')))}.toml"
    path.write_text(text)
    return path


def plan(tmp: Path, name: str, grids: list[dict], repeats: int = 1, dark_every: int = 20,
         beam_every: int = 20, averaging: int = 4, dwell_s: float = 0.0) -> Path:
    """A plan file of [[grid]] tables with dark and beam readings interleaved."""
    text = (f'name = "{name}"\nrepeats = {repeats}\naveraging = {averaging}\n'
            f'order = "as-written"\ndwell_s = {dwell_s}\n')
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

    from sim.bench.geometry import sample_frame_directions
    from sim.bench.sample import exit_view
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
