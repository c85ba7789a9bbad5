"""Data-driven starts in the compiled kernel (numba): the per-angle-of-incidence decomposition
of the table (:func:`_tl_profile`, as :func:`irreflect.models.lobe_profile`), the starts it
gives (:func:`_profile_starts`, :func:`_own_starts`) and the choice of diverse candidates
(:func:`_diverse`). The numpy side: :mod:`.starts` and the models' ``starts``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .kernel_math import TWO_PI, _stable_order, lexp


# ----------------------------------------------------------------------------- data-driven starts
@njit(cache=True)
def _two_columns(gdd, gss, gds, rd, rs, yy):
    """model._two_column_nnls for one grid node."""
    det = gdd * gss - gds * gds
    good = det > 1e-12 * gdd * gss
    cd = (gss * rd - gds * rs) / det if good else -1.0
    cs = (gdd * rs - gds * rd) / det if good else -1.0
    cost_both = yy - cd * rd - cs * rs if (cd >= 0.0 and cs >= 0.0) else math.inf
    d_only = max(rd, 0.0) / gdd if gdd > 0.0 else 0.0
    s_only = max(rs, 0.0) / gss if gss > 0.0 else 0.0
    cost_d = yy - d_only * rd
    cost_s = yy - s_only * rs
    if cost_d <= cost_s:
        cost_single, c1, c2 = cost_d, d_only, 0.0
    else:
        cost_single, c1, c2 = cost_s, 0.0, s_only
    if cost_both < cost_single:
        cost, c1, c2 = cost_both, cd, cs
    else:
        cost = cost_single
    if not math.isfinite(cost):
        cost = math.inf
    return cost, c1, c2


@njit(cache=True)
def _trend(x, y, valid):
    """model._trend for one row: (intercept, slope); NaN without a valid entry."""
    count = 0.0
    sx = 0.0
    sy = 0.0
    for i in range(x.size):
        if valid[i]:
            count += 1.0
            sx += x[i]
            sy += y[i]
    if count == 0.0:
        return math.nan, math.nan
    xm = sx / count
    ym = sy / count
    sxx = 0.0
    sxy = 0.0
    for i in range(x.size):
        if valid[i]:
            dx = x[i] - xm
            sxx += dx * dx
            sxy += dx * (y[i] - ym)
    slope = sxy / sxx if sxx > 1e-12 else 0.0
    return ym - slope * xm, slope


@njit(cache=True)
def _profile_starts(levels, prof, ok):
    """model.two_lobe_profile_starts for one profile: (5, 5)."""
    g_count = levels.size
    x = np.empty(g_count)
    zero = np.zeros(g_count)
    ln_nd = np.empty(g_count)
    ln_ns = np.empty(g_count)
    ln_as = np.empty(g_count)
    spec = np.empty(g_count, np.bool_)
    spec_share = np.empty(g_count, np.bool_)
    for g in range(g_count):
        x[g] = math.log(math.cos(levels[g]))
        d, s = prof[g, 2], prof[g, 3]
        spec[g] = ok[g] and s > 0.0
        total = d + s
        share = s / total if total > 0.0 else math.nan
        spec_share[g] = spec[g] and share > 0.0
        ln_nd[g] = math.log(prof[g, 0]) if ok[g] else math.nan
        ln_ns[g] = math.log(prof[g, 1]) if ok[g] else math.nan
        ln_as[g] = math.log(share) if share > 0.0 else math.nan
    a_nd, b_nd = _trend(x, ln_nd, ok)
    a_ns, b_ns = _trend(x, ln_ns, spec)
    _, b_as = _trend(x, ln_as, spec_share)
    c_nd, _ = _trend(zero, ln_nd, ok)
    c_ns, _ = _trend(zero, ln_ns, spec)
    fallback = np.array([0.0, 0.0, 0.3, math.log(30.0), 0.0])
    rows = np.empty((5, 5))
    ln4 = math.log(4.0)
    vals = ((b_as, a_nd, b_nd, a_ns, b_ns), (0.0, c_nd, 0.0, c_ns, 0.0),
            (b_as, a_nd, b_nd, a_ns + ln4, b_ns), (b_as, a_nd, b_nd, a_ns - ln4, b_ns),
            (b_as, a_nd, b_nd, c_ns, 0.0))
    for r in range(5):
        row = vals[r]
        for c in range(5):
            v = row[c]
            rows[r, c] = v if math.isfinite(v) else fallback[c]
    return rows


@njit(cache=True)
def _median_specular(prof, ok):
    count = 0
    for g in range(ok.size):
        if ok[g] and prof[g, 3] > 0.0:
            count += 1
    if count == 0:
        return 20.0
    vals = np.empty(count)
    k = 0
    for g in range(ok.size):
        if ok[g] and prof[g, 3] > 0.0:
            vals[k] = prof[g, 1]
            k += 1
    return np.median(vals)


@njit(cache=True)
def _own_starts(prof, ok, levels, jitter, lo, hi, ext_start, extra):
    """The caller's ``extra`` starts, then the model's data-driven starts (profile rows of
    the per-angle decomposition ``prof``/``ok``, fixed rows), random perturbations of the
    first row, clipped and made unique (sorted rows, as numpy.unique(axis=0))."""
    prow = _profile_starts(levels, prof, ok)
    n_est = _median_specular(prof, ok)
    p = lo.size
    n_rows = extra.shape[0] + 9 + ext_start.shape[0] - 1 + jitter.shape[0]
    rows = np.empty((n_rows, p))
    r = 0
    for i in range(extra.shape[0]):
        rows[r] = extra[i]
        r += 1
    for i in range(5):
        rows[r, :5] = prow[i]
        rows[r, 5:] = ext_start[0]
        r += 1
    for ln_ns in (math.log(n_est), math.log(30.0)):
        for v_as in (-2.5, 0.5):
            rows[r, 0] = v_as
            rows[r, 1] = 0.0
            rows[r, 2] = 0.3
            rows[r, 3] = ln_ns
            rows[r, 4] = 0.0
            rows[r, 5:] = ext_start[0]
            r += 1
    for e in range(1, ext_start.shape[0]):  # the first base start with the other new values
        rows[r, :5] = prow[0]
        rows[r, 5:] = ext_start[e]
        r += 1
    first = rows[0].copy()
    for i in range(jitter.shape[0]):
        for q in range(p):
            rows[r, q] = first[q] + jitter[i, q]
        r += 1
    for i in range(n_rows):
        for q in range(p):
            rows[i, q] = min(max(rows[i, q], lo[q]), hi[q])
    return _unique_rows(rows)


@njit(cache=True)
def _row_less(a, b):
    for q in range(a.size):
        if a[q] < b[q]:
            return True
        if a[q] > b[q]:
            return False
    return False


@njit(cache=True)
def _unique_rows(rows):
    m = rows.shape[0]
    order = np.arange(m)
    for i in range(1, m):  # insertion sort: a handful of rows
        k = order[i]
        j = i - 1
        while j >= 0 and _row_less(rows[k], rows[order[j]]):
            order[j + 1] = order[j]
            j -= 1
        order[j + 1] = k
    keep = np.ones(m, np.bool_)
    for i in range(1, m):
        same = True
        for q in range(rows.shape[1]):
            if rows[order[i], q] != rows[order[i - 1], q]:
                same = False
                break
        keep[i] = not same
    out = np.empty((keep.sum(), rows.shape[1]))
    k = 0
    for i in range(m):
        if keep[i]:
            out[k] = rows[order[i]]
            k += 1
    return out


@njit(cache=True)
def _diverse(cands, costs, k, lo, hi, min_distance):
    """fitting._diverse_best: indices of up to k low-cost candidates apart from each other."""
    p = lo.size
    width = np.empty(p)
    for q in range(p):
        width[q] = hi[q] - lo[q] if hi[q] > lo[q] else 1.0
    chosen = np.empty(k, np.int64)
    count = 0
    for i in _stable_order(costs):
        if count == k or not math.isfinite(costs[i]):
            break
        ok = True
        for c in range(count):
            j = chosen[c]
            d = 0.0
            for q in range(p):
                u = (cands[i, q] - lo[q]) / width[q] - (cands[j, q] - lo[q]) / width[q]
                d += u * u
            if math.sqrt(d / p) < min_distance:
                ok = False
                break
        if ok:
            chosen[count] = i
            count += 1
    return chosen[:count]


@njit(cache=True, error_model="numpy")
def _tl_profile(pts, m, lgroup, n_levels, nd_grid, ns_grid):
    """:func:`_profile` of the points ``pts[:, :m]`` (weights and power from its rows, the
    level of each in ``lgroup``): per level (diffuse index, specular index, diffuse,
    specular) and ok. The products of every diffuse and specular grid lobe are summed
    level by level, point by point (the sums of :func:`_profile_add`, in its order)."""
    d_count = nd_grid.size
    s_count = ns_grid.size
    ldt, lst = _profile_lobes(pts, m, nd_grid, ns_grid)
    sums = np.zeros((n_levels, _profile_width(d_count, s_count)))
    counts = np.zeros(n_levels, np.int64)
    gdd = np.empty(d_count)
    rd = np.empty(d_count)
    gss = np.empty(s_count)
    rs = np.empty(s_count)
    gds = np.empty((d_count, s_count))
    o_rd = 1 + d_count
    o_ss = 1 + 2 * d_count
    o_rs = o_ss + s_count
    o_ds = o_rs + s_count
    for gi in range(n_levels):
        yy = 0.0
        gdd[:] = 0.0
        rd[:] = 0.0
        gss[:] = 0.0
        rs[:] = 0.0
        gds[:, :] = 0.0
        count = 0
        for k in range(m):
            if lgroup[k] != gi or not pts[7, k] > 0.0:
                continue
            count += 1
            wc = pts[7, k]
            yc = pts[8, k]
            yy += wc * yc * yc
            for a in range(d_count):
                v = wc * ldt[k, a]
                gdd[a] += v * ldt[k, a]
                rd[a] += v * yc
            for a in range(s_count):
                v = wc * lst[k, a]
                gss[a] += v * lst[k, a]
                rs[a] += v * yc
            for a in range(d_count):
                v = wc * ldt[k, a]
                for b in range(s_count):
                    gds[a, b] += v * lst[k, b]
        counts[gi] = count
        sums[gi, 0] = yy
        for a in range(d_count):
            sums[gi, 1 + a] = gdd[a]
            sums[gi, o_rd + a] = rd[a]
            for b in range(s_count):
                sums[gi, o_ds + a * s_count + b] = gds[a, b]
        for a in range(s_count):
            sums[gi, o_ss + a] = gss[a]
            sums[gi, o_rs + a] = rs[a]
    return _profile_pick(sums, counts, nd_grid, ns_grid)


@njit(cache=True)
def _profile_width(d_count, s_count):
    """Products per point of the per-angle decomposition: y'y, then per diffuse grid index
    l_d'l_d and l_d'y, per specular one l_s'l_s and l_s'y, then every l_d'l_s."""
    return 1 + 2 * d_count + 2 * s_count + d_count * s_count


