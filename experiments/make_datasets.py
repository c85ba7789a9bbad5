"""Regenerate the bundled, *reconstructed* datasets in ``datasets/``.

The paper's raw measurements were never published. This script rebuilds stand-ins for
its three materials from the coefficients of its Table 3, on its sampling plan
(sections 4.1 and 5.1), with Gaussian noise of a fixed seed:

* angles of incidence -10 to -60 deg in steps of 10;
* receiver angles between -70 and 70 deg, non-equidistant and denser near the mirror
  angle: every 10 deg from -70 to 70 (15 angles, which contain all of Table 1's points),
  plus 7 angles close to the mirror direction (mirror -15, -7, -5, -2, +2, +5, +7 deg)
  for terrazzo and foam board (22 per gamma, 132 points), or 2 (mirror +-5 deg) for
  plasterboard (17 per gamma, 102 points);
* additive Gaussian noise with a standard deviation per material (``NOISE_SIGMA``),
  chosen so that the RMSE of the 12-point protocol fit against all points is of the
  order of the paper's Table 2.

Run: ``python experiments/make_datasets.py`` (writes ``datasets/*.csv`` and prints the
12-point fit's RMSE beside Table 2).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from irreflect import fit  # noqa: E402
from irreflect.data import Measurements, write_measurements  # noqa: E402
from irreflect.models import two_lobe_power  # noqa: E402
from irreflect.paper import TABLE1, TABLE3  # noqa: E402

PAPER = ROOT.parent / "shared" / "paper" / "tables"
SEED = 20170919  # fixed: the bundled files are reproducible bit for bit
#: 1-sigma of the added noise (power units): about 0.8 x the paper's Table 2 RMSE
NOISE_SIGMA = {"terrazzo": 0.006, "plasterboard": 0.002, "foam_board": 0.015}


def sampling_plan(dense: bool) -> tuple[np.ndarray, np.ndarray]:
    """(gamma_deg, theta_deg) of the paper's plan: 22 (dense) or 17 thetas per gamma."""
    gammas, thetas = [], []
    for magnitude in range(10, 70, 10):
        mirror = magnitude
        near = [-15, -7, -5, -2, 2, 5, 7] if dense else [-5, 5]
        theta = sorted(set(range(-70, 71, 10)) | {mirror + d for d in near})
        theta = [t for t in theta if -70 <= t <= 70]
        gammas += [-magnitude] * len(theta)
        thetas += theta
    return np.array(gammas, float), np.array(thetas, float)


def make(material: str, rng: np.random.Generator) -> Measurements:
    gamma, theta = sampling_plan(dense=material != "plasterboard")
    clean = two_lobe_power(np.radians(gamma), np.radians(theta), *TABLE3[material])
    sigma = NOISE_SIGMA[material]
    power = clean + rng.normal(0.0, sigma, clean.size)
    return Measurements(
        gamma_deg=gamma, theta_deg=theta, power=np.round(power, 6),
        sigma=np.full(clean.size, sigma), material=material, name=material,
    )


def main() -> None:
    rng = np.random.default_rng(SEED)
    out = ROOT / "datasets"
    table2 = pd.read_csv(PAPER / "table2_fit_quality_12pt.csv").set_index("material") \
        if (PAPER / "table2_fit_quality_12pt.csv").exists() else None
    for material in TABLE3:
        meas = make(material, rng)
        write_measurements(meas, out / f"{material}.csv")
        assert len(meas.power) == (102 if material == "plasterboard" else 132)
        mask = np.zeros(meas.n_points, bool)
        for g, t in TABLE1:
            mask |= (meas.gamma_deg == g) & (meas.theta_deg == t)
        twelve = fit(meas.subset(mask), use_sigma=False)
        pred = twelve.predict(meas.gamma_deg, meas.theta_deg)
        rmse = float(np.sqrt(np.mean((meas.power - pred) ** 2)))
        paper = f"{table2.loc[material, 'rmse']:.4f}" if table2 is not None else "n/a"
        print(f"{material:<13} {meas.n_points} points  noise sigma {NOISE_SIGMA[material]:.4f}  "
              f"12-point fit RMSE on all points {rmse:.4f}  (paper's Table 2: {paper})")


if __name__ == "__main__":
    main()
