""":func:`fit`: one table, one model, a global least-squares fit with everything a user is
owed (the search, the finish, the checks, a second search when the first looks like a
local optimum).
"""

from __future__ import annotations

import contextlib
import dataclasses
import time
import warnings
from warnings import warn

import numpy as np

from .. import metrics
from .._compiled import build_notice
from ..data import as_measurements
from ..errors import FitError, FitWarning, IrreflectError
from ..models import (
    get_model,
    parse_spec,
)
from ..validation import check_fit_options, check_seed, check_starts, short_list
from .cache import per_model
from .engine import NUMPY_FIRST_POINTS, _kernel_codes, _kernel_geometry
from .finish import finish, finished_by_kernel
from .options import (
    FIT_SETTINGS,
    SMALL_TABLE_POINTS,
    FitOptions,
)
from .results import (
    FitResult,
    _check_sigma,
    _radians_and_weights,
    check_fit_data,
    judge,
    sigma_note,
)
from .search import fit_plain_table, search_and_finish
from .shape_hint import explained

#: :func:`retry_reasons`: an R^2 below this, or (weighted by 1/sigma^2) a reduced chi^2
#: above the other, looks like a local optimum rather than the model's best.
RETRY_R2 = 0.95
RETRY_CHI2 = 2.0
#: The second search's result is kept when its cost is lower by more than this fraction.
RETRY_GAIN = 1e-9
#: :func:`weights_check`: a fit weighted by the table's sigma is said to be decided by its
#: weights when the same model fitted unweighted explains the power better by this (R^2).
WEIGHTS_GAIN = 0.01
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


def _on_all_points(result, meas) -> dict:
    """A fit at one angle of incidence scored on every point of its table (unweighted)."""
    model = result.model_object or get_model(result.model)
    with np.errstate(all="ignore"):
        pred = model.predict_deg(result.values, meas.gamma_deg, meas.theta_deg)
    return {"n_points": int(meas.n_points), "r2": float(metrics.r2(meas.power, pred)),
            "rmse": float(metrics.rmse(meas.power, pred))}


def _raise_explained(exc: FitError, meas):
    """Raise ``exc``, its generic advice replaced by where the table's readings peak
    (:func:`~.shape_hint.explained`) when that says more."""
    better = explained(exc, meas)
    if better is exc:
        raise exc
    raise better from exc


