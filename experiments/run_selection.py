"""Full selection runs: every selector at the same budget of subset fits, on the bundled sets.

Prints, per dataset and selector, the hypervolume of the checked frontier (reference point
(N/n, 1 - R^2) = (1, 1)), the knee, R^2 of the best 12 points, fits and time, and Methods
A / B / 12 for NSGA-II. Long: a few minutes with the defaults.

    .venv/bin/python experiments/run_selection.py [--pop-size 100] [--generations 100]
        [--max-points 30] [--seeds 0 1] [--data FILE ...]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import pandas as pd

from irreflect.data import BUNDLED, load_bundled, read_measurements
from irreflect.selection import SELECTORS, compare_methods, run_selection


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--pop-size", type=int, default=100)
    ap.add_argument("--generations", type=int, default=100)
    ap.add_argument("--max-points", type=int, default=30)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--data", nargs="*", help="tables (default: the bundled datasets)")
    args = ap.parse_args()
    tables = ([read_measurements(p) for p in args.data] if args.data
              else [load_bundled(n) for n in BUNDLED])
    rows = []
    for meas in tables:
        for seed in args.seeds:
            for selector in SELECTORS:
                t0 = time.perf_counter()
                res = run_selection(meas, selector=selector, pop_size=args.pop_size,
                                    generations=args.generations, seed=seed,
                                    max_points=args.max_points)
                row = {"dataset": meas.name, "seed": seed, "selector": selector,
                       "hypervolume": round(res.hypervolume, 6), "knee_n": res.knee_n,
                       "r2_best12": round(1 - res.best_score(12), 5)
                       if res.best_mask(12) is not None else np.nan,
                       "r2_best8": round(1 - res.best_score(8), 5)
                       if res.best_mask(8) is not None else np.nan,
                       "fits": res.evaluations, "fits_per_s": round(res.fits_per_second),
                       "seconds": round(time.perf_counter() - t0, 1)}
                if selector == "nsga2":
                    m = compare_methods(meas, res, seed=seed)
                    row |= {"A": round(m["A"]["r2"], 5), "B": round(m["B"]["r2"], 5),
                            "12": round(m["12"]["r2"], 5), "order": m["order_holds"]}
                rows.append(row)
                print(pd.DataFrame([row]).to_string(index=False, header=len(rows) == 1),
                      flush=True)
    print()
    print(pd.DataFrame(rows).to_string(index=False))


if __name__ == "__main__":
    main()
