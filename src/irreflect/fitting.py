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

import time
from dataclasses import dataclass, field

import numpy as np

from . import metrics
from .errors import FitError, IrreflectError
from .model import ReflectionModel, get_model, plane_geometry, take_geometry
from .validation import check_angles_deg, check_seed, check_subset_inputs

# ----------------------------------------------------------------------------- core solver
_RIDGE = 1e-12
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


def _solve_linear(bw, yw, nonneg):
    """Weighted (non-negative) linear least squares for every problem of a batch.

    bw : (M, n, L) basis times sqrt(weight); yw : (M, n) data times sqrt(weight);
    nonneg : (L,) bool. Returns alpha (M, L), the mask of free columns (M, L) and the
    inverse of the (free-column) Gram matrix (M, L, L), reused for the Jacobian.
    """
    m, _, n_lin = bw.shape
    bwt = bw.swapaxes(1, 2)
    gram = bwt @ bw
    rhs = (bwt @ yw[:, :, None])[:, :, 0]
    eye = _EYES[n_lin] if n_lin < len(_EYES) else np.eye(n_lin)
    diag = np.diagonal(gram, axis1=1, axis2=2)
    scale = np.maximum(diag, 1e-300)
    inv = _small_inverse(gram + eye * (_RIDGE * scale)[:, :, None])
    alpha = (inv @ rhs[:, :, None])[:, :, 0]
    nonneg = np.asarray(nonneg, bool)
    free = np.ones((m, n_lin), bool)
    bad = (alpha < 0) & nonneg
    if not bad.any():
        return alpha, free, inv
    # active set: drop the most negative coefficient of each offending problem and re-solve
    rows = np.nonzero(bad.any(axis=1))[0]
    for _ in range(n_lin):
        rel = np.where(bad[rows], alpha[rows] * np.sqrt(scale[rows]), np.inf)
        free[rows, np.argmin(rel, axis=1)] = False
        fr = free[rows]
        g = gram[rows] * (fr[:, :, None] & fr[:, None, :])
        g = g + eye * np.where(fr, _RIDGE * scale[rows], 1.0)[:, :, None]
        inv_r = _small_inverse(g) * (fr[:, :, None] & fr[:, None, :])
        alpha_r = (inv_r @ (rhs[rows] * fr)[:, :, None])[:, :, 0]
        inv[rows] = inv_r
        alpha[rows] = alpha_r
        still = ((alpha_r < 0) & nonneg & fr).any(axis=1)
        if not still.any():
            break
        rows = rows[still]
        bad = (alpha < 0) & nonneg & free
    alpha = np.where(free, alpha, 0.0)
    return alpha, free, inv


def _evaluate(model, geom, z, sw, yw):
    """Basis, optimal linear coefficients, residuals and cost for a batch of ``z``."""
    basis, dbasis = model.basis(geom, z, True)
    bw = basis * sw[:, :, None]
    alpha, free, inv = _solve_linear(bw, yw, model.alpha_nonneg)
    resid = yw - (bw @ alpha[:, :, None])[:, :, 0]
    cost = 0.5 * np.einsum("ij,ij->i", resid, resid)
    cost[~np.isfinite(cost)] = np.inf
    if not free.all():
        bw = bw * free[:, None, :]
    return {"dbasis": dbasis, "bw": bw, "alpha": alpha, "inv": inv, "resid": resid, "cost": cost}


def _kaufman_jacobian(state, sw):
    """Jacobian of the projected residual with respect to ``z`` (Kaufman 1975):
    ``-(I - P_B) dB/dz alpha``, with ``P_B`` the projection on the free basis columns."""
    bw = state["bw"]
    dbasis, alpha = state["dbasis"], state["alpha"]
    jm = dbasis[:, :, 0, :] * alpha[:, None, 0:1]
    for col in range(1, alpha.shape[1]):
        jm += dbasis[:, :, col, :] * alpha[:, None, col : col + 1]
    jm *= sw[:, :, None]
    coef = state["inv"] @ (bw.swapaxes(1, 2) @ jm)
    return bw @ coef - jm


def _levenberg_marquardt(model, geom, z0, sw, yw, max_iter=200, ftol=1e-10, xtol=1e-9):
    """Bounded LM for a batch of M problems; returns z, state, nfev (M,), converged (M,).

    ``geom`` is :func:`~irreflect.model.plane_geometry` of arrays ``(1, n)`` shared by
    every problem or ``(M, n)``, one row per problem."""
    with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):
        return _lm_loop(model, geom, z0, sw, yw, max_iter, ftol, xtol)


