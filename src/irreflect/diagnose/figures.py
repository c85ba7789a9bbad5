"""Moved to :mod:`irreflect.plots.diagnose` (shim until the cli/ merge: diagnose/command.py
imports these names from here, with the old residual-map defaults)."""
from functools import partial

from ..plots import NORMALIZED
from ..plots import plot_residual_map as _map
from ..plots.diagnose import plot_diagnosis_polar, plot_residual_maps  # noqa: F401

plot_residual_map = partial(_map, **NORMALIZED)
