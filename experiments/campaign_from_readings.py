"""Campaigns that start from readings the user already has: k settings of each dense table
drawn at random (seeded), given to ``Campaign(tool, rows)``, then irreflect's proposals one
at a time up to --n-max readings. Prints per table the first N from which R^2 against all
points stays within 0.01 of the all-points fit, the verdict's first stop and R^2 at 12 and
15 (docs/campaign.md, "Readings of your own first").

    .venv/bin/python experiments/campaign_from_readings.py --given 6 --seed 1
    .venv/bin/python experiments/campaign_from_readings.py --given 4 --seed 3 TABLE.csv ...
"""

from __future__ import annotations

import argparse
import sys
import warnings

import numpy as np


def run(path: str, given: int, seed: int, n_max: int) -> str:
    from irreflect.campaign import Campaign, DenseInstrument
    from irreflect.data import read_measurements
    from irreflect.fitting import fit

    dense = read_measurements(path)
    source = DenseInstrument(dense)
    if not 0 <= given <= dense.n_points:
        raise ValueError(f"--given {given}: expected 0 to {dense.n_points} readings, the "
                         "table's points; pass a smaller --given")
    target = fit(dense).r2 - 0.01
    pick = np.random.default_rng(seed).choice(dense.n_points, given, replace=False)
    rows = dense.to_frame().iloc[pick][["gamma_deg", "theta_deg", "power"]]
    campaign = Campaign(source.instrument(), rows if given else None, seed=0, name=dense.name,
                        noise_floor=max(0.0, -float(np.min(dense.power))))
    rng = np.random.default_rng([0, 11])
    r2, stop = {}, None
    while campaign.n_measured < n_max and campaign.n_free:
        p = campaign.propose(1)
        campaign.add(p[["gamma_deg", "theta_deg"]].assign(
            power=source.read(p["gamma_deg"], p["theta_deg"], rng)))
        r2[campaign.n_measured] = campaign.r2_against(dense)
        if stop is None and campaign.verdict().stop:
            stop = campaign.n_measured
    hold = next((n for n in sorted(r2) if all(r2[m] >= target for m in r2 if m >= n)), None)
    at = r2.get(stop, float("nan")) if stop else float("nan")
    return (f"{dense.name:28s} given {given}  target {target:.4f}  holds from {hold}  "
            f"stop {stop} ({at:.4f})  R2@12 {r2.get(12, float('nan')):.4f}  "
            f"@15 {r2.get(15, float('nan')):.4f}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("tables", nargs="*", help="dense tables (default: every real set)")
    parser.add_argument("--given", type=int, default=6, help="random readings given first")
    parser.add_argument("--seed", type=int, default=1, help="seeds the random readings")
    parser.add_argument("--n-max", type=int, default=18)
    args = parser.parse_args(argv)
    from irreflect.data import real_datasets

    tables = args.tables or [str(p) for _, p in sorted(real_datasets().items())]
    if not tables:
        print("no tables: pass dense tables, or put ../shared/datasets/real beside the clone")
        return 2
    warnings.simplefilter("ignore")
    from irreflect.errors import IrreflectError

    for path in tables:
        try:
            print(run(path, args.given, args.seed, args.n_max), flush=True)
        except (IrreflectError, ValueError) as exc:  # a missing table, --given too large
            print(f"campaign_from_readings: {path}: {' '.join(str(exc).split())}",
                  file=sys.stderr)
            return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
