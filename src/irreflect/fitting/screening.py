"""Screening (numpy): the model's shape space sampled (:func:`screen_samples`), every
candidate scored by its projected cost, diverse low-cost candidates kept, and the global
scans through the best point of a refinement round. The compiled side:
:mod:`.fast_kernel` (the two-lobe model) and :mod:`.local_kernel` (``_costs``).
"""

from __future__ import annotations

import numpy as np

from ..models.base import share_factor
from . import draws as _draws_mod
from .cache import per_model
from .linear import _linear_step

_SCREEN_CACHE: dict = {}
#: Default number of screening candidates by number of nonlinear coordinates: a full grid
#: for one or two coordinates (the search is then exhaustive at the grid's resolution),
#: a Latin hypercube beyond, 100 candidates per coordinate from 4 on (models with
#: exchangeable lobes, n-lobe and Lafortune, have many equivalent basins). A model may set
#: its own ``hints.n_screen`` and ``hints.n_keep``.
DEFAULT_SCREEN = {0: 0, 1: 96, 2: 400, 3: 300}


def default_screen(model) -> int:
    if model.hints.n_screen is not None:
        return int(model.hints.n_screen)
    return DEFAULT_SCREEN.get(model.n_nonlinear, 100 * model.n_nonlinear)


def _default_hops(model, n_keep: int) -> int:
    """Basin hops per refinement round: ``n_keep`` for models of 4 or more coordinates
    (exchangeable lobes), unless the model sets ``hints.n_hops``."""
    if model.hints.n_hops is not None:
        return int(model.hints.n_hops)
    return n_keep if model.n_nonlinear >= 4 else 0


def default_keep(model) -> int:
    """Levenberg-Marquardt starts from the screening: 3, or one per coordinate from 4 on."""
    if model.hints.n_keep is not None:
        return int(model.hints.n_keep)
    return max(3, model.n_nonlinear if model.n_nonlinear >= 4 else 3)


def screen_samples(model, n: int, seed: int) -> np.ndarray:
    """``n`` screening points in the model's screening box (deterministic per seed).

    One or two nonlinear coordinates: a regular grid (``n`` points, or ``ceil(sqrt(n))``
    per axis), which no narrow optimum can slip through. More: a Latin hypercube, every
    coordinate's range cut into ``n`` strata each sampled once (McKay, Beckman and
    Conover 1979), drawn from the counter-based generator of :mod:`irreflect.fitting.draws` (the
    compiled kernel draws the same points). Plain numpy on purpose: ``scipy.stats.qmc``
    would cost every command a second of import time for the same coverage of the box.
    """
    key = (model.name, model.n_nonlinear, n, seed, _screen_box_key(model))
    if key not in _SCREEN_CACHE:
        lo, hi = model.screen_box()
        p = lo.size
        if p == 0 or n == 0:
            out = np.empty((0, p))
        elif p == 1:
            out = np.linspace(lo, hi, n)
        elif p == 2:
            k = int(np.ceil(np.sqrt(n)))
            a, b = np.meshgrid(np.linspace(lo[0], hi[0], k), np.linspace(lo[1], hi[1], k))
            out = np.column_stack([a.ravel(), b.ravel()])
        else:
            out = _draws_mod.latin_hypercube(_draws_mod.seed_key(seed), n, lo, hi)
        if len(_SCREEN_CACHE) >= 256:  # bounded: one entry per seed a process has used
            _SCREEN_CACHE.pop(next(iter(_SCREEN_CACHE)))
        _SCREEN_CACHE[key] = out
    return _SCREEN_CACHE[key]


def _screen_box_key(model) -> tuple:
    """The screening box as a hashable tuple (kept on the model object: it is asked on
    every fit)."""
    return per_model(model, "screen_box_key",
                     lambda: tuple(np.concatenate(model.screen_box()).tolist()))


#: Values (candidates x points x basis columns) of one screening piece of the numpy path:
#: about 30 MB per array, so that screening many candidates on a 200,000-point table stays
#: within a bounded memory (the pieces give the same costs as one batch).
SCREEN_PIECE_VALUES = 4_000_000


def _screen_costs(model, geom, z, sw, yw):
    """Variable-projection cost of every candidate ``z`` (no derivatives): a cheap global look.
    Scored in pieces of at most :data:`SCREEN_PIECE_VALUES` basis values."""
    z = np.asarray(z, float)
    m = z.shape[0]
    n = yw.shape[-1]
    step = max(1, SCREEN_PIECE_VALUES // max(1, n * max(model.n_linear, 1)))
    if m <= step:
        return _screen_piece(model, geom, z, sw, yw)

    def rows(a, lo, hi):
        return a[lo:hi] if a.shape[0] == m else a

    return np.concatenate([
        _screen_piece(model, geom.take(slice(lo, lo + step)), z[lo:lo + step],
                      rows(sw, lo, lo + step), rows(yw, lo, lo + step))
        for lo in range(0, m, step)])


def _screen_piece(model, geom, z, sw, yw):
    with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):
        basis, _ = model.basis(geom, z, False)
    return _projected_cost(model, basis, sw, yw,
                           share_factor(z, geom) if model.share_cap else None)


