"""The N.V coordinate of a transmission table, remapped per (alpha, eta) so that the edge of
total internal reflection and the Fresnel layer near eta = 1 keep fixed texels.

`tir` (the default): node k of n sits at s = k / (n - 1) (texture coordinate
t = (1/2 + (n - 1) s) / n: N.V = 0 and 1 are nodes). With d = eta^2 - 1, mu_c the critical N.V
sqrt(max(-d, 0)) and the split mu_s = mu_c^3 / (mu_c^2 + alpha^2) (mu_c for a smooth surface,
moving to 0 as the roughness blurs the edge away):

* s in [0, s_c], s_c = node n // 3: N.V in [0, mu_s], s = s_c (1 - y), y = squash(mu_s - mu;
  M = mu_s, w = LOWER_WIDTH alpha) (beyond the critical angle; only roughness makes a layer);
* s in [s_c, 1]: s = s_c + (1 - s_c) x, x = squash(m = (mu - mu_s) (mu + mu_s + e);
  M = m at mu = 1, w = |d| + (ROUGHNESS_WIDTH alpha)^2), e = GRAZING alpha (the rise from a
  grazing view of a rough surface is steeper than linear in N.V),

where squash(m; M, w)^2 = m (M + w) / ((m + w) M) grows like sqrt(m / w) inside the layer
m < w and straightens beyond it. For a smooth surface x min(eta, 1/eta) is the ratio of the
smaller to the larger of N.V and eta cos(theta_t), of which Fresnel's transmittance is a
smooth function on both sides of eta = 1: the critical angle sits on node n // 3, the
square-root rise above it becomes a straight line, and the layer of width sqrt|d| where
Fresnel departs from 0 near eta = 1 keeps its texels however thin it gets. The map is
continuous in (mu, alpha, eta), eta = 1 included. A remapped table also puts the ends of
the alpha and eta ranges on nodes, crowds its eta nodes towards 1 (model.lut.axes.ETA_POWER)
and stores eta^2 T (albedo_factor). `none` is the identity, t = N.V, storing T.
"""

from __future__ import annotations

import numpy as np

REMAPS = ("tir", "none")
#: Roughness's share of the layer width w above the split, in units of alpha^2.
ROUGHNESS_WIDTH = 1.0
#: The layer width below the split (N.V < mu_s), in units of alpha.
LOWER_WIDTH = 4.0
#: Where the rise from grazing view (or from the split) turns from linear to square in m, in
#: units of alpha.
GRAZING = 1.0
#: Floor of every width, so the map stays defined at eta = 1, alpha = 0 (x = 1 for mu > 0).
TINY = 1e-300
#: N.V at which the N.V = 0 nodes are baked: the model's limit N.V -> 0+ (at 0 itself the
#: view is tangent and the model returns 0, which is not the limit of a rough surface).
MU_FLOOR = 1e-6

DESCRIPTION = ("remapped N.V coordinate s (model.lut.remap, docs/lut.md): with d = eta^2 - 1, "
               "mu_c = sqrt(max(-d, 0)), mu_s = mu_c^3 / (mu_c^2 + alpha^2), "
               "q(m; M, w) = sqrt(m (M + w) / ((m + w) M)) and s_c = (n // 3) / (n - 1): "
               f"s = s_c (1 - q(mu_s - mu; mu_s, {LOWER_WIDTH:g} alpha)) for mu < mu_s, else "
               f"s = s_c + (1 - s_c) q(m(mu); m(1), |d| + ({ROUGHNESS_WIDTH:g} alpha)^2) with "
               f"m(mu) = (mu - mu_s) (mu + mu_s + {GRAZING:g} alpha)")


