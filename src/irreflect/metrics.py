"""Goodness-of-fit measures: R^2, RMSE, MSE, residuals and the polar-area error (section 5.3).

All functions are plain vectorised numpy: the last axis runs over measurement points, so a
batch of predictions ``(B, n)`` against one measured vector ``(n,)`` gives ``B`` values.
"""

from __future__ import annotations

from warnings import warn

import numpy as np

from .errors import IrreflectError, MetricWarning

#: Below this R^2 a model misses a table's shape: a campaign that stops on such a fit, and
#: a protocol judged against an all-points fit this poor, say so and name
#: ``irreflect diagnose`` (every real set's two-lobe fit is at 0.94 or above; a
#: retroreflector's at 0.09).
MISFIT_R2 = 0.9


def _paired(what: str, measured, predicted, names=("measured", "predicted")):
    """``measured`` and ``predicted`` as float arrays (at least 1-d) with as many points
    along the last axis; refuse (one line) arrays that only broadcast, or not at all."""
    a = np.atleast_1d(np.asarray(measured, float))
    b = np.atleast_1d(np.asarray(predicted, float))
    if a.shape[-1] != b.shape[-1]:
        raise IrreflectError(
            f"{what}: {names[0]} has {a.shape[-1]} point(s) and {names[1]} "
            f"{b.shape[-1]} (along the last axis): give one {names[1]} value per "
            f"{names[0]} point")
    try:
        np.broadcast_shapes(a.shape, b.shape)
    except ValueError:
        raise IrreflectError(
            f"{what}: {names[0]} of shape {a.shape} and {names[1]} of shape {b.shape} do not "
            "pair up: give one vector, or a batch of rows of the same length") from None
    return a, b


