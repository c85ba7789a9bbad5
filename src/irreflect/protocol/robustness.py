"""Monte Carlo of goniometer errors: how much do a protocol's fitted coefficients move?

A reference model (the two-lobe fit of a dense scan, say) plays the material. In each
trial the technician sets the protocol's nominal angles, but the goniometer delivers

* ``gamma + e_gamma``, one error per angle-of-incidence setting (gamma is set once and
  kept for all of that gamma's points), ``e_gamma ~ U(-angle_error, +angle_error)``;
* ``theta + e_theta``, one error per point, ``e_theta ~ U(-angle_error, +angle_error)``;
* power ``P_true (1 + power_noise * N(0,1)) + power_noise_abs * N(0,1)``.

The model is fitted to the *nominal* angles and these powers, as the technician would,
for every trial in one batch (:func:`irreflect.fitting.fit_subsets`). The result is the
spread of every coefficient and of R^2 (measured against the dense points), and a flag
when the protocol leaves coefficients ill-determined: a robust spread (IQR / 1.349)
larger than :data:`~.advice.RELATIVE_ERROR_LIMIT` times the coefficient's scale, or a
rank correlation between two coefficients beyond :data:`~.advice.CORRELATION_LIMIT`.
The same seed gives the same draws, and the draws are the same standard variates scaled
by ``angle_error``, so runs that differ only in the error size are directly comparable.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from tqdm import tqdm

from .. import metrics
from .._progress import on_terminal
from ..data import Measurements, as_measurements
from ..errors import FitError, FitWarning, IrreflectError
from ..fitting import FitResult, fit, fit_subsets
from ..models import get_model
from ..validation import check_int, check_number, check_seed, check_trials_budget
from .advice import (
    CORRELATION_LIMIT,
    RELATIVE_ERROR_LIMIT,
    coefficient_scale,
    ill_determined,
)
from .export import as_protocol

_CHUNK = 100  # trials per batched fit (bounds the memory of the batch)


def _robust_sd(x, axis=0):
    q75, q25 = np.nanpercentile(x, [75, 25], axis=axis)
    return (q75 - q25) / 1.349


#: Fewer successful trials than this: the coefficients' rank correlations are not judged
#: (with 5 trials, evaluate-protocol flagged every pair of four coefficients at +-1.000).
MIN_CORRELATION_TRIALS = 20


def _rank_correlation(samples: np.ndarray) -> np.ndarray:
    """Spearman correlation of the columns of ``samples`` (NaN for constant columns)."""
    ranks = pd.DataFrame(samples).rank(axis=0).to_numpy()  # average ranks of ties
    k = samples.shape[1]
    with np.errstate(divide="ignore", invalid="ignore"):
        centred = ranks - ranks.mean(axis=0)
        norm = np.sqrt(np.sum(centred**2, axis=0))
        corr = (centred.T @ centred) / np.outer(norm, norm)
    corr[~np.isfinite(corr)] = np.nan
    corr[np.arange(k), np.arange(k)] = 1.0
    return corr


@dataclass(frozen=True)
class RobustnessResult:
    """Spread of a protocol's fitted coefficients and R^2 under goniometer errors."""

    protocol: str
    model: str
    param_names: tuple[str, ...]
    reference: np.ndarray  # (k,) the coefficients playing the material
    nominal: np.ndarray  # (k,) fit at the nominal angles without any error
    samples: np.ndarray  # (T, k) fitted coefficients per trial (NaN where failed)
    r2: np.ndarray  # (T,) R^2 of each trial's fit against the dense points
    r2_nominal: float
    failed: np.ndarray  # (T,) bool
    n_trials: int
    angle_error_deg: float
    power_noise: float
    power_noise_abs: float
    seed: int
    correlation: np.ndarray  # (k, k) rank correlation of the samples
    reasons: tuple[str, ...]
    dense_name: str = "dense"
    scale: np.ndarray = field(default=None, repr=False)

    @property
    def flagged(self) -> bool:
        """True if the protocol leaves a coefficient ill-determined."""
        return bool(self.reasons)

    @property
    def spread(self) -> np.ndarray:
        """Robust standard deviation (IQR / 1.349) of every coefficient."""
        return _robust_sd(self.samples[~self.failed])

    @property
    def relative_spread(self) -> np.ndarray:
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.spread / self.scale

    @property
    def r2_spread(self) -> float:
        return float(_robust_sd(self.r2[~self.failed]))

    def table(self) -> pd.DataFrame:
        """One row per coefficient: reference, nominal fit, median, spread, 5-95 %."""
        ok = self.samples[~self.failed]
        p5, p50, p95 = np.nanpercentile(ok, [5, 50, 95], axis=0)
        ill = {r.split(":")[0] for r in self.reasons if " and " not in r.split(":")[0]}
        return pd.DataFrame({
            "coefficient": self.param_names,
            "reference": self.reference,
            "nominal_fit": self.nominal,
            "median": p50,
            "spread": self.spread,
            "relative_spread": self.relative_spread,
            "p5": p5,
            "p95": p95,
            "ill_determined": [n in ill for n in self.param_names],
        })

    def r2_summary(self) -> dict:
        ok = self.r2[~self.failed]
        p5, p50, p95 = np.percentile(ok, [5, 50, 95]) if ok.size else (np.nan,) * 3
        return {"r2_nominal": self.r2_nominal, "r2_median": float(p50), "r2_p5": float(p5),
                "r2_p95": float(p95), "r2_spread": self.r2_spread,
                "n_failed": int(self.failed.sum())}

    def summary(self) -> str:
        s = self.r2_summary()
        lines = [
            f"robustness of {self.protocol} ({self.model}, reference fitted on {self.dense_name}): "
            f"{self.n_trials} trials, angle errors uniform +-{self.angle_error_deg:g} deg, power "
            f"noise {self.power_noise * 100:g}% + {self.power_noise_abs:g}, seed {self.seed}",
            f"  R^2 against the dense points: nominal {s['r2_nominal']:.4f}, median "
            f"{s['r2_median']:.4f}, 5-95% [{s['r2_p5']:.4f}, {s['r2_p95']:.4f}]"
            + (f", {s['n_failed']} failed fits" if s["n_failed"] else ""),
            f"  {'coefficient':<12}{'nominal':>11}{'median':>11}{'spread':>11}{'rel.':>8}"
            f"{'5%':>11}{'95%':>11}",
        ]
        for row in self.table().itertuples():
            lines.append(
                f"  {row.coefficient:<12}{row.nominal_fit:>11.4g}{row.median:>11.4g}"
                f"{row.spread:>11.3g}{row.relative_spread * 100:>7.0f}%{row.p5:>11.4g}"
                f"{row.p95:>11.4g}" + ("  ILL-DETERMINED" if row.ill_determined else "")
            )
        n_ok = int((~self.failed).sum())
        if n_ok < MIN_CORRELATION_TRIALS:
            lines.append(f"  correlations not judged: {n_ok} successful trial(s), fewer than "
                         f"the {MIN_CORRELATION_TRIALS} a rank correlation needs (of 5 "
                         "samples, one of +-1 is common by chance): pass --monte-carlo "
                         f"{MIN_CORRELATION_TRIALS} or more")
        if self.reasons:
            lines.append("  flagged: " + "; ".join(self.reasons))
        else:
            lines.append("  not flagged: every coefficient is determined by this protocol")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {
            "protocol": self.protocol, "model": self.model, "n_trials": self.n_trials,
            "angle_error_deg": self.angle_error_deg, "power_noise": self.power_noise,
            "power_noise_abs": self.power_noise_abs, "seed": self.seed,
            **self.r2_summary(),
            "coefficients": self.table().to_dict(orient="records"),
            "flagged": self.flagged, "reasons": list(self.reasons),
        }