def fit(measurements, model="two-lobe", options: FitOptions | None = None,
        **settings) -> FitResult:
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
    options : FitOptions, optional
        The fit's settings as one object (:class:`~irreflect.fitting.options.FitOptions`:
        seed, search sizes, engine, warm starts, retry); keywords override its fields.
    **settings
        Any field of :class:`~irreflect.fitting.options.FitOptions` by name: ``seed``
        (the same seed gives the same result), ``n_random_starts``, ``n_screen``,
        ``n_keep``, ``n_data_starts``, ``use_sigma``, ``max_iter``, ``max_rounds``,
        ``polish``, ``engine`` (``"compiled"``, ``"numpy"`` or ``"numpy-first"``), ``extra_starts``,
        ``n_hops``, ``retry`` (search a second time, more widely, when the result looks
        like a local optimum: :func:`retry_reasons`; the result's ``retried`` says why).

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
    opts = _options(options, settings)
    spec = parse_spec(model) if isinstance(model, str) and "@" in model else None
    opts = _checked(opts, spec.model_text if spec is not None else model)
    if spec is not None and spec.at_gamma_deg is not None:  # 'phong@10': one incidence
        meas = as_measurements(measurements)
        sub = points_at_incidence(meas, spec.at_gamma_deg, str(spec))
        with warnings.catch_warnings(record=True) as caught:  # said under the label asked for
            warnings.simplefilter("always")
            inner = fit(sub, spec.model_text, opts)
        for w in caught:
            message = w.message
            if isinstance(message, FitWarning):
                message = FitWarning(str(message).replace(f", {inner.model}: ", f", {spec}: ", 1))
            warn(message, stacklevel=2)
        return dataclasses.replace(inner, model=str(spec),
                                   on_all_points=_on_all_points(inner, meas))
    t0 = time.perf_counter()
    meas = as_measurements(measurements)  # a path is read once, for both searches
    if np.any(meas.gamma_deg > 0):  # only a Measurements built by hand keeps them
        warn(FitWarning(
            f"{meas.name}: gamma_deg > 0 in a Measurements object is the paper's frame "
            "mirrored (mirror at theta = -gamma); a table of magnitudes is read as gamma = "
            "-|gamma| by read_measurements / validate_table (or fit(DataFrame)): build the "
            "Measurements with -abs(gamma) if they are magnitudes"), stacklevel=2)
    try:
        result = _fit_search(meas, model, t0, opts)
        failure = None
    except FitError as exc:
        if not opts.retry:
            _raise_explained(exc, meas)
        result, failure = None, exc
    reasons = retry_reasons(result) if opts.retry else ()
    if reasons:
        try:
            result = _search_again(meas, model, t0, result, failure, reasons, opts)
        except FitError as exc:
            _raise_explained(exc, meas)
    source = getattr(meas, "name", None) or "table"
    for text in result.warnings:
        warn(FitWarning(f"{source}, {result.model}: {text}"), stacklevel=2)
    return result


#: The local searches that fit a receiver's average (:func:`fit_averaged`) from the point
#: model's optimum and any ``extra_starts``.
AVERAGED_OPTIONS = FitOptions(polish=False, n_screen=1, n_keep=2, n_data_starts=0,
                              n_random_starts=0, n_hops=0, max_rounds=1, retry=False)


def fit_averaged(measurements, model="two-lobe", width_deg: float = 0.0,
                 options: FitOptions | None = None, **settings) -> FitResult:
    """:func:`fit` for readings of a receiver that averages over ``width_deg`` degrees of
    receiver angle (its resolution; 0: a point receiver, plain :func:`fit`).

    The model averaged over the receiver (:func:`irreflect.models.aperture.with_aperture`)
    has no compiled kernel, so the global search runs on the point model (``options`` and
    ``settings`` as for :func:`fit`), and local searches from its optimum (and any
    ``extra_starts``) fit the average. The coefficients are the material's, as a point
    receiver would see it; the result's ``predict`` gives what the receiver reads (its
    ``model_object`` is the averaged model). A model ``MODEL@G`` (one angle of incidence)
    is fitted as points (:func:`fit`), so only with ``width_deg`` 0."""
    from ..models.aperture import with_aperture

    spec = parse_spec(model) if isinstance(model, str) and "@" in model else None
    point_model = get_model(model if spec is None else spec.model_text)
    averaged = with_aperture(point_model, width_deg)
    if averaged is point_model:
        return fit(measurements, point_model if spec is None else model, options, **settings)
    if spec is not None:  # get_model's message names the commands, not this function
        at, width = f"{spec.at_gamma_deg:g}", f"{float(width_deg):g}"
        raise IrreflectError(
            f"fit_averaged: model '{spec}' with width_deg {width}: '@{at}' fits the readings "
            "of one angle of incidence as points, not averaged over a receiver: call "
            f"fit(measurements, '{spec}') for that fit, or fit_averaged(points_at_incidence("
            f"measurements, {at}), '{spec.model_text}', {width}) to fit those readings "
            "averaged")
    with warnings.catch_warnings():
        # the point fit is only the averaged fit's start: its warnings (a coefficient it
        # leaves ill-determined, say) are not the result's, which warns for itself
        warnings.simplefilter("ignore", FitWarning)
        point = fit(measurements, point_model, options, **settings)
    opts = _options(options, settings)
    z0 = point_model.from_natural(np.asarray(point.values, float)[None])[0]
    starts = z0 if opts.extra_starts is None else np.vstack(
        [z0, np.atleast_2d(opts.extra_starts)])
    return fit(measurements, averaged, AVERAGED_OPTIONS, seed=opts.seed,
               extra_starts=starts)


def weights_check(measurements, result: FitResult, model="two-lobe", width_deg: float = 0.0,
                  seed: int = 0) -> tuple[str, float]:
    """Whether the table's sigma column, rather than the power, decided a weighted fit.

    Weighted by 1/sigma^2, a model that misfits beyond the noise (reduced chi^2 above
    :data:`RETRY_CHI2`) is pulled toward the points of smallest sigma: with a sigma that
    grows with the power, the low tails outweigh the lobe. When ``result`` is such a fit,
    the same model is fitted unweighted (:func:`fit_averaged`, ``use_sigma=False``) and
    compared on the power. Returns ``(warning, R^2 of the unweighted fit)``: the warning is
    empty unless the unweighted fit explains the power better by more than
    :data:`WEIGHTS_GAIN`; ``("", nan)`` when nothing was checked. (A held-out GGX table
    with a sigma column: weighted R^2 0.271 against all points, unweighted 0.987.)"""
    meas = as_measurements(measurements)
    if (meas.sigma is None or getattr(result, "sigma", None) is None
            or not result.chi2_reduced > RETRY_CHI2):
        return "", float("nan")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)  # the unweighted fit is only a yardstick
        try:
            other = fit_averaged(meas, model, width_deg, seed=seed, use_sigma=False)
        except FitError:
            return "", float("nan")
    if not other.r2 - result.r2 > WEIGHTS_GAIN:
        return "", float(other.r2)
    return (f"weighted by the sigma column, the fit misfits beyond the noise (reduced chi^2 "
            f"{result.chi2_reduced:.3g}), so the points of smallest sigma decide it: it "
            f"explains the power to R^2 {result.r2:.4f}, the same model fitted unweighted to "
            f"{other.r2:.4f}. For a curve of power (a room's multipath) fit unweighted "
            "(irreflect fit --ignore-sigma; in Python use_sigma=False), or give a sigma that "
            "includes the model's error"), float(other.r2)


