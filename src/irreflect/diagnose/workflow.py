"""The discrepancy workflow: where model and measurements disagree, which effect is missing.

1. Fit the base model (default ``two-lobe``). Noise: the table's ``sigma`` column
   ("given"), or estimated from the data ("estimated"): a difference-based estimator
   (Gasser, Sroka and Jennen-Steinmetz 1986) along theta within each angle of incidence,
   applied to the base model's residuals so that the sharp specular peak the model already
   describes does not inflate it, made robust by clipping pseudo-residuals beyond 3 MAD;
   re-estimated on the residuals of each accepted extended model when that gives less
   (a misfit that is sharp on the scale of the grid leaks into the first estimate).
2. Locate the disagreement: residuals normalised by the noise, mapped over (gamma, theta);
   a lack-of-fit statistic ``chi2 / dof`` with its p-value (chi-square with a given sigma,
   F with an estimated one, whose degrees of freedom are measured by simulating pure noise
   on the same grid); structure tests: the runs of residual signs along theta, and the mean
   residual per angle of incidence, per receiver angle, per distance from the mirror
   direction and per distance from the source direction.
3. Name the effect: fit every registered extension on top of the current model, started at
   its optimum, and rank them by BIC. The best is accepted only on strong evidence: BIC
   lower by more than ``min_delta_bic`` (10: "very strong", Kass and Raftery 1995), a lower
   ``chi2 / dof``, at least ``min_share`` of the excess residual (the chi-square above
   what noise alone would give) explained, and a BIC at least ``min_margin`` below the
   runner-up's (else the data cannot tell the two apart and no name is given).
4. Repeat until no candidate is accepted; verdict: "no missing effect", "effects found"
   (and the residual is now consistent with the noise) or "unexplained structure remains"
   (with where it lies).
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import special

from .._jsonio import finite
from ..data import Measurements, as_measurements
from ..errors import FitError, FitWarning, IrreflectError
from ..fitting import FitResult, fit
from ..models import ReflectionModel, get_model
from ..models.extensions import (
    EXTENSIONS,
    applied_extensions,
    get_extension,
    warm_starts,
)

#: verdict codes (the ``verdict`` key of the JSON output)
NO_MISSING_EFFECT = "no missing effect"
EFFECTS_FOUND = "effects found"
UNEXPLAINED = "unexplained structure remains"

_MAD_TO_SIGMA = 1.0 / special.ndtri(0.75)  # normal quantile: 1 / 0.6745


# ----------------------------------------------------------------------------- noise
@dataclass(frozen=True)
class NoiseEstimate:
    """Measurement noise: per-point 1-sigma ``sigma`` (power units), its typical value
    ``value`` (median), where it came from (``source``: "given" or "estimated") and the
    degrees of freedom of the estimate (``inf`` when given)."""

    sigma: np.ndarray
    value: float
    source: str
    dof: float
    method: str


def difference_weights(gamma_deg, theta_deg, order: int = 2):
    """Weights of the difference-based pseudo-residuals along theta within each gamma.

    Every run of ``order + 1`` consecutive receiver angles (sorted, same angle of incidence)
    gives one pseudo-residual ``e = sum_j w_j y_j`` with ``w`` the divided-difference
    weights of that run normalised to unit length: ``e`` is blind to any polynomial of
    degree < ``order`` in theta and has variance ``sigma^2`` for pure noise (Gasser et al.
    1986 for ``order = 2``). Returns a sparse ``(windows, n)`` matrix (``order + 1`` values
    per row: a dense one would hold 3.2 GB on a 20,000-point table); angles in degrees.
    """
    from scipy import sparse

    gamma_deg = np.asarray(gamma_deg, float)
    theta = np.radians(np.asarray(theta_deg, float))
    n = gamma_deg.size
    k = order + 1
    cols, vals = [], []
    for g in np.unique(gamma_deg):
        idx = np.nonzero(gamma_deg == g)[0]
        idx = idx[np.argsort(theta[idx], kind="stable")]
        if idx.size < k:
            continue
        win = np.lib.stride_tricks.sliding_window_view(idx, k)  # (windows, k)
        x = theta[win]
        diff = x[:, :, None] - x[:, None, :]
        diff[:, np.arange(k), np.arange(k)] = 1.0
        good = ~np.any(diff == 0, axis=(1, 2))
        w = 1.0 / np.prod(diff[good], axis=2)
        cols.append(win[good])
        vals.append(w / np.linalg.norm(w, axis=1, keepdims=True))
    cols = np.concatenate(cols) if cols else np.zeros((0, k), np.int64)
    vals = np.concatenate(vals) if vals else np.zeros((0, k))
    m = cols.shape[0]
    return sparse.csr_array((vals.ravel(), cols.ravel(), np.arange(0, m * k + 1, k)),
                            shape=(m, n))


def clipped_scale(e, clip: float = 3.0) -> np.ndarray:
    """Robust RMS along the last axis: pseudo-residuals beyond ``clip`` times the MAD scale
    are dropped (sharp features the differences do not cancel), the RMS of the rest is
    corrected for the truncation of a normal distribution at ``clip`` sigma. As efficient
    as the plain RMS on pure noise, as robust as the median when a minority is spoiled."""
    e = np.atleast_2d(np.asarray(e, float))
    s0 = _MAD_TO_SIGMA * np.median(np.abs(e), axis=-1, keepdims=True)
    keep = np.abs(e) <= clip * s0
    pdf = np.exp(-0.5 * clip * clip) / np.sqrt(2.0 * np.pi)
    kept_var = 1.0 - 2.0 * clip * pdf / (2.0 * special.ndtr(clip) - 1.0)
    mean_sq = np.sum(np.where(keep, e * e, 0.0), axis=-1) / np.maximum(np.sum(keep, axis=-1), 1)
    return np.sqrt(mean_sq / kept_var)


def estimate_noise(measurements, residuals=None, *, order: int = 2, seed: int = 0,
                   n_sim: int = 400) -> NoiseEstimate:
    """Noise of a measurement table: the ``sigma`` column if present, else estimated.

    Parameters
    ----------
    measurements : Measurements
    residuals : array, optional
        Residuals of a fitted model (power units). The estimator is applied to them instead
        of the raw power: the model takes out the sharp specular peak, the differences take
        out what smooth misfit is left. Without them, the raw power is used.
    order : int
        Order of the differences (2: three consecutive receiver angles).
    seed : int
        Seeds the simulation that measures the estimate's degrees of freedom.
    n_sim : int
        Pure-noise replicates of that simulation.

    Returns
    -------
    NoiseEstimate
        The clipped RMS of the pseudo-residuals (:func:`clipped_scale`) for every point
        (constant noise is assumed), with the degrees of freedom ``1 / (2 var(ln sigma))``
        of that estimate measured on pure noise on this grid.

    Raises
    ------
    IrreflectError
        If no angle of incidence has ``order + 1`` receiver angles and no sigma is given.
    """
    meas = as_measurements(measurements)
    if meas.sigma is not None:
        sigma = np.asarray(meas.sigma, float)
        return NoiseEstimate(sigma=sigma, value=float(np.median(sigma)), source="given",
                             dof=float("inf"), method="sigma column of the table")
    weights = difference_weights(meas.gamma_deg, meas.theta_deg, order)
    if weights.shape[0] < 5:
        raise IrreflectError(
            f"cannot estimate the measurement noise: found {weights.shape[0]} runs of "
            f"{order + 1} receiver angles at one angle of incidence, need at least 5; "
            "add a sigma column to the table or measure more receiver angles per gamma"
        )
    values = meas.power if residuals is None else np.asarray(residuals, float)
    sigma_hat = float(clipped_scale(weights @ values)[0])
    floor = 1e-12 * max(float(np.max(np.abs(meas.power))), 1e-300)
    sigma_hat = max(sigma_hat, floor)
    rng = np.random.default_rng(seed)
    log_s = np.log(clipped_scale((weights @ rng.standard_normal((n_sim, meas.n_points)).T).T))
    dof = float(1.0 / (2.0 * max(np.var(log_s), 1e-12)))
    what = "base-model residuals" if residuals is not None else "measured power"
    return NoiseEstimate(
        sigma=np.full(meas.n_points, sigma_hat), value=sigma_hat, source="estimated", dof=dof,
        method=f"clipped RMS of order-{order} differences of the {what} along theta within "
               f"each gamma ({weights.shape[0]} pseudo-residuals, {dof:.0f} effective dof)",
    )


# ----------------------------------------------------------------------------- statistics
@dataclass(frozen=True)
class LackOfFit:
    """Lack-of-fit of a model against the noise: ``chi2 = sum (r / sigma)^2`` on ``dof``
    degrees of freedom, ``ratio = chi2 / dof`` (1 when only noise is left) and the p-value of
    a ratio at least that large (chi-square test with a given sigma, F test with an
    estimated one)."""

    chi2: float
    dof: int
    ratio: float
    p_value: float
    test: str


def lack_of_fit(normalized_residuals, n_params: int, noise: NoiseEstimate) -> LackOfFit:
    z = np.asarray(normalized_residuals, float)
    chi2 = float(np.sum(z * z))
    dof = max(z.size - int(n_params), 1)
    ratio = chi2 / dof
    if np.isinf(noise.dof):
        p, test = float(special.chdtrc(dof, chi2)), "chi-square"
    else:
        p, test = float(special.fdtrc(dof, noise.dof, ratio)), "F"
    return LackOfFit(chi2=chi2, dof=dof, ratio=ratio, p_value=p, test=test)


@dataclass(frozen=True)
class StructureTest:
    """One test for non-random residuals: statistic, degrees of freedom, p-value and where
    the strongest deviation lies (``where``, ``z_worst`` its z-score)."""

    name: str
    statistic: float
    dof: float
    p_value: float
    where: str
    z_worst: float


def _deg(x) -> str:
    """An angle for a sentence: degrees to 0.1, no trailing zeros."""
    return f"{round(float(x), 1):g}"


def _runs_test(gamma_deg, theta_deg, z) -> StructureTest:
    """Wald-Wolfowitz runs of residual signs along theta within each gamma (too few runs
    = neighbouring residuals share their sign = structure)."""
    runs = expected = variance = 0.0
    longest = (0, None, None, None, 0)
    for g in np.unique(gamma_deg):
        sel = np.nonzero(gamma_deg == g)[0]
        sel = sel[np.argsort(theta_deg[sel], kind="stable")]
        signs = np.sign(z[sel])
        keep = signs != 0
        s, th = signs[keep], theta_deg[sel][keep]
        n1, n2 = int(np.sum(s > 0)), int(np.sum(s < 0))
        n = n1 + n2
        if n < 2:
            continue
        change = np.nonzero(s[1:] != s[:-1])[0]
        runs += change.size + 1
        expected += 1.0 + 2.0 * n1 * n2 / n
        variance += 2.0 * n1 * n2 * (2.0 * n1 * n2 - n) / (n * n * (n - 1.0))
        bounds = np.concatenate([[0], change + 1, [n]])
        lengths = np.diff(bounds)
        i = int(np.argmax(lengths))
        if lengths[i] > longest[0]:
            longest = (int(lengths[i]), g, th[bounds[i]], th[bounds[i + 1] - 1], s[bounds[i]])
    zscore = (runs - expected) / np.sqrt(variance) if variance > 0 else 0.0
    p = float(special.ndtr(zscore))
    length, g, t0, t1, sign = longest
    where = (f"{length} residuals in a row {'above' if sign > 0 else 'below'} the model at "
             f"gamma {_deg(g)} deg, theta {_deg(t0)}..{_deg(t1)} deg") if length else "no residuals"
    return StructureTest("runs of signs along theta", float(runs), float(expected), p, where,
                         float(zscore))


def _group_test(name, z, labels, describe) -> StructureTest:
    """Mean normalised residual per group: ``sum n_b mean_b^2 ~ chi2(groups)`` for noise."""
    keys, inverse, counts = np.unique(labels, return_inverse=True, return_counts=True)
    sums = np.bincount(inverse, weights=z, minlength=keys.size)
    means = sums / counts
    zb = means * np.sqrt(counts)
    stat = float(np.sum(zb * zb))
    dof = int(keys.size)
    p = float(special.chdtrc(dof, stat))
    i = int(np.argmax(np.abs(zb)))
    where = (f"{describe(keys[i])}: mean residual {means[i]:+.2f} sigma over {counts[i]} "
             f"points (z = {zb[i]:+.1f})")
    return StructureTest(name, stat, float(dof), p, where, float(zb[i]))


_OFFSET_EDGES = np.array([-30.0, -12.0, -4.0, 4.0, 12.0, 30.0])
_OFFSET_NAMES = (">30", "12-30", "4-12", "within 4", "4-12", "12-30", ">30")


def _offset_label(direction: str, negative: str, positive: str):
    def describe(k):
        k = int(k)
        if k == 3:
            return f"within 4 deg of the {direction} direction"
        side = negative if k < 3 else positive
        return f"{_OFFSET_NAMES[k]} deg from the {direction} direction toward {side}"
    return describe


def structure_tests(gamma_deg, theta_deg, normalized_residuals) -> list[StructureTest]:
    """The five structure tests of the workflow (angles in degrees, residuals / sigma)."""
    g = np.asarray(gamma_deg, float)
    t = np.asarray(theta_deg, float)
    z = np.asarray(normalized_residuals, float)
    mirror = t + g  # > 0: beyond the mirror direction, toward grazing
    source = t - g  # > 0: from the source toward the normal
    return [
        _runs_test(g, t, z),
        _group_test("mean by angle of incidence", z, g, lambda k: f"gamma {_deg(k)} deg"),
        _group_test("mean by receiver angle", z, np.round(t / 10.0) * 10.0,
                    lambda k: f"theta {_deg(k - 5)}..{_deg(k + 5)} deg"),
        _group_test("mean by distance from the mirror direction", z,
                    np.searchsorted(_OFFSET_EDGES, mirror),
                    _offset_label("mirror", "the normal", "grazing")),
        _group_test("mean by distance from the source direction", z,
                    np.searchsorted(_OFFSET_EDGES, source),
                    _offset_label("source", "grazing", "the normal")),
    ]


def per_gamma_chi2(gamma_deg, normalized_residuals) -> dict[float, float]:
    """``chi2 / points`` of the normalised residuals per angle of incidence (1 = noise)."""
    g = np.asarray(gamma_deg, float)
    z = np.asarray(normalized_residuals, float)
    return {float(k): float(np.mean(z[g == k] ** 2)) for k in np.unique(g)}


# ----------------------------------------------------------------------------- steps
@dataclass(frozen=True)
class Assessment:
    """A fitted model judged against the noise."""

    fit: FitResult
    residuals_z: np.ndarray
    lack_of_fit: LackOfFit
    structure: tuple[StructureTest, ...]
    bic: float
    polar_errors: dict
    gamma_chi2: dict

    @property
    def model_name(self) -> str:
        return self.fit.model

    def flagged(self, alpha: float) -> list[StructureTest]:
        """Structure tests significant at ``alpha`` after a Bonferroni correction."""
        return [s for s in self.structure if s.p_value < alpha / len(self.structure)]

    def consistent(self, alpha: float) -> bool:
        """The residual looks like noise: no lack of fit and no structure at ``alpha``."""
        return self.lack_of_fit.p_value >= alpha and not self.flagged(alpha)


@dataclass(frozen=True)
class Candidate:
    """One extension tried on top of the current model."""

    name: str
    assessment: Assessment | None
    delta_bic: float
    share_explained: float
    rss_drop: float
    accepted: bool
    reason: str


@dataclass(frozen=True)
class Effect:
    """An accepted extension: its new parameters with standard errors, the evidence."""

    name: str
    params: dict
    stderr: dict
    units: dict
    delta_bic: float
    share_explained: float
    rss_drop: float


@dataclass(frozen=True)
class Diagnosis:
    """The outcome of :func:`diagnose`."""

    name: str
    n_points: int
    base_model: str
    noise: NoiseEstimate
    steps: tuple[Assessment, ...]
    candidates: tuple[tuple[Candidate, ...], ...]
    effects: tuple[Effect, ...]
    verdict: str
    summary: str
    where: tuple[str, ...]
    alpha: float
    elapsed_s: float
    settings: dict = field(default_factory=dict)

    @property
    def before(self) -> Assessment:
        return self.steps[0]

    @property
    def after(self) -> Assessment:
        return self.steps[-1]

    @property
    def unexplained(self) -> bool:
        return self.verdict == UNEXPLAINED

    @property
    def final_model(self) -> ReflectionModel:
        return self.after.fit.model_object

    def to_dict(self) -> dict:
        """The JSON object of ``irreflect diagnose --json``."""

        def metrics(a: Assessment) -> dict:
            return {"model": a.model_name, "rmse": a.fit.rmse, "r2": a.fit.r2,
                    "chi2_dof": a.lack_of_fit.ratio, "lack_of_fit_p": a.lack_of_fit.p_value,
                    "bic": a.bic,
                    "polar_error_pct": {f"{k:g}": v for k, v in a.polar_errors.items()}}

        return finite({
            "dataset": self.name,
            "n_points": self.n_points,
            "model": self.base_model,
            "effects": [{"name": e.name, "params": e.params, "stderr": e.stderr,
                         "delta_bic": e.delta_bic, "share_explained": e.share_explained}
                        for e in self.effects],
            "before": metrics(self.before),
            "after": metrics(self.after),
            "steps": [metrics(a) | {"structure": {s.name: {"p": s.p_value, "where": s.where}
                                                  for s in a.structure}}
                      for a in self.steps],
            "candidates": [[{"name": c.name, "delta_bic": c.delta_bic,
                             "share_explained": c.share_explained, "accepted": c.accepted,
                             "reason": c.reason} for c in row] for row in self.candidates],
            "noise_sigma": self.noise.value,
            "noise_source": self.noise.source,
            "noise_method": self.noise.method,
            "unexplained": self.unexplained,
            "verdict": self.verdict,
            "summary": self.summary,
            "where": list(self.where),
            "elapsed_s": self.elapsed_s,
        })

    def report(self) -> str:
        """A readable account of every step."""
        lines = [f"diagnose {self.name}: {self.n_points} points, base model {self.base_model}"]
        src = "given by the table's sigma column" if self.noise.source == "given" else \
            f"estimated: {self.noise.method}"
        lines.append(f"noise: sigma = {self.noise.value:.4g} ({src})")
        for i, a in enumerate(self.steps):
            head = "step 0: base model" if i == 0 else f"step {i}: + {self.effects[i - 1].name}"
            lines.append("")
            lines.append(f"{head} ({a.model_name})")
            lines.append(_assessment_line(a))
            lines.append("  structure (p-values; Bonferroni level "
                         f"{self.alpha / len(a.structure):.3g}):")
            for s in a.structure:
                mark = " *" if s.p_value < self.alpha / len(a.structure) else ""
                lines.append(f"    {s.name:<44} {_p_text(s.p_value)}{mark}  [{s.where}]")
            worst = sorted(a.gamma_chi2.items(), key=lambda kv: -kv[1])[:3]
            lines.append("  chi2/points by gamma (1 = noise): "
                         + ", ".join(f"{_deg(g)} deg: {v:.3g}" for g, v in worst))
            if a.polar_errors:
                lines.append("  polar-area error (section 5.3): "
                             + ", ".join(f"{_deg(g)} deg {e:.2f}%"
                                         for g, e in a.polar_errors.items()))
            if i > 0:
                e = self.effects[i - 1]
                lines.append(f"  added {e.name}: delta BIC {e.delta_bic:.1f}, explains "
                             f"{100 * e.share_explained:.0f}% of the excess residual "
                             f"(RSS -{100 * e.rss_drop:.0f}%)")
                lines.append("  " + ", ".join(
                    f"{k} = {v:.4g} +- {e.stderr[k]:.2g} {e.units[k]}".rstrip()
                    for k, v in e.params.items()))
            if i < len(self.candidates):
                lines.append("  candidates (delta BIC; share of the excess residual explained):")
                for c in self.candidates[i]:
                    lines.append(f"    {c.name:<22} {c.delta_bic:>10.1f} "
                                 f"{100 * c.share_explained:>6.0f}%  "
                                 f"{'ACCEPTED' if c.accepted else c.reason}")
        lines.append("")
        lines.append(f"verdict: {self.verdict}")
        lines.append(self.summary)
        for w in self.where:
            lines.append(f"  - {w}")
        b, a = self.before, self.after
        lines.append(f"gap: RMSE {b.fit.rmse:.4g} -> {a.fit.rmse:.4g}, R^2 {b.fit.r2:.5f} -> "
                     f"{a.fit.r2:.5f}, chi2/dof {b.lack_of_fit.ratio:.3g} -> "
                     f"{a.lack_of_fit.ratio:.3g} ({self.elapsed_s:.1f} s)")
        return "\n".join(lines)


def _p_text(p: float) -> str:
    """``p = 0.012``, ``p = 3.1e-09`` or ``p < 1e-300`` (underflow)."""
    if p <= 0.0:
        return "p < 1e-300"
    return f"p = {p:.3g}" if p >= 1e-4 else f"p = {p:.1e}"


def _assessment_line(a: Assessment) -> str:
    lof = a.lack_of_fit
    return (f"  RMSE {a.fit.rmse:.4g}   R^2 {a.fit.r2:.5f}   chi2/dof {lof.ratio:.3g} "
            f"(dof {lof.dof}, {lof.test} {_p_text(lof.p_value)})   BIC {a.bic:.1f}")


def _bic(result: FitResult, z: np.ndarray, noise: NoiseEstimate) -> float:
    """BIC: ``chi2 + k ln n`` with a given sigma (known variance); ``n ln(RSS/n) + k ln n``
    with an estimated one (variance profiled out, which does not lean on the estimate)."""
    n, k = result.n_points, result.n_params
    if noise.source == "given":
        return float(np.sum(z * z) + k * np.log(n))
    rss = float(np.sum(result.residuals ** 2))
    return float(n * np.log(max(rss, 1e-300) / n) + k * np.log(n))


def assess(result: FitResult, noise: NoiseEstimate) -> Assessment:
    """Judge a fit against the noise: normalised residuals, lack of fit, structure, BIC."""
    z = result.residuals / noise.sigma
    return Assessment(
        fit=result,
        residuals_z=z,
        lack_of_fit=lack_of_fit(z, result.n_params, noise),
        structure=tuple(structure_tests(result.gamma_deg, result.theta_deg, z)),
        bic=_bic(result, z, noise),
        polar_errors=result.polar_errors(),
        gamma_chi2=per_gamma_chi2(result.gamma_deg, z),
    )


# ----------------------------------------------------------------------------- the loop
def _fit_candidate(meas, model, current: FitResult, seed: int) -> FitResult:
    """Fit ``model`` (an extension of the current model), started at the current optimum as
    well as from the model's own data-driven starts. No second search (``retry=False``):
    an absent effect leaves its coefficient at a bound or ill-determined, which would
    send nearly every candidate to fit()'s second search (2.3 times the time of a
    diagnosis) while the warm starts already hold the current optimum (the rates of
    experiments/diagnose_rates.py were measured so); the current model's own fit is
    searched again when it looks local."""
    z_cur, _ = current.model_object.from_natural(current.values[None])
    gamma, theta = np.radians(meas.gamma_deg), np.radians(meas.theta_deg)
    warm = warm_starts(model, z_cur[0], gamma, theta, meas.power)
    return fit(meas, model, seed=seed, extra_starts=warm, retry=False)


def _share(before: Assessment, after: Assessment) -> float:
    """Share of the excess residual (chi2 above its noise expectation) an extension removes."""
    b, a = before.lack_of_fit, after.lack_of_fit
    excess = max(b.chi2 - b.dof, np.sqrt(2.0 * b.dof))
    return float(np.clip((b.chi2 - a.chi2) / excess, 0.0, 1.0))


def diagnose(measurements, model="two-lobe", *, extensions: Sequence[str] | None = None,
             max_effects: int = 3, seed: int = 0, min_delta_bic: float = 10.0,
             min_share: float = 0.5, min_margin: float = 6.0, alpha: float = 0.01,
             progress: Callable[[str], None] | None = None) -> Diagnosis:
    """Find what a reflection model misses in a measurement table.

    Parameters
    ----------
    measurements : Measurements, DataFrame or path
        Angles in degrees; an optional ``sigma`` column (power units) is the noise.
    model : str or ReflectionModel
        Base model: a registry name, optionally with extensions (``"two-lobe+background"``).
    extensions : sequence of str, optional
        Candidate extension names (default: every registered one).
    max_effects : int
        At most this many effects are added.
    seed : int
        Seeds the fits' random starts and the noise simulation.
    min_delta_bic : float
        An effect needs a BIC lower by more than this (strong evidence).
    min_share : float
        ... and must explain at least this share (0..1) of the excess residual ...
    min_margin : float
        ... and beat the runner-up's BIC by at least this much (6: "strong", Kass and
        Raftery 1995); otherwise the data cannot tell the two effects apart.
    alpha : float
        Significance level of the lack-of-fit and (Bonferroni-corrected) structure tests.
    progress : callable(str), optional
        Called with a short message before every fit.

    Returns
    -------
    Diagnosis
    """
    t0 = time.perf_counter()
    meas = as_measurements(measurements)
    base_model = get_model(model)
    names = list(EXTENSIONS) if extensions is None else list(extensions)
    for name in names:
        get_extension(name)  # validates the names before any work
    say = progress or (lambda message: None)
    say(f"fitting {base_model.name}")
    base_fit = fit(meas, base_model, seed=seed)
    noise = estimate_noise(meas, residuals=base_fit.residuals, seed=seed)
    current = assess(base_fit, noise)
    steps, rounds, effects = [current], [], []
    for _ in range(max(int(max_effects), 0)):
        used = set(applied_extensions(current.fit.model_object))
        row = []
        for name in names:
            if name in used:
                continue
            say(f"trying {name} on {current.model_name}")
            extended = get_extension(name)(current.fit.model_object)
            try:
                with warnings.catch_warnings():  # candidates are trials: warn for the result
                    warnings.simplefilter("ignore", FitWarning)
                    result = _fit_candidate(meas, extended, current.fit, seed)
            except (FitError, IrreflectError) as exc:  # a candidate that cannot be fitted
                row.append(Candidate(name, None, float("inf"), 0.0, 0.0, False,
                                     f"fit failed: {exc}"))
                continue
            a = assess(result, noise)
            rss_b = float(np.sum(current.fit.residuals ** 2))
            rss_a = float(np.sum(result.residuals ** 2))
            row.append(Candidate(name, a, a.bic - current.bic, _share(current, a),
                                 float(1.0 - rss_a / rss_b) if rss_b > 0 else 0.0, False, ""))
        if not row:
            break
        row.sort(key=lambda c: c.delta_bic)
        best = row[0]
        checks = []
        if not best.delta_bic < -min_delta_bic:
            checks.append(f"delta BIC {best.delta_bic:.1f} not below -{min_delta_bic:g}")
        if best.assessment is None or \
                not best.assessment.lack_of_fit.ratio < current.lack_of_fit.ratio:
            checks.append("lack of fit not reduced")
        if best.share_explained < min_share:
            checks.append(f"explains {100 * best.share_explained:.0f}% of the excess residual, "
                          f"less than {100 * min_share:.0f}%")
        if len(row) > 1 and not row[1].delta_bic - best.delta_bic >= min_margin:
            checks.append(f"ambiguous: {row[1].name} does about as well (BIC "
                          f"{row[1].delta_bic - best.delta_bic:.1f} higher, not {min_margin:g})")
        accept = not checks
        ranked = [dataclasses.replace(c, accepted=(accept and i == 0),
                                      reason=_reason(c, i, accept, checks))
                  for i, c in enumerate(row)]
        rounds.append(tuple(ranked))
        if not accept:
            break
        new = best.assessment
        effects.append(_effect(best, new.fit))
        steps.append(new)
        if noise.source == "estimated":
            # the better model leaves a smoother residual: less of the misfit leaks into
            # the difference-based estimate; every step is then judged with the new noise
            refreshed = estimate_noise(meas, residuals=new.fit.residuals, seed=seed)
            if refreshed.value < noise.value:
                noise = dataclasses.replace(
                    refreshed, method=refreshed.method.replace(
                        "base-model residuals", f"residuals of {new.model_name}"))
                steps = [assess(a.fit, noise) for a in steps]
        current = steps[-1]
    verdict, summary, where = _verdict(steps, effects, alpha)
    if len(steps) > 1:  # the extended model is a result too: say what is doubtful about it
        for text in steps[-1].fit.warnings:
            warnings.warn(FitWarning(f"{meas.name}, {steps[-1].fit.model}: {text}"),
                          stacklevel=2)
    return Diagnosis(
        name=meas.name, n_points=meas.n_points, base_model=base_model.name, noise=noise,
        steps=tuple(steps), candidates=tuple(rounds), effects=tuple(effects), verdict=verdict,
        summary=summary, where=tuple(where), alpha=alpha,
        elapsed_s=time.perf_counter() - t0,
        settings={"max_effects": max_effects, "min_delta_bic": min_delta_bic,
                  "min_share": min_share, "min_margin": min_margin, "alpha": alpha, "seed": seed, "extensions": names},
    )


def _reason(c: Candidate, rank: int, accept: bool, checks: list[str]) -> str:
    if c.assessment is None:
        return c.reason
    if rank == 0:
        return "accepted" if accept else "rejected: " + "; ".join(checks)
    return "not the best"


def _effect(c: Candidate, result: FitResult) -> Effect:
    model = result.model_object
    wrapped = model.wrapped
    k0 = len(wrapped.params) if wrapped is not None else 0
    new = model.params[k0:]
    return Effect(
        name=c.name,
        params={p.name: result.params[p.name] for p in new},
        stderr={p.name: result.stderrs[p.name] for p in new},
        units={p.name: ("" if p.unit == "1" else p.unit) for p in new},
        delta_bic=c.delta_bic, share_explained=c.share_explained, rss_drop=c.rss_drop,
    )


def _verdict(steps, effects, alpha):
    final = steps[-1]
    lof = final.lack_of_fit
    stat = f"chi2/dof = {lof.ratio:.3g}, {_p_text(lof.p_value)}"
    if final.consistent(alpha):
        if not effects:
            return NO_MISSING_EFFECT, (
                f"no missing effect: the {final.model_name} residual is consistent with the "
                f"noise ({stat}; no structure at level {alpha:g})"), []
        named = ", ".join(f"{e.name} ({_param_text(e)})" for e in effects)
        return EFFECTS_FOUND, (
            f"effects found: {named}; with them the residual is consistent with the noise "
            f"({stat}; no structure at level {alpha:g})"), []
    where = [f"{s.name} ({_p_text(s.p_value)}): {s.where}" for s in final.flagged(alpha)]
    worst = sorted(final.gamma_chi2.items(), key=lambda kv: -kv[1])[:2]
    where.append("largest chi2/points at " + ", ".join(f"gamma {_deg(g)} deg ({v:.3g})"
                                                       for g, v in worst))
    added = f" after adding {', '.join(e.name for e in effects)}" if effects else ""
    return UNEXPLAINED, (
        f"unexplained structure remains{added}: the residual of {final.model_name} is not "
        f"consistent with the noise ({stat}) and no candidate extension explains it"), where


def _param_text(e: Effect) -> str:
    return ", ".join(f"{k} = {v:.3g} +- {e.stderr[k]:.2g}{(' ' + e.units[k]) if e.units[k] else ''}"
                     for k, v in e.params.items())


def diagnose_many(datasets: dict[str, Measurements], **kwargs) -> dict[str, Diagnosis]:
    """:func:`diagnose` on every table of a dict (name -> Measurements)."""
    return {name: diagnose(meas, **kwargs) for name, meas in datasets.items()}
