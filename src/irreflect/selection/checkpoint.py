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

import hashlib
import io
import json
import math
import time
import zipfile
from pathlib import Path

import numpy as np
from numpy.lib import format as npformat
from pymoo.core.population import Population

from .. import schema as sc
from .._atomic import atomic_path
from .._inputs import parse_json, read_bytes
from ..errors import IrreflectError, SchemaError

FORMAT = "irreflect-selection-checkpoint"
VERSION = 4  # 4: a digest of the arrays; the metadata checked against a declared schema
#: Checkpoints larger than this (read, or decompressed from the archive) are refused.
MAX_CHECKPOINT_BYTES = 2**30
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
_COUNT = sc.Integer(lo=0, hi=2**62)
#: The declared schema of a checkpoint's metadata (every key, type and range).
META_SCHEMA = sc.Table({
    "format": sc.Choice(options=(FORMAT,)), "version": sc.Integer(),
    "fingerprint": sc.Text(max_len=128), "digest": sc.Text(max_len=128),
    "generation": _COUNT, "seconds": sc.Number(lo=0.0), "n_points": sc.Integer(lo=1),
    "n_iter": sc.Integer(lo=1, hi=2**62), "n_eval": _COUNT,
    "rng": sc.Table({
        "bit_generator": sc.Choice(options=("PCG64",)),
        "state": sc.Table({"state": sc.Integer(lo=0, hi=2**128 - 1),
                           "inc": sc.Integer(lo=0, hi=2**128 - 1)},
                          required=("state", "inc")),
        "has_uint32": sc.Integer(lo=0, hi=1), "uinteger": sc.Integer(lo=0, hi=2**32 - 1),
    }, required=("bit_generator", "state", "has_uint32", "uinteger")),
    "counters": sc.Table({"evaluations": _COUNT, "failed_fits": _COUNT, "cache_hits": _COUNT,
                          "fit_seconds": sc.Number(lo=0.0), "_serial": _COUNT},
                         required=_COUNTERS),
}, required=("format", "version", "fingerprint", "digest", "generation", "seconds",
             "n_points", "n_iter", "n_eval", "rng", "counters"))


def _refuse(path, what: str):
    raise IrreflectError(f"{path}: {what}; delete the file (or use another --checkpoint) to "
                         "start afresh")


def _digest(arrays: dict, meta: dict) -> str:
    """SHA-256 of the metadata (but its digest) and of every array but ``meta`` (name,
    dtype, shape and bytes): a checkpoint edited or damaged after it was written is refused
    rather than resumed from."""
    h = hashlib.sha256()
    h.update(json.dumps({k: v for k, v in meta.items() if k != "digest"}, sort_keys=True)
             .encode())
    for name in sorted(arrays):
        if name == "meta":
            continue
        arr = np.ascontiguousarray(arrays[name])
        h.update(f"{name}|{arr.dtype.str}|{arr.shape}|".encode())
        h.update(arr.tobytes())
    return h.hexdigest()


def save_checkpoint(path, fingerprint: str, algorithm, evaluator, generation: int,
                    seconds: float) -> None:
    """Write the state of ``algorithm`` (pymoo NSGA-II) and ``evaluator`` atomically."""
    pop = algorithm.pop
    nbytes = (evaluator.n + 7) // 8
    keys = list(evaluator.cache)
    archive = [(n, score, serial, key) for n, entries in sorted(evaluator.archive.items())
               for score, serial, key in entries]
    arrays = {
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
    meta = {
        "format": FORMAT, "version": VERSION, "fingerprint": fingerprint,
        "generation": int(generation), "seconds": float(seconds), "n_points": evaluator.n,
        "n_iter": int(algorithm.n_iter), "n_eval": int(algorithm.evaluator.n_eval),
        "rng": algorithm.random_state.bit_generator.state,
        "counters": {k: getattr(evaluator, k) for k in _COUNTERS},
    }
    meta["digest"] = _digest(arrays, json.loads(json.dumps(meta)))
    arrays["meta"] = np.array(json.dumps(meta))
    with atomic_path(Path(path), "--checkpoint") as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **arrays)


