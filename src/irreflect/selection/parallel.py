"""Several datasets x seeds in one call: a local process pool, or a Dask cluster.

Every run is independent and deterministic given its seed, so the results are identical
whether the runs go one after the other, to local worker processes or to the workers of a
``dask.distributed`` scheduler (``--scheduler tcp://host:8786``). Results come back in
task order (dataset-major, then seed).

Ctrl-C: the runs in progress stop at their next generation and return what they found
(:attr:`SelectionResult.interrupted`); runs not yet started are dropped.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import multiprocessing as mp
import os
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

from ..data import Measurements, as_measurements
from ..errors import IrreflectError
from ..validation import check_int, check_seed, short_list
from .run import SelectionResult, compare_methods, run_selection


@dataclass
class RunOutcome:
    """One finished run: its dataset name, seed, result and Methods A/B/12."""

    dataset: str
    seed: int
    result: SelectionResult
    methods: dict | None
    #: warnings the run raised, (category, message): raised again in the calling process
    #: (a worker process would print them with its own source lines)
    warned: list = field(default_factory=list)


@dataclass
class _Task:
    meas: Measurements
    seed: int
    kwargs: dict
    with_methods: bool
    checkpoint: str | None


def _run_task(task: _Task) -> RunOutcome:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = run_selection(task.meas, seed=task.seed, checkpoint=task.checkpoint,
                            progress=False, **task.kwargs)
        methods = None
        if task.with_methods and not res.interrupted:
            methods = compare_methods(task.meas, res, model=task.kwargs.get("model", "two-lobe"),
                                      seed=task.seed)
    warned = [(w.category, str(w.message)) for w in caught]
    return RunOutcome(task.meas.name, task.seed, res, methods, warned)


def _warn_again(outcomes) -> None:
    """The runs' warnings, raised in this process (the CLI prints each once, one line)."""
    for outcome in outcomes:
        for category, message in outcome.warned:
            warnings.warn(message, category if isinstance(category, type)
                          and issubclass(category, Warning) else UserWarning, stacklevel=3)


def _tasks(datasets, seeds, kwargs, with_methods, checkpoint_dir) -> list[_Task]:
    tables = [as_measurements(d) for d in datasets]
    names = [t.name for t in tables]
    if len(set(names)) != len(names):
        raise IrreflectError(
            "datasets must have distinct names (file stems) in one run; found "
            f"{short_list(names)}: rename the files"
        )
    seeds = [check_seed(s, "seeds") for s in seeds]
    if not tables or not seeds:
        raise IrreflectError("run_many needs at least one dataset and one seed")
    if len(set(seeds)) != len(seeds):
        raise IrreflectError(f"seeds must be distinct; found {short_list(seeds)}")
    out = []
    for t in tables:
        for s in seeds:
            ckpt = None
            if checkpoint_dir is not None:
                ckpt = str(Path(checkpoint_dir) / f"{t.name}_seed{s}.ckpt")
            out.append(_Task(t, s, dict(kwargs), with_methods, ckpt))
    return out


#: Thread pools of the numerical libraries: one thread per worker process (a user's own
#: setting of these variables is kept), so that N workers use N cores, not N x cores.
WORKER_THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                           "VECLIB_MAXIMUM_THREADS", "NUMBA_NUM_THREADS")


@contextlib.contextmanager
def one_thread_per_worker():
    """While worker processes start, their libraries' thread counts default to 1."""
    added = [k for k in WORKER_THREAD_VARIABLES if k not in os.environ]
    for k in added:
        os.environ[k] = "1"
    try:
        yield
    finally:
        for k in added:
            os.environ.pop(k, None)


