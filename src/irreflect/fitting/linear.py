"""The linear step (numpy): the optimal linear coefficients of a batch of bases by
(non-negative) least squares, over the saturation patterns of a specular share that
saturates, and Kaufman's Jacobian of the projected residual (variable projection). The
compiled side of the same step: :mod:`.linear_kernel`.
"""

from __future__ import annotations

import numpy as np

from ..models.base import saturated_column, share_factor

# ----------------------------------------------------------------------------- core solver
_RIDGE = 1e-12
_EXTREME = 1e8  # largest ratio of the sum of the linear coefficients to the residual one
_EYES = [np.eye(k) for k in range(8)]


def _small_inverse(a):
    """Inverse of a batch of small symmetric matrices; closed form for 1x1 and 2x2, whose
    batched LAPACK call costs more in overhead than in arithmetic."""
    n = a.shape[-1]
    if n == 1:
        return 1.0 / a
    if n == 2:
        det = a[:, 0, 0] * a[:, 1, 1] - a[:, 0, 1] * a[:, 1, 0]
        out = np.empty_like(a)
        out[:, 0, 0] = a[:, 1, 1]
        out[:, 1, 1] = a[:, 0, 0]
        out[:, 0, 1] = -a[:, 0, 1]
        out[:, 1, 0] = -a[:, 1, 0]
        return out / det[:, None, None]
    return np.linalg.inv(a)


def _solve_linear(bw, yw, nonneg, residual=None):
    """Weighted (non-negative) linear least squares for every problem of a batch.

    bw : (M, n, L) basis times sqrt(weight); yw : (M, n) data times sqrt(weight);
    nonneg : (L,) bool; residual : index of the column whose natural coefficient is the
    remainder of a sum (``K (1 - sum of shares)``, see ``hints.residual_column``) or
    None. Returns alpha (M, L), the mask of free columns (M, L) and the inverse of the
    (free-column) Gram matrix (M, L, L), reused for the Jacobian.

    Columns leave the active set (coefficient 0) when their coefficient would be negative
    where it must not be (non-negative least squares by an active set, most negative
    first), or when the residual column's coefficient would be below 10^-8 of the sum
    of all (the largest leaves): only a column all but invisible in the data (a lobe
    whose peak lies outside every measured direction) needs so large a coefficient, the
    data cannot support it, and the natural coefficients of such a solution would lose
    the residual one to rounding.
    """
    m, _, n_lin = bw.shape
    bwt = bw.swapaxes(1, 2)
    gram = bwt @ bw
    rhs = (bwt @ yw[:, :, None])[:, :, 0]
    eye = _EYES[n_lin] if n_lin < len(_EYES) else np.eye(n_lin)
    diag = np.diagonal(gram, axis1=1, axis2=2)
    scale = np.maximum(diag, 1e-300)
    free = diag > 0
    if free.all():
        inv = _small_inverse(gram + eye * (_RIDGE * scale)[:, :, None])
        alpha = (inv @ rhs[:, :, None])[:, :, 0]
    else:
        both = free[:, :, None] & free[:, None, :]
        g = gram * both + eye * np.where(free, _RIDGE * scale, 1.0)[:, :, None]
        inv = _small_inverse(g) * both
        alpha = (inv @ (rhs * free)[:, :, None])[:, :, 0]
    nonneg = np.asarray(nonneg, bool)
    rows = np.arange(m)
    for _ in range(n_lin):
        a = alpha[rows]
        fr = free[rows]
        negative = (a < 0) & nonneg & fr
        mag = np.abs(np.where(fr, a, 0.0))
        if residual is None:
            extreme = np.zeros(len(rows), bool)
        else:
            extreme = (mag[:, residual] > 0) & (mag[:, residual] < mag.sum(axis=1) / _EXTREME)
        offend = negative.any(axis=1) | extreme
        if not offend.any():
            break
        rows, a, fr, negative = rows[offend], a[offend], fr[offend], negative[offend]
        drop = np.where(negative.any(axis=1),
                        np.argmin(np.where(negative, a * np.sqrt(scale[rows]), np.inf), axis=1),
                        np.argmax(np.abs(np.where(fr, a, 0.0)), axis=1))
        free[rows, drop] = False
        fr = free[rows]
        both = fr[:, :, None] & fr[:, None, :]
        g = gram[rows] * both + eye * np.where(fr, _RIDGE * scale[rows], 1.0)[:, :, None]
        inv_r = _small_inverse(g) * both
        inv[rows] = inv_r
        alpha[rows] = (inv_r @ (rhs[rows] * fr)[:, :, None])[:, :, 0]
    alpha = np.where(free, alpha, 0.0)
    return alpha, free, inv


