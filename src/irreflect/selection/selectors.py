"""Search strategies for measurement plans, in one registry.

Every selector spends (about) the same budget of subset fits through one
:class:`~irreflect.selection.problem.SubsetEvaluator`, whose archive of the best masks per
subset size becomes the Pareto frontier; so fronts of different selectors can be compared
at equal cost (their hypervolumes use the same reference point).

=========== ===========================================================================
nsga2       NSGA-II (pymoo) on boolean masks: size-varied sampling, subset crossover,
            swap/add/drop mutation, size repair, duplicate elimination (the paper's GA)
random      best of k random subsets for every size N (k = budget / number of sizes)
greedy      forward selection: from the best of a few random minimal subsets, add the
            point that most improves R^2 on all points, one point at a time
d-optimal   sequential D-optimal design: add the point that most increases
            det(J^T J) of the model's Jacobian at a pilot fit, then a swap pass
=========== ===========================================================================
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pymoo.operators.selection.tournament import TournamentSelection
from pymoo.termination.max_gen import MaximumGenerationTermination

from ..errors import IrreflectError, unknown_name
from ..fitting import prediction_and_jacobian
from .checkpoint import load_checkpoint, restore, save_checkpoint
from .problem import (
    MaskDuplicateElimination,
    SizeRepair,
    SizeVariedSampling,
    SubsetCrossover,
    SubsetEvaluator,
    SubsetMutation,
    SubsetProblem,
)
from .pymoo_overrides import (
    FeasibleRankAndCrowding,
    MaskEvaluator,
    SubsetNSGA2,
    binary_tournament,
)


@dataclass
class SearchSpec:
    """What a selector gets.

    evaluator : scores masks and keeps the archive (counts the fits)
    n_min, n_max : subset sizes allowed
    candidates : (n,) bool, points that may be chosen
    pop_size, generations : NSGA-II budget; other selectors spend ``budget`` fits
    seed : seeds every random choice
    tick : callable(done: int, total: int), progress in the selector's own unit
    checkpoint : file for NSGA-II state (None: no checkpoints); every ``checkpoint_every``
        generations
    initial : optional (m, n) masks put into the first population
    fingerprint : identifies data and settings; a checkpoint of another run is refused
    pilot : natural parameters of the pilot fit (d-optimal), or None
    """

    evaluator: SubsetEvaluator
    n_min: int
    n_max: int
    candidates: np.ndarray
    pop_size: int = 100
    generations: int = 200
    seed: int = 0
    tick: Callable[[int, int], None] = lambda done, total: None
    checkpoint: Path | None = None
    checkpoint_every: int = 10
    initial: np.ndarray | None = None
    fingerprint: str = ""
    pilot: np.ndarray | None = None
    info: dict = field(default_factory=dict)

    @property
    def budget(self) -> int:
        return int(self.pop_size * self.generations)

    @property
    def allowed(self) -> np.ndarray:
        return np.nonzero(self.candidates)[0]


# ----------------------------------------------------------------------------- nsga2
def nsga2(spec: SearchSpec) -> None:
    """NSGA-II over masks; checkpoints and resumes (same result as an uninterrupted run).

    Checkpoints are data-only ``.npz`` files (:mod:`.checkpoint`): the population, the
    random generator's state and the evaluator's cache and archive."""


    generation, previous_seconds = 0, 0.0
    problem = SubsetProblem(spec.evaluator, spec.n_min, spec.n_max, spec.candidates)
    algorithm = SubsetNSGA2(
        pop_size=spec.pop_size,
        sampling=SizeVariedSampling(spec.initial),
        selection=TournamentSelection(func_comp=binary_tournament),
        crossover=SubsetCrossover(),
        mutation=SubsetMutation(),
        repair=SizeRepair(),
        eliminate_duplicates=MaskDuplicateElimination(),
        survival=FeasibleRankAndCrowding(),
        evaluator=MaskEvaluator(),
    )
    algorithm.setup(problem, termination=("n_gen", spec.generations), seed=spec.seed,
                    verbose=False)
    if spec.checkpoint is not None and Path(spec.checkpoint).exists():
        state = load_checkpoint(Path(spec.checkpoint), spec.fingerprint, spec.evaluator.n,
                                spec.evaluator.model.n_nonlinear)
        generation = restore(state, algorithm, spec.evaluator)
        previous_seconds = state["meta"]["seconds"]
        spec.info["resumed_from_generation"] = generation
    algorithm.termination = MaximumGenerationTermination(max(spec.generations, 1))
    spec.info["seconds_before_resume"] = previous_seconds

    t0 = time.perf_counter()
    spec.tick(generation, spec.generations)
    while generation < spec.generations:
        algorithm.next()
        generation += 1
        spec.info["generations_done"] = generation
        spec.tick(generation, spec.generations)
        if spec.checkpoint is not None and (generation % spec.checkpoint_every == 0
                                            or generation == spec.generations):
            save_checkpoint(Path(spec.checkpoint), spec.fingerprint, algorithm, spec.evaluator,
                            generation, previous_seconds + time.perf_counter() - t0)
    spec.info["generations_done"] = generation


# ----------------------------------------------------------------------------- random
def random_subsets(spec: SearchSpec) -> None:
    """Best of k random subsets per size: the budget is spread evenly over all sizes."""
    rng = np.random.default_rng(spec.seed)
    sizes = np.arange(spec.n_min, spec.n_max + 1)
    allowed = spec.allowed
    per_size = max(1, spec.budget // sizes.size)
    batch = max(1, spec.pop_size)
    total = per_size * sizes.size
    plan = np.repeat(sizes, per_size)
    done = 0
    for lo in range(0, total, batch):
        chunk = plan[lo : lo + batch]
        masks = np.zeros((chunk.size, spec.evaluator.n), bool)
        for i, k in enumerate(chunk):
            masks[i, rng.choice(allowed, size=k, replace=False)] = True
        spec.evaluator(masks)
        done += chunk.size
        spec.tick(done, total)


# ----------------------------------------------------------------------------- greedy
def greedy(spec: SearchSpec) -> None:
    """Forward selection on R^2 against all points: each step tries every allowed point
    not yet chosen (one batch) and keeps the best; stops at ``n_max`` or the budget."""
    rng = np.random.default_rng(spec.seed)
    allowed = spec.allowed
    ev = spec.evaluator
    n_seed = min(max(spec.pop_size, 1), spec.budget)
    seeds = np.zeros((n_seed, ev.n), bool)
    for i in range(n_seed):
        seeds[i, rng.choice(allowed, size=spec.n_min, replace=False)] = True
    scores = ev(seeds)
    used = n_seed
    current = seeds[int(np.argmin(scores))].copy()
    spec.tick(used, spec.budget)
    while current.sum() < spec.n_max:
        options = allowed[~current[allowed]]
        if options.size == 0 or used + options.size > spec.budget:
            break
        trial = np.repeat(current[None], options.size, axis=0)
        trial[np.arange(options.size), options] = True
        s = ev(trial)
        used += options.size
        current = trial[int(np.argmin(s))]
        spec.tick(used, spec.budget)


# ----------------------------------------------------------------------------- d-optimal
def _jacobian(model, params, gamma_rad, theta_rad, sigma):
    """Jacobian (n, P+L) of the model power in its internal coordinates (z, alpha) at the
    pilot parameters, weighted by 1/sigma; D-optimality does not depend on the
    parametrisation (a reparametrisation multiplies every det by the same factor)."""

    with np.errstate(all="ignore"):
        _, jac = prediction_and_jacobian(model, params, gamma_rad, theta_rad)
    jac = np.array(jac, float)
    if sigma is not None:
        jac = jac / sigma[:, None]
    jac[~np.isfinite(jac)] = 0.0
    scale = np.sqrt(np.sum(jac * jac, axis=0))
    return jac / np.where(scale > 0, scale, 1.0)


def d_optimal(spec: SearchSpec) -> None:
    """Nested D-optimal designs at the pilot fit, then Fedorov exchanges.

    Sizes grow one point at a time: the point ``x`` with the largest ``x^T M^-1 x`` is
    added (``M = J_S^T J_S + eps I``; det(M + x x^T) = det(M) (1 + x^T M^-1 x)). Each
    design is then improved by swaps of a chosen point ``a`` for an unchosen ``b`` while
    Fedorov's ratio ``(1 + b'M^-1 b)(1 - a'M^-1 a) + (a'M^-1 b)^2`` exceeds 1. Every design
    is then scored like any other subset (a fit on its points only, R^2 on all points).
    """
    ev = spec.evaluator
    if spec.pilot is None:
        raise IrreflectError("the d-optimal selector needs a pilot fit (run_selection makes one)")
    jac = _jacobian(ev.model, spec.pilot, np.radians(ev.gamma_deg), np.radians(ev.theta_deg),
                    ev.sigma)
    p = jac.shape[1]
    eps = 1e-6 * np.eye(p)
    allowed = spec.allowed
    chosen = np.zeros(ev.n, bool)
    designs = []
    total = spec.n_max - spec.n_min + 1
    while chosen.sum() < spec.n_max:
        options = allowed[~chosen[allowed]]
        if options.size == 0:
            break
        m_inv = np.linalg.inv(jac[chosen].T @ jac[chosen] + eps)
        gain = np.einsum("ip,pq,iq->i", jac[options], m_inv, jac[options])
        chosen[options[int(np.argmax(gain))]] = True
        if chosen.sum() < spec.n_min:
            continue
        design = chosen.copy()
        for _swap in range(4 * p):
            inside = np.nonzero(design)[0]
            outside = allowed[~design[allowed]]
            if outside.size == 0:
                break
            m_inv = np.linalg.inv(jac[design].T @ jac[design] + eps)
            a, b = jac[inside] @ m_inv, jac[outside] @ m_inv
            d_in = np.sum(a * jac[inside], axis=1)
            d_out = np.sum(b * jac[outside], axis=1)
            cross = a @ jac[outside].T
            ratio = (1 + d_out)[None, :] * (1 - d_in)[:, None] + cross**2
            i, j = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
            if ratio[i, j] <= 1 + 1e-9:
                break
            design[inside[i]] = False
            design[outside[j]] = True
        designs.append(design)
        if len(designs) >= max(spec.pop_size, 1):
            ev(np.array(designs))
            designs = []
            spec.tick(int(chosen.sum()) - spec.n_min + 1, total)
    if designs:
        ev(np.array(designs))
    spec.tick(total, total)


# ----------------------------------------------------------------------------- registry
@dataclass(frozen=True)
class Selector:
    """A search strategy and what the run needs to know about it (no name checks
    elsewhere: adding a selector is a function plus one line in :data:`SELECTORS`).

    run : ``run(spec)`` spends the budget through ``spec.evaluator``
    unit : the progress unit (``gen`` for generations, ``fit`` for subset fits)
    needs_pilot : gets a pilot fit on all points in ``spec.pilot``
    resumable : honours ``spec.checkpoint`` (saves its state, resumes from it)
    takes_initial : uses ``spec.initial`` masks (then the full candidate set is offered too,
        so the frontier ends at Method A)
    """

    run: Callable[[SearchSpec], None]
    unit: str = "fit"
    needs_pilot: bool = False
    resumable: bool = False
    takes_initial: bool = False

    def __call__(self, spec: SearchSpec) -> None:
        self.run(spec)


SELECTORS: dict[str, Selector] = {
    "nsga2": Selector(nsga2, unit="gen", resumable=True, takes_initial=True),
    "random": Selector(random_subsets),
    "greedy": Selector(greedy),
    "d-optimal": Selector(d_optimal, needs_pilot=True),
}


def get_selector(name: str) -> Selector:
    """The selector called ``name`` (see :data:`SELECTORS`)."""
    if not isinstance(name, str) or name not in SELECTORS:
        raise unknown_name("selector", name, SELECTORS)
    return SELECTORS[name]
