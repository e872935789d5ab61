"""Integrated quantities of measured BSDF data, each with its standard uncertainty: the
directional-hemispherical reflectance and transmittance, the total scattering of ISO 13696
(backward and forward), the haze of ASTM D1003 and the specular gloss of ISO 2813
(docs/fitting.md, "Integrated quantities").

Each is sum(W * f) over the quadrature cells of one incidence and side (calibration.hemisphere)
for a weight W that the quantity defines. f is the fitted model m plus the data's residual from
it, interpolated between the rows relative to m + c (c: the median of the data, so that a
residual follows the model's lobe where m is large and stays absolute where m vanishes; the
interpolation carries only what the model misses); past the rows' ends (the fill) the rows'
end residual holds, so that the fill is the model's shape scaled as the data at the ends scale
it; with fewer than two rows f is the model alone. The along-row interpolation's Richardson
correction is added to the value.

The uncertainty's components: the readings' own noise and their shared (type B) errors carried
through the interpolation's weights; the interpolation, along the rows (Richardson's, from the
rows thinned to every other and every fourth node) and across them (each cell rectangular
within its change to the nearest row's alone, the cells' errors as one); the fill's model
parameters (the fit's covariance without its scaling by chi2/dof) and model form (the change
when the rows' end intervals continue instead of holding; where no row reaches, the model's
relative misfit to the data beyond their noise)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from calibration.fit.result import FitResult
from calibration.hemisphere import Cells, cells, row_interpolation, side_coordinates
from calibration.reduced import ReducedData
from calibration.smearing import Smearing
from calibration.values import CalibrationError
from model.bsdf.fresnel import fresnel_dielectric

#: ISO 13696's total scattering: the power scattered between these angles from the specular
#: (backward) or direct (forward) beam, relative to the incident power, degrees.
TIS_CONE_DEG = (2.0, 85.0)
#: ASTM D1003's haze: transmitted light deviating from the direct beam by more than this, deg.
HAZE_CONE_DEG = 2.5
#: ISO 2813 (as ASTM D523): geometry (deg) -> the receptor window's full angles, in the plane
#: of incidence and perpendicular to it, degrees (the standard's nominal values).
GLOSS_WINDOWS_DEG = {20.0: (1.8, 3.6), 60.0: (4.4, 11.7), 85.0: (4.0, 6.0)}
#: The primary gloss standard: polished black glass of this index, 100 GU at every geometry.
GLOSS_STANDARD_INDEX = 1.567
#: A block's incidence matches a gloss geometry within this, degrees.
GLOSS_INCIDENCE_TOL_DEG = 0.5
#: Components of an integral's standard uncertainty, in the order tables show them.
COMPONENTS = ("noise", "shared", "interpolation", "model_parameters", "model_form")
#: What each quantity is, for tables and files.
LABELS = {
    "reflectance": "directional-hemispherical reflectance",
    "transmittance": "directional-hemispherical transmittance",
    "tis_backward": "total scattering, backward (ISO 13696: 2-85 deg from the specular beam)",
    "tis_forward": "total scattering, forward (ISO 13696: 2-85 deg from the direct beam)",
    "haze": "haze (ASTM D1003: share of the transmittance beyond 2.5 deg from the direct beam)",
    "gloss": "specular gloss, GU (ISO 2813: the receptor window's reflectance / black glass "
             "n 1.567's, x 100)",
}


@dataclass(frozen=True)
class Integral:
    """One integrated quantity at one incidence: its value, its standard uncertainty's
    components by name (COMPONENTS) and the share of the value the model fill gives."""

    name: str
    theta_i_deg: float
    value: float
    components: dict[str, float]
    model_share: float

    @property
    def u(self) -> float:
        """The combined standard uncertainty: the components' root sum of squares."""
        return math.sqrt(sum(c * c for c in self.components.values()))

    def to_json(self, k: float) -> dict:
        """The integral as a JSON object, with U = k u."""
        return {"quantity": self.name, "label": LABELS[self.name],
                "theta_i_deg": self.theta_i_deg, "value": self.value, "u": self.u,
                "coverage_k": k, "U": k * self.u, "components": dict(self.components),
                "model_share": self.model_share}


