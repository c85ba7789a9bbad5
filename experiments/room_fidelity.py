"""In-plane fidelity of the room's reciprocal surface model on every table we have.

For each bundled reconstruction and each real table (``../shared/datasets/real``, when it is
beside the checkout): fit the two-lobe model (seed 0), build the room material in both
surface models, and print the R^2 of their in-plane curves

* of the reciprocal form against the fitted curve (over the measured angles of incidence),
* of the reciprocal form on the material's own table,
* of the paper's form (the fitted curve itself, up to its per-gamma normalisation) on it,

plus the albedo range over incidence and any warning (energy cap). The numbers in
docs/room.md come from this script.

    python experiments/room_fidelity.py [--reflectance 0.5]
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

from irreflect.data import bundled_dir
from irreflect.fitting import fit
from irreflect.paper import real_data_dir
from irreflect.room.materials import from_model


def tables():
    for name in ("terrazzo", "plasterboard", "foam_board"):
        yield "bundled", bundled_dir() / f"{name}.csv"
    real = real_data_dir()
    if real is None:
        print("(real data not beside the checkout: bundled tables only)")
        return
    for path in sorted(Path(real).rglob("*.csv")):
        yield "real", path


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--reflectance", type=float, default=0.5,
                   help="diffuse reflectance given to every material (default 0.5)")
    args = p.parse_args(argv)
    print(f"{'table':34s} {'fit R^2':>8s} {'recip/curve':>11s} {'recip/table':>11s} "
          f"{'paper/table':>11s} {'terms':>5s}  albedo over incidence")
    worst = []
    for origin, path in tables():
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = fit(str(path), "two-lobe", seed=0)
            params = dict(zip(res.param_names, map(float, res.values), strict=True))
            g = np.abs(res.gamma_deg)
            mat = from_model("two-lobe", params, args.reflectance, name=path.stem,
                             gamma_max_deg=float(g.max()),
                             metadata={"data_file": str(path),
                                       "gamma_range_deg": [float(g.min()), float(g.max())]})
        fid = mat.fidelity
        worst.append(fid["r2_table_paper"] - fid["r2_table_reciprocal"])
        note = "; capped" if any("capped" in w for w in mat.warnings) else ""
        print(f"{origin + ' ' + path.stem:34s} {res.r2:8.4f} {fid['r2_curve']:11.4f} "
              f"{fid['r2_table_reciprocal']:11.4f} {fid['r2_table_paper']:11.4f} "
              f"{fid['terms']:5d}  {mat.rho_table.min():.3g}-{mat.rho_table.max():.3g}{note}"
              f"  ({time.perf_counter() - t0:.1f} s)", flush=True)
    print(f"R^2 on the table, paper form minus reciprocal form: median {np.median(worst):.4f}, "
          f"largest {np.max(worst):.4f}")


if __name__ == "__main__":
    main()
