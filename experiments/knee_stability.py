"""Does the knee move with the budget or the seed? The report's search (population 100) on
every bundled set, seeds 0 and 1, after 100 and after 200 generations (the 200-generation
run continues the 100-generation one from its checkpoint, which gives the uninterrupted
run's result); prints the knee, "enough points" with its range, the best 12 and the
all-points R^2.

    .venv/bin/python experiments/knee_stability.py                 # about 4 minutes
    .venv/bin/python experiments/knee_stability.py --data path/to/scan.csv --seeds 0 1 2
"""

from __future__ import annotations

import argparse
import tempfile
import time
import warnings
from pathlib import Path

from irreflect.data import BUNDLED, load_bundled, read_measurements
from irreflect.selection import run_selection


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", nargs="+", default=list(BUNDLED),
                    help="bundled names or table paths (default: the bundled sets)")
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1])
    ap.add_argument("--generations", nargs="+", type=int, default=[100, 200])
    ap.add_argument("--pop-size", type=int, default=100)
    args = ap.parse_args()
    warnings.simplefilter("ignore")  # fit warnings of individual subsets
    for name in args.data:
        meas = load_bundled(name) if name in BUNDLED else read_measurements(name)
        for seed in args.seeds:
            with tempfile.TemporaryDirectory() as tmp:
                ckpt = Path(tmp) / "search.ckpt"
                for gens in sorted(args.generations):
                    t0 = time.perf_counter()
                    r = run_selection(meas, seed=seed, pop_size=args.pop_size, generations=gens,
                                      checkpoint=ckpt, checkpoint_every=min(args.generations))
                    f = r.front.set_index("n_points")
                    best12 = f"{f.loc[12, 'r2']:.5f}" if 12 in f.index else "n/a"
                    print(f"{meas.name:<13} seed {seed} {gens:>3} generations: knee {r.knee_n} "
                          f"(R^2 {f.loc[r.knee_n, 'r2']:.5f}), enough points "
                          f"{r.enough.range_text()} at sigma {r.enough.sigma:.3g}, best 12 R^2 "
                          f"{best12}, all points {1 - r.front_summary.reference:.5f} "
                          f"({time.perf_counter() - t0:.1f} s)", flush=True)


if __name__ == "__main__":
    main()
