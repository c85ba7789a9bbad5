"""Model comparison on the same data (the paper's section 5.3, Tables 6-7, Fig. 25).

The paper compares its two-lobe model with Phong on its own data (Table 6) but could only
quote other models' errors on other materials (Table 7, from Karner et al. 1994). Here
every model is fitted to the same table by the same global fitter and scored with the
same measures:

* the relative polar-area error of section 5.3 per angle of incidence
  (:func:`irreflect.metrics.polar_area_errors`), its mean and its worst value;
* R^2 and RMSE on all points;
* the number of free parameters ``k`` and AIC / BIC, so that a richer model does not win
  by its parameter count alone.

``MODEL@G`` fits a model to the points of ONE angle of incidence (``|gamma| = G`` deg) and
applies it to all, as the paper did with Phong at 10 deg (``phong@10``). ``phong`` alone
is Phong fitted to all angles at once, which is fairer to it.

API: :func:`compare_models` -> :class:`Comparison` (``.table()``, ``.to_dict()``,
``.format()``). Figures and ``--out`` files: :mod:`irreflect.plots.compare`; report
section: :mod:`irreflect.report.compare`.
"""

from __future__ import annotations

import re
import sys
import time
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from tqdm.auto import tqdm

from . import metrics
from ._progress import on_terminal
from .data import as_measurements
from .errors import DataError, FitError, IrreflectError
from .fitting import GAMMA_TOL_DEG as _GAMMA_TOL_DEG
from .fitting import fit, fit_averaged, points_at_incidence
from .models import get_model, parse_spec
from .models.aperture import check_resolution
from .validation import check_seed, split_names

#: Models compared by default; ``phong@{G}`` takes the ``phong_at_deg`` of the call.
DEFAULT_MODELS = ("two-lobe", "phong@{G}", "phong", "blinn-phong", "lafortune", "ward",
                  "torrance-sparrow", "oren-nayar")
#: The paper's Table 6 columns (bundled dataset names).
TABLE6_MATERIALS = ("terrazzo", "plasterboard", "foam_board")


# ----------------------------------------------------------------------------- results
@dataclass(frozen=True)
class ModelScore:
    """One model's fit and scores on a table.

    name : label in the comparison (``phong@10``, ``two-lobe``)
    model : registry name of the fitted model
    fitted_on : which points the fit saw (``"all points"`` or ``"|gamma| = 10 deg (22 points)"``)
    per_gamma_error_pct : ``{|gamma| (deg): relative polar-area error (%)}``, section 5.3
    mean_error_pct, max_error_pct : mean and worst of those (%)
    r2, rmse : on ALL points (rmse in power units)
    n_params : free parameters k
    rss : residual sum of squares on all points, weighted by 1/sigma^2 when the table has
        sigma (the same weights as the fit)
    aic, bic : from ``rss``, ``n`` and ``k`` (:func:`irreflect.metrics.aic` / ``bic``)
    """

    name: str
    model: str
    fitted_on: str
    params: dict
    per_gamma_error_pct: dict
    mean_error_pct: float
    max_error_pct: float
    r2: float
    rmse: float
    n_params: int
    rss: float
    aic: float
    bic: float
    fit: object = field(repr=False, compare=False, default=None)

    def predict(self, gamma_deg, theta_deg):
        """Model power at the given angles (degrees)."""
        return self.fit.predict(gamma_deg, theta_deg)

    def to_dict(self) -> dict:
        return {
            "model": self.model,
            "fitted_on": self.fitted_on,
            "params": self.params,
            "per_gamma_error_pct": {f"{g:g}": e for g, e in self.per_gamma_error_pct.items()},
            "mean_error_pct": self.mean_error_pct,
            "max_error_pct": self.max_error_pct,
            "r2": self.r2,
            "rmse": self.rmse,
            "n_params": self.n_params,
            "aic": self.aic,
            "bic": self.bic,
        }