def r2(measured, predicted) -> float | np.ndarray:
    """Coefficient of determination ``1 - SS_res / SS_tot`` along the last axis.

    Undefined for a constant target (``SS_tot = 0``): -inf is returned (NaN where the
    prediction matches it exactly), with a :class:`~irreflect.errors.MetricWarning`."""
    measured, predicted = _paired("r2", measured, predicted)
    ss_res = np.sum((measured - predicted) ** 2, axis=-1)
    ss_tot = np.sum((measured - measured.mean(axis=-1, keepdims=True)) ** 2, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = 1.0 - ss_res / ss_tot
    constant = ss_tot == 0
    if np.any(constant):
        _warn_constant_target(measured, constant)
    return float(out) if np.ndim(out) == 0 else out


def _warn_constant_target(measured: np.ndarray, constant: np.ndarray) -> None:
    """The warning of :func:`r2` for a target that does not vary (one line)."""
    n = measured.shape[-1]
    where = (f" in {int(np.sum(constant))} of {constant.size} rows" if measured.ndim > 1
             else "")
    if n:
        first = measured.reshape(-1, n)[int(np.flatnonzero(np.ravel(constant))[0])]
        what = f"measured is {first[0]:g} at all {n} point(s){where}"
    else:
        what = "measured has no points"
    warn(MetricWarning(
        f"r2: R^2 is undefined for a constant target ({what}, so SS_tot = 0); returned "
        "-inf (NaN where predicted matches it exactly): score such a target with rmse or mse "
        "instead"), stacklevel=3)


def mse(measured, predicted) -> float | np.ndarray:
    """Mean squared error along the last axis."""
    measured, predicted = _paired("mse", measured, predicted)
    out = np.mean((measured - predicted) ** 2, axis=-1)
    return float(out) if np.ndim(out) == 0 else out


def rmse(measured, predicted) -> float | np.ndarray:
    """Root mean squared error along the last axis."""
    measured, predicted = _paired("rmse", measured, predicted)
    out = np.sqrt(np.mean((measured - predicted) ** 2, axis=-1))
    return float(out) if np.ndim(out) == 0 else out


def normalized_residuals(measured, predicted, sigma=None) -> np.ndarray:
    """Residuals ``measured - predicted`` divided by ``sigma`` (or, without sigma, by the
    measured value: the paper's relative residuals of Figs. 22-23)."""
    measured, predicted = _paired("normalized_residuals", measured, predicted)
    resid = measured - predicted
    scale = measured if sigma is None else np.asarray(sigma, float)
    if scale.ndim > 0:  # one sigma per point (a single number scales them all)
        _paired("normalized_residuals", measured, scale, ("measured", "sigma"))
    with np.errstate(divide="ignore", invalid="ignore"):
        return resid / scale


def polar_area_error(theta_deg, measured, model_fn, step_deg: float = 0.1,
                     model_sampling: str = "measured") -> float:
    """Relative polar-area error of one angle of incidence, in percent (section 5.3, Fig. 24).

    In polar coordinates (angle theta, radius power) the area swept by a curve r(theta) is
    ``1/2 integral r^2 dtheta``; the area between the measured and model curves is
    ``1/2 integral |r_m^2 - r_model^2| dtheta``. The error is their ratio, integrated over
    the measured theta range only.

    Interpolation: the measured curve is joined by straight segments in (theta, power)
    between measured points (linear interpolation in theta). With
    ``model_sampling="measured"`` (default) the model curve is drawn the same way through
    its values at the measured angles, so identical curves give exactly 0 and the error
    only counts what the measurements can see; with ``"continuous"`` the model is
    evaluated exactly on the integration grid. Both curves are sampled every ``step_deg``
    degrees and integrated with the trapezoidal rule.

    Parameters
    ----------
    theta_deg : array-like, degrees
        Receiver angles of the measured points of one angle of incidence.
    measured : array-like
        Measured power at those angles.
    model_fn : callable
        ``model_fn(theta_deg_array) -> power`` of the model at that angle of incidence.
    """
    theta_deg, measured = _paired("polar_area_error", theta_deg, measured,
                                  ("theta_deg", "measured"))
    if theta_deg.ndim != 1:
        raise IrreflectError(f"polar_area_error: theta_deg must be one vector (one angle of "
                             f"incidence); found shape {theta_deg.shape}")
    order = np.argsort(theta_deg)
    theta_deg, measured = theta_deg[order], measured[order]
    if theta_deg.size < 2 or theta_deg[-1] <= theta_deg[0]:
        return float("nan")
    if model_sampling not in ("measured", "continuous"):
        raise IrreflectError(f"polar_area_error: model_sampling must be 'measured' or "
                             f"'continuous'; found {model_sampling!r}")
    n_steps = max(int(np.ceil((theta_deg[-1] - theta_deg[0]) / step_deg)), 2)
    grid = np.unique(np.concatenate([np.linspace(theta_deg[0], theta_deg[-1], n_steps + 1),
                                     theta_deg]))
    r_meas = np.interp(grid, theta_deg, measured)
    if model_sampling == "measured":
        r_model = np.asarray(model_fn(theta_deg), float)
        _paired("polar_area_error", theta_deg, r_model, ("theta_deg", "model_fn"))
        r_model = np.interp(grid, theta_deg, r_model)
    else:
        r_model = np.asarray(model_fn(grid), float)
        if r_model.ndim:  # a single number is a constant model
            _paired("polar_area_error", grid, r_model, ("the angle grid", "model_fn"))
    x = np.radians(grid)
    with np.errstate(over="ignore", invalid="ignore"):  # a wild model: an infinite error
        between = np.trapezoid(np.abs(r_meas**2 - r_model**2), x)
    under = np.trapezoid(r_meas**2, x)
    return float(100.0 * between / under) if under > 0 else float("nan")


#: A relative polar-area error above this (percent) says only that the model's area is of
#: another order than the measured one (a lobe a thousandth of a degree wide gave 1.74e+19):
#: text shows it as "> 1000" (JSON keeps the number).
POLAR_ERROR_SHOWN_MAX = 1000.0


def format_polar_error(value, spec: str = ".3g") -> str:
    """A relative polar-area error (percent, without the sign) as text: ``value`` in
    ``spec``, or ``"> 1000"`` above :data:`POLAR_ERROR_SHOWN_MAX` (infinite included); NaN
    is formatted as it is."""
    value = float(value)
    if value > POLAR_ERROR_SHOWN_MAX:
        return f"> {POLAR_ERROR_SHOWN_MAX:g}"
    return format(value, spec)


def polar_area_errors(gamma_deg, theta_deg, measured, predict_deg, step_deg: float = 0.1,
                      model_sampling: str = "measured"):
    """Polar-area error (percent) for each angle of incidence.

    ``predict_deg(gamma_deg_array, theta_deg_array) -> power``. Returns ``{|gamma|: error}``
    ordered by increasing magnitude, as in the paper's Table 6.
    """
    gamma_deg, theta_deg = _paired("polar_area_errors", gamma_deg, theta_deg,
                                   ("gamma_deg", "theta_deg"))
    gamma_deg, measured = _paired("polar_area_errors", gamma_deg, measured,
                                  ("gamma_deg", "measured"))
    out = {}
    for g in sorted(np.unique(gamma_deg), key=abs):
        sel = gamma_deg == g
        if sel.sum() < 2:
            continue
        out[float(abs(g))] = polar_area_error(
            theta_deg[sel], measured[sel],
            lambda grid, g=g: predict_deg(np.full_like(grid, g), grid), step_deg,
            model_sampling,
        )
    return out


def aic(cost_rss: float, n_points: int, n_params: int) -> float:
    """Akaike information criterion for Gaussian errors from the residual sum of squares."""
    return float(n_points * np.log(max(cost_rss, 1e-300) / n_points) + 2 * n_params)


def bic(cost_rss: float, n_points: int, n_params: int) -> float:
    """Bayesian information criterion for Gaussian errors from the residual sum of squares."""
    return float(n_points * np.log(max(cost_rss, 1e-300) / n_points) + n_params * np.log(n_points))