@dataclass
class Block:
    """The data and fitted model of one incidence and side on its cells: the model at the
    cells and the points, the data's residual from it interpolated (linearly, from the nearest
    row, from every other and every fourth node, continued linearly beyond the rows' ends),
    the model's change with each fitted parameter (one sigma), and its relative misfit beyond
    the data's noise."""

    theta_i_deg: float
    grid: Cells
    points: ReducedData
    model_cells: np.ndarray  # (n_az, n_rad)
    residual_linear: np.ndarray  # (n_az, n_rad): the data's residual interpolated (0: no rows)
    residual_nearest: np.ndarray  # the nearest row's alone (in azimuth)
    residual_halves: np.ndarray  # (2, n_az, n_rad): from every other inner node of each row
    residual_quarters: np.ndarray  # (4, n_az, n_rad): from every fourth inner node
    residual_continued: np.ndarray  # beyond the rows' ends their end intervals' lines
    covered: np.ndarray
    reached: np.ndarray  # cells the rows' residual reaches (all of them with two rows or more)
    gradient_basis: np.ndarray  # (n_az, n_rad, n): d(cell value)/d(point value)
    parameter_steps: np.ndarray  # (n_params, n_az, n_rad): estimate's change per statistical sigma
    parameter_correlation: np.ndarray
    misfit_rel: float
    estimate: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.estimate = self.model_cells + self.residual_linear

    def value(self, weight: np.ndarray) -> float:
        """sum(weight * f) over the cells."""
        return float(np.sum(weight * self.estimate))

    def correction(self, weight: np.ndarray) -> float:
        """The along-row interpolation's Richardson correction of sum(weight * f) (_along)."""
        return self._along(weight)[0]

    def _along(self, weight: np.ndarray) -> tuple[float, float]:
        """(correction, standard uncertainty) of the interpolation along the rows, by
        Richardson: for each half of the nodes (every other one), the change d1 when the rows
        take that half alone and the change d2 when they take every other node of it, whose
        ratio q = |d1| / |d2| is 2^-p for an interpolation of order p; the larger q of the two
        halves gives the error -d1 q / (1 - q) (d1 their mean), its size the uncertainty; no
        correction and d1 itself (root mean square) where q is 1/2 or more (nodes that do not
        resolve the residual's change)."""
        def integral(residual: np.ndarray) -> np.ndarray:
            return np.sum(weight * residual, axis=(-2, -1))

        halves = integral(self.residual_halves)
        d1 = halves - integral(self.residual_linear)
        d2 = (integral(self.residual_quarters) - halves[[0, 1, 0, 1]]).reshape(2, 2)
        size = math.sqrt(float(np.mean(d1 ** 2)))
        spread = np.sqrt(np.mean(d2 ** 2, axis=0))
        q = max((abs(a) / b if b > 0 else 0.0 if a == 0 else 1.0)
                for a, b in zip(d1, spread, strict=True))
        if q >= 0.5:
            return 0.0, size
        factor = q / (1.0 - q)
        return -float(np.mean(d1)) * factor, size * factor

    def components(self, weight: np.ndarray) -> dict[str, float]:
        """The standard uncertainty's components of sum(weight * f) (COMPONENTS): across the
        rows, each cell's value rectangular within +- its change to the nearest row's alone,
        the cells' errors taken as one (two rows do not tell their signs apart); along them,
        Richardson's (_along); beyond the rows' ends the change when their end intervals
        continue instead of holding."""
        fill = ~self.covered
        gradient = np.tensordot(weight, self.gradient_basis, 2)
        noise, shared = self.points.linear_uncertainty(gradient)
        across = float(np.sum(np.abs(weight * (self.residual_linear - self.residual_nearest))))
        interpolation = math.hypot(across / math.sqrt(3.0), self._along(weight)[1])
        steps = np.sum(np.where(fill, weight, 0.0) * self.parameter_steps, axis=(1, 2))
        parameters = math.sqrt(max(float(steps @ self.parameter_correlation @ steps), 0.0))
        held = float(np.sum(np.where(fill, weight, 0.0)
                            * (self.residual_continued - self.residual_linear)))
        bare = self.misfit_rel * float(np.sum(np.where(self.reached, 0.0, np.abs(weight))
                                              * self.model_cells))
        return dict(zip(COMPONENTS, (noise, shared, interpolation, parameters,
                                     math.hypot(held, bare)), strict=True))

    def model_share(self, weight: np.ndarray) -> float:
        """The share of sum(weight * f) that the model fill gives."""
        total = self.value(weight)
        fill = float(np.sum(np.where(self.covered, 0.0, weight * self.estimate)))
        return fill / total if total else 0.0


