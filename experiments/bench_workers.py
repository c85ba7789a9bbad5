"""Is a local process pool faster than one process for ``irreflect select`` runs?

Runs the same command (several DATA files x ``--seeds``, a small budget) with
``--workers 1`` and ``--workers 2`` (and, for comparison, with 2 workers whose numerical
libraries keep their own thread pools), each in a fresh process so that the pool's
start-up is counted, interleaved and repeated so that a busy machine hits every variant
alike. Prints wall times and subset fits per second of the whole command.

    .venv/bin/python experiments/bench_workers.py                 # terrazzo + plasterboard,
                                                                  # seeds 0 1, 20 generations
    .venv/bin/python experiments/bench_workers.py --generations 60 --repeats 3
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                    "NUMBA_NUM_THREADS")


def run(data, seeds, generations, workers, env_extra) -> tuple[float, int]:
    """Wall time and subset fits of one ``select`` command (``workers`` None: default)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out"
        cmd = [sys.executable, "-m", "irreflect.cli", "select", *map(str, data), "--seeds",
               *map(str, seeds), "--generations", str(generations),
               *([] if workers is None else ["--workers", str(workers)]),
               "--quiet", "--out", str(out)]
        env = {k: v for k, v in os.environ.items() if k not in THREAD_VARIABLES} | env_extra
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, env=env, capture_output=True)
        seconds = time.perf_counter() - t0
        summary = json.loads((out / "summary.json").read_text())
        fits = sum(r["evaluations"] for r in summary["runs"])
    return seconds, fits


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", nargs="+", default=[ROOT / "datasets" / "terrazzo.csv",
                                                 ROOT / "datasets" / "plasterboard.csv"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1])
    ap.add_argument("--generations", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--busy", action="store_true",
                    help="keep one core busy with a spinning process during the runs (a "
                         "shared machine)")
    args = ap.parse_args()
    cores = os.cpu_count() or 1
    variants = {
        "--workers 1 (this process)": (1, {}),
        "--workers 2 (one thread each)": (2, {}),
        f"--workers 2, {cores} library threads each": (2, {k: str(cores)
                                                           for k in THREAD_VARIABLES}),
        "no --workers (the default)": (None, {}),
    }
    print(f"machine: {cores} CPUs; load average {os.getloadavg()[0]:.2f}; "
          f"{len(args.data)} table(s) x seeds {args.seeds}, {args.generations} generations, "
          f"{args.repeats} repeats, interleaved")
    times = {name: [] for name in variants}
    fits = {}
    spinner = None
    if args.busy:
        spinner = subprocess.Popen([sys.executable, "-c", "while True: pass"])
        time.sleep(65)  # let the 1-minute load average see it
        print(f"  a spinning process keeps one core busy; load average "
              f"{os.getloadavg()[0]:.2f}")
    try:
        for _ in range(args.repeats):
            for name, (workers, env) in variants.items():
                seconds, n = run(args.data, args.seeds, args.generations, workers, env)
                times[name].append(seconds)
                fits[name] = n
    finally:
        if spinner is not None:
            spinner.kill()
            spinner.wait()
    serial = statistics.median(times["--workers 1 (this process)"])
    for name, values in times.items():
        med = statistics.median(values)
        print(f"  {name:<40} median {med:6.1f} s  ({', '.join(f'{v:.1f}' for v in values)})  "
              f"{fits[name] / med:7.0f} fits/s  {serial / med:4.2f}x the serial speed")
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
