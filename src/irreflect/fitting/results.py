"""A fit's result and the checks every command prints: :class:`FitResult`, the refusal of
tables no fit can be honest about (:func:`check_fit_data`) and the flags of a result
(:func:`judge`: at a bound, ill-determined, not converged, the model's own validity).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from warnings import warn

import numpy as np

from .. import metrics
from .._text import p_text
from ..data import check_enough_points
from ..errors import DataError, FitWarning, IrreflectError
from ..models import (
    ReflectionModel,
    get_model,
)
from ..models.paper import specular_share
from ..validation import check_angles_deg
from .cache import per_model


# ----------------------------------------------------------------------------- results
def mirrored_gamma_warning(who: str, to: str) -> FitWarning:
    """The warning for angles of incidence > 0 given to ``who`` (``FitResult.predict``,
    ``fit_subsets``): the model reads them in the paper's frame mirrored, where a table's
    gammas >= 0 are read as magnitudes; ``to``: what ``-abs(gamma)`` lets the caller do."""
    return FitWarning(
        f"{who} got gamma_deg > 0, read as the paper's frame mirrored (the source on the "
        "positive side, mirror at theta = -gamma); a table's gammas >= 0 are read as "
        f"magnitudes (gamma = -|gamma|, theta kept): pass -abs(gamma) to {to}")


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
    #: coefficients along a near-singular direction of the information matrix (among
    #: ``ill_determined``): a flag that does not depend on the residuals' scale
    singular: tuple[str, ...] = ()
    #: a ``MODEL@G`` fit (one angle of incidence) scored on every point of its table:
    #: ``{"n_points", "r2", "rmse"}`` (None: fitted on all points)
    on_all_points: dict | None = field(default=None, compare=False)

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
        """Model power at the given angles (degrees, paper convention: gamma <= 0 on the
        source side, the mirror direction theta = -gamma).

        A gamma > 0 is the paper's frame mirrored (the source on the positive side, both
        angles change sign), which is what the model's formulas give; a table whose gammas
        are all >= 0 is read as magnitudes instead (gamma = -|gamma|, theta kept), so a
        warning says so: pass ``-abs(gamma)`` to predict at such a table's settings."""
        model = self.model_object or get_model(self.model)
        gamma_deg, theta_deg = check_angles_deg(gamma_deg, theta_deg)
        if np.any(np.asarray(gamma_deg) > 0):
            warn(mirrored_gamma_warning(f"{self.model}: predict()", "predict at its settings"),
                 stacklevel=2)
        return model.predict_deg(self.values, gamma_deg, theta_deg)

    @property
    def saturated_gammas_deg(self) -> np.ndarray:
        """The measured angles of incidence (|gamma|, degrees) where the fitted specular
        share is 1 (:func:`irreflect.models.paper.specular_share`): there the reflection
        is all specular. Empty for a model without a saturating share."""
        model = self.model_object or get_model(self.model)
        if not model.share_cap:
            return np.empty(0)
        g = np.abs(self.gamma_deg)
        share = specular_share(self.values[0], self.values[1], np.cos(np.radians(g)))
        saturated = share >= 1.0
        # the share at every point (elementwise, so the same as at each distinct angle);
        # the distinct angles only when one saturates (np.unique costs more than the rest)
        return np.unique(g[saturated]) if saturated.any() else np.empty(0)

    def verdict(self):
        """What R^2 cannot say: per angle of incidence whether the specular lobe is resolved
        and the shape reproduced, and the coefficients' checks
        (:class:`irreflect.verdict.FitVerdict`)."""
        from ..verdict import fit_verdict

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
            lines.append("  " + "  ".join(f"{g:g} deg: {metrics.format_polar_error(e, '.2f')}%"
                                          for g, e in errors.items()))
        lines.append("per angle of incidence (the model's continuous curve; lobe half width "
                     "and the receivers within one and two half widths of the mirror):")
        lines += ["  " + row for row in verdict.table()]
        if warnings:
            lines += [f"warning: {w}" for w in self.warnings]
        return "\n".join(lines)


