"""Global least-squares fitting of reflection models.

The fitter is a batched, bounded Levenberg-Marquardt on the *nonlinear* parameters of a
model with the linear coefficients eliminated by (non-negative) linear least squares at
every step (variable projection with Kaufman's Jacobian). Everything is vectorised over
a batch of problems: the starts of one fit, or the subsets of a whole optimiser
population, are solved together so that the cost is numerical work, not Python overhead.

Public entry points
-------------------
fit(measurements, model="two-lobe", seed=0)            -> FitResult (frozen)
fit_subsets(gamma, theta, power, masks, model, ...)    -> SubsetFits (one fit per mask)
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from dataclasses import dataclass, field
from warnings import warn

import numpy as np

from . import _draws as _draws_mod
from . import metrics
from .data import as_measurements, check_enough_points
from .errors import DataError, FitError, FitWarning, IrreflectError, unknown_name
from .models import (
    PROFILE_DIFFUSE_INDICES,
    PROFILE_SPECULAR_INDICES,
    Geometry,
    ReflectionModel,
    get_model,
    parse_spec,
)
from .models.base import saturate_rows, saturated_column, share_factor
from .models.extensions import Extension, _start_rows
from .models.paper import specular_share
from .validation import (
    check_angles_deg,
    check_fit_options,
    check_seed,
    check_starts,
    check_subset_inputs,
    short_list,
)

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
    remainder of a sum (``K (1 - sum of shares)``, see ``options["residual_column"]``) or
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
                                     model.options.get("residual_column"))
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


def _levenberg_marquardt(model, geom, z0, sw, yw, max_iter=200, ftol=1e-10, xtol=1e-9):
    """Bounded LM for a batch of M problems; returns z, state, nfev (M,), converged (M,).

    ``geom`` is a :class:`~irreflect.models.Geometry` of arrays ``(1, n)`` shared by
    every problem or ``(M, n)``, one row per problem."""
    with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):
        return _lm_loop(model, geom, z0, sw, yw, max_iter, ftol, xtol)


#: Why the Levenberg-Marquardt iteration of one start ended (``_lm_loop``'s reason codes).
STOP_FTOL, STOP_XTOL, STOP_STUCK, STOP_MAXITER, STOP_NONFINITE, STOP_POLISHED = 1, 2, 3, 4, 5, 6


def _lm_loop(model, geom, z0, sw, yw, max_iter, ftol, xtol):
    lo, hi = model.z_lower, model.z_upper
    z = np.clip(np.asarray(z0, float), lo, hi)
    m, p = z.shape
    shared_geometry = geom.rows == 1
    state = _evaluate(model, geom, z, sw, yw)
    nfev = np.ones(m, int)
    lam = np.full(m, 1e-3)
    active = np.isfinite(state["cost"])
    reason = np.where(active, 0, STOP_NONFINITE)
    eye = np.eye(p)
    diag_sel = eye.astype(bool)
    for _ in range(max_iter):
        if active.all():
            idx = None
            st, zi, swi, ywi, lam_i = state, z, sw, yw, lam
            geom_i = geom
        else:
            idx = np.nonzero(active)[0]
            if idx.size == 0:
                break
            st = {k: v[idx] for k, v in state.items()}
            zi, swi, ywi, lam_i = z[idx], sw[idx], yw[idx], lam[idx]
            geom_i = geom if shared_geometry else geom.take(idx)
        jac = _kaufman_jacobian(st, swi)
        jact = jac.swapaxes(1, 2)
        grad = (jact @ st["resid"][:, :, None])[:, :, 0]
        hess = jact @ jac
        # variables at a bound whose gradient pushes outwards stay fixed this step
        pinned = ((zi <= lo + 1e-12) & (grad > 0)) | ((zi >= hi - 1e-12) & (grad < 0))
        if pinned.any():
            keep = ~pinned
            hess = hess * (keep[:, :, None] & keep[:, None, :]) + eye * pinned[:, :, None]
            grad = np.where(pinned, 0.0, grad)
        diag = hess[:, diag_sel]
        diag = np.maximum(diag, 1e-12 * diag.max(axis=1, keepdims=True) + 1e-300)
        step = -np.linalg.solve(hess + eye * (lam_i[:, None] * diag)[:, :, None],
                                grad[:, :, None])[:, :, 0]
        step[~np.isfinite(step)] = 0.0
        z_trial = np.clip(zi + step, lo, hi)
        trial = _evaluate(model, geom_i, z_trial, swi, ywi)
        better = trial["cost"] < st["cost"]
        gain = st["cost"] - trial["cost"]
        lam_new = np.where(better, np.maximum(lam_i / 3.0, 1e-12), lam_i * 4.0)
        dzv = z_trial - zi
        dz = np.sqrt(np.einsum("ij,ij->i", dzv, dzv))
        small_step = dz <= xtol * (np.sqrt(np.einsum("ij,ij->i", zi, zi)) + xtol)
        small_gain = better & (gain <= ftol * np.maximum(st["cost"], 1e-300))
        stuck = lam_new > 1e10
        done = small_gain | small_step | stuck
        why = np.where(small_gain, STOP_FTOL, np.where(small_step, STOP_XTOL, STOP_STUCK))
        if idx is None:
            nfev += 1
            lam = lam_new
            if better.all():
                state, z = trial, z_trial
            else:
                for k in state:
                    state[k][better] = trial[k][better]
                z[better] = z_trial[better]
            reason = np.where(done, why, reason)
            active &= ~done
        else:
            nfev[idx] += 1
            lam[idx] = lam_new
            acc = idx[better]
            for k in state:
                state[k][acc] = trial[k][better]
            z[acc] = z_trial[better]
            reason[idx[done]] = why[done]
            active[idx[done]] = False
    reason[active] = STOP_MAXITER
    return z, state, nfev, reason


def _polish(model, geom, z0, sw1, yw1, max_nfev=400):
    """Finish a local search that crawled (iteration limit, no step lowering the cost) with
    scipy's trust-region reflective least squares on the same projected residual and
    Kaufman Jacobian: its steps respect the bounds (Coleman-Li scaling), which a damped
    Gauss-Newton step along a poorly determined coordinate toward a bound does not.
    Returns ``(z, alpha, cost, n_evaluations, converged)``."""
    from scipy.optimize import least_squares

    cache = {}

    def state(z):
        if cache.get("z") is None or not np.array_equal(cache["z"], z):
            with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):
                cache["state"] = _evaluate(model, geom, z[None], sw1, yw1)
            cache["z"] = z.copy()
        return cache["state"]

    def residual(z):
        return np.nan_to_num(-state(z)["resid"][0], nan=1e150, posinf=1e150, neginf=-1e150)

    def jacobian(z):
        with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):
            return np.nan_to_num(-_kaufman_jacobian(state(z), sw1)[0])

    z0 = np.clip(z0, model.z_lower, model.z_upper)
    lo, hi = model.z_lower, model.z_upper
    inside = np.where(z0 <= lo, lo + 1e-10 * (hi - lo), np.where(z0 >= hi, hi - 1e-10 * (hi - lo),
                                                                   z0))
    res = least_squares(residual, inside, jac=jacobian, bounds=(lo, hi), method="trf",
                        x_scale="jac", ftol=1e-12, xtol=1e-12, gtol=1e-12, max_nfev=max_nfev)
    st = state(res.x)
    return res.x, st["alpha"][0], float(st["cost"][0]), int(res.nfev), res.status > 0


def _gauss_newton_decrease(model, geom, z, sw, yw):
    """Cost decrease a full (bound-respecting) Gauss-Newton step predicts from ``z`` (M, P):
    ``g' H^-1 g / 2`` over the coordinates not held at a bound. Near zero at a first-order
    optimum whatever the scale of the data."""
    with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):
        st = _evaluate(model, geom, z, sw, yw)
        jac = _kaufman_jacobian(st, sw)
        grad = (jac.swapaxes(1, 2) @ st["resid"][:, :, None])[:, :, 0]
        hess = jac.swapaxes(1, 2) @ jac
        lo, hi = model.z_lower, model.z_upper
        pinned = ((z <= lo + 1e-12) & (grad > 0)) | ((z >= hi - 1e-12) & (grad < 0))
        keep = ~pinned
        grad = np.where(keep, grad, 0.0)
        eye = np.eye(z.shape[1])
        hess = hess * (keep[:, :, None] & keep[:, None, :]) + eye * pinned[:, :, None]
        scale = np.sqrt(np.maximum(np.diagonal(hess, axis1=1, axis2=2), 1e-300))
        hs = hess / scale[:, :, None] / scale[:, None, :]
        gs = grad / scale
        step = np.linalg.lstsq(hs[0], gs[0], rcond=1e-10)[0] if len(z) == 1 else \
            np.linalg.solve(hs + 1e-10 * eye, gs[:, :, None])[:, :, 0]
        dec = 0.5 * np.sum(np.atleast_2d(gs) * np.atleast_2d(step), axis=1)
    return np.where(np.isfinite(dec), dec, np.inf), st["cost"]


# ----------------------------------------------------------------------------- results
@dataclass(frozen=True, repr=False)
class FitResult:
    """Outcome of one fit. Frozen: the fitter is not kept inside it.

    Besides the coefficients and the quality measures, a result says how far it can be
    trusted: ``converged`` and ``message`` (why the optimiser stopped), ``at_bound`` (the
    coefficients that sit on a bound of their physical range), ``ill_determined`` (those
    the data do not pin down: standard error larger than the value, or part of a
    near-singular covariance) and ``warnings`` (one line each, printed by every command).
    """

    model: str
    param_names: tuple[str, ...]
    values: np.ndarray
    stderr: np.ndarray
    covariance: np.ndarray
    r2: float
    rmse: float
    mse: float
    chi2_reduced: float
    residuals: np.ndarray
    gamma_deg: np.ndarray
    theta_deg: np.ndarray
    power: np.ndarray
    sigma: np.ndarray | None
    n_points: int
    n_params: int
    nfev: int
    n_starts: int
    fit_ms: float
    seed: int
    cost: float
    converged: bool = True
    message: str = "converged"
    at_bound: tuple[str, ...] = ()
    ill_determined: tuple[str, ...] = ()
    warnings: tuple[str, ...] = ()
    model_object: ReflectionModel | None = field(default=None, compare=False)
    retried: str = ""  # why fit() searched a second time, and what it found (empty: no)

    def __repr__(self) -> str:
        flags = "" if not self.warnings else f", {len(self.warnings)} warning(s)"
        params = ", ".join(f"{k}={v:.4g}" for k, v in self.params.items())
        return (f"FitResult(model={self.model!r}, n_points={self.n_points}, r2={self.r2:.6f}, "
                f"{params}, converged={self.converged}{flags})")

    @property
    def params(self) -> dict[str, float]:
        return dict(zip(self.param_names, map(float, self.values), strict=True))

    @property
    def stderrs(self) -> dict[str, float]:
        return dict(zip(self.param_names, map(float, self.stderr), strict=True))

    @property
    def correlation(self) -> np.ndarray:
        sd = np.sqrt(np.clip(np.diag(self.covariance), 0, None))
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.covariance / np.outer(sd, sd)

    @property
    def fitted(self) -> np.ndarray:
        return self.power - self.residuals

    def predict(self, gamma_deg, theta_deg) -> np.ndarray:
        """Model power at the given angles (degrees, paper convention)."""
        model = self.model_object or get_model(self.model)
        gamma_deg, theta_deg = check_angles_deg(gamma_deg, theta_deg)
        return model.predict_deg(self.values, gamma_deg, theta_deg)

    @property
    def saturated_gammas_deg(self) -> np.ndarray:
        """The measured angles of incidence (|gamma|, degrees) where the fitted specular
        share is 1 (:func:`irreflect.models.paper.specular_share`): there the reflection
        is all specular. Empty for a model without a saturating share."""
        model = self.model_object or get_model(self.model)
        if not model.share_cap:
            return np.empty(0)
        g = np.unique(np.abs(self.gamma_deg))
        share = specular_share(self.values[0], self.values[1], np.cos(np.radians(g)))
        return g[share >= 1.0]

    def verdict(self):
        """What R^2 cannot say: per angle of incidence whether the specular lobe is resolved
        and the shape reproduced, and the coefficients' checks
        (:class:`irreflect.verdict.FitVerdict`)."""
        from .verdict import fit_verdict

        return fit_verdict(self)

    def polar_errors(self) -> dict[float, float]:
        """Relative polar-area error (section 5.3) per angle of incidence, in percent."""
        return metrics.polar_area_errors(
            self.gamma_deg, self.theta_deg, self.power, self.predict
        )

    def to_dict(self) -> dict:
        return {
            "model": self.model,
            "params": self.params,
            "stderr": self.stderrs,
            "r2": self.r2,
            "rmse": self.rmse,
            "mse": self.mse,
            "n_points": self.n_points,
            "n_params": self.n_params,
            "nfev": self.nfev,
            "fit_ms": self.fit_ms,
            "seed": self.seed,
            "converged": self.converged,
            "message": self.message,
            "at_bound": list(self.at_bound),
            "ill_determined": list(self.ill_determined),
            "warnings": list(self.warnings),
            "retried": self.retried,
            "verdict": self.verdict().to_dict(),
        }

    def report(self, warnings: bool = True) -> str:
        """Readable fit report: the verdict first (:meth:`verdict`), then coefficients with
        errors, quality, the verdict per angle of incidence, then (with ``warnings``) the
        warnings, one line each."""
        verdict = self.verdict()
        lines = [
            verdict.summary(),
            f"model {self.model}: {self.n_points} points, {self.n_params} parameters, "
            f"{self.n_starts} starts, {self.nfev} evaluations, {self.fit_ms:.1f} ms",
            f"{self.message}",
        ]
        if self.retried:
            lines.append(f"searched a second time, more widely ({self.retried})")
        lines.append(f"{'parameter':<10}{'value':>14}{'std. error':>14}")
        for name, v, s in zip(self.param_names, self.values, self.stderr, strict=True):
            flag = "  at bound" if name in self.at_bound else (
                "  ill-determined" if name in self.ill_determined else "")
            lines.append(f"{name:<10}{v:>14.6g}{s:>14.3g}{flag}")
        lines.append(f"R^2 = {self.r2:.6f}   RMSE = {self.rmse:.6g}   MSE = {self.mse:.6g}")
        if self.sigma is not None:
            lines.append(f"reduced chi^2 = {self.chi2_reduced:.4g} (weighted by 1/sigma^2)")
        errors = self.polar_errors()
        if errors:
            lines.append("relative polar-area error per angle of incidence (section 5.3, the "
                         "model at the measured receivers):")
            lines.append("  " + "  ".join(f"{g:g} deg: {e:.2f}%" for g, e in errors.items()))
        lines.append("per angle of incidence (the model's continuous curve; lobe half width "
                     "and the receivers within one and two half widths of the mirror):")
        lines += ["  " + row for row in verdict.table()]
        if warnings:
            lines += [f"warning: {w}" for w in self.warnings]
        return "\n".join(lines)


# ----------------------------------------------------------------------------- fit()
def _fitted_and_jacobian(model, z, alpha, gamma, theta, weights, engine=None, kgeo=None):
    """The fitted curve and the Jacobian in (z, alpha) of the weighted model, (n, P + L)."""
    codes = _kernel_codes(model, engine)
    if codes is not None:
        from . import _kernel

        geo, glcg = (kgeo if kgeo is not None else _kernel_geometry(gamma, theta))[:2]
        return (_kernel.predict(codes, _w(z), _w(alpha), geo, glcg),
                _kernel.jacobian_full(codes, _w(z), _w(alpha), geo, glcg, _w(np.sqrt(weights))))
    geom = Geometry.of(gamma[None], theta[None])
    with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):
        basis, dbasis = model.basis(geom, z[None], True)
        if model.share_cap:  # the saturated rows' basis and derivative (the unsaturated
            # side of a threshold: there both sides give the same curve)
            factor = share_factor(z[None], geom)
            sat = saturate_rows(basis, factor, alpha[None], strict=True)
            state = {"lower": np.atleast_1d(_saturation_level(alpha, strict=True)),
                     "tau": np.full(1, np.nan)}
            dbasis = _capped_dbasis(basis, dbasis, factor, geom, state)
            basis = sat
    jz = np.einsum("mnlp,ml->mnp", dbasis, alpha[None])[0]
    return basis[0] @ alpha, np.concatenate([jz, basis[0]], axis=1) * np.sqrt(weights)[:, None]


def _saturation_level(alpha, strict: bool = False) -> float:
    """The largest threshold ``tau`` the share at ``alpha`` has passed: rows with
    ``1 / cos^v_as(gamma) <= u`` saturate, so the share at normal incidence ``u``
    (slightly less with ``strict``: a row exactly at its threshold counts as below it)."""
    k = alpha[0] + alpha[1]
    u = alpha[1] / k if k > 0 else 0.0
    return u * (1.0 - 1e-9) if strict else u


def _covariance(model, z, alpha, jfull, absolute_sigma, cost, n_points):
    """Covariance of the natural parameters from the Jacobian ``jfull`` in (z, alpha), and
    which natural parameters lie in a near-singular direction of the information matrix."""
    # scale the columns so that the singularity test does not depend on units
    col = np.sqrt(np.sum(jfull * jfull, axis=0))
    col = np.where(col > 0, col, 1.0)  # a coordinate the data do not see: left unscaled
    info = (jfull / col).T @ (jfull / col)
    dof = max(n_points - model.n_params, 1)
    s2 = 1.0 if absolute_sigma else 2.0 * cost / dof
    # inverse through the symmetric eigen-decomposition; directions the data do not
    # determine keep a huge (floored) variance, so their standard errors show it
    evals, evecs = np.linalg.eigh(info)
    floor = 1e-12 * max(evals.max(), 1e-300)
    weak = evals < floor
    evals = np.maximum(evals, floor)
    cov_internal = (evecs / evals) @ evecs.T * s2 / np.outer(col, col)
    # chain rule to natural parameters, by central differences of the smooth map (one batch)
    x0 = np.concatenate([z, alpha])
    p_dim = z.size
    steps = 1e-6 * np.maximum(np.abs(x0), 1e-3)
    pert = np.concatenate([x0 + np.diag(steps), x0 - np.diag(steps)])
    nat = model.to_natural(pert[:, :p_dim], pert[:, p_dim:])
    grad = ((nat[: x0.size] - nat[x0.size:]) / (2 * steps[:, None])).T
    # natural parameters with a share of their gradient (in the scaled internal
    # coordinates) along the undetermined directions
    g_scaled = grad / col
    along = np.linalg.norm(g_scaled @ evecs[:, weak], axis=1) if weak.any() else \
        np.zeros(grad.shape[0])
    singular = along > 0.1 * np.maximum(np.linalg.norm(g_scaled, axis=1), 1e-300)
    return grad @ cov_internal @ grad.T, singular


_SCREEN_CACHE: dict = {}
#: Default number of screening candidates by number of nonlinear coordinates: a full grid
#: for one or two coordinates (the search is then exhaustive at the grid's resolution),
#: a Latin hypercube beyond, 100 candidates per coordinate from 4 on (models with
#: exchangeable lobes, n-lobe and Lafortune, have many equivalent basins). A model may set
#: its own ``options["n_screen"]`` and ``options["n_keep"]``.
DEFAULT_SCREEN = {0: 0, 1: 96, 2: 400, 3: 300}


def default_screen(model) -> int:
    if "n_screen" in model.options:
        return int(model.options["n_screen"])
    return DEFAULT_SCREEN.get(model.n_nonlinear, 100 * model.n_nonlinear)


def _default_hops(model, n_keep: int) -> int:
    """Basin hops per refinement round: ``n_keep`` for models of 4 or more coordinates
    (exchangeable lobes), unless the model sets ``options["n_hops"]``."""
    if "n_hops" in model.options:
        return int(model.options["n_hops"])
    return n_keep if model.n_nonlinear >= 4 else 0


def default_keep(model) -> int:
    """Levenberg-Marquardt starts from the screening: 3, or one per coordinate from 4 on."""
    if "n_keep" in model.options:
        return int(model.options["n_keep"])
    return max(3, model.n_nonlinear if model.n_nonlinear >= 4 else 3)


def screen_samples(model, n: int, seed: int) -> np.ndarray:
    """``n`` screening points in the model's screening box (deterministic per seed).

    One or two nonlinear coordinates: a regular grid (``n`` points, or ``ceil(sqrt(n))``
    per axis), which no narrow optimum can slip through. More: a Latin hypercube, every
    coordinate's range cut into ``n`` strata each sampled once (McKay, Beckman and
    Conover 1979), drawn from the counter-based generator of :mod:`irreflect._draws` (the
    compiled kernel draws the same points). Plain numpy on purpose: ``scipy.stats.qmc``
    would cost every command a second of import time for the same coverage of the box.
    """
    key = (model.name, model.n_nonlinear, n, seed, _screen_box_key(model))
    if key not in _SCREEN_CACHE:
        lo, hi = model.screen_box()
        p = lo.size
        if p == 0 or n == 0:
            out = np.empty((0, p))
        elif p == 1:
            out = np.linspace(lo, hi, n)
        elif p == 2:
            k = int(np.ceil(np.sqrt(n)))
            a, b = np.meshgrid(np.linspace(lo[0], hi[0], k), np.linspace(lo[1], hi[1], k))
            out = np.column_stack([a.ravel(), b.ravel()])
        else:
            out = _draws_mod.latin_hypercube(_draws_mod.seed_key(seed), n, lo, hi)
        if len(_SCREEN_CACHE) >= 256:  # bounded: one entry per seed a process has used
            _SCREEN_CACHE.pop(next(iter(_SCREEN_CACHE)))
        _SCREEN_CACHE[key] = out
    return _SCREEN_CACHE[key]


def _screen_box_key(model) -> tuple:
    """The screening box as a hashable tuple (kept on the model object: it is asked on
    every fit)."""
    cached = model.options.get("_screen_box_key")
    if cached is not None and cached[0] is model:
        return cached[1]
    key = tuple(np.concatenate(model.screen_box()).tolist())
    try:
        model.options["_screen_box_key"] = (model, key)
    except TypeError:
        pass
    return key


#: Values (candidates x points x basis columns) of one screening piece of the numpy path:
#: about 30 MB per array, so that screening many candidates on a 200,000-point table stays
#: within a bounded memory (the pieces give the same costs as one batch).
SCREEN_PIECE_VALUES = 4_000_000


def _screen_costs(model, geom, z, sw, yw):
    """Variable-projection cost of every candidate ``z`` (no derivatives): a cheap global look.
    Scored in pieces of at most :data:`SCREEN_PIECE_VALUES` basis values."""
    z = np.asarray(z, float)
    m = z.shape[0]
    n = yw.shape[-1]
    step = max(1, SCREEN_PIECE_VALUES // max(1, n * max(model.n_linear, 1)))
    if m <= step:
        return _screen_piece(model, geom, z, sw, yw)

    def rows(a, lo, hi):
        return a[lo:hi] if a.shape[0] == m else a

    return np.concatenate([
        _screen_piece(model, geom.take(slice(lo, lo + step)), z[lo:lo + step],
                      rows(sw, lo, lo + step), rows(yw, lo, lo + step))
        for lo in range(0, m, step)])


def _screen_piece(model, geom, z, sw, yw):
    with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):
        basis, _ = model.basis(geom, z, False)
    return _projected_cost(model, basis, sw, yw,
                           share_factor(z, geom) if model.share_cap else None)


def _projected_cost(model, basis, sw, yw, factor=None):
    """Cost after eliminating the linear coefficients, for basis values ``(M, n, L)``
    (``factor``: the share's ``cos^v_as(gamma)`` per point when it saturates)."""
    with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):
        return _linear_step(model, basis, sw, yw, factor)["cost"]


