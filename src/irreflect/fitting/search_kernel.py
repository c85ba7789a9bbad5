"""The global search in the compiled kernel (numba): the steps of :mod:`.driver` on a
context ``ctx = (model, table, work, draws, stop)``, and :func:`search`, the driver's
:func:`~.driver.run_search` bound to these steps and compiled, so that a search is one
call. The plain two-lobe model takes the fast path (:mod:`.fast_kernel`), its extensions
the generic one (:mod:`.local_kernel`).

``model``: :class:`~.kernel_types.KModel`; ``table``: :class:`~.kernel_types.KTable`;
``work``: :func:`work_for`; ``draws``: (the jitter of the first start, the caller's
extra starts, the screening candidates, the hops (rounds, hops, P), the hops' width);
``stop``: (max_iter, ftol, xtol).
"""

from __future__ import annotations

import math
import types

import numpy as np
from numba import njit

from .driver import run_search
from .fast_kernel import (
    _TL_ROWS,
    _tl_lm,
    _tl_scan_costs,
    _tl_screen_costs,
    _tl_set_yy,
    tl_points,
    tl_work,
)
from .finish_kernel import tl_finish
from .kernel_math import DEG, STOP_MAXITER, STOP_NONFINITE, STOP_STUCK, pairwise_sum
from .kernel_types import Finish, KModel, KTable, Solution, Work
from .local_kernel import _costs, _lm, _scan_candidates
from .model_kernel import _sizes, kernel_geometry
from .starts_kernel import _diverse, _own_starts, _tl_profile


# Every entry point takes its structures as plain tuples (numba's dispatcher types a plain
# tuple of arrays in C, a namedtuple several times slower in Python) and names them first.
def work_for(kt, power, weights):
    """The scratch of one search of a table (numpy, allocated once per fit) as the kernel
    takes it: (the table as :func:`_lm` reads it, the power, the points by angle of
    incidence, the blocks' starts, each point's level, the fast path's scratch)."""
    n, n_groups = power.size, kt[1].size
    sw = np.sqrt(weights)
    ws = tl_work.py_func(n, n_groups)
    return ((tuple(kt[0]), kt[1], sw, sw * power), power, np.empty((_TL_ROWS, n)),
            np.empty(n_groups + 1, np.int64), np.empty(n, np.int64),
            tuple(ws[:12]) + (tuple(ws[12]),))


@njit(cache=True)
def candidates(ctx):
    """The table's points by angle of incidence into ``work``; the own starts (the
    caller's extra rows first, then the per-angle decomposition's, the jittered ones),
    clipped and unique, then the screening candidates. Returns (rows, how many own)."""
    km, kt, work = KModel(*ctx[0]), KTable(*ctx[1]), Work(*ctx[2])
    jitter, extra, screen = ctx[3][0], ctx[3][1], ctx[3][2]
    _, sw, yw, power = work.table[1], work.table[2], work.table[3], work.power
    n = power.size
    pts, gstart, lgroup = work.pts, work.gstart, work.lgroup
    tl_points(kt.geo, kt.glcg.size, (sw, yw, np.ones(n), power), np.ones(n, np.bool_), pts,
              gstart, lgroup, kt.group)
    _tl_set_yy(pts, gstart, work.ws[12][0])
    prof, ok = _tl_profile(pts, n, lgroup, kt.levels.size, km.nd_grid, km.ns_grid)
    own = _own_starts(prof, ok, kt.levels, jitter, km.zlo, km.zhi, km.ext_rows, extra)
    return np.vstack((own, screen)), own.shape[0]


@njit(cache=True)
def score(ctx, rows):
    """The projected cost of every candidate row (no derivatives)."""
    km, work = KModel(*ctx[0]), Work(*ctx[2])
    if km.codes.size == 0:
        return _tl_screen_costs(rows, work.pts, work.gstart, work.table[1], km.nonneg,
                                km.residual, work.ws)
    return _costs(km.codes, km.nonneg, km.residual, rows, work.table)