def load_checkpoint(path, fingerprint: str, n_points: int, n_nonlinear: int | None = None) -> dict:
    """Read and validate a checkpoint; returns ``{"meta": dict, <array name>: ndarray}``.

    The file is read within :data:`MAX_CHECKPOINT_BYTES` (its archive members too, counted
    as they are decompressed, not as declared), every array is checked for its dtype and
    shape, the metadata against :data:`META_SCHEMA`, and the arrays against the digest
    written with them. ``n_nonlinear``: the width of the elite optima, when known.
    """
    path = Path(path)
    if path.is_dir():
        _refuse(path, "is a folder, not a checkpoint file")
    raw = read_bytes(path, "--checkpoint", "an irreflect selection checkpoint",
                     MAX_CHECKPOINT_BYTES, reading="--checkpoint")
    data = _read_archive(path, raw)
    missing = [k for k in _ARRAYS if k not in data]
    if missing:
        _refuse(path, f"not an irreflect selection checkpoint (no '{missing[0]}' array)")
    meta, written = _read_meta(path, data["meta"], fingerprint)
    if _digest(data, written) != meta["digest"]:
        _refuse(path, "the checkpoint was modified after it was written (it does not match "
                      "its digest)")
    _check_arrays(path, data, meta, n_points, n_nonlinear)
    data["meta"] = meta
    return data


def _read_archive(path: Path, raw: bytes) -> dict:
    """The arrays of a NumPy ``.npz`` archive in ``raw``, each decompressed within what is
    left of :data:`MAX_CHECKPOINT_BYTES` and parsed without pickle."""
    if raw[:6] == b"\x93NUMPY":
        _refuse(path, "not an irreflect selection checkpoint (a bare NumPy array, not an "
                      "archive)")
    if raw[:1] == b"\x80":
        _refuse(path, "not an irreflect selection checkpoint (a pickle, which irreflect "
                      "never loads)")
    try:
        archive = zipfile.ZipFile(io.BytesIO(raw))
    except (zipfile.BadZipFile, OSError, ValueError, EOFError):
        _refuse(path, "not an irreflect selection checkpoint (not a NumPy archive)"
                if not raw[:2] == b"PK" else "cannot be read as an irreflect selection "
                "checkpoint (truncated or corrupt)")
    left = MAX_CHECKPOINT_BYTES
    data = {}
    with archive:
        for info in archive.infolist():
            name = info.filename.removesuffix(".npy")
            if name not in _ARRAYS:
                continue
            if info.file_size > left:
                _too_large(path)
            try:
                with archive.open(info) as member:
                    content = member.read(left + 1)
            except (zipfile.BadZipFile, OSError, EOFError, ValueError, NotImplementedError,
                    RuntimeError):
                _refuse(path, "cannot be read as an irreflect selection checkpoint "
                              "(truncated or corrupt)")
            if len(content) > left:
                _too_large(path)
            left -= len(content)
            data[name] = _read_npy(path, name, content)
    return data


def _too_large(path):
    _refuse(path, f"decompresses to more than {MAX_CHECKPOINT_BYTES // 2**20} MB, more than "
                  "a checkpoint of a run within its budget holds")