def _lm_loop(model, geom, z0, sw, yw, max_iter, ftol, xtol):
    lo, hi = model.z_lower, model.z_upper
    z = np.clip(np.asarray(z0, float), lo, hi)
    m, p = z.shape
    shared_geometry = geom["gamma"].shape[0] == 1
    state = _evaluate(model, geom, z, sw, yw)
    nfev = np.ones(m, int)
    lam = np.full(m, 1e-3)
    active = np.isfinite(state["cost"])
    converged = np.zeros(m, bool)
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
            geom_i = geom if shared_geometry else take_geometry(geom, idx)
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
        if idx is None:
            nfev += 1
            lam = lam_new
            if better.all():
                state, z = trial, z_trial
            else:
                for k in state:
                    state[k][better] = trial[k][better]
                z[better] = z_trial[better]
            converged |= done & ~stuck
            active &= ~done
        else:
            nfev[idx] += 1
            lam[idx] = lam_new
            acc = idx[better]
            for k in state:
                state[k][acc] = trial[k][better]
            z[acc] = z_trial[better]
            converged[idx[done & ~stuck]] = True
            active[idx[done]] = False
    return z, state, nfev, converged


# ----------------------------------------------------------------------------- results
@dataclass(frozen=True)
class FitResult:
    """Outcome of one fit. Frozen: the fitter is not kept inside it."""

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
    message: str = "converged"
    model_object: ReflectionModel | None = field(default=None, repr=False, compare=False)

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
        }

    def report(self) -> str:
        """Readable fit report: coefficients with errors, quality, per-gamma polar error."""
        lines = [
            f"model {self.model}: {self.n_points} points, {self.n_params} parameters, "
            f"{self.n_starts} starts, {self.nfev} evaluations, {self.fit_ms:.1f} ms",
            f"{'parameter':<10}{'value':>14}{'std. error':>14}",
        ]
        for name, v, s in zip(self.param_names, self.values, self.stderr, strict=True):
            lines.append(f"{name:<10}{v:>14.6g}{s:>14.3g}")
        lines.append(f"R^2 = {self.r2:.6f}   RMSE = {self.rmse:.6g}   MSE = {self.mse:.6g}")
        if self.sigma is not None:
            lines.append(f"reduced chi^2 = {self.chi2_reduced:.4g} (weighted by 1/sigma^2)")
        errors = self.polar_errors()
        if errors:
            lines.append("relative polar-area error per angle of incidence (section 5.3):")
            lines.append("  " + "  ".join(f"{g:g} deg: {e:.2f}%" for g, e in errors.items()))
        return "\n".join(lines)


# ----------------------------------------------------------------------------- fit()
def _covariance(model, z, alpha, gamma, theta, weights, absolute_sigma, cost, n_points):
    """Covariance of the natural parameters from the Jacobian in (z, alpha)."""
    basis, dbasis = model.basis(plane_geometry(gamma[None], theta[None]), z[None], True)
    jz = np.einsum("mnlp,ml->mnp", dbasis, alpha[None])[0]
    jfull = np.concatenate([jz, basis[0]], axis=1) * np.sqrt(weights)[:, None]
    info = jfull.T @ jfull
    dof = max(n_points - model.n_params, 1)
    s2 = 1.0 if absolute_sigma else 2.0 * cost / dof
    # inverse through the symmetric eigen-decomposition; directions the data do not
    # determine keep a huge (floored) variance, so their standard errors show it
    evals, evecs = np.linalg.eigh(info)
    evals = np.maximum(evals, 1e-14 * max(evals.max(), 1e-300))
    cov_internal = (evecs / evals) @ evecs.T * s2
    # chain rule to natural parameters, by central differences of the smooth map (one batch)
    x0 = np.concatenate([z, alpha])
    p_dim = z.size
    steps = 1e-6 * np.maximum(np.abs(x0), 1e-3)
    pert = np.concatenate([x0 + np.diag(steps), x0 - np.diag(steps)])
    nat = model.to_natural(pert[:, :p_dim], pert[:, p_dim:])
    grad = ((nat[: x0.size] - nat[x0.size:]) / (2 * steps[:, None])).T
    return grad @ cov_internal @ grad.T