@dataclass(frozen=True)
class Comparison:
    """Scores of several models on one measurement table (ordered as requested)."""

    data_name: str
    measurements: object = field(repr=False)
    scores: dict = field(default_factory=dict)
    #: label -> reason, for models left out with ``skip_failures=True``
    skipped: dict = field(default_factory=dict)
    #: what was adapted to the table (e.g. phong@ fitted at another angle of incidence)
    notes: tuple = ()
    #: what the numbers do not say on their own (a sigma column that decided the fits)
    warnings: tuple = ()

    @property
    def gammas(self) -> list[float]:
        """Angles of incidence (|gamma|, deg) that have a polar error."""
        first = next(iter(self.scores.values()))
        return list(first.per_gamma_error_pct)

    @property
    def best_by_bic(self) -> str:
        return min(self.scores, key=lambda k: self.scores[k].bic)

    def table(self) -> pd.DataFrame:
        """One row per model: per-gamma error (%), mean, worst, R^2, RMSE, k, AIC, BIC, dBIC."""
        best = min(s.bic for s in self.scores.values())
        rows = []
        for name, s in self.scores.items():
            row = {"model": name}
            row |= {f"{g:g}": s.per_gamma_error_pct.get(g, np.nan) for g in self.gammas}
            row |= {"mean": s.mean_error_pct, "worst": s.max_error_pct, "r2": s.r2,
                    "rmse": s.rmse, "k": s.n_params, "aic": s.aic, "bic": s.bic,
                    "delta_bic": s.bic - best}
            rows.append(row)
        return pd.DataFrame(rows).set_index("model")

    def to_dict(self) -> dict:
        meas = self.measurements
        return {
            "data": self.data_name,
            "n_points": int(meas.n_points),
            "error_measure": "relative polar-area error per |gamma| (section 5.3), percent",
            "models": {name: s.to_dict() for name, s in self.scores.items()},
            "best_by_bic": self.best_by_bic,
            "skipped": dict(self.skipped),
            "notes": list(self.notes),
            "warnings": list(self.warnings),
        }

    def format(self) -> str:
        """Readable table: rows models, columns per-gamma error %, mean, worst, R^2, RMSE, k, BIC."""
        meas = self.measurements
        gammas = self.gammas
        head = (f"{self.data_name}: {meas.n_points} points; relative polar-area error per "
                "angle of incidence |gamma| (%, section 5.3)")
        width = max(10, *(len(n) for n in self.scores)) + 1
        cols = [f"{g:>6g}" for g in gammas]
        lines = [head,
                 f"{'model':<{width}}" + " ".join(cols)
                 + f" {'mean':>6} {'worst':>6} {'R^2':>8} {'RMSE':>9} {'k':>2} {'BIC':>9}"]
        for name, s in self.scores.items():
            errs = " ".join(_fmt_pct(s.per_gamma_error_pct.get(g, np.nan)) for g in gammas)
            lines.append(f"{name:<{width}}{errs} {_fmt_pct(s.mean_error_pct)} "
                         f"{_fmt_pct(s.max_error_pct)} {s.r2:>8.4f} {s.rmse:>9.3g} "
                         f"{s.n_params:>2d} {s.bic:>9.1f}")
        notes = [f"note: {n}" for n in self.notes] + [f"best by BIC: {self.best_by_bic}"]
        notes += [f"skipped {n}: {why}" for n, why in self.skipped.items()]
        partial = [f"{n} fitted on {s.fitted_on}" for n, s in self.scores.items()
                   if s.fitted_on != "all points"]
        if partial:
            notes.append("; ".join(partial) + ", scored on all points")
        return "\n".join(lines + notes)


def _fmt_pct(value) -> str:
    if np.isnan(value):
        return f"{'-':>6}"
    return f"{metrics.format_polar_error(value, '.1f' if value >= 100 else '.2f'):>6}"


# ----------------------------------------------------------------------------- logic
def parse_model_list(text=None, phong_at_deg: float = 10.0) -> list[str]:
    """Comma-separated model specifications -> list, validated.

    ``None`` or ``""`` gives :data:`DEFAULT_MODELS`. Each label is a model specification
    ``name[:N][+extension...][@G]`` (the one grammar, :func:`irreflect.models.parse_spec`);
    ``MODEL@`` without a number takes ``phong_at_deg`` (which :func:`compare_models` moves
    to the nearest measured incidence when not given).
    """
    g_text = f"{float(phong_at_deg):g}"
    if text is None or not str(text).strip():
        labels = [m.replace("{G}", g_text) for m in DEFAULT_MODELS]
    else:
        labels = split_names(text, "--models", "two-lobe,phong")
    out = []
    for label in labels:
        if label.endswith("@"):
            label += g_text
        spec = parse_spec(label)
        get_model(spec.model_text)  # validates 'n-lobe:4'-style sizes
        label = str(spec)
        if label in out:
            raise IrreflectError(f"model '{label}' is listed twice in models (--models): list it "
                                 "once")
        out.append(label)
    if not out:
        raise IrreflectError("--models is empty: expected a comma-separated list, e.g. two-lobe,phong")
    return out