@njit(cache=True, error_model="numpy")
def _profile_lobes(pts, m, nd_grid, ns_grid):
    """The grid lobes of the per-angle decomposition at the points ``pts[:, :m]``: (m, D)
    diffuse and (m, S) specular (the exponentials in loops over points, which vectorise;
    stored point by point for the sums)."""
    d_count = nd_grid.size
    s_count = ns_grid.size
    ld = np.empty((d_count, m))
    ls = np.empty((s_count, m))
    for a in range(d_count):
        n = nd_grid[a]
        c = (n + 1.0) / TWO_PI
        for k in range(m):
            ld[a, k] = c * (lexp(n * pts[0, k]) * pts[1, k])
    for a in range(s_count):
        n = ns_grid[a]
        c = (n + 1.0) / TWO_PI
        for k in range(m):
            ls[a, k] = c * (lexp(n * pts[2, k]) * pts[3, k])
    return ld.T.copy(), ls.T.copy()


@njit(cache=True, error_model="numpy", inline="always")
def _profile_add(ldt, lst, k, wc, yc, sums, gi):
    """Add point ``k``'s products (weight ``wc``, power ``yc``; layout: _profile_width) to
    ``sums[gi]``."""
    d_count = ldt.shape[1]
    s_count = lst.shape[1]
    o_rd = 1 + d_count
    o_ss = 1 + 2 * d_count
    o_rs = o_ss + s_count
    o_ds = o_rs + s_count
    sums[gi, 0] += wc * yc * yc
    for a in range(d_count):
        v = wc * ldt[k, a]
        sums[gi, 1 + a] += v * ldt[k, a]
        sums[gi, o_rd + a] += v * yc
    for a in range(s_count):
        v = wc * lst[k, a]
        sums[gi, o_ss + a] += v * lst[k, a]
        sums[gi, o_rs + a] += v * yc
    for a in range(d_count):
        v = wc * ldt[k, a]
        o = o_ds + a * s_count
        for s in range(s_count):
            sums[gi, o + s] += v * lst[k, s]