def _projected_cost(model, basis, sw, yw, factor=None):
    """Cost after eliminating the linear coefficients, for basis values ``(M, n, L)``
    (``factor``: the share's ``cos^v_as(gamma)`` per point when it saturates)."""
    with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):
        return _linear_step(model, basis, sw, yw, factor)["cost"]


def _diverse_best(z, cost, k, lo, hi, min_distance=0.08):
    """Indices of up to ``k`` low-cost candidates that are apart from each other (distance
    in the screening box scaled to the unit cube): starts in different basins."""
    width = np.where(hi > lo, hi - lo, 1.0)
    unit = (z - lo) / width
    chosen: list[int] = []
    for i in np.argsort(cost, kind="stable"):
        if not np.isfinite(cost[i]):
            break
        if all(np.sqrt(np.mean((unit[i] - unit[j]) ** 2)) >= min_distance for j in chosen):
            chosen.append(int(i))
            if len(chosen) == k:
                break
    return np.array(chosen, int)


def _scan_axes(model, n: int) -> list[np.ndarray]:
    """For every nonlinear coordinate, ``n`` values spanning its screening box and its
    bounds (within +-15): the values a global scan tries."""
    lo, hi = model.screen_box()
    zl = np.maximum(model.z_lower, -15.0)
    zu = np.minimum(model.z_upper, 15.0)
    return [np.linspace(min(lo[j], zl[j]), max(hi[j], zu[j]), n) for j in range(lo.size)]


def _scan_blocks(model, n1: int = 33, n2: int = 17) -> list[tuple[np.ndarray, np.ndarray]]:
    """The global scans of a refinement round: ``(coordinates, values (m, len))`` per block.

    A model declares which coordinates belong together in ``hints.groups`` (a lobe's
    axis and index, a lobe's ``ln u`` and ``v``): pairs are scanned on a ``n2 x n2`` grid,
    other coordinates one at a time on ``n1`` values (the default: every coordinate
    alone)."""
    groups = model.hints.groups or tuple((j,) for j in range(model.n_nonlinear))
    axes_1, axes_2 = _scan_axes(model, n1), _scan_axes(model, n2)
    blocks = []
    for group in groups:
        idx = np.asarray(group, int)
        if idx.size == 2:
            a, b = np.meshgrid(axes_2[idx[0]], axes_2[idx[1]])
            blocks.append((idx, np.column_stack([a.ravel(), b.ravel()])))
        else:
            blocks += [(np.array([j]), axes_1[j][:, None]) for j in idx]
    return blocks


def _block_candidates(z_best, blocks) -> np.ndarray:
    """Rows of ``z_best`` with each block's coordinates replaced by its scan values."""
    rows = []
    for idx, values in blocks:
        cand = np.repeat(z_best[None], len(values), axis=0)
        cand[:, idx] = values
        rows.append(cand)
    return np.vstack(rows)


def _coordinate_scan(model, geom, z_best, cost_best, sw1, yw1):
    """Global scans through the best point, one block of coordinates at a time.

    A narrow lobe makes the cost multi-modal along its index (and a tilt along the tilt),
    and lobes that can swap roles make it multi-modal along their axes: a local optimiser
    stops in whichever basin it started. Every block (:func:`_scan_blocks`) is swept
    over its whole range with the other coordinates held; each sweep's minimum that beats
    the current cost is returned as a new start (empty when none does: the point is then
    optimal along every block at the sweep's resolution)."""
    blocks = _scan_blocks(model)
    cand = _block_candidates(z_best, blocks)
    cost = _screen_costs(model, geom, cand, sw1, np.broadcast_to(yw1, (len(cand), yw1.shape[1])))
    out, start = [], 0
    for _, values in blocks:
        part = cost[start:start + len(values)]
        j = int(np.argmin(part))
        if part[j] < cost_best * (1.0 - 1e-9):
            out.append(cand[start + j])
        start += len(values)
    return np.array(out).reshape(-1, z_best.size), len(cand)


def _search_defaults(model_obj, n_screen, n_keep, n_data_starts) -> tuple[int, int, int]:
    """The screening candidates, the screened starts kept and the data-driven starts of a
    search: the caller's, else the model's defaults."""
    return (default_screen(model_obj) if n_screen is None else int(n_screen),
            default_keep(model_obj) if n_keep is None else int(n_keep),
            int(model_obj.hints.n_data_starts) if n_data_starts is None
            else int(n_data_starts))
