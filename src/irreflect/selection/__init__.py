"""Which few measurements pin down a material's reflection model (the paper's section 4.3).

A multi-objective search over subsets of a dense goniometer scan: minimise the number of
points N and 1 - R^2 of the model fitted on those points only, evaluated on all points
(Fig. 18), pick the knee (in a fixed normalisation) and the noise-aware "enough points"
(:mod:`.front`), and compare Method A (all points), B (the search's best 12) and
12 (the paper's protocol, Table 1) as in Table 5.

>>> from irreflect.selection import run_selection
>>> res = run_selection(meas, pop_size=100, generations=200, seed=0)   # doctest: +SKIP
>>> res.front, res.knee_n, res.best_mask(12)                          # doctest: +SKIP
"""

from .design import choose_gamma_settings, design_protocol, tool_mask
from .front import EnoughPoints, enough_points, knee_coordinates
from .problem import SEARCH_FIT, VERIFY_FIT, FitSettings, SubsetEvaluator, SubsetProblem
from .run import (
    HV_REFERENCE,
    SelectionResult,
    compare_methods,
    hypervolume,
    knee_index,
    knee_point,
    non_dominated,
    paper_protocol_points,
    protocol_points_mask,
    run_selection,
    snap_points,
)
from .selectors import SELECTORS, get_selector

__all__ = [
    "choose_gamma_settings",
    "design_protocol",
    "tool_mask",
    "EnoughPoints",
    "enough_points",
    "knee_coordinates",
    "HV_REFERENCE",
    "SEARCH_FIT",
    "SELECTORS",
    "VERIFY_FIT",
    "FitSettings",
    "SelectionResult",
    "SubsetEvaluator",
    "SubsetProblem",
    "compare_methods",
    "get_selector",
    "hypervolume",
    "knee_index",
    "knee_point",
    "non_dominated",
    "paper_protocol_points",
    "protocol_points_mask",
    "run_selection",
    "snap_points",
]
