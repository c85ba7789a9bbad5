"""Identification and false-alarm rates of the discrepancy workflow on hidden effects.

For every kind of case (no effect, each catalogue effect, each effect outside the
catalogue) the generator of :mod:`irreflect.diagnose.hidden` makes ``--seeds`` tables and
:func:`irreflect.diagnose.diagnose` runs blind on each. Reported per kind:

* no effect: false alarms = an effect added, or a verdict other than "no missing effect";
* catalogue effect: identified = the first effect added is the hidden one; and how often
  the verdict is then "effects found" (residual consistent with the noise);
* outside effect: how often the verdict is "unexplained structure remains", and how often
  a catalogue name was (wrongly) given.

Usage::

    .venv/bin/python experiments/diagnose_rates.py --seeds 40 [--out rates.csv]

Seeds 1000.. are used (the tests use seeds below 100).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import pandas as pd
from tqdm import tqdm

from irreflect.diagnose import diagnose
from irreflect.diagnose.hidden import KINDS, OUTSIDE, hidden_case
from irreflect.diagnose.workflow import EFFECTS_FOUND, NO_MISSING_EFFECT, UNEXPLAINED


def run(kinds, seeds, first_seed=1000, **diagnose_kwargs) -> pd.DataFrame:
    rows = []
    jobs = [(k, s) for k in kinds for s in range(first_seed, first_seed + seeds)]
    for kind, seed in tqdm(jobs, desc="diagnose", file=sys.stderr, leave=False):
        case = hidden_case(kind, seed)
        t0 = time.perf_counter()
        d = diagnose(case.measurements, seed=seed, **diagnose_kwargs)
        best = d.candidates[0][0] if d.candidates else None
        rows.append({
            "kind": kind, "seed": seed, "sigma_column": case.truth["sigma_column"],
            "material": case.truth["material"], "n_points": case.truth["n_points"],
            "excess_chi2": round(case.truth["excess_chi2"], 1),
            "effects": "+".join(e.name for e in d.effects) or "-",
            "verdict": d.verdict,
            "best": best.name if best else "-",
            "best_dbic": round(best.delta_bic, 1) if best else float("nan"),
            "best_share": round(best.share_explained, 2) if best else float("nan"),
            "reason": best.reason if best else "",
            "chi2_dof_before": round(d.before.lack_of_fit.ratio, 3),
            "chi2_dof_after": round(d.after.lack_of_fit.ratio, 3),
            "seconds": round(time.perf_counter() - t0, 2),
        })
    return pd.DataFrame(rows)


def summarise(df: pd.DataFrame) -> pd.DataFrame:
    """One row per kind; ``rate`` over all cases, ``rate, excess >= 150`` over the clearly
    visible ones (the excess chi2 of the base model on the noise-free table)."""
    rows = []
    for kind, g in df.groupby("kind", sort=False):
        row = _summary_row(kind, g)
        strong = g[g["excess_chi2"] >= 150]
        row["rate, excess >= 150"] = (_summary_row(kind, strong)["rate"]
                                      if kind != "none" and len(strong) else float("nan"))
        row["cases, excess >= 150"] = len(strong) if kind != "none" else 0
        rows.append(row)
    return pd.DataFrame(rows)


def _summary_row(kind, g) -> dict:
    n = len(g)
    first = g["effects"].str.split("+").str[0]
    if kind == "none":
        alarms = (g["effects"] != "-") | (g["verdict"] != NO_MISSING_EFFECT)
        return {"kind": kind, "cases": n, "measure": "false alarms", "rate": alarms.mean(),
                "detail": f"effect added {int((g['effects'] != '-').sum())}, verdict not "
                          f"'{NO_MISSING_EFFECT}' {int((g['verdict'] != NO_MISSING_EFFECT).sum())}"}
    if kind in OUTSIDE:
        ok = g["verdict"] == UNEXPLAINED
        return {"kind": kind, "cases": n, "measure": "'unexplained' verdict", "rate": ok.mean(),
                "detail": f"catalogue name given {int((g['effects'] != '-').sum())}"}
    ident = first == kind
    clean = ident & (g["effects"] == kind) & (g["verdict"] == EFFECTS_FOUND)
    wrong = (g["effects"] != "-") & ~ident
    return {"kind": kind, "cases": n, "measure": "identified", "rate": ident.mean(),
            "detail": f"then consistent with noise {int(clean.sum())}, wrong name "
                      f"{int(wrong.sum())}, nothing named {int((g['effects'] == '-').sum())}"}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=40, help="cases per kind")
    parser.add_argument("--kinds", default=",".join(KINDS),
                        help=f"comma-separated kinds (default all: {','.join(KINDS)})")
    parser.add_argument("--first-seed", type=int, default=1000)
    parser.add_argument("--out", help="write the per-case table as CSV")
    args = parser.parse_args(argv)
    kinds = [k for k in args.kinds.split(",") if k]
    t0 = time.perf_counter()
    df = run(kinds, args.seeds, args.first_seed)
    if args.out:
        from irreflect._atomic import atomic_path

        with atomic_path(Path(args.out)) as tmp:
            df.to_csv(tmp, index=False)
    pd.set_option("display.width", 200)
    pd.set_option("display.max_colwidth", 120)
    pct = "{:.0%}".format
    print(summarise(df).to_string(index=False, formatters={"rate": pct,
                                                           "rate, excess >= 150": pct}))
    print(f"\n{len(df)} cases in {time.perf_counter() - t0:.0f} s "
          f"(median {df['seconds'].median():.2f} s per diagnosis)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
