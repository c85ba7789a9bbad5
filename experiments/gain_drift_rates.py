"""How often the diagnosis names a gain drift between angles of incidence, on tables that
have one and on tables that do not.

Kinds of table (every one seeded; ``--seeds A:B``):

``drift``
    :func:`irreflect.diagnose.hidden.hidden_case` with no hidden effect, every reading at
    one angle of incidence times its own factor ``1 +- U(lo, hi)`` (random sign; ``--drift
    0.05:0.15`` by default; the sigma column, when the table has one, scaled alike): the
    gain of the detector or the source changed between the runs.
``clean``
    The same generator, nothing hidden: a gain drift named is a false alarm.
``reflectance``
    The same generator with a true ``incidence_reflectance`` (``K cos^w(gamma)``,
    ``|w|`` 0.3-1.2): a gain drift named instead of it is a wrong name.
``blind-reflectance``
    :func:`irreflect.diagnose.blind.blind_case` with an incidence reflectance in either of
    its forms (``cos^w`` or ``1 + c sin^2 gamma``, saturating glossy, semigloss and matte
    bases, five grids): a smooth law the catalogue follows only nearly.

Per kind: the share of tables on which ``gain_drift`` is named (``named``), on which it is
among the alternatives of an ambiguity (``ambiguous``), the share on which the right thing
is said (``right``: gain drift named alone on ``drift``; no name and "no missing effect"
on ``clean``; ``incidence_reflectance`` named without the gain drift on the others) and
the median time per diagnosis.

Usage::

    .venv/bin/python experiments/gain_drift_rates.py [--seeds 0:20] [--jobs 2]
        [--kinds drift,clean,reflectance,blind-reflectance] [--out cases.csv]
"""

from __future__ import annotations

import argparse
import time
import warnings
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pandas as pd

from irreflect.data import Measurements
from irreflect.diagnose import diagnose
from irreflect.diagnose.blind import blind_case
from irreflect.diagnose.hidden import hidden_case
from irreflect.errors import FitWarning, IrreflectError

KINDS = ("drift", "clean", "reflectance", "blind-reflectance")


def with_gain_drift(meas: Measurements, seed: int, lo: float = 0.05,
                    hi: float = 0.15) -> tuple[Measurements, dict]:
    """``meas`` with every reading at one angle of incidence times its own factor
    ``1 +- U(lo, hi)`` (random sign, seeded): (table, factor by gamma)."""
    rng = np.random.default_rng([int(seed), 7349])
    levels = np.unique(meas.gamma_deg)
    factors = {float(g): float(1.0 + rng.choice([-1.0, 1.0]) * rng.uniform(lo, hi))
               for g in levels}
    f = np.array([factors[float(g)] for g in meas.gamma_deg])
    return Measurements(gamma_deg=meas.gamma_deg, theta_deg=meas.theta_deg,
                        power=meas.power * f,
                        sigma=None if meas.sigma is None else meas.sigma * f,
                        material=meas.material, name=f"{meas.name}_gain_drift"), factors


def make_table(kind: str, seed: int, lo: float = 0.05, hi: float = 0.15) -> Measurements:
    if kind == "drift":
        return with_gain_drift(hidden_case("none", seed).measurements, seed, lo, hi)[0]
    if kind == "clean":
        return hidden_case("none", seed).measurements
    if kind == "reflectance":
        return hidden_case("incidence_reflectance", seed).measurements
    if kind == "blind-reflectance":
        return blind_case(seed, effects=("incidence_reflectance",)).measurements
    raise ValueError(kind)


def one_case(job) -> dict:
    kind, seed, lo, hi = job
    meas = make_table(kind, seed, lo, hi)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        try:
            d = diagnose(meas, seed=0)
        except IrreflectError as exc:
            return {"kind": kind, "seed": seed, "error": str(exc)[:200]}
    names = [e.name for e in d.effects]
    alternatives = [n for a in d.alternatives for n in a]
    gain_named = "gain_drift" in names
    if kind == "drift":
        right = names == ["gain_drift"] and not d.alternatives
    elif kind == "clean":
        right = not names and not d.alternatives and d.verdict == "no missing effect"
    else:
        right = "incidence_reflectance" in names and not gain_named \
            and "gain_drift" not in alternatives
    return {"kind": kind, "seed": seed, "n_points": meas.n_points,
            "gammas": int(np.unique(meas.gamma_deg).size), "sigma": meas.sigma is not None,
            "verdict": d.verdict, "named": "+".join(names),
            "alternatives": " | ".join("+".join(a) for a in d.alternatives),
            "gain_named": gain_named, "gain_ambiguous": "gain_drift" in alternatives,
            "right": bool(right), "seconds": time.perf_counter() - t0, "error": ""}


def summarize(rows: pd.DataFrame) -> pd.DataFrame:
    ok = rows[rows["error"] == ""]
    out = ok.groupby("kind").agg(n=("seed", "size"), named=("gain_named", "mean"),
                                 ambiguous=("gain_ambiguous", "mean"),
                                 right=("right", "mean"), median_s=("seconds", "median"))
    out["errors"] = rows.groupby("kind")["error"].apply(lambda e: int((e != "").sum()))
    return out.reindex([k for k in KINDS if k in out.index])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="0:20", help="seed range A:B (default 0:20)")
    ap.add_argument("--kinds", default=",".join(KINDS))
    ap.add_argument("--drift", default="0.05:0.15", help="range of |factor - 1| (default "
                                                         "0.05:0.15)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", help="write the per-case table (CSV)")
    args = ap.parse_args(argv)
    a, b = (int(x) for x in args.seeds.split(":"))
    lo, hi = (float(x) for x in args.drift.split(":"))
    kinds = [k for k in args.kinds.split(",") if k]
    jobs = [(k, s, lo, hi) for k in kinds for s in range(a, b)]
    t0 = time.perf_counter()
    if args.jobs > 1:
        with ProcessPoolExecutor(args.jobs) as pool:
            rows = list(pool.map(one_case, jobs))
    else:
        rows = [one_case(j) for j in jobs]
    frame = pd.DataFrame(rows)
    if args.out:
        frame.to_csv(args.out, index=False)
    with pd.option_context("display.width", 200, "display.max_columns", 20):
        wrong = frame[(frame["error"] == "") & ~frame["right"].astype(bool)]
        if len(wrong):
            print(wrong[["kind", "seed", "gammas", "sigma", "verdict", "named",
                         "alternatives"]].to_string(index=False))
        print(summarize(frame).to_string(float_format=lambda x: f"{x:.2f}"))
    print(f"{len(jobs)} diagnoses, seeds {a}:{b}, drift {lo:g}-{hi:g}, "
          f"{time.perf_counter() - t0:.0f} s with {args.jobs} job(s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