def _evaluate(model, geom, z, sw, yw):
    """Basis, optimal linear coefficients, residuals and cost for a batch of ``z``."""
    basis, dbasis = model.basis(geom, z, True)
    factor = share_factor(z, geom) if model.share_cap else None
    state = _linear_step(model, basis, sw, yw, factor)
    if factor is not None:
        state["v_as"] = np.array(np.broadcast_to(np.asarray(z, float)[:, 0],
                                                 state["cost"].shape))
        dbasis = _capped_dbasis(basis, dbasis, factor, geom, state)
    state["dbasis"] = dbasis
    return state


def _plain_step(model, bw, yw):
    """The linear step without a share cap: ``(alpha, free, inv, resid, cost)``."""
    alpha, free, inv = _solve_linear(bw, yw, model.alpha_nonneg,
                                     model.hints.residual_column)
    resid = yw - (bw @ alpha[:, :, None])[:, :, 0]
    cost = 0.5 * np.einsum("ij,ij->i", resid, resid)
    cost[~np.isfinite(cost)] = np.inf
    return alpha, free, inv, resid, cost


def _linear_step(model, basis, sw, yw, factor=None):
    """The optimal linear coefficients of a batch of bases ``(M, n, L)`` (unweighted; ``sw``
    the square roots of the weights), as a state: ``alpha`` (the model's coefficients),
    ``alpha_j`` (those of the effective basis, for the Jacobian), ``bw`` (the effective
    weighted basis, fixed columns zeroed), ``inv``, ``resid``, ``cost``.

    A model whose specular share saturates (``share_cap``; ``factor`` = ``cos^v_as(gamma)``
    per point, ``(M, n)``) is piecewise linear in its first two coefficients ``(K (1 - u),
    K u)``: the rows where ``u factor >= 1`` take the saturated column
    (:func:`~irreflect.models.base.saturated_column`) in both. Which rows those are is set
    by ``u`` alone, through the thresholds ``tau = 1 / factor`` of the angles of incidence
    with ``factor > 1``: between two consecutive thresholds the model is linear, so the
    step solves each interval's problem (non-negative least squares, kept when its ``u``
    lies in the interval) and each threshold's (``u = tau``: one column
    ``(1 - tau) b0 + tau b1``) and keeps the lowest cost. The cost over ``(K, u)`` is
    piecewise quadratic and need not be convex, hence every interval; an optimum at a
    threshold (the share exactly 1 at a measured angle) is found as one."""
    bw = basis * sw[:, :, None]
    if factor is None:
        alpha, free, inv, resid, cost = _plain_step(model, bw, yw)
        return {"bw": np.where(free[:, None, :], bw, 0.0) if not free.all() else bw,
                "alpha": alpha, "alpha_j": alpha, "inv": inv, "resid": resid, "cost": cost}
    m, n, n_lin = bw.shape
    factor = np.broadcast_to(factor, (m, n))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        tau = np.where(factor > 1.0, 1.0 / factor, np.inf)
    thresholds = np.sort(tau, axis=1)
    repeat = np.zeros_like(thresholds, bool)
    repeat[:, 1:] = thresholds[:, 1:] == thresholds[:, :-1]
    thresholds = np.sort(np.where(repeat, np.inf, thresholds), axis=1)
    count = np.isfinite(thresholds).sum(axis=1)
    k_max = int(count.max()) if m else 0
    thresholds = np.concatenate([thresholds[:, :k_max], np.full((m, 1), np.inf)], axis=1)
    sat_col = saturated_column(bw, factor)
    best = {"cost": np.full(m, np.inf), "alpha": np.zeros((m, n_lin)),
            "alpha_j": np.zeros((m, n_lin)), "free": np.zeros((m, n_lin), bool),
            "inv": np.zeros((m, n_lin, n_lin)), "resid": np.array(yw, float, copy=True),
            "bw": np.zeros_like(bw), "tau": np.full(m, np.nan), "lower": np.zeros(m)}

    def keep(rows, ok, cost, alpha, alpha_j, free, inv, resid, bwe, tau, lower):
        better = ok & (cost < best["cost"][rows])
        if not better.any():
            return
        r = rows[better]
        for key, value in (("cost", cost), ("alpha", alpha), ("alpha_j", alpha_j),
                           ("free", free), ("inv", inv), ("resid", resid), ("bw", bwe),
                           ("tau", tau), ("lower", lower)):
            best[key][r] = value[better]

    for k in range(k_max + 1):
        rows = np.flatnonzero(count >= k)
        lower = thresholds[rows, k - 1] if k else np.zeros(rows.size)
        upper = np.minimum(thresholds[rows, k], 1.0)
        sat = tau[rows] <= lower[:, None]
        bk = bw[rows].copy()
        col = np.where(sat, sat_col[rows], 0.0)
        bk[..., 0] = np.where(sat, col, bk[..., 0])
        bk[..., 1] = np.where(sat, col, bk[..., 1])
        alpha, free, inv, resid, cost = _plain_step(model, bk, yw[rows])
        total = alpha[:, 0] + alpha[:, 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = np.where(total > 0, alpha[:, 1] / np.where(total > 0, total, 1.0), lower)
        inside = (u >= lower) & (u <= upper)
        keep(rows, inside, cost, alpha, alpha, free, inv, resid, bk * free[:, None, :],
             np.full(rows.size, np.nan), lower)
        if k == 0:
            continue
        # the threshold itself: u = lower, one column (1 - u) b0 + u b1
        br = bk.copy()
        br[..., 0] = (1.0 - lower)[:, None] * bk[..., 0] + lower[:, None] * bk[..., 1]
        br[..., 1] = 0.0
        alpha_r, free_r, inv_r, resid_r, cost_r = _plain_step(model, br, yw[rows])
        alpha_t = alpha_r.copy()
        alpha_t[:, 0] = alpha_r[:, 0] * (1.0 - lower)
        alpha_t[:, 1] = alpha_r[:, 0] * lower
        keep(rows, np.ones(rows.size, bool), cost_r, alpha_t, alpha_r, free_r, inv_r, resid_r,
             br * free_r[:, None, :], lower, lower)
    return best


def _capped_dbasis(basis, dbasis, factor, geom, state):
    """The derivative (unweighted, ``(M, n, L, P)``) of the effective basis the linear step
    of a saturating share chose (:func:`_linear_step`): saturated rows carry the
    saturated column's derivative in both share columns; at a threshold ``tau = 1 /
    cos^v_as(gamma*)`` the one column ``(1 - tau) b0 + tau b1`` moves with ``v_as``
    through ``tau`` too: ``d tau / d v_as = -tau ln cos gamma* = tau ln(tau) / v_as``."""
    shape = basis.shape[:2]
    factor = np.broadcast_to(factor, shape)
    with np.errstate(divide="ignore"):
        tau_pt = np.where(factor > 1.0, 1.0 / np.where(factor > 1.0, factor, 1.0), np.inf)
    sat = tau_pt <= state["lower"][:, None]
    ray = np.flatnonzero(np.isfinite(state["tau"]))
    if not sat.any() and not ray.size:
        return dbasis
    lcg = np.broadcast_to(geom.log_cos_gamma, shape)
    out = np.array(np.broadcast_to(dbasis, basis.shape + dbasis.shape[-1:]), copy=True)
    safe = np.where(factor > 0, factor, 1.0)
    d_sat = out[..., 0, :] + (out[..., 1, :] - out[..., 0, :]) / safe[..., None]
    d_sat[..., 0] -= (basis[..., 1] - basis[..., 0]) / safe * lcg
    out[..., 0, :] = np.where(sat[..., None], d_sat, out[..., 0, :])
    out[..., 1, :] = np.where(sat[..., None], d_sat, out[..., 1, :])
    if ray.size:
        t = state["tau"][ray][:, None]
        b0 = np.where(sat[ray], saturated_column(basis[ray], factor[ray]), basis[ray, :, 0])
        b1 = np.where(sat[ray], b0, basis[ray, :, 1])
        comb = (1.0 - t[..., None]) * out[ray, :, 0, :] + t[..., None] * out[ray, :, 1, :]
        comb[..., 0] += (b1 - b0) * (t * np.log(t) / state["v_as"][ray][:, None])
        out[ray, :, 0, :] = comb
        out[ray, :, 1, :] = 0.0
    return out


def _kaufman_jacobian(state, sw):
    """Jacobian of the projected residual with respect to ``z`` (Kaufman 1975):
    ``-(I - P_B) dB/dz alpha``, with ``P_B`` the projection on the free basis columns (of
    the effective basis: see :func:`_linear_step`)."""
    bw = state["bw"]
    dbasis, alpha = state["dbasis"], state["alpha_j"]
    jm = dbasis[:, :, 0, :] * alpha[:, None, 0:1]
    for col in range(1, alpha.shape[1]):
        jm += dbasis[:, :, col, :] * alpha[:, None, col : col + 1]
    jm *= sw[:, :, None]
    coef = state["inv"] @ (bw.swapaxes(1, 2) @ jm)
    return bw @ coef - jm