@njit(cache=True, error_model="numpy")
def _profile_pick(sums, counts, nd_grid, ns_grid):
    """The per-angle decomposition from each level's summed products (_profile_width):
    per level the grid node of least cost (_two_columns' numbers: the one-column fits
    once per row and column of the grid, the coefficients kept for the best node only),
    levels of fewer than 3 points not ok. Returns (prof (levels, 4), ok)."""
    n_levels = counts.size
    d_count = nd_grid.size
    s_count = ns_grid.size
    o_rd = 1 + d_count
    o_ss = 1 + 2 * d_count
    o_rs = o_ss + s_count
    o_ds = o_rs + s_count
    out = np.full((n_levels, 4), np.nan)
    ok = np.zeros(n_levels, np.bool_)
    cost_s = np.empty(s_count)
    costs = np.empty(s_count)
    for gi in range(n_levels):
        if counts[gi] < 3:
            continue
        yy = sums[gi, 0]
        for s in range(s_count):
            gss = sums[gi, o_ss + s]
            rs = sums[gi, o_rs + s]
            so = max(rs, 0.0) / gss if gss > 0.0 else 0.0
            cost_s[s] = yy - so * rs
        best = math.inf
        bi = 0
        bk = 0
        for a in range(d_count):
            gdd = sums[gi, 1 + a]
            rd = sums[gi, o_rd + a]
            d_only = max(rd, 0.0) / gdd if gdd > 0.0 else 0.0
            cost_d = yy - d_only * rd
            o = o_ds + a * s_count
            for s in range(s_count):
                gss = sums[gi, o_ss + s]
                gds = sums[gi, o + s]
                rs = sums[gi, o_rs + s]
                det = gdd * gss - gds * gds
                good = det > 1e-12 * gdd * gss
                cd = (gss * rd - gds * rs) / det if good else -1.0
                cs = (gdd * rs - gds * rd) / det if good else -1.0
                both = cd >= 0.0 and cs >= 0.0
                cost_both = yy - cd * rd - cs * rs if both else math.inf
                cost_single = min(cost_d, cost_s[s])
                cost = cost_both if cost_both < cost_single else cost_single
                costs[s] = cost if math.isfinite(cost) else math.inf
            for s in range(s_count):
                if costs[s] < best:
                    best = costs[s]
                    bi = a
                    bk = s
        bcd = 0.0
        bcs = 0.0
        if best < math.inf:  # the best node's coefficients (_two_columns)
            cost, bcd, bcs = _two_columns(sums[gi, 1 + bi], sums[gi, o_ss + bk],
                                          sums[gi, o_ds + bi * s_count + bk],
                                          sums[gi, o_rd + bi], sums[gi, o_rs + bk], yy)
        ok[gi] = True
        out[gi, 0] = nd_grid[bi]
        out[gi, 1] = ns_grid[bk]
        out[gi, 2] = bcd
        out[gi, 3] = bcs
    return out, ok


@njit(cache=True, error_model="numpy")
def _profile_table(geo, weights, power, nd_grid, ns_grid):
    """Every point's products of the per-angle decomposition (:func:`_profile_add`; table
    order, weight and power of the table): a subset's per-level sums are then sums of
    its points' rows, without an exponential."""
    n = power.size
    pts = np.empty((9, n))
    for j in range(n):
        pts[0, j] = geo[3][j]
        pts[1, j] = 1.0 if geo[4][j] else 0.0
        pts[2, j] = geo[5][j]
        pts[3, j] = 1.0 if geo[6][j] else 0.0
    ldt, lst = _profile_lobes(pts, n, nd_grid, ns_grid)
    out = np.zeros((n, _profile_width(nd_grid.size, ns_grid.size)))
    for j in range(n):
        _profile_add(ldt, lst, j, weights[j], power[j], out, j)
    return out