def check_fit_data(power, model, source: str = "table") -> None:
    """Refuse tables no fit can be honest about: no degree of freedom left
    (``n_points <= n_params``), non-finite or constant power."""

    power = np.asarray(power)
    n = power.size
    check_enough_points(n, model, source)
    low, high = float(power.min()), float(power.max())  # NaN or inf show in either
    if not (math.isfinite(low) and math.isfinite(high)):
        raise DataError(f"{source}: power has non-finite values: remove or fix those rows")
    if high == low:
        raise DataError(
            f"{source}: power is constant ({power.flat[0]:g} at all {n} points): a reflection "
            "model needs the power measured at varying angles; check the power column"
        )


def _fmt_bound(b):
    return f"{b:g}"


def _bound_checks(model) -> tuple:
    """Per parameter of ``model``: (name, ((side, bound, tolerance) per finite bound)).
    A scale in power units (bounds 0 and infinity: K) is at its bound only at 0 itself: an
    absolute tolerance has no meaning in the table's units (Krylon's readings times 1e-12,
    picoampere photocurrents, had K = 2.4e-13 called at its lower bound)."""
    def make():
        out = []
        for p in model.params:
            scale = not (math.isfinite(p.lower) and math.isfinite(p.upper))
            checks = tuple((side, b, 1e-6 * abs(b) if b != 0 else (0.0 if scale else 1e-12))
                           for side, b in (("lower", p.lower), ("upper", p.upper))
                           if math.isfinite(b))
            out.append((p.name, checks))
        return tuple(out)

    return per_model(model, "bound checks", make)


#: A standard error below this share of a coefficient's physical range (upper - lower)
#: determines it whatever its value: an exponent fitted as 0 +- 4e-17 on noise-free data
#: (a share or an index constant in gamma) was called ill-determined by std. error > |value|.
NEGLIGIBLE_STDERR = 1e-6
#: A coefficient whose standard error (or Monte Carlo spread) exceeds this multiple of its
#: scale (:func:`coefficient_scale`) is ill-determined.
RELATIVE_ERROR_LIMIT = 1.0


def _negligible(model) -> tuple:
    """Per parameter: the standard error below which it is determined (0 when a bound is
    infinite)."""
    return per_model(model, "negligible stderr", lambda: tuple(
        NEGLIGIBLE_STDERR * (p.upper - p.lower) if math.isfinite(p.upper - p.lower) else 0.0
        for p in model.params))


def coefficient_scale(model, values) -> np.ndarray:
    """Scale against which a coefficient's uncertainty is judged: ``|value|``, but at least
    the parameter's :attr:`~irreflect.models.base.Parameter.zero_scale` (1 for the exponents
    ``v_*`` of ``cos^v(gamma)``, which are naturally 0: ``v_as = 0.0004 +- 0.0009`` is
    determined, ``0.3 +- 2`` is not)."""
    model = get_model(model)
    floor = per_model(model, "zero scale", lambda: np.array([p.zero_scale for p in model.params]))
    return np.maximum(np.abs(np.asarray(values, float)), floor)


def uncertain_mask(model, values, spread, relative_limit=RELATIVE_ERROR_LIMIT) -> np.ndarray:
    """Per coefficient, whether ``spread`` (standard errors or Monte Carlo spreads) leaves it
    ill-determined: not finite, or above ``relative_limit`` times its
    :func:`coefficient_scale` and above a millionth of its physical range. The one rule of
    the fit's flags, its verdict, the campaign and the protocol advice."""
    model = get_model(model)
    s = np.asarray(spread, float)
    with np.errstate(invalid="ignore"):
        loose = (s > relative_limit * coefficient_scale(model, values)) & (s > _negligible(model))
    return ~np.isfinite(s) | loose


def _why_ill(p, value: float, singular: bool) -> str:
    if singular:
        return "near-singular covariance"
    if abs(value) >= p.zero_scale:
        return "std. error > |value|"
    unit = "" if p.unit == "1" else f" {p.unit}"
    return f"std. error > {p.zero_scale:g}{unit}, its scale near 0"


