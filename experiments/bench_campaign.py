"""Benchmark of the adaptive measurement campaign (issue 23), and the targets it is held to.

Every real set in ../shared/datasets/real/ and generated glossy and matte materials are used
as the instrument of replayed campaigns (``irreflect.campaign.replay``): the adaptive
campaign (``irreflect next``, 25 readings), the paper's 12-point protocol, the glossy-aware
protocol (designed from the dense table itself), random readings and ``select``'s best
subsets (hindsight). Per table it prints:

  N     the first number of readings from which the adaptive campaign's R^2 against all
        points stays >= the all-points fit's R^2 - 0.01 (up to 25)
  stop  where its verdict first said stop, and R^2 there (0.02 below the all-points R^2 is
        a failure; more than 3 readings after N is late)
  @12   R^2 at 12 readings: adaptive, the paper's protocol, the glossy-aware one, hindsight
  gap   the largest shortfall of the adaptive campaign below the hindsight bound at equal
        N from N = 12 on (target <= 0.01)
  rand  the N from which random readings (median of 3 draws) stay within 0.01
  t     median and slowest proposal, and the whole adaptive campaign (seconds)

Generated materials vary what the generators assume: ``synthetic_material`` (glossy and
matte two-lobe materials on paper-like, goniometer, uneven, sparse and mirror grids),
``wild_material`` (1-8 angles of incidence, steps to 20 deg, additive noise, sigma
columns), the diagnosis's hidden-effect tables (the model plus an effect it lacks), and
``misfit_glossy`` below: dense RGL-like scans of glossy materials whose specular lobe has a
heavier halo than cos^n and whose share rises toward grazing incidence faster than
u cos^v (the two-lobe model misfits them, as it misfits the real films and paints);
``saturating`` (the specular share reaches 1 inside the range) and ``foreign``
(materials of other literature models: Torrance-Sparrow, Ward, Lafortune, Oren-Nayar,
Blinn-Phong).

Usage::

    .venv/bin/python experiments/bench_campaign.py                 # everything (~25 min)
    .venv/bin/python experiments/bench_campaign.py --generated 8   # fewer generated
    .venv/bin/python experiments/bench_campaign.py --real-only
    .venv/bin/python experiments/bench_campaign.py --data-dir /work/heldout   # other tables

Timings come from a shared 2-core machine; they are noisy.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

TOL = 0.01
TARGET_N = 15
GENERATED_SHARE = 0.95


# ----------------------------------------------------------------------------- materials
def misfit_glossy(seed: int):
    """A dense scan of a glossy material the two-lobe model does not describe exactly."""
    from irreflect.data import Measurements

    rng = np.random.default_rng([seed, 2323])
    n_g = int(rng.integers(4, 8))
    gammas = -np.sort(rng.choice(np.arange(0.0, 76.0, 1.0), n_g, replace=False))
    step = float(rng.choice([0.5, 1.0, 2.0, 4.0]))
    fine = rng.random() < 0.6
    n_core = 10 ** rng.uniform(1.5, 4.3)  # core lobe index: half width 11 to 0.7 deg
    halo_k = 10 ** rng.uniform(0.7, 1.5)  # the halo is 5-30 times wider
    halo_w = rng.uniform(0.05, 0.3)  # share of the specular power in the halo
    u_as, v_as = 10 ** rng.uniform(-1.7, -0.5), rng.uniform(-1.5, 0.5)
    fresnel = rng.uniform(0.0, 0.6)  # extra share toward grazing: (1 - cos)^5
    n_d = 10 ** rng.uniform(-0.3, 0.4)
    level = 10 ** rng.uniform(-2, 2)
    noise = 10 ** rng.uniform(-2.5, -1.5)
    g_all, t_all = [], []
    for g in gammas:
        th = np.arange(-85.0, 85.0 + 1e-9, step)
        if fine:
            th = np.r_[th, -g + np.arange(-3.0, 3.01, 0.25)]
        th = np.unique(np.round(th[np.abs(th) <= 85.0], 4))
        g_all.append(np.full(th.size, g))
        t_all.append(th)
    g, t = np.concatenate(g_all), np.concatenate(t_all)
    gr, tr = np.radians(g), np.radians(t)
    cg = np.cos(gr)
    share = np.clip(u_as * cg ** v_as + fresnel * (1 - cg) ** 5, 0.0, 0.95)
    cphi = np.clip(np.cos(-gr - tr), 0.0, None)
    n_s = n_core * cg ** rng.uniform(-0.8, 0.8)
    lobe = ((1 - halo_w) * (n_s + 1) * cphi ** n_s
            + halo_w * (n_s / halo_k + 1) * cphi ** (n_s / halo_k)) / (2 * np.pi)
    diffuse = (n_d + 1) / (2 * np.pi) * np.clip(np.cos(tr), 0.0, None) ** n_d
    clean = level * ((1 - share) * diffuse + share * lobe)
    power = clean * (1 + noise * rng.standard_normal(clean.size))
    return Measurements(gamma_deg=g, theta_deg=t, power=power, name=f"misfit-glossy-{seed}")


def saturating(seed: int):
    """A dense scan of a glossy material whose specular share saturates: ``u_as
    cos^v_as(gamma)`` reaches 1 inside the measured range, and all the power is specular
    beyond (as on the real Ibiza and golden yellow tables), with a halo around the lobe
    in half of them (then the model misfits it) and grids of 3-9 angles of incidence."""
    from irreflect.data import Measurements
    from irreflect.models import two_lobe_power

    rng = np.random.default_rng([seed, 4242])
    n_g = int(rng.integers(3, 10))
    top = rng.uniform(55.0, 80.0)
    gammas = -np.unique(np.round(np.r_[0.0, top, rng.uniform(0.0, top, n_g - 2)], 2))
    v_as = -rng.uniform(1.0, 5.0)
    at = rng.uniform(0.45, 0.95) * top  # the share reaches 1 here
    u_as = float(np.cos(np.radians(at)) ** -v_as)
    u_nd, v_nd = 10 ** rng.uniform(-0.5, 0.7), rng.uniform(-2.0, 6.0)
    u_ns, v_ns = 10 ** rng.uniform(1.3, 3.8), rng.uniform(-1.5, 1.5)
    halo = rng.uniform(0.1, 0.3) if rng.random() < 0.5 else 0.0
    step = float(rng.choice([0.5, 0.8, 1.0, 2.0]))
    level = 10 ** rng.uniform(-2, 2)
    noise = 10 ** rng.uniform(-2.5, -1.5)
    g_all, t_all = [], []
    for g in gammas:
        th = np.arange(-85.0, 85.0 + 1e-9, step)
        th = np.unique(np.round(np.r_[th, -g + np.arange(-3.0, 3.01, 0.5)], 4))
        th = th[np.abs(th) <= 85.0]
        g_all.append(np.full(th.size, g))
        t_all.append(th)
    g, t = np.concatenate(g_all), np.concatenate(t_all)
    gr, tr = np.radians(g), np.radians(t)
    clean = two_lobe_power(gr, tr, u_as, v_as, u_nd, v_nd, u_ns, v_ns, level)
    if halo:
        wide = two_lobe_power(gr, tr, u_as, v_as, u_nd, v_nd, u_ns / 10.0, v_ns, level)
        diffuse = two_lobe_power(gr, tr, 0.0, 0.0, u_nd, v_nd, u_ns, v_ns, level)
        share = np.minimum(1.0, u_as * np.cos(gr) ** v_as)
        spec, spec_wide = clean - (1 - share) * diffuse, wide - (1 - share) * diffuse
        clean = (1 - share) * diffuse + (1 - halo) * spec + halo * spec_wide
    power = clean * (1 + noise * rng.standard_normal(clean.size))
    return Measurements(gamma_deg=g, theta_deg=t, power=power, name=f"saturating-{seed}")


def generated(n: int, first: int = 0) -> list[tuple[str, str, int]]:
    """(label, kind, seed) of the generated tables: ``n`` of each family, seeds from
    ``first`` (a new ``first`` gives tables no rule was tuned on)."""
    from irreflect.synthetic import FOREIGN_MODELS

    out = []
    for seed in range(first, first + n):
        out += [(f"glossy-{seed}", "glossy", seed), (f"matte-{seed}", "matte", seed),
                (f"wild-{seed}", "wild", seed), (f"misfit-glossy-{seed}", "misfit", seed),
                (f"saturating-{seed}", "saturating", seed),
                (f"foreign-{FOREIGN_MODELS[seed % len(FOREIGN_MODELS)]}-{seed}", "foreign",
                 seed)]
    effects = ("incidence_reflectance", "offspecular_peak", "specular_halo", "angle_offset",
               "retroreflection", "bump")
    for seed in range(first, first + max(1, n // 2)):
        eff = effects[seed % len(effects)]
        out.append((f"hidden-{eff}-{seed}", f"hidden:{eff}", seed))
    return out


def load(kind: str, seed: int):
    from irreflect.synthetic import synthetic_material, wild_material

    if kind in ("glossy", "matte"):
        return synthetic_material(seed, kind).measurements
    if kind == "wild":
        return wild_material(seed).measurements
    if kind == "misfit":
        return misfit_glossy(seed)
    if kind == "saturating":
        return saturating(seed)
    if kind == "foreign":
        from irreflect.synthetic import foreign_material

        return foreign_material(seed).measurements
    if kind.startswith("hidden:"):
        from irreflect.diagnose.hidden import hidden_case

        return hidden_case(kind.split(":", 1)[1], seed, sigma_column=False).measurements
    raise ValueError(kind)


def platform_line() -> str:
    """The machine and the numeric libraries the numbers were measured with: a campaign's
    curve can change at a borderline set from one machine to another (the fits' sums and
    numpy's exp/pow take different vector paths on different CPUs, and a fit of 8-15
    readings that sits between two optima can then land in the other)."""
    import platform

    import numba
    import scipy

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            info = fh.read()
        names = [ln.split(":", 1)[1].strip() for ln in info.splitlines()
                 if ln.startswith("model name")]
        flags = next((ln.split(":", 1)[1].split() for ln in info.splitlines()
                      if ln.startswith("flags")), [])
        if names:
            cpu = names[0]
        wide = "avx512f" if "avx512f" in flags else "avx2" if "avx2" in flags else ""
        if wide:
            cpu += f" ({wide})"
    except OSError:
        pass
    return (f"platform: {cpu}, {os.cpu_count()} cores; numpy {np.__version__}, scipy "
            f"{scipy.__version__}, numba {numba.__version__}")


# ----------------------------------------------------------------------------- one table
def _warm_worker():
    """Load the compiled fitting kernel once per worker process, before any campaign is
    timed: the load (about a second, several under load) is the process's, not the
    campaign's, and used to land on whichever table a worker replayed first."""
    warnings.simplefilter("ignore")
    from irreflect.fitting import warm

    warm()


