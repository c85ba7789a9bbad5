"""The linear step in the compiled kernel (numba): the optimal linear coefficients of a basis
by (non-negative) least squares on its Gram matrix, and over the saturation patterns of a
specular share that saturates (:func:`_capped_solve`); :func:`_evaluate` gives a start's
cost, residuals and derivatives for the generic path. The numpy side: :mod:`.linear`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .kernel_math import EXTREME, RIDGE, TWO_PI, _insert_by_threshold, fexp
from .kernel_types import CappedWork, GenScratch, GenState
from .model_kernel import _group_values, _point


# ----------------------------------------------------------------------------- projection
@njit(cache=True)
def _inverse(g, free, scale, out):
    """Inverse of the free block of the Gram matrix ``g`` (ridge ``RIDGE * scale`` on the
    diagonal, 1 on fixed columns), zero outside it (as fitting._solve_linear)."""
    ll = g.shape[0]
    if ll == 1:
        out[0, 0] = 1.0 / (g[0, 0] + RIDGE * scale[0]) if free[0] else 0.0
        return
    if ll == 2:
        a00 = g[0, 0] + RIDGE * scale[0] if free[0] else 1.0
        a11 = g[1, 1] + RIDGE * scale[1] if free[1] else 1.0
        a01 = g[0, 1] if (free[0] and free[1]) else 0.0
        det = a00 * a11 - a01 * a01
        out[0, 0] = a11 / det if free[0] else 0.0
        out[1, 1] = a00 / det if free[1] else 0.0
        off = -a01 / det if (free[0] and free[1]) else 0.0
        out[0, 1] = off
        out[1, 0] = off
        return
    a = np.empty((ll, ll))
    for i in range(ll):
        for j in range(ll):
            if free[i] and free[j]:
                a[i, j] = g[i, j]
            else:
                a[i, j] = 0.0
        a[i, i] += RIDGE * scale[i] if free[i] else 1.0
    out[:, :] = np.linalg.inv(a)
    for i in range(ll):
        for j in range(ll):
            if not (free[i] and free[j]):
                out[i, j] = 0.0


@njit(cache=True)
def _solve_small(a, b, x):
    """Solve the small system ``a x = b`` by Gaussian elimination with partial pivoting
    (``a`` and ``b`` are overwritten); a singular pivot leaves that component 0."""
    p = b.size
    for k in range(p):
        piv = k
        big = abs(a[k, k])
        for i in range(k + 1, p):
            if abs(a[i, k]) > big:
                big = abs(a[i, k])
                piv = i
        if piv != k:
            for j in range(p):
                tmp = a[k, j]
                a[k, j] = a[piv, j]
                a[piv, j] = tmp
            tmp = b[k]
            b[k] = b[piv]
            b[piv] = tmp
        if a[k, k] == 0.0:
            continue
        for i in range(k + 1, p):
            f = a[i, k] / a[k, k]
            if f != 0.0:
                for j in range(k, p):
                    a[i, j] -= f * a[k, j]
                b[i] -= f * b[k]
    for k in range(p - 1, -1, -1):
        acc = b[k]
        for j in range(k + 1, p):
            acc -= a[k, j] * x[j]
        x[k] = acc / a[k, k] if a[k, k] != 0.0 else 0.0


@njit(cache=True)
def _solve_gram(g, rhs, nonneg, residual, alpha, free, inv, scale):
    """:func:`_solve_linear` from the Gram matrix ``g`` (symmetric) and ``rhs`` (``scale``:
    scratch of length L)."""
    ll = rhs.size
    for i in range(ll):
        scale[i] = max(g[i, i], 1e-300)
        free[i] = g[i, i] > 0.0
    _inverse(g, free, scale, inv)
    _apply(inv, rhs, free, alpha)
    for _ in range(ll):
        worst = -1
        worst_value = 0.0
        total = 0.0
        largest = -1
        largest_value = -1.0
        for i in range(ll):
            if free[i]:
                a = alpha[i]
                if nonneg[i] and a < 0.0:
                    v = a * math.sqrt(scale[i])
                    if worst < 0 or v < worst_value:
                        worst = i
                        worst_value = v
                m = abs(a)
                total += m
                if m > largest_value:
                    largest = i
                    largest_value = m
        drop = worst
        if drop < 0 and residual >= 0 and free[residual]:
            r = abs(alpha[residual])
            if r > 0.0 and r < total / EXTREME:
                drop = largest
        if drop < 0:
            break
        free[drop] = False
        _inverse(g, free, scale, inv)
        _apply(inv, rhs, free, alpha)
    for i in range(ll):
        if not free[i]:
            alpha[i] = 0.0


@njit(cache=True)
def _apply(inv, rhs, free, alpha):
    ll = rhs.size
    for i in range(ll):
        acc = 0.0
        for k in range(ll):
            if free[k]:
                acc += inv[i, k] * rhs[k]
        alpha[i] = acc


@njit(cache=True)
def _evaluate(codes, nonneg, residual, z, table, deriv, st, sc):
    """Basis (weighted, fixed columns zeroed), linear coefficients, residuals and cost at
    ``z``. ``table``: (geometry, log cos of the angles of incidence, sqrt(weights),
    weighted power); ``st``: the evaluation's state (:func:`_gen_state`), written;
    ``sc``: scratch (:func:`_gen_scratch`). The linear step is the saturating share's
    (:func:`_capped_solve`): the state's ``alpha`` are the effective basis' coefficients
    (for the Jacobian), its ``alpha_true`` the model's."""
    geo, glcg, sw, yw = table
    bw, dbw, alpha, free, inv, resid, alpha_true, share = st
    b, db, bp, dbp, gval, sums, cw = sc
    n, ll = bw.shape
    p = z.size
    _group_values(z, gval[0], gval[1])
    if codes.size == 0:
        _two_lobe_fill(geo, gval[1], sw, deriv, bw, dbw)
    else:
        for j in range(n):
            _point(codes, z, j, geo, gval[1], deriv, b, db, bp, dbp)
            w = sw[j]
            for col in range(ll):
                bw[j, col] = b[col] * w
                if deriv:
                    for q in range(p):
                        dbw[j, col, q] = db[col, q]
    tau_g = cw[9]
    for g in range(glcg.size):
        sg = gval[1][g, 0]
        tau_g[g] = 1.0 / sg if sg > 1.0 else math.inf
    yy = 0.0
    for j in range(n):
        yy += yw[j] * yw[j]
    _group_grams(bw, yw, geo[7], tau_g, sums)
    cost, lower, tau = _capped_solve(sums, tau_g, yy, nonneg, residual, cw,
                                     (alpha, alpha_true, free, inv))
    share[0] = lower
    share[1] = tau
    if lower > 0.0 or tau >= 0.0:
        _saturate_basis(z, geo, glcg, sw, tau_g, lower, tau, deriv, bw, dbw)
    cost = 0.0
    for j in range(n):
        acc = yw[j]
        for col in range(ll):
            acc -= bw[j, col] * alpha[col]
        resid[j] = acc
        cost += acc * acc
    cost *= 0.5
    if not math.isfinite(cost):
        cost = math.inf
    for col in range(ll):
        if not free[col]:
            for j in range(n):
                bw[j, col] = 0.0
    return cost


