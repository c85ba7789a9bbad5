"""The measurement-point selection problem: masks in, (N, 1 - R^2) out.

A candidate measurement plan is a boolean mask over the points of a dense measurement set.
Its two objectives (the paper, section 4.3 and Fig. 18) are the number of chosen points
``N`` and ``1 - R^2``, where R^2 compares the model fitted **on the chosen points only**
with **all** points of the set. Fits of a whole population are done in one batch by
:func:`irreflect.fitting.fit_subsets`; a subset fit sees nothing outside its subset.

Contents
--------
SubsetEvaluator    batched, counted, cached scoring of masks, with a per-N archive
SubsetProblem      the pymoo ``Problem`` (vectorised ``_evaluate`` on the 2-D mask array)
SizeVariedSampling, SubsetCrossover, SubsetMutation, SizeRepair, MaskDuplicateElimination
                   binary operators that keep masks binary and sizes within bounds

pymoo's internals that irreflect overrides (its evaluator, NSGA-II's mating selection and
survival, the operators' ``do``) are in :mod:`.pymoo_overrides`.
"""

from __future__ import annotations

import inspect
import time
from dataclasses import dataclass

import numpy as np
from pymoo.core.duplicate import DuplicateElimination
from pymoo.core.problem import Problem
from pymoo.core.sampling import Sampling

from ..errors import IrreflectError
from ..fitting import fit_subsets, uses_kernel
from ..models import get_model
from .pymoo_overrides import BatchedCrossover, BatchedMutation, BatchedRepair, masks_of

#: what a FitSettings may set: the keyword-only options of fit_subsets that tune a fit
_SUBSET_FIT_OPTIONS = frozenset(
    name for name, p in inspect.signature(fit_subsets).parameters.items()
    if p.kind is p.KEYWORD_ONLY and name not in ("sigma", "shared_starts")
)

#: Score given to a subset whose fit failed (R^2 = 0: no better than the mean).
FAILED_SCORE = 1.0


def pack(mask: np.ndarray) -> bytes:
    """Compact, hashable key of one boolean mask."""
    return np.packbits(np.asarray(mask, bool)).tobytes()


def pack_rows(masks: np.ndarray) -> list[bytes]:
    """:func:`pack` of every row of a (B, n) mask array."""
    packed = np.packbits(np.asarray(masks, bool), axis=1)
    return [row.tobytes() for row in packed]


def unpack(key: bytes, n: int) -> np.ndarray:
    return np.unpackbits(np.frombuffer(key, np.uint8), count=n).astype(bool)


@dataclass(frozen=True)
class FitSettings:
    """Keyword options of :func:`irreflect.fitting.fit_subsets` for each subset fit
    (``max_iter``, ``n_screen``, ``n_keep``, ...). An option ``fit_subsets`` does not take
    is refused when the settings are made (a typo must not disappear)."""

    options: tuple[tuple[str, object], ...] = ()

    def __post_init__(self):
        accepted = _SUBSET_FIT_OPTIONS
        unknown = sorted(k for k, _ in self.options if k not in accepted)
        if unknown:
            raise IrreflectError(
                f"unknown subset-fit option(s) {', '.join(map(repr, unknown))}: "
                f"expected some of {', '.join(sorted(accepted))} (the keyword options of "
                "irreflect.fitting.fit_subsets)"
            )

    @classmethod
    def of(cls, **options) -> FitSettings:
        return cls(tuple(sorted(options.items())))

    def kwargs(self) -> dict:
        return dict(self.options)

    def as_dict(self) -> dict:
        return dict(self.options)


#: The search: a light screening (16 candidates, the data-driven starts of each subset's own
#: points, and the optima of the best subsets found so far, all scored on the subset's
#: points) and Levenberg-Marquardt from the best candidate and the best data-driven start,
#: stopped at a relative cost change of 1e-6 and 15 iterations: it only ranks subsets.
#: On generated glossy tables (10-40-point subsets of 8 tables) its cost is within 1 % of
#: the exhaustive fit's for 86 % of subsets and within 2x for 99 % (without the shared
#: optima: 56 % and 65 %); every reported subset is refitted with VERIFY_FIT.
SEARCH_FIT = FitSettings.of(n_screen=16, n_keep=1, n_data_starts=1, max_iter=15, ftol=1e-6)
#: How many optima of the best subsets are shared as starting candidates.
N_ELITES = 4
#: The final check of every reported subset: exactly ``fit``'s global search on the
#: subset's own points.
VERIFY_FIT = FitSettings.of(exhaustive=True)