_SCREEN_CACHE: dict = {}


def screen_samples(model, n: int, seed: int) -> np.ndarray:
    """``n`` Latin-hypercube points in the model's screening box (deterministic per seed).

    Every coordinate's range is cut into ``n`` strata and each stratum is sampled once
    (McKay, Beckman and Conover 1979). Plain numpy on purpose: ``scipy.stats.qmc`` would
    cost every command a second of import time for the same coverage of the box.
    """
    key = (model.name, model.n_nonlinear, n, seed)
    if key not in _SCREEN_CACHE:
        lo, hi = model.screen_box()
        rng = np.random.default_rng(seed)
        strata = rng.permuted(np.tile(np.arange(n), (lo.size, 1)), axis=1).T
        unit = (strata + rng.random((n, lo.size))) / n
        _SCREEN_CACHE[key] = lo + unit * (hi - lo)
    return _SCREEN_CACHE[key]


def _screen_costs(model, geom, z, sw, yw):
    """Variable-projection cost of every candidate ``z`` (no derivatives): a cheap global look."""
    with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):
        basis, _ = model.basis(geom, z, False)
    return _projected_cost(model, basis, sw, yw)


def _projected_cost(model, basis, sw, yw):
    """Cost after eliminating the linear coefficients, for basis values ``(M, n, L)``."""
    with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):
        bw = basis * sw[:, :, None]
        alpha, _, _ = _solve_linear(bw, yw, model.alpha_nonneg)
        resid = yw - (bw @ alpha[:, :, None])[:, :, 0]
        cost = 0.5 * np.einsum("ij,ij->i", resid, resid)
    cost[~np.isfinite(cost)] = np.inf
    return cost


def _candidates(model, gamma_rad, theta_rad, power, seed, n_random, n_screen):
    """Data-driven starts, seeded random perturbations of the first, and screening samples."""
    starts = np.asarray(model.starts(gamma_rad, theta_rad, power), float)
    parts = [starts]
    if n_random:
        rng = np.random.default_rng(seed)
        width = model.z_upper - model.z_lower
        jitter = rng.normal(0.0, 0.15, (n_random, starts.shape[1])) * np.minimum(width, 10.0)
        parts.append(starts[0] + jitter)
    if n_screen:
        parts.append(screen_samples(model, n_screen, seed))
    return np.clip(np.vstack(parts), model.z_lower, model.z_upper)