def _structural_reasons(model_obj, g0, t0, power, seed, reasons) -> list[str]:
    """Coefficients the protocol's angles cannot determine whatever the noise: those in
    a near-singular direction of the information matrix of the error-free fit (e.g. every
    ``v`` of Eqs. 15-18 when all points share one angle of incidence). A Monte Carlo
    alone can miss them: a degenerate coefficient may simply stay at its start."""


    try:
        with warnings.catch_warnings():  # an internal check, not a fit the user asked for
            warnings.simplefilter("ignore", FitWarning)
            nominal = fit(Measurements(g0, t0, power, name="protocol"), model_obj, seed=seed)
    except (FitError, IrreflectError):
        return []
    named = {r.split(":")[0] for r in reasons}
    return [f"{name}: not determined by these angles (near-singular information matrix)"
            for name in nominal.ill_determined if name not in named]


def _bound_reasons(model_obj, samples, reasons) -> list[str]:
    """Coefficients that sit on a bound of their range in at least half of the trials: their
    spread there is 0 because the fit runs to the edge of the range, not because the
    protocol's angles pin them (a spread alone would call them determined)."""
    named = {r.split(":")[0] for r in reasons}
    out = []
    for k, p in enumerate(model_obj.params):
        if p.name in named:
            continue
        width = (p.upper - p.lower) if np.isfinite(p.upper - p.lower) else 1.0
        tol = 1e-6 * max(width, 1.0)
        for bound in (p.lower, p.upper):
            if not np.isfinite(bound):
                continue
            share = float(np.mean(np.abs(samples[:, k] - bound) <= tol))
            if share >= 0.5:
                out.append(f"{p.name}: at its bound {bound:g} in {share:.0%} of the trials (the "
                           "fit runs to the edge of its range: these angles do not pin it)")
                break
    return out


