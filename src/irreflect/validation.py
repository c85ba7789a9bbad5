"""Input checks shared by the library and the command line, in one place.

Each ``check_*`` helper converts its input and returns it, or raises an
:class:`~irreflect.errors.IrreflectError` (a ``ValueError``) whose one-line message says
what was expected, what was found and how to fix it (scikit-learn's ``check_*`` style).
The size budgets of the commands (how many measured points each one accepts, so that it
finishes within bounded memory) are here too, with the check that refuses a table up front.
"""

from __future__ import annotations

import math
import numbers
import os
import tempfile
from pathlib import Path

import numpy as np

from .errors import DataError, IrreflectError


# ----------------------------------------------------------------------------- text
def short_list(items, limit: int = 8, fmt=str) -> str:
    """``a, b, c`` for short lists, ``a, b, c, ... (400 in all)`` for long ones: an error
    line names a few values, never hundreds."""
    items = list(items)
    shown = ", ".join(fmt(x) for x in items[:limit])
    if len(items) > limit:
        shown += f", ... ({len(items)} in all)"
    return shown


# ----------------------------------------------------------------------------- scalars
def check_seed(seed, name: str = "seed") -> int:
    """A seed (for ``numpy.random.default_rng`` or the fitter's generator,
    :mod:`irreflect.fitting.draws`): an integer >= 0."""
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral):
        raise IrreflectError(f"{name} must be an integer >= 0; found {seed!r} "
                             f"({type(seed).__name__}): pass e.g. {name}=0")
    if seed < 0:
        raise IrreflectError(f"{name} must be an integer >= 0; found {seed}: use a "
                             "non-negative seed (the same seed gives the same result)")
    return int(seed)


def check_int(value, name: str, minimum: int = 1) -> int:
    """An integer >= ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < minimum:
        raise IrreflectError(f"{name} must be an integer >= {minimum}; found {value!r}")
    return int(value)


def check_number(value, name: str, *, low=None, high=None, low_open=False,
                 high_open=False, unit: str = "") -> float:
    """A finite real number within the given bounds (``*_open``: bound excluded)."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        x = math.nan
    ok = math.isfinite(x) and not isinstance(value, bool)
    if ok and low is not None:
        ok = x > low if low_open else x >= low
    if ok and high is not None:
        ok = x < high if high_open else x <= high
    if not ok:
        parts = []
        if low is not None:
            parts.append(f"{'>' if low_open else '>='} {low:g}")
        if high is not None:
            parts.append(f"{'<' if high_open else '<='} {high:g}")
        want = "a finite number" + (" " + " and ".join(parts) if parts else "")
        raise IrreflectError(f"{name} must be {want}{unit}; found {value!r}")
    return x


# ----------------------------------------------------------------------------- arrays
def check_real_array(values, name: str, *, ndim: int | None = 1, finite: bool = True,
                     source: str = "") -> np.ndarray:
    """A float array of real numbers: no text, no booleans, no complex numbers, and (with
    ``finite``) no NaN or infinity."""
    where = f"{source}: " if source else ""
    arr = np.asarray(values) if not isinstance(values, np.ndarray) else values
    if arr.dtype == bool:
        raise DataError(f"{where}{name} holds true/false values; expected numbers")
    if np.iscomplexobj(arr):
        raise DataError(f"{where}{name} holds complex numbers; expected real numbers: pass "
                        "the magnitude (abs) or the real part")
    if arr.dtype.kind not in "iuf":
        try:
            arr = arr.astype(float)
        except (TypeError, ValueError):
            first = next((v for v in np.ravel(arr) if not _is_number(v)), None)
            raise DataError(f"{where}{name} must be numbers; found {first!r} "
                            f"({type(first).__name__})") from None
    arr = arr.astype(float, copy=False)
    if ndim is not None and arr.ndim != ndim:
        raise DataError(f"{where}{name} must be a {ndim}-D array; found shape {arr.shape}")
    if finite and arr.size and not np.all(np.isfinite(arr)):
        i = int(np.flatnonzero(~np.isfinite(arr))[0])
        raise DataError(f"{where}{name} must be finite; found {arr.ravel()[i]} at index {i}")
    return arr


