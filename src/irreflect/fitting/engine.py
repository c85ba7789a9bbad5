"""Which implementation fits a model (the compiled kernel or numpy) and what the kernel needs
of a model and a table.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ..errors import unknown_name
from .cache import per_model
from .kernel_types import KModel
from .screening import _scan_axes
from .starts import _PROFILE_GRIDS, _extension_start_rows


def _kernel_static(model_obj) -> KernelStatic:
    """What the kernel needs of a model that does not change between fits (computed once
    per model object, :mod:`.cache`)."""
    return per_model(model_obj, "kernel_static", lambda: _make_kernel_static(model_obj))


@dataclass(frozen=True)
class KernelStatic:
    """What the kernel needs of a model (``k``, a :class:`~.kernel_types.KModel`) and what
    the compiled backend needs besides: the jitter's width per coordinate, the natural
    parameters' bounds (for the result's checks)."""

    k: KModel
    jitter_width: np.ndarray

    @functools.cached_property
    def hop_width(self) -> np.ndarray:
        """The screening box's width per coordinate (1 where it is empty): a hop's scale."""
        return np.where(self.k.hi > self.k.lo, self.k.hi - self.k.lo, 1.0)

    @functools.cached_property
    def plain(self) -> tuple:
        """``k`` as the plain tuple a kernel call takes (see :mod:`.kernel_types`)."""
        return tuple(self.k)


def _make_kernel_static(model_obj) -> KernelStatic:
    p = model_obj.n_nonlinear
    residual = model_obj.hints.residual_column
    lo, hi = model_obj.screen_box()
    codes = _kernel_codes(model_obj, "compiled")
    k = KModel(codes=np.zeros(0, np.int64) if codes is None else codes,
               nonneg=_w(model_obj.alpha_nonneg, np.bool_),
               residual=-1 if residual is None else int(residual),
               lo=_w(lo), hi=_w(hi), zlo=_w(model_obj.z_lower.copy()),
               zhi=_w(model_obj.z_upper.copy()),
               axes=_w(np.array(_scan_axes(model_obj, 33)).reshape(p, 33)),
               ext_rows=_w(_extension_start_rows(model_obj)),
               nd_grid=_PROFILE_GRIDS[0], ns_grid=_PROFILE_GRIDS[1])
    return KernelStatic(k, _w(np.minimum(model_obj.z_upper - model_obj.z_lower, 10.0)))


def _w(a, dtype=float) -> np.ndarray:
    """``a`` as a writeable C-contiguous array (a copy only when it is not one already):
    numba compiles a kernel once per argument type, and a read-only array (a
    Measurements column, a cached draw) is another type, so every argument is passed
    writeable and the cache that ``make`` warms is the one every caller uses."""
    if type(a) is np.ndarray and a.dtype == dtype:
        flags = a.flags
        if flags.c_contiguous:  # a read-only column: a copy (what np.require makes, faster)
            return a if flags.writeable else a.copy()
    return np.require(a, dtype, ("C", "W"))


def _kernel_geometry(gamma, theta):
    """The compiled kernel's geometry of one table, its exact angles of incidence (log cos)
    and the rounded ones of the per-angle decomposition (as model.lobe_profile), each
    point's index among the rounded ones, the exact angles of incidence."""
    from .model_kernel import kernel_geometry

    return kernel_geometry(_w(gamma), _w(theta))

#: Which implementation fits: "compiled" (the numba kernel, for the models it covers;
#: numpy for the others) or "numpy" (the reference implementation everywhere).
ENGINE = "compiled"
#: "numpy-first": numpy for the first search, the compiled kernel for a second one
#: (:func:`~irreflect.fitting.fit`'s retry), for a command that fits one table once: the
#: kernel's load (about a second) costs more than it saves on a search, but a second,
#: wider search is several times the work, and the kernel does it 8-14 times faster (a
#: held-out 2880-point table that the model misfits: 11.7 s with numpy, 0.8 s compiled)
ENGINES = ("compiled", "numpy", "numpy-first")
#: "numpy-first" runs the second search compiled on tables of more than this many points;
#: on smaller ones numpy's second search (0.2-0.8 s on 108-198 points) costs less than the
#: kernel's load (experiments/bench_single_fit.py)
NUMPY_FIRST_POINTS = 500


def _kernel_codes(model_obj, engine=None):
    """The kernel's code of ``model_obj`` when the compiled engine is to fit it, else None
    (models the kernel does not cover, or a model whose starts a caller replaced)."""
    engine = engine or ENGINE
    if engine not in ENGINES:

        raise unknown_name("fitting engine", str(engine), ENGINES)
    if engine != "compiled" or model_obj.hints.kernel_starts is not model_obj.starts:
        return None
    return per_model(model_obj, "kernel_code", lambda: model_code(model_obj))


def model_code(model) -> np.ndarray | None:
    """The kernel's description of ``model``: extension codes innermost first, or None when
    the kernel does not cover the model (then the numpy path fits it). The model declares
    its kernel (``hints.kernel``); the kernel knows the extensions it implements."""
    from ..models.extensions import applied_extensions, base_of

    if base_of(model).hints.kernel != "two-lobe" or model.hints.kernel != "two-lobe":
        return None
    from .model_kernel import EXT_CODES  # deferred: numba costs ~1 s to import

    codes = []
    for name in applied_extensions(model):
        if name not in EXT_CODES:
            return None
        codes.append(EXT_CODES[name])
    return np.array(codes, np.int64)


def uses_kernel(model_obj, engine=None) -> bool:
    """Whether ``engine`` (None: :data:`ENGINE`) fits ``model_obj`` with the compiled kernel
    (the selection sizes its batches by it)."""
    return _kernel_codes(model_obj, engine) is not None