def _diverse_best(z, cost, k, lo, hi, min_distance=0.08):
    """Indices of up to ``k`` low-cost candidates that are apart from each other (distance
    in the screening box scaled to the unit cube): starts in different basins."""
    width = np.where(hi > lo, hi - lo, 1.0)
    unit = (z - lo) / width
    chosen: list[int] = []
    for i in np.argsort(cost, kind="stable"):
        if not np.isfinite(cost[i]):
            break
        if all(np.sqrt(np.mean((unit[i] - unit[j]) ** 2)) >= min_distance for j in chosen):
            chosen.append(int(i))
            if len(chosen) == k:
                break
    return np.array(chosen, int)


def _scan_axes(model, n: int) -> list[np.ndarray]:
    """For every nonlinear coordinate, ``n`` values spanning its screening box and its
    bounds (within +-15): the values a global scan tries."""
    lo, hi = model.screen_box()
    zl = np.maximum(model.z_lower, -15.0)
    zu = np.minimum(model.z_upper, 15.0)
    return [np.linspace(min(lo[j], zl[j]), max(hi[j], zu[j]), n) for j in range(lo.size)]


def _scan_blocks(model, n1: int = 33, n2: int = 17) -> list[tuple[np.ndarray, np.ndarray]]:
    """The global scans of a refinement round: ``(coordinates, values (m, len))`` per block.

    A model declares which coordinates belong together in ``options["groups"]`` (a lobe's
    axis and index, a lobe's ``ln u`` and ``v``): pairs are scanned on a ``n2 x n2`` grid,
    other coordinates one at a time on ``n1`` values (the default: every coordinate
    alone)."""
    groups = model.options.get("groups") or tuple((j,) for j in range(model.n_nonlinear))
    axes_1, axes_2 = _scan_axes(model, n1), _scan_axes(model, n2)
    blocks = []
    for group in groups:
        idx = np.asarray(group, int)
        if idx.size == 2:
            a, b = np.meshgrid(axes_2[idx[0]], axes_2[idx[1]])
            blocks.append((idx, np.column_stack([a.ravel(), b.ravel()])))
        else:
            blocks += [(np.array([j]), axes_1[j][:, None]) for j in idx]
    return blocks