@njit(cache=True)
def pick(ctx, rows, costs, k, min_distance):
    """Up to ``k`` low-cost rows at least ``min_distance`` apart in the screening box."""
    km = KModel(*ctx[0])
    return _diverse(rows, costs, k, km.lo, km.hi, min_distance)


@njit(cache=True)
def solve(ctx, starts):
    """Levenberg-Marquardt from every row of ``starts``: the best end point (the first of
    equal costs; cost inf when none is finite) and the evaluations of all."""
    km, work, stop = KModel(*ctx[0]), Work(*ctx[2]), ctx[4]
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
def scan(ctx, z):
    """A refinement round's global scans through ``z``: every coordinate swept along its
    axis (``km.axes``) with the others held. Returns each sweep's lowest point and its
    cost (the first of equal costs), ``(P, P)`` and ``(P,)``, and the points scanned."""
    km, work = KModel(*ctx[0]), Work(*ctx[2])
    cands = _scan_candidates(z, km.axes)
    if km.codes.size == 0:
        costs = _tl_scan_costs(z, km.axes, work.pts, work.gstart, work.table[1], km.nonneg,
                               km.residual, work.ws)
    else:
        costs = _costs(km.codes, km.nonneg, km.residual, cands, work.table)
    p, n_axis = km.axes.shape
    rows = np.empty((p, p))
    best = np.empty(p)
    for q in range(p):
        j = q * n_axis + np.argmin(costs[q * n_axis:(q + 1) * n_axis])
        rows[q] = cands[j]
        best[q] = costs[j]
    return rows, best, p * n_axis


@njit(cache=True)
def hops(ctx, rnd, z):
    """The basin hops of round ``rnd`` around ``z`` (not yet clipped)."""
    jumps, width = ctx[3][3], ctx[3][4]
    out = np.empty((jumps.shape[1], z.size))
    for h in range(jumps.shape[1]):
        for q in range(z.size):
            out[h, q] = z[q] + jumps[rnd, h, q] * width[q]
    return out


@njit(cache=True)
def clip(ctx, rows):
    """``rows`` within the model's bounds."""
    km = KModel(*ctx[0])
    out = np.empty_like(rows)
    for i in range(rows.shape[0]):
        for q in range(rows.shape[1]):
            out[i, q] = min(max(rows[i, q], km.zlo[q]), km.zhi[q])
    return out


#: The driver (:func:`irreflect.fitting.driver.run_search`) on these steps, compiled:
#: ``search(ctx, n_data_starts, n_keep, max_rounds) -> (Solution, n_starts, n_evals)``.
search = njit(cache=True)(types.FunctionType(run_search.__code__, globals(), "run_search"))



@njit(cache=True)
def _plain_work(kt, power, weights):
    """:func:`work_for` in the kernel (the same arrays, the same tuple types)."""
    n, n_groups = power.size, kt[1].size
    sw = np.sqrt(weights)
    ws = tl_work(n, n_groups)
    cap = ws.cap
    # one structure (Work, as a plain tuple: the type the search's steps were compiled for)
    work = ((kt[0], kt[1], sw, sw * power), power, np.empty((_TL_ROWS, n)),
            np.empty(n_groups + 1, np.int64), np.empty(n, np.int64),
            (ws.vec, ws.lin, ws.coef, ws.grad, ws.hess, ws.a, ws.rhs, ws.step, ws.z, ws.zt,
             ws.pinned, ws.gbuf, (cap.sums, cap.tau, cap.order, cap.lin, cap.s_g)))
    return work


