"""The discrepancy workflow: where model and measurements disagree, which effect is missing.

1. Fit the base model (default ``two-lobe``). Noise (:mod:`irreflect.diagnose.noise`): the
   table's ``sigma`` column, or estimated from differences along theta of the base
   model's residuals, with a part proportional to the power when the data show one (then
   the base model is fitted again, weighted by that noise). Every later fit is weighted by
   the same noise.
2. Locate the disagreement: residuals normalised by the noise over (gamma, theta); a
   lack-of-fit statistic ``chi2 / dof`` with its p-value (chi-square with a given sigma,
   F with an estimated one); structure tests: runs of residual signs along theta, and the
   mean residual per angle of incidence, per receiver angle, per distance from the mirror
   direction and per distance from the source direction.
3. Name the effect. Each catalogue effect is a law in the angle of incidence as well as in
   theta: a constant receiver offset shifts every gamma alike, an off-specular tilt grows
   toward grazing (``sin^2 gamma``), a background is flat in theta and gamma, an
   incidence-dependent reflectance scales each gamma's whole curve, retroreflection peaks
   toward the source (``theta = gamma``), a halo widens the base of the lobe. Beside
   them, on a table of at least 3 angles of incidence with 3 readings each, a gain drift
   between angles of incidence (:data:`GAIN_DRIFT`: every reading at one gamma times its
   own factor; a measurement artefact, built for the table by
   :func:`irreflect.models.extensions.gain_drift`), dropped wherever an explanation
   without it is as good (it nests every law that only scales each gamma's curve; every
   explanation is judged against the best one without it too), and named only where its
   factors depart from every smooth law of gamma (:func:`irreflect.diagnose.gain.
   smooth_gains`; else it is neither grown nor anyone's rival). Every
   explanation (a set of effects) is fitted on top of the base model, over all angles of
   incidence at once, started from the optimum of every smaller set it contains and from
   a scan of the coordinates it adds (:mod:`irreflect.diagnose.search`), and compared by
   likelihood ratio (:func:`irreflect.diagnose.noise.deviance`):

   * an explanation ``S`` is *adequate* when no single further effect ``X`` improves it
     significantly: the likelihood ratio of ``S + X`` against ``S`` is below the
     chi-square quantile at level ``alpha / m`` (``m`` effects tried, Bonferroni) or, for
     ``S`` not empty, ``X`` explains less than ``min_share`` of the excess residual ``S``
     leaves (the chi-square above what noise alone would give: a sliver of misfit an
     extra term can always mop up is not a second effect). This holds for an ``S`` whose
     residual passes the lack-of-fit and structure tests too: those omnibus tests spread
     their power over every direction a residual can take, the likelihood ratio puts it
     on the one direction ``X`` adds (a second effect of chi-square 30 hides in a
     lack of fit on 100 degrees of freedom);
   * sets are tried by size, from the empty one (the base model): the smallest adequate
     explanations win. One: its effects are named. Several of the same size: each fits as
     well as the model that holds both (neither is rejected against it): the data cannot
     tell them apart, and the diagnosis says "ambiguous between A and B" with the
     measurements that would separate them (:mod:`irreflect.diagnose.separate`). Effects
     common to all of them are named;
   * explanations that are not adequate are grown by one effect; of the grown ones, those
     rejected against the best of their size (the likelihood ratio to the best exceeds the
     quantile, a lower bound of the one to their union) are dropped;
   * what is named must explain at least ``min_share`` of the base model's excess
     residual; else nothing is named (an effect outside the catalogue).
4. Verdict: "no missing effect", "effects found" (the residual is then consistent with
   the noise), "ambiguous" (with the alternatives and the separating measurements) or
   "unexplained structure remains" (with where it lies).
"""

from __future__ import annotations

import dataclasses
import re
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import special

from .._jsonio import finite
from .._text import p_text
from ..data import Measurements, as_measurements
from ..errors import FitError, FitWarning, IrreflectError
from ..fitting import FitResult, fit
from ..fitting.results import SIGMA_NOTE_HEAD
from ..fitting.shape_hint import peak_summary
from ..metrics import format_polar_error
from ..models import ReflectionModel, get_model
from ..models.extensions import EXTENSIONS, GAIN_DRIFT, applied_extensions, get_extension
from ..validation import check_int, check_number, check_seed
from .gain import (
    GAIN_ADVICE,
    GAIN_PARSIMONY,
    GAIN_SMOOTH,
    artefact_note,
    gain_candidate,
    gain_params,
    gain_starts,
    smooth_gains,
)
from .noise import (
    NoiseEstimate,
    clipped_scale,
    deviance,
    difference_weights,
    estimate_noise,
)
from .search import ModelSets, canonical_order, set_name, starts_for
from .separate import separating_settings
from .structure import (
    LackOfFit,
    StructureTest,
    _deg,
    lack_of_fit,
    per_gamma_chi2,
    structure_tests,
)

#: A negative background (a dark level subtracted too far) is not named when its magnitude
#: passes this share of the median reading: a table whose detector offset is most of its
#: signal is a broken measurement the dark reading shows, and a shape the model lacks fits
#: the same way (an unseen sheen toward grazing reception, stop 52: b = -0.000117 against a
#: median reading of 0.000134 was named "background", and the residual stayed structured)
NEGATIVE_BACKGROUND_SHARE = 0.25


def _offset_text(b: float, median: float, head: str = "not named: ") -> str:
    return (f"{head}a negative offset b = {b:.3g}, {-b / median:.0%} of the median reading, "
            "would be a dark level subtracted that far beyond the true one, and a shape the "
            "model lacks fits the same way (check the dark reading)")

#: verdict codes (the ``verdict`` key of the JSON output)
NO_MISSING_EFFECT = "no missing effect"
EFFECTS_FOUND = "effects found"
AMBIGUOUS = "ambiguous"
UNEXPLAINED = "unexplained structure remains"
#: at most this many explanations of one size are grown further (the rest are ambiguous
#: with them anyway, and every one costs a fit per effect)
MAX_CONTENDERS = 3
#: at most this many times the noise is estimated again from a chosen explanation's
#: residual and the explanations judged again
MAX_NOISE_PASSES = 2
#: the fewest effective degrees of freedom of an estimated noise the diagnosis judges by:
#: a campaign's 15-20 scattered readings give 2-3 (a few runs of three receiver angles
#: 10-60 deg apart, whose differences take the model's misfit for noise: "no missing
#: effect" on a retroreflective table, or a sigma of 1.6e14 on one that lacked an
#: incidence law), every dense real table 44 or more
MIN_NOISE_DOF = 10.0