@njit(cache=True)
def _gen_state(n, ll, p):
    """One evaluation's state of the generic path: weighted basis (n, L), its derivative
    (n, L, P), the effective coefficients, free columns, the free block's inverse,
    residuals, the model's coefficients, and (the saturation level, the threshold or -1)."""
    return GenState(np.empty((n, ll)), np.empty((n, ll, p)), np.empty(ll),
                    np.empty(ll, np.bool_), np.empty((ll, ll)), np.empty(n), np.empty(ll),
                    np.zeros(2))


@njit(cache=True)
def _gen_scratch(ll, p, n_groups, glcg):
    """Scratch of the generic path's evaluations: one point's basis and derivative (and
    their copies for the central differences), the per-angle values, the per-angle Gram
    sums (:func:`_group_grams`) and the linear step's workspace (:func:`_capped_work`)."""
    gval = (glcg, np.empty((n_groups, 3)))
    return GenScratch(np.empty(ll), np.empty((ll, p)), np.empty(ll), np.empty((ll, p)), gval,
                      _group_sums(n_groups, ll), _capped_work(n_groups, ll))


@njit(cache=True)
def _group_sums(n_groups, ll):
    """Per angle of incidence: the Gram matrix and right-hand side of the basis as it is,
    and with the share's two columns saturated (see :func:`_group_grams`)."""
    return (np.zeros((n_groups, ll, ll)), np.zeros((n_groups, ll)),
            np.zeros((n_groups, ll, ll)), np.zeros((n_groups, ll)))