def fit(measurements, model="two-lobe", *, seed: int = 0, n_random_starts: int = 2,
        n_screen: int = 64, n_keep: int = 3, use_sigma: bool = True,
        max_iter: int = 200) -> FitResult:
    """Fit a reflection model to a measurement table by global least squares.

    Parameters
    ----------
    measurements : Measurements, pandas.DataFrame or path
        Table with ``gamma_deg, theta_deg, power`` (degrees) and optional ``sigma``.
    model : str or ReflectionModel
        Registry name (see :func:`irreflect.model.model_names`).
    seed : int
        Seeds the random extra starts; the same seed gives the same result.
    n_random_starts : int
        Random starts added to the data-driven ones.
    n_screen, n_keep : int
        Global screening: the projected cost is evaluated at the data-driven starts, the
        random ones and ``n_screen`` Latin-hypercube points of the model's plausible box
        (one batched evaluation); Levenberg-Marquardt then runs from the ``n_keep`` best.
    use_sigma : bool
        Weight by ``1 / sigma^2`` when the table has ``sigma``.

    Returns
    -------
    FitResult

    Raises
    ------
    FitError
        If no start reaches a finite optimum.
    DataError
        If the table has fewer points than the model has parameters.
    """
    from .data import as_measurements, check_enough_points

    t0 = time.perf_counter()
    seed = check_seed(seed)
    meas = as_measurements(measurements)
    model_obj = get_model(model)
    check_enough_points(meas.n_points, model_obj)
    gamma = np.radians(meas.gamma_deg)
    theta = np.radians(meas.theta_deg)
    power = meas.power
    sigma = meas.sigma if (use_sigma and meas.sigma is not None) else None
    if sigma is not None and np.any(sigma <= 0):
        raise IrreflectError(
            "sigma must be > 0 to weight a fit by 1/sigma^2: found zero sigma; "
            "drop the column or fit with use_sigma=False"
        )
    weights = np.ones_like(power) if sigma is None else 1.0 / sigma**2
    geom = plane_geometry(gamma[None], theta[None])
    candidates = _candidates(model_obj, gamma, theta, power, seed, n_random_starts, n_screen)
    sw1 = np.sqrt(weights)[None]
    screen = _screen_costs(model_obj, geom, candidates, sw1,
                           np.broadcast_to(sw1 * power, (len(candidates), power.size)))
    order = np.argsort(screen, kind="stable")
    starts = candidates[order[: max(1, min(n_keep, len(order)))]]
    s = starts.shape[0]
    sw = np.broadcast_to(sw1, (s, power.size)).copy()
    yw = sw * power
    z, state, nfev, _ = _levenberg_marquardt(model_obj, geom, starts, sw, yw, max_iter=max_iter)
    nfev = nfev.sum() + len(candidates)
    cost = state["cost"]
    if not np.any(np.isfinite(cost)):
        raise FitError(
            f"fit of '{model_obj.name}' failed: no start reached a finite cost "
            f"({len(candidates)} candidates screened, {s} starts tried); check the data for "
            "extreme values"
        )
    best = int(np.argmin(cost))
    zb, ab = z[best], state["alpha"][best]
    values = model_obj.to_natural(zb[None], ab[None])[0]
    if not np.all(np.isfinite(values)):
        raise FitError(f"fit of '{model_obj.name}' ended at non-finite parameters {values}")
    fitted = model_obj.predict(values, gamma, theta)
    resid = power - fitted
    cov = _covariance(model_obj, zb, ab, gamma, theta, weights, sigma is not None,
                      float(cost[best]), meas.n_points)
    dof = max(meas.n_points - model_obj.n_params, 1)
    chi2 = float(2 * cost[best] / dof) if sigma is not None else float("nan")
    elapsed = (time.perf_counter() - t0) * 1e3
    return FitResult(
        model=model_obj.name,
        param_names=model_obj.param_names,
        values=values,
        stderr=np.sqrt(np.clip(np.diag(cov), 0, None)),
        covariance=cov,
        r2=metrics.r2(power, fitted),
        rmse=metrics.rmse(power, fitted),
        mse=metrics.mse(power, fitted),
        chi2_reduced=chi2,
        residuals=resid,
        gamma_deg=meas.gamma_deg.copy(),
        theta_deg=meas.theta_deg.copy(),
        power=power.copy(),
        sigma=None if sigma is None else sigma.copy(),
        n_points=meas.n_points,
        n_params=model_obj.n_params,
        nfev=int(nfev),
        n_starts=s,
        fit_ms=elapsed,
        seed=seed,
        cost=float(cost[best]),
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


def fit_subsets(gamma_deg, theta_deg, power, masks, model="two-lobe", *, sigma=None,
                max_iter: int = 40, ftol: float = 1e-8, n_screen: int = 32, n_keep: int = 2,
                data_starts: bool = False, seed: int = 0) -> SubsetFits:
    """Fit the model to every subset in ``masks`` (B, n) independently, in one batch.

    Each subset fit sees only its own points. Its starting points are chosen by the same
    global screening as :func:`fit`: ``n_screen`` Latin-hypercube candidates of the model's
    plausible box (the same candidates for every subset; with ``data_starts`` also the
    model's data-driven guesses from the subset's own points) are scored by the projected
    cost **on the subset's points**, and Levenberg-Marquardt runs from the ``n_keep`` best.
    Nothing from the points outside the subset is used. The fit's R^2 is then measured
    against all ``n`` points, as a technician who measured only that subset would get.
    Subsets with fewer points than parameters, or whose fit fails, are marked failed with
    R^2 = 0 (score 1 - R^2 = 1).
    """
    model_obj = get_model(model)
    seed = check_seed(seed)
    gamma_deg, theta_deg, power, masks, sigma = check_subset_inputs(gamma_deg, theta_deg, power,
                                                                    masks, sigma)
    gamma = np.radians(gamma_deg)
    theta = np.radians(theta_deg)
    b, n = masks.shape
    weights_all = np.ones(n) if sigma is None else 1.0 / np.asarray(sigma, float) ** 2
    counts = masks.sum(axis=1)
    ok = counts >= model_obj.n_params
    n_max = max(int(counts.max()) if b else 0, 1)
    # gather every subset into a padded (B, n_max) problem with zero weight on padding
    order = np.argsort(~masks, axis=1, kind="stable")[:, :n_max]
    valid = np.take_along_axis(masks, order, axis=1)
    g, t, y = gamma[order], theta[order], power[order]
    sw = np.sqrt(np.where(valid, weights_all[order], 0.0))
    geom = plane_geometry(g, t)
    # global screening, per subset, on the subset's own points. The shared candidates'
    # basis is computed once on all points and gathered per subset (the same numbers as
    # computing it on each subset, without the repeated trigonometry and powers).
    cands = screen_samples(model_obj, n_screen, seed) if n_screen else \
        np.empty((0, model_obj.n_nonlinear))
    cands = np.clip(cands, model_obj.z_lower, model_obj.z_upper)
    parts_z, parts_cost = [], []
    if len(cands):
        with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):
            basis_all, _ = model_obj.basis(plane_geometry(gamma[None], theta[None]), cands, False)
        gathered = basis_all[:, order, :].transpose(1, 0, 2, 3)  # (B, C, n_max, L)
        k = len(cands)
        rep_k = lambda a: np.repeat(a, k, axis=0)  # noqa: E731
        cost_shared = _projected_cost(model_obj, gathered.reshape(b * k, n_max, -1), rep_k(sw),
                                      rep_k(sw * y)).reshape(b, k)
        parts_z.append(np.broadcast_to(cands, (b,) + cands.shape))
        parts_cost.append(cost_shared)
    if data_starts or not len(cands):
        per_subset = [np.asarray(model_obj.starts(g[i, valid[i]], t[i, valid[i]], y[i, valid[i]]))
                      for i in range(b)]
        k0 = min(len(x) for x in per_subset)
        extra = np.clip(np.stack([x[:k0] for x in per_subset]), model_obj.z_lower,
                        model_obj.z_upper)  # (B, k0, P)
        rep_e = lambda a: np.repeat(a, k0, axis=0)  # noqa: E731
        cost_extra = _screen_costs(model_obj, {key: rep_e(v) for key, v in geom.items()},
                                   extra.reshape(b * k0, -1), rep_e(sw),
                                   rep_e(sw * y)).reshape(b, k0)
        parts_z.append(extra)
        parts_cost.append(cost_extra)
    all_cands = np.concatenate(parts_z, axis=1)
    screen = np.concatenate(parts_cost, axis=1)
    c = all_cands.shape[1]
    keep = min(n_keep, c)
    best_idx = np.argsort(screen, axis=1, kind="stable")[:, :keep]
    starts = np.take_along_axis(all_cands, best_idx[:, :, None], axis=1)  # (B, keep, P)
    rep = lambda a: np.repeat(a, keep, axis=0)  # noqa: E731
    z, state, nfev, _ = _levenberg_marquardt(
        model_obj, {k: rep(v) for k, v in geom.items()}, starts.reshape(b * keep, -1),
        rep(sw), rep(sw * y), max_iter=max_iter, ftol=ftol,
    )
    cost = state["cost"].reshape(b, keep)
    best = np.argmin(cost, axis=1)
    flat = np.arange(b) * keep + best
    params = model_obj.to_natural(z[flat], state["alpha"][flat])
    best_cost = cost[np.arange(b), best]
    failed = ~ok | ~np.isfinite(best_cost) | ~np.all(np.isfinite(params), axis=1)
    safe = np.where(failed[:, None], _placeholder_params(model_obj, params), params)
    pred = model_obj.predict(safe, gamma, theta)
    r2_all = np.asarray(metrics.r2(power, pred), float).reshape(b)
    r2_all = np.where(failed | ~np.isfinite(r2_all), 0.0, r2_all)
    params = np.where(failed[:, None], np.nan, params)
    return SubsetFits(params=params, r2_all=r2_all, cost=np.where(failed, np.inf, best_cost),
                      failed=failed, nfev=int(nfev.sum()) + b * c)


def _placeholder_params(model_obj, params):
    """A harmless parameter vector to evaluate in place of failed fits (then discarded)."""
    z = 0.5 * (model_obj.z_lower + model_obj.z_upper)[None]
    alpha = np.ones((1, model_obj.n_linear))
    return np.broadcast_to(model_obj.to_natural(z, alpha), params.shape)
