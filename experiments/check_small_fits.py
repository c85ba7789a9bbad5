"""Check: is the fit of a 12-point protocol global? (the small-table search of fitting.fit)

For every real set in ``../shared/datasets/real`` the paper's 12-point protocol is snapped
to the measured points (as ``select``'s Method 12 does) and the two-lobe model is fitted to
those 12 points with ``--seeds`` seeds: with fit()'s defaults (on a table this small
``fitting.SMALL_TABLE_SEARCH``, then ``fitting.RETRY_SMALL_TABLE_SEARCH`` when the result
looks like a local optimum), with the small-table search alone (``retry=False``), and
with the search fit() uses first on large tables alone (96 screening candidates, 3 kept,
no basin hops, 3 rounds). Per set: the lowest cost any
run found, how many seeds of each search reach it (within 1e-6), the worst excess cost and
the mean time per fit.

Run: ``.venv/bin/python experiments/check_small_fits.py [--seeds 10]``.
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from irreflect import fit
from irreflect.data import read_measurements, real_datasets
from irreflect.errors import FitWarning, IrreflectError
from irreflect.fitting import SMALL_TABLE_SEARCH
from irreflect.protocol.points import paper_protocol_points
from irreflect.selection.run import snap_points

LARGE_TABLE_SEARCH = {"n_screen": 96, "n_keep": 3, "n_hops": 0, "max_rounds": 3}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    args = parser.parse_args(argv)
    searches = {"default (small-table search, second search if it looks local)": {},
                "small-table search alone": {"retry": False},
                "large-table search alone": {**LARGE_TABLE_SEARCH, "retry": False}}
    print(f"small-table search: {SMALL_TABLE_SEARCH}; seeds 0-{args.seeds - 1}")
    misses = dict.fromkeys(searches, 0)
    for name, path in real_datasets().items():
        meas = read_measurements(path)
        snapped = snap_points(meas, paper_protocol_points(meas))
        mask = np.zeros(meas.n_points, bool)
        mask[snapped["index"].to_numpy()] = True
        sub = meas.subset(mask)
        costs, ms = {}, {}
        for label, options in searches.items():
            c = []
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", FitWarning)
                for seed in range(args.seeds):
                    try:
                        c.append(fit(sub, seed=seed, **options).cost)
                    except IrreflectError:
                        c.append(np.inf)
            ms[label] = (time.perf_counter() - t0) / args.seeds * 1e3
            costs[label] = np.array(c)
        best = min(c.min() for c in costs.values())
        parts = []
        for label, c in costs.items():
            hits = int(np.sum(c <= best * (1 + 1e-6)))
            parts.append(f"{label}: {hits}/{args.seeds} reach it, worst +{c.max() / best - 1:.1%}"
                         f", {ms[label]:.1f} ms")
            misses[label] += args.seeds - hits
        print(f"{name:<24} best cost {best:.6g}; " + "; ".join(parts))
    for label, n in misses.items():
        print(f"{label}: {n} fit(s) short of the best cost found")


if __name__ == "__main__":
    main()