@njit(cache=True)
def _capped_work(n_groups, ll):
    """Workspace of :func:`_capped_solve`: a Gram matrix and right-hand side being summed,
    a transformed pair, the candidate's coefficients, free columns, inverse, column
    scales, the saturable angles in threshold order, the thresholds (set by the caller)."""
    return CappedWork(np.empty((ll, ll)), np.empty(ll), np.empty((ll, ll)), np.empty(ll),
                      np.empty(ll), np.empty(ll, np.bool_), np.empty((ll, ll)), np.empty(ll),
                      np.empty(n_groups, np.int64), np.empty(n_groups))


@njit(cache=True, error_model="numpy")
def _group_grams(bw, yw, group, tau_g, sums):
    """Per angle of incidence ``g``: ``gu[g] = B'B`` and ``ru[g] = B'y`` of the weighted
    basis rows at that angle, and ``gs``, ``rs`` the same with the share's two columns
    replaced by the saturated column ``b0 + (b1 - b0) / s`` (``s = 1 / tau_g``; the
    curve where the share is 1, see models.base.saturated_column); angles that cannot
    saturate (``tau_g`` infinite) keep ``gs = gu``."""
    gu, ru, gs, rs = sums
    n, ll = bw.shape
    gu[:] = 0.0
    ru[:] = 0.0
    gs[:] = 0.0
    rs[:] = 0.0
    for j in range(n):
        g = group[j]
        y = yw[j]
        t = tau_g[g]
        sat = bw[j, 0] + (bw[j, 1] - bw[j, 0]) * t if t < math.inf else 0.0
        for a in range(ll):
            ba = bw[j, a]
            sa = ba if (a >= 2 or t == math.inf) else sat
            ru[g, a] += ba * y
            rs[g, a] += sa * y
            for c in range(a, ll):
                bc = bw[j, c]
                scv = bc if (c >= 2 or t == math.inf) else sat
                gu[g, a, c] += ba * bc
                gs[g, a, c] += sa * scv
    for g in range(gu.shape[0]):
        for a in range(ll):
            for c in range(a + 1, ll):
                gu[g, c, a] = gu[g, a, c]
                gs[g, c, a] = gs[g, a, c]


@njit(cache=True)
def _gram_candidate(g, r, yy, nonneg, residual, cw):
    """Non-negative least squares from a Gram matrix (:func:`_solve_gram`, into the
    workspace's coefficients, free columns and inverse); returns its cost
    ``0.5 (y'y - 2 a'r + a'G a)``."""
    alpha, free, inv, scale = cw[4], cw[5], cw[6], cw[7]
    _solve_gram(g, r, nonneg, residual, alpha, free, inv, scale)
    ll = r.size
    cost = yy
    for i in range(ll):
        cost -= 2.0 * alpha[i] * r[i]
        for k in range(ll):
            cost += alpha[i] * g[i, k] * alpha[k]
    cost *= 0.5
    return cost if math.isfinite(cost) else math.inf


@njit(cache=True)
def _keep_candidate(cw, out, tau):
    """Copy the workspace's candidate into ``out`` (effective coefficients, the model's
    coefficients, free columns, inverse); at a threshold ``tau`` (>= 0) the one column
    ``(1 - tau) b0 + tau b1`` carries ``K``: the model's are ``(K (1 - tau), K tau)``."""
    alpha, free, inv = cw[4], cw[5], cw[6]
    a_eff, a_true, f_eff, i_eff = out
    a_eff[:] = alpha
    a_true[:] = alpha
    f_eff[:] = free
    i_eff[:, :] = inv
    if tau >= 0.0:
        a_true[0] = alpha[0] * (1.0 - tau)
        a_true[1] = alpha[0] * tau


