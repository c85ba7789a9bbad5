""":func:`fit_subsets`: one fit per subset mask of a table, in one batch (the point selection's
inner loop). The compiled side: :mod:`.subsets_kernel`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from warnings import warn

import numpy as np

from .. import metrics
from .._compiled import build_notice
from ..errors import DataError
from ..models import (
    Geometry,
    get_model,
)
from ..validation import check_fit_options, check_seed, check_starts, check_subset_inputs
from .engine import _kernel_codes, _kernel_geometry, _kernel_static, _w
from .local import STOP_FTOL, STOP_STUCK, STOP_XTOL, _levenberg_marquardt
from .options import FitOptions
from .results import mirrored_gamma_warning
from .screening import (
    _block_candidates,
    _projected_cost,
    _scan_blocks,
    _screen_costs,
    screen_samples,
)
from .search import global_search


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
    batch = model.hints.batch_starts
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
    points, as a technician who measured only that subset would get. Subsets with no
    more points than parameters (no degree of freedom, which :func:`fit` refuses), or
    whose fit fails, are marked failed with R^2 = 0 (score 1 - R^2 = 1). Constant power
    is refused (:class:`~irreflect.errors.DataError`), as :func:`fit` refuses it.

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
    if gamma_deg.size and gamma_deg.max() > 0:  # once per call, as FitResult.predict says it
        warn(mirrored_gamma_warning("fit_subsets", "fit them at a table's settings"),
             stacklevel=2)
    n = masks.shape[1]
    if n and power.max() == power.min():  # as fit: R^2 on all points means nothing
        raise DataError(
            f"fit_subsets: power is constant ({power[0]:g} at all {n} points): a reflection "
            "model needs the power measured at varying angles; check the power column")
    # the power in units near 1, by a power of two (exact): a table in nW underflowed the
    # data-driven starts of a narrow lobe (1e-300 x 1e-9), and 6 of 12 subsets of the same
    # readings in W and in nW ended at other coefficients (stop 48's metamorphic audit)
    unit = _unit_scale(power)
    out = _fit_subsets(model_obj, np.radians(gamma_deg), np.radians(theta_deg), power / unit,
                       masks, None if sigma is None else np.asarray(sigma, float) / unit,
                       dict(max_iter=max_iter, ftol=ftol, n_screen=n_screen, n_keep=n_keep,
                            data_starts=data_starts, n_data_starts=n_data_starts, scan=scan,
                            exhaustive=exhaustive, seed=seed, engine=engine,
                            shared_starts=shared_starts))
    in_power = np.array([q.unit == "power" for q in model_obj.params])
    return replace(
        out, params=out.params * np.where(in_power, unit, 1.0),
        cost=out.cost * (unit * unit if sigma is None else 1.0))


def _unit_scale(power: np.ndarray) -> float:
    """The power of two nearest the root mean square of the finite ``power`` (1 when there
    is none): dividing by it is exact, so a table in any power-of-two multiple of a unit
    is fitted bit for bit alike."""
    finite = power[np.isfinite(power)]
    rms = float(np.sqrt(np.mean(finite * finite))) if finite.size else 0.0
    if not (np.isfinite(rms) and rms > 0):
        return 1.0
    return float(2.0 ** np.round(np.log2(rms)))


def _fit_subsets(model_obj, gamma, theta, power, masks, sigma, cfg) -> SubsetFits:
    """:func:`fit_subsets` on the checked table in radians and power near 1."""
    max_iter, ftol, seed, engine = cfg["max_iter"], cfg["ftol"], cfg["seed"], cfg["engine"]
    n_screen, n_keep, n_data_starts = cfg["n_screen"], cfg["n_keep"], cfg["n_data_starts"]
    data_starts, scan, shared_starts = cfg["data_starts"], cfg["scan"], cfg["shared_starts"]
    exhaustive = cfg["exhaustive"]
    n = masks.shape[1]
    p_dim = model_obj.n_nonlinear
    weights_all = np.ones(n) if sigma is None else 1.0 / sigma ** 2
    counts = masks.sum(axis=1)
    ok = counts > model_obj.n_params  # a degree of freedom left, as fit requires
    if exhaustive:
        return _fit_subsets_one_by_one(model_obj, gamma, theta, power, masks, weights_all, ok,
                                       seed, engine)
    codes = _kernel_codes(model_obj, engine)
    if codes is not None and data_starts and not scan and p_dim:
        with build_notice():  # a cold cache is built by this call: announced, as fit's is
            return _fit_subsets_compiled(model_obj, codes, gamma, theta, power, masks, weights_all,
                                         ok, n_screen=n_screen, n_keep=n_keep,
                                         n_data_starts=n_data_starts, max_iter=max_iter,
                                         ftol=ftol, seed=seed, shared_starts=shared_starts)
    return _fit_subsets_numpy(model_obj, (gamma, theta, power, weights_all), masks, ok,
                              dict(n_screen=n_screen, n_keep=n_keep, data_starts=data_starts,
                                   n_data_starts=n_data_starts, scan=scan, seed=seed,
                                   max_iter=max_iter, ftol=ftol),
                              shared_starts)


def _fit_subsets_numpy(model_obj, table, masks, ok, cfg, shared_starts) -> SubsetFits:
    """The batched subset search in numpy (see :func:`fit_subsets`): every subset padded to
    the largest, candidates scored per subset, Levenberg-Marquardt from the best."""
    gamma, theta, power, weights_all = table
    n_screen, n_keep, seed = cfg["n_screen"], cfg["n_keep"], cfg["seed"]
    max_iter, ftol = cfg["max_iter"], cfg["ftol"]
    b = masks.shape[0]
    p_dim = model_obj.n_nonlinear
    counts = masks.sum(axis=1)
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
    padded = (g, t, y, sw, valid, order, geom)
    all_cands, screen, n_data = _subset_candidates(model_obj, table, masks, padded, cands,
                                                   cfg["data_starts"])
    c = all_cands.shape[1]
    picks = [np.argsort(screen, axis=1, kind="stable")[:, :min(n_keep, c)]]
    if n_data:
        order = np.argsort(screen[:, :n_data], axis=1, kind="stable")
        picks.append(order[:, :cfg["n_data_starts"]])
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
    if cfg["scan"] and p_dim:
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


def _subset_candidates(model_obj, table, masks, padded, cands, data_starts):
    """Every subset's candidates scored on its own points: its data-driven starts (with
    ``data_starts``, or when there are no shared candidates) and the shared ``cands``.
    Returns (candidates (B, C, P), costs (B, C), how many data-driven starts lead)."""
    gamma, theta, power, weights_all = table
    g, t, y, sw, valid, order, geom = padded
    b = masks.shape[0]
    n_max = g.shape[1]
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
    return np.concatenate(parts_z, axis=1), np.concatenate(parts_cost, axis=1), n_data


def _fit_subsets_compiled(model, codes, gamma, theta, power, masks, weights, ok, *, n_screen,
                          n_keep, n_data_starts, max_iter, ftol, seed, shared_starts=None):
    """The batched subset search in the compiled kernel (see :func:`fit_subsets`)."""
    from .subsets_kernel import r2_rows, subset_search

    km = _kernel_static(model).k
    kt = _kernel_geometry(gamma, theta)
    p = model.n_nonlinear
    screen = screen_samples(model, n_screen, seed) if n_screen else np.zeros((0, p))
    if shared_starts is not None and len(shared_starts):
        screen = np.vstack([screen, np.asarray(shared_starts, float).reshape(-1, p)])
    z, alpha, cost, conv, nfev = subset_search(
        km, kt, _w(power), _w(weights), _w(masks, np.bool_), _w(screen),
        (int(n_keep), int(n_data_starts), int(max_iter), float(ftol)))
    r2 = r2_rows(codes, _w(z), _w(alpha), kt.geo, kt.glcg, _w(power))
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
        opts = FitOptions(seed=seed, engine=engine).sized_for(model, int(m.sum()))
        out = global_search(model, (gamma[m], theta[m], power[m], weights[m]), opts)
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
