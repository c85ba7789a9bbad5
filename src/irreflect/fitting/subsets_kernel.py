"""Subset fits in the compiled kernel (numba): one batched search per mask row
(:func:`subset_search`), the shared candidates' products summed per subset, and R^2 of
every row against all points (:func:`r2_rows`). The numpy side: :mod:`.subsets`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .fast_kernel import (
    _SUMS,
    _TL_ROWS,
    _tl_broadcast,
    _tl_costs,
    _tl_gram_cost,
    _tl_group_values,
    _tl_lm,
    _tl_set_yy,
    _tl_ss,
    tl_points,
    tl_work,
)
from .kernel_math import STOP_FTOL, STOP_STUCK, STOP_XTOL, _stable_order, fexp, lexp
from .kernel_types import SubsetSolution
from .local_kernel import _costs, _lm
from .model_kernel import _sizes, _take, predict
from .starts_kernel import (
    _profile_pick,
    _profile_starts,
    _profile_table,
    _profile_width,
    _tl_profile,
)

#: Products per point and shared candidate (:func:`_shared_products`): x0 x0, x0 x1, x1 x1,
#: x0 y, x1 y (the sums of _tl_fill).
_SHARED = 5


@njit(cache=True, error_model="numpy", fastmath=_SUMS)
def _shared_products(cands, geo, glcg, sw, yw):
    """For every point (table order) and candidate row of the plain two-lobe model, the
    products whose sums over a subset's points at each angle of incidence are that
    angle's sums of the linear step (see _tl_fill; x: the weighted basis, y: the
    weighted power), as (n, _SHARED * candidates). Shared candidates are then scored on
    any subset without an exponential."""
    n = sw.size
    c_count = cands.shape[0]
    out = np.empty((n, _SHARED * c_count))
    gval = np.empty((glcg.size, 5))
    lct_all, pt_all, lcp_all, pp_all, group = geo[3], geo[4], geo[5], geo[6], geo[7]
    for c in range(c_count):
        z = cands[c]
        _tl_group_values(z, glcg, gval)
        o = _SHARED * c
        for j in range(n):
            g = group[j]
            a = lexp(gval[g, 1] * lct_all[j]) * (1.0 if pt_all[j] else 0.0)
            b = lexp(gval[g, 2] * lcp_all[j]) * (1.0 if pp_all[j] else 0.0)
            ld = gval[g, 3] * a
            ls = gval[g, 4] * b
            w = sw[j]
            x0 = ld * w
            x1 = (ld + gval[g, 0] * (ls - ld)) * w
            y = yw[j]
            out[j, o] = x0 * x0
            out[j, o + 1] = x0 * x1
            out[j, o + 2] = x1 * x1
            out[j, o + 3] = x0 * y
            out[j, o + 4] = x1 * y
    return out


@njit(cache=True, error_model="numpy")
def _subset_sums(mask, weights, groups, tables, out):
    """A subset's sums of its points' rows: the per-angle decomposition's products per
    level (points of positive weight, ``out[0]``; ``groups[0]``: each point's level) and
    the shared candidates' per angle of incidence (``out[1]``, (G, _SHARED *
    candidates); ``groups[1]``: each point's angle). ``tables``: the batch's
    (:func:`_profile_table`, :func:`_shared_products`)."""
    pgroup, egroup = groups
    qtab, shared = tables
    sums, gsums = out
    sums[:, :] = 0.0
    gsums[:, :] = 0.0
    width = sums.shape[1]
    n_shared = gsums.shape[1]
    for j in range(mask.size):
        if mask[j]:
            g = egroup[j]
            for i in range(n_shared):
                gsums[g, i] += shared[j, i]
            if weights[j] > 0.0:
                gi = pgroup[j]
                for i in range(width):
                    sums[gi, i] += qtab[j, i]


@njit(cache=True)
def subset_search(km, kt, power, weights, masks, screen, cfg):
    """fitting.fit_subsets' batched search for every mask row: the profile starts of each
    subset's points and the shared screening candidates, scored on the subset's points;
    Levenberg-Marquardt from the best ``n_keep`` candidates and the best
    ``n_data_starts`` data-driven starts. One thread (parallel runs use processes, see
    irreflect.selection.parallel). ``km``: the model (KModel), ``kt``: the table's
    geometry (KTable), ``cfg``: (n_keep, n_data_starts, max_iter, ftol). Returns a
    SubsetSolution: z (B, P), alpha (B, L), cost (B,), converged (B,), nfev."""
    codes, zlo, zhi = km.codes, km.zlo, km.zhi
    geo, glcg = kt.geo, kt.glcg
    nd_grid, ns_grid = km.nd_grid, km.ns_grid
    b_count, n = masks.shape
    p = zlo.size
    pp, ll = _sizes(codes, codes.size)
    z_out = np.full((b_count, p), np.nan)
    a_out = np.full((b_count, ll), np.nan)
    c_out = np.full(b_count, math.inf)
    conv = np.zeros(b_count, np.bool_)
    nfev_each = np.zeros(b_count, np.int64)
    n_screen = screen.shape[0]
    clipped = np.empty((n_screen, p))
    for i in range(n_screen):
        for q in range(p):
            clipped[i, q] = min(max(screen[i, q], zlo[q]), zhi[q])
    # per call, not per subset: the whole table's sqrt(weights) and weighted power, the
    # scratch of the subsets' points and of the fast path
    sw = np.sqrt(weights)
    yw = sw * power
    pts = np.empty((_TL_ROWS, n))
    gstart = np.empty(glcg.size + 1, np.int64)
    lgroup = np.empty(n, np.int64)
    ws = tl_work(n, glcg.size)
    if codes.size == 0:
        # the plain two-lobe model: every point's products of the per-angle decomposition
        # and of the shared candidates, once for the whole batch
        qtab = _profile_table(geo, weights, power, nd_grid, ns_grid)
        shared = _shared_products(clipped, geo, glcg, sw, yw)
    else:
        qtab = np.zeros((0, 0))
        shared = np.zeros((0, 0))
    sums = (np.empty((kt.levels.size, _profile_width(nd_grid.size, ns_grid.size))),
            np.empty((glcg.size, _SHARED * n_screen)))
    data = (power, weights, sw, yw)
    scratch = (pts, gstart, lgroup, ws, qtab, shared, sums)
    out = (z_out, a_out, c_out, conv, nfev_each)
    for bi in range(b_count):
        _one_subset(km, kt, data, masks[bi], clipped, cfg, scratch, out, bi)
    return SubsetSolution(z_out, a_out, c_out, conv, nfev_each.sum())


@njit(cache=True)
def _one_subset(km, kt, data, mask, clipped, cfg, scratch, out, bi):
    """One subset of :func:`subset_search` (row ``bi`` of the outputs ``out``)."""
    codes, nonneg, residual, zlo, zhi = km.codes, km.nonneg, km.residual, km.zlo, km.zhi
    nd_grid, ns_grid, ext_first = km.nd_grid, km.ns_grid, km.ext_rows[0]
    geo, glcg, levels, group = kt.geo, kt.glcg, kt.levels, kt.group
    power, weights, sw_all, yw_all = data
    n_keep, n_data_starts, max_iter, ftol = cfg
    pts, gstart, lgroup, ws, qtab, shared, sums = scratch
    z_out, a_out, c_out, conv, nfev_each = out
    z_row = z_out[bi]
    a_row = a_out[bi]
    p = zlo.size
    pp, ll = _sizes(codes, codes.size)
    fast = codes.size == 0
    count = tl_points(geo, glcg.size, (sw_all, yw_all, weights, power), mask, pts, gstart,
                      lgroup, group)
    _tl_set_yy(pts, gstart, ws[12][0])
    if fast:  # sums of the subset's rows of the batch's tables
        _subset_sums(mask, weights, (group, geo[7]), (qtab, shared), sums)
        counts = np.zeros(levels.size, np.int64)
        for j in range(mask.size):
            if mask[j] and weights[j] > 0.0:
                counts[group[j]] += 1
        prof, ok = _profile_pick(sums[0], counts, nd_grid, ns_grid)
    else:
        prof, ok = _tl_profile(pts, count, lgroup, levels.size, nd_grid, ns_grid)
    data = _profile_starts(levels, prof, ok)
    n_data = data.shape[0]
    n_screen = clipped.shape[0]
    cands = np.empty((n_data + n_screen, p))
    for i in range(n_data):
        for q in range(p):
            v = data[i, q] if q < 5 else ext_first[q - 5]
            cands[i, q] = min(max(v, zlo[q]), zhi[q])
    cands[n_data:] = clipped
    if fast:
        costs = np.empty(cands.shape[0])
        costs[:n_data] = _tl_costs(cands[:n_data], pts, gstart, glcg, nonneg, residual, ws)
        gsums = sums[1]
        gsum = ws[12][0]
        s_g = ws[12][4]
        for i in range(n_screen):
            o = _SHARED * i
            for g in range(glcg.size):
                for c in range(_SHARED):
                    gsum[g, c] = gsums[g, o + c]
                s_g[g] = fexp(clipped[i, 0] * glcg[g])
            costs[n_data + i] = _tl_gram_cost(clipped[i], s_g, pts, gstart, glcg, ws)
        sub = geo
        sw = sw_all
        yw = yw_all
    else:
        idx = np.empty(count, np.int64)
        k = 0
        for j in range(mask.size):
            if mask[j]:
                idx[k] = j
                k += 1
        sub = _take(geo, idx)
        sw = sw_all[idx]
        yw = yw_all[idx]
        costs = _costs(codes, nonneg, residual, cands, (sub, glcg, sw, yw))
    nfev = cands.shape[0]
    order = _stable_order(costs)
    data_order = _stable_order(costs[:n_data])
    n1 = min(n_keep, cands.shape[0])
    n2 = min(n_data_starts, n_data)
    best = math.inf
    zt = np.empty(p)
    at = np.empty(ll)
    done = np.empty(n1 + n2, np.int64)
    for k in range(n1 + n2):
        s = order[k] if k < n1 else data_order[k - n1]
        done[k] = s
        again = False
        for i in range(k):  # the same start again would end at the same point
            again = again or done[i] == s
        if again:
            continue
        if fast:
            c, r, nf = _tl_lm(nonneg, residual, cands[s], (zlo, zhi), (pts, gstart, glcg),
                              (max_iter, ftol, 1e-9), zt, at, ws)
        else:
            c, r, nf = _lm(codes, nonneg, residual, cands[s], (zlo, zhi), (sub, glcg, sw, yw),
                           (max_iter, ftol, 1e-9), zt, at)
        nfev += nf
        if c < best:
            best = c
            z_row[:] = zt
            a_row[:] = at
            conv[bi] = r == STOP_FTOL or r == STOP_XTOL or r == STOP_STUCK
    c_out[bi] = best
    nfev_each[bi] = nfev


@njit(cache=True)
def r2_rows(codes, zs, alphas, geo, glcg, power):
    """R^2 against ``power`` of the model at every row of (zs, alphas) (NaN rows: NaN)."""
    b = zs.shape[0]
    n = power.size
    mean = 0.0
    for j in range(n):
        mean += power[j]
    mean /= n
    ss_tot = 0.0
    for j in range(n):
        ss_tot += (power[j] - mean) ** 2
    out = np.full(b, np.nan)
    pred = np.empty(n)
    fast = codes.size == 0
    if fast:  # the points by blocks, as the search stores them
        pts = np.empty((_TL_ROWS, n))
        gstart = np.empty(glcg.size + 1, np.int64)
        lgroup = np.empty(n, np.int64)
        ones = np.ones(n)
        tl_points(geo, glcg.size, (ones, ones, ones, power), np.ones(n, np.bool_), pts, gstart,
                  lgroup, geo[7])
        vec = np.empty((10, n))
        gbuf = np.zeros(3 * glcg.size + 8)
    for i in range(b):
        ok = True
        for q in range(zs.shape[1]):
            ok = ok and math.isfinite(zs[i, q])
        for q in range(alphas.shape[1]):
            ok = ok and math.isfinite(alphas[i, q])
        if not ok:
            continue
        if fast:
            _tl_broadcast(zs[i], gstart, glcg, vec, 5, gbuf)
            ss = _tl_ss(pts, n, vec, alphas[i, 0], alphas[i, 1])
        else:
            pred = predict(codes, zs[i], alphas[i], geo, glcg)
            ss = 0.0
            for j in range(n):
                ss += (power[j] - pred[j]) ** 2
        out[i] = 1.0 - ss / ss_tot if ss_tot > 0.0 else math.nan
    return out