def _is_number(v) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool)


def check_same_length(**arrays) -> int:
    """All arrays (None skipped) have the same length; returns it."""
    sizes = {k: len(v) for k, v in arrays.items() if v is not None}
    if len(set(sizes.values())) > 1:
        raise DataError("arrays must have one value per measured point; found lengths "
                        + ", ".join(f"{k} {n}" for k, n in sizes.items()))
    return next(iter(sizes.values()), 0)


def check_angles_deg(gamma_deg, theta_deg, *, limit: float = 90.0):
    """Angles in degrees for a prediction: real numbers within [-limit, limit] (NaN passes
    through: NaN in, NaN out), broadcast against each other (any shape)."""
    out = []
    for name, values in (("gamma_deg", gamma_deg), ("theta_deg", theta_deg)):
        arr = check_real_array(values, name, ndim=None, finite=False)
        bad = np.abs(arr) > limit
        if np.any(bad):
            raise IrreflectError(f"{name} must lie within -{limit:g} and {limit:g} degrees "
                                 f"(from the surface normal); found {arr[bad][0]:g}")
        out.append(arr)
    try:
        g, t = np.broadcast_arrays(*out)
    except ValueError:
        raise IrreflectError(f"gamma_deg and theta_deg must have the same shape (or one be a "
                             f"number); found shapes {out[0].shape} and {out[1].shape}") from None
    return g, t


def check_masks(masks, n_points: int, name: str = "masks") -> np.ndarray:
    """A (B, n) boolean array of subset masks over ``n_points`` measured points."""
    arr = np.asarray(masks)
    if arr.ndim == 1:
        arr = arr[None]
    if arr.ndim != 2 or arr.shape[1] != n_points:
        raise DataError(f"{name} must be a (subsets, {n_points}) boolean array, one column per "
                        f"measured point; found shape {np.shape(masks)}")
    if arr.dtype != bool:
        if arr.dtype.kind not in "iuf" or not np.all((arr == 0) | (arr == 1)):
            raise DataError(f"{name} must hold true/false (or 0/1) values; found dtype "
                            f"{arr.dtype}")
        arr = arr.astype(bool)
    return arr


def check_subset_inputs(gamma_deg, theta_deg, power, masks, sigma=None):
    """The inputs of :func:`irreflect.fitting.fit_subsets`, converted and checked."""
    g = check_real_array(gamma_deg, "gamma_deg")
    t = check_real_array(theta_deg, "theta_deg")
    p = check_real_array(power, "power")
    s = None if sigma is None else check_real_array(sigma, "sigma")
    n = check_same_length(gamma_deg=g, theta_deg=t, power=p, sigma=s)
    if s is not None and np.any(s <= 0):
        raise DataError("sigma must be > 0 to weight fits by 1/sigma^2; found "
                        f"{s[s <= 0][0]:g}: pass sigma=None to fit unweighted")
    return g, t, p, check_masks(masks, n), s


# ----------------------------------------------------------------------------- size budgets
#: Tables larger than this are refused before they are parsed (every command).
MAX_FILE_BYTES = 256 * 2**20
#: Rows any command reads. Above, the parsed text alone takes gigabytes.
MAX_TABLE_ROWS = 2_000_000
#: Measured points per command, chosen so that each stays under about 2 GB of memory
#: (``experiments/bench_memory.py`` measures them; README, "Bad input"). ``diagnose``
#: (0.42 GB at 10,000 points) and ``reproduce`` (which diagnoses every table) take seconds
#: per thousand points; ``protocol --design-from`` searches subsets of every size.
POINT_BUDGET = {
    "fit": 200_000,
    "plot": 200_000,
    "evaluate-protocol": 200_000,
    "compare": 200_000,
    "diagnose": 10_000,
    "select": 50_000,
    "protocol": 2_000,
    "reproduce": 10_000,
}
#: ``select``: largest subset size searched on a table of more than
#: :data:`SELECT_FULL_SEARCH_POINTS` points (``--max-points`` must be at most this).
SELECT_MAX_SUBSET = 500
#: ``select`` without ``--max-points`` searches subsets of every size up to the whole table:
#: allowed up to this many points.
SELECT_FULL_SEARCH_POINTS = 2_000