__all__ = [
    "AMBIGUOUS", "EFFECTS_FOUND", "NO_MISSING_EFFECT", "UNEXPLAINED", "Assessment",
    "Candidate", "Diagnosis", "Effect", "LackOfFit", "NoiseEstimate", "StructureTest",
    "assess", "clipped_scale", "diagnose", "diagnose_many", "difference_weights",
    "estimate_noise", "lack_of_fit", "per_gamma_chi2", "structure_tests",
]


# ----------------------------------------------------------------------------- steps
@dataclass(frozen=True)
class Assessment:
    """A fitted model judged against the noise: normalised residuals, lack of fit,
    structure, ``deviance`` (-2 log L, :func:`irreflect.diagnose.noise.deviance`) and
    ``bic = deviance + k ln n``; ``effects``: the extensions it adds to the base model."""

    fit: FitResult
    residuals_z: np.ndarray
    lack_of_fit: LackOfFit
    structure: tuple[StructureTest, ...]
    bic: float
    polar_errors: dict
    gamma_chi2: dict
    deviance: float = float("nan")
    effects: tuple[str, ...] = ()

    @property
    def model_name(self) -> str:
        return self.fit.model

    def level(self, alpha: float) -> float:
        """The level of each of the lack-of-fit and structure tests: ``alpha`` shared
        among them (Bonferroni), so that noise alone fails the family at most ``alpha``."""
        return alpha / (1 + len(self.structure))

    def flagged(self, alpha: float) -> list[StructureTest]:
        """Structure tests significant at :meth:`level`."""
        return [s for s in self.structure if s.p_value < self.level(alpha)]

    def consistent(self, alpha: float) -> bool:
        """The residual looks like noise: neither lack of fit nor structure (each test at
        :meth:`level`: the family at ``alpha``)."""
        return self.lack_of_fit.p_value >= self.level(alpha) and not self.flagged(alpha)


@dataclass(frozen=True)
class Candidate:
    """One explanation tried: the set ``name`` (effects joined by ``+``), grown from
    ``parent`` by the effect ``added``; the likelihood ratio ``lr`` against the parent on
    ``df`` degrees of freedom, its p-value and the level it was judged at, ``delta_bic``
    against the parent, the share of the parent's excess residual it explains."""

    name: str
    assessment: Assessment | None
    delta_bic: float
    share_explained: float
    rss_drop: float
    accepted: bool
    reason: str
    added: str = ""
    parent: str = ""
    lr: float = float("nan")
    df: int = 0
    p_value: float = float("nan")
    level: float = float("nan")


@dataclass(frozen=True)
class Effect:
    """A named effect: its parameters (in the final model) with standard errors, and the
    evidence for it (against the explanation without it)."""

    name: str
    params: dict
    stderr: dict
    units: dict
    delta_bic: float
    share_explained: float
    rss_drop: float
    lr: float = float("nan")
    p_value: float = float("nan")
    #: for an artefact of the measurement rather than a property of the material (the
    #: gain drift): what to do about it; empty for a physical effect
    advice: str = ""
    #: the parameters the final fit left at a bound of their range (no standard error
    #: holds there; the effect's form is then not what the data follow), each with its
    #: bound (``{"n_r": "lower bound 1"}``)
    bounds: dict = field(default_factory=dict)

    @property
    def at_bound(self) -> tuple[str, ...]:
        """The effect's parameters at a bound of their range."""
        return tuple(self.bounds)

    @property
    def artefact(self) -> bool:
        """Whether the effect is an artefact of the measurement (see ``advice``)."""
        return bool(self.advice)


