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
import stat
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import DataError, IrreflectError


# ----------------------------------------------------------------------------- text
def split_names(text: str, option: str, example: str) -> list[str]:
    """The names of a comma-separated option (``--models two-lobe,phong``), stripped; []
    when it names none (the caller says what it expected), and a one-line error for an
    empty name between commas ('a,,b', a trailing comma), which would be dropped silently."""
    names = [t.strip() for t in str(text).split(",")]
    if not any(names):
        return []
    if not all(names):
        raise IrreflectError(f"{option} '{text}' has an empty name between its commas "
                             f"(expected names separated by single commas, e.g. {example}): "
                             "remove the extra comma")
    return names


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
        # a number as the user wrote it (100, not 100.0 or np.float64(100.0))
        shown = (f"{x:.15g}" if isinstance(value, (int, float, np.number))
                 and not isinstance(value, (bool, np.bool_)) else repr(value))
        raise IrreflectError(f"{name} must be {want}{unit}; found {shown}")
    return x


def check_bool(value, name: str) -> bool:
    """True or False (numpy's too), not a string or a number: ``use_sigma="no"`` must not
    mean True."""
    if isinstance(value, bool | np.bool_):
        return bool(value)
    raise IrreflectError(f"{name} must be True or False; found {value!r}")


#: Integer settings of :func:`irreflect.fitting.fit` and ``fit_subsets``: (smallest,
#: largest; None: the setting may be None for its default). The largest values bound the
#: work of one fit.
_FIT_COUNTS = {
    "n_random_starts": (0, 10_000, False), "n_screen": (1, 1_000_000, True),
    "n_keep": (0, 10_000, True), "n_data_starts": (0, 10_000, True),
    "max_iter": (1, 100_000, False), "max_rounds": (0, 1_000, True),
    "n_hops": (0, 10_000, True),
}
_FIT_FLAGS = ("use_sigma", "polish", "retry", "data_starts", "scan", "exhaustive")


def check_fit_options(**options) -> None:
    """The keyword settings of :func:`irreflect.fitting.fit` and ``fit_subsets``: counts
    are integers in their range (:data:`_FIT_COUNTS`), flags are booleans, ``ftol`` a
    number in (0, 1), ``seed`` a seed; one line naming the setting otherwise."""
    for name, value in options.items():
        if name in _FIT_COUNTS:
            low, high, optional = _FIT_COUNTS[name]
            if value is None and optional:
                continue
            if isinstance(value, bool) or not isinstance(value, numbers.Integral) or \
                    not low <= value <= high:
                raise IrreflectError(f"{name} must be an integer from {low} to {high}"
                                     f"{' (or None for the default)' if optional else ''}; "
                                     f"found {value!r}")
        elif name in _FIT_FLAGS:
            check_bool(value, name)
        elif name == "ftol":
            check_number(value, "ftol", low=0.0, high=1.0, low_open=True, high_open=True)
        elif name == "seed":
            check_seed(value)


