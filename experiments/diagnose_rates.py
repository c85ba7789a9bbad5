"""Right names, wrong names, false alarms and ambiguity reports of the diagnosis on the
harder blind set (:mod:`irreflect.diagnose.blind`), per base and per effect.

Every case is made by :func:`irreflect.diagnose.blind.blind_case` (glossy, medium-gloss
and matte bases with a saturating specular share; no effect, one effect or a pair, in forms
that are not all the catalogue's; additive and proportional noise; weak effects near the
detection limit; five kinds of grid) and :func:`irreflect.diagnose.diagnose` runs blind
on it. Seeds 0-299 were used while building the diagnosis; 10000.. were not (``--seeds
10000:10300``).

What the data can support, measured on the noise-free table (:func:`truth_analysis`):
every catalogue explanation ``S`` (the base model, each single effect and, for a pair,
each pair) is fitted to it as the diagnosis fits them, weighted by the noise as the table
can tell it: the true sigma when the table has a sigma column; otherwise the estimate
the diagnosis would make from the true residuals (no misfit leaking in: the best it can
do; at a lobe's peak seen by one receiver that is the upper bound the rest of the table
allows). The truth ``T`` (the catalogue names of the generating effects) is

* **identifiable** when every other explanation ``S`` with at most as many effects fits
  the noise-free table worse than ``T`` by at least ``lambda*``: the non-centrality at
  which the diagnosis' own likelihood-ratio test (level ``alpha / 6``, on the degrees of
  freedom ``T`` adds to ``S``; chi-square with a sigma column, F with the estimate's
  degrees of freedom without) rejects ``S`` with 95 % probability. ``S`` empty is
  detection; ``S`` a subset of a pair is seeing both members; ``S`` a rival is telling
  them apart. A case fails it when an effect is too weak for its noise, when a rival
  explanation mimics it on that grid (an offset and a tilt on three angles of
  incidence), or when the generating form is one the catalogue cannot follow (the
  reflectance ``1 + c sin^2 gamma`` on a glossy lobe measured at high signal-to-noise);
  and when, besides, no explanation with one effect more than ``T`` fits the noise-free
  table better than ``T`` by ``lambda*`` (*complete*): else the catalogue follows the
  generating forms better with a further name (a reflectance ``1 + c sin^2 gamma`` that
  ``cos^w`` plus a background follows), which the diagnosis then rightly adds. The
  summary also prints the rates on the earlier definition (rivals only, without
  completeness), to compare with the figures quoted before it.
* **detectable** when only the empty explanation is held to that bar.

Per case the outcome is: *right* (exactly the truth named, no ambiguity), *partial* (a
strict subset of the truth named), *wrong* (a name not in the truth given, without an
ambiguity report), *ambiguous* (an ambiguity report; counted "with truth" when one of its
alternatives is the truth, else also as wrong), *missed* (nothing named); on a table
without an effect, a *false alarm* is a name, an ambiguity report or a verdict other than
"no missing effect". The targets: right names >= 95 % and wrong names 0 % on the
identifiable cases, false alarms <= 2 %.

Usage::

    .venv/bin/python experiments/diagnose_rates.py [--seeds 0:300] [--jobs 2]
        [--no-saturate] [--out cases.csv]
    .venv/bin/python experiments/diagnose_rates.py --summarize part1.csv part2.csv

``--summarize`` prints the rates of per-case tables written by ``--out`` (a seed range run
in parts, joined) without diagnosing again.

``--no-saturate`` draws the same cases with the specular share kept below 0.95 on each
table (the paper's unbounded law then holds): it separates what the diagnosis does from
what a base model without the saturating share cannot fit.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import optimize, stats
from tqdm import tqdm

from irreflect.diagnose import CATALOGUE, diagnose
from irreflect.diagnose.blind import BASES, blind_case
from irreflect.errors import FitWarning

ALPHA = 0.01
N_TESTS = len(CATALOGUE)  # the diagnosis tests each step's extensions at alpha / (their number)
POWER = 0.95


def lambda_star(df: int, noise_dof: float = np.inf, alpha: float = ALPHA,
                power: float = POWER) -> float:
    """Non-centrality at which the diagnosis' likelihood-ratio test at level
    ``alpha / N_TESTS`` rejects with probability ``power``: chi-square(df) with a known
    sigma, ``df`` times F(df, noise_dof) with an estimated one."""
    if np.isfinite(noise_dof):
        crit = stats.f.isf(alpha / N_TESTS, df, noise_dof)
        return float(optimize.brentq(lambda lam: stats.ncf.sf(crit, df, noise_dof, lam)
                                     - power, 1e-6, 1e7))
    crit = stats.chi2.isf(alpha / N_TESTS, df)
    return float(optimize.brentq(lambda lam: stats.ncx2.sf(crit, df, lam) - power, 1e-6, 1e7))


def truth_analysis(case, seed: int) -> dict:
    """Chi-square (true noise) of every catalogue explanation with at most as many effects
    as the truth, fitted to the noise-free table the way the diagnosis fits them, and
    what that makes of the case (see the module docstring)."""
    import itertools

    from irreflect.data import Measurements
    from irreflect.diagnose.noise import NoiseEstimate, estimate_noise
    from irreflect.diagnose.search import canonical_order, set_name
    from irreflect.diagnose.workflow import _Search
    from irreflect.fitting import fit
    from irreflect.models import get_model

    m = case.measurements
    if m.sigma is not None:  # the table says its noise
        noise = NoiseEstimate(sigma=case.sigma, value=float(np.median(case.sigma)),
                              source="given", dof=float("inf"), method="true")
    else:  # what the table can say of its noise: estimated from the true residuals
        noise = estimate_noise(m, residuals=m.power - case.clean, fitted=case.clean,
                               seed=seed, alpha=ALPHA)
    clean = Measurements(gamma_deg=m.gamma_deg, theta_deg=m.theta_deg, power=case.clean,
                         sigma=noise.sigma)  # every fit weighted by that noise
    truth = canonical_order(case.effects)
    k = len(truth)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        search = _Search(clean, clean, get_model("two-lobe"), list(CATALOGUE), noise, seed,
                         lambda m: None)
        search.add("", fit(clean, "two-lobe", seed=seed), ())
        chi2 = {"": search.fits[""].deviance}
        for size in range(1, max(k, 1) + 1):
            for s in itertools.combinations(CATALOGUE, size):
                a = search.get(s)
                chi2[set_name(s)] = a.deviance if a is not None else float("inf")
        # the truth with one effect more: when one fits the noise-free table better by
        # the non-centrality of 95 % power, the catalogue cannot follow the generating
        # forms (a reflectance 1 + c sin^2 gamma that cos^w plus a background follows
        # better): the catalogue's names of the truth are then not all the data support
        extra = {}
        if truth:
            for x in CATALOGUE:
                if x not in truth:
                    a = search.get(canonical_order(truth + (x,)))
                    extra[x] = a.deviance if a is not None else float("inf")
    out = {"chi2_" + (key or "base"): v for key, v in chi2.items()}
    if not truth:
        return out | {"identifiable": True, "identifiable_rivals": True, "complete": True,
                      "detectable": True, "margin": float("nan"), "closest": "",
                      "beyond": ""}
    tkey = set_name(truth)
    beyond, beyond_ratio = "", 0.0
    for x, v in extra.items():
        df = (search.n_params(canonical_order(truth + (x,)))
              - search.n_params(truth))
        ratio = (chi2[tkey] - v) / lambda_star(max(df, 1), noise.dof)
        if ratio > beyond_ratio:
            beyond, beyond_ratio = x, ratio
    worst, closest = np.inf, ""
    detect = np.inf
    for key, v in chi2.items():
        s = tuple(key.split("+")) if key else ()
        if key == tkey or len(s) > k:
            continue
        df = search.n_params(canonical_order(set(s) | set(truth))) - search.n_params(s)
        ratio = (v - chi2[tkey]) / lambda_star(max(df, 1), noise.dof)
        if ratio < worst:
            worst, closest = ratio, key or "(base)"
        if not s:
            detect = ratio
    complete = beyond_ratio < 1.0
    return out | {"identifiable": bool(worst >= 1.0 and complete),
                  "identifiable_rivals": bool(worst >= 1.0), "complete": complete,
                  "detectable": bool(detect >= 1.0), "margin": float(worst),
                  "closest": closest, "beyond": beyond if not complete else ""}


def with_readings(case, plan, seed):
    """The case's table with the readings of a measurement plan taken (the generating
    model plus its noise; repeated readings at a setting, and a setting already in the
    table, averaged with what is there)."""
    from irreflect.data import Measurements
    from irreflect.diagnose.blind import clean_power

    tr, m = case.truth, case.measurements
    g = np.repeat([r["gamma_deg"] for r in plan], [r["readings"] for r in plan])
    t = np.repeat([r["theta_deg"] for r in plan], [r["readings"] for r in plan])
    p = clean_power(tr["base_params"], tr["params"], g, t)
    a, b = tr["noise"]["a"], tr["noise"]["b"]
    sig = np.sqrt(a * a + (b * p) ** 2)
    rng = np.random.default_rng([seed, 7])
    df = pd.DataFrame({"gamma_deg": np.concatenate([m.gamma_deg, g]),
                       "theta_deg": np.concatenate([m.theta_deg, t]),
                       "power": np.concatenate([m.power, p + rng.standard_normal(p.size) * sig]),
                       "var": np.concatenate([case.sigma, sig]) ** 2})
    df = df.groupby(["gamma_deg", "theta_deg"], as_index=False).agg(
        power=("power", "mean"), var=("var", "mean"), n=("power", "size"))
    sigma = np.sqrt(df["var"] / df["n"]).to_numpy()
    return Measurements(gamma_deg=df["gamma_deg"].to_numpy(), theta_deg=df["theta_deg"].to_numpy(),
                        power=df["power"].to_numpy(),
                        sigma=sigma if m.sigma is not None else None, name=m.name + "_more")


def one_case(job) -> dict:
    seed, saturate = job
    warnings.simplefilter("ignore")
    case = blind_case(seed, saturate=saturate)
    tr = case.truth
    t0 = time.perf_counter()
    try:
        d = diagnose(case.measurements, seed=seed)
    except Exception as exc:  # noqa: BLE001 - one case's failure is a result, not the end of the run
        # counted as an outcome of its own (never right, never quiet), so that a run of
        # hundreds of seeds ends with its rates and names the seeds that raised
        row = {"seed": seed, "base": tr["base"], "truth": "+".join(sorted(case.effects)) or "-",
               "n_effects": len(case.effects), "grid": tr["grid"]["kind"],
               "n_points": tr["n_points"], "noise": tr["noise"]["kind"],
               "sigma_column": tr["noise"]["sigma_column"], "saturates": tr["saturates"],
               "lambda": round(tr["lambda"], 1), "named": "-", "alternatives": "",
               "verdict": f"raised {type(exc).__name__}: {' '.join(str(exc).split())[:200]}",
               "seconds": round(time.perf_counter() - t0, 2), "outcome": "raised"}
        return row | truth_analysis(case, seed)
    seconds = time.perf_counter() - t0
    named = tuple(sorted(e.name for e in d.effects))
    alts = tuple(tuple(sorted(named + tuple(a))) for a in getattr(d, "alternatives", ()))
    truth = tuple(sorted(case.effects))
    row = {
        "seed": seed, "base": tr["base"], "truth": "+".join(truth) or "-",
        "n_effects": len(truth), "grid": tr["grid"]["kind"], "n_points": tr["n_points"],
        "noise": tr["noise"]["kind"], "sigma_column": tr["noise"]["sigma_column"],
        "saturates": tr["saturates"], "lambda": round(tr["lambda"], 1),
        "named": "+".join(named) or "-",
        "alternatives": " | ".join("+".join(a) for a in alts),
        "verdict": d.verdict, "seconds": round(seconds, 2),
    }
    if not truth:
        alarm = bool(named) or bool(alts) or d.verdict != "no missing effect"
        row["outcome"] = "false alarm" if alarm else "quiet"
    elif alts:
        row["outcome"] = "ambiguous, truth among" if truth in alts else "ambiguous, wrong"
    elif named == truth:
        row["outcome"] = "right"
    elif named and not set(named) <= set(truth):
        row["outcome"] = "wrong"
    elif named:
        row["outcome"] = "partial"
    else:
        row["outcome"] = "missed"
    sep = getattr(d, "separating", ())
    if sep:  # measure what was proposed, add it to the table, diagnose again
        again = diagnose(with_readings(case, sep, seed), seed=seed)
        named2 = tuple(sorted(e.name for e in again.effects))
        row["proposed_readings"] = int(sum(r["readings"] for r in sep))
        row["proposal_reaches_target"] = bool(sep[0]["total_chi2"]
                                              >= d.settings["separation_target"])
        row["after_readings"] = ("ambiguous" if again.alternatives else
                                 "right" if named2 == truth else
                                 "nothing named" if not named2 else "wrong")
    row |= truth_analysis(case, seed)
    return row


def rate(mask, of) -> str:
    n = int(of.sum())
    return f"{int((mask & of).sum())}/{n} = {100 * (mask & of).sum() / n:.0f}%" if n else "-"


def summary(df: pd.DataFrame) -> pd.DataFrame:
    """One row per group (all, each base, each effect, singles and pairs)."""
    groups = [("all cases", np.ones(len(df), bool))]
    groups += [(f"base {b}", (df["base"] == b).to_numpy()) for b in BASES]
    groups += [(f"effect {e}", df["truth"].str.split("+").apply(lambda t, e=e: e in t).to_numpy())
               for e in CATALOGUE]
    groups += [("one effect", (df["n_effects"] == 1).to_numpy()),
               ("two effects", (df["n_effects"] == 2).to_numpy())]
    rows = []
    out = df["outcome"]
    effect = df["n_effects"] > 0
    ident = effect & df["identifiable"].astype(bool)
    for name, sel in groups:
        sel = pd.Series(sel, index=df.index)
        wrong = out.isin(["wrong", "ambiguous, wrong"])
        rows.append({
            "group": name,
            "identifiable": f"{int((ident & sel).sum())}/{int((effect & sel).sum())}",
            "right names": rate(out == "right", ident & sel),
            "wrong names": rate(wrong, ident & sel),
            "ambiguous (ident.)": rate(out.str.startswith("ambiguous"), ident & sel),
            "right (all)": rate(out == "right", effect & sel),
            "wrong (all)": rate(wrong, effect & sel),
            "ambiguous (all)": rate(out.str.startswith("ambiguous"), effect & sel),
            "false alarms": rate(out.isin(["false alarm", "raised"]), ~effect & sel),
        })
    return pd.DataFrame(rows)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--seeds", default="0:300", help="seed range A:B (default 0:300)")
    parser.add_argument("--no-saturate", action="store_true",
                        help="keep the specular share below 0.95 on every table")
    parser.add_argument("--jobs", type=int, default=1, help="worker processes (default 1)")
    parser.add_argument("--out", help="write the per-case table as CSV")
    parser.add_argument("--summarize", nargs="+", metavar="CSV",
                        help="print the rates of per-case tables written by --out (runs "
                             "over parts of a seed range, joined) instead of running")
    args = parser.parse_args(argv)
    a, _, b = args.seeds.partition(":")
    seeds = range(int(a), int(b))
    if not len(seeds):
        parser.error(f"--seeds {args.seeds}: empty range, expected A:B with A < B")
    jobs = [(s, not args.no_saturate) for s in seeds]
    t0 = time.perf_counter()
    if args.summarize:
        missing = [p for p in args.summarize if not Path(p).is_file()]
        if missing:
            parser.error(f"--summarize: no such file {missing[0]}; expected CSV files "
                         "written by --out")
        df = pd.concat([pd.read_csv(p) for p in args.summarize], ignore_index=True)
        df = df.sort_values("seed").drop_duplicates("seed").reset_index(drop=True)
        df["alternatives"] = df["alternatives"].fillna("")
        args.seeds = f"{df['seed'].min()}:{df['seed'].max() + 1}"
        args.jobs = 0
        rows = None
    elif args.jobs > 1:
        with ProcessPoolExecutor(args.jobs) as pool:
            rows = list(tqdm(pool.map(one_case, jobs), total=len(jobs), desc="diagnose",
                             file=sys.stderr, leave=False))
    else:
        rows = [one_case(j) for j in tqdm(jobs, desc="diagnose", file=sys.stderr, leave=False)]
    if rows is not None:
        df = pd.DataFrame(rows)
    if args.out and rows is not None:
        from irreflect._atomic import atomic_path

        with atomic_path(Path(args.out)) as tmp:
            df.to_csv(tmp, index=False)
    pd.set_option("display.width", 250)
    pd.set_option("display.max_colwidth", 60)
    sat = "share kept below 0.95" if args.no_saturate else "saturating share"
    print(f"harder blind set, seeds {args.seeds} ({sat}): {len(df)} cases, "
          f"{int((df['n_effects'] == 0).sum())} without an effect, "
          f"{int((df['n_effects'] == 1).sum())} with one, {int((df['n_effects'] == 2).sum())} "
          f"with two; identifiable = the truth beats every rival of its size on the "
          f"noise-free table by the non-centrality of 95 % power (known sigma, df 1: "
          f"{lambda_star(1):.1f}, df 2: {lambda_star(2):.1f}; estimated with 40 dof: "
          f"{lambda_star(1, 40):.1f}, {lambda_star(2, 40):.1f})")
    print(summary(df).to_string(index=False))
    raised = df[df["outcome"] == "raised"]
    if len(raised):
        print(f"\n{len(raised)} case(s) where the diagnosis raised (counted as not right and, "
              "without an effect, as a false alarm): "
              + "; ".join(f"seed {r.seed}: {r.verdict}" for r in raised.itertuples()))
    effect = df["n_effects"] > 0
    if "identifiable_rivals" not in df:  # a table written before completeness was asked
        df["identifiable_rivals"], df["complete"], df["beyond"] = df["identifiable"], True, ""
    rivals = effect & df["identifiable_rivals"].astype(bool)
    incomplete = rivals & ~df["complete"].astype(bool)
    wrong = df["outcome"].isin(["wrong", "ambiguous, wrong"])
    print(f"\nthe earlier definition (rivals only, completeness not asked): identifiable "
          f"{int(rivals.sum())}/{int(effect.sum())}, right names "
          f"{rate(df['outcome'] == 'right', rivals)}, wrong names {rate(wrong, rivals)}; "
          f"{int(incomplete.sum())} of them not complete (a further name fits the "
          "noise-free table better): "
          + (", ".join(f"{r.seed} {r.truth} (+{r.beyond}: {r.outcome})"
                       for r in df[incomplete].itertuples()) or "none"))
    counts = df[df["n_effects"] > 0].groupby(["identifiable", "outcome"]).size()
    print("\noutcomes of the cases with effects (identifiable, outcome):")
    print(counts.to_string())
    found = df[df["outcome"] == "right"]
    if len(found):
        print("\nverdict when the names are right: "
              + ", ".join(f"{k} {v}" for k, v in found["verdict"].value_counts().items()))
    if "after_readings" in df and df["after_readings"].notna().any():
        amb = df[df["after_readings"].notna()]
        within = amb[amb["proposal_reaches_target"].astype(bool)]
        print(f"\nambiguity reports: {len(amb)}; the proposed readings reach the chi2 the test "
              f"needs on {len(within)} (median {within['proposed_readings'].median():.0f} "
              "readings); with the readings taken (simulated from the generating model) and "
              "the table diagnosed again: "
              + ", ".join(f"{k} {v}" for k, v in within["after_readings"].value_counts().items())
              + ("; where they do not reach it: "
                 + ", ".join(f"{k} {v}" for k, v in amb[~amb["proposal_reaches_target"].astype(
                     bool)]["after_readings"].value_counts().items())
                 if len(within) < len(amb) else ""))
    bad = df[df["outcome"].isin(["wrong", "ambiguous, wrong", "false alarm"])]
    if len(bad):
        print("\nwrong names and false alarms:")
        cols = ["seed", "base", "truth", "named", "alternatives", "verdict", "grid", "noise",
                "lambda", "identifiable", "closest", "margin", "beyond"]
        print(bad[cols].to_string(index=False))
    run = (f"whole run {time.perf_counter() - t0:.0f} s with {args.jobs} job(s) (truth "
           "analysis included; timings on a shared machine are noisy)" if rows is not None
           else f"from {len(args.summarize)} table(s) written by --out")
    print(f"\ntime per diagnosis: median {df['seconds'].median():.2f} s, 90th percentile "
          f"{df['seconds'].quantile(0.9):.2f} s, max {df['seconds'].max():.1f} s; {run}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