@njit(cache=True, error_model="numpy")
def _capped_solve(sums, tau_g, yy, nonneg, residual, cw, out):
    """The linear step of a model whose specular share saturates (fitting._linear_step,
    here from per-angle Gram sums): between consecutive thresholds ``tau`` (``1 /
    cos^v_as(gamma)`` of the angles where that exceeds 1) the model is linear in ``(K (1 -
    u), K u)`` with the angles past the interval saturated; each interval's
    non-negative least squares is kept when its ``u`` lies in it, each threshold's
    (``u = tau``, one column) always; the lowest cost wins. ``out``: (effective
    coefficients, the model's, free columns, inverse), written. Returns (cost from the
    Gram sums, the saturation level: angles with ``tau_g <= level`` saturate, the
    threshold of a solution on one or -1)."""
    gu, ru, gs, rs = sums
    gk, rk, gt, rt, alpha, order = cw[0], cw[1], cw[2], cw[3], cw[4], cw[8]
    n_groups, ll = ru.shape
    gk[:, :] = 0.0
    rk[:] = 0.0
    count = 0
    for g in range(n_groups):
        for a in range(ll):
            rk[a] += ru[g, a]
            for c in range(ll):
                gk[a, c] += gu[g, a, c]
        if tau_g[g] < 1.0:
            count = _insert_by_threshold(order, count, tau_g, g)
    best = math.inf
    best_lower = 0.0
    best_tau = -1.0
    lower = 0.0
    i = 0
    while True:
        upper = tau_g[order[i]] if i < count else 1.0
        cost = _gram_candidate(gk, rk, yy, nonneg, residual, cw)
        k = alpha[0] + alpha[1]
        u = alpha[1] / k if k > 0.0 else lower
        if cost < best and u >= lower and u <= upper:
            best = cost
            best_lower = lower
            best_tau = -1.0
            _keep_candidate(cw, out, -1.0)
        if i >= count:
            break
        t = upper  # past it, every angle with this threshold saturates
        while i < count and tau_g[order[i]] == t:
            g = order[i]
            for a in range(ll):
                rk[a] += rs[g, a] - ru[g, a]
                for c in range(ll):
                    gk[a, c] += gs[g, a, c] - gu[g, a, c]
            i += 1
        lower = t
        # the threshold itself: u = t, the one column (1 - t) b0 + t b1
        for a in range(ll):
            for c in range(ll):
                gt[a, c] = gk[a, c]
            rt[a] = rk[a]
        gt[0, 0] = ((1.0 - t) * (1.0 - t) * gk[0, 0] + 2.0 * t * (1.0 - t) * gk[0, 1]
                    + t * t * gk[1, 1])
        rt[0] = (1.0 - t) * rk[0] + t * rk[1]
        for c in range(2, ll):
            gt[0, c] = (1.0 - t) * gk[0, c] + t * gk[1, c]
            gt[c, 0] = gt[0, c]
        for c in range(ll):
            gt[1, c] = 0.0
            gt[c, 1] = 0.0
        rt[1] = 0.0
        cost = _gram_candidate(gt, rt, yy, nonneg, residual, cw)
        if cost < best:
            best = cost
            best_lower = t
            best_tau = t
            _keep_candidate(cw, out, t)
    return best, best_lower, best_tau


