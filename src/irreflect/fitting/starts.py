"""Starts (numpy): the model's data-driven starts, the caller's, and seeded perturbations of
them; the search's random draws; the extensions' starting rows. The compiled side:
:mod:`.starts_kernel`.
"""

from __future__ import annotations

import functools

import numpy as np

from ..models import (
    PROFILE_DIFFUSE_INDICES,
    PROFILE_SPECULAR_INDICES,
)
from ..models.extensions import Extension
from . import draws as _draws_mod


def _candidates(model, gamma_rad, theta_rad, power, seed, n_random, extra=None):
    """The caller's extra starts, data-driven starts, and seeded random perturbations of
    the first row."""
    starts = np.atleast_2d(np.asarray(model.starts(gamma_rad, theta_rad, power), float))
    starts = starts.reshape(-1, model.n_nonlinear)
    if extra is not None and len(extra):
        starts = np.vstack([np.asarray(extra, float).reshape(-1, model.n_nonlinear), starts])
    parts = [starts]
    if n_random and len(starts):
        width = model.z_upper - model.z_lower
        jitter, _ = _draws(seed, n_random, 0, 0, starts.shape[1])
        parts.append(starts[0] + jitter * np.minimum(width, 10.0))
    out = np.clip(np.vstack(parts), model.z_lower, model.z_upper)
    return np.unique(out, axis=0) if len(out) else out


@functools.lru_cache(maxsize=64)
def _draws(seed, n_random: int, n_hops: int, rounds: int, p: int):
    """The random draws of one search (:mod:`irreflect.fitting.draws`; the kernel's tl_fit draws
    the same inside): normal jitter of the first start (times 0.15; the caller scales it)
    and the basin hops of every round (times 0.15; the caller scales them)."""
    key = _draws_mod.seed_key(seed)
    jitter = (0.15 * _draws_mod.normals(key, _draws_mod.STREAM_JITTER, n_random * p)
              ).reshape(n_random, p)
    hops = (0.15 * _draws_mod.normals(key, _draws_mod.STREAM_HOPS, rounds * n_hops * p)
            ).reshape(rounds, n_hops, p)
    jitter.flags.writeable = False
    hops.flags.writeable = False
    return jitter, hops


def _extension_start_rows(model) -> np.ndarray:
    """The starting values of the extensions' coordinates, as the extended models' own
    ``starts`` combine them (the first row with every extension's first value, then, one
    extension at a time, its other values): ``(rows, P - 5)``."""

    chain = []
    m = model
    while m.wrapped is not None:
        chain.append(m.extension)
        m = m.wrapped
    tails = [np.zeros(0)]
    for ext in reversed(chain):
        assert isinstance(ext, Extension)
        values = ext.start_rows()
        tails = ([np.concatenate([t, values[0]]) for t in tails]
                 + [np.concatenate([tails[0], v]) for v in values[1:]])
    return np.array(tails, float).reshape(len(tails), -1)


#: The index grids of the per-angle decomposition, writeable copies for the kernel.
_PROFILE_GRIDS = (PROFILE_DIFFUSE_INDICES.copy(), PROFILE_SPECULAR_INDICES.copy())
