"""The global search, written once: :func:`run_search`.

It calls the search's steps by name, as module-level functions of a context ``ctx``::

    candidates(ctx)                  -> (rows, n_own): the own starts, then the screening
    score(ctx, rows)                 -> the projected cost of every row
    pick(ctx, rows, costs, k, d)     -> up to k low-cost rows at least d apart (unit box)
    solve(ctx, starts)               -> Solution: Levenberg-Marquardt from every start, the
                                        best end point and the evaluations of all
    scan(ctx, z)                     -> (each scan block's lowest point, its cost, points
                                        scanned) through z
    hops(ctx, round, z)              -> the round's basin hops around z
    clip(ctx, rows)                  -> rows within the model's bounds

Each backend binds this very code to its own steps (``types.FunctionType(run_search.
__code__, its globals)``): :mod:`.search` to the numpy steps (run in Python), and
:mod:`.search_kernel` to the compiled ones (compiled by numba, the whole search one call).
So the search's logic (which candidates start, the rounds, the stopping rules) exists
once; a backend only implements the steps. The code is in the subset of Python that
numba compiles.
"""

from __future__ import annotations

import math

import numpy as np


def run_search(ctx, n_data_starts, n_keep, max_rounds):
    """The global search: (1) the own starts (the caller's, the model's data-driven ones,
    seeded perturbations) and the screening candidates, each scored by its projected
    cost; (2) Levenberg-Marquardt from the ``n_data_starts`` best own starts and the
    ``n_keep`` best candidates in different basins; (3) refinement rounds: the scans
    through the best point and seeded jumps around it (basin hopping, Wales and Doye
    1997), Levenberg-Marquardt from every scan point that beats it and every jump, until a
    round improves nothing (at most ``max_rounds``). Returns (the best Solution, starts,
    evaluations); its cost is inf when no start reaches a finite one."""
    cands, n_own = candidates(ctx)  # noqa: F821 (bound by each backend)
    costs = score(ctx, cands)  # noqa: F821
    first = pick(ctx, cands[:n_own], costs[:n_own], n_data_starts, 1e-9)  # noqa: F821
    others = pick(ctx, cands, costs, n_keep, 0.08)  # noqa: F821
    picks = np.unique(np.concatenate((first, others)))
    if picks.size == 0:
        picks = np.zeros(1, np.int64)
    best = solve(ctx, cands[picks])  # noqa: F821
    n_starts = picks.size
    n_evals = cands.shape[0] + best.nfev
    if not math.isfinite(best.cost):
        return best, n_starts, n_evals
    for rnd in range(max_rounds if cands.shape[1] else 0):
        rows, row_costs, scanned = scan(ctx, best.z)  # noqa: F821
        n_evals += scanned
        better = rows[row_costs < best.cost * (1.0 - 1e-9)]
        extra = clip(ctx, np.vstack((better, hops(ctx, rnd, best.z))))  # noqa: F821
        if extra.shape[0] == 0:
            break
        found = solve(ctx, extra)  # noqa: F821
        n_starts += extra.shape[0]
        n_evals += found.nfev
        if not found.cost < best.cost * (1.0 - 1e-12):
            break
        best = found
    return best, n_starts, n_evals


def bind(steps: dict):
    """:func:`run_search` calling ``steps`` (name -> function) as its steps (plus
    whatever else the given namespace holds), as a new function."""
    import types

    namespace = {"np": np, "math": math, **steps}
    return types.FunctionType(run_search.__code__, namespace, "run_search")
