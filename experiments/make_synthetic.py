"""Write a generated glossy or matte table (``irreflect.synthetic``) to try the commands on.

    .venv/bin/python experiments/make_synthetic.py --kind glossy --seed 7 --out glossy.csv

Writes the table (``gamma_deg, theta_deg, power``; 1 % proportional noise) and prints the
generating coefficients and the generating curve's R^2 on the noisy table: a global fit
must reach it (``irreflect fit glossy.csv``).
"""

from __future__ import annotations

import argparse

from irreflect.data import write_measurements
from irreflect.synthetic import GRIDS, KINDS, synthetic_material


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kind", choices=KINDS, default="glossy")
    ap.add_argument("--grid", choices=GRIDS, default=None, help="default: drawn by the seed")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", required=True, help="CSV or Parquet file")
    args = ap.parse_args(argv)
    case = synthetic_material(args.seed, args.kind, args.grid)
    write_measurements(case.measurements, args.out)
    names = ("u_as", "v_as", "u_nd", "v_nd", "u_ns", "v_ns", "K")
    print(f"wrote {args.out}: {case.kind} material, {case.grid} grid, seed {case.seed}, "
          f"{case.measurements.n_points} points")
    print("generating coefficients: " + ", ".join(f"{n} = {v:.4g}"
                                                  for n, v in zip(names, case.params, strict=True)))
    print(f"the generating curve's R^2 on the noisy table: {case.r2_truth:.6f}")


if __name__ == "__main__":
    main()