# numba keys this module's on-disk cache on this file alone, and fit_plain's cached code
# holds tl_finish: after a change to finish_kernel.py, change this file too (a checkout's
# cache is otherwise stale; a new install builds afresh). Last: the difference steps of
# the linear coefficients floored relative to their scale (stop 48).
@njit(cache=True)
def fit_plain(model, table, draws, config):
    """A fit of the plain two-lobe model in one call from the table as it is stored, as
    main's tl_fit was: angles to radians, weights ``1 / sigma^2`` (1 without sigma), the
    power's scale (its weighted root mean square, numpy's ``sqrt(mean(w p p))`` to the
    bit), the table's kernel geometry (:func:`~.model_kernel.kernel_geometry`), the
    search's scratch (:func:`work_for`), :func:`search` on the power divided by its scale,
    and, when the search met a tolerance (nothing for :func:`~.finish._conclude` to
    polish), the finish (:func:`~.finish_kernel.tl_finish`) of its end point with the
    standard errors and residuals fit() reports. ``model``: the model's
    :class:`~.kernel_types.KModel` as a tuple; ``table``: (gamma_deg, theta_deg, power,
    sigma; an empty sigma: unweighted); ``draws`` as in the context; ``config``:
    ((n_data_starts, n_keep, max_rounds), (max_iter, ftol, xtol), n_params). The table's
    checks are fit()'s (:func:`~.results.check_fit_data`), before this call. Returns
    (Solution in the scaled units, (n_starts, n_evals, scale), (finished, Finish, standard
    errors, residuals; placeholders when not finished), the exact angles of incidence)."""
    gamma_deg, theta_deg, power, sigma = table
    sizes, stop, n_params = config
    n = power.size
    weights = np.ones(n)
    if sigma.size:
        for j in range(n):
            weights[j] = 1.0 / sigma[j] ** 2
    scale = math.sqrt(pairwise_sum(weights * power * power, 0, n) / n)
    if not (math.isfinite(scale) and scale > 0.0):
        scale = 1.0
    kg = kernel_geometry(gamma_deg * DEG, theta_deg * DEG)
    g = kg.geo
    kt = ((g.gamma, g.theta, g.lcg, g.lct, g.pt, g.lcp, g.pp, g.group), kg.glcg, kg.levels,
          kg.group, kg.exact)
    ctx = (model, kt, _plain_work(kt, power / scale, weights), draws, stop)
    best, counts, done, fin = search_finish(
        ctx, sizes, (weights, power, sigma.size > 0, scale, n_params))
    k = fin.values.size
    stderr = np.empty(k)
    for q in range(k):  # numpy.sqrt(numpy.clip(numpy.diag(cov), 0, None)), NaN kept
        v = fin.covariance[q, q]
        stderr[q] = math.sqrt(v) if v > 0.0 else (0.0 if v <= 0.0 else v)
    return best, (counts[0], counts[1], scale), (done, fin, stderr, power - fin.fitted), \
        kg.exact


@njit(cache=True)
def search_finish(ctx, sizes, fin_in):
    """:func:`search` of the plain two-lobe model, then, when it met a tolerance (nothing
    for :func:`~.finish._conclude` to polish), the fit's finish
    (:func:`~.finish_kernel.tl_finish`) of its end point in the same call, as fit() would
    compute it after. ``sizes``: (n_data_starts, n_keep, max_rounds); ``fin_in``: the
    table's own weights and power, whether sigma is absolute, the power's scale and the
    model's parameter count. Returns (Solution, (n_starts, n_evals), finished, Finish);
    the Finish is a placeholder when not finished."""
    best, n_starts, n_evals = search(ctx, sizes[0], sizes[1], sizes[2])
    weights, power, absolute_sigma, scale, n_params = fin_in
    kt = ctx[1]
    done = (math.isfinite(best.cost) and best.reason != STOP_STUCK
            and best.reason != STOP_MAXITER)
    if done:
        fin = tl_finish(best.z, best.alpha * scale, kt[0], kt[1], weights, power,
                        absolute_sigma, best.cost * scale * scale, n_params)
    else:
        k = best.z.size + best.alpha.size
        fin = Finish(np.full(k, np.nan), False, np.full(power.size, np.nan), np.nan, np.nan,
                     np.nan, np.full((k, k), np.nan), np.zeros(k, np.bool_))
    return best, (n_starts, n_evals), done, fin
