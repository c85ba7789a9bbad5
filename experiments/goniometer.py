"""A stand-in goniometer for trying `irreflect next` without one: it answers the settings
of a NEXT.csv from a dense table of a real material (the power interpolated along theta at
the table's angles of incidence, as `irreflect campaign --method interpolate` does) and
appends the readings to MEASURED.csv (written atomically; its rows are kept).

    .venv/bin/python experiments/goniometer.py next.csv measured.csv \
        --dense ../shared/datasets/real/cornell/cornell_krylon_blue.csv

Optional relative power noise (--noise 0.01) and receiver angle error (--angle-error 0.2),
seeded (--seed).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("next", help="the settings to measure (irreflect next --out)")
    parser.add_argument("measured", help="the readings so far; the new ones are appended")
    parser.add_argument("--dense", required=True, help="dense table that plays the material")
    parser.add_argument("--noise", type=float, default=0.0)
    parser.add_argument("--angle-error", type=float, default=0.0)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)

    from irreflect._atomic import atomic_path
    from irreflect.campaign import DenseInstrument
    from irreflect.campaign.io import read_readings
    from irreflect.data import read_measurements

    source = DenseInstrument(read_measurements(args.dense), method="interpolate",
                             noise=args.noise, angle_error_deg=args.angle_error,
                             seed=args.seed)
    todo = pd.read_csv(args.next)
    done = read_readings(args.measured)
    rng = np.random.default_rng([args.seed, len(todo), 0 if done is None else done.n_points])
    power = source.read(todo["gamma_deg"], todo["theta_deg"], rng)
    new = pd.DataFrame({"gamma_deg": todo["gamma_deg"], "theta_deg": todo["theta_deg"],
                        "power": power})
    table = new if done is None else pd.concat(
        [done.to_frame()[["gamma_deg", "theta_deg", "power"]], new], ignore_index=True)
    with atomic_path(Path(args.measured)) as tmp:
        table.to_csv(tmp, index=False, float_format="%.6g")
    print(f"measured {len(new)} settings; {args.measured} now holds {len(table)} readings")
    return 0


if __name__ == "__main__":
    sys.exit(main())
