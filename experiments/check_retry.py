"""Check: is fit() global on tables unlike the ones it was tuned on? (its second search)

Tables of :func:`irreflect.synthetic.wild_material`, a generator independent of the one
the fitter was tuned on (other distributions, other grids, other noise): per seed, a
two-lobe material of one of four kinds (glossy: u_ns 10^1.5 to 10^5, mirror-like: u_ns
10^3.5 to 10^5.5 and a large specular share, matte, diffuse: u_as 10^-4 to 10^-2), K from
10^-6 to 10^6, 1 to 8 angles of incidence of 3 to 79 deg, receivers every 1 to 20 deg
with a random offset (half the tables with a point within 2 deg of the mirror), and
proportional, additive or mixed noise of 0.03 % to 5 %, with a ``sigma`` column on 30 %
of the tables (then the fit is weighted by 1/sigma^2, over up to 10 decades).

A global optimum is at least as good as the generating coefficients on the same noisy
table, so every fit is held to ``cost <= (1 + 1e-6) * cost(generating coefficients)``.
Each table is fitted with fit()'s defaults, ``retry=False`` (the first search alone) and
``retry=True`` (a second, wider search when the first result looks like a local optimum,
:func:`irreflect.fitting.retry_reasons`). Printed: the failures of each, how many tables
were searched twice, fit times, and every table that fails.

Run: ``.venv/bin/python experiments/check_retry.py [--seeds 0 2000]``.
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from irreflect import fit
from irreflect._progress import progress
from irreflect.errors import FitError, FitWarning
from irreflect.synthetic import wild_material


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs=2, default=[0, 2000],
                        metavar=("FIRST", "STOP"))
    args = parser.parse_args(argv)
    if not 0 <= args.seeds[0] < args.seeds[1]:
        parser.error(f"--seeds FIRST STOP needs 0 <= FIRST < STOP; found {args.seeds[0]} "
                     f"{args.seeds[1]}")
    seeds = range(*args.seeds)
    fails = {False: [], True: []}
    times = {False: [], True: []}
    retried = 0
    fit(wild_material(0).measurements, seed=0, retry=False)  # the kernel's cache, outside the times
    with warnings.catch_warnings(), progress(len(seeds), "tables") as bar:
        warnings.simplefilter("ignore", FitWarning)
        for seed in seeds:
            case = wild_material(seed)
            table, kind, cost_truth = case.measurements, case.kind, case.cost_truth
            for retry in (False, True):
                t0 = time.perf_counter()
                try:
                    result = fit(table, seed=seed, retry=retry)
                    cost, r2 = result.cost, result.r2
                    retried += retry and bool(result.retried)
                except FitError:
                    cost, r2 = np.inf, np.nan
                times[retry].append(time.perf_counter() - t0)
                if not cost <= (1 + 1e-6) * cost_truth:
                    fails[retry].append(
                        f"seed {seed} ({kind}, {table.n_points} points, "
                        f"{'weighted' if table.sigma is not None else 'unweighted'}): cost "
                        f"{cost / cost_truth:.4g} x the generating coefficients', R^2 {r2:.6f}")
            bar.update()
    n = len(seeds)
    print(f"{n} generated tables (seeds {args.seeds[0]}-{args.seeds[1] - 1}); a fit fails "
          "when its cost exceeds the generating coefficients' by more than 1e-6")
    for retry, label in ((False, "first search only (retry=False)"),
                         (True, "fit() default (retry=True)     ")):
        ms = np.array(times[retry]) * 1e3
        print(f"  {label}: {len(fails[retry]):4d} failures; fit time median {np.median(ms):.1f} "
              f"ms, 90th percentile {np.percentile(ms, 90):.1f} ms, worst {ms.max():.0f} ms")
        for line in fails[retry]:
            print(f"      {line}")
    print(f"  searched a second time: {retried} of {n} tables")


if __name__ == "__main__":
    main()
