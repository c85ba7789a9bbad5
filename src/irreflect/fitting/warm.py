"""Compile the fitter's kernels once (or load them from numba's on-disk cache)."""

from __future__ import annotations

import warnings

import numpy as np

from ..data import Measurements
from ..errors import FitWarning
from ..models import two_lobe_power
from ..models.registry import extend
from .api import fit
from .subsets import fit_subsets


def warm() -> None:
    """Compile (or load from the on-disk cache) every entry point once: a fit, a batch of
    subset fits and an extended model's fit of a small generated table. ``make`` runs it
    after installing so that test workers and commands find the cache warm."""
    g = np.repeat([-20.0, -40.0, -60.0], 9)
    t = np.tile(np.linspace(-60.0, 80.0, 9), 3)
    p = two_lobe_power(np.radians(g), np.radians(t), 0.05, -1.0, 1.0, 0.4, 80.0, 0.2, 1.0)
    meas = Measurements(g, t, p * (1.0 + 0.01 * np.sin(np.arange(p.size))))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        fit(meas, engine="compiled")
        fit(meas, extend("two-lobe", ["background"]), engine="compiled")
        masks = np.ones((2, p.size), bool)
        masks[0, ::2] = False
        fit_subsets(g, t, p, masks, engine="compiled")
