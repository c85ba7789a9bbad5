"""The global search of one table, written once (:func:`run_search`) over a backend that
implements its few steps: numpy (:class:`NumpyBackend`, every model) or the compiled kernel
(:class:`KernelBackend`, the two-lobe model and its extensions; :mod:`.search_kernel`).

The search: (1) the caller's starts, the model's data-driven ones and seeded random
perturbations of them, and a screening of the model's shape space (:mod:`.screening`);
every candidate scored by its projected cost; (2) Levenberg-Marquardt from the best
data-driven starts and the best candidates in different basins; (3) refinement rounds:
global scans through the best point, one block of coordinates at a time, and seeded
jumps around it (basin hopping, Wales and Doye 1997), Levenberg-Marquardt from every
point that beats it, until a round improves nothing.

A backend offers:

``candidates()``            the own starts and the screening candidates, ``(rows, n_own)``
``score(rows)``             the projected cost of every row
``pick(rows, costs, k, d)`` up to ``k`` low-cost rows at least ``d`` apart (unit box)
``solve(starts)``           Levenberg-Marquardt from every start: the best end point
                            (:class:`~irreflect.fitting.kernel_types.Solution`)
``scan(z)``                 the scan candidates through ``z``, their costs and blocks
``hops(round, z)``          the basin hops of a round around ``z``
``clip(rows)``              rows within the model's bounds
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import NamedTuple

import numpy as np

from ..models import Geometry
from . import draws as _draws_mod
from .engine import _kernel_codes, _kernel_geometry, _kernel_static, _w
from .finish import _conclude
from .kernel_types import Solution
from .local import _levenberg_marquardt
from .options import FitOptions
from .screening import (
    _block_candidates,
    _default_hops,
    _diverse_best,
    _scan_blocks,
    _screen_costs,
    _search_defaults,
    screen_samples,
)
from .starts import _candidates, _draws


class Found(NamedTuple):
    """The best point of a search: shape coordinates, linear coefficients, cost, why its
    local search stopped, how many starts and evaluations the search spent."""

    z: np.ndarray
    alpha: np.ndarray
    cost: float
    reason: int
    n_starts: int
    n_evals: int


def run_search(backend, n_data_starts: int, n_keep: int, max_rounds: int) -> Found | None:
    """The global search over ``backend`` (see the module docstring); None when no start
    reaches a finite cost."""
    cands, n_own = backend.candidates()
    costs = backend.score(cands)
    first = backend.pick(cands[:n_own], costs[:n_own], n_data_starts, 1e-9)
    others = backend.pick(cands, costs, n_keep, 0.08)
    picks = np.unique(np.concatenate([first, others]))
    if not picks.size:
        picks = np.zeros(1, np.int64)
    best = backend.solve(cands[picks])
    n_starts, n_evals = picks.size, len(cands) + best.nfev
    if not math.isfinite(best.cost):
        return None
    for rnd in range(max_rounds if backend.n_nonlinear else 0):
        scan, scan_costs, blocks = backend.scan(best.z)
        n_evals += len(scan)
        rows = [scan[a + int(np.argmin(scan_costs[a:b]))] for a, b in blocks
                if np.min(scan_costs[a:b]) < best.cost * (1.0 - 1e-9)]
        extra = backend.clip(np.vstack([np.reshape(rows, (-1, backend.n_nonlinear)),
                                        backend.hops(rnd, best.z)]))
        if not len(extra):
            break
        found = backend.solve(extra)
        n_starts += len(extra)
        n_evals += found.nfev
        if not found.cost < best.cost * (1.0 - 1e-12):
            break
        best = found
    return Found(best.z, best.alpha, float(best.cost), int(best.reason), int(n_starts),
                 int(n_evals))


class NumpyBackend:
    """The search's steps in numpy, batched over candidates (every model)."""

    def __init__(self, model, table, opts: FitOptions, n_hops: int):
        gamma, theta, power, weights = table
        self.model, self.opts, self.table = model, opts, table
        self.n_nonlinear = model.n_nonlinear
        self.lo, self.hi = model.screen_box()
        self.geom = Geometry.of(gamma[None], theta[None])
        self.sw1 = np.sqrt(weights)[None]
        self.yw1 = self.sw1 * power
        rounds = opts.max_rounds if model.n_nonlinear else 0
        self.jumps = _draws(opts.seed, 0, n_hops, rounds, model.n_nonlinear)[1]

    def candidates(self):
        gamma, theta, power, _ = self.table
        m, o = self.model, self.opts
        own = _candidates(m, gamma, theta, power, o.seed, o.n_random_starts, o.extra_starts)
        if not (o.n_screen and m.n_nonlinear):
            return own, len(own)
        return np.vstack([own, self.clip(screen_samples(m, o.n_screen, o.seed))]), len(own)

    def score(self, rows):
        return _screen_costs(self.model, self.geom, rows, self.sw1,
                             np.broadcast_to(self.yw1, (len(rows), self.yw1.shape[1])))

    def pick(self, rows, costs, k, min_distance):
        return _diverse_best(rows, costs, k, self.lo, self.hi, min_distance)

    def solve(self, starts):
        shape = (len(starts), self.sw1.shape[1])
        z, state, nfev, reason = _levenberg_marquardt(
            self.model, self.geom, starts, np.broadcast_to(self.sw1, shape),
            np.broadcast_to(self.yw1, shape), max_iter=self.opts.max_iter)
        j = int(np.argmin(state["cost"]))
        return Solution(z[j], state["alpha"][j], float(state["cost"][j]), int(reason[j]),
                        int(nfev.sum()))

    def scan(self, z):
        blocks = _scan_blocks(self.model)
        rows = _block_candidates(z, blocks)
        ends = np.cumsum([0] + [len(values) for _, values in blocks])
        return rows, self.score(rows), list(zip(ends[:-1], ends[1:], strict=True))

    def hops(self, rnd, z):
        return z + self.jumps[rnd] * np.where(self.hi > self.lo, self.hi - self.lo, 1.0)

    def clip(self, rows):
        return np.clip(rows, self.model.z_lower, self.model.z_upper)