def _aligned(points: ReducedData, isotropic: bool) -> ReducedData:
    """The points turned about the normal so that each one's source lies on -x in the x-z
    plane (an isotropic sample looks the same); an anisotropic one must be measured so."""
    phi = np.arctan2(points.wi[:, 1], points.wi[:, 0]) - math.pi
    tilted = np.abs(np.sin(phi)) > 1e-9
    if not np.any(tilted):
        return points
    if not isotropic:
        raise CalibrationError("integrals: an anisotropic fit needs incidence in the x-z plane "
                               "with the source on -x (phi_i = 180 deg)")
    c, s = np.cos(-phi)[:, None], np.sin(-phi)[:, None]

    def turn(v: np.ndarray) -> np.ndarray:
        return np.column_stack([c[:, 0] * v[:, 0] - s[:, 0] * v[:, 1],
                                s[:, 0] * v[:, 0] + c[:, 0] * v[:, 1], v[:, 2]])

    turned = points.subset(np.ones(len(points.bsdf), bool))
    turned.wi, turned.wo = turn(points.wi), turn(points.wo)
    return turned


def _misfit(points: ReducedData, model: np.ndarray) -> float:
    """The model's relative misfit to the points beyond their noise: the root of
    sum((f - m)^2 - u^2) / sum(m^2), so that the points where the BSDF is large, which carry
    the integrals, weigh most (0 where the noise explains the residuals)."""
    excess = float(np.sum((points.bsdf - model) ** 2 - points.sigma ** 2))
    return math.sqrt(max(excess, 0.0) / float(np.sum(model ** 2)))


def incidence(theta_i_deg: float) -> np.ndarray:
    """The direction toward the source at theta_i_deg, the source on -x."""
    t = math.radians(theta_i_deg)
    return np.array([-math.sin(t), 0.0, math.cos(t)])


def _specular(theta_i_deg: float, transmission: bool, eta: float) -> tuple[float, str]:
    """(angle from the normal, scatter type) of the specular or direct-transmission direction
    (refracted into the hemisphere's medium)."""
    if not transmission:
        return theta_i_deg, "BRDF"
    return math.degrees(math.asin(math.sin(math.radians(theta_i_deg)) / eta)), "BTDF"


def block_cells(theta_i_deg: float, transmission: bool, eta: float) -> Cells:
    """The quadrature cells of one incidence and side."""
    return cells(*_specular(theta_i_deg, transmission, eta))


def block(data: ReducedData, result: FitResult, theta_i_deg: float, transmission: bool,
          isotropic: bool = True) -> Block | None:
    """The Block of `data`'s valid points at one incidence and side (None without any),
    with `result`'s model as the fill."""
    select = (data.valid & (data.transmission == transmission)
              & (np.abs(data.theta_i_deg - theta_i_deg) < 0.05) & np.isfinite(data.bsdf))
    if not np.any(select):
        return None
    points = _aligned(data.subset(select), isotropic)
    wi, grid = incidence(theta_i_deg), block_cells(theta_i_deg, transmission,
                                                   float(data.meta["eta"]))

    def model_at(fitted: FitResult) -> np.ndarray:
        """The model's point BSDF at the cells (the points' aperture average left out: the
        integrals are of the BSDF, not of what the receiver saw)."""
        out = np.zeros(grid.weight.shape)
        side = grid.on_side
        point = replace(fitted, optics=Smearing(0.0, 0, 0.0, 0))
        out[side] = point.predict(np.broadcast_to(wi, (int(side.sum()), 3)), grid.wo[side])
        return out

    model_cells = model_at(result)
    model_points = result.predict(points.wi, points.wo)
    rows = row_interpolation(*side_coordinates(grid.wo), *side_coordinates(points.wo),
                             isotropic)
    floor = float(np.median(np.abs(points.bsdf))) or 1.0  # 1/sr where half the data are 0
    relative = (points.bsdf - model_points) / (model_points + floor)
    reached = grid.on_side & np.any(rows.linear != 0, axis=-1)
    scale = np.where(reached, model_cells + floor, 0.0)

    def residual(thin: tuple[int, int] | None = None, extrapolate: bool = False
                 ) -> np.ndarray:
        """The relative residual interpolated onto the cells and scaled back (the rows
        thinned or continued: row_interpolation)."""
        found = row_interpolation(*side_coordinates(grid.wo), *side_coordinates(points.wo),
                                  isotropic, thin, extrapolate)
        return scale * (found.linear @ relative)

    def estimate_at(values: np.ndarray) -> np.ndarray:
        """The cells' estimate with the model's parameters at `values`: the model and the
        data's residual from it, both moving with them (so that where the residual holds
        beyond the rows, only the model's change of shape from the rows' ends counts)."""
        fitted = replace(result, values=values)
        cells_at = model_at(fitted)
        points_at = fitted.predict(points.wi, points.wo)
        return cells_at + np.where(reached, cells_at + floor, 0.0) * (
            rows.linear @ ((points.bsdf - points_at) / (points_at + floor)))

    basis = scale[..., None] * rows.linear / (model_points + floor)
    # the parameters' statistical sigmas: the fit scales its covariance by chi2/dof for the
    # misfit, which here the residual carries and the model-form term bounds past the rows
    sigmas = result.errors / math.sqrt(max(1.0, result.chi2_dof_fit))
    steps = []
    for k, sigma in enumerate(sigmas):
        shifted = [result.values.copy(), result.values.copy()]
        shifted[0][k] += sigma
        shifted[1][k] -= sigma
        up, down = (estimate_at(v) for v in shifted)
        steps.append(0.5 * (up - down))
    spread = np.sqrt(np.clip(np.diag(result.covariance), 1e-300, None))
    correlation = result.covariance / np.outer(spread, spread)
    return Block(theta_i_deg, grid, points, model_cells, scale * (rows.linear @ relative),
                 scale * (rows.nearest @ relative),
                 np.stack([residual((2, k)) for k in range(2)]),
                 np.stack([residual((4, k)) for k in range(4)]),
                 residual(extrapolate=True), rows.covered, reached, basis, np.array(steps),
                 correlation,
                 _misfit(points, model_points) if len(points.bsdf) else 0.0)


