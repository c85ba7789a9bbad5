"""The named structures the compiled kernels take and return (plain namedtuples, which
numba compiles as records): a kernel call passes a few of these instead of dozens of
positional arrays. Built on the numpy side without importing numba. Across the call
from Python they travel as plain tuples (``tuple(km)``), which numba's dispatcher types
in C; an entry point names them again first (``km = KModel(*km)``).

KModel     what the kernel needs of a model (built once per model: engine._kernel_static)
KTable     one table's geometry as the kernel stores it (model_kernel.kernel_geometry)
Work       one search's table, points by angle of incidence and scratch (search_kernel.prepare)
Solution   the best point of a batch of local searches (search_kernel.solve)
FastWork   the two-lobe fast path's scratch (fast_kernel.tl_work)
Finish     a fit's finish (finish_kernel.tl_finish)
"""

from __future__ import annotations

from collections import namedtuple

KModel = namedtuple("KModel", ["codes", "nonneg", "residual", "lo", "hi", "zlo", "zhi", "axes",
                               "ext_rows", "nd_grid", "ns_grid"])
KTable = namedtuple("KTable", ["geo", "glcg", "levels", "group", "exact"])
Work = namedtuple("Work", ["table", "power", "pts", "gstart", "lgroup", "ws"])
Solution = namedtuple("Solution", ["z", "alpha", "cost", "reason", "nfev"])
SubsetSolution = namedtuple("SubsetSolution", ["z", "alpha", "cost", "converged", "nfev"])
FastWork = namedtuple("FastWork", ["vec", "lin", "coef", "grad", "hess", "a", "rhs", "step",
                                   "z", "zt", "pinned", "gbuf", "cap"])
CapWork = namedtuple("CapWork", ["sums", "tau", "order", "lin", "s_g"])
GenState = namedtuple("GenState", ["bw", "dbw", "alpha_j", "free", "inv", "resid", "alpha",
                                   "level"])
GenScratch = namedtuple("GenScratch", ["b", "db", "bp", "dbp", "gval", "sums", "capped"])
CappedWork = namedtuple("CappedWork", ["g", "r", "gt", "rt", "alpha", "free", "inv", "scale",
                                       "order", "tau"])
KGeo = namedtuple("KGeo", ["gamma", "theta", "lcg", "lct", "pt", "lcp", "pp", "group"])
Finish = namedtuple("Finish", ["values", "round_trip", "fitted", "r2", "rmse", "mse",
                               "covariance", "singular"])
