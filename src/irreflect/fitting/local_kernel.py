"""The local solver in the compiled kernel (numba): bounded Levenberg-Marquardt with Kaufman's
Jacobian from one start (:func:`_lm`, the generic path), its step and stopping rule, and
the projected cost of a batch of candidates (:func:`_costs`). The numpy side: :mod:`.local`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .kernel_math import STOP_FTOL, STOP_MAXITER, STOP_NONFINITE, STOP_STUCK, STOP_XTOL
from .linear_kernel import _evaluate, _gen_scratch, _gen_state, _jacobian, _solve_small
from .model_kernel import _sizes


@njit(cache=True, error_model="numpy")
def _lm_step(z, bounds, lam, grad, hess, pinned, a, rhs, step, zt):
    """One bounded Levenberg-Marquardt trial point ``zt`` from ``z``: coordinates at a bound
    whose gradient points outwards are pinned (their row and column of ``hess`` and their
    gradient cleared), the diagonal damped by ``lam`` (relative to itself, floored), the
    step solved and the trial point clipped into ``[lo, hi]``. ``grad`` and ``hess`` are
    modified; ``pinned``, ``a``, ``rhs``, ``step`` are scratch."""
    lo, hi = bounds
    p = z.size
    for q in range(p):
        pinned[q] = (z[q] <= lo[q] + 1e-12 and grad[q] > 0.0) or \
            (z[q] >= hi[q] - 1e-12 and grad[q] < 0.0)
    for q in range(p):
        if pinned[q]:
            for r in range(p):
                hess[q, r] = 0.0
                hess[r, q] = 0.0
            hess[q, q] = 1.0
            grad[q] = 0.0
    dmax = 0.0
    for q in range(p):
        dmax = max(dmax, hess[q, q])
    a[:, :] = hess
    for q in range(p):
        d = max(hess[q, q], 1e-12 * dmax + 1e-300)
        a[q, q] += lam * d
        rhs[q] = -grad[q]
    _solve_small(a, rhs, step)
    for q in range(p):
        if not math.isfinite(step[q]):
            step[q] = 0.0
        zt[q] = min(max(z[q] + step[q], lo[q]), hi[q])


@njit(cache=True)
def _lm_verdict(z, zt, cost, tcost, lam, xtol, ftol):
    """Judge the trial point ``zt`` of a Levenberg-Marquardt step from ``z``: returns
    (better, the new damping, stop), ``stop`` 0 to go on, else why to stop, in this order:
    STOP_FTOL (an accepted step gained at most ``ftol`` of the cost), STOP_XTOL (a step of
    at most ``xtol`` relative to |z|), STOP_STUCK (the damping grew past 1e10)."""
    better = tcost < cost
    lam_new = max(lam / 3.0, 1e-12) if better else lam * 4.0
    dz = 0.0
    zn = 0.0
    for q in range(z.size):
        dz += (zt[q] - z[q]) ** 2
        zn += z[q] * z[q]
    if better and cost - tcost <= ftol * max(cost, 1e-300):
        return better, lam_new, STOP_FTOL
    if math.sqrt(dz) <= xtol * (math.sqrt(zn) + xtol):
        return better, lam_new, STOP_XTOL
    if lam_new > 1e10:
        return better, lam_new, STOP_STUCK
    return better, lam_new, 0


@njit(cache=True)
def _lm(codes, nonneg, residual, z0, bounds, table, stop, z_out, alpha_out):
    """Bounded Levenberg-Marquardt from one start (fitting._lm_loop for one problem).
    ``bounds``: (lower, upper); ``table``: as :func:`_evaluate`; ``stop``: (max_iter,
    ftol, xtol). Returns (cost, reason, nfev); writes z_out and alpha_out (the model's
    coefficients)."""
    lo, hi = bounds
    max_iter, ftol, xtol = stop
    geo, glcg, sw, yw = table
    n = sw.size
    p = z0.size
    pp, ll = _sizes(codes, codes.size)
    cur = _gen_state(n, ll, p)
    trial = _gen_state(n, ll, p)
    sc = _gen_scratch(ll, p, glcg.size, glcg)
    jac = np.empty((n, p))
    z = np.empty(p)
    zt = np.empty(p)
    for q in range(p):
        z[q] = min(max(z0[q], lo[q]), hi[q])
    cost = _evaluate(codes, nonneg, residual, z, table, True, cur, sc)
    nfev = 1
    lam = 1e-3
    if not math.isfinite(cost):
        z_out[:] = z
        alpha_out[:] = cur[6]
        return math.inf, STOP_NONFINITE, nfev
    reason = STOP_MAXITER
    grad = np.empty(p)
    hess = np.empty((p, p))
    pinned = np.empty(p, np.bool_)
    jm = np.empty((n, p))
    tt = np.empty((ll, p))
    coef = np.empty((ll, p))
    a = np.empty((p, p))
    rhs = np.empty(p)
    step = np.empty(p)
    for _ in range(max_iter):
        bw, dbw, alpha, inv, resid = cur[0], cur[1], cur[2], cur[4], cur[5]
        _jacobian(bw, dbw, alpha, inv, sw, jac, jm, tt, coef)
        for q in range(p):
            acc = 0.0
            for j in range(n):
                acc += jac[j, q] * resid[j]
            grad[q] = acc
            for r in range(q, p):
                acc = 0.0
                for j in range(n):
                    acc += jac[j, q] * jac[j, r]
                hess[q, r] = acc
                hess[r, q] = acc
        _lm_step(z, (lo, hi), lam, grad, hess, pinned, a, rhs, step, zt)
        tcost = _evaluate(codes, nonneg, residual, zt, table, True, trial, sc)
        better, lam, stop_now = _lm_verdict(z, zt, cost, tcost, lam, xtol, ftol)
        nfev += 1
        if better:
            z[:] = zt
            cost = tcost
            cur, trial = trial, cur
        if stop_now:
            reason = stop_now
            break
    z_out[:] = z
    alpha_out[:] = cur[6]
    return cost, reason, nfev


@njit(cache=True)
def _costs(codes, nonneg, residual, cands, table):
    """Projected cost of every candidate row (no derivatives)."""
    m, p = cands.shape
    glcg, sw = table[1], table[2]
    n = sw.size
    pp, ll = _sizes(codes, codes.size)
    st = _gen_state(n, ll, 1)
    sc = _gen_scratch(ll, p, glcg.size, glcg)
    out = np.empty(m)
    for i in range(m):
        out[i] = _evaluate(codes, nonneg, residual, cands[i], table, False, st, sc)
    return out


@njit(cache=True)
def _scan_candidates(z, axes):
    """One row per value of every coordinate's scan axis, the others held at ``z``."""
    p, m = axes.shape
    out = np.empty((p * m, p))
    for q in range(p):
        for i in range(m):
            out[q * m + i] = z
            out[q * m + i, q] = axes[q, i]
    return out