def check_starts(starts, n_nonlinear: int, name: str = "extra_starts") -> np.ndarray | None:
    """Starting points of the nonlinear coordinates: None, or finite numbers of shape
    (S, ``n_nonlinear``) (a single start may be 1-D)."""
    if starts is None:
        return None
    arr = check_real_array(starts, name, ndim=None)
    if arr.ndim == 1:
        arr = arr[None]
    if arr.ndim != 2 or arr.shape[1] != n_nonlinear or arr.shape[0] > 100_000:
        raise IrreflectError(f"{name} must be an array of shape (starts, {n_nonlinear}) (the "
                             f"model's nonlinear coordinates, at most 100000 starts); found "
                             f"shape {np.shape(starts)}")
    return arr


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
    if arr.dtype == object:  # None is no number: astype(float) would make it NaN
        missing = next((i for i, v in enumerate(arr.flat) if v is None), None)
        if missing is not None:
            at = f" at index {missing}" if arr.ndim else ""
            raise DataError(f"{where}{name} must be numbers; found None{at}: give a number "
                            f"for every value{'' if finite else ' (NaN for a missing one)'}")
    if arr.dtype.kind not in "iuf":
        try:
            arr = arr.astype(float)
        except (TypeError, ValueError):
            first = next((v for v in np.ravel(arr) if not _is_number(v)), None)
            first = first.item() if isinstance(first, np.generic) else first  # not np.str_('a')
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
    through: NaN in, NaN out), broadcast against each other (any shape). pandas Series of
    different indexes are refused, as in Measurements: they would pair by position, not by
    label."""
    indexes = [getattr(v, "index", None) for v in (gamma_deg, theta_deg)]  # pandas' labels
    if all(hasattr(i, "equals") for i in indexes) and not indexes[0].equals(indexes[1]):
        raise IrreflectError("gamma_deg and theta_deg are pandas Series with different indexes, "
                             "which would pair their values by position, not by label: take "
                             "them from one DataFrame, call .reset_index(drop=True) on each, or "
                             "pass arrays (.to_numpy())")
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
    # a pilot scan is fitted once (0.43 GB at 112,000 points, as 'fit'): the 2,000 of
    # 'protocol --design-from', which searches subsets, refused a 2,976-point pilot
    "protocol-lobe-from": 200_000,
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


def point_budget(command: str) -> int | None:
    """Measured points ``command`` accepts: :data:`POINT_BUDGET`, or the environment
    variable ``IRREFLECT_BUDGET_POINTS_<COMMAND>`` when set."""
    limit = POINT_BUDGET.get(command)
    if limit is None:
        return None
    env = "IRREFLECT_BUDGET_POINTS_" + command.upper().replace("-", "_")
    text = os.environ.get(env)
    if text is None or not text.strip():
        return limit
    try:
        value = int(float(text))
    except (ValueError, OverflowError):
        value = 0
    if value < 1:
        raise BudgetError(f"{env}={text!r}: expected a number of points >= 1 (default {limit})")
    return value


def check_points_budget(n_points: int, command: str, source: str = "") -> None:
    """Refuse up front a table too large for ``command`` (see :data:`POINT_BUDGET`)."""
    limit = point_budget(command)
    note_memory_option("the table's size: subsample the table")
    if limit is not None and n_points > limit:
        where = f"{source}: " if source else ""
        env = "IRREFLECT_BUDGET_POINTS_" + command.upper().replace("-", "_")
        shown = {"protocol-lobe-from": "protocol --lobe-from"}.get(command, command)
        raise DataError(
            f"{where}{n_points} measured points is more than '{shown}' handles within its "
            f"memory budget ({limit} points): {_SUBSAMPLE}{_OTHERWISE.get(command, '')} "
            f"(or raise the budget: {env}=N)"
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


# ----------------------------------------------------------------------------- work budgets
class BudgetError(IrreflectError):
    """A run larger than its budget, refused before it starts (one line naming the option
    and the largest value allowed on this machine)."""


@dataclass(frozen=True)
class Budget:
    """A limit on the size of one kind of work, checked before the work starts.

    ``limit`` is the default; the environment variable :attr:`env` (``IRREFLECT_BUDGET_`` +
    the name in capitals) replaces it, for a machine that can do more (or should do less).
    """

    name: str
    limit: float
    unit: str
    what: str

    @property
    def env(self) -> str:
        return "IRREFLECT_BUDGET_" + self.name.upper().replace("-", "_")

    def value(self) -> float:
        text = os.environ.get(self.env)
        if text is None or not text.strip():
            return float(self.limit)
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and value > 0):
            raise BudgetError(f"{self.env}={text!r}: expected a number > 0 ({self.what}, in "
                              f"{self.unit}; default {self.limit:g})")
        return value


def physical_memory() -> int:
    """Bytes of memory of this machine (8 GiB when the system does not say)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not POSIX
        return 8 * 2**30


