"""Run a point selection: the Pareto frontier, its knee, the best subsets, Methods A/B/12.

The search (a selector from :data:`~irreflect.selection.selectors.SELECTORS`) scores
subsets with fast fits (:data:`~irreflect.selection.problem.SEARCH_FIT`: the first two
data-driven starts). Before anything is reported, the best archived subsets of every size
on the frontier are fitted again with every data-driven start and more iterations
(:data:`~irreflect.selection.problem.VERIFY_FIT`), and the frontier is rebuilt from those
values: every reported R^2 is what a fit on the subset's points alone gives, evaluated on
all points.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import numbers
import os
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from pymoo.indicators.hv import HV

from .. import metrics
from .._atomic import claim_output
from .._progress import progress
from ..data import Measurements, as_measurements
from ..errors import IrreflectError
from ..fitting import fit
from ..models import get_model
from ..protocol.points import as_points as _as_points
from ..protocol.points import (  # noqa: F401
    check_snapped,
    paper_protocol_points,
    protocol_points_mask,
    snap_points,
)
from ..validation import (
    check_int,
    check_masks,
    check_search_budget,
    check_seed,
    check_selection_budget,
)
from .front import (  # noqa: F401  (knee_index, knee_point, non_dominated re-exported)
    FrontSummary,
    finish_front,
    knee_index,
    knee_point,
    non_dominated,
)
from .problem import SEARCH_FIT, VERIFY_FIT, FitSettings, SubsetEvaluator, check_sizes, unpack
from .selectors import SELECTORS, SearchSpec, get_selector

#: Reference point of every hypervolume: (N / n, 1 - R^2) = (1, 1).
HV_REFERENCE = (1.0, 1.0)
#: The paper's protocol size (Method B uses the GA's best subset of this size).
PAPER_N = 12
#: The search's default budget, shared by ``irreflect select`` and the full report, so that
#: both give the same knee and "enough points" for the same table and seed.
DEFAULT_POP_SIZE = 100
DEFAULT_GENERATIONS = 200


# ----------------------------------------------------------------------------- front tools
# knee_index, knee_point, non_dominated: see .front (the knee's fixed normalisation)


def hypervolume(n_points, one_minus_r2, n_total: int) -> float:
    """Hypervolume (pymoo's indicator) of a front in (N / n_total, 1 - R^2) with the fixed
    reference point :data:`HV_REFERENCE`; larger is better, at most 1."""

    f = np.column_stack([np.asarray(n_points, float) / n_total, np.asarray(one_minus_r2, float)])
    f = f[np.all(f < np.asarray(HV_REFERENCE), axis=1)]
    if len(f) == 0:
        return 0.0
    return float(HV(ref_point=np.asarray(HV_REFERENCE))(f))


# ----------------------------------------------------------------------------- result
@dataclass
class SelectionResult:
    """Outcome of :func:`run_selection`.

    front : DataFrame ``n_points, one_minus_r2, r2`` (verified, non-dominated, by increasing N)
    masks : n_points -> (n,) bool mask of that front point
    knee_n : N of the knee of the front (Fig. 18)
    evaluations : subset fits of the search (the budget); verify_fits: fits of the final check
    failed_fits : search fits that failed (scored 1 - R^2 = 1)
    seconds : wall time of the whole run (including earlier runs resumed from a checkpoint)
    hypervolume : of the front, reference point :data:`HV_REFERENCE`
    """

    front: pd.DataFrame
    masks: dict[int, np.ndarray]
    knee_n: int
    evaluations: int
    failed_fits: int
    seconds: float
    seed: int
    hypervolume: float
    selector: str
    model: str
    measurements: Measurements
    verified: dict[int, tuple[float, np.ndarray]] = field(repr=False)
    search_best: dict[int, tuple[float, np.ndarray]] = field(repr=False)
    search_seconds: float = 0.0
    fit_seconds: float = 0.0
    verify_fits: int = 0
    cache_hits: int = 0
    generations_done: int | None = None
    interrupted: bool = False
    settings: dict = field(default_factory=dict)
    front_summary: FrontSummary | None = field(default=None, repr=False)

    @property
    def enough(self):
        """The noise-aware "enough points" (:class:`.front.EnoughPoints`) or None."""
        return None if self.front_summary is None else self.front_summary.enough

    @property
    def fits_per_second(self) -> float:
        return self.evaluations / self.search_seconds if self.search_seconds > 0 else float("nan")

    def best_mask(self, n: int) -> np.ndarray | None:
        """Mask of the best subset with ``n`` points found (checked fit if available,
        else the search's best), or None when no subset of that size was tried."""
        n = int(n)
        if n in self.verified:
            return self.verified[n][1].copy()
        if n in self.search_best:
            return self.search_best[n][1].copy()
        return None

    def best_score(self, n: int) -> float:
        """1 - R^2 of :meth:`best_mask` (NaN when none)."""
        n = int(n)
        if n in self.verified:
            return self.verified[n][0]
        return self.search_best[n][0] if n in self.search_best else float("nan")

    def points(self, n: int) -> pd.DataFrame:
        """The angles (degrees) of the best ``n``-point subset."""
        mask = self.best_mask(n)
        if mask is None:
            raise IrreflectError(
                f"no {n}-point subset was evaluated: allow N = {n} (--max-points) or raise the budget"
            )
        m = self.measurements
        return pd.DataFrame({"gamma_deg": m.gamma_deg[mask], "theta_deg": m.theta_deg[mask]})

    def summary(self, methods: dict | None = None) -> dict:
        """What ``summary.json`` of ``irreflect select`` holds (JSON-ready with
        :func:`irreflect._jsonio.dumps`); ``methods`` from :func:`compare_methods` adds
        Methods A/B/12."""
        out = {
            "dataset": self.measurements.name,
            "n_measured": self.measurements.n_points,
            "selector": self.selector,
            "model": self.model,
            "seed": self.seed,
            "knee_n": self.knee_n,
            "knee_r2": float(self.front.set_index("n_points").loc[self.knee_n, "r2"]),
            "knee_rule": ("closest to the ideal point in x = (N - m) / (n - m), m = k + 1 "
                          "(k model parameters and a degree of freedom), "
                          "y = (e - e_A) / (1 - e_A), e = 1 - R^2, e_A of the fit on all "
                          "points"),
            "reference_r2_all_points": (None if self.front_summary is None
                                        else 1.0 - self.front_summary.reference),
            "enough_points": None if self.enough is None else self.enough.as_dict(),
            "front_completed_up_to": (None if self.front_summary is None
                                      else self.front_summary.completed_up_to),
            "completion_fits": (0 if self.front_summary is None
                                else self.front_summary.completion_fits),
            "evaluations": self.evaluations,
            "failed_fits": self.failed_fits,
            "verify_fits": self.verify_fits,
            "cache_hits": self.cache_hits,
            "seconds": round(self.seconds, 3),
            "fits_per_second": round(self.fits_per_second, 1),
            "hypervolume": self.hypervolume,
            "hypervolume_reference": list(HV_REFERENCE),
            "generations_done": self.generations_done,
            "interrupted": self.interrupted,
            "settings": self.settings,
        }
        if methods is not None:
            out["methods"] = {k: dict(methods[k]) for k in ("A", "B", "12")}
            out["methods_order_holds"] = methods["order_holds"]
            out["methods_note"] = methods["note"]
        else:
            out["methods"] = None
        out["optimal_points_n"] = self.optimal_n
        return out

    @property
    def optimal_n(self) -> int:
        """N of "the optimal points" a run reports: the paper's 12 when that subset was
        evaluated (the frontier is completed up to 12), else the knee."""
        return PAPER_N if self.best_mask(PAPER_N) is not None else self.knee_n


# ----------------------------------------------------------------------------- run
def _fingerprint(meas, model, selector, pop_size, seed, n_min, n_max, candidates, initial,
                 search_fit) -> str:
    h = hashlib.sha256()
    for arr in (meas.gamma_deg, meas.theta_deg, meas.power,
                np.zeros(0) if meas.sigma is None else meas.sigma, candidates,
                np.zeros(0) if initial is None else np.asarray(initial, bool)):
        h.update(np.ascontiguousarray(arr).tobytes())
    h.update(repr((model, selector, pop_size, seed, n_min, n_max, search_fit.options)).encode())
    return h.hexdigest()


class _Progress:
    """tqdm bar on stderr: generation, best 1 - R^2 at N = 12, fits per second."""

    def __init__(self, enabled: bool, evaluator: SubsetEvaluator, name: str, unit: str):
        self.ev = evaluator
        self.t0 = time.perf_counter()
        self.bar = None
        if enabled:

            self.bar = progress(total=1, desc=f"select {name}", unit=unit)

    def __call__(self, done: int, total: int) -> None:
        if self.bar is None:
            return
        self.bar.total = total
        self.bar.n = done
        rate = self.ev.evaluations / max(time.perf_counter() - self.t0, 1e-9)
        best = self.ev.best_score_at(PAPER_N)
        # no 12-point subset scored yet (a short search, or one over other sizes) is said
        # so; "nan" read as a failed fit
        shown = f"{best:.4g}" if np.isfinite(best) else "none yet"
        self.bar.set_postfix_str(f"best 1-R2@{PAPER_N}={shown} fits/s={rate:.0f}",
                                 refresh=False)
        self.bar.refresh()

    def close(self):
        if self.bar is not None:
            self.bar.close()


def _checked_run(meas, model_obj, run, selector, pop_size, generations, max_points,
                 candidates, checkpoint, more):
    """:func:`run_selection`'s arguments checked (one line naming the setting): returns
    (max_points, checkpoint_every, the candidate mask, (n_min, n_max), the first
    population's masks). ``more``: (initial, checkpoint_every, include_all_points)."""
    initial, checkpoint_every, include_all_points = more
    if isinstance(pop_size, bool) or not isinstance(pop_size, numbers.Integral) or \
            isinstance(generations, bool) or not isinstance(generations, numbers.Integral) or \
            pop_size < 2 or generations < 1:
        raise IrreflectError(
            f"pop_size must be an integer >= 2 and generations >= 1; found {pop_size!r} and "
            f"{generations!r}"
        )
    if max_points is not None:
        max_points = check_int(max_points, "max_points", 1)
    checkpoint_every = check_int(checkpoint_every, "checkpoint_every", 1)
    if checkpoint is not None and not isinstance(checkpoint, str | os.PathLike):
        raise IrreflectError(f"checkpoint must be a file path (or None); found {checkpoint!r}")
    n = meas.n_points
    check_selection_budget(n, max_points, meas.name, option="max_points")
    check_search_budget(pop_size, generations, n)
    cand = np.ones(n, bool) if candidates is None else np.asarray(candidates, bool)
    n_min, n_max = check_sizes(n, model_obj.n_params, max_points, candidates)
    if max_points is not None and max_points > n:
        # searched up to n (check_sizes has clamped it); said here, not only by the CLI
        warnings.warn(f"{meas.name}: max_points {max_points} exceeds the table's {n} "
                      f"points: subsets of up to all {n} points are searched (as with "
                      f"max_points={n})", UserWarning, stacklevel=3)
    if initial is not None:
        initial = check_masks(initial, n, "initial")
    if checkpoint is not None and not run.resumable:
        resumable = [k for k, v in SELECTORS.items() if v.resumable]
        raise IrreflectError(f"selector '{selector}' does not save checkpoints: drop "
                             f"--checkpoint or use {', '.join(resumable)}")
    if initial is not None and not run.takes_initial:
        raise IrreflectError(f"selector '{selector}' does not start from given masks "
                             "('initial'): drop them or use nsga2")
    if run.takes_initial and include_all_points and cand.sum() <= n_max:
        full = cand[None].copy()
        initial = full if initial is None else np.vstack([initial, full])
    return max_points, checkpoint_every, cand, (n_min, n_max), initial


def run_selection(measurements, model="two-lobe", selector: str = "nsga2",
                  pop_size: int = DEFAULT_POP_SIZE, generations: int = DEFAULT_GENERATIONS,
                  seed: int = 0, max_points: int | None = None,
                  candidates=None, progress: bool = False, checkpoint=None, *,
                  initial=None, checkpoint_every: int = 10,
                  search_fit: FitSettings = SEARCH_FIT, verify_fit: FitSettings = VERIFY_FIT,
                  include_all_points: bool = True, enough: bool = True) -> SelectionResult:
    """Find the Pareto frontier of (number of points N, 1 - R^2) over subsets of a dense set.

    The frontier is completed for every N from the smallest to ``max(knee, 12)``
    (:func:`.front.complete_front`) and the knee taken in a fixed normalisation
    (:func:`.front.knee_index`), so neither depends on how far the search's frontier
    happens to extend.

    Parameters
    ----------
    measurements : Measurements, DataFrame or path (angles in degrees)
    model : model name (see ``irreflect models``)
    selector : ``nsga2`` (default), ``random``, ``greedy`` or ``d-optimal`` (the D-optimal
        design needs a parameter guess: a pilot fit on all points; its designs are then
        scored like every subset, by fits on their own points only)
    pop_size, generations : NSGA-II population and generations; every selector spends
        ``pop_size * generations`` subset fits at most
    seed : seeds the search; the same seed gives the same result
    max_points : largest N considered (default: every allowed point)
    candidates : optional (n,) bool mask of the points that may be chosen (tool limits)
    progress : show a tqdm bar on stderr
    checkpoint : file; NSGA-II state is saved there every ``checkpoint_every`` generations
        and a run started with an existing checkpoint resumes from it (``generations``
        may be raised to continue a finished run)
    initial : optional (m, n) masks placed in the first population (NSGA-II)
    include_all_points : put the full candidate set in the first population (NSGA-II)
        when ``max_points`` allows it, so the frontier ends at Method A
    enough : also find the noise-aware "enough points" (:func:`.front.enough_points`)

    Returns
    -------
    SelectionResult

    Raises
    ------
    IrreflectError
        Too few points, a bad ``candidates`` mask, an unknown selector or model, a
        checkpoint of another run.
    """
    t_start = time.perf_counter()
    seed = check_seed(seed)
    meas = as_measurements(measurements)
    model_obj = get_model(model)
    run = get_selector(selector)
    max_points, checkpoint_every, cand, (n_min, n_max), initial = _checked_run(
        meas, model_obj, run, selector, pop_size, generations, max_points, candidates,
        checkpoint, (initial, checkpoint_every, include_all_points))
    n = meas.n_points
    evaluator = SubsetEvaluator(meas.gamma_deg, meas.theta_deg, meas.power, meas.sigma,
                                model_obj, settings=search_fit)
    pilot = None
    if run.needs_pilot:
        pilot = fit(meas, model_obj, seed=seed).values
    spec = SearchSpec(
        evaluator=evaluator, n_min=n_min, n_max=n_max, candidates=cand, pop_size=pop_size,
        generations=generations, seed=seed,
        checkpoint=None if checkpoint is None else Path(checkpoint),
        checkpoint_every=max(1, int(checkpoint_every)), initial=initial, pilot=pilot,
        fingerprint=_fingerprint(meas, model_obj.name, selector, pop_size, seed, n_min, n_max,
                                 cand, initial, search_fit),
    )
    bar = _Progress(progress, evaluator, meas.name, run.unit)
    spec.tick = bar
    interrupted = False
    t_search = time.perf_counter()
    # the checkpoint file is this run's until it ends: checked, locked, leftovers removed
    claim = (contextlib.nullcontext() if checkpoint is None
             else claim_output(checkpoint, "file", "--checkpoint"))
    try:
        with claim:
            run(spec)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        bar.close()
    search_seconds = time.perf_counter() - t_search
    if not evaluator.archive:
        raise IrreflectError("the search was stopped before any subset was fitted: nothing to report")
    verified, verify_fits = _verify(evaluator, verify_fit)
    done = finish_front(meas, evaluator, verified, model=model_obj.name, n_min=n_min,
                        n_max=n_max, candidates=cand, seed=seed, verify_fit=verify_fit,
                        paper_n=PAPER_N, with_enough=enough)
    front, masks, verified = done.front, done.masks, done.verified
    search_best = {k: (v[0][0], unpack(v[0][2], n)) for k, v in evaluator.archive.items()}
    seconds = time.perf_counter() - t_start + spec.info.get("seconds_before_resume", 0.0)
    return SelectionResult(
        front=front.reset_index(drop=True),
        masks=masks,
        knee_n=done.knee_n,
        evaluations=evaluator.evaluations,
        failed_fits=evaluator.failed_fits,
        seconds=seconds,
        seed=seed,
        hypervolume=hypervolume(front["n_points"], front["one_minus_r2"], n),
        selector=selector,
        model=model_obj.name,
        measurements=meas,
        verified=verified,
        search_best=search_best,
        search_seconds=search_seconds + spec.info.get("seconds_before_resume", 0.0),
        fit_seconds=evaluator.fit_seconds,
        verify_fits=verify_fits,
        cache_hits=evaluator.cache_hits,
        generations_done=spec.info.get("generations_done"),
        interrupted=interrupted,
        front_summary=done,
        settings={"pop_size": pop_size, "generations": generations, "max_points": n_max,
                  "n_candidates": int(cand.sum()),
                  "search_fit": search_fit.as_dict(), "verify_fit": verify_fit.as_dict(),
                  "resumed_from_generation": spec.info.get("resumed_from_generation")},
    )


def _verify(ev: SubsetEvaluator, settings: FitSettings):
    """Refit the archived candidates of every size on the search's frontier (and of the
    paper's N = 12) with the thorough settings; returns N -> (1 - R^2, mask) and the count."""
    ns = np.array(sorted(ev.archive))
    best = np.array([ev.archive[k][0][0] for k in ns])
    wanted = set(ns[non_dominated(ns, best)].tolist())
    if PAPER_N in ev.archive:
        wanted.add(PAPER_N)
    keys, sizes = [], []
    for k in sorted(wanted):
        for _score, _serial, key in ev.archive[k]:
            keys.append(key)
            sizes.append(k)
    masks = np.array([unpack(key, ev.n) for key in keys])
    scores, _failed = ev.fit_masks(masks, settings)
    out: dict[int, tuple[float, np.ndarray]] = {}
    for k, s, m in zip(sizes, scores, masks, strict=True):
        if k not in out or s < out[k][0]:
            out[k] = (float(s), m)
    return out, len(keys)


# ----------------------------------------------------------------------------- methods A/B/12
def _r2_all(meas: Measurements, mask: np.ndarray, model, seed: int, what: str = "") -> float:
    sub = meas.subset(mask)
    if what and not mask.all():  # a warning names the subset, not the whole table
        sub = dataclasses.replace(sub, name=f"{what} on {meas.name}")
    res = fit(sub, model, seed=seed)
    return float(metrics.r2(meas.power, res.predict(meas.gamma_deg, meas.theta_deg)))


def _check_same_points(meas: Measurements, other, what: str) -> None:
    """Refuse a search result or fit (``other``: anything with ``gamma_deg``, ``theta_deg``,
    ``power``) that was not made on the points of ``meas``."""
    n = np.size(other.power)
    if n != meas.n_points:
        raise IrreflectError(
            f"compare_methods: {what} was made on {n} points, but '{meas.name}' has "
            f"{meas.n_points}: pass one made on this table")
    if not (np.array_equal(other.gamma_deg, meas.gamma_deg)
            and np.array_equal(other.theta_deg, meas.theta_deg)
            and np.array_equal(other.power, meas.power)):
        raise IrreflectError(
            f"compare_methods: {what} was made on other points than those of '{meas.name}' "
            f"(same count, {meas.n_points}, other angles or power): pass one made on this table")


def compare_methods(meas: Measurements, result: SelectionResult | None = None,
                    model="two-lobe", seed: int = 0, protocol_points=None,
                    full_fit=None) -> dict:
    """R^2 on all points of Method A (fit on all points), B (the search's best 12-point
    subset) and 12 (the paper's protocol points, Table 1, snapped to the nearest measured
    points), each fitted with :func:`irreflect.fitting.fit` on its own points only.

    ``full_fit`` : an existing :class:`~irreflect.fitting.FitResult` of ``model`` on all
    points, used for Method A instead of fitting again.

    Returns ``{"A": {...}, "B": {...}, "12": {...}, "order_holds": bool, "note": str}``;
    each method has ``r2`` and ``n_points`` (B is None-valued without a 12-point subset).
    """
    meas = as_measurements(meas)
    if result is not None:
        _check_same_points(meas, result.measurements, "result (a selection run)")
    if full_fit is not None:
        _check_same_points(meas, full_fit, "full_fit")
        wanted = get_model(model).name
        if full_fit.model != wanted:
            raise IrreflectError(
                f"compare_methods: full_fit is a fit of model '{full_fit.model}', not of "
                f"'{wanted}': pass a fit of model '{wanted}' on all points, or no full_fit")
    summary = None if result is None else result.front_summary
    if (full_fit is None and summary is not None and summary.n_total == meas.n_points
            and result.model == get_model(model).name):
        full_fit = summary.reference_fit  # the search's own fit on all points
    if full_fit is not None:
        r2_a = float(metrics.r2(meas.power, full_fit.predict(meas.gamma_deg, meas.theta_deg)))
    else:
        r2_a = _r2_all(meas, np.ones(meas.n_points, bool), model, seed)
    out = {"A": {"r2": r2_a, "n_points": meas.n_points}}
    mask_b = None if result is None else result.best_mask(PAPER_N)
    if mask_b is not None:
        out["B"] = {"r2": _r2_all(meas, mask_b, model, seed, f"best-{PAPER_N}"),
                    "n_points": int(mask_b.sum())}
    else:
        out["B"] = {"r2": None, "n_points": None}
    points = paper_protocol_points(meas) if protocol_points is None else protocol_points
    if len(_as_points(points)) > meas.n_points:
        # fewer measured points than the protocol has: Method 12 cannot be formed
        return _without_method12(out, f"the table has {meas.n_points} points, fewer than "
                                      f"the protocol's {len(_as_points(points))}: Method 12 "
                                      "not available")
    snapped = snap_points(meas, points)
    try:
        check_snapped(meas, snapped, "the paper's protocol" if protocol_points is None
                      else "the given protocol points")
    except IrreflectError as exc:  # the table lacks the protocol's settings
        return _without_method12(out, f"Method 12 not available: {exc}")
    mask_12 = np.zeros(meas.n_points, bool)
    mask_12[snapped["index"].to_numpy()] = True
    gammas = sorted({float(g) for g in snapped["gamma_requested"]}, key=abs)
    moved = snapped["distance_deg"] > 1e-9
    out["12"] = {"r2": _r2_all(meas, mask_12, model, seed, "paper-12pt"),
                 "n_points": int(mask_12.sum()),
                 "gammas": gammas,
                 "max_snap_deg": float(snapped["distance_deg"].max()),
                 "n_snapped": int(moved.sum()),
                 "how": _method12_text(meas, gammas, snapped, protocol_points is None)}
    a, b, c = out["A"]["r2"], out["B"]["r2"], out["12"]["r2"]
    tol = 1e-9
    if b is None:
        out["order_holds"] = bool(a >= c - tol)
        out["note"] = "no 12-point subset was searched (max_points < 12): B not available"
    else:
        out["order_holds"] = bool(a >= b - tol and b >= c - tol)
        if out["order_holds"]:
            out["note"] = "A >= B >= 12 holds"
        elif b > a + tol and meas.sigma is not None:
            out["note"] = ("B above A: the fit on all points is weighted by 1/sigma^2 (the "
                           "table's sigma column) and minimises chi^2, not the unweighted "
                           "error that R^2 measures")
        elif b > a + tol:
            out["note"] = ("B above A: the fit on all points did not reach its global optimum "
                           "(a least-squares fit on all points maximises R^2 on them)")
        else:
            out["note"] = _b_below_12_note(result, b, c)
    return out


def _b_below_12_note(result: SelectionResult | None, b: float, c: float) -> str:
    """Why Method B (the search's best 12 points, fitted thoroughly) falls below Method 12.
    When the search's own fits of its 12-point subsets beat Method 12 but the thorough fit
    of the same points does not, the search did find good points for its fits: a
    thorough fit of 12 points settles elsewhere (a noisy matte table: every 12-point
    subset's global least-squares optimum put a lobe where it has no point, R^2 -236
    against all points, while the search's fits of them gave 0.91), and a larger budget
    does not mend that."""
    quick = None if result is None else result.search_best.get(PAPER_N)
    if quick is not None and 1.0 - quick[0] > c:
        return (f"12 above B: the search's fits of its best {PAPER_N} points reach R^2 "
                f"{1.0 - quick[0]:.4g} against all points, the thorough fit of the same "
                f"points (their global least-squares optimum) {b:.4g}: {PAPER_N} points "
                "leave the model's optimum free where they have no point; a larger search "
                "budget does not mend it (a simpler model, fixed coefficients, or an "
                "adaptive campaign: irreflect next)")
    return ("12 above B: the search did not find the best 12-point subset within its budget "
            "(raise --generations or --pop-size)")


def _without_method12(out: dict, note: str) -> dict:
    """``out`` of :func:`compare_methods` when Method 12 cannot be formed: A >= B is all
    the order there is to check."""
    out["12"] = {"r2": None, "n_points": None}
    b = out["B"]["r2"]
    out["order_holds"] = bool(b is None or out["A"]["r2"] >= b - 1e-9)
    out["note"] = note
    return out


def _method12_text(meas: Measurements, gammas, snapped: pd.DataFrame, paper_rule: bool) -> str:
    """How Method 12's points were made, in one line (printed by ``select``)."""
    table1 = sorted(abs(g) for g in gammas) == [20.0, 40.0, 60.0]
    if paper_rule:
        head = ("the paper's rule (section 4.3, Eqs. 23-34) at gamma "
                + "/".join(f"{g:g}" for g in gammas) + " deg"
                + (" (Table 1's angles of incidence)" if table1 else
                   " (three of this table's angles of incidence: it lacks Table 1's -20/-40/-60)")
                + f", receivers within {np.min(meas.theta_deg):g}..{np.max(meas.theta_deg):g} deg")
    else:
        head = f"the given points at gamma {'/'.join(f'{g:g}' for g in gammas)} deg"
    moved = snapped[snapped["distance_deg"] > 1e-9]
    if not len(moved):
        return head + "; every point was measured exactly"
    return (head + f"; {len(moved)} of {len(snapped)} points snapped to the nearest measured "
            f"point, by {moved['distance_deg'].min():.2g}-{moved['distance_deg'].max():.2g} deg")
