"""Where irreflect overrides pymoo's internals, all in this one module (pymoo is pinned
``>=0.6.1,<0.7`` in pyproject.toml; tests/test_selection.py checks that a seeded run with
these overrides gives the very front stock NSGA-II gives).

pymoo reads and writes every attribute of a population one individual at a time
(``Population.get`` calls ``Individual.get``, whose ``hasattr`` evaluates each property,
the constraint violation twice); per generation that was as long as the batched fits. The
classes below do the same things through the attributes directly, with the same values
and the same random draws:

MaskEvaluator            pymoo's Evaluator, values (F, G, H, CV) set in one pass
binary_tournament        NSGA-II's mating selection on arrays of the population's values
FeasibleRankAndCrowding  NSGA-II's survival without the feasible/infeasible split while
                         every constraint holds
SubsetNSGA2              NSGA-II whose optimum is found without Population.get
BatchedCrossover, BatchedMutation, BatchedRepair
                         the operators' ``do`` with the masks gathered in one pass
"""

from __future__ import annotations

import numpy as np
from pymoo.algorithms.moo.nsga2 import NSGA2
from pymoo.algorithms.moo.nsga2 import binary_tournament as _pymoo_binary_tournament
from pymoo.core.crossover import Crossover
from pymoo.core.evaluator import Evaluator
from pymoo.core.individual import Individual
from pymoo.core.mutation import Mutation
from pymoo.core.population import Population
from pymoo.core.repair import Repair
from pymoo.core.survival import Survival
from pymoo.core.variable import get
from pymoo.operators.survival.rank_and_crowding.classes import RankAndCrowding
from pymoo.operators.survival.rank_and_crowding.metrics import get_crowding_function
from pymoo.util.nds.non_dominated_sorting import NonDominatedSorting
from pymoo.util.randomized_argsort import randomized_argsort


def masks_of(pop) -> np.ndarray:
    """``pop.get("X")``."""
    return np.array([ind.X for ind in pop])


def _violations(pop) -> np.ndarray:
    """``pop.get("CV")[:, 0]``: every individual's constraint violation."""
    return np.array([ind.CV[0] for ind in pop], float)


def _new_population(X) -> Population:
    """``Population.new("X", X)``: one individual per row (a copy of it)."""
    pop = Population.empty(len(X))
    for ind, row in zip(pop, X, strict=True):
        ind.X = row.copy()
    return pop


class MaskEvaluator(Evaluator):
    """pymoo's Evaluator with the masks gathered and the values (F, G, H) set in one pass,
    and every individual's constraint violation stored with them: pymoo's ``calc_cv``
    under its default configuration (the sum of the positive parts of G; the problems
    here have no equality constraints), which pymoo would otherwise compute lazily, one
    individual at a time, on every access."""

    def _eval(self, problem, pop, evaluate_values_of, **kwargs):
        out = problem.evaluate(masks_of(pop), return_values_of=evaluate_values_of,
                               return_as_dictionary=True, **kwargs)
        values = [(k, v) for k, v in out.items() if v is not None]
        G = out.get("G")
        H = out.get("H")
        cv = None
        if G is not None and G.ndim == 2 and (H is None or H.size == 0) and \
                len(pop) and pop[0].config == Individual.default_config():
            cv = np.maximum(0.0, G - 0.0).sum(axis=1)
        keys = out.keys()
        attrs = [(k, v, hasattr(Individual, k)) for k, v in values]
        for i, ind in enumerate(pop):
            for k, v, attr in attrs:  # Individual.set: an attribute, else a data entry
                row = v[i]
                row = row.copy() if isinstance(row, np.ndarray) else row
                if attr:
                    setattr(ind, k, row)
                else:
                    ind.data[k] = row
            if cv is not None:
                ind.CV = np.array([cv[i] + 0.0])
            ind.evaluated.update(keys)


def binary_tournament(pop, P, algorithm, **kwargs):
    """NSGA-II's binary tournament (pymoo's ``binary_tournament``, the same comparisons
    and the same random draws for ties) on arrays of the population's values."""
    n_tournaments, n_parents = P.shape
    if n_parents != 2:
        raise ValueError("Only implemented for binary tournament!")
    if algorithm.tournament_type != "comp_by_dom_and_crowding":
        return _pymoo_binary_tournament(pop, P, algorithm, **kwargs)
    rng = algorithm.random_state
    cv = _violations(pop).tolist()
    F = np.array([ind.F for ind in pop]).tolist()
    data = [ind.data for ind in pop]
    S = np.full(n_tournaments, np.nan)
    for i, (a, b) in enumerate(P.tolist()):
        a_cv, b_cv = cv[a], cv[b]
        if a_cv > 0.0 or b_cv > 0.0:
            S[i] = a if a_cv < b_cv else b if a_cv > b_cv else rng.choice([a, b])
            continue
        rel = _relation(F[a], F[b])
        if rel == 1:
            S[i] = a
        elif rel == -1:
            S[i] = b
        else:
            cd_a, cd_b = data[a].get("crowding"), data[b].get("crowding")
            S[i] = a if cd_a > cd_b else b if cd_a < cd_b else rng.choice([a, b])
    return S[:, None].astype(int, copy=False)


def _relation(a, b) -> int:
    """pymoo's Dominator.get_relation of two objective vectors (no violations)."""
    val = 0
    for x, y in zip(a, b, strict=True):
        if x < y:
            if val == -1:
                return 0
            val = 1
        elif y < x:
            if val == 1:
                return 0
            val = -1
    return val