#: The budgets of every command (README, "Bad input"; docs/bad-input.md). Work budgets
#: bound the time a run takes (a few tens of minutes on one core at most), the memory
#: budget what one run may allocate (a quarter of this machine's memory, at most 8 GiB).
BUDGETS = {b.name: b for b in (
    Budget("memory", min(physical_memory() / 4, 8 * 2**30) / 2**30, "GB",
           "memory one run may take"),
    Budget("ray-bounces", 1e9, "ray-bounces",
           "Monte Carlo rays x emitter-receiver pairs x bounces of one room run"),
    Budget("cell-pairs", 6e10, "cell pairs",
           "cells x cells met (at most 128 log2 cells) x emitters x (bounces - 1) + cells x "
           "emitter-receiver pairs of one recursive room run, a pair counted 30 times when "
           "a material is not Lambertian"),
    Budget("receivers", 40_000, "receivers", "receivers of one scene (grids included)"),
    Budget("subset-fits", 5e6, "subset fits",
           "generations x population of one selection run"),
    Budget("trials", 500_000, "trials", "Monte Carlo trials of evaluate-protocol"),
)}


def budget(name: str) -> float:
    """The value in force of budget ``name`` (bytes for ``memory``)."""
    b = BUDGETS[name]
    return b.value() * (2**30 if name == "memory" else 1)


#: What to lower when a command runs out of memory (the CLI's message), set by the last
#: budget check of the run.
_memory_hint: list[str] = []


def memory_hint(default: str) -> str:
    """The option that sized the run that ran out of memory (the last budget checked)."""
    return _memory_hint[-1] if _memory_hint else default


def note_memory_option(text: str) -> None:
    """Remember which option(s) size this run's memory, for an out-of-memory message. A
    command-line option (``--dt``) is not replaced by the library's name of the same
    setting checked again further down (``time_resolution_ns``); the CLI clears the note
    when a command starts (:func:`forget_memory_options`)."""
    if _memory_hint and _memory_hint[-1].startswith("--") and not text.startswith("--"):
        return
    _memory_hint[:] = [text]


def forget_memory_options() -> None:
    _memory_hint.clear()


def _amount(x: float) -> str:
    return f"{x:,.0f}" if abs(x) < 1e7 else f"{x:.3g}"


def check_budget(name: str, amount: float, *, option: str, value, largest, detail: str,
                 direction: str = "or less", alternative: str = "") -> None:
    """Refuse work of ``amount`` (in the budget's unit) above budget ``name``: one line
    naming ``option`` (given ``value``), what the amount is made of (``detail``) and the
    ``largest`` value the option may take here (``direction``: "or less", "or more")."""
    limit = budget(name)
    b = BUDGETS[name]
    if name == "memory":
        note_memory_option(f"{option} ({largest} {direction} with {detail})")
    if amount <= limit:
        return
    unit = b.unit
    shown = (f"{amount / 2**30:.3g} GB" if name == "memory" else f"{_amount(amount)} {unit}")
    allowed = (f"{limit / 2**30:.3g} GB" if name == "memory" else f"{_amount(limit)}")
    way = (f"pass {option} {largest} {direction}" if largest is not None
           else f"lower {option}")
    raise BudgetError(
        f"{option} {value}: {shown} ({detail}) is more than this machine's budget of "
        f"{allowed} ({b.what}): {way}{alternative} (or raise the budget: {b.env}=N)")