_SUBSAMPLE = ("subsample the table (e.g. every 10th theta of each gamma, or fewer angles of "
              "incidence)")


_OTHERWISE = {
    "protocol": " (or choose points with 'irreflect select DATA --max-points 30')",
    "reproduce": " (or run the commands one by one: fit, compare and select accept more)",
    "diagnose": " (or fit and compare, which accept more points)",
}


def check_points_budget(n_points: int, command: str, source: str = "") -> None:
    """Refuse up front a table too large for ``command`` (see :data:`POINT_BUDGET`)."""
    limit = POINT_BUDGET.get(command)
    if limit is not None and n_points > limit:
        where = f"{source}: " if source else ""
        raise DataError(
            f"{where}{n_points} measured points is more than '{command}' handles within its "
            f"memory budget ({limit} points): {_SUBSAMPLE}{_OTHERWISE.get(command, '')}"
        )


def check_selection_budget(n_points: int, max_points: int | None, source: str = "",
                           option: str = "--max-points") -> None:
    """Refuse up front a selection whose subset fits would not fit in memory."""
    where = f"{source}: " if source else ""
    check_points_budget(n_points, "select", source)
    if max_points is None and n_points > SELECT_FULL_SEARCH_POINTS:
        raise DataError(
            f"{where}{n_points} measured points is too many to search subsets of every size "
            f"(at most {SELECT_FULL_SEARCH_POINTS} without {option}): pass {option} 30 "
            f"(the paper's frontier bends below 15 points) or {_SUBSAMPLE}"
        )
    if max_points is not None and max_points > SELECT_MAX_SUBSET and \
            n_points > SELECT_FULL_SEARCH_POINTS:
        raise DataError(
            f"{where}{option} {max_points} is more than the {SELECT_MAX_SUBSET} points a "
            f"subset may have on a table of {n_points} points: pass {option} "
            f"{SELECT_MAX_SUBSET} or less (e.g. 30)"
        )


# ----------------------------------------------------------------------------- output paths
def check_output_path(path, kind: str = "file", option: str = "--out",
                      suffixes: tuple[str, ...] | None = None) -> Path:
    """Check before any work that ``path`` can be written as a ``kind`` (``file`` or
    ``dir``): not an existing folder where a file is expected (or a file where a folder is),
    inside a folder that exists or can be created, and writable."""
    if path is None or str(path).strip() == "":
        raise IrreflectError(f"{option} must name a {'folder' if kind == 'dir' else 'file'}")
    path = Path(path)
    if kind == "file":
        if path.is_dir():
            raise IrreflectError(f"{option} {path}: is a folder; expected a file name"
                                 + (f" ending in {', '.join(suffixes)}" if suffixes else ""))
        if suffixes and path.suffix.lower() not in suffixes:
            raise IrreflectError(f"{option} {path}: expected a file name ending in "
                                 f"{', '.join(suffixes)}; found '{path.suffix or 'no suffix'}'")
    elif path.exists() and not path.is_dir():
        raise IrreflectError(f"{option} {path}: is a file; expected a folder (give a new or "
                             "existing folder name)")
    parent = path.absolute().parent
    ancestor = parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise IrreflectError(f"{option} {path}: '{ancestor}' is a file, so the folder "
                             f"'{parent}' cannot be created: choose another path")
    if not _writable(ancestor):
        raise IrreflectError(f"{option} {path}: cannot write in '{ancestor}' (permission "
                             "denied or read-only): choose a folder you can write to")
    return path


def _writable(folder: Path) -> bool:
    """Try to create a file in ``folder`` (``os.access`` is wrong for root and some
    network file systems)."""

    try:
        fd, probe = tempfile.mkstemp(prefix=".irreflect-probe-", dir=folder)
    except OSError:
        return False
    os.close(fd)
    os.unlink(probe)
    return True
