"""Held-out generator no. 5 (stop 52): Beckmann lobes, Fresnel shares, sheens, sigma columns.

A small generator written at stop 52 without reading the others, to vary what they assume:
every table carries a ``sigma`` column (1 % of the power plus a floor of 0.2 % of the
diffuse level), its receiver step is 0.5-2.5 deg, its angles of incidence 3-6 of
-5..-75 deg, its power scale 1e-3..1e4, and the receiver is kept 4 deg off the source.
The material is ``scale * ((1 - F) * diffuse + 0.3 * F * specular)`` in the plane of
incidence, with ``F`` a Schlick Fresnel share ``F0 + (1 - F0) (1 - cos gamma)^5`` and
``specular`` a Beckmann distribution of the half angle ``(theta + gamma) / 2``. Kinds
(``KINDS[seed % 5]``):

``beckmann``      the above, roughness 0.05-0.3
``fresnel_sat``   the share tripled and capped at 1: it saturates toward grazing
``sheen``         a diffuse curve times ``1 + 0.8 sin^4 theta`` (brighter at grazing
                  reception; outside the two-lobe model and the diagnosis's catalogue)
``wide_grazing``  a roughness that grows as ``1 + 2 sin|gamma|``
``two_scale``     70 % of the lobe at the roughness, 30 % four times wider

Usage::

    .venv/bin/python experiments/unseen_tables5.py OUT --first 0 --count 40
    .venv/bin/python experiments/bench_campaign.py --real-only --data-dir OUT --generations 30

Tables are ``OUT/u52_SSS_KIND.csv``; the same seed gives the same table.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

KINDS = ("beckmann", "fresnel_sat", "sheen", "wide_grazing", "two_scale")
STEPS = (1.0, 2.0, 0.5, 2.5, 1.5)


def table(seed: int) -> tuple[str, pd.DataFrame]:
    rng = np.random.default_rng(seed)
    kind, step = KINDS[seed % 5], STEPS[seed % 5]
    gammas = -np.array(sorted(rng.choice([5, 10, 20, 25, 30, 40, 45, 50, 60, 65, 70, 75],
                                         size=rng.integers(3, 7), replace=False)))
    scale = 10.0 ** rng.uniform(-3, 4)
    rough = rng.uniform(0.05, 0.3)
    f0 = rng.uniform(0.02, 0.2)
    albedo = rng.uniform(0.1, 0.9)
    rows = []
    for g in gammas:
        th = np.arange(-85, 85.01, step)
        th = th[np.abs(th - g) > 4]  # the receiver kept off the source
        gi, tr = np.radians(-g), np.radians(th)
        dev = np.radians(th + g) / 2.0  # the half angle's tilt from the normal, in plane
        share = f0 + (1 - f0) * (1 - np.cos(gi)) ** 5
        if kind == "fresnel_sat":
            share = np.minimum(1.0, share * 3)
        w = rough * (1 + (2.0 * np.sin(gi) if kind == "wide_grazing" else 0))
        spec = np.exp(-np.tan(dev) ** 2 / w ** 2) / (np.pi * w ** 2 * np.cos(dev) ** 4)
        if kind == "two_scale":
            wide = 4 * w
            spec = 0.7 * spec + 0.3 * np.exp(-np.tan(dev) ** 2 / wide ** 2) / (
                np.pi * wide ** 2 * np.cos(dev) ** 4)
        spec = spec / (4 * np.maximum(np.cos(tr), 0.05)) * np.cos(tr)
        diffuse = albedo / np.pi * np.cos(tr)
        if kind == "sheen":
            diffuse = diffuse * (1 + 0.8 * np.sin(np.abs(tr)) ** 4)
        power = scale * ((1 - share) * diffuse + share * spec * 0.3)
        sigma = 0.01 * power + 0.002 * scale * albedo / np.pi
        power = power + sigma * rng.standard_normal(power.size)
        rows.append(pd.DataFrame({"gamma_deg": g, "theta_deg": th, "power": power,
                                  "sigma": sigma}))
    return kind, pd.concat(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("outdir", type=Path)
    ap.add_argument("--first", type=int, default=0, help="first seed (default 0)")
    ap.add_argument("--count", type=int, default=40, help="number of tables (default 40)")
    args = ap.parse_args(argv)
    args.outdir.mkdir(parents=True, exist_ok=True)
    for seed in range(args.first, args.first + args.count):
        kind, frame = table(seed)
        frame.to_csv(args.outdir / f"u52_{seed:03d}_{kind}.csv", index=False)
    print(f"wrote {args.count} tables to {args.outdir}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
