"""The adaptive campaign on grids of the real sets it was not tuned on.

Each real set in ../shared/datasets/real/ is cut three ways, and each cut is used as the
instrument of a replayed adaptive campaign (``irreflect.campaign.replay.replay_adaptive``,
20 readings, seed 0):

  drop-mid    the middle angle of incidence removed (a gap in gamma the grid never had)
  thin2       every second receiver angle at each angle of incidence (a coarser scan)
  no-normal   the normal incidence row removed (where there is one; Cornell has none)

Per cut it prints the table's all-points R^2, the first N from which the campaign stays
within 0.01 of it (up to 20; "-" if never), where the verdict first says stop and the R^2
there (more than 0.02 below the all-points R^2 is a failed stop), and the slowest proposal.
The cuts change the range the campaign must predict and the settings it may take; no rule
was chosen on them. Usage::

    .venv/bin/python experiments/campaign_variants.py [--workers 2] [--readings 20]

About 45 s on 2 cores.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

CUTS = ("drop-mid", "thin2", "no-normal")


def cut(meas, how: str):
    """The table cut as ``how`` says (see the module docstring)."""
    gammas = meas.gammas
    if how == "drop-mid":
        keep = ~np.isclose(meas.gamma_deg, gammas[len(gammas) // 2])
    elif how == "thin2":
        keep = np.zeros(meas.n_points, bool)
        for g in gammas:
            idx = np.flatnonzero(np.isclose(meas.gamma_deg, g))
            keep[idx[np.argsort(meas.theta_deg[idx])][::2]] = True
    elif how == "no-normal":
        keep = np.abs(meas.gamma_deg) > 1.0
    else:
        raise ValueError(how)
    return meas.subset(keep)


def run(job):
    path, how, readings, changes = job
    warnings.simplefilter("ignore")
    from irreflect import fit
    from irreflect.campaign import DenseInstrument
    from irreflect.campaign.replay import replay_adaptive
    from irreflect.data import read_measurements

    table = cut(read_measurements(path), how)
    target = fit(table, seed=0).r2 - 0.01
    from irreflect.campaign.design import DEFAULT_RULE

    rule = dataclasses.replace(DEFAULT_RULE, **changes)
    curve, verdicts, times = replay_adaptive(DenseInstrument(table), readings, seed=0,
                                             rule=rule)
    r2 = curve.r2
    held = [n for n in sorted(r2) if all(r2[k] >= target for k in r2 if k >= n)]
    stop = min((n for n, v in verdicts.items() if v.stop), default=None)
    return {"dataset": Path(path).stem, "cut": how, "points": table.n_points,
            "r2_all": target + 0.01, "N": held[0] if held else None, "stop": stop,
            "stop_r2": r2.get(stop, float("nan")) if stop else float("nan"),
            "slowest": max(times) if times else float("nan")}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--readings", type=int, default=20)
    parser.add_argument("--data-dir", default=None,
                        help="folder of tables (default ../shared/datasets/real)")
    parser.add_argument("--rule", nargs="+", default=[], metavar="KNOB=VALUE",
                        help="change numeric knobs of the adaptive rule "
                             "(irreflect.campaign.DesignRule), e.g. tie_ratio=0")
    args = parser.parse_args(argv)
    changes = {}
    for item in args.rule:
        key, _, value = item.partition("=")
        try:
            changes[key] = float(value)
        except ValueError:
            parser.error(f"--rule {item}: expected KNOB=NUMBER")
    if changes:
        print(f"rule: {changes}")
    root = Path(args.data_dir) if args.data_dir else (
        Path(__file__).resolve().parents[1].parent / "shared" / "datasets" / "real")
    files = sorted(root.rglob("*.csv"))
    if not files:
        print(f"no tables under {root}", file=sys.stderr)
        return 1
    jobs = [(str(f), how, args.readings, changes) for f in files for how in CUTS]
    t0 = time.perf_counter()
    rows = []
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_campaign import platform_line

    print(platform_line())
    print(f"{'dataset':28} {'cut':10} {'pts':>5} {'R2 all':>7} {'N':>3} {'stop (R2)':>14} "
          f"{'slowest (s)':>11}")
    with ProcessPoolExecutor(args.workers) as ex:
        for r in ex.map(run, jobs):
            rows.append(r)
            stop = "never" if r["stop"] is None else f"{r['stop']} ({r['stop_r2']:.4f})"
            n = "-" if r["N"] is None else str(r["N"])
            print(f"{r['dataset'][:28]:28} {r['cut']:10} {r['points']:5d} {r['r2_all']:7.4f} "
                  f"{n:>3} {stop:>14} {r['slowest']:11.2f}", flush=True)
    within = [r for r in rows if r["N"] is not None and r["N"] <= 15]
    bad = [r for r in rows if r["stop"] is not None
           and r["stop_r2"] < r["r2_all"] - 0.02]
    print(f"\nwithin 0.01 of the all-points fit by N <= 15: {len(within)} of {len(rows)} cuts")
    print(f"stops more than 0.02 below it: {len(bad)} "
          + ", ".join(f"{r['dataset']} {r['cut']} ({r['r2_all'] - r['stop_r2']:.3f} below)"
                      for r in bad))
    print(f"{time.perf_counter() - t0:.0f} s in all")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