def judge(model, values, stderr, singular, gamma_rad, converged, message,
          validity: bool = True) -> tuple:
    """(at_bound, ill_determined, warnings) of a fit: the checks every command prints
    (``validity``: run the model's own check, :meth:`~irreflect.models.ReflectionModel.validity_warnings`, too)."""
    at_bound, detail = [], []
    values_f = np.asarray(values, float).tolist()  # Python floats: scalar tests in µs, not 10s
    for (name, checks), v in zip(_bound_checks(model), values_f, strict=True):
        for side, b, tol in checks:
            if (side == "lower" and v <= b + tol) or (side == "upper" and v >= b - tol):
                at_bound.append(name)
                detail.append(f"{name} = {v:.4g} ({side} bound {_fmt_bound(b)})")
    ill, ill_detail = [], []
    loose = uncertain_mask(model, values, stderr).tolist()
    for p, v, s, sing, bad in zip(model.params, values_f, np.asarray(stderr, float).tolist(),
                                  np.asarray(singular, bool).tolist(), loose, strict=True):
        if bad or sing:
            ill.append(p.name)
            ill_detail.append(f"{p.name} = {v:.4g} +- {s:.2g} ({_why_ill(p, v, sing)})")
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
    if validity:
        warnings += list(model.validity_warnings(values, gamma_rad))
    return tuple(at_bound), tuple(ill), tuple(warnings)


#: A fit weighted by the table's sigma whose reduced chi^2 exceeds this, at a chance
#: below :data:`SIGMA_LACK_OF_FIT_P` under the sigma, says its standard errors understate.
SIGMA_CHI2 = 2.0
SIGMA_LACK_OF_FIT_P = 1e-3
#: How :func:`sigma_note`'s warning begins (diagnose, which tests the lack of fit itself
#: against the noise it estimates, leaves it out).
SIGMA_NOTE_HEAD = "the readings depart from the fit by chi^2/dof"


def sigma_note(model, values, stderr, ill, chi2_reduced: float, dof: int) -> tuple[str, ...]:
    """A warning when the readings depart from a fit weighted by their sigma far beyond
    it: the standard errors take sigma as given (a Cornell table with sigma 1 % of its
    median power, chi^2/dof 2.9e5: errors 500 times below the unweighted fit's, and no
    coefficient called ill-determined that the unweighted fit calls so). Names the
    coefficients that errors scaled by sqrt(chi^2/dof) would leave ill-determined."""
    from scipy import special

    if not (dof > 0 and np.isfinite(chi2_reduced) and chi2_reduced > SIGMA_CHI2):
        return ()
    p = float(special.chdtrc(dof, chi2_reduced * dof))
    if not p < SIGMA_LACK_OF_FIT_P:
        return ()
    scaled = uncertain_mask(model, values, np.asarray(stderr, float) * math.sqrt(chi2_reduced))
    more = [q.name for q, bad in zip(model.params, scaled, strict=True)
            if bad and q.name not in ill]
    return (f"{SIGMA_NOTE_HEAD} {chi2_reduced:.3g} against "
            f"their sigma ({p_text(p)}): the model lacks an effect of the material "
            "(irreflect diagnose names it) or sigma understates the noise, and the standard "
            "errors, which take sigma as given, understate the uncertainty"
            + (f" (scaled by sqrt(chi^2/dof), {', '.join(more)} would be ill-determined)"
               if more else ""),)


def _radians_and_weights(meas, sigma) -> tuple:
    """A table's angles in radians and its weights ``1 / sigma^2`` (1 without sigma)."""
    weights = np.ones_like(meas.power) if sigma is None else 1.0 / sigma**2
    return np.radians(meas.gamma_deg), np.radians(meas.theta_deg), weights


def _check_sigma(sigma, source) -> None:
    if (sigma <= 0).any():
        raise IrreflectError(
            f"{source}: sigma must be > 0 to weight a fit by 1/sigma^2, found "
            f"{int(np.sum(sigma <= 0))} zero or negative value(s): fix them or drop the "
            "sigma column to fit unweighted"
        )
