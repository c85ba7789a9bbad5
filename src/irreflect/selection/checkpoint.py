"""Checkpoints of an NSGA-II point selection: data only, validated on load.

A checkpoint is a NumPy ``.npz`` archive written and read with ``allow_pickle=False``, so
loading one can never run code. It holds everything the search needs to continue exactly
as an uninterrupted run would:

- ``meta``: a JSON document (format tag :data:`FORMAT`, :data:`VERSION`, the run's
  fingerprint of data and settings, the generation reached, wall time so far, the
  evaluator's counters and the random generator's state);
- the population: masks ``pop_X`` (bool), objectives ``pop_F``, constraints ``pop_G``,
  ``pop_CV`` and NSGA-II's ``pop_rank`` and ``pop_crowding`` (what mating selection reads);
- the evaluator's cache of scored masks (``cache_keys`` packed bits, ``cache_scores``) and
  its archive of the best masks per subset size (``archive_*``).

Anything else (a pickle, another program's archive, a truncated file, a checkpoint of a
different run) is refused with a one-line :class:`~irreflect.errors.IrreflectError`.
"""

from __future__ import annotations

import json
import time
import zipfile
from pathlib import Path

import numpy as np
from pymoo.core.population import Population

from .._atomic import atomic_path
from ..errors import IrreflectError

FORMAT = "irreflect-selection-checkpoint"
VERSION = 3  # 3: the shared elite optima of the search
_ARRAYS = {
    # name: (dtype kind(s), ndim)
    "meta": ("U", 0),
    "pop_X": ("b", 2), "pop_F": ("f", 2), "pop_G": ("f", 2), "pop_CV": ("f", 2),
    "pop_rank": ("iu", 1), "pop_crowding": ("f", 1),
    "cache_keys": ("u", 2), "cache_scores": ("f", 1),
    "archive_n": ("iu", 1), "archive_score": ("f", 1), "archive_serial": ("iu", 1),
    "archive_keys": ("u", 2), "elite_scores": ("f", 1), "elites": ("f", 2),
}
_COUNTERS = ("evaluations", "failed_fits", "cache_hits", "fit_seconds", "_serial")


def _refuse(path, what: str):
    raise IrreflectError(f"{path}: {what}; delete the file (or use another --checkpoint) to "
                         "start afresh")


def save_checkpoint(path, fingerprint: str, algorithm, evaluator, generation: int,
                    seconds: float) -> None:
    """Write the state of ``algorithm`` (pymoo NSGA-II) and ``evaluator`` atomically."""
    pop = algorithm.pop
    nbytes = (evaluator.n + 7) // 8
    keys = list(evaluator.cache)
    archive = [(n, score, serial, key) for n, entries in sorted(evaluator.archive.items())
               for score, serial, key in entries]
    meta = {
        "format": FORMAT, "version": VERSION, "fingerprint": fingerprint,
        "generation": int(generation), "seconds": float(seconds), "n_points": evaluator.n,
        "n_iter": int(algorithm.n_iter), "n_eval": int(algorithm.evaluator.n_eval),
        "rng": algorithm.random_state.bit_generator.state,
        "counters": {k: getattr(evaluator, k) for k in _COUNTERS},
    }
    arrays = {
        "meta": np.array(json.dumps(meta)),
        "pop_X": np.asarray(pop.get("X"), bool),
        "pop_F": np.asarray(pop.get("F"), float),
        "pop_G": np.asarray(pop.get("G"), float),
        "pop_CV": np.asarray(pop.get("CV"), float),
        "pop_rank": np.asarray(pop.get("rank"), np.int64),
        "pop_crowding": np.asarray(pop.get("crowding"), float),
        "cache_keys": (np.frombuffer(b"".join(keys), np.uint8).reshape(len(keys), nbytes)
                       if keys else np.zeros((0, nbytes), np.uint8)),
        "cache_scores": np.array([evaluator.cache[k] for k in keys], float),
        "archive_n": np.array([a[0] for a in archive], np.int64),
        "archive_score": np.array([a[1] for a in archive], float),
        "archive_serial": np.array([a[2] for a in archive], np.int64),
        "archive_keys": (np.frombuffer(b"".join(a[3] for a in archive), np.uint8)
                         .reshape(len(archive), nbytes) if archive
                         else np.zeros((0, nbytes), np.uint8)),
        "elite_scores": np.asarray(evaluator.elite_scores, float),
        "elites": np.asarray(evaluator.elites, float),
    }
    with atomic_path(Path(path), "--checkpoint") as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **arrays)


