"""The evidence behind the protocol verdict's pass / marginal / fails rule
(:mod:`irreflect.protocol.advice`, docs/protocol.md).

    .venv/bin/python experiments/protocol_verdict_rule.py [--generated 15] [--random 20]

On every real set of at most 300 points in ``../shared/datasets/real`` and on generated
glossy, matte (3 % proportional noise) and wild materials (seeds 0..N-1), it fits the
two-lobe model on the points of 12-point designs (the paper's protocol, the glossy-aware
one and ``--random`` random ones: three angles of incidence, four measured receivers each)
and scores each against all points next to the fit on all points. It prints

1. per set: the paper's and the glossy-aware protocol's drop of R^2, the verdict and its
   causes;
2. per bin of the drop: the share of designs whose polar-area error at some angle of
   incidence exceeds the all-points fit's by more than 10 and 25 points (the reflected
   power at that incidence wrong by that much);
3. on the generated tables: how closely the drop measured on the noisy table follows the
   loss against the noise-free generating curve (is the drop the protocol's, or noise?).

Takes 2-4 minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

from irreflect import metrics
from irreflect.data import read_measurements, real_datasets
from irreflect.errors import FitError, FitWarning, IrreflectError
from irreflect.fitting import fit
from irreflect.protocol.advice import noise_fraction
from irreflect.protocol.evaluate import (
    evaluate_protocol,
    glossy_protocol_for,
    paper_protocol_for,
)
from irreflect.synthetic import synthetic_material, wild_material

BINS = [(0, 0.005), (0.005, 0.01), (0.01, 0.02), (0.02, 0.05), (0.05, 0.1), (0.1, 0.3),
        (0.3, np.inf)]


def tables(n_generated: int):
    for name, path in sorted(real_datasets().items()):
        meas = read_measurements(path)
        if meas.n_points <= 300:
            yield name, meas, None
    for seed in range(n_generated):
        for kind in ("glossy", "matte"):
            t = synthetic_material(seed, kind, noise=0.03)
            yield t.measurements.name, t.measurements, t.clean
        t = wild_material(seed)
        if np.unique(t.measurements.gamma_deg).size >= 3:
            yield t.measurements.name, t.measurements, t.clean


def polar_excess(meas, reference, predict) -> float:
    pa = metrics.polar_area_errors(meas.gamma_deg, meas.theta_deg, meas.power, reference.predict)
    pp = metrics.polar_area_errors(meas.gamma_deg, meas.theta_deg, meas.power, predict)
    return max(np.nan_to_num(pp[g] - pa[g], nan=1e9) for g in pa)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--generated", type=int, default=15, help="seeds per generator")
    ap.add_argument("--random", type=int, default=20, help="random designs per table")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", FitWarning)
    rng = np.random.default_rng(args.seed)
    pairs, truth = [], []  # (drop, excess polar error); (drop, drop against the truth)
    print(f"{'table':<26}{'R^2 all':>9}{'noise':>8}  {'protocol':<8}{'drop':>9}  verdict "
          "(causes)")
    for name, meas, clean in tables(args.generated):
        reference = fit(meas)
        frac = noise_fraction(meas, meas.power - reference.predict(meas.gamma_deg,
                                                                   meas.theta_deg))
        for label, make in (("paper", lambda m=meas: paper_protocol_for(m)),
                            ("glossy", lambda m=meas, r=reference: glossy_protocol_for(m, r))):
            try:
                ev = evaluate_protocol(make(), meas, reference=reference)
            except (IrreflectError, FitError):
                continue
            v = ev.verdict
            kinds = ", ".join(c.kind for c in v.causes)
            print(f"{name[:25]:<26}{reference.r2:9.4f}{frac:8.4f}  {label:<8}"
                  f"{v.judgement.drop:9.4f}  {v.status}" + (f" ({kinds})" if kinds else ""))
        gammas = np.unique(meas.gamma_deg)
        for _ in range(args.random):
            idx = []
            for g in rng.choice(gammas, 3, replace=False):
                rows = np.nonzero(meas.gamma_deg == g)[0]
                idx += list(rng.choice(rows, min(4, rows.size), replace=False))
            mask = np.zeros(meas.n_points, bool)
            mask[idx] = True
            try:
                sub = fit(meas.subset(mask))
            except (IrreflectError, FitError):
                continue
            pred = sub.predict(meas.gamma_deg, meas.theta_deg)
            drop = reference.r2 - metrics.r2(meas.power, pred)
            pairs.append((drop, polar_excess(meas, reference, sub.predict)))
            if clean is not None:
                ref_pred = reference.predict(meas.gamma_deg, meas.theta_deg)
                truth.append((drop, metrics.r2(clean, ref_pred) - metrics.r2(clean, pred)))
    p = np.array(pairs)
    print(f"\n{len(p)} random 12-point designs: drop of R^2 against the share whose "
          "polar-area error at some |gamma| exceeds the all-points fit's by more than")
    print(f"{'drop':>14}{'designs':>9}{'10 points':>11}{'25 points':>11}")
    for lo, hi in BINS:
        sel = (p[:, 0] > lo) & (p[:, 0] <= hi)
        if sel.any():
            print(f"{lo:>6g}-{hi:<7g}{int(sel.sum()):>9d}{np.mean(p[sel, 1] > 10):>11.2f}"
                  f"{np.mean(p[sel, 1] > 25):>11.2f}")
    t = np.array(truth)
    small = t[:, 1] < 0.1  # designs near the pass / fail limits
    diff = np.abs(t[small, 0] - t[small, 1])
    print(f"\ngenerated tables, {int(small.sum())} designs losing less than 0.1 against the "
          f"truth: |drop on the noisy table - loss against the generating curve| median "
          f"{np.median(diff):.4f}, 90th percentile {np.quantile(diff, 0.9):.4f}; the two "
          f"sides of 0.01 agree on {np.mean((t[small, 0] <= 0.01) == (t[small, 1] <= 0.01)):.0%}"
          f", of 0.05 on {np.mean((t[small, 0] <= 0.05) == (t[small, 1] <= 0.05)):.0%}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
