"""The fitter's random draws compiled (numba): the counter-based generator of :mod:`.draws`,
the same numbers drawn inside the kernel from the seed's key alone.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .kernel_math import TWO_PI

# ----------------------------------------------------------------------------- draws
# The counter-based generator of irreflect._draws, compiled: the same numbers from the
# same (key, stream, index), so that a fit draws its candidates inside its one call.
_U_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_U_M1 = np.uint64(0xBF58476D1CE4E5B9)
_U_M2 = np.uint64(0x94D049BB133111EB)
STREAM_STRATA, STREAM_OFFSETS, STREAM_JITTER, STREAM_HOPS = 0, 1, 2, 3


@njit(cache=True, inline="always")
def _mix64(x):
    x = (x ^ (x >> np.uint64(30))) * _U_M1
    x = (x ^ (x >> np.uint64(27))) * _U_M2
    return x ^ (x >> np.uint64(31))


@njit(cache=True)
def draw_uniforms(key, stream, count):
    """_draws.uniforms: ``count`` uniforms in (0, 1) of ``stream``."""
    base = _mix64(np.uint64(key) + _U_GOLDEN * np.uint64(stream + 1))
    out = np.empty(count)
    for i in range(count):
        h = _mix64(base + np.uint64(i + 1) * _U_GOLDEN)
        out[i] = (np.float64(h >> np.uint64(11)) + 0.5) * 2.0 ** -53
    return out


@njit(cache=True)
def draw_normals(key, stream, count):
    """_draws.normals: ``count`` standard normals of ``stream`` (Box-Muller)."""
    u = draw_uniforms(key, stream, 2 * count)
    out = np.empty(count)
    for i in range(count):
        out[i] = math.sqrt(-2.0 * math.log(u[2 * i])) * math.cos(TWO_PI * u[2 * i + 1])
    return out


@njit(cache=True)
def draw_latin_hypercube(key, n, lo, hi):
    """_draws.latin_hypercube: ``n`` points of a Latin hypercube in the box (lo, hi)."""
    p = lo.size
    keys = draw_uniforms(key, STREAM_STRATA, n * p)
    offsets = draw_uniforms(key, STREAM_OFFSETS, n * p)
    out = np.empty((n, p))
    for q in range(p):
        strata = np.argsort(keys[q * n:(q + 1) * n], kind="mergesort")
        for i in range(n):
            out[i, q] = lo[q] + (strata[i] + offsets[q * n + i]) / n * (hi[q] - lo[q])
    return out