def _chunks(counts: np.ndarray, overhead: float = 300.0) -> list[np.ndarray]:
    """Split a batch so that padding every subset of a chunk to the chunk's largest size
    wastes little work: subsets sorted by size, chunk ends chosen by dynamic programming to
    minimise ``sum(len(chunk) * max_size(chunk) + overhead)``; ``overhead`` is the fixed cost
    of one batched call in point-fits (measured: ~300 on the two-lobe model)."""
    order = np.argsort(counts, kind="stable")
    c = counts[order].astype(float)
    b = c.size
    if b <= 16:
        return [order]
    ends = np.unique(np.r_[np.arange(8, b, 8), b])  # chunk ends (exclusive)
    best = {0: (0.0, ())}
    for end in ends:
        best[end] = min(((cost + (end - s) * c[end - 1] + overhead, cuts + (end,))
                         for s, (cost, cuts) in best.items() if s < end), key=lambda t: t[0])
    out, lo = [], 0
    for hi in best[b][1]:
        out.append(order[lo:hi])
        lo = hi
    return out


#: Caller-side memory bound of one :func:`~irreflect.fitting.fit_subsets` call: its arrays
#: are about (subsets) x (largest subset) x (screening candidates + starts x 16) float64
#: values each; a chunk is split until that product is at most this (about 100 MB per array).
MAX_BATCH_VALUES = 12_000_000


def values_per_point(options: dict) -> int:
    """float64 values per subset point that one batched subset fit holds at once: the
    screening candidates and data-driven starts (one basis value each), and 16 per
    Levenberg-Marquardt start (basis, derivatives and their products), plus 8."""
    starts = int(options.get("n_keep", 2)) + int(options.get("n_data_starts", 1))
    return int(options.get("n_screen", 32)) + 5 + 16 * starts + 8