def fit_at_incidence(meas, model, gamma_abs_deg: float, *, seed: int = 0,
                     resolution: float = 0.0):
    """Fit ``model`` to the points of one angle of incidence ``|gamma| = gamma_abs_deg``
    (``fit(meas, "MODEL@G")``).

    This is how the paper fitted Phong (at 10 deg, section 5.3): a model whose parameters do
    not depend on gamma is identified from one incidence and then applied to all. (A model
    whose parameters vary with gamma, such as two-lobe, is left undetermined in those
    directions by a single incidence.)

    With ``resolution`` (deg), the points of that incidence are fitted as the model
    averaged over a receiver that wide (:func:`irreflect.fitting.fit_averaged`).

    Returns ``(FitResult, number of points fitted)``. Raises IrreflectError if the table
    has no such angle of incidence.
    """
    text = parse_spec(model).model_text
    if resolution:
        sub = points_at_incidence(meas, gamma_abs_deg, f"{text}@{abs(gamma_abs_deg):g}")
        return fit_averaged(sub, text, resolution, seed=seed), sub.n_points
    result = fit(meas, f"{text}@{abs(gamma_abs_deg):g}", seed=seed)
    return result, int(result.n_points)


def score(meas, fit_result, name: str, fitted_on: str = "all points") -> ModelScore:
    """Score a fit on ALL points of ``meas`` (polar-area errors, R^2, RMSE, AIC, BIC)."""
    predict = fit_result.predict
    errors = metrics.polar_area_errors(meas.gamma_deg, meas.theta_deg, meas.power, predict)
    pred = predict(meas.gamma_deg, meas.theta_deg)
    resid = meas.power - pred
    weights = 1.0 / meas.sigma**2 if meas.sigma is not None and np.all(meas.sigma > 0) else 1.0
    rss = float(np.sum(weights * resid**2))
    values = np.array([e for e in errors.values() if np.isfinite(e)])
    k = int(fit_result.n_params)
    return ModelScore(
        name=name,
        model=fit_result.model,
        fitted_on=fitted_on,
        params=fit_result.params,
        per_gamma_error_pct=errors,
        mean_error_pct=float(values.mean()) if values.size else float("nan"),
        max_error_pct=float(values.max()) if values.size else float("nan"),
        r2=float(metrics.r2(meas.power, pred)),
        rmse=float(metrics.rmse(meas.power, pred)),
        n_params=k,
        rss=rss,
        aic=metrics.aic(rss, meas.n_points, k),
        bic=metrics.bic(rss, meas.n_points, k),
        fit=fit_result,
    )


#: The paper's angle of incidence for Phong (Table 6): the default of ``phong@``.
PAPER_PHONG_DEG = 10.0
#: s: ``compare_models(progress=True)`` away from a terminal writes a line per model once
#: the fits so far took this long (a quick comparison stays silent).
PROGRESS_LINES_AFTER_S = 5.0


def default_phong_deg(meas) -> tuple[float, str]:
    """The angle of incidence (|gamma|, deg) for ``phong@`` when none is asked for: the
    paper's 10 deg when the table has it, else the nearest measured one (not 0), with a
    note saying so ("" when 10 deg was measured)."""
    have = np.unique(np.abs(meas.gamma_deg))
    if np.any(np.abs(have - PAPER_PHONG_DEG) <= _GAMMA_TOL_DEG):
        return PAPER_PHONG_DEG, ""
    g = _nearest_gamma(meas, PAPER_PHONG_DEG)
    return g, (f"{meas.name} has no measurements at |gamma| = {PAPER_PHONG_DEG:g} deg (the "
               f"paper's Phong incidence): phong@ is fitted at the nearest measured angle of "
               f"incidence, {g:g} deg (--phong-at-deg G to choose another)")