def _block_candidates(z_best, blocks) -> np.ndarray:
    """Rows of ``z_best`` with each block's coordinates replaced by its scan values."""
    rows = []
    for idx, values in blocks:
        cand = np.repeat(z_best[None], len(values), axis=0)
        cand[:, idx] = values
        rows.append(cand)
    return np.vstack(rows)


def _coordinate_scan(model, geom, z_best, cost_best, sw1, yw1):
    """Global scans through the best point, one block of coordinates at a time.

    A narrow lobe makes the cost multi-modal along its index (and a tilt along the tilt),
    and lobes that can swap roles make it multi-modal along their axes: a local optimiser
    stops in whichever basin it started. Every block (:func:`_scan_blocks`) is swept
    over its whole range with the other coordinates held; each sweep's minimum that beats
    the current cost is returned as a new start (empty when none does: the point is then
    optimal along every block at the sweep's resolution)."""
    blocks = _scan_blocks(model)
    cand = _block_candidates(z_best, blocks)
    cost = _screen_costs(model, geom, cand, sw1, np.broadcast_to(yw1, (len(cand), yw1.shape[1])))
    out, start = [], 0
    for _, values in blocks:
        part = cost[start:start + len(values)]
        j = int(np.argmin(part))
        if part[j] < cost_best * (1.0 - 1e-9):
            out.append(cand[start + j])
        start += len(values)
    return np.array(out).reshape(-1, z_best.size), len(cand)


def _candidates(model, gamma_rad, theta_rad, power, seed, n_random, extra=None):
    """The caller's extra starts, data-driven starts, and seeded random perturbations of
    the first row."""
    starts = np.atleast_2d(np.asarray(model.starts(gamma_rad, theta_rad, power), float))
    starts = starts.reshape(-1, model.n_nonlinear)
    if extra is not None and len(extra):
        starts = np.vstack([np.asarray(extra, float).reshape(-1, model.n_nonlinear), starts])
    parts = [starts]
    if n_random and len(starts):
        width = model.z_upper - model.z_lower
        jitter, _ = _draws(seed, n_random, 0, 0, starts.shape[1])
        parts.append(starts[0] + jitter * np.minimum(width, 10.0))
    out = np.clip(np.vstack(parts), model.z_lower, model.z_upper)
    return np.unique(out, axis=0) if len(out) else out


def check_fit_data(power, model, source: str = "table") -> None:
    """Refuse tables no fit can be honest about: no degree of freedom left
    (``n_points <= n_params``), non-finite or constant power."""

    power = np.asarray(power)
    n = power.size
    check_enough_points(n, model, source)
    if not np.all(np.isfinite(power)):
        raise DataError(f"{source}: power has non-finite values: remove or fix those rows")
    if np.ptp(power) == 0:
        raise DataError(
            f"{source}: power is constant ({power.flat[0]:g} at all {n} points): a reflection "
            "model needs the power measured at varying angles; check the power column"
        )


def _fmt_bound(b):
    return f"{b:g}"


def judge(model, values, stderr, singular, gamma_rad, converged, message,
          validity: bool = True) -> tuple:
    """(at_bound, ill_determined, warnings) of a fit: the checks every command prints
    (``validity``: run the model's own check, ``options["validity"]``, too)."""
    at_bound, detail = [], []
    values_f = np.asarray(values, float).tolist()  # Python floats: scalar tests in µs, not 10s
    for p, v in zip(model.params, values_f, strict=True):
        for side, b in (("lower", p.lower), ("upper", p.upper)):
            if not math.isfinite(b):
                continue
            tol = 1e-6 * abs(b) if b != 0 else 1e-12
            if (side == "lower" and v <= b + tol) or (side == "upper" and v >= b - tol):
                at_bound.append(p.name)
                detail.append(f"{p.name} = {v:.4g} ({side} bound {_fmt_bound(b)})")
    ill, ill_detail = [], []
    for p, v, s, sing in zip(model.params, values_f, np.asarray(stderr, float).tolist(),
                             np.asarray(singular, bool).tolist(), strict=True):
        if not math.isfinite(s) or s > abs(v) or sing:
            ill.append(p.name)
            why = "near-singular covariance" if sing else "std. error > |value|"
            ill_detail.append(f"{p.name} = {v:.4g} +- {s:.2g} ({why})")
    warnings = []
    if not converged:
        warnings.append(f"not converged: {message}; the coefficients may not be the optimum")
    if at_bound:
        warnings.append(
            "at a bound of the physical range: " + ", ".join(detail)
            + ": the data push past the model's range or do not constrain it"
        )
    if ill:
        warnings.append("ill-determined by these data: " + ", ".join(ill_detail)
                        + ": measure more angles or fix these coefficients")
    check = model.options.get("validity") if validity else None
    if check is not None:
        warnings += list(check(values, gamma_rad))
    return tuple(at_bound), tuple(ill), tuple(warnings)


_STOP_MESSAGES = {
    STOP_FTOL: "converged: relative change of the cost below {ftol:g}",
    STOP_XTOL: "converged: step below {xtol:g}",
    STOP_STUCK: "converged: no step lowers the cost further",
    STOP_MAXITER: "iteration limit ({max_iter}) reached",
    STOP_NONFINITE: "the cost is not finite at the start",
    STOP_POLISHED: "converged: Levenberg-Marquardt crawled, a trust-region least-squares "
                   "polish met its tolerance (1e-12)",
}


