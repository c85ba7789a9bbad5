"""The local solver (numpy): a batched, bounded Levenberg-Marquardt on the nonlinear
coordinates (the linear ones eliminated, :mod:`.linear`), scipy's trust-region polish of a
search that crawled, the Gauss-Newton decrease that judges convergence, and why a search
stopped. The compiled side: :mod:`.local_kernel`.
"""

from __future__ import annotations

import numpy as np

from .linear import _evaluate, _kaufman_jacobian

#: Values (problems x points x nonlinear coordinates) of one piece of a batched local
#: search in numpy: the problems are independent, so a batch too big for memory runs in
#: pieces with the same result (a Lafortune fit of a 200,000-point table held 4.3 GB in one
#: batch). About 64 MB per Jacobian; no batch of the real sets' 1261 points is cut.
LM_PIECE_VALUES = 8_000_000


def _levenberg_marquardt(model, geom, z0, sw, yw, max_iter=200, ftol=1e-10, xtol=1e-9):
    """Bounded LM for a batch of M problems; returns z, state, nfev (M,), converged (M,).

    ``geom`` is a :class:`~irreflect.models.Geometry` of arrays ``(1, n)`` shared by
    every problem or ``(M, n)``, one row per problem. Run in pieces of at most
    :data:`LM_PIECE_VALUES` Jacobian values."""
    z0 = np.asarray(z0, float)
    m, p = z0.shape
    n = np.shape(yw)[-1]
    step = max(1, LM_PIECE_VALUES // max(1, n * max(p, 1)))
    if m <= step:
        with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):
            return _lm_loop(model, geom, z0, sw, yw, max_iter, ftol, xtol)

    def rows(a, lo, hi):
        return a[lo:hi] if np.shape(a)[0] == m else a

    pieces = []
    for lo in range(0, m, step):
        hi = min(m, lo + step)
        g = geom if geom.rows == 1 else geom.take(slice(lo, hi))
        with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):
            pieces.append(_lm_loop(model, g, z0[lo:hi], rows(sw, lo, hi), rows(yw, lo, hi),
                                   max_iter, ftol, xtol))
    z = np.concatenate([q[0] for q in pieces])
    state = {k: np.concatenate([q[1][k] for q in pieces]) for k in pieces[0][1]}
    return (z, state, np.concatenate([q[2] for q in pieces]),
            np.concatenate([q[3] for q in pieces]))


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


_STOP_MESSAGES = {
    STOP_FTOL: "converged: relative change of the cost below {ftol:g}",
    STOP_XTOL: "converged: step below {xtol:g}",
    STOP_STUCK: "converged: no step lowers the cost further",
    STOP_MAXITER: "iteration limit ({max_iter}) reached",
    STOP_NONFINITE: "the cost is not finite at the start",
    STOP_POLISHED: "converged: Levenberg-Marquardt crawled, a trust-region least-squares "
                   "polish met its tolerance (1e-12)",
}