def _cone(grid: Cells, lo_deg: float, hi_deg: float) -> np.ndarray:
    """The cells' weights between lo_deg and hi_deg from the specular direction."""
    inside = (grid.radial_deg >= lo_deg) & (grid.radial_deg <= hi_deg)
    return np.where(inside[None, :], grid.weight, 0.0)


def _window(grid: Cells, full_in_plane_deg: float, full_across_deg: float) -> np.ndarray:
    """The cells' weights inside a rectangular receptor window centred on the specular
    direction: angles in and across the plane of incidence within half the full angles."""
    r = np.radians(grid.radial_deg)[None, :]
    phi = np.radians(grid.azimuth_deg)[:, None]
    along = np.degrees(np.arctan2(np.sin(r) * np.cos(phi), np.cos(r)))
    across = np.degrees(np.arcsin(np.sin(r) * np.sin(phi)))
    inside = (np.abs(along) <= full_in_plane_deg / 2) & (np.abs(across) <= full_across_deg / 2)
    return np.where(inside, grid.weight, 0.0)


def black_glass_reflectance(theta_deg: float) -> float:
    """Unpolarised Fresnel reflectance of ISO 2813's black glass standard at theta_deg."""
    return float(fresnel_dielectric(np.array(math.cos(math.radians(theta_deg))),
                                    GLOSS_STANDARD_INDEX))


def _gloss_geometry(theta_i_deg: float) -> float | None:
    """The ISO 2813 geometry an incidence matches, if any."""
    return next((g for g in GLOSS_WINDOWS_DEG
                 if abs(theta_i_deg - g) <= GLOSS_INCIDENCE_TOL_DEG), None)


def quantities(theta_i_deg: float, transmission: bool) -> list[str]:
    """The quantities of one incidence and side."""
    if transmission:
        return ["transmittance", "tis_forward", "haze"]
    gloss = ["gloss"] if _gloss_geometry(theta_i_deg) is not None else []
    return ["reflectance", "tis_backward", *gloss]


def weights(name: str, grid: Cells, theta_i_deg: float) -> np.ndarray:
    """The cell weights W of a quantity linear in the BSDF (value = sum(W * f)); haze's
    numerator (the transmittance beyond the cone) for "haze"."""
    if name in ("reflectance", "transmittance"):
        return grid.weight
    if name in ("tis_backward", "tis_forward"):
        return _cone(grid, *TIS_CONE_DEG)
    if name == "haze":
        return _cone(grid, HAZE_CONE_DEG, 180.0)
    geometry = _gloss_geometry(theta_i_deg)
    return _window(grid, *GLOSS_WINDOWS_DEG[geometry]) * 100.0 / black_glass_reflectance(
        geometry)