def default_workers(n_runs: int) -> int:
    """Local worker processes when ``--workers`` is not given: one per core this process
    may use, at most one per run. With one library thread per worker
    (:func:`one_thread_per_worker`) the pool was faster than one process both on a quiet
    2-core machine (1.8x) and with one core kept busy by another process (1.3x); with the
    libraries' own threads it was slower (1.5x and 1.2x): ``experiments/bench_workers.py``."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (
        os.cpu_count() or 1)
    return max(1, min(cores, n_runs))


def run_many(datasets, seeds=(0,), *, scheduler=None, workers: int | None = None,
             progress: bool = False, with_methods: bool = True, checkpoint_dir=None,
             **kwargs) -> tuple[list[RunOutcome], bool]:
    """Run :func:`run_selection` for every dataset and seed.

    Parameters
    ----------
    datasets : Measurements, DataFrames or paths (names, i.e. file stems, must differ)
    seeds : seeds, one run per dataset and seed
    scheduler : None (local), a ``dask.distributed`` scheduler address or a ``Client``
    workers : local worker processes (default: :func:`default_workers`, one per core, at
        most one per run; 1 runs everything in this process). Each worker's numerical
        libraries use one thread (:func:`one_thread_per_worker`).
    checkpoint_dir : folder for one checkpoint per run (``<name>_seed<S>.ckpt``); with a
        Dask cluster it must be visible to the workers
    kwargs : passed to :func:`run_selection` (model, selector, pop_size, generations, ...)

    Returns
    -------
    (outcomes in task order, interrupted)
    """
    if workers is not None:
        check_int(workers, "workers", 1)
    if scheduler is not None and not isinstance(scheduler, str):
        from distributed import Client

        if not isinstance(scheduler, Client):
            raise IrreflectError(f"scheduler must be an address such as tcp://host:8786 or a "
                                 f"distributed.Client; found {type(scheduler).__name__}")
    elif scheduler is not None:
        check_scheduler_address(scheduler)
    if checkpoint_dir is not None:
        Path(checkpoint_dir).mkdir(parents=True, exist_ok=True)
    tasks = _tasks(datasets, seeds, kwargs, with_methods, checkpoint_dir)
    bar = None
    if progress:
        from .._progress import progress as progress_display

        bar = progress_display(total=len(tasks), desc="select runs", unit="run")
    try:
        if scheduler is not None:
            outcomes, interrupted = _run_dask(tasks, scheduler, bar)
        else:
            n_workers = min(workers, len(tasks)) if workers else default_workers(len(tasks))
            run = _run_serial if n_workers <= 1 else (
                lambda t, b: _run_pool(t, n_workers, b))
            outcomes, interrupted = run(tasks, bar)
        _warn_again(outcomes)
        return outcomes, interrupted
    finally:
        if bar is not None:
            bar.close()


def _tick(bar):
    if bar is not None:
        bar.update(1)


def _run_serial(tasks, bar):
    out = []
    for task in tasks:
        try:
            outcome = _run_task(task)
        except KeyboardInterrupt:
            return out, True
        out.append(outcome)
        _tick(bar)
        if outcome.result.interrupted:
            return out, True
    return out, False


def _collect(futures, results):
    """Results of the futures that finished cleanly, in task order."""
    out, interrupted = [], False
    for i in sorted(results):
        out.append(results[i])
        interrupted |= results[i].result.interrupted
    return out, interrupted or len(out) < len(futures)


def _run_pool(tasks, n_workers, bar):
    results: dict[int, RunOutcome] = {}
    ctx = mp.get_context("forkserver")
    with one_thread_per_worker():  # the workers (and a forkserver started now) inherit it
        pool = cf.ProcessPoolExecutor(max_workers=n_workers, mp_context=ctx)
        futures = {pool.submit(_run_task, t): i for i, t in enumerate(tasks)}
    try:
        for fut in cf.as_completed(futures):
            results[futures[fut]] = fut.result()
            _tick(bar)
    except KeyboardInterrupt:
        # workers got the same SIGINT: running ones return what they found so far
        for fut in futures:
            fut.cancel()
        done, _ = cf.wait(futures, timeout=60)
        for fut in done:
            if not fut.cancelled() and fut.exception() is None:
                results[futures[fut]] = fut.result()
        pool.shutdown(wait=False, cancel_futures=True)
        return _collect(futures, results)[0], True
    pool.shutdown()
    return _collect(futures, results)


_ADDRESS = re.compile(r"(?:(tcp|tls|inproc|ucx|ws|wss)://)?(\[[0-9a-fA-F:]+\]|[\w.-]+)"
                      r"(?::(\d{1,5}))?")


def check_scheduler_address(address) -> str:
    """A ``dask.distributed`` scheduler address (``tcp://host:8786``, ``host:8786``),
    checked before any work."""
    match = _ADDRESS.fullmatch(str(address).strip()) if isinstance(address, str) else None
    if match is None or (match.group(3) is None and match.group(1) != "inproc") or (
            match.group(3) is not None and not 0 < int(match.group(3)) < 65536):
        raise IrreflectError(
            f"--scheduler '{address}' is not a scheduler address: expected e.g. "
            "tcp://host:8786 (start one with 'dask scheduler'), or leave out --scheduler to "
            "use local processes"
        )
    return str(address).strip()


def _run_dask(tasks, scheduler, bar):
    try:
        from distributed import Client, as_completed
    except ImportError as exc:  # pragma: no cover - dask is a dependency
        raise IrreflectError("--scheduler needs dask.distributed: pip install distributed") from exc
    own = not isinstance(scheduler, Client)
    try:
        client = Client(check_scheduler_address(scheduler), timeout="10s") if own else scheduler
    except IrreflectError:
        raise
    except (OSError, ValueError, TypeError, TimeoutError) as exc:
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise IrreflectError(
            f"cannot reach the Dask scheduler at '{scheduler}' ({first}): start one with "
            "'dask scheduler' or leave out --scheduler to use local processes"
        ) from None
    results: dict[int, RunOutcome] = {}
    futures = client.map(_run_task, tasks, pure=False)
    index = {f.key: i for i, f in enumerate(futures)}
    try:
        for fut in as_completed(futures):
            results[index[fut.key]] = fut.result()
            _tick(bar)
    except KeyboardInterrupt:
        client.cancel(futures)
        return _collect(futures, results)[0], True
    finally:
        if own:
            client.close()
    return _collect(futures, results)
