"""The compiled fitting kernel's on-disk cache: where it lies, whether it is warm, and the
announced first build.

numba compiles the fitter's kernels (the ``*_kernel`` modules of :mod:`irreflect.fitting`)
on first use and keeps the machine code on disk (``cache=True``): in ``$NUMBA_CACHE_DIR``
when that is set, else beside the source (``irreflect/fitting/__pycache__``) when the installed package's folder is writable, else in the
user's cache folder (numba's user-wide cache, ``~/.cache/numba/`` or under
``$XDG_CACHE_HOME``), so a read-only ``site-packages`` still gets a cache. The first build
takes one to three minutes; every later process loads it in about a second. The cache is
tied to the kernel's source file and numba's version: a new install builds it once more.

:func:`ensure_compiled` is what the commands that fit call before any work: when the cache
is cold it says so on stderr, builds every entry point (:func:`irreflect.fitting.warm`) and
says how long that took, instead of a first run that is silently two minutes slower.
"""

from __future__ import annotations

import contextlib
import sys
import time
from pathlib import Path

#: The kernel's entry points whose cache decides whether a build is due (what ``warm()``
#: compiles: the global search, the two-lobe finish, the batched subset fits), as
#: (module of :mod:`irreflect.fitting`, name).
ENTRY_POINTS = (("search_kernel", "search"), ("finish_kernel", "tl_finish"),
                ("subsets_kernel", "subset_search"))


#: The room simulation's compiled kernels whose cache decides whether a build is due (what
#: :func:`irreflect.room.warm.warm` compiles), as (module of :mod:`irreflect.room`, name).
ROOM_ENTRY_POINTS = (("kernels", "term_albedo_table"), ("transport", "lobe_matrix"))


def kernel_cache(entry_points=ENTRY_POINTS,
                 package: str = "irreflect.fitting") -> tuple[Path | None, bool | None]:
    """(the folder numba caches the kernel in, whether a build is due): ``True`` when an
    entry point has no cached code for this source and numba version, ``None`` when numba's
    cache cannot be inspected (then nothing is announced). ``entry_points`` and
    ``package``: the fitter's by default, :data:`ROOM_ENTRY_POINTS` in
    ``irreflect.room`` for the room's."""
    import importlib

    folder, cold = None, False
    for module, name in entry_points:
        kernel = importlib.import_module(f"{package}.{module}")
        cache = getattr(getattr(kernel, name, None), "_cache", None)
        try:
            folder = Path(cache.cache_path)
            index = cache._cache_file._load_index()  # {} when absent or stale
        except Exception:  # another numba's internals, or no on-disk cache at all
            return folder, None
        cold = cold or not index
    return folder, cold


#: Whether this process has looked at the cache for :func:`build_notice` (once is enough:
#: a build, announced or not, leaves it warm for the rest of the process).
_LOOKED = [False]


@contextlib.contextmanager
def build_notice(stream=None):
    """Around work that may compile the kernel: when its on-disk cache is cold (looked at
    once per process), a line on ``stream`` (stderr) before the work and one after it with
    the seconds it took; the work itself builds what it uses. Yields the folder of the
    cache when a build is announced, else None."""
    if _LOOKED[0]:
        yield None
        return
    _LOOKED[0] = True
    folder, cold = kernel_cache()
    if not cold:
        yield None
        return
    stream = sys.stderr if stream is None else stream
    print(f"irreflect: first use of this install: compiling the fitting kernel (once, about "
          f"1-5 min; cached in {folder}) ...", file=stream, flush=True)
    t0 = time.perf_counter()
    yield folder
    print(f"irreflect: fitting kernel compiled in {time.perf_counter() - t0:.0f} s; later "
          "runs load it from the cache", file=stream, flush=True)


def ensure_compiled(build, stream=None) -> float | None:
    """Build the kernel now (``build``: :func:`irreflect.fitting.warm`, passed in so that
    this module does not import the fitter that imports it) when its on-disk cache is cold,
    with a line before and after on ``stream`` (stderr); returns the seconds it took, or
    None when nothing was built."""
    _LOOKED[0] = False  # look again: the caller asks now
    t0 = time.perf_counter()
    with build_notice(stream) as building:
        if building is not None:
            build()
    return None if building is None else time.perf_counter() - t0


def ensure_room_compiled(build, stream=None) -> float | None:
    """As :func:`ensure_compiled`, for the room simulation's kernels (``build``:
    :func:`irreflect.room.warm.warm`): a cold cache is built before the simulation, with a
    line before and after on ``stream`` (stderr), instead of a first ``irreflect room`` that
    sits a minute or more in a silent build; returns the seconds, or None."""
    folder, cold = kernel_cache(ROOM_ENTRY_POINTS, "irreflect.room")
    if not cold:
        return None
    stream = sys.stderr if stream is None else stream
    print(f"irreflect: first use of this install: compiling the room simulation's kernels "
          f"(once, about 1-2 min; cached in {folder}) ...", file=stream, flush=True)
    t0 = time.perf_counter()
    build()
    seconds = time.perf_counter() - t0
    print(f"irreflect: room kernels compiled in {seconds:.0f} s; later runs load them from "
          "the cache", file=stream, flush=True)
    return seconds