def _global_search(model_obj, gamma, theta, power, weights, **options):
    """The global search of :func:`fit` on one table (radians, power, weights): returns
    ``(z, alpha, cost, converged, message, n_starts, n_evals)``, or None when no start
    reaches a finite cost.

    The power is divided by its weighted root mean square first (and the linear
    coefficients and the cost scaled back), so that the search sees the same numbers
    whatever the unit of power: the shape coefficients do not depend on it."""
    power = np.asarray(power, float)
    scale = float(np.sqrt(np.mean(weights * power * power)))
    if not (np.isfinite(scale) and scale > 0):
        scale = 1.0
    out = _global_search_unit(model_obj, gamma, theta, power / scale, weights, **options)
    if out is None:
        return None
    z, alpha, cost, *rest = out
    return (z, alpha * scale, cost * scale * scale, *rest)


def _search_numpy(model_obj, codes, gamma, theta, power, weights, geom, sw1, yw1, *, seed,
                  n_random_starts, n_screen, n_keep, n_data_starts, max_iter, max_rounds,
                  extra_starts, kgeo=None, n_hops=None):
    """The global search in numpy (the reference implementation): data-driven and random
    starts, screening, Levenberg-Marquardt from diverse candidates, refinement rounds.
    Returns ``(z, alpha, cost, reason, n_starts, n_evals)`` or None."""
    lo, hi = model_obj.screen_box()
    # every candidate is scored by its projected cost in one batch; Levenberg-Marquardt
    # starts from the best data-driven ones and from the best in different basins
    own = _candidates(model_obj, gamma, theta, power, seed, n_random_starts, extra_starts)
    cands = own
    if n_screen and model_obj.n_nonlinear:
        cands = np.vstack([own, np.clip(screen_samples(model_obj, n_screen, seed),
                                        model_obj.z_lower, model_obj.z_upper)])
    screen = _screen_costs(model_obj, geom, cands, sw1,
                           np.broadcast_to(yw1, (len(cands), power.size)))
    n_evals = len(cands)
    first = _diverse_best(own, screen[: len(own)], n_data_starts, lo, hi, min_distance=1e-9)
    others = _diverse_best(cands, screen, n_keep, lo, hi)
    starts = cands[np.unique(np.concatenate([first, others]))]
    if not len(starts):
        starts = cands[:1]

    def local(z0):
        m = len(z0)
        return _levenberg_marquardt(model_obj, geom, z0, np.broadcast_to(sw1, (m, power.size)),
                                    np.broadcast_to(yw1, (m, power.size)), max_iter=max_iter)

    z, state, nfev, reason = local(starts)
    n_starts = len(starts)
    n_evals += int(nfev.sum())
    best = int(np.argmin(state["cost"]))
    if not np.isfinite(state["cost"][best]):
        return None
    zb, ab, cb, rb = z[best], state["alpha"][best], float(state["cost"][best]), int(reason[best])
    # refinement rounds: global line searches along every coordinate and, for models
    # with many coordinates, seeded jumps around the best point (basin hopping, Wales and
    # Doye 1997); Levenberg-Marquardt from all of them; stop when nothing improves
    n_hops = _default_hops(model_obj, n_keep) if n_hops is None else int(n_hops)
    rounds = max_rounds if model_obj.n_nonlinear else 0
    _, jumps = _draws(seed, 0, n_hops, rounds, zb.size)
    width = np.where(hi > lo, hi - lo, 1.0)
    for rnd in range(rounds):
        extra, scanned = _coordinate_scan(model_obj, geom, zb, cb, sw1, yw1)
        n_evals += scanned
        hops = zb + jumps[rnd] * width
        extra = np.clip(np.vstack([extra, hops]), model_obj.z_lower, model_obj.z_upper)
        if not len(extra):
            break
        z2, st2, nfev2, reason2 = local(extra)
        n_starts += len(extra)
        n_evals += int(nfev2.sum())
        j = int(np.argmin(st2["cost"]))
        if not st2["cost"][j] < cb * (1.0 - 1e-12):
            break
        zb, ab, cb, rb = z2[j], st2["alpha"][j], float(st2["cost"][j]), int(reason2[j])
    return zb, ab, cb, rb, n_starts, n_evals


def _search_compiled(model_obj, codes, gamma, theta, power, weights, geom, sw1, yw1, *, seed,
                     n_random_starts, n_screen, n_keep, n_data_starts, max_iter, max_rounds,
                     extra_starts, kgeo=None, n_hops=None):
    """The same search in the compiled kernel (:mod:`irreflect._kernel`): the same
    candidates (the random draws of :mod:`irreflect._draws`, the same numbers), the same
    order and stopping rules."""
    from . import _kernel

    p = model_obj.n_nonlinear
    st = _kernel_static(model_obj)
    geo, glcg, levels, group = (kgeo if kgeo is not None else
                                _kernel_geometry(gamma, theta))[:4]
    if n_hops is None:
        n_hops = _default_hops(model_obj, n_keep)
    jitter, hops = _draws(seed, n_random_starts, int(n_hops), max_rounds, p)
    screen = (screen_samples(model_obj, n_screen, seed) if n_screen and p
              else np.zeros((0, p)))
    extra = (st["no_extra"] if extra_starts is None else
             np.clip(np.asarray(extra_starts, float).reshape(-1, p), st["zlo"], st["zhi"]))
    zb, ab, cb, rb, n_starts, n_evals = _kernel.global_search(
        codes, st["nonneg"], st["residual"], geo, glcg, _w(power), _w(weights), levels, group,
        _PROFILE_GRIDS[0], _PROFILE_GRIDS[1], _w(jitter * st["jitter_width"]),
        st["ext_rows"], _w(extra), _w(screen), st["lo"], st["hi"], st["zlo"], st["zhi"],
        st["axes"], _w(hops), int(n_data_starts), int(n_keep), int(max_iter),
        int(max_rounds))
    if not np.isfinite(cb):
        return None
    return zb, ab, float(cb), int(rb), int(n_starts), int(n_evals)


def _fit_plain_compiled(model_obj, meas, sigma, source, *, columns=None, seed,
                        n_random_starts=2, n_screen=None, n_keep=None,
                        n_data_starts=None, max_iter=200, max_rounds=3, polish=True,
                        extra_starts=None, n_hops=None):
    """:func:`fit` of the plain two-lobe model with the compiled kernel: the checks of the
    data, the draws, the global search and fit()'s finish in one compiled call
    (:func:`irreflect._kernel.tl_fit`; the same search as :func:`_global_search`, the same
    numbers), so that a fit pays almost nothing in Python. Returns ``(found, finish,
    angles, flagged)``: ``found`` as :func:`_global_search` returns it (None: no finite
    start), ``finish`` the values of ``tl_finish`` (None when fit() has to compute them:
    after a polish), the exact angles of incidence and whether :func:`judge` would find
    anything to say (when not, fit() need not ask it). ``columns``: the table's gamma,
    theta and power as writeable copies (fit() keeps them in its result), else the
    table's own."""
    from . import _kernel

    p = model_obj.n_nonlinear
    st = _kernel_static(model_obj)
    n_screen, n_keep, n_data_starts = _search_defaults(model_obj, n_screen, n_keep,
                                                       n_data_starts)
    extra = (st["no_extra"] if extra_starts is None else
             np.clip(np.asarray(extra_starts, float).reshape(-1, p), st["zlo"], st["zhi"]))
    weighted = sigma is not None
    if columns is None:
        columns = (meas.gamma_deg, meas.theta_deg, meas.power)
    (status, z, alpha, cost, scale, reason, n_starts, n_evals, exact, finished,
     *finish, flagged) = _kernel.tl_fit(
        _w(columns[0]), _w(columns[1]), _w(columns[2]),
        _w(sigma) if weighted else st["no_sigma"], weighted, model_obj.n_params,
        st["nonneg"], st["residual"], _PROFILE_GRIDS[0], _PROFILE_GRIDS[1],
        _draws_mod.seed_key(seed), int(n_random_starts), n_screen,
        _default_hops(model_obj, n_keep) if n_hops is None else int(n_hops),
        st["jitter_width"], st["ext_rows"], _w(extra),
        st["lo"], st["hi"], st["zlo"], st["zhi"], st["axes"], st["plo"], st["phi"],
        int(n_data_starts), n_keep, int(max_iter), int(max_rounds))
    if status:  # the same one-line errors as the numpy path
        check_fit_data(meas.power, model_obj, source)
        if weighted:
            _check_sigma(sigma, source)
        raise FitError(f"fit of '{model_obj.name}' to {source}: the data were refused "
                       f"(status {status}) without a reason: please report this")
    if not math.isfinite(cost):
        return None, None, exact, flagged
    found = (z, alpha, float(cost), int(reason), int(n_starts), int(n_evals))
    if finished:  # _conclude's verdict on a search that met its tolerance
        message = _STOP_MESSAGES[reason].format(ftol=1e-10, xtol=1e-9, max_iter=max_iter)
        converged = reason in (STOP_FTOL, STOP_XTOL)
        return ((z, alpha * scale, cost * scale * scale, converged, message, int(n_starts),
                 int(n_evals)), finish, exact, flagged)
    gamma, theta, weights = _radians_and_weights(meas, sigma)
    zb, ab, cb, *rest = _conclude(model_obj, gamma, theta, meas.power / scale, weights, found,
                                  polish, max_iter)
    return (zb, ab * scale, cb * scale * scale, *rest), None, exact, True


def _radians_and_weights(meas, sigma) -> tuple:
    """A table's angles in radians and its weights ``1 / sigma^2`` (1 without sigma)."""
    weights = np.ones_like(meas.power) if sigma is None else 1.0 / sigma**2
    return np.radians(meas.gamma_deg), np.radians(meas.theta_deg), weights


def _check_sigma(sigma, source) -> None:
    if np.any(sigma <= 0):
        raise IrreflectError(
            f"{source}: sigma must be > 0 to weight a fit by 1/sigma^2, found "
            f"{int(np.sum(sigma <= 0))} zero or negative value(s): fix them or drop the "
            "sigma column to fit unweighted"
        )


def _kernel_static(model_obj) -> dict:
    """What the kernel needs of a model that does not change between fits (cached on the
    model object)."""
    cached = model_obj.options.get("_kernel_static")
    if cached is not None and cached[0] is model_obj:
        return cached[1]
    p = model_obj.n_nonlinear
    lo, hi = model_obj.screen_box()
    st = {
        "nonneg": _w(model_obj.alpha_nonneg, np.bool_),
        "residual": int(model_obj.options.get("residual_column", -1)),
        "lo": _w(lo), "hi": _w(hi),
        "zlo": _w(model_obj.z_lower.copy()),
        "zhi": _w(model_obj.z_upper.copy()),
        "axes": _w(np.array(_scan_axes(model_obj, 33)).reshape(p, 33)),
        "ext_rows": _w(_extension_start_rows(model_obj)),
        "jitter_width": _w(np.minimum(model_obj.z_upper - model_obj.z_lower, 10.0)),
        "no_extra": np.zeros((0, p)),
        "no_sigma": np.zeros(0),
        "plo": _w([q.lower for q in model_obj.params]),
        "phi": _w([q.upper for q in model_obj.params]),
    }
    try:
        model_obj.options["_kernel_static"] = (model_obj, st)
    except TypeError:
        pass
    return st


