"""The frontier's knee, its completion, and the noise-aware "enough points".

Three answers to "how many points must I measure?", all read off the Pareto frontier of
(N, 1 - R^2) (the paper's Fig. 18; R^2 of a fit on N points, judged on all points):

**The knee** (the paper's rule: the frontier point closest to the ideal point). The
distance is measured in a *fixed* normalisation, set by the data and the model, never by
how far the frontier found in one run happens to extend (which moved the knee between
runs and budgets)::

    x = (N - m) / (n - m)                 m = k + 1: the fewest points a fit takes (the
                                          model's k parameters and a degree of freedom,
                                          as irreflect.fit requires), n: points that may
                                          be chosen
    y = (e - e_A) / (1 - e_A)             e = 1 - R^2 of the subset's fit; e_A the same
                                          for the fit on all n points (Method A)

so x runs from the smallest possible subset (0) to all points (1), and y from "as good as
the fit on all points" (0) to "no better than the mean" (R^2 = 0, y = 1); points better
than Method A count as y = 0. The knee is the frontier point nearest to (0, 0); ties go to
fewer points. One more point is worth measuring when it lowers y by more than it raises
x, i.e. when it gains more than about R^2_A / (n - m) of R^2.

**Enough points** (noise-aware): the fewest points whose fit predicts all points as well
as the all-points fit within the measurement noise, i.e. whose RMSE on all points exceeds
the all-points fit's by at most the noise sigma (the table's ``sigma`` column, RMS over
the points, or the difference-based estimate of :func:`irreflect.diagnose.estimate_noise`
from the all-points residuals). Its range combines the noise estimate's 68 % interval
and the standard error of the RMSE difference (from the per-point squared residuals of
the two fits): the lower end uses the most lenient combination, the upper the strictest.

**Completion**: NSGA-II may leave sizes out, or keep a size whose best subset is worse
than a smaller one's. :func:`complete_front` fills every N from the smallest to
``max(knee, 12)`` by growing the best subset of N - 1 points by its best additional point
and shrinking the best of N + 1 by its least useful point (screened with the search's
fast fits, the best few checked with the full fitter), so the frontier holds every such N
and "the best 12 points" is always a frontier point.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy import special

from .. import metrics
from ..diagnose.workflow import estimate_noise
from ..errors import FitError, FitWarning, IrreflectError
from ..fitting import RETRY_GAIN, fit, fit_subsets
from ..models import get_model
from .problem import PointMasks

#: Candidates screened per added point by :func:`complete_front` (a seeded sample of the
#: allowed points when there are more): keeps the completion cheap on 1000-point scans.
FILL_CANDIDATES = 64
#: Screened candidates per size that are checked with the full fitter.
FILL_VERIFY = 2
#: At most this many further points screened where no sampled point helps (all of them
#: on tables of up to this many points).
FILL_REST = 2_000
#: Probability mass of the noise estimate's interval used for "enough points" (1 sigma).
ENOUGH_INTERVAL = 0.68


# ----------------------------------------------------------------------------- front tools
def non_dominated(n_points, scores) -> np.ndarray:
    """Indices of the non-dominated points of (N, score), by increasing N (strictly better
    score than every smaller N; the first of equal (N, score) pairs)."""
    n_points = np.asarray(n_points)
    scores = np.asarray(scores, float)
    order = np.lexsort((scores, n_points))
    keep, best = [], np.inf
    for i in order:
        if np.isfinite(scores[i]) and scores[i] < best:
            keep.append(i)
            best = scores[i]
    return np.asarray(keep, int)


def assemble_front(verified: dict, n_min: int = 0, n_hi: int = -1):
    """Frontier from the checked subsets (N -> (1 - R^2, mask)): the non-dominated points,
    plus every N in ``[n_min, n_hi]`` that has a subset (after :func:`complete_front` these
    are non-dominated too, unless no subset of that size beats a smaller one). Returns
    ``(front DataFrame n_points, one_minus_r2, r2; masks N -> mask)``."""
    ns = np.array(sorted(verified), int)
    scores = np.array([verified[k][0] for k in ns], float)
    keep = set(ns[non_dominated(ns, scores)].tolist())
    keep |= {int(k) for k in ns if n_min <= k <= n_hi and np.isfinite(verified[k][0])}
    sizes = sorted(keep)
    front = pd.DataFrame({"n_points": np.array(sizes, int),
                          "one_minus_r2": [verified[k][0] for k in sizes]})
    front["r2"] = 1.0 - front["one_minus_r2"]
    return front, {int(k): verified[k][1] for k in sizes}


# ----------------------------------------------------------------------------- knee
def knee_coordinates(n_points, one_minus_r2, *, n_min: int, n_total: int,
                     reference: float) -> tuple[np.ndarray, np.ndarray]:
    """The fixed normalisation of the knee rule (see the module docstring): ``(x, y)``.

    n_min : fewest points a fit takes (the model's parameter count plus one: a degree of
        freedom, as :func:`irreflect.fit` requires)
    n_total : points that may be chosen (all candidates)
    reference : 1 - R^2 of the fit on all ``n_total`` points (Method A)
    """
    x = np.asarray(n_points, float)
    f = np.asarray(one_minus_r2, float)
    span_x = max(float(n_total) - float(n_min), 1.0)
    ref = float(reference) if np.isfinite(reference) else 0.0
    ref = min(max(ref, 0.0), 1.0 - 1e-12)
    return (x - float(n_min)) / span_x, np.maximum(f - ref, 0.0) / (1.0 - ref)


def knee_index(n_points, one_minus_r2, *, n_min: int, n_total: int, reference: float) -> int:
    """Index of the frontier point closest to the ideal point in the fixed normalisation
    of :func:`knee_coordinates` (the paper's Fig. 18); ties go to fewer points."""
    x, y = knee_coordinates(n_points, one_minus_r2, n_min=n_min, n_total=n_total,
                            reference=reference)
    if x.size == 0:
        raise IrreflectError("the frontier is empty: no subset could be fitted")
    dist = np.hypot(x, np.where(np.isfinite(y), y, np.inf))
    best = np.flatnonzero(dist <= np.min(dist) + 1e-12)
    return int(best[np.argmin(np.asarray(n_points)[best])])


def knee_point(n_points, one_minus_r2=None, *, n_min: int, n_total: int,
               reference: float) -> int:
    """Number of points of the knee (:func:`knee_index`). Accepts a front DataFrame
    (columns ``n_points, one_minus_r2``) or the two arrays."""
    if isinstance(n_points, pd.DataFrame):
        one_minus_r2 = n_points["one_minus_r2"].to_numpy()
        n_points = n_points["n_points"].to_numpy()
    i = knee_index(n_points, one_minus_r2, n_min=n_min, n_total=n_total, reference=reference)
    return int(np.asarray(n_points)[i])


# ----------------------------------------------------------------------------- completion
def complete_front(evaluator, verified: dict, *, n_min: int, n_hi: int, candidates,
                   verify_fit, seed: int = 0, max_candidates: int = FILL_CANDIDATES,
                   n_verify: int = FILL_VERIFY) -> tuple[dict, int]:
    """Fill and polish the frontier for every N in ``[n_min, n_hi]`` (in place).

    ``verified``: N -> (1 - R^2, mask) of the checked subsets (updated where a better
    subset is found). Upward, the best subset of N - 1 points grows by each allowed point
    (at most ``max_candidates``, a seeded sample); downward, the best of N + 1 drops each
    of its points; the ``n_verify`` best by the search's fast fit are fitted with
    ``verify_fit`` and kept if better. Passes: up, down, then up again where a size is no
    better than the one below. Returns ``(verified, fits)``.
    """
    allowed = np.flatnonzero(np.asarray(candidates, bool))
    n_hi = int(min(n_hi, allowed.size))
    if not verified or n_hi <= n_min:
        return verified, 0
    rng = np.random.default_rng([int(seed), 14])
    fits = 0

    def consider(size: int, masks: PointMasks, verify: int = n_verify) -> float:
        """Screen ``masks``, check the best ``verify``; keep the best if it beats the
        current subset of ``size`` points. Returns the best checked score."""
        nonlocal fits
        if not len(masks):
            return np.inf
        screened, _ = evaluator.fit_masks(masks)
        fits += len(masks)
        top = np.argsort(screened, kind="stable")[:verify]
        checked = masks.rows(top)
        scores, _ = evaluator.fit_masks(checked, verify_fit)
        fits += len(top)
        j = int(np.argmin(scores))
        if np.isfinite(scores[j]) and (size not in verified or scores[j] < verified[size][0]):
            verified[size] = (float(scores[j]), checked[j].copy())
        return float(scores[j])

    def grow(size: int) -> None:
        base_score, base = verified[size - 1]
        free = allowed[~base[allowed]]
        sample = free
        if free.size > max_candidates:
            sample = np.sort(rng.choice(free, max_candidates, replace=False))
        best = consider(size, PointMasks(base, sample))
        if verified[size][0] >= base_score and sample.size < free.size:
            # no sampled point helps: screen the others too (at most FILL_REST more, a
            # seeded sample, on large tables) and check more of them
            rest = np.setdiff1d(free, sample)
            if rest.size > FILL_REST:
                rest = np.sort(rng.choice(rest, FILL_REST, replace=False))
            consider(size, PointMasks(base, rest), verify=n_verify + 1)
        elif verified[size][0] >= base_score and best >= base_score:
            consider(size, PointMasks(base, free), verify=3 * n_verify)

    def shrink(size: int) -> None:
        base = verified[size + 1][1]
        consider(size, PointMasks(base, np.flatnonzero(base), add=False))

    start = min((k for k in verified if n_min <= k <= n_hi), default=None)
    if start is None:
        return verified, fits
    for size in range(max(start, n_min) + 1, n_hi + 1):
        if size - 1 in verified:
            grow(size)
    for size in range(n_hi - 1, n_min - 1, -1):
        if size + 1 in verified:
            shrink(size)
    for size in range(n_min + 1, n_hi + 1):  # repair: grow where a size is no better
        if size - 1 in verified and (size not in verified
                                     or verified[size][0] >= verified[size - 1][0]):
            grow(size)
    return verified, fits


# ----------------------------------------------------------------------------- enough points
@dataclass(frozen=True)
class EnoughPoints:
    """The fewest points whose fit predicts all points as well as the all-points fit
    within the measurement noise (module docstring).

    n : that number (None when no frontier point qualifies: then more points than the
        largest subset searched, up to all points, are needed)
    n_low, n_high : its range (68 % noise interval and one standard error of the RMSE
        difference; None as for ``n``)
    sigma, sigma_low, sigma_high : the noise (power units) and its interval
    noise : where sigma comes from
    rmse_all : RMSE on all points of the fit on all points
    table : per frontier point: ``n_points, rmse, excess_rmse, excess_se`` (the points
        examined, in increasing N)
    """

    n: int | None
    n_low: int | None
    n_high: int | None
    sigma: float
    sigma_low: float
    sigma_high: float
    noise: str
    rmse_all: float
    n_total: int
    table: pd.DataFrame = field(repr=False)

    def threshold_one_minus_r2(self, power) -> float:
        """1 - R^2 of a fit whose RMSE on all points is ``rmse_all + sigma`` (the
        criterion as a line on the frontier plot)."""
        y = np.asarray(power, float)
        sst_per_point = float(np.mean((y - y.mean()) ** 2))
        return (self.rmse_all + self.sigma) ** 2 / sst_per_point

    def range_text(self) -> str:
        if self.n is None:
            return f"more than any subset searched (up to all {self.n_total})"
        lo = self.n if self.n_low is None else self.n_low
        if self.n_high is None:
            return f"{self.n} (range {lo} to more than {int(self.table['n_points'].max())})"
        return f"{self.n} (range {lo}-{self.n_high})"

    def as_dict(self) -> dict:
        return {"n": self.n, "n_low": self.n_low, "n_high": self.n_high,
                "sigma": self.sigma, "sigma_low": self.sigma_low,
                "sigma_high": self.sigma_high, "noise": self.noise,
                "rmse_all_points": self.rmse_all,
                "criterion": "fewest points whose fit's RMSE on all points is within sigma "
                             "of the all-points fit's"}


def noise_level(meas, residuals, seed: int = 0, interval: float = ENOUGH_INTERVAL):
    """``(sigma, sigma_low, sigma_high, description)`` of a table: the RMS of its ``sigma``
    column (taken as known), or the difference-based estimate from the all-points fit's
    ``residuals`` with the chi-square interval of its effective degrees of freedom."""
    if meas.sigma is not None:
        s = float(np.sqrt(np.mean(np.asarray(meas.sigma, float) ** 2)))
        return s, s, s, "the table's sigma column (RMS)"

    est = estimate_noise(meas, residuals, seed=seed)
    dof = max(float(est.dof), 1.0)
    tail = (1.0 - interval) / 2.0
    low = est.value * np.sqrt(dof / special.chdtri(dof, tail))
    high = est.value * np.sqrt(dof / special.chdtri(dof, 1.0 - tail))
    return float(est.value), float(low), float(high), (
        f"estimated from the all-points fit's residuals ({dof:.0f} effective dof)")


def enough_points(meas, front: pd.DataFrame, masks: dict, reference_fit, model, verify_fit=None,
                  *, seed: int = 0, chunk: int = 8) -> EnoughPoints:
    """:class:`EnoughPoints` of a frontier (``front``: ``n_points, one_minus_r2``;
    ``masks``: N -> mask; ``reference_fit``: the FitResult on all points).

    The RMSE of each frontier point comes from its (checked) 1 - R^2; the standard error of
    its difference from the all-points fit's needs the per-point residuals, from batched
    subset fits (``chunk`` frontier points at a time, only as far as the decision needs)."""

    model_obj = get_model(model)

    y = np.asarray(meas.power, float)
    pred_a = reference_fit.predict(meas.gamma_deg, meas.theta_deg)
    res_a = y - pred_a
    mse_a = float(np.mean(res_a**2))
    rmse_a = float(np.sqrt(mse_a))
    sigma, s_lo, s_hi, noise = noise_level(meas, res_a, seed=seed)
    sst = float(np.mean((y - y.mean()) ** 2))
    rows = []
    n_est = n_lo = n_hi = None
    ordered = front.sort_values("n_points")
    sizes = ordered["n_points"].astype(int).tolist()
    errors: dict[int, float] = {}

    def standard_errors(first: int) -> None:
        """Standard errors of the RMSE difference for the next ``chunk`` frontier points."""
        batch = sizes[first:first + chunk]
        fitted = fit_subsets(meas.gamma_deg, meas.theta_deg, y,
                             np.array([masks[k] for k in batch]), model_obj, sigma=meas.sigma,
                             seed=seed)
        for k, params, failed in zip(batch, fitted.params, fitted.failed, strict=True):
            if failed:
                errors[k] = np.nan
                continue
            pred = model_obj.predict_deg(params, meas.gamma_deg, meas.theta_deg)
            d = (y - pred) ** 2 - res_a**2
            mse_s = max(mse_a + float(np.mean(d)), 1e-300)
            errors[k] = float(np.std(d, ddof=1) / np.sqrt(d.size) / (2.0 * np.sqrt(mse_s)))

    for i, row in enumerate(ordered.itertuples()):
        k = int(row.n_points)
        excess = float(np.sqrt(max(row.one_minus_r2, 0.0) * sst)) - rmse_a
        if n_est is None and excess <= sigma:
            n_est = k
        se = np.nan
        if n_hi is None:  # the standard error is needed until the strictest test passes
            if k not in errors:
                standard_errors(i)
            se = errors[k]
            if n_lo is None and np.isfinite(se) and excess - se <= s_hi:
                n_lo = k
            if np.isfinite(se) and excess + se <= s_lo:
                n_hi = k
        rows.append({"n_points": k, "rmse": rmse_a + excess, "excess_rmse": excess,
                     "excess_se": se})
        if n_hi is not None and n_est is not None:
            break
    if n_lo is None and n_est is not None:
        n_lo = n_est
    return EnoughPoints(n=n_est, n_low=n_lo, n_high=n_hi, sigma=sigma, sigma_low=s_lo,
                        sigma_high=s_hi, noise=noise, rmse_all=rmse_a,
                        n_total=int(meas.n_points), table=pd.DataFrame(rows))


# ----------------------------------------------------------------------------- all together
@dataclass
class FrontSummary:
    """What :func:`finish_front` makes of the checked subsets of a search."""

    front: pd.DataFrame
    masks: dict
    verified: dict
    knee_n: int
    reference: float  # 1 - R^2 on all points of the fit on all candidate points
    reference_fit: object
    n_min: int
    n_total: int
    completed_up_to: int
    completion_fits: int
    enough: EnoughPoints | None
    enough_note: str = ""


def finish_front(meas, evaluator, verified: dict, *, model: str, n_min: int, n_max: int,
                 candidates, seed: int, verify_fit, paper_n: int = 12,
                 with_enough: bool = True) -> FrontSummary:
    """Knee, completion and "enough points" of a search's checked subsets.

    The fit on all candidate points (Method A when every point may be chosen) fixes the
    knee's normalisation; the frontier is completed for every N up to ``max(knee,
    paper_n)`` (at most ``n_max``), and the knee taken again on the completed frontier.
    """

    cand = np.asarray(candidates, bool)
    n_total = int(cand.sum())
    with warnings.catch_warnings(record=True) as said:  # the fit that stands says them
        warnings.simplefilter("always")
        reference_fit = fit(meas if cand.all() else meas.subset(cand), model, seed=seed)
    reference = 1.0 - float(metrics.r2(meas.power, reference_fit.predict(meas.gamma_deg,
                                                                          meas.theta_deg)))
    norm = dict(n_min=n_min, n_total=n_total, reference=reference)
    front, _ = assemble_front(verified)
    n_hi = int(min(max(knee_point(front, **norm), paper_n), n_max))
    verified, fits = complete_front(evaluator, verified, n_min=n_min, n_hi=n_hi,
                                    candidates=cand, verify_fit=verify_fit, seed=seed)
    front, masks = assemble_front(verified, n_min, n_hi)
    first_fit = reference_fit
    if cand.all():
        reference_fit = global_reference(meas, reference_fit, verified, model, seed)
        reference = 1.0 - float(metrics.r2(meas.power, reference_fit.predict(
            meas.gamma_deg, meas.theta_deg)))
        norm["reference"] = reference
    if reference_fit is first_fit:
        for w in said:
            warnings.warn(w.message, stacklevel=2)
    else:  # the first fit's warnings are not the refitted one's
        for text in reference_fit.warnings:
            warnings.warn(FitWarning(f"{meas.name}, {reference_fit.model}: {text}"),
                          stacklevel=2)
    knee = knee_point(front, **norm)
    enough, note = None, ""
    if with_enough:
        try:
            enough = enough_points(meas, front, masks, reference_fit, model, verify_fit,
                                   seed=seed)
        except IrreflectError as exc:  # e.g. no sigma column and too few receiver angles
            note = f"enough points not available: {exc}"
    return FrontSummary(front=front.reset_index(drop=True), masks=masks, verified=verified,
                        knee_n=knee, reference=reference, reference_fit=reference_fit,
                        n_min=n_min, n_total=n_total, completed_up_to=n_hi,
                        completion_fits=fits, enough=enough, enough_note=note)


#: How many of the subsets that score above the all-points fit are tried as its starts.
GLOBAL_CHECK_SUBSETS = 3


def global_reference(meas, reference_fit, verified: dict, model: str, seed: int):
    """The fit on all points, checked against the search's subsets: a subset whose own fit
    scores a higher R^2 against all points than the all-points fit does (1 - R^2 in
    ``verified``, N -> (score, mask)) shows, on an unweighted table, that the all-points
    fit is not the least-squares optimum (a held-out noisy matte table, stop 43: a
    12-point subset at R^2 0.9066 where the all-points fit had 0.8359). The best few
    such subsets' fits are tried as starts of the all-points fit; a lower cost (by more
    than :data:`~irreflect.fitting.RETRY_GAIN`) replaces it, with a printed warning
    (:class:`~irreflect.errors.FitWarning`). On a weighted table a higher R^2 need not
    mean a lower chi^2, so only a lower cost counts there too."""
    r2_ref = float(metrics.r2(meas.power, reference_fit.predict(meas.gamma_deg,
                                                                meas.theta_deg)))
    # only clearly above: a subset holding every point (or a tie along a flat direction)
    # scores the same as the all-points fit up to rounding
    better = sorted((score, int(k)) for k, (score, _m) in verified.items()
                    if np.isfinite(score) and score < (1.0 - r2_ref) * (1.0 - 1e-6) - 1e-12
                    and int(k) < meas.n_points)
    model_obj = reference_fit.model_object or get_model(model)
    best, found = reference_fit, None
    for score, k in better[:GLOBAL_CHECK_SUBSETS]:
        try:
            with warnings.catch_warnings():  # the subset's and the refit's own warnings
                warnings.simplefilter("ignore", FitWarning)
                sub = fit(meas.subset(verified[k][1]), model, seed=seed)
                start = model_obj.from_natural(np.asarray(sub.values, float)[None])[0]
                again = fit(meas, model, seed=seed, extra_starts=start)
        except (IrreflectError, FitError):  # a subset no fit can describe: the next
            continue
        if again.cost < best.cost * (1.0 - RETRY_GAIN):
            best, found = again, (k, 1.0 - score)
    if found is None:
        return reference_fit
    r2_new = float(metrics.r2(meas.power, best.predict(meas.gamma_deg, meas.theta_deg)))
    warnings.warn(
        f"{meas.name}: the fit on all points (R^2 {r2_ref:.4f}) was not the least-squares "
        f"optimum: the best {found[0]}-point subset's fit scores R^2 {found[1]:.4f} against "
        f"all points; refitted from it, the fit on all points has R^2 {r2_new:.4f} (used as "
        "Method A and the knee's reference)", FitWarning, stacklevel=2)
    return best