def split(n: int) -> float:
    """s of the node holding the split (the critical angle of a smooth surface): n // 3."""
    return (n // 3) / (n - 1)


def _layer(alpha: np.ndarray, eta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The split N.V mu_s and the layer width w above it."""
    d = eta * eta - 1.0
    mu_c2 = np.maximum(-d, 0.0)
    mu_s = np.sqrt(mu_c2) * mu_c2 / (mu_c2 + alpha * alpha + TINY)
    return mu_s, np.abs(d) + (ROUGHNESS_WIDTH * alpha) ** 2 + TINY


def _squash(m: np.ndarray, big_m: np.ndarray, width: np.ndarray) -> np.ndarray:
    """x in [0, 1] of m in [0, M]: x^2 = m (M + w) / ((m + w) M) (0 when M = 0)."""
    return np.sqrt(np.minimum(m * (big_m + width) / np.maximum((m + width) * big_m, TINY), 1.0))


def _unsquash(x: np.ndarray, big_m: np.ndarray, width: np.ndarray) -> np.ndarray:
    """m of x (the inverse of _squash)."""
    x2 = x * x
    return x2 * width * big_m / np.maximum(big_m + width - x2 * big_m, TINY)


def _arrays(*values) -> list[np.ndarray]:
    """The values as broadcast float64 arrays."""
    return [np.asarray(v, dtype=np.float64) for v in np.broadcast_arrays(*values)]


def nv_coord(mu, alpha, eta, n: int) -> np.ndarray:
    """Texture coordinate t of N.V = mu at (alpha, eta) on an N.V axis of n nodes."""
    mu, alpha, eta = _arrays(mu, alpha, eta)
    mu = np.clip(mu, 0.0, 1.0)
    mu_s, width = _layer(alpha, eta)
    s_c = split(n)
    eps = GRAZING * alpha
    x = _squash(np.maximum((mu - mu_s) * (mu + mu_s + eps), 0.0),
                (1.0 - mu_s) * (1.0 + mu_s + eps), width)
    y = _squash(np.maximum(mu_s - mu, 0.0), mu_s, LOWER_WIDTH * alpha + TINY)
    s = np.where(mu < mu_s, s_c * (1.0 - y), s_c + (1.0 - s_c) * x)
    return (0.5 + (n - 1) * s) / n


def nv_value(t, alpha, eta, n: int) -> np.ndarray:
    """N.V at texture coordinate t (the inverse of nv_coord; t beyond the outer texel centres
    is clamped to them)."""
    t, alpha, eta = _arrays(t, alpha, eta)
    s = np.clip((t * n - 0.5) / (n - 1), 0.0, 1.0)
    mu_s, width = _layer(alpha, eta)
    s_c = split(n)
    eps = GRAZING * alpha
    above = _unsquash(np.clip((s - s_c) / (1.0 - s_c), 0.0, 1.0),
                      (1.0 - mu_s) * (1.0 + mu_s + eps), width)
    below = mu_s - _unsquash(np.clip(1.0 - s / max(s_c, TINY), 0.0, 1.0), mu_s,
                             LOWER_WIDTH * alpha + TINY)
    root = 0.5 * (np.sqrt(eps * eps + 4.0 * (mu_s * (mu_s + eps) + above)) - eps)
    return np.clip(np.where(s < s_c, below, root), 0.0, 1.0)


def albedo_factor(remapped: bool, eta: np.ndarray | float) -> np.ndarray:
    """What a transmission table stores per unit of T at this eta: eta^2 when remapped (the
    directional albedo E = eta^2 T, bounded by 1 and free of the 1 / eta^2 that a lerp across
    eta would bend), else 1."""
    eta = np.asarray(eta, dtype=np.float64)
    return eta * eta if remapped else np.ones_like(eta)


def node_points(t, alpha, eta, n: int, mirror: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(N.V, eta) at which to bake the nodes at (t, alpha, eta): N.V = nv_value (MU_FLOOR at
    the least), and with `mirror` (a table with an eta axis), beyond the split on an eta > 1
    slice, where no view lands, the mirror node at 1 / eta, so the lerp across eta = 1 meets
    the side it continues."""
    t, alpha, eta = _arrays(t, alpha, eta)
    below = (t * n - 0.5) / (n - 1) < split(n) - 1e-12
    eta = np.where(mirror & below & (eta > 1.0), 1.0 / eta, eta)
    return np.maximum(nv_value(t, alpha, eta, n), MU_FLOOR), eta