@functools.lru_cache(maxsize=64)
def _draws(seed, n_random: int, n_hops: int, rounds: int, p: int):
    """The random draws of one search (:mod:`irreflect._draws`; the kernel's tl_fit draws
    the same inside): normal jitter of the first start (times 0.15; the caller scales it)
    and the basin hops of every round (times 0.15; the caller scales them)."""
    key = _draws_mod.seed_key(seed)
    jitter = (0.15 * _draws_mod.normals(key, _draws_mod.STREAM_JITTER, n_random * p)
              ).reshape(n_random, p)
    hops = (0.15 * _draws_mod.normals(key, _draws_mod.STREAM_HOPS, rounds * n_hops * p)
            ).reshape(rounds, n_hops, p)
    jitter.flags.writeable = False
    hops.flags.writeable = False
    return jitter, hops


def _w(a, dtype=float) -> np.ndarray:
    """``a`` as a writeable C-contiguous array (a copy only when it is not one already):
    numba compiles a kernel once per argument type, and a read-only array (a
    Measurements column, a cached draw) is another type, so every argument is passed
    writeable and the cache that ``make`` warms is the one every caller uses."""
    if type(a) is np.ndarray and a.dtype == dtype:
        flags = a.flags
        if flags.c_contiguous and flags.writeable:
            return a
    return np.require(a, dtype, ("C", "W"))


def _kernel_geometry(gamma, theta):
    """The compiled kernel's geometry of one table, its exact angles of incidence (log cos)
    and the rounded ones of the per-angle decomposition (as model.lobe_profile), each
    point's index among the rounded ones, the exact angles of incidence."""
    from . import _kernel

    return _kernel.kernel_geometry(_w(gamma), _w(theta))


def _extension_start_rows(model) -> np.ndarray:
    """The starting values of the extensions' coordinates, as the extended models' own
    ``starts`` combine them (the first row with every extension's first value, then, one
    extension at a time, its other values): ``(rows, P - 5)``."""

    chain = []
    m = model
    while "wrapped" in m.options:
        chain.append(m.options["extension"])
        m = m.options["wrapped"]
    tails = [np.zeros(0)]
    for ext in reversed(chain):
        assert isinstance(ext, Extension)
        values = _start_rows(ext.z_starts, len(ext.nonlinear_names))
        tails = ([np.concatenate([t, values[0]]) for t in tails]
                 + [np.concatenate([tails[0], v]) for v in values[1:]])
    return np.array(tails, float).reshape(len(tails), -1)


#: The index grids of the per-angle decomposition, writeable copies for the kernel.
_PROFILE_GRIDS = (PROFILE_DIFFUSE_INDICES.copy(), PROFILE_SPECULAR_INDICES.copy())

#: Which implementation fits: "compiled" (the numba kernel, for the models it covers;
#: numpy for the others) or "numpy" (the reference implementation everywhere).
ENGINE = "compiled"
ENGINES = ("compiled", "numpy")


def _kernel_codes(model_obj, engine=None):
    """The kernel's code of ``model_obj`` when the compiled engine is to fit it, else None
    (models the kernel does not cover, or a model whose starts a caller replaced)."""
    engine = engine or ENGINE
    if engine not in ENGINES:

        raise unknown_name("fitting engine", str(engine), ENGINES)
    if engine != "compiled" or model_obj.options.get("canonical_starts") is not \
            model_obj.starts:
        return None
    cached = model_obj.options.get("_kernel_code")
    if cached is not None and cached[0] is model_obj:
        return cached[1]
    from . import _kernel  # deferred: numba costs ~1 s to import, the numpy path none

    code = _kernel.model_code(model_obj)
    try:
        model_obj.options["_kernel_code"] = (model_obj, code)
    except TypeError:
        pass
    return code


def _search_defaults(model_obj, n_screen, n_keep, n_data_starts) -> tuple[int, int, int]:
    """The screening candidates, the screened starts kept and the data-driven starts of a
    search: the caller's, else the model's defaults."""
    return (default_screen(model_obj) if n_screen is None else int(n_screen),
            default_keep(model_obj) if n_keep is None else int(n_keep),
            int(model_obj.options.get("n_data_starts", 2)) if n_data_starts is None
            else int(n_data_starts))


def _global_search_unit(model_obj, gamma, theta, power, weights, *, seed, n_random_starts=2,
                        n_screen=None, n_keep=None, n_data_starts=None, max_iter=200,
                        max_rounds=3, polish=True, engine=None, extra_starts=None,
                        kgeo=None, n_hops=None):
    codes = _kernel_codes(model_obj, engine)
    geom = sw1 = yw1 = None
    if codes is None:
        geom = Geometry.of(gamma[None], theta[None])
        sw1 = np.sqrt(weights)[None]
        yw1 = sw1 * power
    n_screen, n_keep, n_data_starts = _search_defaults(model_obj, n_screen, n_keep,
                                                       n_data_starts)
    search = _search_numpy if codes is None else _search_compiled
    found = search(model_obj, codes, gamma, theta, power, weights, geom, sw1, yw1, seed=seed,
                   n_random_starts=n_random_starts, n_screen=n_screen, n_keep=n_keep,
                   n_data_starts=n_data_starts, max_iter=max_iter, max_rounds=max_rounds,
                   extra_starts=extra_starts, kgeo=kgeo, n_hops=n_hops)
    if found is None:
        return None
    return _conclude(model_obj, gamma, theta, power, weights, found, polish, max_iter, geom)


def _conclude(model_obj, gamma, theta, power, weights, found, polish, max_iter, geom=None):
    """A search's end as fit() reports it: a crawling Levenberg-Marquardt polished
    (:func:`_polish`), convergence judged by the Gauss-Newton decrease where the iteration
    limit or a stuck step ended it, the message. ``found``: (z, alpha, cost, reason,
    n_starts, n_evals) of the power ``power``. Returns (z, alpha, cost, converged,
    message, n_starts, n_evals)."""
    zb, ab, cb, rb, n_starts, n_evals = found
    if rb in (STOP_STUCK, STOP_MAXITER) and geom is None:
        geom = Geometry.of(gamma[None], theta[None])
    if geom is not None:
        sw1 = np.sqrt(weights)[None]
        yw1 = sw1 * power
    if polish and rb in (STOP_STUCK, STOP_MAXITER) and model_obj.n_nonlinear:
        polished = _polish(model_obj, geom, zb, sw1, yw1)
        n_evals += polished[3]
        if polished[2] < cb:
            zb, ab, cb = polished[:3]
            rb = STOP_POLISHED if polished[4] else rb
    converged = rb in (STOP_FTOL, STOP_XTOL, STOP_POLISHED)
    if rb == STOP_STUCK or rb == STOP_MAXITER:
        decrease, _ = _gauss_newton_decrease(model_obj, geom, zb[None], sw1, yw1)
        converged = bool(decrease[0] <= 1e-6 * max(cb, 1e-300)) or cb == 0.0
    message = _STOP_MESSAGES[rb].format(ftol=1e-10, xtol=1e-9, max_iter=max_iter)
    if rb == STOP_MAXITER and converged:
        message = f"converged: {message}, first-order optimal"
    elif not converged and rb == STOP_STUCK:
        message = "no step lowers the cost, but the gradient is not small"
    return zb, ab, cb, converged, message, n_starts, n_evals


#: Tolerance (deg) when matching ``G`` of ``MODEL@G`` to a measured angle of incidence.
GAMMA_TOL_DEG = 1e-6


def points_at_incidence(measurements, gamma_abs_deg: float, label: str = "the fit"):
    """The points of one angle of incidence ``|gamma| = gamma_abs_deg`` (degrees), for a
    ``MODEL@G`` fit; a one-line error listing the measured ones when there are none."""
    meas = as_measurements(measurements)
    sel = np.abs(np.abs(meas.gamma_deg) - abs(gamma_abs_deg)) <= GAMMA_TOL_DEG
    if not sel.any():
        available = np.unique(np.abs(meas.gamma_deg))
        raise IrreflectError(
            f"{meas.name}: no measurements at |gamma| = {abs(gamma_abs_deg):g} deg to fit "
            f"'{label}'; found |gamma| = {short_list(available, fmt=lambda g: f'{g:g}')}: "
            "choose one of them after '@'"
        )
    return meas.subset(sel)


#: Tables of at most this many points get the search of :data:`SMALL_TABLE_SEARCH`.
SMALL_TABLE_POINTS = 40
#: The search on small tables: on the paper's 12-point protocol of each of the 11 real
#: sets, the large-table search (96 candidates, 3 kept, no hops, 3 rounds) reached the best
#: cost found in 60 of 110 fits (10 seeds per set; up to 68 % above it otherwise), this
#: one in 103 of 110, at 2-60 ms a fit (experiments/check_small_fits.py).
SMALL_TABLE_SEARCH = {"n_screen": 1000, "n_keep": 30, "n_hops": 30, "max_rounds": 8}
#: The second search of :func:`fit` when the first result looks like a local optimum (see
#: :func:`retry_reasons`): the search of :data:`SMALL_TABLE_SEARCH` on any table, and a
#: larger one on small tables (whose first search was already that one). On 2,000
#: tables of :func:`irreflect.synthetic.wild_material` (glossy, mirror-like, matte and
#: diffuse; 1 to 8 angles of incidence, steps of 1 to 20 deg; proportional and additive
#: noise, with and without sigma), the first search alone ended above the generating
#: coefficients' cost in 15, with the second search in 1; about half the tables are
#: searched twice (experiments/check_retry.py).
RETRY_SEARCH = SMALL_TABLE_SEARCH
RETRY_SMALL_TABLE_SEARCH = {"n_screen": 4000, "n_keep": 60, "n_hops": 30, "max_rounds": 8}
#: :func:`retry_reasons`: an R^2 below this, or (weighted by 1/sigma^2) a reduced chi^2
#: above the other, looks like a local optimum rather than the model's best.
RETRY_R2 = 0.95
RETRY_CHI2 = 2.0
#: The second search's result is kept when its cost is lower by more than this fraction.
RETRY_GAIN = 1e-9