def load_checkpoint(path, fingerprint: str, n_points: int) -> dict:
    """Read and validate a checkpoint; returns ``{"meta": dict, <array name>: ndarray}``."""
    path = Path(path)
    if path.is_dir():
        _refuse(path, "is a folder, not a checkpoint file")
    try:
        with np.load(path, allow_pickle=False) as archive:
            if not isinstance(archive, np.lib.npyio.NpzFile):
                _refuse(path, "not an irreflect selection checkpoint (a bare array, not an "
                              "archive)")
            data = {name: archive[name] for name in archive.files if name in _ARRAYS}
    except IrreflectError:
        raise
    except ValueError as exc:  # pickles are refused here, before anything is unpickled
        with open(path, "rb") as fh:
            head = fh.read(4)
        if head.startswith(b"\x80") or "Object arrays" in str(exc):
            reason = "a pickle, which irreflect never loads"
        else:
            reason = "not a NumPy archive"
        _refuse(path, f"not an irreflect selection checkpoint ({reason})")
    except (OSError, EOFError, zipfile.BadZipFile, KeyError) as exc:
        _refuse(path, f"cannot be read as an irreflect selection checkpoint "
                      f"({type(exc).__name__}: truncated or corrupt)")
    missing = [k for k in _ARRAYS if k not in data]
    if missing:
        _refuse(path, f"not an irreflect selection checkpoint (no '{missing[0]}' array)")
    try:
        meta = json.loads(str(data["meta"]))
    except ValueError:
        _refuse(path, "corrupt checkpoint (its metadata is not JSON)")
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        _refuse(path, "not an irreflect selection checkpoint (no format tag)")
    if meta.get("version") != VERSION:
        _refuse(path, f"checkpoint format version {meta.get('version')}; this irreflect "
                      f"reads version {VERSION}")
    if meta.get("fingerprint") != fingerprint:
        raise IrreflectError(
            f"{path}: checkpoint of a different run (other data, model, seed, population or "
            "selection settings): use another --checkpoint file or delete this one"
        )
    _check_arrays(path, data, meta, n_points)
    data["meta"] = meta
    return data


def _check_arrays(path, data, meta, n_points) -> None:
    for name, (kinds, ndim) in _ARRAYS.items():
        arr = data[name]
        if arr.dtype.kind not in kinds or arr.ndim != ndim:
            _refuse(path, f"corrupt checkpoint ('{name}' has dtype {arr.dtype}, "
                          f"{arr.ndim} dimensions)")
    nbytes = (n_points + 7) // 8
    pop = len(data["pop_X"])
    shapes_ok = (
        meta.get("n_points") == n_points and data["pop_X"].shape[1] == n_points
        and all(len(data[k]) == pop for k in ("pop_F", "pop_G", "pop_CV", "pop_rank",
                                              "pop_crowding"))
        and data["cache_keys"].shape == (len(data["cache_scores"]), nbytes)
        and data["archive_keys"].shape == (len(data["archive_n"]), nbytes)
        and len(data["archive_score"]) == len(data["archive_serial"]) == len(data["archive_n"])
        and isinstance(meta.get("generation"), int) and meta["generation"] >= 0
        and isinstance(meta.get("rng"), dict) and isinstance(meta.get("counters"), dict)
        and all(k in meta["counters"] for k in _COUNTERS)
    )
    if not shapes_ok:
        _refuse(path, "corrupt checkpoint (its arrays do not fit together)")


def restore(state: dict, algorithm, evaluator) -> int:
    """Put a loaded checkpoint into a set-up (not yet run) NSGA-II ``algorithm`` and its
    ``evaluator``; returns the generation reached."""

    meta = state["meta"]
    evaluator.cache = {row.tobytes(): float(s)
                       for row, s in zip(state["cache_keys"], state["cache_scores"], strict=True)}
    evaluator.archive = {}
    for k, score, serial, key in zip(state["archive_n"], state["archive_score"],
                                     state["archive_serial"], state["archive_keys"], strict=True):
        evaluator.archive.setdefault(int(k), []).append((float(score), int(serial), key.tobytes()))
    for entries in evaluator.archive.values():
        entries.sort()
    evaluator.elite_scores = np.asarray(state["elite_scores"], float)
    evaluator.elites = np.asarray(state["elites"], float).reshape(
        len(evaluator.elite_scores), evaluator.model.n_nonlinear)
    for k in _COUNTERS:
        setattr(evaluator, k, type(getattr(evaluator, k))(meta["counters"][k]))
    pop = Population.new("X", state["pop_X"].astype(bool))
    pop.set("F", state["pop_F"], "G", state["pop_G"], "H", np.zeros((len(pop), 0)),
            "CV", state["pop_CV"], "rank", state["pop_rank"].astype(int),
            "crowding", state["pop_crowding"])
    for ind in pop:
        ind.evaluated = {"F", "G", "H"}
    algorithm.pop = pop
    algorithm.off = None
    algorithm.n_iter = int(meta["n_iter"])
    algorithm.evaluator.n_eval = int(meta["n_eval"])
    try:
        algorithm.random_state.bit_generator.state = meta["rng"]
    except (TypeError, ValueError, KeyError) as exc:
        raise IrreflectError(f"corrupt checkpoint (random generator state: {exc}); delete it "
                             "to start afresh") from None
    algorithm.is_initialized = True
    algorithm.start_time = time.time()
    algorithm._set_optimum()
    return int(meta["generation"])