def compare_models(measurements, models=None, *, phong_at_deg: float | None = None,
                   seed: int = 0, fits: dict | None = None, progress: bool | None = False,
                   skip_failures: bool = False, resolution: float = 0.0) -> Comparison:
    """Fit every model to the same table and score it (section 5.3).

    Parameters
    ----------
    measurements : Measurements, DataFrame or path
    models : list of labels or comma-separated str, optional
        Registry names or ``MODEL@G`` (fitted at ``|gamma| = G`` deg only, scored on all
        points); default :data:`DEFAULT_MODELS` with ``phong@<phong_at_deg>``.
    phong_at_deg : float, degrees, optional
        Angle of incidence of ``phong@``. Default: 10 deg as in the paper, or, when the
        table has no 10 deg incidence, the nearest measured one (said in
        ``Comparison.notes``). Given explicitly, a missing angle is an error.
    seed : int
        Seed of every fit.
    fits : dict, optional
        Precomputed FitResults on all points by registry name (e.g. the report's two-lobe
        fits), reused instead of fitting again.
    progress : bool or None
        A tqdm progress bar on stderr when it is a terminal (None: only there; False:
        never). True also writes plain lines elsewhere (through a pipe, into a log) once
        the models fitted so far took :data:`PROGRESS_LINES_AFTER_S` seconds: which model
        is being fitted, the count and the time so far (a 200,000-point table ran for
        15 min without a word).
    skip_failures : bool
        Leave out (and list in ``Comparison.skipped``) a model the data cannot support (a
        FitError, e.g. no better than a constant, or a DataError, e.g. more parameters than
        points) instead of raising; a request that cannot be met (``MODEL@G`` at an angle
        that was not measured) still raises.
    resolution : float, degrees
        The receiver's angular resolution (the full width of receiver angle a reading
        averages over; 0: a point receiver): every model is fitted as its average over
        the receiver (:func:`irreflect.fitting.fit_averaged`; ``MODEL@G`` on the points of
        that incidence) and scored as such, as ``irreflect fit --resolution`` fits; ``fits``
        (point fits) are not reused.
    """
    seed = check_seed(seed)
    resolution = check_resolution(resolution)
    meas = as_measurements(measurements)
    listed = isinstance(models, list | tuple) and all(isinstance(m, str) for m in models)
    text = ",".join(models) if listed else models
    if models is not None and not (isinstance(text, str) and text.strip()):
        raise IrreflectError(
            f"compare_models: models must be one or more model names, a list or a "
            f"comma-separated text (e.g. 'two-lobe,phong'); found {models!r}: pass "
            "models=None for the default models")
    notes = []
    if phong_at_deg is None:
        phong_at_deg, note = default_phong_deg(meas)
        defaults = parse_model_list(None, phong_at_deg)
        if note and any("@" in m and m in defaults for m in parse_model_list(text, phong_at_deg)):
            notes.append(note)
    labels = parse_model_list(text, phong_at_deg)
    n_gammas = np.unique(np.round(np.abs(meas.gamma_deg), 6)).size
    if n_gammas == 1 and len(labels) > 1:  # ward came out best by BIC on such a table
        notes.append(f"{meas.name} has one angle of incidence ({abs(meas.gamma_deg[0]):g} "
                     "deg): the comparison judges each model's curve there only, not how it "
                     "varies with the angle of incidence (the two-lobe model's laws in gamma "
                     "are not determined); measure two more angles to compare that")
    fits = fits or {}
    if resolution:
        fits = {}
        notes.append(f"every model fitted as its average over the receiver's {resolution:g} "
                     "deg resolution (the coefficients are the material's)")
    scores, skipped, sigma_decided, failed_fits = {}, {}, {}, 0
    lines = bool(progress) and not on_terminal()  # plain lines instead of a bar
    bar = tqdm(labels, desc=f"compare {meas.name}", unit="model", leave=False,
               disable=True if lines else (not progress) if progress is not None else None)
    started, said = time.perf_counter(), False
    for i, label in enumerate(bar):
        elapsed = time.perf_counter() - started
        if lines and elapsed >= PROGRESS_LINES_AFTER_S:
            print(f"compare {meas.name}: [{i}/{len(labels)}] fitting {label} ({elapsed:.0f} s "
                  "so far)", file=sys.stderr, flush=True)
            said = True
        base, at, g = label.partition("@")
        try:
            if at:
                result, n_sub = fit_at_incidence(meas, base, float(g), seed=seed,
                                                 resolution=resolution)
                scores[label] = score(meas, result, label, f"|gamma| = {g} deg ({n_sub} points)")
            else:
                result = fits.get(label)
                if result is None or result.n_points != meas.n_points:
                    result = fit_averaged(meas, label, resolution, seed=seed)
                scores[label] = score(meas, result, label)
                sigma_decided[label] = _sigma_decided(meas, result, label, resolution, seed)
        except (IrreflectError, FitError) as exc:
            # the data cannot support this model (no usable optimum, too few points): left
            # out when asked; a request that cannot be met (an angle not measured) raises
            if not skip_failures or not isinstance(exc, FitError | DataError):
                raise
            skipped[label] = str(exc)
            failed_fits += isinstance(exc, FitError)
    if said:
        print(f"compare {meas.name}: done ({len(labels)}/{len(labels)} models, "
              f"{time.perf_counter() - started:.1f} s)", file=sys.stderr, flush=True)
    if not scores:
        raise _none_fitted(meas.name, skipped, failed_fits)
    return Comparison(data_name=meas.name, measurements=meas, scores=scores, skipped=skipped,
                      notes=tuple(notes), warnings=_sigma_warnings(sigma_decided))