def value_of(name: str, grid: Cells, theta_i_deg: float, f: np.ndarray) -> float:
    """A quantity from the BSDF at the cells (haze: the ratio of its weights' sums)."""
    value = float(np.sum(weights(name, grid, theta_i_deg) * f))
    return value / float(np.sum(grid.weight * f)) if name == "haze" else value


def _integral(b: Block, name: str) -> Integral | None:
    """The Integral of one quantity of a block, with the along-row interpolation's Richardson
    correction (Block.correction); haze's correction and uncertainty through the ratio's
    linear weight (W_diffuse - h W) / T (None: no haze of a transmittance that is not
    positive)."""
    w = weights(name, b.grid, b.theta_i_deg)
    if name != "haze":
        return Integral(name, b.theta_i_deg, b.value(w) + b.correction(w), b.components(w),
                        b.model_share(w))
    total = b.value(b.grid.weight)
    if not total > 0:
        return None
    h = b.value(w) / total
    linear = (w - h * b.grid.weight) / total
    return Integral(name, b.theta_i_deg, h + b.correction(linear), b.components(linear),
                    b.model_share(w))


def integrals(data: ReducedData, result: FitResult) -> list[Integral]:
    """Every integrated quantity of `data` at each of its incidences, `result` (a fit over
    every incidence) filling what the data do not cover."""
    isotropic = "alpha" in result.names
    out = []
    for theta_i in sorted(set(np.round(data.theta_i_deg[data.valid], 1).tolist())):
        for transmission in (False, True):
            b = block(data, result, theta_i, transmission, isotropic)
            if b is not None:
                found = (_integral(b, name) for name in quantities(theta_i, transmission))
                out += [i for i in found if i is not None]
    return out


#: What the integrals assume, for tables and files.
ASSUMPTIONS = (
    "an isotropic fit mirrors the points across the plane of incidence; the residual from the "
    "fitted model is interpolated linearly in azimuth between measured rows (an in-plane scan: "
    "its forward and backward halves), so U holds out-of-plane structure the model and the "
    "rows miss only as far as the nearest-row term sees it; past the rows' last measured angle "
    "their end residual holds (the model's shape scaled as the data at the ends scale it)",
    "transmission is integrated inside the hemisphere's medium about the refracted direct beam "
    "(the integrals of f |cos theta_o|, as the Zemax export's TIS); ASTM D1003 defines haze "
    "at normal incidence",
    "gloss: an ideal collimated source (the standard's 0.75 x 2.5 deg source aperture not "
    "convolved), the receptor window as a rectangle of in-plane x across angles "
    + ", ".join(f"{g:g} deg: {a:g} x {b:g} deg" for g, (a, b) in GLOSS_WINDOWS_DEG.items())
    + f"; the black glass (n {GLOSS_STANDARD_INDEX}) reflects its Fresnel reflectance into it",
)


def to_json(found: list[Integral], k: float, result: FitResult) -> dict:
    """The integrals, the fit that fills what the data do not cover, and the assumptions, as
    a JSON object (`gonio reduce --integrals-json`)."""
    return {"coverage_k": k, "fill_model": {"distribution": result.distribution,
                                            "parameters": result.to_dict()["parameters"],
                                            "chi2_dof": result.chi2_dof_fit},
            "integrals": [i.to_json(k) for i in found], "assumptions": list(ASSUMPTIONS)}


def table(found: list[Integral], k: float) -> list[str]:
    """Lines of a table of integrals: incidence, quantity, value, u, U = k u, each component
    and the model fill's share; then what each quantity is."""
    head = (f"{'theta_i':>7} {'quantity':<14} {'value':>10} {'u':>9} {'U':>9} "
            + " ".join(f"{c:>16}" for c in COMPONENTS) + f" {'model share':>11}")
    lines = [head]
    for i in found:
        lines.append(f"{i.theta_i_deg:7g} {i.name:<14} {i.value:10.5g} {i.u:9.2g} "
                     f"{k * i.u:9.2g} " + " ".join(f"{i.components[c]:16.2g}" for c in COMPONENTS)
                     + f" {i.model_share:11.1%}")
    names = dict.fromkeys(i.name for i in found)
    return lines + [f"{name}: {LABELS[name]}" for name in names]
