"""The global search of one table: the driver (:func:`~.driver.run_search`, written once)
on numpy's steps (:class:`NumpyBackend`, every model) or compiled in the kernel with the
kernel's steps (:func:`~.search_kernel.search`, the two-lobe model and its extensions, a
search in one call); :func:`global_search` chooses, scales the power and finishes.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from ..models import Geometry
from . import draws as _draws_mod
from .cache import per_model
from .driver import bind
from .engine import _kernel_codes, _kernel_geometry, _kernel_static, _w
from .finish import _conclude
from .kernel_types import Solution
from .local import _STOP_MESSAGES, STOP_FTOL, STOP_XTOL, _levenberg_marquardt
from .options import FitOptions
from .results import _radians_and_weights
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


class NumpyBackend:
    """The search's steps in numpy, batched over candidates (every model)."""

    def __init__(self, model, table, opts: FitOptions, n_screen: int, n_hops: int):
        gamma, theta, power, weights = table
        self.model, self.opts, self.table, self.n_screen = model, opts, table, n_screen
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
        if not (self.n_screen and m.n_nonlinear):
            return own, len(own)
        return np.vstack([own, self.clip(screen_samples(m, self.n_screen, o.seed))]), len(own)

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
        costs = self.score(rows)
        ends = np.cumsum([0] + [len(values) for _, values in blocks])
        best = [a + int(np.argmin(costs[a:b])) for a, b in zip(ends[:-1], ends[1:], strict=True)]
        return rows[best].reshape(-1, self.n_nonlinear), costs[best], len(rows)

    def hops(self, rnd, z):
        return z + self.jumps[rnd] * np.where(self.hi > self.lo, self.hi - self.lo, 1.0)

    def clip(self, rows):
        return np.clip(rows, self.model.z_lower, self.model.z_upper)


#: The driver on numpy's steps: ``run_search_numpy(NumpyBackend(...), n_data_starts,
#: n_keep, max_rounds)``.
run_search_numpy = bind({name: getattr(NumpyBackend, name) for name in
                         ("candidates", "score", "pick", "solve", "scan", "hops", "clip")})


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


def _kernel_inputs(model, opts: FitOptions, n_screen: int, n_hops: int):
    """The compiled search's model, draws and stopping rule (see :mod:`.search_kernel`)."""
    static = _kernel_static(model)
    p = model.n_nonlinear
    jitter, jumps = _kernel_draws(opts.seed, opts.n_random_starts, n_hops, opts.max_rounds, p)
    extra = (np.zeros((0, p)) if opts.extra_starts is None else
             np.clip(np.asarray(opts.extra_starts, float).reshape(-1, p), model.z_lower,
                     model.z_upper))
    screen = per_model(model, ("clipped screen", n_screen, opts.seed), lambda: _w(np.clip(
        screen_samples(model, n_screen, opts.seed) if n_screen else np.zeros((0, p)),
        model.z_lower, model.z_upper)))
    draws = (_w(jitter * static.jitter_width), _w(extra), screen, _w(jumps), static.hop_width)
    return static.plain, draws, (int(opts.max_iter), 1e-10, 1e-9)


def _kernel_context(model, kt, table, opts: FitOptions, n_screen: int, n_hops: int):
    """The compiled search's context (see :mod:`.search_kernel`) for one table."""
    from .search_kernel import work_for

    _, _, power, weights = table
    plain, draws, stop = _kernel_inputs(model, opts, n_screen, n_hops)
    kt = (tuple(kt.geo), kt.glcg, kt.levels, kt.group, kt.exact)
    return (plain, kt, work_for(kt, _w(power), _w(weights)), draws, stop)


def global_search(model_obj, table, opts: FitOptions, kgeo=None):
    """The global search of :func:`fit` on one table ``(gamma, theta, power, weights)``
    (radians), finished (:func:`~irreflect.fitting.finish._conclude`): returns ``(z,
    alpha, cost, converged, message, n_starts, n_evals)``, or None when no start reaches
    a finite cost. ``opts``: sized (:meth:`FitOptions.sized_for`); ``kgeo``: the table's
    kernel geometry when the compiled kernel fits the model.

    The power is divided by its weighted root mean square first (and the linear
    coefficients and the cost scaled back), so that the search sees the same numbers
    whatever the unit of power: the shape coefficients do not depend on it."""
    return search_and_finish(model_obj, table, opts, kgeo)[0]