def _reference(reference, model, dense, seed):
    """(the reference fit, the model, the points R^2 is measured against) of
    :func:`protocol_robustness`'s ``reference``, ``model`` and ``dense``."""
    if isinstance(reference, FitResult):
        ref_fit = reference
        model_obj = get_model(model or reference.model_object or reference.model)
        if model_obj.name != ref_fit.model:
            raise IrreflectError(
                f"the reference was fitted with '{ref_fit.model}' but model '{model_obj.name}' "
                "was asked: pass the dense measurements instead of the fit"
            )
        if dense is None:
            dense = Measurements(ref_fit.gamma_deg, ref_fit.theta_deg, ref_fit.power,
                                 name="reference data")
    else:
        dense = as_measurements(reference) if dense is None else dense
        model_obj = get_model(model or "two-lobe")
        ref_fit = fit(as_measurements(reference), model_obj, seed=seed)
    return ref_fit, model_obj, dense


def _fit_rows(rows, g0, t0, model_obj, max_iter, progress):
    """The fit of every row of power at the protocol's angles ``(g0, t0)`` in batches of
    subset fits: (parameters (R, k), failed (R,))."""
    n = g0.size
    params = np.empty((rows.shape[0], model_obj.n_params))
    failed = np.empty(rows.shape[0], bool)
    chunks = range(0, rows.shape[0], _CHUNK)
    if progress and on_terminal():  # a transient bar; nothing through a pipe
        chunks = tqdm(chunks, desc="Monte Carlo", unit="batch", leave=False)
    for start in chunks:
        block = rows[start:start + _CHUNK]
        b = block.shape[0]
        masks = np.kron(np.eye(b, dtype=bool), np.ones((1, n), bool))
        res = fit_subsets(np.tile(g0, b), np.tile(t0, b), block.ravel(), masks, model_obj,
                          max_iter=max_iter)
        params[start:start + b] = res.params
        failed[start:start + b] = res.failed
    return params, failed