def _search_effort(model_obj, n_points, n_screen=None, n_keep=None, n_hops=None,
                   max_rounds=None):
    """fit()'s search options: the caller's, else :data:`SMALL_TABLE_SEARCH` on a small
    table (and a model of 4 or more shape coordinates), else the model's defaults (None)
    and 3 rounds."""
    if n_points <= SMALL_TABLE_POINTS and model_obj.n_nonlinear >= 4:
        effort = SMALL_TABLE_SEARCH
        n_screen = effort["n_screen"] if n_screen is None else n_screen
        n_keep = effort["n_keep"] if n_keep is None else n_keep
        n_hops = effort["n_hops"] if n_hops is None else n_hops
        max_rounds = effort["max_rounds"] if max_rounds is None else max_rounds
    return n_screen, n_keep, n_hops, 3 if max_rounds is None else max_rounds


def fit(measurements, model="two-lobe", *, seed: int = 0, n_random_starts: int = 2,
        n_screen: int | None = None, n_keep: int | None = None,
        n_data_starts: int | None = None, use_sigma: bool = True, max_iter: int = 200,
        max_rounds: int | None = None, polish: bool = True, engine: str | None = None,
        extra_starts=None, n_hops: int | None = None, retry: bool = True) -> FitResult:
    """Fit a reflection model to a measurement table by global least squares.

    The search: (1) the model's data-driven starts (for the paper's models, from the
    per-angle-of-incidence decomposition of `irreflect.models.lobe_profile`: the
    mirror peak, its width, the diffuse floor) and seeded random perturbations of them;
    (2) a screening of the model's whole shape space (a grid for one or two nonlinear
    coordinates, a Latin hypercube beyond); the projected cost of every candidate is
    computed, and the ``n_data_starts`` best data-driven ones and the ``n_keep`` best
    *in different basins* are kept; (3) a batched bounded Levenberg-Marquardt from all of them, with the
    linear coefficients eliminated (variable projection); (4) global line searches through
    the best point along every coordinate, and Levenberg-Marquardt again from any better
    point, until none is found (at most ``max_rounds``). The scale of ``power`` does not
    change the shape coefficients.

    Parameters
    ----------
    measurements : Measurements, pandas.DataFrame or path
        Table with ``gamma_deg, theta_deg, power`` (degrees) and optional ``sigma``.
    model : str or ReflectionModel
        A specification ``name[:N][+extension...][@G]`` (see
        :mod:`irreflect.models.registry`; names from `irreflect.models.model_names`).
        With ``@G`` the model is fitted to the points of ``|gamma| = G`` degrees only (the
        paper's Phong at 10 deg, ``phong@10``) and the result describes those points
        (score it on all points with its ``predict``).
    seed : int
        Seeds the random extra starts and the screening; the same seed gives the same result.
    n_random_starts : int
        Random perturbations of the first data-driven start.
    n_screen, n_keep, n_data_starts : int
        Number of screening candidates (default by model size, see :data:`DEFAULT_SCREEN`);
        how many of all candidates, in different basins (default :func:`default_keep`),
        and how many of the best data-driven ones start Levenberg-Marquardt.
    use_sigma : bool
        Weight by ``1 / sigma^2`` when the table has ``sigma``.
    max_iter, max_rounds : int
        Iteration limit of each local search; rounds of coordinate scans (default 3).
    n_hops : int, optional
        Basin hops around the best point per round (default by model, see
        :func:`_default_hops`). On small tables (at most :data:`SMALL_TABLE_POINTS`
        points, a model of 4 or more shape coordinates: a 12-point protocol) the
        defaults of ``n_screen``, ``n_keep``, ``n_hops`` and ``max_rounds`` are those of
        :data:`SMALL_TABLE_SEARCH`: 7 coefficients on a dozen points leave a landscape of
        many basins of nearly equal cost, and such a fit costs milliseconds.
    polish : bool
        Finish a local search that crawled with scipy's trust-region least squares.
    engine : ``"compiled"``, ``"numpy"`` or None
        The compiled kernel (:mod:`irreflect._kernel`; the two-lobe model and its
        extensions) or the numpy reference implementation; None: :data:`ENGINE`.
    extra_starts : array (S, P), optional
        More starting points of the nonlinear coordinates, tried first (a warm start).
    retry : bool
        When the result looks like a local optimum (:func:`retry_reasons`: a coefficient
        at a bound or ill-determined, not converged, R^2 below :data:`RETRY_R2`, a
        weighted fit's reduced chi^2 above :data:`RETRY_CHI2`, or no fit beating a
        constant), search again with :data:`RETRY_SEARCH` (on small tables
        :data:`RETRY_SMALL_TABLE_SEARCH`), from the first result too, and keep the lower
        cost; the result's ``retried`` says why. The caller's larger sizes are kept.

    Returns
    -------
    FitResult
        With ``converged``, ``message``, ``at_bound``, ``ill_determined`` and ``warnings``.

    Raises
    ------
    DataError
        Constant or non-finite power, zero sigma, or no degree of freedom left.
    FitError
        No start reaches a finite optimum, non-finite coefficients, or a fit that cannot
        beat a constant (R^2 <= 0).
    """

    check_fit_options(seed=seed, n_random_starts=n_random_starts, n_screen=n_screen,
                      n_keep=n_keep, n_data_starts=n_data_starts, use_sigma=use_sigma,
                      max_iter=max_iter, max_rounds=max_rounds, polish=polish, n_hops=n_hops,
                      retry=retry)
    spec = parse_spec(model) if isinstance(model, str) and "@" in model else None
    extra_starts = check_starts(extra_starts, get_model(
        spec.model_text if spec is not None else model).n_nonlinear)
    if spec is not None and spec.at_gamma_deg is not None:  # 'phong@10': one incidence
        sub = points_at_incidence(as_measurements(measurements), spec.at_gamma_deg, str(spec))
        result = fit(sub, spec.model_text, seed=seed, n_random_starts=n_random_starts,
                     n_screen=n_screen, n_keep=n_keep, n_data_starts=n_data_starts,
                     use_sigma=use_sigma, max_iter=max_iter, max_rounds=max_rounds,
                     polish=polish, engine=engine, extra_starts=extra_starts,
                     n_hops=n_hops, retry=retry)
        return dataclasses.replace(result, model=str(spec))
    t0 = time.perf_counter()
    meas = as_measurements(measurements)  # a path is read once, for both searches
    options = dict(seed=seed, n_random_starts=n_random_starts, n_screen=n_screen,
                   n_keep=n_keep, n_data_starts=n_data_starts, use_sigma=use_sigma,
                   max_iter=max_iter, max_rounds=max_rounds, polish=polish, engine=engine,
                   extra_starts=extra_starts, n_hops=n_hops)
    try:
        result = _fit_search(meas, model, t0, **options)
        failure = None
    except FitError as exc:
        if not retry:
            raise
        result, failure = None, exc
    reasons = retry_reasons(result) if retry else ()
    if reasons:
        result = _search_again(meas, model, t0, result, failure, reasons, options)
    source = getattr(meas, "name", None) or "table"
    for text in result.warnings:
        warn(FitWarning(f"{source}, {result.model}: {text}"), stacklevel=2)
    return result


def retry_reasons(result) -> tuple[str, ...]:
    """Why a result looks like a local optimum rather than the model's best (empty: it
    does not): coefficients at a bound of their physical range or ill-determined, a
    local search that did not converge, R^2 below :data:`RETRY_R2`, a weighted fit's
    reduced chi^2 above :data:`RETRY_CHI2`, or (None) no fit that beats a constant.
    :func:`fit` searches again when there is any."""
    if result is None:
        return ("no fit beat a constant",)
    reasons = []
    if result.at_bound:
        reasons.append(f"at a bound: {', '.join(result.at_bound)}")
    if result.ill_determined:
        reasons.append(f"ill-determined: {', '.join(result.ill_determined)}")
    if not result.converged:
        reasons.append("not converged")
    if result.r2 < RETRY_R2:
        reasons.append(f"R^2 {result.r2:.4g} < {RETRY_R2:g}")
    if result.sigma is not None and result.chi2_reduced > RETRY_CHI2:
        reasons.append(f"reduced chi^2 {result.chi2_reduced:.4g} > {RETRY_CHI2:g}")
    saturated = result.saturated_gammas_deg
    if saturated.size:
        # where the share is 1 the curve no longer sees u_as and v_as: the landscape has
        # basins the unsaturated law has not (wild_material seeds 212, 1811: a grazing
        # angle saturated at 1.4x the generating coefficients' cost, no other sign)
        reasons.append("the specular share saturates at |gamma| = "
                       + ", ".join(f"{g:g}" for g in saturated) + " deg")
    return tuple(reasons)


def _search_again(meas, model, t0, first, failure, reasons, options):
    """:func:`fit`'s second search (:data:`RETRY_SEARCH`), from the first result too;
    the second result when its cost is lower by more than :data:`RETRY_GAIN`, else the
    first, marked ``retried``, with both searches' starts, evaluations and time."""
    effort = (RETRY_SMALL_TABLE_SEARCH if meas.n_points <= SMALL_TABLE_POINTS
              else RETRY_SEARCH)
    again = dict(options)
    for key, size in effort.items():
        again[key] = size if options[key] is None else max(int(options[key]), size)
    if first is not None:
        model_obj = first.model_object
        z_first = model_obj.from_natural(first.values[None])[0]
        extra = options["extra_starts"]
        again["extra_starts"] = (z_first if extra is None else np.vstack(
            [z_first, np.asarray(extra, float).reshape(-1, model_obj.n_nonlinear)]))
    try:
        second = _fit_search(meas, model, t0, **again)
    except FitError:
        if first is None:
            raise failure from None
        second = None
    # the second only when lower by more than rounding (1e-9): a tie along a flat
    # direction keeps the first, whatever the scale of power
    best = first if second is None or (
        first is not None and not second.cost < first.cost * (1.0 - RETRY_GAIN)) else second
    spent = [r for r in (first, second) if r is not None]
    outcome = ("the second search found a lower cost" if best is second else
               "the second search found no lower cost")
    return dataclasses.replace(
        best, retried=f"{'; '.join(reasons)}: {outcome}",
        fit_ms=(time.perf_counter() - t0) * 1e3,
        n_starts=sum(r.n_starts for r in spent), nfev=sum(r.nfev for r in spent))


