"""The direction maps of the recursive method's kernels (numba): a cell's outgoing light as
res x res equal solid-angle bins over its hemisphere (Shirley and Chiu's concentric map of
an equal-area disk), with bilinear lookup and a deposit shared between bins on a boundary.
Split from :mod:`irreflect.room.transport` at stop 49 (module size)."""

from __future__ import annotations

import math

from .kernels import PI, TWO_PI, hot


@hot
def to_square(x, y, z):
    """Local direction (z = normal) -> (u, v) in [0, 1]^2: equal-area disk ``r = sqrt(1 - z)``,
    then the inverse of Shirley and Chiu's concentric map (equal solid-angle bins; the mirror
    direction ``(-x, -y, z)`` maps to ``(1 - u, 1 - v)``)."""
    r = math.sqrt(max(0.0, 1.0 - z))
    rho = math.sqrt(x * x + y * y)
    if rho < 1e-15 or r < 1e-15:
        return 0.5, 0.5
    phi = math.atan2(y, x)
    if phi < -0.25 * PI:
        phi += TWO_PI
    if phi < 0.25 * PI:
        a = r
        b = phi * a / (0.25 * PI)
    elif phi < 0.75 * PI:
        b = r
        a = -(phi - 0.5 * PI) * b / (0.25 * PI)
    elif phi < 1.25 * PI:
        a = -r
        b = (phi - PI) * a / (0.25 * PI)
    else:
        b = -r
        a = -(phi - 1.5 * PI) * b / (0.25 * PI)
    return 0.5 * (a + 1.0), 0.5 * (b + 1.0)


@hot
def from_square(u, v):
    """(u, v) in [0, 1]^2 -> local unit direction (inverse of :func:`to_square`)."""
    a = 2.0 * u - 1.0
    b = 2.0 * v - 1.0
    if a == 0.0 and b == 0.0:
        return 0.0, 0.0, 1.0
    if abs(a) > abs(b):
        r = a
        phi = 0.25 * PI * (b / a)
    else:
        r = b
        phi = 0.5 * PI - 0.25 * PI * (a / b)
    x = r * math.cos(phi)
    y = r * math.sin(phi)
    rr = x * x + y * y  # = 1 - z
    z = 1.0 - rr
    s = math.sqrt(max(0.0, 2.0 - rr))  # sin(theta) / r
    return x * s, y * s, z


@hot
def _bilinear_cell(u, v, res):
    """Bilinear weights of bin centres around (u, v): (i0, j0, fx, fy)."""
    x = u * res - 0.5
    y = v * res - 0.5
    i0 = min(max(int(math.floor(x)), 0), res - 2)
    j0 = min(max(int(math.floor(y)), 0), res - 2)
    fx = min(max(x - i0, 0.0), 1.0)
    fy = min(max(y - j0, 0.0), 1.0)
    return i0, j0, fx, fy


@hot
def map_bin(u, v, res):
    """The bin of (u, v) on the res x res grid."""
    return min(int(u * res), res - 1) * res + min(int(v * res), res - 1)


@hot
def map_res(row):
    """Bins per side of a map row."""
    return int(math.sqrt(row.shape[0]) + 0.5)


@hot
def map_lookup(row, u, v):
    res = map_res(row)
    i0, j0, fx, fy = _bilinear_cell(u, v, res)
    b = i0 * res + j0
    return ((row[b] * (1 - fy) + row[b + 1] * fy) * (1 - fx)
            + (row[b + res] * (1 - fy) + row[b + res + 1] * fy) * fx)


@hot
def _bin_span(u, res):
    """Bin of ``u`` in [0, 1] on ``res`` bins: (i, i), or (i - 1, i) within 1e-12 of the
    boundary between them (the light is then shared, whichever way rounding falls: light
    from a source straight along a surface axis lands on a boundary, and a mirror image
    of the room must give the mirror image of the map)."""
    x = u * res
    r = int(x + 0.5)
    if 0 < r < res and abs(x - r) < 1e-12 * res:
        return r - 1, r
    i = min(max(int(x), 0), res - 1)
    return i, i


@hot
def map_splat(row, u, v, value):
    res = map_res(row)
    i0, i1 = _bin_span(u, res)
    j0, j1 = _bin_span(v, res)
    share = value / ((i1 - i0 + 1) * (j1 - j0 + 1))
    for i in range(i0, i1 + 1):
        for j in range(j0, j1 + 1):
            row[i * res + j] += share
