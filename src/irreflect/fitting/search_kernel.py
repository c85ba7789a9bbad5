"""The steps of the global search in the compiled kernel (numba), one call each, for the
search driver (:func:`irreflect.fitting.search.run_search` with the compiled backend):
the table's points and the data-driven starts (:func:`prepare`), the projected cost of
candidates (:func:`score`), Levenberg-Marquardt from a batch of starts (:func:`solve`) and
a refinement round's scans (:func:`scan`). The plain two-lobe model takes the fast path
(:mod:`.fast_kernel`), its extensions the generic one (:mod:`.local_kernel`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .fast_kernel import (
    _TL_ROWS,
    _tl_lm,
    _tl_scan_costs,
    _tl_screen_costs,
    _tl_set_yy,
    tl_points,
    tl_work,
)
from .kernel_math import STOP_NONFINITE
from .kernel_types import Solution, Work
from .local_kernel import _costs, _lm, _scan_candidates
from .model_kernel import _sizes
from .starts_kernel import _own_starts, _tl_profile


@njit(cache=True)
def prepare(km, kt, power, weights, jitter, extra):
    """One table ready to search (``power`` already divided by its scale): its points by
    angle of incidence, the fast path's scratch and the data-driven starts (the caller's
    ``extra`` rows first, then the per-angle decomposition's, the jittered ones), clipped
    and unique. Returns (Work, starts)."""
    n = power.size
    sw = np.sqrt(weights)
    yw = sw * power
    pts = np.empty((_TL_ROWS, n))
    gstart = np.empty(kt.glcg.size + 1, np.int64)
    lgroup = np.empty(n, np.int64)
    tl_points(kt.geo, kt.glcg.size, (sw, yw, np.ones(n), power), np.ones(n, np.bool_), pts,
              gstart, lgroup, kt.group)
    ws = tl_work(n, kt.glcg.size)
    _tl_set_yy(pts, gstart, ws[12][0])
    prof, ok = _tl_profile(pts, n, lgroup, kt.levels.size, km.nd_grid, km.ns_grid)
    own = _own_starts(prof, ok, kt.levels, jitter, km.zlo, km.zhi, km.ext_rows, extra)
    return Work((kt.geo, kt.glcg, sw, yw), pts, gstart, ws), own


@njit(cache=True)
def score(km, work, cands):
    """The projected cost of every candidate row (no derivatives)."""
    if km.codes.size == 0:
        return _tl_screen_costs(cands, work.pts, work.gstart, work.table[1], km.nonneg,
                                km.residual, work.ws)
    return _costs(km.codes, km.nonneg, km.residual, cands, work.table)


@njit(cache=True)
def solve(km, work, starts, stop):
    """Levenberg-Marquardt from every row of ``starts`` (``stop``: max_iter, ftol, xtol);
    the best end point (the first of equal costs; cost inf when none is finite) and the
    evaluations of all."""
    p = km.zlo.size
    _, ll = _sizes(km.codes, km.codes.size)
    fast = km.codes.size == 0
    zb = np.empty(p)
    ab = np.empty(ll)
    cb = math.inf
    rb = STOP_NONFINITE
    zt = np.empty(p)
    at = np.empty(ll)
    nfev = 0
    for i in range(starts.shape[0]):
        if fast:
            c, r, nf = _tl_lm(km.nonneg, km.residual, starts[i], (km.zlo, km.zhi),
                              (work.pts, work.gstart, work.table[1]), stop, zt, at, work.ws)
        else:
            c, r, nf = _lm(km.codes, km.nonneg, km.residual, starts[i], (km.zlo, km.zhi),
                           work.table, stop, zt, at)
        nfev += nf
        if c < cb:
            cb = c
            rb = r
            zb[:] = zt
            ab[:] = at
    return Solution(zb, ab, cb, rb, nfev)


@njit(cache=True)
def scan(km, work, z):
    """A refinement round's global scans through ``z``: every coordinate swept along its
    axis (``km.axes``) with the others held. Returns (candidates, costs)."""
    cands = _scan_candidates(z, km.axes)
    if km.codes.size == 0:
        costs = _tl_scan_costs(z, km.axes, work.pts, work.gstart, work.table[1], km.nonneg,
                               km.residual, work.ws)
    else:
        costs = _costs(km.codes, km.nonneg, km.residual, cands, work.table)
    return cands, costs