def search_and_finish(model_obj, table, opts: FitOptions, kgeo=None):
    """:func:`global_search`. Returns (the search's end as global_search returns it,
    None, the exact angles of incidence or None (the numpy engine)); the plain two-lobe
    model's fit in one compiled call is :func:`fit_plain_table`."""
    gamma, theta, power, weights = table
    power = np.asarray(power, float)
    scale = float(np.sqrt(np.mean(weights * power * power)))
    if not (np.isfinite(scale) and scale > 0):
        scale = 1.0
    unit = (gamma, theta, power / scale, weights)
    n_screen, n_keep, n_data_starts = _search_defaults(model_obj, opts.n_screen, opts.n_keep,
                                                       opts.n_data_starts)
    n_hops = _default_hops(model_obj, n_keep) if opts.n_hops is None else int(opts.n_hops)
    codes = _kernel_codes(model_obj, opts.engine)
    exact = None
    sizes = (int(n_data_starts), int(n_keep), int(opts.max_rounds))
    if codes is None:
        backend = NumpyBackend(model_obj, unit, opts, n_screen, n_hops)
        best, n_starts, n_evals = run_search_numpy(backend, *sizes)
    else:
        from .search_kernel import search

        kgeo = kgeo if kgeo is not None else _kernel_geometry(gamma, theta)
        exact = kgeo.exact
        ctx = _kernel_context(model_obj, kgeo, unit, opts, n_screen, n_hops)
        best, n_starts, n_evals = search(ctx, *sizes)
    if not math.isfinite(best.cost):
        return None, None, exact
    found = (best.z, best.alpha, float(best.cost), int(best.reason), int(n_starts),
             int(n_evals))
    z, alpha, cost, *rest = _conclude(model_obj, *unit, found, opts.polish, opts.max_iter)
    return (z, alpha * scale, cost * scale * scale, *rest), None, exact


_NO_SIGMA = np.zeros(0)


def _plain_inputs(model_obj, opts: FitOptions):
    """The compiled fit's model, draws and configuration (:func:`fit_plain_table`); the
    same for every fit with these options, kept per model unless there are extra starts
    (writeable arrays, as numba's cached signatures want them: the kernel only reads them,
    and repeated fits of one seed give the same numbers)."""
    def make():
        n_screen, n_keep, n_data_starts = _search_defaults(
            model_obj, opts.n_screen, opts.n_keep, opts.n_data_starts)
        n_hops = _default_hops(model_obj, n_keep) if opts.n_hops is None else int(opts.n_hops)
        model, draws, stop = _kernel_inputs(model_obj, opts, n_screen, n_hops)
        sizes = (int(n_data_starts), int(n_keep), int(opts.max_rounds))
        return model, draws, (sizes, stop, model_obj.n_params)

    if opts.extra_starts is not None:
        return make()
    key = ("plain inputs", opts.seed, opts.n_random_starts, opts.n_screen, opts.n_keep,
           opts.n_data_starts, opts.max_iter, opts.max_rounds, opts.n_hops)
    return per_model(model_obj, key, make)


@functools.lru_cache(maxsize=32)
def _message(reason: int, max_iter: int) -> str:
    return _STOP_MESSAGES[reason].format(ftol=1e-10, xtol=1e-9, max_iter=max_iter)


def fit_plain_table(model_obj, meas, sigma, opts: FitOptions):
    """:func:`search_and_finish` of the plain two-lobe model in one compiled call
    (:func:`~.search_kernel.fit_plain`: radians, weights, the power's scale, the geometry,
    the search and, when the search met its tolerance, the finish) from the table ``meas``
    as it is stored (``sigma``: the table's, None: unweighted; ``opts`` sized). Returns
    (the search's end as :func:`global_search` returns it, or None; ``(Finish, standard
    errors, residuals)`` of the kernel or None (fit() finishes a polished search); the exact
    angles of incidence)."""
    from .search_kernel import fit_plain

    model, draws, config = _plain_inputs(model_obj, opts)
    best, (n_starts, n_evals, scale), (done, fin, stderr, resid), exact = fit_plain(
        model, (_w(meas.gamma_deg), _w(meas.theta_deg), _w(meas.power),
                _NO_SIGMA if sigma is None else _w(sigma)), draws, config)
    if not math.isfinite(best.cost):
        return None, None, exact
    cost = float(best.cost)
    if done:  # _conclude's verdict on a search that met its tolerance
        reason = int(best.reason)
        return ((best.z, best.alpha * scale, cost * scale * scale,
                 reason in (STOP_FTOL, STOP_XTOL), _message(reason, opts.max_iter),
                 int(n_starts), int(n_evals)), (fin, stderr, resid), exact)
    gamma, theta, weights = _radians_and_weights(meas, sigma)
    found = (best.z, best.alpha, cost, int(best.reason), int(n_starts), int(n_evals))
    z, alpha, cost, *rest = _conclude(model_obj, gamma, theta, meas.power / scale, weights,
                                      found, opts.polish, opts.max_iter)
    return (z, alpha * scale, cost * scale * scale, *rest), None, exact