class SubsetNSGA2(NSGA2):
    """pymoo's NSGA-II whose optimum (the first front) is found without
    Population.get."""

    def _set_optimum(self, **kwargs):
        if not np.any(_violations(self.pop) <= 0.0):
            return super()._set_optimum(**kwargs)
        rank = np.array([ind.data.get("rank") for ind in self.pop])
        self.opt = self.pop[rank == 0]


class FeasibleRankAndCrowding(Survival):
    """NSGA-II's survival (pymoo's rank and crowding distance) for a population that is
    feasible by construction (:class:`SizeRepair` keeps every mask within the size limits):
    the per-generation split into feasible and infeasible individuals, which costs as much
    as the sorting itself, is skipped while every constraint holds (pymoo's own survival
    serves otherwise), and rank and crowding are stored in one call per attribute."""

    def __init__(self):
        super().__init__(filter_infeasible=False)

        self._general = RankAndCrowding()

        self._nds = NonDominatedSorting()
        self._crowding = get_crowding_function("cd")

    def do(self, problem, pop, *args, n_survive=None, random_state=None,
           return_indices=False, **kwargs):
        if return_indices or (len(pop) and np.any(_violations(pop) > 0)):
            return self._general.do(problem, pop, *args, n_survive=n_survive,
                                    random_state=random_state, return_indices=return_indices,
                                    **kwargs)
        if len(pop) == 0:
            return pop
        n_survive = len(pop) if n_survive is None else min(n_survive, len(pop))
        return self._do(problem, pop, n_survive=n_survive, random_state=random_state)

    def _do(self, problem, pop, *args, random_state=None, n_survive=None, **kwargs):

        F = np.array([ind.F for ind in pop]).astype(float, copy=False)
        fronts = self._nds.do(F, n_stop_if_ranked=n_survive)
        survivors = []
        ranks = np.zeros(len(pop), int)
        crowd = np.zeros(len(pop))
        for k, front in enumerate(fronts):
            keep = np.arange(len(front))
            if len(survivors) + len(front) > n_survive:
                n_remove = len(survivors) + len(front) - n_survive
                distance = self._crowding.do(F[front, :], n_remove=n_remove)
                keep = randomized_argsort(distance, order="descending", method="numpy",
                                          random_state=random_state)[:-n_remove]
            else:
                distance = self._crowding.do(F[front, :], n_remove=0)
            ranks[front] = k
            crowd[front] = distance
            survivors.extend(np.asarray(front)[keep])
        survivors = np.asarray(survivors, int)
        out = pop[survivors]
        for ind, r, c in zip(out, ranks[survivors], crowd[survivors], strict=True):
            ind.data["rank"] = r  # Individual.set of a key that is not an attribute
            ind.data["crowding"] = c
        return out


# ----------------------------------------------------------------------------- operators
class BatchedCrossover(Crossover):
    """A crossover whose ``do`` gathers the parents' masks in one pass."""

    def do(self, problem, pop, parents=None, *args, random_state=None, **kwargs):
        """pymoo's Crossover.do (the same random draws, the same offspring) with the
        parents' masks gathered in one pass instead of per individual."""
        if random_state is None or self.vtype is not None:
            return super().do(problem, pop, parents, *args, **kwargs)
        if parents is not None:
            pop = [pop[mating] for mating in parents]
        # (parents, matings, n)
        X = np.swapaxes(np.array([[parent.X for parent in mating] for mating in pop]), 0, 1)
        n_matings = X.shape[1]
        prob = get(self.prob, size=n_matings)
        cross = random_state.random(n_matings) < prob
        Xp = np.empty((self.n_offsprings, n_matings, X.shape[2]), dtype=X.dtype)
        if np.any(cross):
            Q = self._do(problem, X, *args, random_state=random_state, **kwargs)
            Xp[:, cross] = Q[:, cross]
        Xp[:, ~cross] = X[:, ~cross]  # two parents, two offspring: the parents themselves
        return _new_population(Xp.reshape(-1, X.shape[-1]))


class BatchedMutation(Mutation):
    """A mutation whose ``do`` sets the masks without Population.get and set."""

    def do(self, problem, pop, inplace=True, *args, random_state=None, **kwargs):
        """pymoo's Mutation.do (the same draws, the same masks set) without its
        per-individual Population.get and set."""
        if not inplace or random_state is None:
            return super().do(problem, pop, inplace, *args, random_state=random_state,
                              **kwargs)
        n_mut = len(pop)
        Xp = self._do(problem, masks_of(pop), *args, random_state=random_state, **kwargs)
        mut = random_state.random(size=n_mut) <= get(self.prob, size=n_mut)
        for i in np.flatnonzero(mut):
            pop[i].X = Xp[i].copy()
        return pop


class BatchedRepair(Repair):
    """A repair whose ``do`` sets the masks without Population.set's look-ups."""

    def do(self, problem, pop, **kwargs):
        """pymoo's Repair.do without Population.set's per-individual look-ups."""
        if not isinstance(pop, Population) or self.vtype is not None:
            return super().do(problem, pop, **kwargs)
        Xp = self._do(problem, masks_of(pop), **kwargs)
        for ind, row in zip(pop, Xp, strict=True):
            ind.X = row.copy()
        return pop
