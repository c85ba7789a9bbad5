"""A fit's finish in the compiled kernel (numba): natural parameters, the fitted curve, R^2,
the covariance and which coefficients are ill-determined (:func:`tl_finish`). The numpy
side: :mod:`.finish`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .fast_kernel import _tl_group_values
from .kernel_math import TWO_PI, _close, _saturates, _share_at_normal, fexp
from .kernel_types import Finish


@njit(cache=True)
def tl_natural(z, alpha, out):
    """models.paper._two_lobe_to_natural of one row."""
    k = alpha[0] + alpha[1]
    out[0] = alpha[1] / k if k > 0.0 else 0.0
    out[1] = z[0]
    out[2] = math.exp(z[1])
    out[3] = z[2]
    out[4] = math.exp(z[3])
    out[5] = z[4]
    out[6] = k


@njit(cache=True)
def tl_finish(z, alpha, geo, glcg, weights, power, absolute_sigma, cost, n_params):
    """What fit() computes after the search of the plain two-lobe model, in one call:
    natural parameters, whether they map back to (z, alpha) (fit's round-trip check),
    the fitted curve, R^2, RMSE, MSE, the covariance of the natural parameters and which
    lie along a near-singular direction (fitting._covariance, the same steps). Returns
    (values, round_trip_ok, fitted, r2, rmse, mse, covariance, singular)."""
    n = power.size
    p = 5
    k = p + 2
    values = np.empty(k)
    tl_natural(z, alpha, values)
    zb = np.empty(p)
    zb[0] = values[1]
    zb[1] = math.log(values[2])
    zb[2] = values[3]
    zb[3] = math.log(values[4])
    zb[4] = values[5]
    ab = np.empty(2)
    ab[0] = values[6] * (1.0 - values[0])
    ab[1] = values[6] * values[0]
    amax = max(abs(alpha[0]), abs(alpha[1]))
    ok = _close(zb, z, 1e-9, 1e-12) and _close(ab, alpha, 1e-6, 1e-9 * amax)
    # the fitted curve and the Jacobian in (z, alpha) of the weighted model (jacobian_full)
    fitted = np.empty(n)
    jfull = np.empty((n, k))
    a0 = alpha[0]
    a1 = alpha[1]
    gval = np.empty((glcg.size, 5))
    _tl_group_values(z, glcg, gval)
    lcg_all, lct_all, pt_all, lcp_all, pp_all, group = geo[2], geo[3], geo[4], geo[5], \
        geo[6], geo[7]
    u = _share_at_normal(alpha)
    for j in range(n):
        g = group[j]
        s = gval[g, 0]
        nd = gval[g, 1]
        ns = gval[g, 2]
        a = fexp(nd * lct_all[j]) if pt_all[j] else 0.0
        b = fexp(ns * lcp_all[j]) if pp_all[j] else 0.0
        ld = gval[g, 3] * a
        ls = gval[g, 4] * b
        diff = ls - ld
        lcg = lcg_all[j]
        dd = nd * (a / TWO_PI + ld * lct_all[j])
        ds = ns * (b / TWO_PI + ls * lcp_all[j])
        oms = 1.0 - s
        w = math.sqrt(weights[j])
        if _saturates(u, s, True):  # a_s = 1: K L_s (jacobian_full's saturated rows)
            fitted[j] = ls * (a0 + a1)
            jfull[j, 0] = 0.0
            jfull[j, 1] = 0.0
            jfull[j, 2] = 0.0
            jfull[j, 3] = ds * (a0 + a1) * w
            jfull[j, 4] = ds * lcg * (a0 + a1) * w
            jfull[j, 5] = ls * w
            jfull[j, 6] = ls * w
            continue
        b1 = ld + s * diff
        fitted[j] = ld * a0 + b1 * a1
        jfull[j, 0] = (0.0 * a0 + s * diff * lcg * a1) * w
        jfull[j, 1] = (dd * a0 + oms * dd * a1) * w
        jfull[j, 2] = (dd * lcg * a0 + oms * dd * lcg * a1) * w
        jfull[j, 3] = (0.0 * a0 + s * ds * a1) * w
        jfull[j, 4] = (0.0 * a0 + s * ds * lcg * a1) * w
        jfull[j, 5] = ld * w
        jfull[j, 6] = b1 * w
    mean = 0.0
    for j in range(n):
        mean += power[j]
    mean /= n
    ss_res = 0.0
    ss_tot = 0.0
    for j in range(n):
        ss_res += (power[j] - fitted[j]) ** 2
        ss_tot += (power[j] - mean) ** 2
    r2 = 1.0 - ss_res / ss_tot if ss_tot > 0.0 else (math.nan if ss_res == 0.0 else -math.inf)
    mse = ss_res / n
    # covariance (fitting._covariance)
    col = np.empty(k)
    for q in range(k):
        acc = 0.0
        for j in range(n):
            acc += jfull[j, q] * jfull[j, q]
        col[q] = math.sqrt(acc) if acc > 0.0 else 1.0
    info = np.empty((k, k))
    for q in range(k):
        for r in range(q, k):
            acc = 0.0
            for j in range(n):
                acc += (jfull[j, q] / col[q]) * (jfull[j, r] / col[r])
            info[q, r] = acc
            info[r, q] = acc
    dof = max(n - n_params, 1)
    s2 = 1.0 if absolute_sigma else 2.0 * cost / dof
    evals, evecs = np.linalg.eigh(info)
    floor = 1e-12 * max(evals.max(), 1e-300)
    weak = evals < floor
    cov_internal = np.zeros((k, k))
    for e in range(k):
        ev = max(evals[e], floor)
        for q in range(k):
            for r in range(k):
                cov_internal[q, r] += evecs[q, e] * evecs[r, e] / ev
    for q in range(k):
        for r in range(k):
            cov_internal[q, r] = cov_internal[q, r] * s2 / (col[q] * col[r])
    x0 = np.empty(k)
    x0[:p] = z
    x0[p:] = alpha
    grad = np.empty((k, k))  # d natural / d internal: (natural, internal)
    plus = np.empty(k)
    minus = np.empty(k)
    xp = np.empty(k)
    top = 0.0  # the linear coefficients' scale (power units): finish._block_scales
    for i in range(p, k):
        top = max(top, abs(x0[i]))
    if not top > 0.0:
        top = 1.0
    for i in range(k):
        step = 1e-6 * max(abs(x0[i]), 1e-3 * (1.0 if i < p else top))
        xp[:] = x0
        xp[i] = x0[i] + step
        tl_natural(xp[:p], xp[p:], plus)
        xp[i] = x0[i] - step
        tl_natural(xp[:p], xp[p:], minus)
        for q in range(k):
            grad[q, i] = (plus[q] - minus[q]) / (2.0 * step)
    cov = grad @ cov_internal @ grad.T
    singular = np.zeros(k, np.bool_)
    for q in range(k):
        total = 0.0
        along = 0.0
        for i in range(k):
            total += (grad[q, i] / col[i]) ** 2
        for e in range(k):
            if weak[e]:
                acc = 0.0
                for i in range(k):
                    acc += grad[q, i] / col[i] * evecs[i, e]
                along += acc * acc
        singular[q] = math.sqrt(along) > 0.1 * max(math.sqrt(total), 1e-300)
    return Finish(values, ok, fitted, r2, math.sqrt(mse), mse, cov, singular)