def protocol_robustness(protocol, reference, *, model=None, dense=None, n_trials: int = 200,
                        angle_error_deg: float = 1.0, power_noise: float = 0.01,
                        power_noise_abs: float = 0.0, seed: int = 0, max_iter: int = 100,
                        relative_limit: float = RELATIVE_ERROR_LIMIT,
                        correlation_limit: float = CORRELATION_LIMIT,
                        progress: bool = False) -> RobustnessResult:
    """Monte Carlo of angle errors and power noise for a protocol (see the module docstring).

    Parameters
    ----------
    protocol : Protocol, table or path
    reference : FitResult or Measurements
        The material: a fitted model, or a dense scan to which ``model`` is fitted first.
    model : str, optional
        Model to fit (default: the reference's model, else ``"two-lobe"``).
    dense : Measurements, optional
        Points R^2 is measured against (default: the reference's own points).
    n_trials : int
    angle_error_deg : float, degrees
        Half-width of the uniform error of both arms.
    power_noise : float
        Relative (multiplicative) Gaussian power noise, 1-sigma (0.01 = 1 %).
    power_noise_abs : float
        Additive Gaussian power noise, 1-sigma, in the power's unit.
    seed : int
    """
    n_trials = check_int(n_trials, "n_trials", 2)
    check_trials_budget(n_trials)  # before any fit
    # an angle error beyond 10 deg moves a reading to another part of the curve: it is no
    # longer an error of the setting (the campaign's replay has the same limit)
    check_number(angle_error_deg, "angle error (deg)", low=0.0, high=10.0)
    for name, value in (("power_noise", power_noise), ("power_noise_abs", power_noise_abs)):
        check_number(value, name, low=0.0)
    seed = check_seed(seed)
    protocol = as_protocol(protocol)
    ref_fit, model_obj, dense = _reference(reference, model, dense, seed)
    dense = as_measurements(dense)
    for name, value in (("angle error", angle_error_deg), ("power noise", power_noise),
                        ("absolute power noise", power_noise_abs)):
        if not (np.isfinite(value) and value >= 0):
            raise IrreflectError(f"{name} must be a finite number >= 0; found {value:g}")
    if protocol.n_points < model_obj.n_params:
        raise IrreflectError(
            f"the protocol has {protocol.n_points} points, fewer than the {model_obj.n_params} "
            f"parameters of '{model_obj.name}': no fit is possible"
        )
    n_trials = int(n_trials)
    truth = ref_fit.values
    g0, t0 = protocol.gamma_deg, protocol.theta_deg
    n = g0.size
    levels, level_of = np.unique(g0, return_inverse=True)
    rng = np.random.default_rng(seed)
    ug = rng.uniform(-1.0, 1.0, (n_trials, levels.size))
    ut = rng.uniform(-1.0, 1.0, (n_trials, n))
    zr = rng.standard_normal((n_trials, n))
    za = rng.standard_normal((n_trials, n))
    g_act = np.clip(g0 + angle_error_deg * ug[:, level_of], -89.9, 89.9)
    t_act = np.clip(t0 + angle_error_deg * ut, -89.9, 89.9)
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        true = model_obj.predict_deg(truth, g_act, t_act)
    measured = true * (1.0 + power_noise * zr) + power_noise_abs * za
    nominal_power = model_obj.predict_deg(truth, g0, t0)[None]
    rows = np.vstack([nominal_power, measured])  # row 0: no error at all

    params, failed = _fit_rows(rows, g0, t0, model_obj, max_iter, progress)
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        pred = model_obj.predict_deg(np.where(failed[:, None], truth, params),
                                     dense.gamma_deg, dense.theta_deg)
    r2 = np.asarray(metrics.r2(dense.power, pred), float).reshape(-1)
    r2 = np.where(failed, np.nan, r2)
    nominal, samples, r2_trials = params[0], params[1:], r2[1:]
    failed_trials = failed[1:]
    ok = samples[~failed_trials]
    if ok.shape[0] < 2:
        raise IrreflectError(
            f"only {ok.shape[0]} of {n_trials} Monte Carlo fits succeeded: the protocol cannot "
            "determine this model"
        )
    centre = nominal if np.all(np.isfinite(nominal)) else truth
    scale = coefficient_scale(model_obj, centre)
    corr = _rank_correlation(ok)
    spread = _robust_sd(ok)
    # too few trials for a rank correlation to mean much: not judged (summary says so)
    judged = corr if ok.shape[0] >= MIN_CORRELATION_TRIALS else np.full_like(corr, np.nan)
    reasons = ill_determined(model_obj, centre, spread, judged, relative_limit=relative_limit,
                             correlation_limit=correlation_limit)
    reasons += _structural_reasons(model_obj, g0, t0, nominal_power[0], seed, reasons)
    reasons += _bound_reasons(model_obj, ok, reasons)
    return RobustnessResult(
        protocol=protocol.name, model=model_obj.name, param_names=model_obj.param_names,
        reference=np.asarray(truth, float), nominal=nominal, samples=samples, r2=r2_trials,
        r2_nominal=float(r2[0]), failed=failed_trials, n_trials=n_trials,
        angle_error_deg=float(angle_error_deg), power_noise=float(power_noise),
        power_noise_abs=float(power_noise_abs), seed=int(seed), correlation=corr,
        reasons=tuple(reasons), dense_name=dense.name, scale=scale,
    )