@functools.lru_cache(maxsize=64)
def _kernel_draws(seed, n_random: int, n_hops: int, rounds: int, p: int):
    """The compiled backend's random draws (:mod:`.draws_kernel`, the numbers the kernel
    draws from the seed's key): the jitter of the first start and the basin hops of every
    round, times 0.15 (the caller scales them)."""
    from .draws_kernel import STREAM_HOPS, STREAM_JITTER, draw_normals

    key = _draws_mod.seed_key(seed)
    jitter = (0.15 * draw_normals(key, STREAM_JITTER, n_random * p)).reshape(n_random, p)
    hops = (0.15 * draw_normals(key, STREAM_HOPS, rounds * n_hops * p)).reshape(
        rounds, n_hops, p)
    jitter.flags.writeable = False
    hops.flags.writeable = False
    return jitter, hops


class KernelBackend:
    """The search's steps in the compiled kernel (:mod:`.search_kernel`), one call each."""

    def __init__(self, model, kt, table, opts: FitOptions, n_hops: int):
        from . import search_kernel, starts_kernel

        self.kernel, self.diverse = search_kernel, starts_kernel._diverse
        _, _, power, weights = table
        static = _kernel_static(model)
        self.km = km = static.k
        self.n_nonlinear = p = model.n_nonlinear
        self.model, self.opts, self.kt = model, opts, kt
        self.power, self.weights = _w(power), _w(weights)
        jitter, self.jumps = _kernel_draws(opts.seed, opts.n_random_starts, n_hops,
                                           opts.max_rounds, p)
        self.jitter = jitter * static.jitter_width
        self.width = np.where(km.hi > km.lo, km.hi - km.lo, 1.0)
        self.stop = (int(opts.max_iter), 1e-10, 1e-9)
        self.work = None

    def candidates(self):
        o, km = self.opts, self.km
        extra = (np.zeros((0, self.n_nonlinear)) if o.extra_starts is None else
                 self.clip(np.asarray(o.extra_starts, float).reshape(-1, self.n_nonlinear)))
        self.work, own = self.kernel.prepare(km, self.kt, self.power, self.weights,
                                             _w(self.jitter), _w(extra))
        screen = (screen_samples(self.model, o.n_screen, o.seed) if o.n_screen
                  else np.zeros((0, self.n_nonlinear)))
        return np.vstack([own, self.clip(screen)]), len(own)

    def score(self, rows):
        return self.kernel.score(self.km, self.work, _w(rows))

    def pick(self, rows, costs, k, min_distance):
        return self.diverse(_w(rows), costs, k, self.km.lo, self.km.hi, min_distance)

    def solve(self, starts):
        return self.kernel.solve(self.km, self.work, _w(starts), self.stop)

    def scan(self, z):
        rows, costs = self.kernel.scan(self.km, self.work, _w(z))
        n_axis = self.km.axes.shape[1]
        return rows, costs, [(q * n_axis, (q + 1) * n_axis) for q in range(self.n_nonlinear)]

    def hops(self, rnd, z):
        return z + self.jumps[rnd] * self.width

    def clip(self, rows):
        return np.clip(rows, self.km.zlo, self.km.zhi)


def global_search(model_obj, table, opts: FitOptions, kgeo=None):
    """The global search of :func:`fit` on one table ``(gamma, theta, power, weights)``
    (radians), finished (:func:`~irreflect.fitting.finish._conclude`): returns ``(z,
    alpha, cost, converged, message, n_starts, n_evals)``, or None when no start reaches
    a finite cost. ``opts``: sized (:meth:`FitOptions.sized_for`); ``kgeo``: the table's
    kernel geometry when the compiled kernel fits the model.

    The power is divided by its weighted root mean square first (and the linear
    coefficients and the cost scaled back), so that the search sees the same numbers
    whatever the unit of power: the shape coefficients do not depend on it."""
    gamma, theta, power, weights = table
    power = np.asarray(power, float)
    scale = float(np.sqrt(np.mean(weights * power * power)))
    if not (np.isfinite(scale) and scale > 0):
        scale = 1.0
    unit = (gamma, theta, power / scale, weights)
    n_screen, n_keep, n_data_starts = _search_defaults(model_obj, opts.n_screen, opts.n_keep,
                                                       opts.n_data_starts)
    n_hops = _default_hops(model_obj, n_keep) if opts.n_hops is None else int(opts.n_hops)
    opts_n = dataclasses.replace(opts, n_screen=n_screen)
    codes = _kernel_codes(model_obj, opts.engine)
    if codes is not None and kgeo is None:
        kgeo = _kernel_geometry(gamma, theta)
    if codes is None:
        backend = NumpyBackend(model_obj, unit, opts_n, n_hops)
    else:
        backend = KernelBackend(model_obj, kgeo, unit, opts_n, n_hops)
    found = run_search(backend, n_data_starts, n_keep, opts.max_rounds)
    if found is None:
        return None
    z, alpha, cost, *rest = _conclude(model_obj, *unit, found, opts.polish, opts.max_iter)
    return (z, alpha * scale, cost * scale * scale, *rest)