@dataclass(frozen=True)
class Diagnosis:
    """The outcome of :func:`diagnose`.

    ``effects`` are named; ``alternatives`` (when the verdict is "ambiguous") are the
    explanations the data cannot tell apart, each the effects it adds to ``effects``, with
    their fits in ``alternative_fits`` and the settings that would separate them in
    ``separating``. ``steps`` lead from the base model to the final one (the best of the
    alternatives when ambiguous); ``candidates`` holds every explanation tried, by size."""

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
    alternatives: tuple[tuple[str, ...], ...] = ()
    alternative_fits: dict = field(default_factory=dict)
    separating: tuple[dict, ...] = ()
    #: the base model's unweighted fit (``irreflect fit`` on a table without sigma):
    #: ``{"r2", "rmse"}``
    unweighted_base: dict = field(default_factory=dict)

    @property
    def reweighted(self) -> bool:
        """Whether the fits are weighted by a noise the diagnosis estimated and that varies
        with the power: their R^2 and RMSE are then not those of an unweighted fit."""
        return self.noise.source == "estimated" and self.noise.relative > 0

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
    def ambiguous(self) -> bool:
        return bool(self.alternatives)

    @property
    def final_model(self) -> ReflectionModel:
        return self.after.fit.model_object

    def separating_table(self):
        """The separating settings as a measurement plan: ``gamma_deg, theta_deg,
        readings, why, separation_sigma`` (empty when nothing is ambiguous)."""
        import pandas as pd

        cols = ["gamma_deg", "theta_deg", "readings", "why", "separation_sigma"]
        return pd.DataFrame([{k: r[k] for k in cols} for r in self.separating], columns=cols)

    def to_dict(self) -> dict:
        """The JSON object of ``irreflect diagnose --json``."""

        def metrics(a: Assessment) -> dict:
            return {"model": a.model_name, "rmse": a.fit.rmse, "r2": a.fit.r2,
                    "chi2_dof": a.lack_of_fit.ratio, "lack_of_fit_p": a.lack_of_fit.p_value,
                    "bic": a.bic, "deviance": a.deviance,
                    "polar_error_pct": {f"{k:g}": v for k, v in a.polar_errors.items()}}

        return finite({
            "dataset": self.name,
            "n_points": self.n_points,
            "model": self.base_model,
            "effects": [{"name": e.name, "params": e.params, "stderr": e.stderr,
                         "delta_bic": e.delta_bic, "share_explained": e.share_explained,
                         "lr": e.lr, "p_value": e.p_value,
                         "measurement_artefact": e.artefact, "advice": e.advice,
                         "at_bound": list(e.at_bound)}
                        for e in self.effects],
            "alternatives": [list(a) for a in self.alternatives],
            "alternative_fits": {k: metrics(a) | {"params": a.fit.params}
                                 for k, a in self.alternative_fits.items()},
            "separating_measurements": [dict(r) for r in self.separating],
            "before": metrics(self.before),
            "after": metrics(self.after),
            "steps": [metrics(a) | {"structure": {s.name: {"p": s.p_value, "where": s.where}
                                                  for s in a.structure}}
                      for a in self.steps],
            "candidates": [[{"name": c.name, "added": c.added, "parent": c.parent,
                             "delta_bic": c.delta_bic, "lr": c.lr, "df": c.df,
                             "p_value": c.p_value, "share_explained": c.share_explained,
                             "accepted": c.accepted, "reason": c.reason} for c in row]
                           for row in self.candidates],
            "noise_sigma": self.noise.value,
            "noise_source": self.noise.source,
            "noise_method": self.noise.method,
            "noise_additive": self.noise.additive,
            "noise_relative": self.noise.relative,
            "fits_weighted_by_estimated_noise": self.reweighted,
            "unweighted_base": dict(self.unweighted_base) if self.reweighted else None,
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
            added = [n for n in a.effects if i and n not in self.steps[i - 1].effects]
            head = "step 0: base model" if i == 0 else f"step {i}: + {' + '.join(added)}"
            lines.append("")
            lines.append(f"{head} ({a.model_name})")
            lines.append(_assessment_line(a) + (self._weighted_note() if i == 0 else ""))
            lines.append("  structure (p-values; each test, and the lack of fit, at level "
                         f"{a.level(self.alpha):.3g}):")
            for s in a.structure:
                mark = " *" if s.p_value < a.level(self.alpha) else ""
                lines.append(f"    {s.name:<44} {p_text(s.p_value)}{mark}  [{s.where}]")
            worst = sorted(a.gamma_chi2.items(), key=lambda kv: -kv[1])[:3]
            lines.append("  chi2/points by gamma (1 = noise): "
                         + ", ".join(f"{_deg(g)} deg: {v:.3g}" for g, v in worst))
            if a.polar_errors:
                lines.append("  polar-area error (section 5.3): "
                             + ", ".join(f"{_deg(g)} deg {format_polar_error(e, '.2f')}%"
                                         for g, e in a.polar_errors.items()))
            if i > 0:
                prev = self.steps[i - 1]
                gain = {g: prev.gamma_chi2[g] - a.gamma_chi2.get(g, np.nan)
                        for g in prev.gamma_chi2}
                lines.append("  evidence by angle of incidence (chi2/points removed): "
                             + ", ".join(f"{_deg(g)} deg {v:+.3g}" for g, v in
                                         sorted(gain.items(), key=lambda kv: abs(kv[0]))))
            if i < len(self.candidates):
                lines.append(f"  explanations with {i + 1} effect(s) (likelihood ratio to "
                             "the one grown from; share of its excess residual explained):")
                for c in self.candidates[i]:
                    lr = f"LR {c.lr:9.1f} (df {c.df}, {p_text(c.p_value)})" \
                        if np.isfinite(c.lr) else f"{'':>28}"
                    lines.append(f"    {c.name:<34} {lr} {100 * c.share_explained:>5.0f}%  "
                                 f"{c.reason}")
        lines.append("")
        if self.effects:
            lines.append("named: " + "; ".join(f"{e.name} ({_param_text(e)})"
                                               for e in self.effects))
        lines.append(f"verdict: {self.verdict}")
        lines.append(self.summary)
        for w in self.where:
            lines.append(f"  - {w}")
        if self.separating:
            lines.append("measurements that would separate them (setting, readings, the "
                         "separation they add in noise units with the wrong one refitted):")
            for r in self.separating:
                lines.append(f"  - gamma {_deg(r['gamma_deg'])} deg, theta "
                             f"{_deg(r['theta_deg'])} deg x{r['readings']}: "
                             f"{r['separation_sigma']:.1f} sigma"
                             + (" (measured already)" if r["measured"] else ""))
            lines.append(f"  together: chi2 {self.separating[0]['total_chi2']:.1f} (write "
                         "them as a plan with --separate-out)")
        b, a = self.before, self.after
        weighted = ", fitted weighted by the estimated noise" if self.reweighted else ""
        lines.append(f"gap: RMSE {b.fit.rmse:.4g} -> {a.fit.rmse:.4g}, R^2 {b.fit.r2:.5f} -> "
                     f"{a.fit.r2:.5f}, chi2/dof {b.lack_of_fit.ratio:.3g} -> "
                     f"{a.lack_of_fit.ratio:.3g} ({self.elapsed_s:.1f} s{weighted})")
        return "\n".join(lines)

    def _weighted_note(self) -> str:
        """Said after the base model's R^2 when the fits are weighted by the noise found."""
        if not self.reweighted:
            return ""
        u = self.unweighted_base
        unweighted = (f"; unweighted R^2 {u['r2']:.5f}, RMSE {u['rmse']:.4g}"
                      if u else "")
        return f"\n  (fitted weighted by the estimated noise{unweighted})"


def _assessment_line(a: Assessment) -> str:
    lof = a.lack_of_fit
    return (f"  RMSE {a.fit.rmse:.4g}   R^2 {a.fit.r2:.5f}   chi2/dof {lof.ratio:.3g} "
            f"(dof {lof.dof}, {lof.test} {p_text(lof.p_value)})   -2 ln L {a.deviance:.1f}")


def assess(result: FitResult, noise: NoiseEstimate, effects: Sequence[str] = (),
           polar: bool = True) -> Assessment:
    """Judge a fit against the noise: normalised residuals, lack of fit, structure, the
    deviance and BIC (and the polar-area errors, unless ``polar`` is False)."""
    z = result.residuals / noise.sigma
    dev = deviance(result.residuals, result.fitted, noise)
    return Assessment(
        fit=result,
        residuals_z=z,
        lack_of_fit=lack_of_fit(z, result.n_params, noise),
        structure=tuple(structure_tests(result.gamma_deg, result.theta_deg, z, noise.dof)),
        bic=float(dev + result.n_params * np.log(result.n_points)),
        polar_errors=result.polar_errors() if polar else {},
        gamma_chi2=per_gamma_chi2(result.gamma_deg, z),
        deviance=dev,
        effects=tuple(effects),
    )


# ----------------------------------------------------------------------------- the search
def _share(before: Assessment, after: Assessment, alpha: float | None = None) -> float:
    """Share of the excess residual (chi2 above its noise expectation) an extension
    removes. The excess is taken as no less than one standard deviation of chi-square
    (``sqrt(2 dof)``); with ``alpha`` (a further effect on top of named ones), no less
    than the excess noise alone leaves in ``alpha`` of tables (the ``1 - alpha``
    quantile of chi-square, less the dof): a residual whose excess is within that has
    none that can be measured, and a further effect that removes less than half of that
    is a sliver an extra term mops up, not an effect (the named effects' true forms,
    which the catalogue follows only nearly, a tilt growing as ``sin^2.4 gamma`` rather
    than ``sin^2``, a reflectance ``1 + c sin^2 gamma`` rather than ``cos^w``, leave such
    slivers along the direction of another effect)."""
    b, a = before.lack_of_fit, after.lack_of_fit
    floor = np.sqrt(2.0 * b.dof) if alpha is None else \
        max(float(special.chdtri(b.dof, alpha)) - b.dof, np.sqrt(2.0 * b.dof))
    excess = max(b.chi2 - b.dof, floor)
    return float(np.clip((b.chi2 - a.chi2) / excess, 0.0, 1.0))


class _Search:
    """The fits of one diagnosis: every explanation tried, by set name, judged against the
    current noise estimate."""

    def __init__(self, meas, work, base_model, names, noise, seed, say, local=None):
        self.meas, self.work, self.names, self.noise = meas, work, names, noise
        self.seed, self.say = seed, say
        self.sets = ModelSets(base_model, local)
        self.gamma = np.radians(meas.gamma_deg)
        self.theta = np.radians(meas.theta_deg)
        self.weights = 1.0 / noise.sigma
        self.fits: dict[str, Assessment | None] = {}
        self.z: dict[str, np.ndarray] = {}
        self.failed: dict[str, str] = {}
        self.stale: set[str] = set()
        #: explanations with a gain drift dropped for one as good without it (_select)
        self.parsimony: set[str] = set()
        #: the level of the gain drift's smoothness test (:func:`smooth_gains`), and its
        #: verdict per explanation holding it: (smooth, sentence)
        self.gain_level = 0.01
        self.smooth_of: dict[str, tuple[bool, str]] = {}
        #: explanations whose background is implausibly negative (:meth:`offset_refused`):
        #: (b, the median reading)
        self.offsets: dict[str, tuple[float, float]] = {}

    def offset_refused(self, effects) -> bool:
        """Whether the fit of ``effects`` (which holds the background) puts it below zero
        by more than :data:`NEGATIVE_BACKGROUND_SHARE` of the median reading (the reason
        kept in :attr:`offsets`)."""
        a = self.get(effects)
        if a is None or "b" not in a.fit.param_names:
            return False
        b = float(a.fit.values[list(a.fit.param_names).index("b")])
        median = float(np.median(np.abs(self.meas.power)))
        if not (b < 0.0 and median > 0.0 and -b > NEGATIVE_BACKGROUND_SHARE * median):
            return False
        self.offsets[set_name(effects)] = (b, median)
        return True

    def add(self, key: str, result: FitResult, effects) -> Assessment:
        a = assess(result, self.noise, effects, polar=False)
        self.fits[key] = a
        zz, _ = result.model_object.from_natural(result.values[None])
        self.z[key] = zz[0]
        return a

    def reassess(self, noise: NoiseEstimate) -> None:
        """Judge with another noise estimate: every fit is redone, weighted by it and
        started from its previous optimum, when it is next asked for."""
        self.noise = noise
        self.work = dataclasses.replace(self.work, sigma=noise.sigma)
        self.weights = 1.0 / noise.sigma
        self.stale = set(self.fits)
        self.smooth_of = {}
        self.offsets = {}

    def smooth(self, effects) -> tuple[bool, str]:
        """Whether the gain factors of the fit of ``effects`` (which holds the gain drift)
        follow a smooth law of gamma (:func:`smooth_gains`), and the sentence that says so."""
        key = set_name(effects)
        if key not in self.smooth_of:
            a = self.get(effects)
            self.smooth_of[key] = (True, "") if a is None else smooth_gains(
                a.fit, self.sets.local[GAIN_DRIFT].levels_deg, self.gain_level)
        return self.smooth_of[key]

    def get(self, effects) -> Assessment | None:
        key = set_name(effects)
        if key in self.fits and key not in self.stale:
            return self.fits[key]
        effects = canonical_order(effects)
        model = self.sets.model(effects)
        self.say(f"trying {key or 'the base model'}")
        starts = starts_for(self.sets, effects, self.z, self.gamma, self.theta,
                            self.meas.power, self.weights)
        if GAIN_DRIFT in effects:
            curves = {k: a.fit.fitted for k, a in self.fits.items() if a is not None}
            starts = np.vstack([gain_starts(self.sets, effects, self.z, curves,
                                            self.meas.gamma_deg, self.meas.power,
                                            self.weights), starts])
        if key in self.z:  # a fit with other weights: its optimum first
            starts = np.vstack([self.z[key][None], starts])
        self.stale.discard(key)
        try:
            with warnings.catch_warnings():  # candidates are trials: warn for the result
                warnings.simplefilter("ignore", FitWarning)
                result = fit(self.work, model, seed=self.seed,
                             extra_starts=starts if starts.shape[0] else None,
                             retry=not effects)
        except (FitError, IrreflectError) as exc:
            if key in self.fits and self.fits[key] is not None:  # keep the previous fit
                self.fits[key] = assess(self.fits[key].fit, self.noise, effects, polar=False)
                return self.fits[key]
            self.fits[key] = None
            self.failed[key] = str(exc)
            return None
        return self.add(key, result, effects)

    def settle(self, effects, children) -> Assessment:
        """The fit of ``effects`` again, started from each fitted superset in ``children``
        with the extensions it adds dropped: a larger model that every added effect
        improves by the same amount has usually found a better optimum of the smaller one
        (a nested model's fit can never be better than its parent's). The better fit is
        kept; returns the assessment."""
        key = set_name(effects)
        old = self.get(effects)
        rows = [self.sets.restrict(self.z[set_name(c)], c, effects) for c in children
                if set_name(c) in self.z]
        if old is None or not rows:
            return old
        model = self.sets.model(canonical_order(effects))
        starts = np.clip(np.unique(np.vstack(rows), axis=0), model.z_lower, model.z_upper)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", FitWarning)
                result = fit(self.work, model, seed=self.seed, extra_starts=starts,
                             retry=False)
        except (FitError, IrreflectError):
            return old
        new = assess(result, self.noise, effects, polar=False)
        if new.deviance < old.deviance - 1e-6 * max(1.0, abs(old.deviance)):
            self.say(f"{key or 'the base model'}: a better optimum from its extensions")
            return self.add(key, result, effects)
        return old

    def dev(self, effects) -> float:
        return self.get(effects).deviance

    def n_params(self, effects) -> int:
        return self.sets.model(canonical_order(effects)).n_params


def _beaten(search: _Search, s, other, level: float, min_share: float,
            alpha: float = 0.01) -> bool:
    """Whether explanation ``s`` is rejected in favour of the one holding both it and
    ``other``: the likelihood ratio to ``other`` (a lower bound of the one to that union)
    exceeds the quantile at ``level`` on the union's extra degrees of freedom, and (for
    ``s`` not empty) ``other`` explains at least ``min_share`` of the excess residual
    ``s`` leaves."""
    if set(other) <= set(s):
        return False
    a, b = search.get(s), search.get(other)
    union = canonical_order(set(s) | set(other))
    df = search.n_params(union) - search.n_params(s)
    if not a.deviance - b.deviance > _quantile(level, df, search.noise):
        return False
    return not s or _share(a, b, alpha) >= min_share


def _quantile(level: float, df: int, noise: NoiseEstimate) -> float:
    """What a likelihood ratio on ``df`` degrees of freedom must exceed at ``level``: the
    chi-square quantile with a given sigma; ``df`` times the F quantile with an estimated
    one (its ``noise.dof`` degrees of freedom: the ratio is measured in units of the
    estimate)."""
    df = max(int(df), 1)
    if np.isfinite(noise.dof):
        return float(df * special.fdtri(df, noise.dof, 1.0 - level))
    return float(special.chdtri(df, level))


def _lr_p_value(lr: float, df: int, noise: NoiseEstimate) -> float:
    """p-value of a likelihood ratio (chi-square with a given sigma, F with an estimated
    one; see :func:`_quantile`)."""
    df = max(int(df), 1)
    if np.isfinite(noise.dof):
        return float(special.fdtrc(df, noise.dof, lr / df))
    return float(special.chdtrc(df, lr))


def _rivals(search: _Search, sets) -> list:
    """What explanations are judged against: the best (lowest deviance) of ``sets``, and
    the best of those without the gain drift when that is another. (The gain drift nests
    the incidence reflectance: judged against it alone, on its many degrees of freedom,
    what the best of the catalogue rejects would survive.)"""
    best = min(sets, key=search.dev)
    plain = [s for s in sets if GAIN_DRIFT not in s]
    best_plain = min(plain, key=search.dev) if plain else best
    return [best] if best_plain == best else [best, best_plain]


def _needless_gain(search: _Search, u, bests, level: float) -> bool:
    """Whether ``u`` holds the gain drift and does not reject the best explanation of
    its size without it: it is not grown further (it would be dropped for that one)."""
    plain = [b for b in bests if GAIN_DRIFT not in b]
    return GAIN_DRIFT in u and bool(plain) and not _beaten(search, plain[0], u, level, 0.0)


def _select(search: _Search, names, max_effects: int, alpha: float, min_share: float):
    """The search over explanations (see the module docstring): the rounds of candidates
    tried, by size, and the final explanations (one; several when ambiguous; the empty
    one when nothing is named), best first."""
    search.parsimony = set()
    rounds: list[list[Candidate]] = []
    contenders: list[tuple[str, ...]] = [()]
    adequate: list[tuple[str, ...]] = []
    inadequate_best = None
    level_all = alpha / max(len(names), 1)
    for size in range(max(int(max_effects), 0) + 1):
        row, grown, ok = [], [], []
        for s in contenders:
            parent = search.get(s)
            tried = [x for x in names if x not in s]
            if size >= max_effects or not tried:
                ok.append(s)
                continue
            level = alpha / len(tried)
            counted_here = False
            children = [canonical_order(s + (x,)) for x in tried]
            for u in children:
                search.get(u)
            parent = search.settle(s, [u for u in children if search.get(u) is not None])
            for x in tried:
                u = canonical_order(s + (x,))
                c = _candidate(search, s, x, parent, alpha, level)
                row.append(c)
                if c.assessment is None:
                    continue
                if c.p_value < level and (not s or c.share_explained >= min_share):
                    if GAIN_DRIFT in u and search.smooth(u)[0]:
                        # factors a smooth law of gamma would give: no drift, and no
                        # rival of the catalogue's explanations either
                        search.parsimony.add(set_name(u))
                        continue
                    if "background" in u and search.offset_refused(u):
                        continue
                    counted_here = True
                    grown.append(u)
            if not counted_here:
                ok.append(s)
        if row:
            rounds.append(row)
        grown = list(dict.fromkeys(grown))
        if grown:  # an explanation no single effect improves may still be beaten by one
            bests = _rivals(search, grown)  # grown from another
            ok = [s for s in ok if not any(_beaten(search, s, b, level_all, min_share, alpha)
                                           for b in bests)]
        if ok or not grown:
            adequate = ok
            break
        # grow: drop what the best of the next size rejects, keep a few
        needless = {u for u in grown if _needless_gain(search, u, bests, level_all)}
        search.parsimony |= {set_name(u) for u in needless}
        keep = sorted((u for u in grown if u not in needless
                       and not any(_beaten(search, u, b, level_all, 0.0) for b in bests)),
                      key=search.dev)
        contenders = keep[:MAX_CONTENDERS]
        inadequate_best = contenders[0]
    if not adequate:  # every explanation of the largest size tried can still be improved
        adequate = [inadequate_best] if inadequate_best is not None else [()]
    # among the adequate ones, those the best rejects go; what is named must explain enough
    base = search.get(())
    bests = _rivals(search, adequate)
    final = [s for s in adequate
             if not any(_beaten(search, s, b, level_all, 0.0) for b in bests)
             and (not s or _share(base, search.get(s)) >= min_share)]
    final.sort(key=search.dev)
    # a gain drift nests every law that only scales each angle of incidence's curve (the
    # incidence reflectance): beside an explanation without it that is as good (not
    # rejected against the best), it is the larger model, and goes
    plain = [s for s in final if GAIN_DRIFT not in s]
    if plain:
        search.parsimony |= {set_name(s) for s in final if GAIN_DRIFT in s}
        final = plain
    return rounds, (final or [()])


def _candidate(search: _Search, s: tuple, x: str, parent, alpha: float,
               level: float) -> Candidate:
    """The candidate line of explanation ``s`` grown by effect ``x`` (its likelihood ratio
    against ``parent``, the share of the excess residual it explains), or the failed fit's."""
    u = canonical_order(s + (x,))
    a = search.get(u)
    if a is None:
        return Candidate(set_name(u), None, float("inf"), 0.0, 0.0, False,
                         f"fit failed: {search.failed[set_name(u)]}", added=x,
                         parent=set_name(s))
    df = a.fit.n_params - parent.fit.n_params
    lr = max(parent.deviance - a.deviance, 0.0)
    p = _lr_p_value(lr, df, search.noise)
    share = _share(parent, a, alpha if s else None)
    rss_b = float(np.sum(parent.fit.residuals ** 2))
    rss_a = float(np.sum(a.fit.residuals ** 2))
    return Candidate(set_name(u), a, a.bic - parent.bic, share,
                     float(1.0 - rss_a / rss_b) if rss_b > 0 else 0.0, False, "", added=x,
                     parent=set_name(s), lr=lr, df=df, p_value=p, level=level)


def _check_settings(extensions, max_effects, seed, min_share, alpha) -> None:
    """:func:`diagnose`'s settings, each in its range (one line otherwise)."""
    if extensions is not None and (isinstance(extensions, str) or not all(
            isinstance(e, str) for e in _iterable(extensions))):
        raise IrreflectError(f"extensions must be a list of extension names (or None for "
                             f"all); found {extensions!r}")
    check_int(max_effects, "max_effects", 0)
    check_seed(seed)
    check_number(alpha, "alpha", low=0.0, high=1.0, low_open=True, high_open=True)
    check_number(min_share, "min_share", low=0.0, high=1.0)


def _iterable(obj):
    try:
        return list(obj)
    except TypeError:
        return [None]


def _base_fit(meas, base_model, seed):
    """The base model's fit; when it cannot beat a constant, an error that says what the
    diagnosis needs (held-out blind seed 30148: a background 6 times the material's
    power, which the base model, without an offset, cannot follow at all)."""
    try:
        with warnings.catch_warnings():
            # the diagnosis tests the lack of fit itself: not "irreflect diagnose names it"
            warnings.filterwarnings("ignore", message=".*" + re.escape(SIGMA_NOTE_HEAD),
                                    category=FitWarning)
            return fit(meas, base_model, seed=seed)
    except FitError as exc:
        if "cannot beat a constant" not in str(exc):
            raise
        lo, hi = float(np.min(meas.power)), float(np.max(meas.power))
        peaks = peak_summary(meas)
        cause = ("a power dominated by an offset (stray light, a background) or angles "
                 "against the convention (gamma < 0 on the source side, mirror at theta = "
                 f"-gamma); check with 'irreflect fit TABLE --model {base_model.name}"
                 "+background'")
        if peaks is not None and peaks[0] != "mirror":  # the table says more (velvet)
            cause = peaks[1]
        raise FitError(
            f"diagnosis of {meas.name}: the base model '{base_model.name}' cannot beat a "
            f"constant on this table (power {lo:.4g} to {hi:.4g}), and the diagnosis starts "
            f"from its fit: {cause}") from exc


def _base_fit_and_noise(meas, base_model, seed, alpha):
    """The base model's fit and the table's noise (estimated from its residuals when the
    table has no sigma; a proportional part found: the base fit weighted by it, and the
    noise judged again): (base fit, noise, the table with the noise as its sigma, the
    unweighted base fit's ``{"r2", "rmse"}``)."""
    base_fit = _base_fit(meas, base_model, seed)
    unweighted = {"r2": float(base_fit.r2), "rmse": float(base_fit.rmse)}
    noise = estimate_noise(meas, residuals=base_fit.residuals, fitted=base_fit.fitted,
                           seed=seed, alpha=alpha)
    if noise.source == "estimated" and not noise.dof >= MIN_NOISE_DOF:
        runs = difference_weights(meas.gamma_deg, meas.theta_deg).shape[0]
        raise IrreflectError(
            f"cannot estimate the measurement noise of {meas.name} from its own readings: "
            f"expected runs of closely spaced receiver angles at one angle of incidence "
            f"giving at least {MIN_NOISE_DOF:g} effective degrees of freedom, found {runs} "
            f"runs giving {noise.dof:.1f} (between sparse readings the model's misfit "
            "would pass for noise and hide a missing effect); add a sigma column (the "
            "instrument's 1-sigma noise of each reading) or measure a run of receiver "
            "angles a few degrees apart")
    work = meas
    if noise.source == "estimated":
        work = dataclasses.replace(meas, sigma=noise.sigma)
        if noise.relative > 0:  # weight the base fit by the noise found, then look again
            z0, _ = base_model.from_natural(base_fit.values[None])
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", FitWarning)
                    weighted = fit(work, base_model, seed=seed, extra_starts=z0)
            except FitError as exc:
                # weighted by a noise proportional to the power, the model cannot follow
                # the table at all (a sub-degree lobe that the weights make invisible):
                # the proportional part is not usable; the noise is taken as additive
                # the fit's advice (check the sigma column, or drop it) is not the user's
                # to follow here: the diagnosis made that sigma itself
                reason = re.split(r"[:;] check", str(exc))[0]
                warnings.warn(
                    f"{meas.name}: a noise proportional to the power was found, but the "
                    f"model weighted by it fails ({reason}); the diagnosis takes the noise "
                    "as constant: give a sigma column to settle it", FitWarning, stacklevel=3)
                noise = estimate_noise(meas, residuals=base_fit.residuals, seed=seed,
                                       alpha=alpha)
            else:
                base_fit = weighted
                noise = estimate_noise(meas, residuals=base_fit.residuals,
                                       fitted=base_fit.fitted, seed=seed, alpha=alpha)
            work = dataclasses.replace(meas, sigma=noise.sigma)
    return base_fit, noise, work, unweighted


def _separation(search, final, alternatives, meas, target, separate):
    """When the diagnosis is ambiguous, the alternatives' fits and the readings that
    would separate them: (fits by explanation, settings); else ({}, [])."""
    if not alternatives:
        return {}, []
    alt_fits = {set_name(s): search.get(s) for s in final}
    separating = separating_settings({k: a.fit for k, a in alt_fits.items()},
                                     search.noise, meas.gamma_deg, meas.theta_deg,
                                     target=target, max_readings=max(int(separate), 0))
    return alt_fits, separating


def _chain(search, chosen) -> list:
    """The steps from the base model to ``chosen``, each time through the best-fitting
    explanation one effect smaller that was fitted."""
    chain = [chosen]
    while chain[-1]:
        subs = [tuple(n for n in chain[-1] if n != x) for x in chain[-1]]
        subs = [s for s in subs if search.get(s) is not None]
        chain.append(min(subs, key=search.dev))
    chain.reverse()
    return chain


def _ranked(search, rounds, chain, final, min_share) -> list:
    """The candidates of every round, marked accepted (on the chain) with their reason,
    by deviance."""
    ranked = []
    for row in rounds:
        out = []
        for c in row:
            named = any(set_name(s) == c.name for s in chain)
            in_final = any(set_name(s) == c.name for s in final)
            reason = _reason(c, named, in_final, min_share)
            if c.name in search.parsimony:
                reason = (GAIN_SMOOTH if search.smooth_of.get(c.name, (False, ""))[0]
                          else GAIN_PARSIMONY)
            elif c.name in search.offsets:
                reason = _offset_text(*search.offsets[c.name])
            out.append(dataclasses.replace(c, accepted=named, reason=reason))
        ranked.append(tuple(sorted(out, key=lambda c: (c.assessment is None,
                                                       c.assessment.deviance if c.assessment
                                                       else 0.0))))
    return ranked


def _offset_note(search) -> str:
    """The sentence of the best-fitting explanation with a background that was not grown
    because it is implausibly negative (:meth:`_Search.offset_refused`; "" when none)."""
    if not search.offsets:
        return ""
    best = min(search.offsets, key=lambda k: search.fits[k].deviance)
    return "; " + _offset_text(*search.offsets[best], head=f"{best} fits the data too with "
                               ) + ": it is not named"


def _smooth_note(search) -> str:
    """The sentence of the best-fitting explanation with the gain drift that was not
    grown because its factors follow a smooth law of gamma ("" when none)."""
    dropped = [k for k, (smooth, _) in search.smooth_of.items() if smooth]
    if not dropped:
        return ""
    best = min(dropped, key=lambda k: search.fits[k].deviance)
    return search.smooth_of[best][1]


def _choose(search, meas, names, max_effects, alpha, min_share, seed):
    """The search over explanations (:func:`_select`), with the noise judged again from
    the chosen explanation's residual: (rounds, final)."""
    rounds, final = _select(search, names, max_effects, alpha, min_share)
    for _ in range(MAX_NOISE_PASSES):
        # the noise is judged again from the residual the chosen explanation leaves when
        # that shows less than the base model's (a misfit leaks into a difference
        # estimate), and the explanations with it (their fits are kept)
        if search.noise.source != "estimated" or not final[0]:
            break
        chosen = search.get(final[0]).fit
        refreshed = estimate_noise(meas, residuals=chosen.residuals, fitted=chosen.fitted,
                                   seed=seed, alpha=alpha)
        if not refreshed.value < search.noise.value:
            break
        search.reassess(dataclasses.replace(refreshed, method=refreshed.method.replace(
            "base-model residuals", f"residuals of {chosen.model}")))
        previous = final
        rounds, final = _select(search, names, max_effects, alpha, min_share)
        if final == previous:
            break
    return rounds, final


def diagnose(measurements, model="two-lobe", *, extensions: Sequence[str] | None = None,
             max_effects: int = 3, seed: int = 0, min_share: float = 0.5,
             alpha: float = 0.01, separate: int = 12,
             progress: Callable[[str], None] | None = None, **legacy) -> Diagnosis:
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
        Explanations hold at most this many effects.
    seed : int
        Seeds the fits' random starts and the noise simulation.
    min_share : float
        A further effect must explain at least this share (0..1) of the excess residual an
        explanation leaves to count against it; what is named must explain this share of
        the base model's excess residual.
    alpha : float
        Significance level of the likelihood-ratio tests (Bonferroni-corrected for the
        number of effects tried at each step), of the noise's proportional part, and of
        the lack-of-fit and (Bonferroni-corrected) structure tests.
    separate : int
        When ambiguous, propose at most this many readings that would separate the
        alternatives (fewer when fewer reach the chi-square the test needs, at 95 %
        power).
    progress : callable(str), optional
        Called with a short message before every fit.

    Returns
    -------
    Diagnosis
    """
    legacy.pop("min_delta_bic", None)  # the rules of the BIC-ranking diagnosis: ignored
    legacy.pop("min_margin", None)
    if legacy:
        raise TypeError(f"diagnose() got unexpected keyword arguments {sorted(legacy)}")
    t0 = time.perf_counter()
    _check_settings(extensions, max_effects, seed, min_share, alpha)
    separate = check_int(separate, "separate", 0)  # was read as max(separate, 0)
    meas = as_measurements(measurements)
    base_model = get_model(model)
    names = list(EXTENSIONS) if extensions is None else list(extensions)
    for name in names:
        if name != GAIN_DRIFT:
            get_extension(name)  # validates the names before any work
    used = set(applied_extensions(base_model))
    names = [n for n in names if n not in used]
    names, local = gain_candidate(names, extensions is None, used, meas)
    say = progress or (lambda message: None)
    say(f"fitting {base_model.name}")
    base_fit, noise, work, unweighted = _base_fit_and_noise(meas, base_model, seed, alpha)
    search = _Search(meas, work, base_model, names, noise, seed, say, local)
    search.gain_level = alpha / len(names)
    search.add("", base_fit, ())
    rounds, final = _choose(search, meas, names, max_effects, alpha, min_share, seed)
    # the gain drift is named only where no smooth law of gamma would do: explanations
    # whose factors follow one are not grown (_select); what the noise passes changed is
    # checked here
    smooth, smooth_note = (search.smooth(final[0]) if GAIN_DRIFT in final[0]
                           else (False, _smooth_note(search)))
    if GAIN_DRIFT in final[0]:
        if smooth:  # the search again without it, from the start (its noise passes
            # judged the noise from the gain drift's residual)
            plain = [n for n in names if n != GAIN_DRIFT]
            search = _Search(meas, work, base_model, plain, noise, seed, say)
            search.add("", base_fit, ())
            rounds, final = _choose(search, meas, plain, max_effects, alpha, min_share, seed)
    noise = search.noise
    base = search.get(())
    common = tuple(n for n in final[0] if all(n in s for s in final))
    alternatives = tuple(tuple(n for n in s if n not in common) for s in final) \
        if len(final) > 1 else ()
    chosen = final[0]
    # the steps: from the base model to the chosen explanation, each time through the
    # best-fitting explanation one effect smaller that was fitted
    chain = _chain(search, chosen)
    steps = [dataclasses.replace(search.get(s), polar_errors=search.get(s).fit.polar_errors())
             for s in chain]
    final_fit = steps[-1].fit
    # the named effects, in the order the steps add them, with the final model's values
    marks = {c.name: c for row in rounds for c in row}
    effects = []
    for prev, cur in zip(chain, chain[1:], strict=False):
        added = next(n for n in cur if n not in prev)
        if added in common:
            effects.append(_effect(added, marks.get(set_name(cur)), final_fit, search.sets))
    ranked = _ranked(search, rounds, chain, final, min_share)
    target = _separation_target(alpha, len(names), noise)
    alt_fits, separating = _separation(search, final, alternatives, meas, target, separate)
    verdict, summary, where = _verdict(steps, effects, alternatives, common, separating,
                                       alpha, base, target, meas)
    summary += _untested(rounds) + artefact_note(effects) + smooth_note + _offset_note(search)
    if len(steps) > 1:  # the extended model is a result too: say what is doubtful about it
        for text in steps[-1].fit.warnings:
            if text.startswith(SIGMA_NOTE_HEAD):  # the verdict's own test of the noise
                continue
            warnings.warn(FitWarning(f"{meas.name}, {steps[-1].fit.model}: {text}"),
                          stacklevel=2)
    return Diagnosis(
        name=meas.name, n_points=meas.n_points, base_model=base_model.name, noise=noise,
        steps=tuple(steps), candidates=tuple(ranked), effects=tuple(effects),
        verdict=verdict, summary=summary, where=tuple(where), alpha=alpha,
        elapsed_s=time.perf_counter() - t0,
        settings={"max_effects": max_effects, "min_share": min_share, "alpha": alpha,
                  "seed": seed, "extensions": names, "separation_target": target},
        alternatives=alternatives, alternative_fits=alt_fits, separating=tuple(separating),
        unweighted_base=unweighted,
    )


def _separation_target(alpha: float, m: int, noise: NoiseEstimate, power: float = 0.95):
    """The chi-square gain at which the diagnosis' likelihood-ratio test on one degree of
    freedom (level ``alpha / m``) tells two explanations apart with probability
    ``power``: the non-centrality of that test's power."""
    from scipy import optimize, stats

    level = alpha / max(m, 1)
    if np.isfinite(noise.dof):
        crit = stats.f.isf(level, 1, noise.dof)
        return float(optimize.brentq(lambda lam: stats.ncf.sf(crit, 1, noise.dof, lam)
                                     - power, 1e-6, 1e7))
    crit = stats.chi2.isf(level, 1)
    return float(optimize.brentq(lambda lam: stats.ncx2.sf(crit, 1, lam) - power, 1e-6, 1e7))


def _untested(rounds) -> str:
    """What the summary adds when no candidate extension could be tested (every fit
    failed, or none is left to add): a verdict on the residual alone."""
    tried = [c for row in rounds[:1] for c in row]
    if any(c.assessment is not None for c in tried):
        return ""
    why = (f"every one failed ({tried[0].reason})" if tried
           else "none is left to add to this model")
    return f"; but no candidate extension could be tested: {why}"


def _reason(c: Candidate, named: bool, in_final: bool, min_share: float) -> str:
    if c.assessment is None:
        return c.reason
    if named:
        return "named"
    if in_final:
        return "ambiguous: as good as the named explanation"
    if not c.p_value < c.level:
        return f"not significant at {c.level:.2g}"
    if c.share_explained < min_share:
        return (f"significant, but explains {100 * c.share_explained:.0f}% of the excess "
                f"residual, less than {100 * min_share:.0f}%")
    return "rejected: a better explanation of this size"


def _effect(name: str, c: Candidate | None, result: FitResult, sets: ModelSets) -> Effect:
    model = result.model_object
    one = sets.model([name])
    new = one.params[len(sets.base.params):]
    params = {p.name: result.params[p.name] for p in new}
    stderr = {p.name: result.stderrs[p.name] for p in new}
    units = {p.name: ("" if p.unit == "1" else p.unit) for p in new}
    bounds = {p.name: (f"lower bound {p.lower:g}" if abs(params[p.name] - p.lower)
                       <= abs(params[p.name] - p.upper) else f"upper bound {p.upper:g}")
              for p in new if p.name in result.at_bound}
    advice = ""
    if name == GAIN_DRIFT:
        params, stderr = gain_params(result, sets.local[GAIN_DRIFT].levels_deg)
        units = {k: "" for k in params}
        advice = GAIN_ADVICE
    return Effect(
        name=name,
        params=params,
        stderr=stderr,
        units=units,
        delta_bic=c.delta_bic if c else float("nan"),
        share_explained=c.share_explained if c else float("nan"),
        rss_drop=c.rss_drop if c else float("nan"),
        lr=c.lr if c else float("nan"), p_value=c.p_value if c else float("nan"),
        advice=advice, bounds=bounds,
    ) if model is not None else None


def _verdict(steps, effects, alternatives, common, separating, alpha, base, target, meas):
    final = steps[-1]
    lof = final.lack_of_fit
    stat = f"chi2/dof = {lof.ratio:.3g}, {p_text(lof.p_value)}"
    named = ", ".join(f"{e.name} ({_param_text(e)})" for e in effects)
    where = []
    if not final.consistent(alpha):
        where = [f"{s.name} ({p_text(s.p_value)}): {s.where}" for s in final.flagged(alpha)]
        worst = sorted(final.gamma_chi2.items(), key=lambda kv: -kv[1])[:2]
        where.append("largest chi2/points at " + ", ".join(f"gamma {_deg(g)} deg ({v:.3g})"
                                                           for g, v in worst))
    if alternatives:
        alts = " and ".join(" + ".join(a) for a in alternatives)
        sep = ""
        total = separating[0]["total_chi2"] if separating else 0.0
        if total < target:
            g = np.abs(meas.gamma_deg)
            sep = (f"; within the table's reach (gamma {_deg(g.min())}..{_deg(g.max())} deg, "
                   f"theta {_deg(meas.theta_deg.min())}..{_deg(meas.theta_deg.max())} deg) "
                   f"no readings separate them: {sum(r['readings'] for r in separating)} "
                   f"would add chi2 {total:.1f} of the {target:.0f} needed; measure at other "
                   "angles of incidence, or nearer the source or grazing")
        else:
            n = sum(r["readings"] for r in separating)
            where_to = "; ".join(f"gamma {_deg(r['gamma_deg'])} deg, theta "
                                 f"{_deg(r['theta_deg'])} deg"
                                 + (f" (x{r['readings']})" if r["readings"] > 1 else "")
                                 for r in separating[:3])
            more = f" and {len(separating) - 3} more settings" if len(separating) > 3 else ""
            sep = (f"; to separate them, measure {n} reading(s) at {where_to}{more} (their "
                   f"expected chi2 gain {separating[0]['total_chi2']:.0f} against the wrong "
                   "one refitted)")
        rest = ("the residual is then consistent with the noise" if final.consistent(alpha)
                else f"structure remains ({stat})")
        head = f"effects found: {named}; " if effects else ""
        return AMBIGUOUS, (
            f"{head}ambiguous between {alts}: each explains the data as well as the model "
            f"holding both (likelihood ratio not significant at {alpha:g}); {rest}{sep}"), where
    if final.consistent(alpha):
        if not effects:
            return NO_MISSING_EFFECT, (
                f"no missing effect: the {final.model_name} residual is consistent with the "
                f"noise ({stat}; no structure at level {alpha:g})"), []
        return EFFECTS_FOUND, (
            f"effects found: {named}; with them the residual is consistent with the noise "
            f"({stat}; no structure at level {alpha:g})"), []
    if effects:
        return UNEXPLAINED, (
            f"effects found: {named}; unexplained structure remains after adding them: the "
            f"residual of {final.model_name} is not consistent with the noise ({stat}) and "
            "no further catalogue effect explains it"), where
    return UNEXPLAINED, (
        f"unexplained structure remains: the residual of {final.model_name} is not "
        f"consistent with the noise ({stat}) and no candidate extension explains it"), where


def _param_text(e: Effect) -> str:
    """``delta = 1.5 +- 0.005 deg``; a parameter at a bound of its range has no standard
    error: ``n_r = 1 (at its lower bound 1: not determined)``."""
    def one(k, v):
        unit = f" {e.units[k]}" if e.units[k] else ""
        if k in e.bounds:
            return f"{k} = {v:.3g}{unit} (at its {e.bounds[k]}: not determined)"
        return f"{k} = {v:.3g} +- {e.stderr[k]:.2g}{unit}"

    return ", ".join(one(k, v) for k, v in e.params.items())


def diagnose_many(datasets: dict[str, Measurements], **kwargs) -> dict[str, Diagnosis]:
    """:func:`diagnose` on every table of a dict (name -> Measurements)."""
    return {name: diagnose(meas, **kwargs) for name, meas in datasets.items()}