def _fit_search(meas, model, t0, *, seed, n_random_starts, n_screen, n_keep,
                n_data_starts, use_sigma, max_iter, max_rounds, polish, engine,
                extra_starts, n_hops) -> FitResult:
    """One global search of :func:`fit` (its arguments, the table as Measurements; ``t0``
    when the fit began); the result's warnings are not issued here."""
    seed = check_seed(seed)
    model_obj = get_model(model)
    source = getattr(meas, "name", None) or "table"
    sigma = meas.sigma if (use_sigma and meas.sigma is not None) else None
    n_screen, n_keep, n_hops, max_rounds = _search_effort(
        model_obj, meas.n_points, n_screen, n_keep, n_hops, max_rounds)
    codes = _kernel_codes(model_obj, engine)
    plain = codes is not None and codes.size == 0
    finish = None
    flagged = True  # whether judge() may have anything to say
    columns = None  # the result's own copies of the table's columns
    if plain:  # the plain two-lobe model: checks, search and finish in one compiled call
        check_enough_points(meas.n_points, model_obj, source)
        columns = (meas.gamma_deg.copy(), meas.theta_deg.copy(), meas.power.copy())
        out, finish, angles, flagged = _fit_plain_compiled(
            model_obj, meas, sigma, source, columns=columns, seed=seed,
            n_random_starts=n_random_starts, n_screen=n_screen, n_keep=n_keep,
            n_data_starts=n_data_starts, max_iter=max_iter, max_rounds=max_rounds,
            polish=polish, extra_starts=extra_starts, n_hops=n_hops)
    else:
        check_fit_data(meas.power, model_obj, source)
        if sigma is not None:
            _check_sigma(sigma, source)
        gamma, theta, weights = _radians_and_weights(meas, sigma)
        kgeo = _kernel_geometry(gamma, theta) if codes is not None else None
        angles = gamma if kgeo is None else kgeo[4]
        out = _global_search(model_obj, gamma, theta, meas.power, weights, seed=seed,
                             n_random_starts=n_random_starts, n_screen=n_screen,
                             n_keep=n_keep, n_data_starts=n_data_starts, max_iter=max_iter,
                             max_rounds=max_rounds, polish=polish, engine=engine,
                             extra_starts=extra_starts, kgeo=kgeo, n_hops=n_hops)
    power = meas.power
    if out is None:
        raise FitError(
            f"fit of '{model_obj.name}' to {source} failed: no start reached a finite cost; "
            "check the data for extreme values"
        )
    zb, ab, cb, converged, message, n_starts, n_evals = out
    stderr = resid = finite = None
    validity = True  # whether judge() runs the model's own validity check
    if plain:  # the plain two-lobe model: one compiled call
        if finish is None:  # a polished search: its finish here
            from . import _kernel

            gamma, theta, weights = _radians_and_weights(meas, sigma)
            kgeo = _kernel_geometry(gamma, theta)
            finish = (*_kernel.tl_finish(_w(zb), _w(ab), kgeo[0], kgeo[1], _w(weights),
                                         _w(power), sigma is not None, cb, model_obj.n_params),
                      None, None, None)
        (values, round_trip, fitted, r2, rmse, mse, cov, singular, stderr, resid,
         finite) = finish
        validity = "validity" in model_obj.options
    else:
        values = model_obj.to_natural(zb[None], ab[None])[0]
        round_trip = None
    if not (np.all(np.isfinite(values)) if finite is None else finite):
        raise FitError(
            f"fit of '{model_obj.name}' to {source} ended at non-finite parameters "
            f"{np.array2string(values, precision=4)}: check the data for extreme values"
        )
    if round_trip is None:
        fitted, jfull = _fitted_and_jacobian(model_obj, zb, ab, gamma, theta, weights, engine,
                                             kgeo)
        z_back, a_back = model_obj.from_natural(values[None])
        round_trip = (np.allclose(z_back[0], zb, rtol=1e-9, atol=1e-12)
                      and np.allclose(a_back[0], ab, rtol=1e-6, atol=1e-9 * np.max(np.abs(ab))))
        r2 = metrics.r2(power, fitted)
        rmse, mse = metrics.rmse(power, fitted), metrics.mse(power, fitted)
        cov = singular = None
    if not round_trip:
        raise FitError(
            f"fit of '{model_obj.name}' to {source}: the coefficients "
            f"{np.array2string(values, precision=4)} do not reproduce the fitted curve in "
            "floating point (a share within 1e-16 of its bound): check the data for extreme "
            "values"
        )
    if resid is None:
        resid = power - fitted
    r2 = float(r2)
    if not np.isfinite(r2) or r2 <= 0:
        raise FitError(
            f"fit of '{model_obj.name}' to {source} cannot beat a constant (R^2 = {r2:.4g} "
            "<= 0): check that power is the reflected power and that the angles follow the "
            "convention (gamma < 0 on the source side, mirror at theta = -gamma)"
        )
    if cov is None:
        cov, singular = _covariance(model_obj, zb, ab, jfull, sigma is not None, cb,
                                    meas.n_points)
    if stderr is None:
        stderr = np.sqrt(np.clip(np.diag(cov), 0, None))
    # the distinct angles of incidence stand for all (judge's checks look at each once)
    if flagged or not converged or validity:
        at_bound, ill, warnings = judge(model_obj, values, stderr, singular, angles,
                                        converged, message, validity=validity)
    else:  # the kernel ran judge()'s tests on these numbers: nothing to say
        at_bound = ill = warnings = ()
    dof = meas.n_points - model_obj.n_params
    chi2 = float(2 * cb / dof) if sigma is not None else float("nan")
    elapsed = (time.perf_counter() - t0) * 1e3
    return FitResult(
        model=model_obj.name,
        param_names=model_obj.param_names,
        values=values,
        stderr=stderr,
        covariance=cov,
        r2=r2,
        rmse=float(rmse),
        mse=float(mse),
        chi2_reduced=chi2,
        residuals=resid,
        gamma_deg=meas.gamma_deg.copy() if columns is None else columns[0],
        theta_deg=meas.theta_deg.copy() if columns is None else columns[1],
        power=power.copy() if columns is None else columns[2],
        sigma=None if sigma is None else sigma.copy(),
        n_points=meas.n_points,
        n_params=model_obj.n_params,
        nfev=int(n_evals),
        n_starts=n_starts,
        fit_ms=elapsed,
        seed=seed,
        cost=cb,
        converged=converged,
        message=message,
        at_bound=at_bound,
        ill_determined=ill,
        warnings=warnings,
        model_object=model_obj,
    )


# ----------------------------------------------------------------------------- subsets
@dataclass(frozen=True)
class SubsetFits:
    """One fit per subset mask, and the R^2 of each fit against *all* points."""

    params: np.ndarray  # (B, k) natural parameters (NaN where the fit failed)
    r2_all: np.ndarray  # (B,) R^2 of the subset fit evaluated on all points
    cost: np.ndarray  # (B,) weighted least-squares cost on the subset
    failed: np.ndarray  # (B,) bool
    nfev: int
    converged: np.ndarray | None = None  # (B,) bool: the local search met its tolerance


def _subset_data_starts(model, gamma, theta, power, weights, g, t, y, valid):
    """Data-driven starts of every subset from its own points: ``(B, S, P)``.

    Batched (one call for all subsets) when the model offers ``batch_starts``; otherwise
    the model's ``starts`` per subset (the same number of rows for every subset)."""
    batch = model.options.get("batch_starts")
    if batch is not None:
        return np.asarray(batch(gamma, theta, power, weights), float)
    per_subset = [np.atleast_2d(np.asarray(model.starts(g[i, valid[i]], t[i, valid[i]],
                                                        y[i, valid[i]]), float))
                  for i in range(g.shape[0])]
    k0 = min(len(x) for x in per_subset)
    return np.stack([x[:k0] for x in per_subset])