def _bounded(rows: np.ndarray, counts: np.ndarray, per_point: int,
             per_row: int = 0) -> list[np.ndarray]:
    """Split ``rows`` (sorted by subset size) into pieces whose (rows x largest subset x
    per_point) and (rows x per_row: what each row holds over the whole table, its mask and
    the prediction for R^2 on all points) both stay within :data:`MAX_BATCH_VALUES`."""
    largest = int(counts[rows].max()) if rows.size else 1
    step = max(1, MAX_BATCH_VALUES // max(1, largest * per_point, int(per_row)))
    return [rows[i:i + step] for i in range(0, rows.size, step)]


class PointMasks:
    """The masks ``base`` plus one point each (``add``) or minus one point each, one row per
    entry of ``points``, built piece by piece when fitted: a table of 20,000 points has
    20,000 such neighbours, whose full (rows x points) array alone would be 400 MB.

    Rows come in the order ``np.unique(masks, axis=0)`` gives (added points descending,
    dropped points ascending), so that ties are broken as for an explicit array."""

    def __init__(self, base: np.ndarray, points: np.ndarray, add: bool = True):
        self.base = np.asarray(base, bool)
        points = np.unique(np.asarray(points, np.int64))
        self.points = points[::-1] if add else points
        self.add = bool(add)

    def __len__(self) -> int:
        return int(self.points.size)

    def counts(self) -> np.ndarray:
        return np.full(len(self), int(self.base.sum()) + (1 if self.add else -1), np.int64)

    def rows(self, idx) -> np.ndarray:
        idx = np.atleast_1d(np.asarray(idx, np.int64))
        out = np.repeat(self.base[None], idx.size, axis=0)
        out[np.arange(idx.size), self.points[idx]] = self.add
        return out


class SubsetEvaluator:
    """Scores masks by ``1 - R^2`` of the subset fit against all points, in batches.

    Counts real fits (``evaluations``), failed fits and fitting time; remembers every
    scored mask (same mask, same score: no refit) and keeps, for each subset size N, the
    ``keep`` best distinct masks found (the archive the front is built from).

    Parameters
    ----------
    gamma_deg, theta_deg : (n,) arrays, degrees
    power : (n,) array, power units
    sigma : (n,) array or None, power units; fits are weighted by 1/sigma^2 like ``fit``
    model : str or ReflectionModel
    settings : FitSettings
    keep : int, masks kept per N in the archive
    """

    def __init__(self, gamma_deg, theta_deg, power, sigma=None, model="two-lobe",
                 settings: FitSettings = SEARCH_FIT, keep: int = 3):
        self.gamma_deg = np.asarray(gamma_deg, float)
        self.theta_deg = np.asarray(theta_deg, float)
        self.power = np.asarray(power, float)
        self.sigma = None if sigma is None else np.asarray(sigma, float)
        self.model = get_model(model)
        self.settings = settings
        self.keep = int(keep)
        self.n = self.power.size
        self.evaluations = 0
        self.failed_fits = 0
        self.cache_hits = 0
        self.fit_seconds = 0.0
        self.cache: dict[bytes, float] = {}
        self.archive: dict[int, list[tuple[float, int, bytes]]] = {}
        self._serial = 0
        #: shape optima of the best subsets seen (score, z): starting candidates shared
        #: with every later subset fit of the search
        self.elite_scores = np.zeros(0)
        self.elites = np.zeros((0, self.model.n_nonlinear))

    def __getstate__(self):
        # models may hold closures (n-lobe): store the registry name, rebuild on load
        state = self.__dict__.copy()
        state["model"] = self.model.name
        return state

    def __setstate__(self, state):
        state = dict(state)
        state["model"] = get_model(state["model"])
        self.__dict__.update(state)

    # -- fitting
    def fit_masks(self, masks: np.ndarray | PointMasks, settings: FitSettings | None = None):
        """Fit every mask (no cache, no counting); returns (scores (B,), failed (B,)).
        ``masks``: a (B, n) array or :class:`PointMasks` (built piece by piece)."""
        settings = settings or self.settings
        if isinstance(masks, PointMasks):
            counts, take = masks.counts(), masks.rows
        else:
            masks = np.atleast_2d(np.asarray(masks, bool))
            counts = masks.sum(axis=1)

            def take(idx):
                return masks[idx]
        scores = np.full(len(masks), FAILED_SCORE)
        failed = np.ones(len(masks), bool)
        fittable = np.nonzero(counts > self.model.n_params)[0]  # a degree of freedom, as fit
        if fittable.size == 0:
            return scores, failed
        options = settings.kwargs()
        share = not options.get("exhaustive", False)
        per_point = values_per_point(options)
        # the shared optima are those known before this call: every piece of the batch
        # gets the same (the scores do not depend on how the batch is split)
        extra = {"shared_starts": self.elites} if share and len(self.elites) else {}
        found = []
        # the compiled kernel fits subset by subset (no padding to the largest of a chunk):
        # one call for the whole batch; the numpy path pads, chunks by size pay off there
        compiled = not options.get("exhaustive", False) and \
            uses_kernel(self.model, options.get("engine"))
        chunks = [np.arange(fittable.size)] if compiled else _chunks(counts[fittable])
        for idx in chunks:
            # per row over the whole table: its mask (compiled: the R^2 is summed point by
            # point), or the numpy path's weighted mask and predictions (about 8 values)
            per_row = self.n if compiled else 8 * self.n
            for piece in _bounded(fittable[idx], counts, per_point, per_row):
                res = fit_subsets(self.gamma_deg, self.theta_deg, self.power, take(piece),
                                  self.model, sigma=self.sigma, **options, **extra)
                ok = ~res.failed & np.isfinite(res.r2_all)
                scores[piece] = np.where(ok, 1.0 - res.r2_all, FAILED_SCORE)
                failed[piece] = ~ok
                found.append((scores[piece], res.params, ok))
        if share:
            for piece_scores, params, ok in found:
                self._update_elites(piece_scores, params, ok)
        return scores, failed

    def _update_elites(self, scores, params, ok) -> None:
        """Keep the shape optima of the :data:`N_ELITES` best subsets (distinct shapes)."""
        if not ok.any():
            return
        z, _ = self.model.from_natural(params[ok])
        all_scores = np.concatenate([self.elite_scores, scores[ok]])
        all_z = np.vstack([self.elites, z])
        order = np.argsort(all_scores, kind="stable")
        finite = np.all(np.isfinite(all_z), axis=1)
        keep = []
        for i in order:
            if not finite[i]:
                continue
            if keep:  # np.allclose(all_z[i], kept, rtol=1e-6, atol=1e-9) for any kept
                kept = all_z[keep]
                if np.any(np.all(np.abs(all_z[i] - kept) <= 1e-9 + 1e-6 * np.abs(kept),
                                 axis=1)):
                    continue
            keep.append(i)
            if len(keep) == N_ELITES:
                break
        self.elite_scores = all_scores[keep]
        self.elites = all_z[keep].reshape(len(keep), -1)

    def __call__(self, masks: np.ndarray) -> np.ndarray:
        """Scores ``1 - R^2`` (B,) of every mask; failed fits score :data:`FAILED_SCORE`."""
        masks = np.atleast_2d(np.asarray(masks, bool))
        keys = pack_rows(masks)
        scores = np.empty(len(masks))
        todo, todo_keys, first = [], {}, {}
        for i, k in enumerate(keys):
            if k in self.cache:
                scores[i] = self.cache[k]
                self.cache_hits += 1
            elif k in todo_keys:
                first[i] = todo_keys[k]
            else:
                todo_keys[k] = i
                todo.append(i)
        if todo:
            t0 = time.perf_counter()
            new, failed = self.fit_masks(masks[todo])
            self.fit_seconds += time.perf_counter() - t0
            self.evaluations += len(todo)
            self.failed_fits += int(failed.sum())
            counts = masks[todo].sum(axis=1)
            for j, i in enumerate(todo):
                scores[i] = new[j]
                self.cache[keys[i]] = float(new[j])
                self._remember(int(counts[j]), float(new[j]), keys[i])
        for i, j in first.items():
            scores[i] = scores[j]
        return scores

    def _remember(self, n_points: int, score: float, key: bytes) -> None:
        if not np.isfinite(score):
            return
        entries = self.archive.setdefault(n_points, [])
        if len(entries) >= self.keep and score >= entries[-1][0]:
            return
        self._serial += 1
        entries.append((score, self._serial, key))
        entries.sort()
        del entries[self.keep:]

    # -- archive views
    def best(self, n_points: int) -> tuple[float, np.ndarray] | None:
        """Best (score, mask) found with exactly ``n_points`` points, or None."""
        entries = self.archive.get(int(n_points))
        if not entries:
            return None
        return entries[0][0], unpack(entries[0][2], self.n)

    def best_score_at(self, n_points: int) -> float:
        found = self.best(n_points)
        return float("nan") if found is None else found[0]


class SubsetProblem(Problem):
    """pymoo problem: minimise (N, 1 - R^2) over boolean masks of the measured points.

    Constraints (``G <= 0``): ``n_min - N`` (more points than the model has parameters) and
    ``N - n_max``; points outside ``candidates`` may not be chosen (the operators never
    set them; a mask that does is infeasible).
    """

    def __init__(self, evaluator: SubsetEvaluator, n_min: int, n_max: int,
                 candidates: np.ndarray | None = None):
        n = evaluator.n
        self.evaluator = evaluator
        self.n_min = int(n_min)
        self.n_max = int(n_max)
        self.candidates = (np.ones(n, bool) if candidates is None
                           else np.asarray(candidates, bool).copy())
        super().__init__(n_var=n, n_obj=2, n_ieq_constr=3, xl=0, xu=1, vtype=bool)

    def _evaluate(self, X, out, *args, **kwargs):
        masks = np.asarray(X, bool)
        counts = masks.sum(axis=1)
        scores = self.evaluator(masks)
        out["F"] = np.column_stack([counts.astype(float), scores])
        outside = (masks & ~self.candidates).sum(axis=1)
        out["G"] = np.column_stack([self.n_min - counts, counts - self.n_max, outside]).astype(float)


# ----------------------------------------------------------------------------- operators
def _allowed(problem) -> np.ndarray:
    return getattr(problem, "candidates", np.ones(problem.n_var, bool))


class SizeVariedSampling(Sampling):
    """Random masks whose sizes spread log-uniformly over ``[n_min, n_max]`` (small plans
    are where the frontier bends), optionally plus given initial masks."""

    def __init__(self, initial: np.ndarray | None = None):
        super().__init__()
        self.initial = None if initial is None else np.atleast_2d(np.asarray(initial, bool))

    def _do(self, problem, n_samples, *args, random_state=None, **kwargs):
        allowed = np.nonzero(_allowed(problem))[0]
        lo, hi = problem.n_min, problem.n_max
        out = np.zeros((n_samples, problem.n_var), bool)
        sizes = np.exp(random_state.uniform(np.log(lo), np.log(hi + 1), n_samples))
        sizes = np.clip(np.floor(sizes).astype(int), lo, hi)
        for i, k in enumerate(sizes):
            out[i, random_state.choice(allowed, size=k, replace=False)] = True
        if self.initial is not None:
            m = min(len(self.initial), n_samples)
            out[:m] = self.initial[:m]
        return out


class SubsetCrossover(BatchedCrossover):
    """Two parents, two children: the points both parents share are kept, each point only
    one parent has goes to one child or the other (so child sizes stay near the parents')."""

    def __init__(self, prob=0.9):
        super().__init__(2, 2, prob=prob)

    def _do(self, problem, X, *args, random_state=None, **kwargs):
        a, b = X[0].astype(bool), X[1].astype(bool)
        differ = a ^ b
        coin = random_state.random(a.shape) < 0.5
        c1 = (a & b) | (differ & coin)
        c2 = (a & b) | (differ & ~coin)
        return np.stack([c1, c2])


class SubsetMutation(BatchedMutation):
    """Moves that change which points are chosen: swap a chosen point for an unchosen one
    (same N, probability ``p_swap``), add one (``p_add``) or drop one (``p_drop``)."""

    def __init__(self, p_swap=0.8, p_add=0.25, p_drop=0.25):
        super().__init__(prob=1.0)
        self.p_swap, self.p_add, self.p_drop = p_swap, p_add, p_drop

    def _do(self, problem, X, *args, random_state=None, **kwargs):
        X = np.asarray(X, bool).copy()
        allowed = _allowed(problem)
        rows = np.arange(len(X))
        r = random_state.random((len(X), 3))

        def pick(pool):
            """One uniformly random True column per row of ``pool`` (and whether any)."""
            key = np.where(pool, random_state.random(pool.shape), -1.0)
            return np.argmax(key, axis=1), pool.any(axis=1)

        out_i, has_on = pick(X)
        in_i, has_off = pick(~X & allowed)
        swap = (r[:, 0] < self.p_swap) & has_on & has_off
        X[rows[swap], out_i[swap]] = False
        X[rows[swap], in_i[swap]] = True
        in_i, has_off = pick(~X & allowed)
        add = (r[:, 1] < self.p_add) & has_off
        X[rows[add], in_i[add]] = True
        out_i, has_on = pick(X)
        drop = (r[:, 2] < self.p_drop) & has_on
        X[rows[drop], out_i[drop]] = False
        return X


class SizeRepair(BatchedRepair):
    """Keeps masks inside the allowed points and sizes within ``[n_min, n_max]`` by
    dropping or adding random allowed points."""

    def _do(self, problem, X, random_state=None, **kwargs):
        rng = random_state if random_state is not None else np.random.default_rng(0)
        X = np.asarray(X, bool) & _allowed(problem)
        allowed = _allowed(problem)
        counts = X.sum(axis=1)
        for i in np.nonzero((counts < problem.n_min) | (counts > problem.n_max))[0]:
            on = np.nonzero(X[i])[0]
            if counts[i] > problem.n_max:
                X[i, rng.choice(on, counts[i] - problem.n_max, replace=False)] = False
            else:
                off = np.nonzero(~X[i] & allowed)[0]
                X[i, rng.choice(off, problem.n_min - counts[i], replace=False)] = True
        return X


class MaskDuplicateElimination(DuplicateElimination):
    """Exact duplicate masks by hashing (O(B) instead of pymoo's pairwise distances)."""

    def _do(self, pop, other, is_duplicate):
        keys = pack_rows(masks_of(pop))
        if other is None:
            seen = set()
            for i, k in enumerate(keys):
                if k in seen:
                    is_duplicate[i] = True
                seen.add(k)
        else:
            seen = set(pack_rows(masks_of(other)))
            for i, k in enumerate(keys):
                if k in seen:
                    is_duplicate[i] = True
        return is_duplicate


def check_sizes(n: int, n_params: int, max_points: int | None, candidates) -> tuple[int, int]:
    """Validate the size bounds of a selection run; returns ``(n_min, n_max)``, with
    ``n_min = n_params + 1``: the fewest points :func:`irreflect.fit` fits."""
    n_allowed = n if candidates is None else int(np.asarray(candidates, bool).sum())
    if candidates is not None and np.asarray(candidates).shape != (n,):
        raise IrreflectError(
            f"candidates must be a boolean mask of {n} points (one per measurement); found "
            f"shape {np.asarray(candidates).shape}"
        )
    if n_allowed <= n_params:
        raise IrreflectError(
            f"point selection needs more than {n_params} selectable points to fit the "
            f"{n_params} model parameters; found {n_allowed}: measure a denser set or allow "
            "more candidate points"
        )
    # a subset must leave the fit a degree of freedom, as irreflect.fit requires: a plan
    # of exactly n_params points interpolates them and cannot be fitted or checked
    n_min = n_params + 1
    n_max = n_allowed if max_points is None else int(max_points)
    if n_max < n_min:
        raise IrreflectError(
            f"max_points (--max-points) must be at least {n_min} (the model's {n_params} parameters and a "
            f"degree of freedom); found {n_max}"
        )
    return n_min, min(n_max, n_allowed)
