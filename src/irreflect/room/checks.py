"""Checks before a room simulation starts: its arguments, and its size against the
budgets of this machine (:data:`irreflect.validation.BUDGETS`).

The size of a run is known before it starts:

* **Monte Carlo**: ``rays x emitter-receiver pairs x bounces`` ray-bounces (budget
  ``ray-bounces``, about 1e9: tens of minutes on one core);
* **recursive method**: ``cells x min(cells, NODES_PER_LOG2 x log2 cells) x emitters x
  (bounces - 1) + cells x pairs`` cell pairs (budget ``cell-pairs``; the receiver-independent
  method with its quadtree; a pair costs :data:`GENERAL_PAIR_COST` when a material is not
  Lambertian), the cells counted as :func:`irreflect.room.geometry.discretize` cuts them;
* **memory**: the impulse responses kept for every pair, ``pairs x (bounces + 1) x time
  bins`` (the bins follow ``--dt`` and the room's diagonal), and for the recursive method the
  per-cell responses, ``cells x time bins x ...`` (budget ``memory``).

A run above a budget is refused with one line naming the option to change and the largest
(or smallest) value this machine allows with the other settings as they are.

And what a scene's materials say of themselves, before a simulation uses them.

A material file written by ``irreflect fit --save`` carries its fit's verdict and warnings
(:mod:`irreflect.verdict`): ``irreflect room`` and ``irreflect reproduce --scene`` print
them for every material they use, so a floor fitted from a lobe seen by one receiver does
not enter a room without a word. A material whose model predicts negative power anywhere
in the room's range (:func:`irreflect.room.materials.negative_power`) is refused unless
the caller allows it: the room would clip the negative part and simulate another curve
than the one fitted.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from ..errors import IrreflectError, SceneError
from ..validation import check_budget, note_memory_option
from .materials import fit_notes

#: A run's settings when neither the scene's [simulation] nor the caller sets them.
DEFAULTS = {"method": "montecarlo", "bounces": 3, "cell_m": 0.25, "rays": 20000, "seed": 0,
            "time_resolution_ns": 0.25}

C_LIGHT = 299_792_458.0
#: A cell pair of the recursive method costs this many Lambertian ones when some material is
#: not Lambertian (lobes evaluated per pair: 2e6 against 7e7 pairs/s on a busy 2-core machine).
GENERAL_PAIR_COST = 30
#: cells and far-field groups a cell meets per reflection, per log2(cells) (the quadtree
#: of the recursive method; about 1,900 at 28,160 cells)
NODES_PER_LOG2 = 128
#: Bytes each kept time bin of each emitter-receiver pair and order costs: the float64
#: histogram while it is computed, the float32 one kept, and its row of the long-form
#: impulse response table written at the end.
BYTES_PER_BIN = 64
#: Option names in messages: the command line's, and the library's keywords.
CLI_OPTIONS = {"rays": "--rays", "cell_m": "--cell", "time_resolution_ns": "--dt",
               "bounces": "--bounces"}
KEYWORDS = {k: k for k in CLI_OPTIONS}


def check_simulate_arguments(scene, scheduler=None, workers=None, threads=None) -> None:
    """The arguments of :func:`irreflect.room.simulate` that are not settings."""
    from .scene import Scene

    if not isinstance(scene, Scene):
        raise IrreflectError(f"simulate expects a Scene (from irreflect.room.load_scene or "
                             f"scene_from_dict); found {type(scene).__name__}")
    if scheduler is not None and not _is_client(scheduler):
        from ..selection.parallel import check_scheduler_address

        check_scheduler_address(scheduler)
    for name, value in (("workers", workers), ("threads", threads)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, int)
                                  or value < 1):
            raise IrreflectError(f"{name} must be an integer >= 1 (or None); found {value!r}")


def _is_client(obj) -> bool:
    try:
        from distributed import Client
    except ImportError:  # pragma: no cover - dask is a dependency
        return False
    return isinstance(obj, Client)


def resolve_settings(scene, overrides: Mapping) -> dict:
    """The settings a run will use: the engine's defaults, the scene's [simulation], then
    ``overrides`` that are not None."""
    out = dict(DEFAULTS)
    out.update(scene.settings)
    out.update({k: v for k, v in overrides.items() if v is not None})
    return out


def count_cells(scene, cell_m: float) -> int:
    """Cells :func:`irreflect.room.geometry.discretize` would cut (room faces and the box
    faces that do not lie on one; cells under boxes counted too: an upper bound)."""
    size = [float(x) for x in scene.size]

    def n(length: float) -> int:
        return max(1, round(min(length / cell_m, 1e12)))

    total = 0
    for axis in range(3):
        a, b = (size[i] for i in range(3) if i != axis)
        total += 2 * n(a) * n(b)
    for box in scene.boxes:
        for axis in range(3):
            others = [i for i in range(3) if i != axis]
            face = n(box.hi[others[0]] - box.lo[others[0]]) * n(box.hi[others[1]]
                                                                  - box.lo[others[1]])
            for coord in (box.lo[axis], box.hi[axis]):
                if 1e-12 < coord < size[axis] - 1e-12:
                    total += face
    return total


def time_bins(scene, bounces: int, dt_ns: float, legs: int | None = None) -> float:
    """Bins of an impulse response covering ``legs`` (default ``bounces + 1``) room
    diagonals at ``dt_ns``."""
    legs = bounces + 1 if legs is None else legs
    diagonal = math.sqrt(sum(float(x) ** 2 for x in scene.size))
    return legs * diagonal / C_LIGHT / (dt_ns * 1e-9) + 2


def results_memory(scene, settings: Mapping) -> float:
    """Bytes of the impulse responses a run keeps: pairs x (bounces + 1) x time bins x
    :data:`BYTES_PER_BIN`."""
    bounces = int(settings["bounces"])
    pairs = len(scene.emitters) * len(scene.receivers)
    bins = time_bins(scene, bounces, float(settings["time_resolution_ns"]))
    return pairs * (bounces + 1) * BYTES_PER_BIN * bins


def cells_memory(scene, settings: Mapping, cell_m: float, copies: int = 1) -> float:
    """Bytes of the recursive method's per-cell responses: after 1 .. K-2 reflections per
    emitter (of 2 .. K-1 legs' length) and the receiver's 2-leg response, float32, in each
    of ``copies`` processes; orders >= 3 convolve them by FFT in chunks of up to 256 cells
    (complex128)."""
    bounces = int(settings["bounces"])
    legs = len(scene.emitters) * sum(m + 1 for m in range(1, bounces - 1)) + 3
    bins = time_bins(scene, bounces, float(settings["time_resolution_ns"]), legs=1)
    n = count_cells(scene, cell_m)
    fft = 32.0 * min(256, n) * (bounces + 1) * bins if bounces >= 3 else 0.0
    return 4.0 * n * bins * legs * copies + fft


def memory_estimate(scene, settings: Mapping, workers: int | None = None) -> float:
    """Bytes a run takes beyond the interpreter, as the budget check counts them."""
    total = results_memory(scene, settings)
    if settings["method"] == "recursive" and int(settings["bounces"]) >= 1:
        total += cells_memory(scene, settings, float(settings["cell_m"]), _copies(workers))
    return total


def _copies(workers) -> int:
    return 1 + (workers if workers and workers > 1 else 0)


def check_room_budget(scene, settings: Mapping, options: Mapping = KEYWORDS,
                      workers: int | None = None) -> None:
    """Refuse a run larger than this machine's budgets, before it starts (see the module
    docstring); ``settings`` as :func:`resolve_settings` gives them; ``workers``: local
    worker processes, each of which holds the recursive method's per-cell responses."""
    for key in ("bounces", "rays", "seed"):
        if isinstance(settings.get(key), bool):
            raise IrreflectError(f"{options.get(key, key)} must be an integer; found "
                                 f"{settings[key]!r}")
    method, bounces = settings["method"], int(settings["bounces"])
    dt = float(settings["time_resolution_ns"])
    emitters, receivers = len(scene.emitters), len(scene.receivers)
    pairs = emitters * receivers
    note_memory_option(f"{options['time_resolution_ns']}, {options['bounces']} or the "
                       "number of receivers")
    _check_memory(scene, settings, pairs, bounces, dt, options)
    if method == "montecarlo" and bounces >= 1:
        rays = int(settings["rays"])
        per_ray = pairs * bounces
        check_budget("ray-bounces", rays * per_ray, option=options["rays"], value=rays,
                     largest=max(1, int(_limit("ray-bounces") // per_ray)),
                     detail=f"{options['rays']} x {receivers} receiver(s) x {emitters} "
                            f"emitter(s) x {bounces} bounce(s)",
                     alternative=f", fewer {options['bounces']} or fewer receivers")
    elif method == "recursive" and bounces >= 1:
        _check_recursive(scene, settings, pairs, emitters, bounces, dt, options,
                         _copies(workers))


def _limit(name: str) -> float:
    from ..validation import budget

    return budget(name)


def _check_memory(scene, settings, pairs: int, bounces: int, dt: float, options) -> None:
    per_bin = pairs * (bounces + 1) * BYTES_PER_BIN
    largest_bins = _limit("memory") / per_bin
    smallest_dt = (bounces + 1) * scene.diagonal / C_LIGHT * 1e9 / max(largest_bins - 2, 1e-300)
    check_budget("memory", results_memory(scene, settings),
                 option=options["time_resolution_ns"], value=dt,
                 largest=f"{_round_up(smallest_dt):g}", direction="or more",
                 detail=f"{pairs} emitter-receiver pair(s) x {bounces + 1} orders x "
                        f"{time_bins(scene, bounces, dt):,.0f} time bins of {dt:g} ns",
                 alternative=f", fewer {options['bounces']} or fewer receivers")


def _check_recursive(scene, settings, pairs, emitters, bounces, dt, options,
                     copies: int = 1) -> None:
    cell = float(settings["cell_m"])
    cost = 1 if all(m.is_lambertian for m in scene.materials.values()) else GENERAL_PAIR_COST

    def work(c: float) -> float:
        # the receiver-independent method (irreflect.room.recursive): per emitter and
        # reflection every cell meets the cells and far-field groups of a quadtree, at most
        # NODES_PER_LOG2 x log2(cells) of them; each receiver then gathers from every cell
        n = float(count_cells(scene, c))
        met = min(n, NODES_PER_LOG2 * math.log2(max(n, 2.0)))
        return (n * met * emitters * max(bounces - 1, 0) + n * pairs) * cost

    results = results_memory(scene, settings)

    def memory(c: float) -> float:
        return results + cells_memory(scene, settings, c, copies)

    n_cells = count_cells(scene, cell)
    check_budget("cell-pairs", work(cell), option=options["cell_m"], value=cell,
                 largest=f"{_smallest_cell(work, _limit('cell-pairs'), scene):g}",
                 direction="or more", detail=f"{n_cells:,} cells of {cell:g} m, {pairs} "
                                             f"pair(s), {bounces} bounce(s)",
                 alternative=f", fewer {options['bounces']} or receivers, or the Monte "
                             "Carlo method")
    check_budget("memory", memory(cell), option=options["cell_m"], value=cell,
                 largest=f"{_smallest_cell(memory, _limit('memory'), scene):g}",
                 direction="or more", detail=f"{n_cells:,} cells x time bins of {dt:g} ns "
                                             f"in {copies} process(es)",
                 alternative=f" or a larger {options['time_resolution_ns']}")


def _smallest_cell(cost, limit: float, scene) -> float:
    """The smallest cell size (m, rounded up to 3 digits) whose ``cost`` is within
    ``limit`` (bisection on a log scale; the room's smallest side if none is)."""
    hi = float(min(scene.size))
    if cost(hi) > limit:
        return hi
    lo = hi * 1e-9
    for _ in range(80):
        mid = math.sqrt(lo * hi)
        if cost(mid) > limit:
            lo = mid
        else:
            hi = mid
    return _round_up(hi)


def _round_up(x: float) -> float:
    """``x`` rounded up to 3 significant digits (a value the user can type that passes)."""
    if not (x > 0 and math.isfinite(x)):
        return x
    scale = 10 ** (math.floor(math.log10(x)) - 2)
    return math.ceil(x / scale) * scale


def used_materials(scene) -> list[str]:
    """The names of the materials a scene's room faces and boxes use, in first-use order."""
    names = list(scene.room_materials)
    for box in scene.boxes:
        names += list(box.materials)
    return list(dict.fromkeys(names))


def material_notes(scene, allow_unphysical: bool = False) -> list[str]:
    """One block of lines per used material that has anything to say (its fit's verdict
    and warnings, an unphysical model). Raises SceneError for an unphysical material
    unless ``allow_unphysical`` (then it is a warning line)."""
    lines, refused = [], []
    for name in used_materials(scene):
        mat = scene.materials[name]
        notes = fit_notes(mat)
        if not notes:
            continue
        lines.append(f"material '{name}' ({mat.source}):")
        lines += [f"  {n}" for n in notes]
        if (mat.metadata or {}).get("unphysical"):
            refused.append(f"'{name}': {mat.metadata['unphysical']}")
    if refused and not allow_unphysical:
        raise SceneError(
            f"{scene.path or scene.name}: material {refused[0]}: fit another model (the "
            "two-lobe model's share saturates and never goes negative) or pass "
            "--allow-unphysical to simulate it with the negative part clipped to 0")
    return lines


__all__ = ["check_simulate_arguments", "check_room_budget", "resolve_settings", "count_cells",
           "time_bins", "results_memory", "cells_memory", "memory_estimate", "CLI_OPTIONS",
           "KEYWORDS", "used_materials", "material_notes"]