def fit_subsets(gamma_deg, theta_deg, power, masks, model="two-lobe", *, sigma=None,
                max_iter: int = 40, ftol: float = 1e-8, n_screen: int = 32, n_keep: int = 2,
                data_starts: bool = True, n_data_starts: int = 1, scan: bool = False,
                exhaustive: bool = False, seed: int = 0, engine: str | None = None,
                shared_starts=None) -> SubsetFits:
    """Fit the model to every subset in ``masks`` (B, n) independently, in one batch.

    Each subset fit sees only its own points. Its starts are chosen as in :func:`fit`:
    ``n_screen`` screening candidates of the model's shape space (the same for every
    subset) and, with ``data_starts``, the model's data-driven starts from the subset's
    own points (for the paper's models, its per-angle lobe decomposition, batched over
    all subsets) are scored by the projected cost **on the subset's points**;
    Levenberg-Marquardt runs from the best data-driven start and the ``n_keep`` best
    candidates. With ``scan``, global line searches along every coordinate follow (as in
    :func:`fit`), and Levenberg-Marquardt again from any better point. Nothing from the
    points outside the subset is used. The fit's R^2 is then measured against all ``n``
    points, as a technician who measured only that subset would get. Subsets with fewer
    points than parameters, or whose fit fails, are marked failed with R^2 = 0 (score
    1 - R^2 = 1).

    With ``exhaustive``, every subset gets the complete search of :func:`fit` (one
    subset at a time; the screening options above are then ignored): the subset fit is
    then exactly ``fit`` on the subset's table, for the final check of reported subsets.

    ``shared_starts`` (S, P): more shape candidates scored on every subset beside the
    screening ones (the optimiser passes the optima of the best subsets it has seen:
    starts only, each subset's optimum is still that of its own points).
    """
    model_obj = get_model(model)
    check_fit_options(seed=seed, max_iter=max_iter, ftol=ftol, n_screen=n_screen,
                      n_keep=n_keep, data_starts=data_starts, n_data_starts=n_data_starts,
                      scan=scan, exhaustive=exhaustive)
    shared_starts = check_starts(shared_starts, model_obj.n_nonlinear, "shared_starts")
    seed = check_seed(seed)
    gamma_deg, theta_deg, power, masks, sigma = check_subset_inputs(gamma_deg, theta_deg, power,
                                                                    masks, sigma)
    gamma = np.radians(gamma_deg)
    theta = np.radians(theta_deg)
    b, n = masks.shape
    p_dim = model_obj.n_nonlinear
    weights_all = np.ones(n) if sigma is None else 1.0 / np.asarray(sigma, float) ** 2
    counts = masks.sum(axis=1)
    ok = counts >= model_obj.n_params
    if exhaustive:
        return _fit_subsets_one_by_one(model_obj, gamma, theta, power, masks, weights_all, ok,
                                       seed, engine)
    codes = _kernel_codes(model_obj, engine)
    if codes is not None and data_starts and not scan and p_dim:
        return _fit_subsets_compiled(model_obj, codes, gamma, theta, power, masks, weights_all,
                                     ok, n_screen=n_screen, n_keep=n_keep,
                                     n_data_starts=n_data_starts, max_iter=max_iter,
                                     ftol=ftol, seed=seed, shared_starts=shared_starts)
    n_max = max(int(counts.max()) if b else 0, 1)
    # gather every subset into a padded (B, n_max) problem with zero weight on padding
    order = np.argsort(~masks, axis=1, kind="stable")[:, :n_max]
    valid = np.take_along_axis(masks, order, axis=1)
    g, t, y = gamma[order], theta[order], power[order]
    sw = np.sqrt(np.where(valid, weights_all[order], 0.0))
    geom = Geometry.of(g, t)
    cands = screen_samples(model_obj, n_screen, seed) if n_screen else np.empty((0, p_dim))
    if shared_starts is not None and len(shared_starts):
        cands = np.vstack([cands, np.asarray(shared_starts, float).reshape(-1, p_dim)])
    cands = np.clip(cands, model_obj.z_lower, model_obj.z_upper)
    parts_z, parts_cost = [], []
    n_data = 0
    if data_starts or not len(cands):
        extra = _subset_data_starts(model_obj, gamma, theta, power, masks * weights_all,
                                    g, t, y, valid)
        extra = np.clip(extra, model_obj.z_lower, model_obj.z_upper)  # (B, S, P)
        n_data = extra.shape[1]
        rep_e = lambda a: np.repeat(a, n_data, axis=0)  # noqa: E731
        cost_extra = _screen_costs(model_obj, geom.repeat(n_data),
                                   extra.reshape(b * n_data, -1), rep_e(sw),
                                   rep_e(sw * y)).reshape(b, n_data)
        parts_z.append(extra)
        parts_cost.append(cost_extra)
    if len(cands):
        # the shared candidates' basis is computed once on all points and gathered per
        # subset (the same numbers as on each subset, without the repeated trigonometry)
        with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):
            basis_all, _ = model_obj.basis(Geometry.of(gamma[None], theta[None]), cands, False)
        gathered = basis_all[:, order, :].transpose(1, 0, 2, 3)  # (B, C, n_max, L)
        k = len(cands)
        rep_k = lambda a: np.repeat(a, k, axis=0)  # noqa: E731
        factor = None
        if model_obj.share_cap:  # (B, C, n_max): each candidate's v_as at each subset's gammas
            with np.errstate(over="ignore", under="ignore"):
                factor = np.exp(cands[None, :, :1] * np.log(np.cos(g))[:, None, :])
            factor = factor.reshape(b * k, n_max)
        cost_shared = _projected_cost(model_obj, gathered.reshape(b * k, n_max, -1), rep_k(sw),
                                      rep_k(sw * y), factor).reshape(b, k)
        parts_z.append(np.broadcast_to(cands, (b,) + cands.shape))
        parts_cost.append(cost_shared)
    all_cands = np.concatenate(parts_z, axis=1)
    screen = np.concatenate(parts_cost, axis=1)
    c = all_cands.shape[1]
    picks = [np.argsort(screen, axis=1, kind="stable")[:, :min(n_keep, c)]]
    if n_data:
        picks.append(np.argsort(screen[:, :n_data], axis=1, kind="stable")[:, :n_data_starts])
    best_idx = np.concatenate(picks, axis=1)
    keep = best_idx.shape[1]
    starts = np.take_along_axis(all_cands, best_idx[:, :, None], axis=1)  # (B, keep, P)
    rep = lambda a: np.repeat(a, keep, axis=0)  # noqa: E731
    z, state, nfev, reason = _levenberg_marquardt(
        model_obj, geom.repeat(keep), starts.reshape(b * keep, -1),
        rep(sw), rep(sw * y), max_iter=max_iter, ftol=ftol,
    )
    nfev_total = int(nfev.sum()) + b * c
    cost = state["cost"].reshape(b, keep)
    best = np.argmin(cost, axis=1)
    flat = np.arange(b) * keep + best
    zb, ab = z[flat], state["alpha"][flat]
    best_cost = cost[np.arange(b), best]
    conv = np.isin(reason[flat], (STOP_FTOL, STOP_XTOL, STOP_STUCK))
    if scan and p_dim:
        zb, ab, best_cost, conv, extra_fev = _scan_subsets(model_obj, geom, zb, ab, best_cost,
                                                           conv, sw, y, max_iter, ftol)
        nfev_total += extra_fev
    params = model_obj.to_natural(zb, ab)
    failed = ~ok | ~np.isfinite(best_cost) | ~np.all(np.isfinite(params), axis=1)
    safe = np.where(failed[:, None], _placeholder_params(model_obj, params), params)
    pred = model_obj.predict(safe, gamma, theta)
    r2_all = np.asarray(metrics.r2(power, pred), float).reshape(b)
    r2_all = np.where(failed | ~np.isfinite(r2_all), 0.0, r2_all)
    params = np.where(failed[:, None], np.nan, params)
    return SubsetFits(params=params, r2_all=r2_all, cost=np.where(failed, np.inf, best_cost),
                      failed=failed, nfev=nfev_total, converged=conv & ~failed)


def _fit_subsets_compiled(model, codes, gamma, theta, power, masks, weights, ok, *, n_screen,
                          n_keep, n_data_starts, max_iter, ftol, seed, shared_starts=None):
    """The batched subset search in the compiled kernel (see :func:`fit_subsets`)."""
    from . import _kernel

    st = _kernel_static(model)
    geo, glcg, levels, group = _kernel_geometry(gamma, theta)[:4]
    p = model.n_nonlinear
    screen = screen_samples(model, n_screen, seed) if n_screen else np.zeros((0, p))
    if shared_starts is not None and len(shared_starts):
        screen = np.vstack([screen, np.asarray(shared_starts, float).reshape(-1, p)])
    z, alpha, cost, conv, nfev = _kernel.subset_search(
        codes, st["nonneg"], st["residual"], geo, glcg, _w(power), _w(weights),
        _w(masks, np.bool_), levels, group, _PROFILE_GRIDS[0], _PROFILE_GRIDS[1],
        _w(st["ext_rows"][0]), _w(screen), st["zlo"], st["zhi"], int(n_keep),
        int(n_data_starts), int(max_iter), float(ftol))
    r2 = _kernel.r2_rows(codes, _w(z), _w(alpha), geo, glcg, _w(power))
    return _subset_result(model, gamma, theta, power, z, alpha, cost, conv, ok, int(nfev), r2)


def _subset_result(model, gamma, theta, power, z, alpha, cost, conv, ok, nfev,
                   r2=None) -> SubsetFits:
    """SubsetFits from the per-subset optimum (z, alpha, cost): natural parameters, R^2 on
    all points (computed here unless given), failures (too few points, no finite
    optimum) marked."""
    b = z.shape[0]
    finite = np.isfinite(cost) & np.all(np.isfinite(z), axis=1) & np.all(np.isfinite(alpha),
                                                                          axis=1)
    params = model.to_natural(np.where(finite[:, None], z, 0.0),
                              np.where(finite[:, None], alpha, 0.0))
    failed = ~ok | ~finite | ~np.all(np.isfinite(params), axis=1)
    if r2 is None:
        safe = np.where(failed[:, None], _placeholder_params(model, params), params)
        r2 = np.asarray(metrics.r2(power, model.predict(safe, gamma, theta)), float).reshape(b)
    r2_all = np.where(failed | ~np.isfinite(r2), 0.0, r2)
    return SubsetFits(params=np.where(failed[:, None], np.nan, params), r2_all=r2_all,
                      cost=np.where(failed, np.inf, cost), failed=failed, nfev=nfev,
                      converged=np.asarray(conv, bool) & ~failed)


def _fit_subsets_one_by_one(model, gamma, theta, power, masks, weights, ok, seed, engine=None):
    """``fit``'s global search on every subset in turn (see :func:`fit_subsets`)."""
    b = masks.shape[0]
    zs = np.full((b, model.n_nonlinear), np.nan)
    alphas = np.full((b, model.n_linear), np.nan)
    cost = np.full(b, np.inf)
    conv = np.zeros(b, bool)
    nfev = 0
    for i in np.flatnonzero(ok):
        m = masks[i]
        n_screen, n_keep, n_hops, max_rounds = _search_effort(model, int(m.sum()))
        out = _global_search(model, gamma[m], theta[m], power[m], weights[m], seed=seed,
                             engine=engine, n_screen=n_screen, n_keep=n_keep, n_hops=n_hops,
                             max_rounds=max_rounds)
        if out is None:
            continue
        zs[i], alphas[i], cost[i], conv[i], _, _, evals = out
        nfev += evals
    return _subset_result(model, gamma, theta, power, zs, alphas, cost, conv, ok, nfev)


def _scan_subsets(model, geom, zb, ab, cost, conv, sw, y, max_iter, ftol, rounds=2):
    """:func:`_coordinate_scan` for every subset of a batch, and Levenberg-Marquardt from
    the best point found per subset; returns the updated (z, alpha, cost, converged, nfev)."""
    blocks = _scan_blocks(model)
    b = zb.shape[0]
    nfev = 0
    for _ in range(rounds):
        cand = np.stack([_block_candidates(zb[i], blocks) for i in range(b)])  # (B, m, P)
        m = cand.shape[1]
        sc = _screen_costs(model, geom.repeat(m),
                           cand.reshape(b * m, -1), np.repeat(sw, m, axis=0),
                           np.repeat(sw * y, m, axis=0)).reshape(b, m)
        nfev += b * m
        j = np.argmin(sc, axis=1)
        improve = sc[np.arange(b), j] < cost * (1.0 - 1e-9)
        if not improve.any():
            break
        rows = np.flatnonzero(improve)
        sub = geom.take(rows)
        z2, st2, nf2, reason2 = _levenberg_marquardt(model, sub, cand[rows, j[rows]], sw[rows],
                                                     sw[rows] * y[rows], max_iter=max_iter,
                                                     ftol=ftol)
        nfev += int(nf2.sum())
        better = st2["cost"] < cost[rows]
        upd = rows[better]
        zb, ab, cost, conv = zb.copy(), ab.copy(), cost.copy(), conv.copy()
        zb[upd], ab[upd], cost[upd] = z2[better], st2["alpha"][better], st2["cost"][better]
        conv[upd] = np.isin(reason2[better], (STOP_FTOL, STOP_XTOL, STOP_STUCK))
    return zb, ab, cost, conv, nfev


def _placeholder_params(model_obj, params):
    """A harmless parameter vector to evaluate in place of failed fits (then discarded)."""
    z = 0.5 * (model_obj.z_lower + model_obj.z_upper)[None]
    alpha = np.ones((1, model_obj.n_linear))
    return np.broadcast_to(model_obj.to_natural(z, alpha), params.shape)
