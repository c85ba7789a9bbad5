"""Record adaptive campaigns reading by reading, for offline study of the rule.

Replays the adaptive campaign (as ``irreflect campaign`` does: the dense table as the
instrument, 25 readings, seed 0) on every table given, and keeps per reading the setting
and power read, the weighted fit's and the quadrature estimate's coefficients and R^2
against all points, the R^2 the campaign reports and the verdict (with how far the fits
without the last readings lie from the current one, and what keeps it from stopping: the
input of experiments/stop_rules.py). Faster than
``bench_campaign.py`` (no other strategy, no hindsight bound), and it keeps what the
benchmark does not: both fits, so that a choice between them, or a stop rule, can be
replayed offline (docs/campaign.md, stop 51). Usage::

    .venv/bin/python experiments/campaign_record.py OUT.json SOURCE [SOURCE ...]
        [--rule '{"leverage": 1.0}'] [--workers 2]

SOURCE: a CSV table, a folder of them (searched recursively), or ``gen:FIRST:N`` (the
benchmark's generated families, ``N`` of each from seed ``FIRST``). Rows are in the order
of the sources; labels may repeat across folders (the random held-out sets reuse names).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def jobs(sources, rule):
    out = []
    for s in sources:
        if s.startswith("gen:"):
            import bench_campaign

            _, first, n = s.split(":")
            out += [(label, kind, seed, rule)
                    for label, kind, seed in bench_campaign.generated(int(n), int(first))]
        elif os.path.isdir(s):
            out += [(p.stem, "file", str(p), rule) for p in sorted(Path(s).rglob("*.csv"))]
        else:
            out.append((Path(s).stem, "file", s, rule))
    return out


def _warm():
    warnings.simplefilter("ignore")
    from irreflect.fitting import warm

    warm()


def _fit_row(campaign, meas, res, key, rec):
    from irreflect.metrics import r2

    if res is None:
        return
    values = np.asarray(res.values, float)
    with np.errstate(all="ignore"):
        pred = campaign.model.predict_deg(values, meas.gamma_deg, meas.theta_deg)
    rec[key] = values.tolist()
    rec["r2" + key] = float(r2(meas.power, pred))


def run(job):
    label, kind, source, rule_changes = job
    warnings.simplefilter("ignore")
    import bench_campaign

    from irreflect.campaign import Campaign
    from irreflect.campaign.design import DEFAULT_RULE
    from irreflect.campaign.replay import DenseInstrument
    from irreflect.data import read_measurements
    from irreflect.fitting import fit_averaged
    from irreflect.models import get_model

    rule = dataclasses.replace(DEFAULT_RULE, **rule_changes)
    try:
        meas = (read_measurements(source, average_duplicates=True) if kind == "file"
                else bench_campaign.load(kind, int(source)))
        if len(np.unique(meas.gamma_deg)) < 3 or meas.n_points < 40:
            return {"label": label, "skipped": "fewer than 40 points or 3 angles of incidence"}
        dense = DenseInstrument(meas)
        reference = fit_averaged(meas, get_model("two-lobe"), 0.0, seed=0)
        campaign = Campaign(dense.instrument(), seed=0, rule=rule, name=meas.name,
                            noise_floor=max(0.0, -float(np.min(meas.power))))
        rng = np.random.default_rng([0, 11])  # the replay's readings
        rows, t0 = [], time.perf_counter()
        while campaign.n_measured < 25 and campaign.n_free:
            p = campaign.propose(1)
            power = dense.read(p["gamma_deg"], p["theta_deg"], rng)
            read = p[["gamma_deg", "theta_deg"]].assign(power=power)
            sigma = dense.reading_sigma(p["gamma_deg"], p["theta_deg"], power)
            campaign.add(read if sigma is None else read.assign(sigma=sigma))
            state, verdict = campaign._current(), campaign.verdict()
            rec = {"n": campaign.n_measured, "g": float(p.gamma_deg.iloc[0]),
                   "t": float(p.theta_deg.iloc[0]), "p": float(power[0]),
                   "stop": bool(verdict.stop), "why": str(p.why.iloc[0]),
                   # the verdict's parts, for stop rules replayed offline (stop_rules.py)
                   "moves": list(verdict.moves), "blocking": list(verdict.blocking)}
            _fit_row(campaign, meas, state.fit, "w", rec)
            _fit_row(campaign, meas, state.estimate, "e", rec)
            rec["r2rep"] = (float(campaign.r2_against(meas)) if campaign.fit is not None
                            else None)
            rows.append(rec)
        return {"label": label, "r2_all": float(reference.r2), "rows": rows,
                "seconds": time.perf_counter() - t0}
    except Exception as exc:  # noqa: BLE001 - recorded, the run goes on
        return {"label": label, "skipped": f"{type(exc).__name__}: {exc}"}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("out")
    parser.add_argument("sources", nargs="+")
    parser.add_argument("--rule", default="{}", help="DesignRule changes as a JSON object")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args(argv)
    todo = jobs(args.sources, json.loads(args.rule))
    with ProcessPoolExecutor(args.workers, initializer=_warm) as pool:
        rows = list(pool.map(run, todo))
    Path(args.out).write_text(json.dumps(rows))
    print(f"{len(rows)} tables recorded in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