def _read_npy(path: Path, name: str, content: bytes) -> np.ndarray:
    """One ``.npy`` member: its header's shape and dtype checked against its length before
    anything is allocated; object arrays (pickles) refused."""
    buf = io.BytesIO(content)
    try:
        version = npformat.read_magic(buf)
        header = (npformat.read_array_header_1_0 if version == (1, 0)
                  else npformat.read_array_header_2_0)
        shape, _fortran, dtype = header(buf)
    except (ValueError, OSError, EOFError, SyntaxError, TypeError):
        _refuse(path, f"corrupt checkpoint (array '{name}' has no NumPy header)")
    if dtype.hasobject:
        _refuse(path, "not an irreflect selection checkpoint (object arrays are pickles, "
                      "which irreflect never loads)")
    count = math.prod(int(d) for d in shape)
    if count * dtype.itemsize != len(content) - buf.tell():
        _refuse(path, f"corrupt checkpoint (array '{name}' is truncated or padded: its "
                      f"header declares {count} values of {dtype.itemsize} bytes)")
    buf.seek(0)
    try:
        return np.load(buf, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        _refuse(path, f"corrupt checkpoint (array '{name}': {type(exc).__name__})")


def _read_meta(path: Path, arr, fingerprint: str) -> dict:
    if arr.dtype.kind != "U" or arr.ndim != 0:
        _refuse(path, "corrupt checkpoint (its metadata is not text)")
    try:
        meta = parse_json(str(arr), str(path), "a checkpoint's metadata (JSON)")
    except IrreflectError:
        _refuse(path, "corrupt checkpoint (its metadata is not JSON)")
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        _refuse(path, "not an irreflect selection checkpoint (no format tag)")
    if meta.get("version") != VERSION:
        _refuse(path, f"checkpoint format version {sc.found(meta.get('version'))}; this "
                      f"irreflect reads version {VERSION}")
    written = meta
    try:
        meta = sc.validate(META_SCHEMA, meta, f"{path} (metadata)")
    except SchemaError as exc:
        _refuse(path, f"corrupt checkpoint ({str(exc).removeprefix(f'{path} (metadata): ')})")
    if meta["fingerprint"] != fingerprint:
        raise IrreflectError(
            f"{path}: checkpoint of a different run (other data, model, seed, population or "
            "selection settings): use another --checkpoint file or delete this one"
        )
    return meta, written


def _check_arrays(path, data, meta, n_points, n_nonlinear=None) -> None:
    for name, (kinds, ndim) in _ARRAYS.items():
        arr = data[name]
        if arr.dtype.kind not in kinds or arr.ndim != ndim:
            _refuse(path, f"corrupt checkpoint ('{name}' has dtype {arr.dtype}, "
                          f"{arr.ndim} dimensions)")
    nbytes = (n_points + 7) // 8
    pop = len(data["pop_X"])
    shapes_ok = (
        meta["n_points"] == n_points and data["pop_X"].shape[1] == n_points and pop >= 1
        and all(len(data[k]) == pop for k in ("pop_F", "pop_G", "pop_CV", "pop_rank",
                                              "pop_crowding"))
        and data["pop_F"].shape[1] == 2 and data["pop_CV"].shape[1] == 1
        and data["cache_keys"].shape == (len(data["cache_scores"]), nbytes)
        and data["archive_keys"].shape == (len(data["archive_n"]), nbytes)
        and len(data["archive_score"]) == len(data["archive_serial"]) == len(data["archive_n"])
        and data["elites"].shape[0] == len(data["elite_scores"])
        and (n_nonlinear is None or data["elites"].shape[1] == n_nonlinear)
    )
    if not shapes_ok:
        _refuse(path, "corrupt checkpoint (its arrays do not fit together)")
    values_ok = (
        all(np.all(np.isfinite(data[k])) for k in ("pop_F", "pop_G", "pop_CV", "cache_scores",
                                                   "archive_score", "elite_scores", "elites"))
        and not np.any(np.isnan(data["pop_crowding"]))
        and np.all(data["pop_rank"] >= 0) and np.all(data["archive_serial"] >= 0)
        and np.all((data["archive_n"] >= 1) & (data["archive_n"] <= n_points))
        and np.all(data["cache_scores"] >= 0) and np.all(data["archive_score"] >= 0)
        and np.array_equal(data["pop_F"][:, 0], data["pop_X"].sum(axis=1))
    )
    if not values_ok:
        _refuse(path, "corrupt checkpoint (values out of range: NaN, negative scores or "
                      "counts that do not match the masks)")


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
    elites = np.asarray(state["elites"], float)
    if elites.shape != (len(evaluator.elite_scores), evaluator.model.n_nonlinear):
        raise IrreflectError(f"corrupt checkpoint (elites of shape {elites.shape}, expected "
                             f"{len(evaluator.elite_scores)} x {evaluator.model.n_nonlinear}); "
                             "delete it to start afresh")
    evaluator.elites = elites
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
    except (TypeError, ValueError, KeyError, OverflowError) as exc:
        raise IrreflectError(f"corrupt checkpoint (random generator state: {exc}); delete it "
                             "to start afresh") from None
    algorithm.is_initialized = True
    algorithm.start_time = time.time()
    algorithm._set_optimum()
    return int(meta["generation"])
