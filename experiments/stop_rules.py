"""Stop rules replayed on recorded campaigns: how the verdict would do if it judged the
curve's last moves otherwise.

The verdict stops when the fits without the last 1, 2 and 3 readings all lie within 1 % of
the current fit's variance from it (``irreflect.campaign.core.STOP_TOLERANCE``,
``STOP_HOLD``), and nothing else keeps it from stopping. The proposals do not depend on
how the moves are judged, so a recording of whole campaigns
(``experiments/campaign_record.py``, which keeps every verdict's ``moves`` and
``blocking``) replays any rule that judges the same moves: the largest (the campaign's),
the mean, the median, the oldest fit given twice the tolerance, the tolerance growing
with how far back the fit is, and only the last two fits (``STOP_HOLD`` 1). Per recording
it prints the verdicts that are right by the benchmark's target (experiments/bench_campaign.py:
within 3 readings of the first N from which the reported R^2 stays within 0.01 of the
all-points fit, and never 0.02 below it), and how the others fail. The first rule, the
campaign's own, must reproduce the recorded stops ("recorded stops reproduced"). Usage::

    .venv/bin/python experiments/campaign_record.py real.json ../shared/datasets/real
    .venv/bin/python experiments/stop_rules.py real.json [more.json ...] [--tolerance 0.01]

docs/campaign.md ("At stop 53") quotes it on the real sets and seven held-out sets.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench_campaign's judgement

#: the verdict's reasons that are about the moves (every other one blocks any rule)
MOVE_REASONS = ("the last ", "the curve must hold")


def _twice_oldest(m):
    return float(np.max(m / np.r_[np.ones(len(m) - 1), 2.0]))


RULES = {
    "largest (the campaign's)": lambda m: float(np.max(m)),
    "mean": lambda m: float(np.mean(m)),
    "median": lambda m: float(np.median(m)),
    "oldest at twice": _twice_oldest,
    "growing with age": lambda m: float(np.max(m / np.arange(1, len(m) + 1))),
    "last two only": lambda m: float(np.max(m[:2])),
}


def stop_at(rows, rule, tolerance: float) -> int | None:
    """The first N at which ``rule`` of the recorded moves stops (None: never)."""
    for r in rows:
        blocking = r.get("blocking")
        if blocking is None or r.get("moves") is None:
            raise SystemExit("the recording has no verdict moves: record it again with "
                             "experiments/campaign_record.py (stop 53 or later)")
        if any(not b.startswith(MOVE_REASONS) for b in blocking):
            continue
        m = np.array([np.inf if v is None else v for v in r["moves"]], float)
        if m.size and np.all(np.isfinite(m)) and rule(m) <= tolerance:
            return int(r["n"])
    return None


def holds_from(rows, target: float) -> int | None:
    """The first N from which the reported R^2 stays at or above ``target``."""
    first = None
    for r in reversed(rows):
        if r.get("r2rep") is None or not r["r2rep"] >= target:
            break
        first = int(r["n"])
    return first


def judge(table, stop: int | None) -> str:
    """``ok``, ``late``, ``below`` or ``never``: bench_campaign.stop_ok's judgement."""
    from bench_campaign import stop_ok

    rows = {int(r["n"]): r for r in table["rows"]}
    r2 = rows[stop].get("r2rep") if stop is not None else None
    good, why = stop_ok({"stop": stop, "N": holds_from(table["rows"], table["r2_all"] - 0.01),
                         "stop_r2": -np.inf if r2 is None else r2,
                         "r2_all": table["r2_all"]})
    if good:
        return "ok"
    return "never" if stop is None else "late" if why.startswith("late") else "below"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("records", nargs="+", help="JSON files of campaign_record.py")
    parser.add_argument("--tolerance", type=float, default=0.01,
                        help="the share of the curve's variance (default 0.01, the campaign's)")
    args = parser.parse_args(argv)
    totals = {name: {"ok": 0, "late": 0, "below": 0, "never": 0} for name in RULES}
    count = 0
    for path in args.records:
        try:
            data = json.loads(Path(path).read_text())
        except (OSError, ValueError) as exc:
            raise SystemExit(f"stop_rules.py: {path}: expected a JSON recording of "
                             f"experiments/campaign_record.py; found {exc}") from None
        tables = [t for t in (data if isinstance(data, list) else [])
                  if isinstance(t, dict) and "rows" in t]
        if not tables:
            raise SystemExit(f"stop_rules.py: {path}: expected a list of recorded campaigns "
                             "(experiments/campaign_record.py); found none: record them again")
        count += len(tables)
        same = sum(stop_at(t["rows"], RULES["largest (the campaign's)"], args.tolerance)
                   == next((int(r["n"]) for r in t["rows"] if r["stop"]), None)
                   for t in tables)
        print(f"{path}: {len(tables)} campaigns; recorded stops reproduced: {same}/"
              f"{len(tables)}" + ("" if args.tolerance == 0.01 else " (other tolerance)"))
        for name, rule in RULES.items():
            kinds = [judge(t, stop_at(t["rows"], rule, args.tolerance)) for t in tables]
            for k in kinds:
                totals[name][k] += 1
            print(f"  {name:26s} right {kinds.count('ok'):4d}  late {kinds.count('late'):3d}"
                  f"  0.02 below {kinds.count('below'):3d}  never {kinds.count('never'):3d}")
    if len(args.records) > 1:
        print(f"all {count} campaigns:")
        for name, t in totals.items():
            print(f"  {name:26s} right {t['ok']:4d}  late {t['late']:3d}  0.02 below "
                  f"{t['below']:3d}  never {t['never']:3d}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