@njit(cache=True, error_model="numpy")
def _saturate_basis(z, geo, glcg, sw, tau_g, lower, tau, deriv, bw, dbw):
    """The effective basis the linear step chose (:func:`_capped_solve`): rows at angles
    with ``tau_g <= lower`` take the saturated column in both share columns (and its
    derivative); at a threshold ``tau >= 0`` column 0 becomes ``(1 - tau) b0 + tau b1``
    (column 1 is then fixed at 0), whose derivative along ``v_as`` has the threshold's
    own: ``d tau / d v_as = -tau ln cos gamma* = tau ln(tau) / v_as``."""
    n, ll = bw.shape
    p = z.size
    group = geo[7]
    lcg_all = geo[2]
    dtau = tau * math.log(tau) / z[0] if tau > 0.0 else 0.0
    for j in range(n):
        t = tau_g[group[j]]
        w = sw[j]
        b0 = bw[j, 0]
        b1 = bw[j, 1]
        if t <= lower:
            sat = b0 + (b1 - b0) * t
            if deriv:
                inv_w = 1.0 / w if w > 0.0 else 0.0
                for q in range(p):
                    d = dbw[j, 0, q] + (dbw[j, 1, q] - dbw[j, 0, q]) * t
                    dbw[j, 0, q] = d
                    dbw[j, 1, q] = d
                dbw[j, 0, 0] -= (b1 - b0) * inv_w * t * lcg_all[j]
                dbw[j, 1, 0] = dbw[j, 0, 0]
            b0 = sat
            b1 = sat
            bw[j, 0] = sat
            bw[j, 1] = sat
        if tau >= 0.0:
            bw[j, 0] = (1.0 - tau) * b0 + tau * b1
            bw[j, 1] = 0.0
            if deriv:
                inv_w = 1.0 / w if w > 0.0 else 0.0
                for q in range(p):
                    dbw[j, 0, q] = (1.0 - tau) * dbw[j, 0, q] + tau * dbw[j, 1, q]
                    dbw[j, 1, q] = 0.0
                dbw[j, 0, 0] += (b1 - b0) * inv_w * dtau


@njit(cache=True)
def _two_lobe_fill(geo, gval, sw, deriv, bw, dbw):
    """The plain two-lobe model's weighted basis and unweighted derivative at every point
    (the hot loop: two exponentials per point, the angle-of-incidence parts from gval)."""
    lcg_all, lct_all, pt_all, lcp_all, pp_all, group = geo[2], geo[3], geo[4], geo[5], \
        geo[6], geo[7]
    for j in range(sw.size):
        g = group[j]
        s = gval[g, 0]
        nd = gval[g, 1]
        ns = gval[g, 2]
        lct = lct_all[j]
        lcp = lcp_all[j]
        pd = fexp(nd * lct) if pt_all[j] else 0.0
        ps = fexp(ns * lcp) if pp_all[j] else 0.0
        ld = (nd + 1.0) / TWO_PI * pd
        ls = (ns + 1.0) / TWO_PI * ps
        diff = ls - ld
        w = sw[j]
        bw[j, 0] = ld * w
        bw[j, 1] = (ld + s * diff) * w
        if deriv:
            lcg = lcg_all[j]
            dd = nd * (pd / TWO_PI + ld * lct)
            ds = ns * (ps / TWO_PI + ls * lcp)
            oms = 1.0 - s
            dbw[j, 0, 0] = 0.0
            dbw[j, 0, 1] = dd
            dbw[j, 0, 2] = dd * lcg
            dbw[j, 0, 3] = 0.0
            dbw[j, 0, 4] = 0.0
            dbw[j, 1, 0] = s * diff * lcg
            dbw[j, 1, 1] = oms * dd
            dbw[j, 1, 2] = oms * dd * lcg
            dbw[j, 1, 3] = s * ds
            dbw[j, 1, 4] = s * ds * lcg


@njit(cache=True)
def _jacobian(bw, dbw, alpha, inv, sw, jac, jm, t, coef):
    """Kaufman's Jacobian of the projected residual: ``(P_B - I) dB/dz alpha``
    (``jm``, ``t``, ``coef``: scratch of shapes (n, P), (L, P), (L, P))."""
    n, ll = bw.shape
    p = jac.shape[1]
    for j in range(n):
        for q in range(p):
            acc = 0.0
            for col in range(ll):
                acc += dbw[j, col, q] * alpha[col]
            jm[j, q] = acc * sw[j]
    t[:, :] = 0.0
    for j in range(n):
        for col in range(ll):
            bjc = bw[j, col]
            if bjc != 0.0:
                for q in range(p):
                    t[col, q] += bjc * jm[j, q]
    for col in range(ll):
        for q in range(p):
            acc = 0.0
            for k in range(ll):
                acc += inv[col, k] * t[k, q]
            coef[col, q] = acc
    for j in range(n):
        for q in range(p):
            acc = -jm[j, q]
            for col in range(ll):
                acc += bw[j, col] * coef[col, q]
            jac[j, q] = acc