def _options(options: FitOptions | None, settings: dict) -> FitOptions:
    """``options`` (default: FitOptions()) with the keyword ``settings`` applied; an
    unknown keyword is a TypeError, as for any function."""
    unknown = sorted(set(settings) - set(FIT_SETTINGS))
    if unknown:
        raise TypeError(f"fit() got an unexpected keyword argument '{unknown[0]}' (its "
                        f"settings: {', '.join(FIT_SETTINGS)})")
    if options is None:
        return FitOptions(**settings) if settings else _DEFAULT_OPTIONS
    if not isinstance(options, FitOptions):  # a dict raised AttributeError deep inside
        raise IrreflectError(f"options must be an irreflect.fitting.FitOptions (or None); "
                             f"found {type(options).__name__}: pass the settings as keywords, "
                             "e.g. fit(data, seed=0, n_random_starts=8)")
    return dataclasses.replace(options, **settings) if settings else options


_DEFAULT_OPTIONS = FitOptions()


def _checked(opts: FitOptions, model) -> FitOptions:
    """``opts`` with its counts, flags and seed checked (one line naming the setting) and
    ``extra_starts`` as a float array of the model's nonlinear coordinates."""
    check_fit_options(seed=opts.seed, n_random_starts=opts.n_random_starts,
                      n_screen=opts.n_screen, n_keep=opts.n_keep,
                      n_data_starts=opts.n_data_starts, use_sigma=opts.use_sigma,
                      max_iter=opts.max_iter, max_rounds=opts.max_rounds, polish=opts.polish,
                      n_hops=opts.n_hops, retry=opts.retry)
    if opts.extra_starts is None:
        return opts
    extra = check_starts(opts.extra_starts, get_model(model).n_nonlinear)
    return dataclasses.replace(opts, extra_starts=extra)


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


