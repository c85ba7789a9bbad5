"""The campaign's quadrature estimate (:meth:`Campaign._quadrature`): the posterior's
picture of the range, and the checks of whether the model fitted to it may be reported, and
the result it then is, a fit of the readings."""

from __future__ import annotations

import dataclasses

import numpy as np

from .. import metrics
from ..data import Measurements
from ..fitting import FitResult, judge
from .design import DesignRule, Prior, posterior_mean


def picture(prior: Prior, n_settings: int, noise, power, center_read, center_range,
            floor: float) -> np.ndarray:
    """The posterior's picture of the material over the design's ``n_settings`` settings:
    the curve ``center_range`` (``center_read`` at the readings ``power``, whose noise
    variances are ``noise``) times the exponential of the posterior mean of the readings'
    log-ratio to it, the ratio taken of ``power + floor`` to ``center + floor``: a
    departure by ratios, so that a reading above the fit on one flank of a narrow lobe
    does not raise the other flank with it (on the RGL sunflower film at 20 readings, 0.5
    deg beyond the mirror at 68.8 deg, 38 above the fit: a departure by differences
    pictured the film at 77 on the other flank where it gives 42). The log-ratio is carried
    in the units of power (times ``center + floor``) so the prior's scales stand; far above
    every power (``floor`` large) the picture is the fit plus the posterior mean of the
    difference, and with ``floor`` 0 it is exactly that."""
    noise = np.maximum(noise, 1e-300)
    if not floor > 0:
        return center_range + posterior_mean(prior, n_settings, noise, power - center_read)
    f_read = np.maximum(center_read, 0.0) + floor
    resid = f_read * np.log(np.maximum(power + floor, 0.1 * floor) / f_read)
    mean = posterior_mean(prior, n_settings, noise, resid)
    f_range = np.maximum(center_range, 0.0) + floor
    with np.errstate(all="ignore"):
        return f_range * np.exp(np.clip(mean / f_range, -50.0, 50.0)) - floor


def accepted_estimate(model, own, base: FitResult, res: FitResult, meas: Measurements,
                      center, center_read, range_deg, rule: DesignRule) -> FitResult | None:
    """``res`` (the picture's fit) as a fit of the readings ``meas``, or None when it
    explains them ``rule.quadrature_ratio`` times worse (summed squares) than the curve
    ``center`` it started from (``center_read``: that curve at the readings), or explains
    that curve over the range (``own``: the material's model) to an R^2 below
    ``rule.quadrature_agree``. Its residuals and R^2 are the readings'; its bounds and
    convergence are checked on its own values, with ``base``'s (the weighted fit's)
    standard errors. ``model`` gives what the receiver reads."""
    values = np.asarray(res.values, float)
    with np.errstate(all="ignore"):
        fitted = model.predict_deg(values, meas.gamma_deg, meas.theta_deg)
    resid = meas.power - fitted
    if not np.all(np.isfinite(resid)):
        return None
    ratio = float(rule.quadrature_ratio)
    if ratio and np.sum(resid ** 2) > ratio * np.sum((meas.power - center_read) ** 2):
        return None
    agree = float(rule.quadrature_agree)
    if agree:
        # a refinement of the centre's curve over the range, not another curve
        with np.errstate(all="ignore"):
            mine = own.predict_deg(values, range_deg[:, 0], range_deg[:, 1])
            theirs = own.predict_deg(center, range_deg[:, 0], range_deg[:, 1])
        if not float(metrics.r2(theirs, mine)) >= agree:
            return None
    singular = np.array([name in base.singular for name in base.param_names])
    at_bound, ill, notes = judge(model, values, base.stderr, singular,
                                 np.radians(np.unique(meas.gamma_deg)), res.converged,
                                 res.message)
    return dataclasses.replace(base, values=values, residuals=resid,
                               r2=float(metrics.r2(meas.power, fitted)),
                               rmse=float(np.sqrt(np.mean(resid ** 2))),
                               mse=float(np.mean(resid ** 2)), converged=res.converged,
                               message=res.message, at_bound=at_bound, ill_determined=ill,
                               warnings=notes)
