"""Plane wave at a flat interface by Maxwell's boundary conditions, for the Mueller tests.

Independent of the model's Fresnel formulas and s/p rotations: the reflected and transmitted
fields are 3-vectors solved from the continuity of tangential E and H (mu = 1, H = K x E, fields
~ exp(i(K.r - omega t))), for any interface normal, and read in whatever frames a test names."""

from __future__ import annotations

import numpy as np

#: Jones vectors (s, p) of the four probe states: s, p, +45 degrees, and S3 = +1.
PROBES = np.array([[1, 0], [0, 1], [1, 1], [1, 1j]]) / np.array([[1], [1], [2**0.5], [2**0.5]])


def stokes(a: complex, b: complex) -> np.ndarray:
    """Stokes vector of the field a s + b p: (|a|^2+|b|^2, |a|^2-|b|^2, 2Re(a* b), 2Im(a* b))."""
    return np.array([abs(a) ** 2 + abs(b) ** 2, abs(a) ** 2 - abs(b) ** 2,
                     2 * (np.conj(a) * b).real, 2 * (np.conj(a) * b).imag])


def interface_fields(k_in: np.ndarray, normal: np.ndarray, index: complex, e_in: np.ndarray):
    """(E_reflected, E_transmitted, K_transmitted) for the incident field e_in (3, complex) along
    unit k_in in a medium of index 1 meeting a medium of relative index `index` (n + ik, k >= 0)
    across the plane of unit `normal`, which points into the incident medium."""
    normal = normal if np.dot(k_in, normal) < 0 else -normal
    k_r = k_in - 2 * np.dot(k_in, normal) * normal
    along = k_in - np.dot(k_in, normal) * normal
    k_t = along - normal * np.sqrt(complex(index) ** 2 - np.dot(along, along))
    t1 = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(normal, t1)

    def curl(k):  # the matrix of E -> k x E
        return np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])

    rows, rhs = [], []
    for t in (t1, t2):  # tangential E and H continuous: E_r - E_t = -E_i, H_r - H_t = -H_i
        rows.append(np.concatenate([t, -t]))
        rhs.append(-np.dot(t, e_in))
        rows.append(np.concatenate([t @ curl(k_r), -(t @ curl(k_t))]))
        rhs.append(-np.dot(t, np.cross(k_in, e_in)))
    rows.append(np.concatenate([k_r, np.zeros(3)]))  # transverse waves
    rows.append(np.concatenate([np.zeros(3), k_t]))
    rhs += [0.0, 0.0]
    fields = np.linalg.solve(np.array(rows, dtype=complex), np.array(rhs, dtype=complex))
    return fields[:3], fields[3:], k_t


def interface_mueller(k_in, normal, index, frame_in, frame_out, transmitted=False):
    """Mueller matrix (4, 4) of the interface from Stokes vectors in frame_in = (s, p) of the
    incident beam to frame_out = (s, p) of the reflected (or transmitted) beam, by probing
    with PROBES; the transmitted one is scaled to power (normal flux of the refracted wave)."""
    s_in, p_in = frame_in
    s_out, p_out = frame_out
    before, after = [], []
    for a, b in PROBES:
        e_r, e_t, k_t = interface_fields(k_in, normal, index, a * s_in + b * p_in)
        e = e_t if transmitted else e_r
        after.append(stokes(np.dot(e, s_out), np.dot(e, p_out)))
        before.append(stokes(a, b))
    m = np.array(after).T @ np.linalg.inv(np.array(before).T)
    if transmitted:
        normal = normal if np.dot(k_in, normal) < 0 else -normal
        m *= np.dot(k_t, -normal).real / np.dot(k_in, -normal)
    return m
