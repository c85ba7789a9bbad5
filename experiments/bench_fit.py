"""Benchmark: one two-lobe fit, irreflect vs a plain ``scipy.optimize.curve_fit``.

Both fit the same bundled 132-point terrazzo table in the same run, repeatedly; the
script prints both medians, their ratio and the R^2 each reaches (a fast fit that
stops in a local optimum is no bargain).

* irreflect: ``irreflect.fit`` with everything it does for a user (data-driven and
  seeded random starts, variable projection, bounded LM, standard errors).
* baseline: ``curve_fit(two_lobe_power, ...)`` with default settings (LM, numerical
  Jacobian) from ``p0 = ones`` (curve_fit's default), plus a second baseline from a
  sensible physical start (Table 3's order of magnitude), since p0 = ones is unfair.

Run: ``python experiments/bench_fit.py [--repeats 200]`` (single core is enough; the
numbers in README.md come from this script).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.optimize import curve_fit

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from irreflect import fit, metrics  # noqa: E402
from irreflect.data import load_bundled  # noqa: E402
from irreflect.model import two_lobe_power  # noqa: E402


def _two_lobe_xy(x, *p):
    return two_lobe_power(x[0], x[1], *p)


def time_curve_fit(x, y, p0, repeats):
    times, r2 = [], float("nan")
    failures = 0
    for _ in range(repeats):
        t0 = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                popt, _ = curve_fit(_two_lobe_xy, x, y, p0=p0)
            r2 = metrics.r2(y, _two_lobe_xy(x, *popt))
        except (RuntimeError, ValueError):
            failures += 1
        times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1e3, r2, failures


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=200)
    parser.add_argument("--dataset", default="terrazzo")
    args = parser.parse_args(argv)

    meas = load_bundled(args.dataset)
    x = np.radians(np.vstack([meas.gamma_deg, meas.theta_deg]))
    y = meas.power
    fit(meas)  # warm-up (imports, caches)
    times = []
    for i in range(args.repeats):
        t0 = time.perf_counter()
        result = fit(meas, seed=i)
        times.append(time.perf_counter() - t0)
    ours = statistics.median(times) * 1e3

    base_ones, r2_ones, fail_ones = time_curve_fit(x, y, np.ones(7), args.repeats)
    p0 = [0.02, -2.0, 1.0, 0.5, 30.0, 0.0, 0.4]
    base_phys, r2_phys, fail_phys = time_curve_fit(x, y, p0, args.repeats)

    print(f"dataset {args.dataset}: {meas.n_points} points, {args.repeats} repeats, "
          f"pid {os.getpid()}, one process")
    print(f"irreflect.fit (two-lobe, {result.n_starts} starts, std. errors)  median "
          f"{ours:8.2f} ms   R^2 {result.r2:.6f}")
    print(f"curve_fit, default p0 = ones                           median {base_ones:8.2f} ms"
          f"   R^2 {r2_ones:.6f}   failures {fail_ones}/{args.repeats}")
    print(f"curve_fit, physical p0                                 median {base_phys:8.2f} ms"
          f"   R^2 {r2_phys:.6f}   failures {fail_phys}/{args.repeats}")
    print(f"ratio curve_fit(p0=ones) / irreflect: {base_ones / ours:.2f}x;  "
          f"curve_fit(physical p0) / irreflect: {base_phys / ours:.2f}x")
    print("paper (Table 4, MATLAB R2015, Core 2 Duo E8400): 273-660 ms per fit")


if __name__ == "__main__":
    main()
