"""A search's finish (numpy): polish and convergence verdict (:func:`_conclude`), the fitted
curve and its Jacobian in (z, alpha), the covariance of the natural parameters. The
compiled side: :mod:`.finish_kernel`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .. import metrics
from ..errors import FitError
from ..models import Geometry
from ..models.base import saturate_rows, share_factor
from .engine import _kernel_codes, _kernel_geometry, _w
from .linear import _capped_dbasis
from .local import (
    _STOP_MESSAGES,
    STOP_FTOL,
    STOP_MAXITER,
    STOP_POLISHED,
    STOP_STUCK,
    STOP_XTOL,
    _gauss_newton_decrease,
    _polish,
)
from .shape_hint import GENERIC_ADVICE


# ----------------------------------------------------------------------------- fit()
def _fitted_and_jacobian(model, z, alpha, gamma, theta, weights, engine=None, kgeo=None):
    """The fitted curve and the Jacobian in (z, alpha) of the weighted model, (n, P + L)."""
    codes = _kernel_codes(model, engine)
    if codes is not None:
        from .model_kernel import jacobian_full, predict

        geo, glcg = (kgeo if kgeo is not None else _kernel_geometry(gamma, theta))[:2]
        return (predict(codes, _w(z), _w(alpha), geo, glcg),
                jacobian_full(codes, _w(z), _w(alpha), geo, glcg, _w(np.sqrt(weights))))
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


def prediction_and_jacobian(model, values, gamma_rad, theta_rad, engine=None):
    """The model's curve at natural ``values`` and its Jacobian in the internal
    coordinates ``(z, alpha)``, ``(n,)`` and ``(n, P + L)``, at angles in radians: the
    curve the fitter fits and :meth:`~irreflect.models.ReflectionModel.predict` gives,
    with a saturating specular share's saturated rows (their derivative the unsaturated
    side's at a threshold). What the designs (the campaign's prior, the D-optimal
    selector, the diagnosis's discriminating readings) linearise the model with."""
    z, alpha = model.from_natural(np.atleast_2d(np.asarray(values, float)))
    gamma = np.asarray(gamma_rad, float).ravel()
    theta = np.asarray(theta_rad, float).ravel()
    return _fitted_and_jacobian(model, z[0], alpha[0], gamma, theta, np.ones(gamma.size),
                                engine)


def _saturation_level(alpha, strict: bool = False) -> float:
    """The largest threshold ``tau`` the share at ``alpha`` has passed: rows with
    ``1 / cos^v_as(gamma) <= u`` saturate, so the share at normal incidence ``u``
    (slightly less with ``strict``: a row exactly at its threshold counts as below it)."""
    k = alpha[0] + alpha[1]
    u = alpha[1] / k if k > 0 else 0.0
    return u * (1.0 - 1e-9) if strict else u


def _block_scales(z, alpha):
    """Per internal coordinate (``z`` then ``alpha``), the scale its difference step is
    floored against: 1 for the unitless shape coordinates, the largest linear coefficient
    (in power units; 1 when all are zero) for the linear ones."""
    top = float(np.max(np.abs(alpha))) if np.size(alpha) else 0.0
    return np.concatenate([np.ones(np.size(z)),
                           np.full(np.size(alpha), top if top > 0 else 1.0)])


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
    # steps relative to each coordinate, floored at 1e-3 of its block's scale: the shape
    # coordinates are unitless, the linear coefficients carry the power's unit (a floor of
    # 1e-3 power units made the step of a table in nW as large as its coefficients, and
    # its standard errors depend on the unit)
    steps = 1e-6 * np.maximum(np.abs(x0), 1e-3 * _block_scales(z, alpha))
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


class Finished(NamedTuple):
    """What a fit reports besides the search's end point: the natural parameters, their
    standard errors and covariance (and which lie along a near-singular direction), the
    quality of the fitted curve and its residuals."""

    values: np.ndarray
    stderr: np.ndarray
    covariance: np.ndarray
    singular: np.ndarray
    r2: float
    rmse: float
    mse: float
    residuals: np.ndarray