def check_search_budget(pop_size: int, generations: int, n_points: int, *,
                        pop_option: str = "pop_size",
                        gen_option: str = "generations") -> None:
    """A subset search of ``generations x pop_size`` fits on ``n_points`` points within the
    ``subset-fits`` budget (time) and the memory budget (every scored subset is cached)."""
    fits = int(pop_size) * int(generations)
    limit = budget("subset-fits")
    if pop_size * 2 > limit or generations < 2:  # the population alone is too large
        check_budget("subset-fits", fits, option=pop_option, value=pop_size,
                     largest=max(2, int(limit // generations)),
                     detail=f"{pop_option} x {gen_option} {generations}",
                     alternative=f" or fewer {gen_option}")
    check_budget("subset-fits", fits, option=gen_option, value=generations,
                 largest=max(1, int(limit // pop_size)),
                 detail=f"{gen_option} x {pop_option} {pop_size}",
                 alternative=f" or a smaller {pop_option}")
    per_fit = (n_points + 7) // 8 + 160  # the cache entry of a scored subset
    check_budget("memory", fits * per_fit + pop_size * n_points * 16, option=gen_option,
                 value=generations,
                 largest=max(1, int(budget("memory") // (per_fit * pop_size))),
                 detail=f"{fits:,} cached subsets of {n_points} points",
                 alternative=f" or a smaller {pop_option}")


def check_trials_budget(n_trials: int, option: str = "n_trials") -> None:
    """A Monte Carlo of ``n_trials`` fits within the ``trials`` budget."""
    check_budget("trials", n_trials, option=option, value=n_trials,
                 largest=int(budget("trials")), detail="one fit per trial")


# ----------------------------------------------------------------------------- output paths
def check_output_path(path, kind: str = "file", option: str = "--out",
                      suffixes: tuple[str, ...] | None = None) -> Path:
    """Check before any work that ``path`` can be written as a ``kind`` (``file`` or
    ``dir``): not an existing folder where a file is expected (or a file where a folder is),
    not a device, FIFO or anything else that is not a regular file or folder, inside a folder
    that exists or can be created, and writable. A symlink is followed only within the
    folder it lies in; the path to write (the link's target, else ``path``) is returned."""
    noun = "folder" if kind == "dir" else "file"
    if path is None or not isinstance(path, str | os.PathLike) or str(path).strip() == "":
        raise IrreflectError(f"{option} must name a {noun}; found "
                             f"{'an empty name' if isinstance(path, str) else repr(path)}")
    if "\0" in str(path):
        raise IrreflectError(f"{option} {path!r}: a path cannot hold a NUL character")
    if kind == "file" and str(path).endswith(tuple(filter(None, (os.sep, os.altsep, "/")))):
        # Path() drops the separator: 'x.json/' would be written as 'x.json'
        raise IrreflectError(f"{option} {path}: ends in '{str(path)[-1]}', so it names a folder;"
                             " expected a file name" + (f" ending in {', '.join(suffixes)}"
                                                        if suffixes else "")
                             + f": write {str(path).rstrip(os.sep + (os.altsep or '') + '/')}")
    path = _follow_link(Path(path), noun, option)
    if kind == "file":
        if path.is_dir():
            raise IrreflectError(f"{option} {path}: is a folder; expected a file name"
                                 + (f" ending in {', '.join(suffixes)}" if suffixes else ""))
        if suffixes and path.suffix.lower() not in suffixes:
            raise IrreflectError(f"{option} {path}: expected a file name ending in "
                                 f"{', '.join(suffixes)}; found '{path.suffix or 'no suffix'}'")
    _check_special(path, noun, option)
    if kind != "file" and path.exists() and not path.is_dir():
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


def _follow_link(path: Path, noun: str, option: str) -> Path:
    """``path``, or the target of the symlink ``path`` when it lies within the link's own
    folder; a link out of it is refused (an output never follows a link elsewhere)."""
    if not path.is_symlink():
        return path
    folder = Path(os.path.realpath(path.absolute().parent))
    target = Path(os.path.realpath(path))
    if folder != target and folder not in target.parents:
        raise IrreflectError(
            f"{option} {path}: is a symlink to '{os.readlink(path)}', outside '{folder}': "
            f"irreflect does not write through links out of the folder asked for: give the "
            f"real {noun} ({target}) or another name")
    return target


def _check_special(path: Path, noun: str, option: str) -> None:
    """Refuse an existing output that is a device, a FIFO, a socket or a link that leads
    nowhere it may write: it would be replaced by a regular file (or written into)."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return
    except OSError as exc:
        raise IrreflectError(f"{option} {path}: cannot be checked ({exc.strerror or exc}): "
                             "choose another path") from None
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return
    kind = ("a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else
            "a pipe (FIFO)" if stat.S_ISFIFO(mode) else
            "a socket" if stat.S_ISSOCK(mode) else "not a regular file")
    raise IrreflectError(f"{option} {path}: is {kind}; expected a {noun} name (irreflect "
                         f"writes regular files and replaces nothing else): choose another path")


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
