"""HigherOrderLobe's table lookup, one compiled loop over the pairs (numba; plain Python without).

A reading asks for a handful of pairs, so the lookup is one call that finds each pair's
incidence nodes, azimuth columns and polar cell and sums the tables there: order 2 and orders
>= 3 by cubic Hermite (PCHIP slopes, tabulated at the build), the standard error linearly.
Tables a pair needs that are not built yet are reported instead, for the caller to build.
"""

from __future__ import annotations

import math

import numpy as np

from model.bsdf.primitives import scalar


@scalar
def _cell(x, nodes, snap):
    """(lower node index, fraction towards the next) of x on increasing nodes, clamped to
    them; within `snap` of a step from a node, that node exactly."""
    last = len(nodes) - 1
    x = min(max(x, nodes[0]), nodes[last])
    k = min(int(np.searchsorted(nodes, x, side="right")) - 1, last - 1)
    pos = k + (x - nodes[k]) / (nodes[k + 1] - nodes[k])
    near = round(pos)
    if abs(pos - near) < snap:
        pos = near
    k = min(int(math.floor(pos)), last - 1)
    return k, pos - k


@scalar
def lookup(wi, wo, incidence, incidence_snap, column_cos, phi_snap, pole_deg, upper, lower,
           f2, d2, f3, d3, e3, built, plane_of, value2, value3, var, missing):
    """Interpolate the tables (side, node, column, polar) f2 (order 2), f3 (orders >= 3), d2 and
    d3 (their PCHIP slopes in degrees) and e3 (the standard error of f3) at the pairs wi, wo
    (n, 3; any length) into value2, value3 and var (n,): linear in the incidence nodes (deg) and in
    -cos(phi_o - phi_i) over column_cos (within pole_deg of a pole between the first and last
    column only); in theta_o over the polar nodes of the upper half (deg, up to the horizon) or
    the lower one, cubic Hermite for f2 and f3 and linear for e3. A pair needing a table
    whose plane_of[column] is not built[side, node, plane, half] writes (side, node, plane,
    half) to a row of missing instead; returns how many rows."""
    n_missing = 0
    last = len(column_cos) - 1
    split = len(upper)
    ends = np.array([-1.0, 1.0])
    for n in range(len(wi)):
        cos_i = wi[n, 2] / math.sqrt(wi[n, 0] ** 2 + wi[n, 1] ** 2 + wi[n, 2] ** 2)
        cos_o = wo[n, 2] / math.sqrt(wo[n, 0] ** 2 + wo[n, 1] ** 2 + wo[n, 2] ** 2)
        side = 0 if cos_i >= 0.0 else 1
        theta_i = math.degrees(math.acos(min(abs(cos_i), 1.0)))
        theta_o = math.degrees(math.acos(min(max(cos_o, -1.0), 1.0)))
        turn = math.atan2(wo[n, 1], wo[n, 0]) - math.atan2(wi[n, 1], wi[n, 0])
        c = -math.cos(turn)
        node0, a_node = _cell(theta_i, incidence, incidence_snap)
        if theta_o < pole_deg or theta_o > 180.0 - pole_deg:
            j0, j1, a_col = 0, last, _cell(c, ends, phi_snap)[1]
        else:
            j0, a_col = _cell(c, column_cos, phi_snap)
            j1 = j0 + 1
        half = 1 if theta_o > 90.0 else 0
        nodes, offset = (lower, split) if half else (upper, 0)
        k, t = _cell(theta_o, nodes, 0.0)
        h = nodes[k + 1] - nodes[k]
        k += offset
        h00, h10 = (1.0 + 2.0 * t) * (1.0 - t) ** 2, t * (1.0 - t) ** 2 * h
        h01, h11 = t * t * (3.0 - 2.0 * t), t * t * (t - 1.0) * h
        v2, v3, v = 0.0, 0.0, 0.0
        for node, w_node in ((node0, 1.0 - a_node), (node0 + 1, a_node)):
            if w_node <= 0.0:
                continue
            for j, w_col in ((j0, 1.0 - a_col), (j1, a_col)) if node else ((0, 1.0), (0, 0.0)):
                w = w_node * w_col
                if w <= 0.0:
                    continue
                if not built[side, node, plane_of[j], half]:
                    missing[n_missing, 0], missing[n_missing, 1] = side, node
                    missing[n_missing, 2], missing[n_missing, 3] = plane_of[j], half
                    n_missing += 1
                    continue
                row2, slope2, row3, slope3 = f2[side, node, j], d2[side, node, j], \
                    f3[side, node, j], d3[side, node, j]
                v2 += w * (h00 * row2[k] + h10 * slope2[k] + h01 * row2[k + 1]
                           + h11 * slope2[k + 1])
                v3 += w * (h00 * row3[k] + h10 * slope3[k] + h01 * row3[k + 1]
                           + h11 * slope3[k + 1])
                err = e3[side, node, j]
                v += (w * ((1.0 - t) * err[k] + t * err[k + 1])) ** 2
        value2[n], value3[n], var[n] = v2, v3, v
    return n_missing