def _search_again(meas, model, t0, first, failure, reasons, opts: FitOptions):
    """:func:`fit`'s second search (:meth:`FitOptions.widened`), from the first result too;
    the second result when its cost is lower by more than :data:`RETRY_GAIN`, else the
    first, marked ``retried``, with every search's starts, evaluations and time. When the
    model still misfits a table of more than :data:`SMALL_TABLE_POINTS` points (R^2 below
    :data:`RETRY_R2`), a third search screens beyond the model's screening box
    (:func:`_widened_model`)."""
    base = get_model(model)
    second = _wider_search(meas, base, t0, first, opts)
    if second is None and first is None:
        raise failure from None
    best = _lower(first, second)
    outcome = ("the second search found a lower cost" if best is second else
               "the second search found no lower cost")
    spent = [r for r in (first, second) if r is not None]
    if meas.n_points > SMALL_TABLE_POINTS and best.r2 < RETRY_R2:
        # only where the model misfits a dense table: its optimum can lie beyond the box
        # (a held-out noisy matte table: R^2 0.8359 in the box, 0.9080 beyond); a table
        # the model fits costs no third search, and a few readings keep the box: beyond
        # it they find needles that fit them and miss the rest (a campaign's 8 opening
        # readings of Cornell Krylon: R^2 -4466 against all points, 0.967 within the box)
        wider = _widened_model(base)  # the model itself when its box is its bounds
        third = (None if wider is base
                 else _wider_search(meas, wider, t0, best, opts, compiled=True))
        if third is not None:
            third = dataclasses.replace(third, model_object=base)
            spent.append(third)
            if _lower(best, third) is third:
                best, outcome = third, ("a search beyond the model's screening box found "
                                        "a lower cost")
            else:
                outcome += "; a search beyond the model's screening box found none lower"
    return dataclasses.replace(
        best, retried=f"{'; '.join(reasons)}: {outcome}",
        fit_ms=(time.perf_counter() - t0) * 1e3,
        n_starts=sum(r.n_starts for r in spent), nfev=sum(r.nfev for r in spent))


def _wider_search(meas, model_obj, t0, start, opts: FitOptions, compiled: bool = False):
    """One search of :meth:`FitOptions.widened` for ``model_obj``, from ``start`` (a
    result, or None) too; None when it finds no fit. With engine ``numpy-first`` it runs
    compiled on tables of more than :data:`NUMPY_FIRST_POINTS` points, or on any with
    ``compiled`` (the third search: beyond the box, numpy took 7.1 s on a held-out
    387-point table where the kernel, loaded, takes about 0.5 s)."""
    z_start = n_nonlinear = None
    if start is not None:
        z_start = start.model_object.from_natural(start.values[None])[0]
        n_nonlinear = start.model_object.n_nonlinear
    wide = opts.widened(meas.n_points, z_start, n_nonlinear)
    if wide.engine == "numpy-first" and (compiled or meas.n_points > NUMPY_FIRST_POINTS):
        wide = dataclasses.replace(wide, engine="compiled")
    try:
        return _fit_search(meas, model_obj, t0, wide)
    except FitError:
        return None


def _lower(first, second):
    """``second`` when its cost is lower than ``first``'s by more than rounding
    (:data:`RETRY_GAIN`: a tie along a flat direction keeps the first, whatever the scale
    of power), else ``first``; either may be None."""
    if second is None:
        return first
    if first is None or second.cost < first.cost * (1.0 - RETRY_GAIN):
        return second
    return first