def run_one(job):
    label, kind, source, generations, n_max, rule = job
    warnings.simplefilter("ignore")
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    from irreflect.campaign import replay
    from irreflect.data import read_measurements

    try:
        # a table with repeated settings is read at their mean, as `campaign
        # --average-duplicates` reads it (a held-out table of stop 45 repeated 638 settings
        # and stopped the whole benchmark)
        meas = (read_measurements(source, average_duplicates=True) if kind == "file"
                else load(kind, int(source)))
    except Exception as exc:  # noqa: BLE001 - reported in the table, the benchmark goes on
        return {"label": label, "kind": kind, "skipped": f"{type(exc).__name__}: {exc}"}
    if len(np.unique(meas.gamma_deg)) < 3 or meas.n_points < 40:
        return {"label": label, "kind": kind, "skipped": f"{meas.n_points} points, "
                f"{len(np.unique(meas.gamma_deg))} angles of incidence (a dense table needs "
                "40 points or more at three angles or more)"}
    t0 = time.perf_counter()
    try:
        from irreflect.campaign.design import DEFAULT_RULE

        result = replay(meas, n_max=n_max, seed=0, generations=generations,
                        rule=rule or DEFAULT_RULE)
    except Exception as exc:  # noqa: BLE001 - reported in the table, the benchmark goes on
        return {"label": label, "kind": kind, "skipped": f"{type(exc).__name__}: {exc}"}
    c = result.curves
    target = result.target
    ad, hs = c["adaptive"], c["hindsight"]
    gap = max((hs.r2[n] - ad.r2.get(n, -np.inf) for n in hs.r2 if n >= 12 and n in ad.r2),
              default=np.nan)
    stop = result.stop_n
    reach = ad.reached(target)
    times = sorted(result.proposal_seconds)
    return {
        "label": label, "kind": kind, "points": meas.n_points, "r2_all": result.reference_r2,
        "N": reach, "stop": stop, "stop_r2": ad.r2.get(stop, np.nan) if stop else np.nan,
        "ad12": ad.r2.get(12, np.nan), "paper12": c["paper"].r2.get(12, np.nan),
        "glossy12": c["glossy"].r2.get(12, np.nan), "hind12": hs.r2.get(12, np.nan),
        "gap": gap, "rand": c["random"].reached(target),
        "t_med": times[len(times) // 2] if times else np.nan,
        "t_max": times[-1] if times else np.nan, "t_campaign": ad.seconds,
        "ad25": ad.r2.get(n_max, np.nan), "seconds": time.perf_counter() - t0,
        "curve": ad.r2, "bands": {n: v.r2_band for n, v in result.verdicts.items()},
        "stability": {n: v.stability for n, v in result.verdicts.items()},
        "stops": {n: bool(v.stop) for n, v in result.verdicts.items()},
        # the replay's warnings on its target (an all-points fit that misfits the table or
        # whose lobe no reading sees) and on the table (mirror gaps)
        "warnings": list(result.warnings),
    }


# ----------------------------------------------------------------------------- judging
def stop_ok(row) -> tuple[bool, str]:
    """The verdict's targets: stops within 3 readings of N and never 0.02 below."""
    stop, n = row["stop"], row["N"]
    if stop is None:
        return False, "never stops"
    if row["stop_r2"] < row["r2_all"] - 0.02:
        return False, f"stops {row['r2_all'] - row['stop_r2']:.3f} below"
    if n is None:
        return True, "stops (target never held)"
    if stop > n + 3:
        return False, f"late by {stop - n - 3}"
    return True, "ok"


def fmt(v, spec=".4f"):
    if v is None:
        return "never"
    if isinstance(v, float) and not np.isfinite(v):
        return "n/a"
    if isinstance(v, float) and abs(v) > 1e4:
        return f"{v:.2g}"
    return format(v, spec)


def print_table(rows, title):
    print(f"\n{title}")
    head = (f"{'dataset':<30} {'pts':>5} {'R2 all':>7} {'N':>5} {'stop (R2)':>16} "
            f"{'ad@12':>7} {'paper@12':>8} {'glossy@12':>9} {'hind@12':>7} {'gap':>6} "
            f"{'rand':>5} {'t med/max/camp (s)':>19}")
    print(head)
    print("-" * len(head))
    for r in rows:
        if "skipped" in r:
            print(f"{r['label']:<30} skipped: {r['skipped'][:90]}")
            continue
        stop = "never" if r["stop"] is None else f"{r['stop']} ({fmt(r['stop_r2'])})"
        print(f"{r['label']:<30} {r['points']:>5} {fmt(r['r2_all']):>7} {fmt(r['N'], 'd'):>5} "
              f"{stop:>16} {fmt(r['ad12']):>7} {fmt(r['paper12']):>8} {fmt(r['glossy12']):>9} "
              f"{fmt(r['hind12']):>7} {fmt(r['gap'], '.3f'):>6} {fmt(r['rand'], 'd'):>5} "
              f"{r['t_med']:>6.2f}/{r['t_max']:.2f}/{r['t_campaign']:.1f}")


def _flag(row) -> str:
    """' [target: ...]' when the replay warned that its target, the all-points fit, misfits
    the table or puts a lobe where no reading falls (``irreflect campaign`` prints the
    warning in full); '' otherwise."""
    said = [w for w in row.get("warnings", ()) if w.startswith("the all-points fit")]
    kinds = ["unseen lobe" if "no reading of the table falls" in w else "misfit"
             for w in said]
    return f" [target: {', '.join(kinds)}]" if kinds else ""


def family_counts(rows, good) -> str:
    """'glossy 60/60, matte 60/60, ...': of each generated family (the kind before any
    ':'), how many of its tables are in ``good``; then the issue's own words, "generated
    glossy and matte materials", counted apart, since the other families (wild grids,
    misfits, saturating shares, foreign models, hidden effects) were added to be harder."""
    fams: dict[str, list[int]] = {}
    for r in rows:
        counts = fams.setdefault(r["kind"].split(":")[0], [0, 0])
        counts[0] += r in good
        counts[1] += 1
    text = ", ".join(f"{k} {a}/{b}" for k, (a, b) in fams.items())
    plain = [fams.get(k, [0, 0]) for k in ("glossy", "matte")]
    a, b = sum(p[0] for p in plain), sum(p[1] for p in plain)
    if b:
        text += (f"; glossy and matte alone (the issue's words) {a}/{b} = {a / b:.0%}, the "
                 f"other families {len(good) - a}/{len(rows) - b}")
    return text


def targets(real, gen) -> list[str]:
    from irreflect.campaign.replay import NO_BOUND_MARGIN

    lines = []
    done_r = [r for r in real if "skipped" not in r]
    done_g = [r for r in gen if "skipped" not in r]

    def ok(flag):
        return "met" if flag else "NOT met"

    within = [r for r in done_r if r["N"] is not None and r["N"] <= TARGET_N]
    miss = [f"{r['label']} ({fmt(r['N'], 'd')}){_flag(r)}" for r in done_r if r not in within]
    lines.append(f"adaptive holds within {TOL} of the all-points R^2 by N <= {TARGET_N}: real "
                 f"{len(within)}/{len(done_r)} ({ok(len(within) == len(done_r))})"
                 + (f"; missed: {', '.join(miss)}" if miss else ""))
    if done_g:
        within_g = [r for r in done_g if r["N"] is not None and r["N"] <= TARGET_N]
        share = len(within_g) / len(done_g)
        miss = [r["label"] + _flag(r) for r in done_g if r not in within_g]
        lines.append(f"  generated {len(within_g)}/{len(done_g)} = {share:.0%} (target >= "
                     f"{GENERATED_SHARE:.0%}: {ok(share >= GENERATED_SHARE)})"
                     + (f"; missed: {', '.join(miss[:12])}" + (" ..." if len(miss) > 12 else "")
                        if miss else ""))
        lines.append("    by family: " + family_counts(done_g, within_g))
    for name, rows in (("real", done_r), ("generated", done_g)):
        if not rows:
            continue
        beat = [r for r in rows if not (r["paper12"] >= r["ad12"])]  # NaN paper counts
        lose = [f"{r['label']} ({fmt(r['ad12'])} vs {fmt(r['paper12'])})" for r in rows
                if r not in beat]
        worst = max((r["paper12"] - r["ad12"] for r in rows if r not in beat), default=0.0)
        lines.append(f"adaptive beats the paper's 12 points at N = 12, {name}: "
                     f"{len(beat)}/{len(rows)} ({ok(not lose)})"
                     + (f"; not on {', '.join(lose[:8])}" if lose else "")
                     + (f"; the largest shortfall {worst:.4f}" if lose else ""))
        # a bound whose best 12 points fall more than TOL below the paper's 12 (themselves a
        # subset of 12) is no bound: select's thorough fits of its subsets settled elsewhere
        # (a noisy matte table: -235.6 against the paper's 0.8828); counted apart, not as met
        broken = [r for r in rows if r["hind12"] < r["paper12"] - NO_BOUND_MARGIN]
        close = [r for r in rows if np.isfinite(r["gap"]) and r["gap"] <= TOL
                 and r not in broken]
        far = [f"{r['label']} ({r['gap']:.3f})" for r in rows
               if r not in close and r not in broken]
        lines.append(f"within {TOL} of the hindsight bound at every N >= 12, {name}: "
                     f"{len(close)}/{len(rows)} ({ok(not far and not broken)})"
                     + (f"; short on {', '.join(far[:8])}" + (" ..." if len(far) > 8 else "")
                        if far else "")
                     + (f"; no bound on {', '.join(r['label'] for r in broken[:8])} (its best "
                        f"12 points fall more than {TOL} below the paper's 12)" if broken else ""))
        verdicts = [(r, *stop_ok(r)) for r in rows]
        bad = [f"{r['label']} ({why})" for r, good, why in verdicts if not good]
        lines.append(f"stopping verdict within 3 of N and never 0.02 below, {name}: "
                     f"{len(rows) - len(bad)}/{len(rows)} ({ok(not bad)})"
                     + (f"; {', '.join(bad[:8])}" + (" ..." if len(bad) > 8 else "")
                        if bad else ""))
        t_max = max(r["t_max"] for r in rows)
        t_camp = max(r["t_campaign"] for r in rows)
        lines.append(f"time, {name}: slowest proposal {t_max:.2f} s (target < 1 s: "
                     f"{ok(t_max < 1)}), slowest campaign of 25 readings {t_camp:.1f} s "
                     f"(target < 10 s: {ok(t_camp < 10)})")
        inside = []
        for r in rows:
            for n, (lo, hi) in r["bands"].items():
                if n in r["curve"] and np.isfinite(lo):
                    inside.append(lo - 0.005 <= r["curve"][n] <= hi + 0.005)
        if inside:
            lines.append(f"predicted R^2 band, {name}: the true R^2 inside (+-0.005) at "
                         f"{np.mean(inside):.0%} of {len(inside)} verdicts")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--generated", type=int, default=12,
                        help="tables of each generated family (default 12)")
    parser.add_argument("--first-seed", type=int, default=0,
                        help="seeds of the generated tables start here (default 0; the rule "
                             "was tuned on 0-11: use e.g. 100 for tables it has not seen)")
    parser.add_argument("--rule", nargs="+", metavar="KNOB=VALUE",
                        help="change knobs of the adaptive rule (irreflect.campaign.DesignRule), "
                             "e.g. range_weights=false misfit_min=0.06")
    parser.add_argument("--families", default=None,
                        help="comma-separated generated families to run (glossy, matte, wild, "
                             "misfit, saturating, foreign, hidden; default: all)")
    parser.add_argument("--real-only", action="store_true")
    parser.add_argument("--generated-only", action="store_true")
    parser.add_argument("--data-dir", default=None,
                        help="replay on every CSV of this folder instead of the real sets")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--generations", type=int, default=100,
                        help="NSGA-II generations of the hindsight subsets (default 100)")
    parser.add_argument("--n-max", type=int, default=25)
    parser.add_argument("--dump", default=None,
                        help="also write every row (curves, verdicts) to this JSON file")
    args = parser.parse_args(argv)

    from irreflect.data import real_data_dir

    rule = None
    if args.rule:
        import dataclasses

        from irreflect.campaign.design import DEFAULT_RULE
        from irreflect.errors import IrreflectError

        changes = {}
        knobs = [f.name for f in dataclasses.fields(DEFAULT_RULE)]
        for item in args.rule:
            key, _, value = item.partition("=")
            if key not in knobs:
                parser.error(f"--rule {item}: expected KNOB=VALUE with a knob of DesignRule "
                             f"({', '.join(knobs)}), found '{key}'")
            current = getattr(DEFAULT_RULE, key)
            try:
                if isinstance(current, bool):
                    changes[key] = value.lower() in ("1", "true", "yes")
                elif isinstance(current, tuple | dict):
                    # lobe_factors=0.1,10 or lobe_factors=[0.1,10]; law_sd={"u_as":0.5}
                    import json

                    text = value if value.lstrip().startswith(("[", "{")) else f"[{value}]"
                    parsed = json.loads(text)
                    if isinstance(current, tuple):
                        changes[key] = tuple(float(x) for x in parsed)
                    elif isinstance(parsed, dict):
                        changes[key] = {**current, **{str(k): float(v)
                                                      for k, v in parsed.items()}}
                    else:
                        raise ValueError(value)
                else:
                    changes[key] = type(current)(value)
            except (TypeError, ValueError):
                what = ("comma-separated numbers" if isinstance(current, tuple) else
                        'a JSON table {"NAME": number, ...}' if isinstance(current, dict)
                        else f"a {type(current).__name__}")
                parser.error(f"--rule {item}: expected {what} for {key}, found '{value}'")
        try:
            rule = dataclasses.replace(DEFAULT_RULE, **changes)
        except IrreflectError as exc:
            parser.error(f"--rule: {exc}")
        print(f"rule: {changes}")
    jobs_r, jobs_g = [], []
    if not args.generated_only:
        root = Path(args.data_dir) if args.data_dir else real_data_dir()
        if root is None:
            print("real data not found (../shared/datasets/real)", file=sys.stderr)
        else:
            for p in sorted(root.rglob("*.csv")):
                jobs_r.append((p.stem, "file", str(p), args.generations, args.n_max, rule))
    wanted = None
    if args.families:
        wanted = {f.strip() for f in args.families.split(",") if f.strip()}
        known = {"glossy", "matte", "wild", "misfit", "saturating", "foreign", "hidden"}
        if not wanted or not wanted <= known:
            parser.error(f"--families: expected a comma-separated list of "
                         f"{', '.join(sorted(known))}; found '{args.families}'")
    if not args.real_only:
        jobs_g = [(label, kind, seed, min(args.generations, 50), args.n_max, rule)
                  for label, kind, seed in generated(args.generated, args.first_seed)
                  if wanted is None or kind.split(":")[0] in wanted]
    t0 = time.perf_counter()
    print(f"{len(jobs_r)} real and {len(jobs_g)} generated tables, {args.workers} workers, "
          f"{args.n_max} readings per campaign", flush=True)
    print(platform_line(), flush=True)
    with ProcessPoolExecutor(args.workers, initializer=_warm_worker) as pool:
        rows = list(pool.map(run_one, jobs_r + jobs_g))
    real, gen = rows[:len(jobs_r)], rows[len(jobs_r):]
    if args.dump:
        import json

        with open(args.dump, "w") as fh:
            json.dump(rows, fh, default=lambda o: None if o is None else float(o))
    if real:
        print_table(real, "real measured tables" if not args.data_dir else str(args.data_dir))
    if gen:
        print_table(gen, "generated materials")
    print("\ntargets (issue 23):")
    for line in targets(real, gen):
        print("  " + line)
    print(f"\n{time.perf_counter() - t0:.0f} s in all")
    return 0


if __name__ == "__main__":
    sys.exit(main())