def _sigma_decided(meas, result, label, resolution, seed) -> tuple | None:
    """(R^2 on the power weighted, unweighted) when the table's sigma column rather than
    the power decided ``result`` (:func:`irreflect.fitting.weights_check`), else None."""
    if meas.sigma is None:
        return None
    from .fitting import weights_check

    text, unweighted = weights_check(meas, result, label, resolution or 0.0, seed)
    return (float(result.r2), float(unweighted)) if text else None


def _sigma_warnings(decided: dict) -> tuple[str, ...]:
    """One warning naming the models whose weighted fit the sigma column decided: the
    comparison then ranks fits of the sigma, not of the power (a held-out GGX table:
    two-lobe R^2 0.271 weighted, 0.987 unweighted)."""
    hit = {k: v for k, v in decided.items() if v is not None}
    if not hit:
        return ()
    listed = "; ".join(f"{k}: R^2 {w:.4f} on the power, {u:.4f} fitted unweighted"
                       for k, (w, u) in hit.items())
    return (f"weighted by the sigma column, {len(hit)} model(s) misfit beyond the noise and "
            f"follow the points of smallest sigma ({listed}): the comparison ranks their fits "
            "of the sigma, not of the power. Compare unweighted with --ignore-sigma (in "
            "Python, dataclasses.replace(data, sigma=None)), or give a sigma that includes "
            "the model's error",)


_NO_CONSTANT = re.compile(
    r"^fit of '[^']*' to .*? cannot beat a constant \(R\^2 = ([^ ]+) <= 0\): (.*)$")


def _none_fitted(name: str, skipped: dict, failed_fits: int) -> Exception:
    """The error when no model of a comparison could be fitted: a fit failure (exit 1)
    when every model's fit failed, else a user error; the advice the models share said
    once (a velvet-like table of ``experiments/unseen_tables3.py`` repeated it 8 times
    on one 2,400-character line, exit code 2)."""
    found = {k: _NO_CONSTANT.match(v) for k, v in skipped.items()}
    if found and all(found.values()):  # the advice of the whole table's fits, once
        scores = ", ".join(f"{k} R^2 {m.group(1)}" for k, m in found.items())
        advice = [m.group(2) for k, m in found.items() if "@" not in k] or [
            m.group(2) for m in found.values()]
        text = (f"{name}: no model could be fitted: none beats a constant ({scores}): "
                + max(advice, key=advice.count))
    else:
        text = f"{name}: no model could be fitted: " + "; ".join(
            f"{k}: {v}" for k, v in skipped.items())
    return FitError(text) if failed_fits == len(skipped) else IrreflectError(text)


def at_label(comparison: Comparison) -> str | None:
    """The ``phong@G`` label of a comparison, if it was fitted."""
    return next((n for n in comparison.scores if n.startswith("phong@")), None)


def _nearest_gamma(meas, target: float) -> float:
    """The measured |gamma| nearest to ``target`` (ties: the smaller), excluding 0."""
    gammas = np.unique(np.abs(meas.gamma_deg))
    nonzero = gammas[gammas > 0] if np.any(gammas > 0) else gammas
    return float(nonzero[np.argmin(np.abs(nonzero - target))])