def _widened_model(model_obj):
    """``model_obj`` with its screening box opened to its bounds (within +-15), for
    :func:`fit`'s third search: a model's box holds the coefficients of the materials it
    was made for, and a table the model misfits can have its optimum beyond it (a
    held-out noisy matte table: v_as = -12, u_ns = 0.5 and v_ns = -10.4, a share and a
    specular index that rise steeply toward grazing). Built once per model (its kernel's
    statics are cached on it)."""
    if model_obj.screen_lower is None and model_obj.screen_upper is None:
        return model_obj  # the box is already the bounds
    lo = np.maximum(model_obj.z_lower, -15.0)
    hi = np.minimum(model_obj.z_upper, 15.0)
    return per_model(model_obj, "widened_model",
                     lambda: dataclasses.replace(model_obj, screen_lower=lo, screen_upper=hi))


def _fit_search(meas, model, t0, opts: FitOptions) -> FitResult:
    """One global search of :func:`fit` (the table as Measurements; ``t0`` when the fit
    began); the result's warnings are not issued here."""
    seed = check_seed(opts.seed)
    model_obj = get_model(model)
    opts = opts.sized_for(model_obj, meas.n_points)
    source = getattr(meas, "name", None) or "table"
    sigma = meas.sigma if (opts.use_sigma and meas.sigma is not None) else None
    check_fit_data(meas.power, model_obj, source)
    if sigma is not None:
        _check_sigma(sigma, source)
    codes = _kernel_codes(model_obj, opts.engine)
    table = kgeo = None
    # a cold kernel cache: the first compiled fit of a process builds it, announced (a
    # first `irreflect fit` whose second search ran compiled sat 1-3 min with no word)
    with build_notice() if codes is not None else contextlib.nullcontext():
        if codes is not None and codes.size == 0:  # the plain two-lobe model: one call
            out, fin, exact = fit_plain_table(model_obj, meas, sigma, opts)
        else:
            gamma, theta, weights = _radians_and_weights(meas, sigma)
            kgeo = _kernel_geometry(gamma, theta) if codes is not None else None
            table = (gamma, theta, meas.power, weights)
            out, fin, exact = search_and_finish(model_obj, table, opts, kgeo)
    if out is None:
        raise FitError(
            f"fit of '{model_obj.name}' to {source} failed: no start reached a finite cost; "
            "check the data for extreme values"
        )
    zb, ab, cb, converged, message, n_starts, n_evals = out
    if fin is not None:
        fin = finished_by_kernel(model_obj, fin[0], meas.power, source, *fin[1:], sigma=sigma)
    else:
        if table is None:
            gamma, theta, weights = _radians_and_weights(meas, sigma)
            table = (gamma, theta, meas.power, weights)
        fin = finish(model_obj, zb, ab, cb, table, sigma is not None, opts.engine, kgeo,
                     source)
    # the distinct angles of incidence stand for all (judge's checks look at each once)
    angles = table[0] if exact is None else exact
    at_bound, ill, warnings = judge(model_obj, fin.values, fin.stderr, fin.singular, angles,
                                    converged, message)
    dof = meas.n_points - model_obj.n_params
    if sigma is not None:
        warnings += sigma_note(model_obj, fin.values, fin.stderr, ill, 2 * cb / max(dof, 1),
                               dof)
    return FitResult(
        model=model_obj.name, param_names=model_obj.param_names, values=fin.values,
        stderr=fin.stderr, covariance=fin.covariance, r2=fin.r2, rmse=fin.rmse, mse=fin.mse,
        chi2_reduced=float(2 * cb / dof) if sigma is not None else float("nan"),
        residuals=fin.residuals, gamma_deg=meas.gamma_deg.copy(),
        theta_deg=meas.theta_deg.copy(), power=meas.power.copy(),
        sigma=None if sigma is None else sigma.copy(), n_points=meas.n_points,
        n_params=model_obj.n_params, nfev=int(n_evals), n_starts=n_starts,
        fit_ms=(time.perf_counter() - t0) * 1e3, seed=seed, cost=cb, converged=converged,
        message=message, at_bound=at_bound, ill_determined=ill, warnings=warnings,
        singular=tuple(n for n, s in zip(model_obj.param_names, fin.singular, strict=True)
                       if s),
        model_object=model_obj)