def finish(model, z, alpha, cost, table, absolute_sigma, engine, kgeo, source) -> Finished:
    """A search's end point ``(z, alpha, cost)`` as fit() reports it: natural parameters
    (refused when not finite or when they do not map back to the fitted curve), the fitted
    curve and R^2 (refused when it cannot beat a constant), the covariance. The plain
    two-lobe model in one compiled call (:func:`~.finish_kernel.tl_finish`), other models
    from the Jacobian in (z, alpha) (compiled or numpy) and :func:`_covariance`."""
    gamma, theta, power, weights = table
    codes = _kernel_codes(model, engine)
    if codes is not None and codes.size == 0:  # the plain two-lobe model
        from .finish_kernel import tl_finish

        kgeo = kgeo if kgeo is not None else _kernel_geometry(gamma, theta)
        fin = tl_finish(_w(z), _w(alpha), tuple(kgeo.geo), kgeo.glcg, _w(weights), _w(power),
                        absolute_sigma, cost, model.n_params)
        return finished_by_kernel(model, fin, power, source,
                                  weights=weights if absolute_sigma else None)
    values = model.to_natural(z[None], alpha[None])[0]
    _check_values(model, values, True, source)
    fitted, jfull = _fitted_and_jacobian(model, z, alpha, gamma, theta, weights, engine, kgeo)
    z_back, a_back = model.from_natural(values[None])
    round_trip = (np.allclose(z_back[0], z, rtol=1e-9, atol=1e-12)
                  and np.allclose(a_back[0], alpha, rtol=1e-6,
                                  atol=1e-9 * np.max(np.abs(alpha))))
    _check_values(model, values, round_trip, source)
    r2 = _check_r2(model, metrics.r2(power, fitted), source,
                   weights=weights if absolute_sigma else None)
    cov, singular = _covariance(model, z, alpha, jfull, absolute_sigma, cost, power.size)
    return Finished(values, np.sqrt(np.clip(np.diag(cov), 0, None)), cov, singular, r2,
                    float(metrics.rmse(power, fitted)), float(metrics.mse(power, fitted)),
                    power - fitted)


def finished_by_kernel(model, fin, power, source, stderr=None, residuals=None, *,
                       sigma=None, weights=None) -> Finished:
    """The kernel's finish (:class:`~.kernel_types.Finish` of
    :func:`~.finish_kernel.tl_finish`) as :func:`finish` returns it, checked; ``stderr``
    and ``residuals`` when the kernel computed them too; ``sigma`` or ``weights`` (``1 /
    sigma^2``): the table's, when the fit was weighted by its sigma."""
    _check_values(model, fin.values, fin.round_trip, source)
    r2 = _check_r2(model, fin.r2, source, sigma, weights)
    if stderr is None:
        stderr = np.sqrt(np.clip(np.diag(fin.covariance), 0, None))
    if residuals is None:
        residuals = power - fin.fitted
    return Finished(fin.values, stderr, fin.covariance, fin.singular, r2, float(fin.rmse),
                    float(fin.mse), residuals)


def _check_values(model, values, round_trip, source) -> None:
    if not np.isfinite(values).all():
        raise FitError(
            f"fit of '{model.name}' to {source} ended at non-finite parameters "
            f"{np.array2string(values, precision=4)}: check the data for extreme values"
        )
    if not round_trip:
        raise FitError(
            f"fit of '{model.name}' to {source}: the coefficients "
            f"{np.array2string(values, precision=4)} do not reproduce the fitted curve in "
            "floating point (a share within 1e-16 of its bound): check the data for extreme "
            "values"
        )


def _check_r2(model, r2, source, sigma=None, weights=None) -> float:
    """``r2``, refused when it cannot beat a constant. A fit weighted by the table's
    ``sigma`` (or ``weights``, 1 / sigma^2; sigma is derived only for the error) that
    cannot is most often told by a sigma far below the noise on some readings (2 % of
    each reading, with nothing for the noise floor, on readings near zero: 4 of 300
    generated tables, R^2 -0.15 to -0.0005), and the error says so."""
    r2 = float(r2)
    if (not np.isfinite(r2) or r2 <= 0) and (sigma is not None or weights is not None):
        sigma = (np.asarray(sigma, float) if sigma is not None
                 else 1.0 / np.sqrt(np.asarray(weights, float)))
        raise FitError(
            f"fit of '{model.name}' to {source}, weighted by 1/sigma^2, cannot beat a "
            f"constant (R^2 = {r2:.4g} <= 0): its sigma spans {np.min(sigma):.3g} to "
            f"{np.max(sigma):.3g}, and the readings with the smallest sigma outweigh the "
            "rest; check that sigma is the 1-sigma uncertainty of power, including that of "
            "readings near zero, or drop the sigma column to fit unweighted"
        )
    if not np.isfinite(r2) or r2 <= 0:
        raise FitError(
            f"fit of '{model.name}' to {source} cannot beat a constant (R^2 = {r2:.4g} "
            f"<= 0): {GENERIC_ADVICE}"
        )
    return r2
