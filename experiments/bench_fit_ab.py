"""Benchmark: ``irreflect.fit`` of two checkouts interleaved in one run (a refactor's
speed against the code it replaces, on a shared machine).

Two worker processes, one per source tree (``PYTHONPATH``), each warmed up, then fit the
same table in alternating blocks of 50 fits until each has done ``--fits``; the medians,
10th percentiles and their ratio are printed, and whether both gave the same cost and
coefficients. Make the baseline tree with e.g. ``git archive main | tar -x -C /tmp/base``.

Run: ``.venv/bin/python experiments/bench_fit_ab.py /tmp/base/src src datasets/terrazzo.csv``
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys

_WORKER = r"""
import json, sys, time, warnings
import irreflect
from irreflect.data import read_measurements
from irreflect.errors import FitWarning
warnings.simplefilter("ignore", FitWarning)
meas = read_measurements(sys.argv[1])
r = irreflect.fit(meas, seed=0)
for _ in range(20):
    irreflect.fit(meas, seed=0)
print(json.dumps([r.cost] + [float(v) for v in r.values]), flush=True)
for line in sys.stdin:
    ts = []
    for _ in range(int(line)):
        t = time.perf_counter()
        irreflect.fit(meas, seed=0)
        ts.append(time.perf_counter() - t)
    print(json.dumps(ts), flush=True)
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("baseline_src")
    ap.add_argument("candidate_src")
    ap.add_argument("table")
    ap.add_argument("--fits", type=int, default=2000)
    args = ap.parse_args()
    procs = {}
    for name, src in (("baseline", args.baseline_src), ("candidate", args.candidate_src)):
        env = dict(os.environ, PYTHONPATH=os.path.abspath(src))
        procs[name] = subprocess.Popen([sys.executable, "-c", _WORKER, args.table], env=env,
                                       text=True, stdin=subprocess.PIPE,
                                       stdout=subprocess.PIPE)
    first = {k: json.loads(p.stdout.readline()) for k, p in procs.items()}
    times = {k: [] for k in procs}
    block = 50
    for i in range(max(1, args.fits // block)):
        order = ("baseline", "candidate") if i % 2 == 0 else ("candidate", "baseline")
        for k in order:
            procs[k].stdin.write(f"{block}\n")
            procs[k].stdin.flush()
            times[k] += json.loads(procs[k].stdout.readline())
    for p in procs.values():
        p.stdin.close()
        p.wait()
    print(f"{args.table}: same cost and coefficients: {first['baseline'] == first['candidate']}")
    for k, ts in times.items():
        ts = sorted(ts)
        print(f"  {k:<9}: {len(ts)} fits, median {statistics.median(ts) * 1e3:.3f} ms, "
              f"10th percentile {ts[len(ts) // 10] * 1e3:.3f} ms")
    ratio = statistics.median(times["candidate"]) / statistics.median(times["baseline"])
    print(f"  candidate / baseline (medians): {ratio:.3f}")


if __name__ == "__main__":
    main()
