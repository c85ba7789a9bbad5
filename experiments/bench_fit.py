"""Benchmark: one global fit, irreflect (compiled and numpy engines) vs scipy's curve_fit.

In one run, on the same tables:

* the bundled 132-point terrazzo table: ``irreflect.fit`` with everything it does for a
  user (data-driven starts, screening, Levenberg-Marquardt, scans, standard errors,
  checks), with the compiled kernel and with the numpy reference implementation, against
  ``scipy.optimize.curve_fit(two_lobe_power)`` from a physical start (Table 3's order of
  magnitude) and from its default start ``p0 = ones``; medians, ratios and the R^2 each
  reaches (a fast fit that stops in a local optimum is no bargain);
* generated glossy materials (``irreflect.synthetic``, seeds 0-39): median and worst fit
  time per engine, and how often each reaches the generating curve's R^2;
* every real set in ``../shared/datasets/real``: median and worst per engine;
* the diagnosis catalogue's extended models (``--extended``, alone with
  ``--extended-only``): both engines' times, their ratio and the time per evaluation.

Run: ``.venv/bin/python experiments/bench_fit.py [--repeats 200]`` on a quiet machine (it
measures wall time; the README quotes its output). Peak memory (max RSS) is printed last.
"""

from __future__ import annotations

import argparse
import resource
import statistics
import time
import warnings

import numpy as np
from scipy.optimize import curve_fit

from irreflect import fit, metrics
from irreflect.data import load_bundled, read_measurements, real_datasets
from irreflect.errors import FitError, FitWarning
from irreflect.models import two_lobe_power
from irreflect.synthetic import synthetic_material


def _two_lobe_xy(x, *p):
    return two_lobe_power(x[0], x[1], *p)


def time_curve_fit(x, y, p0, repeats):
    times, r2, failures = [], float("nan"), 0
    for _ in range(repeats):
        t0 = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                popt, _ = curve_fit(_two_lobe_xy, x, y, p0=p0)
            r2 = metrics.r2(y, _two_lobe_xy(x, *popt))
        except (RuntimeError, ValueError):
            failures += 1
        times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1e3, r2, failures


BLOCK = 22  # back-to-back calls of one kind in a row (the first 2 untimed)


def _busy(seconds):
    """Unrelated work (a spinning Python loop) for ``seconds``."""
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        pass


def time_fit(meas, engine, repeats=1, model="two-lobe", seed=0):
    """(median ms, last result) of ``repeats`` fits (seeds ``seed``, ``seed + 1``, ...),
    warnings silenced."""
    times, result = [], None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        for i in range(repeats):
            t0 = time.perf_counter()
            try:
                result = fit(meas, model, seed=seed + i, engine=engine)
            except FitError:
                result = None
            times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1e3, result


def extended(repeats: int) -> None:
    """The diagnosis catalogue's models ("two-lobe+<effect>", the generic compiled path)
    on the 85-point ``hidden_case("angle_offset", 0)``: each engine's median time
    (interleaved), its ratio, and the time per model evaluation (the fit's ``nfev``)."""
    from irreflect.diagnose import CATALOGUE
    from irreflect.diagnose.hidden import hidden_case

    meas = hidden_case("angle_offset", 0).measurements
    print(f"extended models on hidden_case('angle_offset', 0), {meas.n_points} points, "
          f"{repeats} repeats (interleaved, medians, seed 0):")
    for model in ["two-lobe", *(f"two-lobe+{e}" for e in CATALOGUE)]:
        for engine in ("compiled", "numpy"):
            time_fit(meas, engine, model=model)  # warm-up
        t = {"compiled": [], "numpy": []}
        res = {}
        for _ in range(repeats):
            for engine in t:
                ms, res[engine] = time_fit(meas, engine, model=model)
                t[engine].append(ms)
        mc, mn = statistics.median(t["compiled"]), statistics.median(t["numpy"])
        nf = res["compiled"].nfev
        print(f"  {model:32s} compiled {mc:8.1f} ms ({mc * 1e3 / nf:6.1f} us/eval, nfev {nf:5d})"
              f"  numpy {mn:8.1f} ms   numpy / compiled {mn / mc:5.1f}x")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=200)
    parser.add_argument("--glossy", type=int, default=40, help="generated glossy materials")
    parser.add_argument("--extended", type=int, default=5, metavar="REPEATS",
                        help="repeats of the extended models' comparison (0: skip it)")
    parser.add_argument("--extended-only", action="store_true",
                        help="only the extended models' comparison")
    args = parser.parse_args(argv)
    if args.extended_only:
        extended(max(args.extended, 1))
        return

    meas = load_bundled("terrazzo")
    for engine in ("compiled", "numpy"):  # warm-up: imports, the kernel's cache
        time_fit(meas, engine)
    x = np.radians(np.vstack([meas.gamma_deg, meas.theta_deg]))
    y = meas.power
    phys = [0.02, -2.0, 1.0, 0.5, 30.0, 0.0, 0.4]
    # interleaved: every repeat times one fit of each kind (a new seed for irreflect), so a
    # busy moment of the machine hits all of them alike; medians
    t_c, t_n, t_p, t_o = [], [], [], []
    fail_phys = fail_ones = 0
    for i in range(args.repeats):
        ms, res_c = time_fit(meas, "compiled", seed=i)
        t_c.append(ms)
        if i % 4 == 0:
            ms, res_n = time_fit(meas, "numpy", seed=i)
            t_n.append(ms)
        ms, r2_phys, f = time_curve_fit(x, y, phys, 1)
        t_p.append(ms)
        fail_phys += f
        ms, r2_ones, f = time_curve_fit(x, y, np.ones(7), 1)
        t_o.append(ms)
        fail_ones += f
    ms_c, ms_n, base_phys, base_ones = (statistics.median(t) for t in (t_c, t_n, t_p, t_o))
    print(f"terrazzo: {meas.n_points} points, {args.repeats} repeats (interleaved, medians)")
    print(f"  irreflect.fit, compiled kernel : median {ms_c:8.3f} ms   R^2 {res_c.r2:.6f}   "
          f"(global: screening, LM from several starts, scans, standard errors)")
    print(f"  irreflect.fit, numpy reference : median {ms_n:8.3f} ms   R^2 {res_n.r2:.6f}")
    print(f"  curve_fit, physical p0 (local) : median {base_phys:8.3f} ms   R^2 {r2_phys:.6f}   "
          f"failures {fail_phys}/{args.repeats}")
    print(f"  curve_fit, default p0 = ones   : median {base_ones:8.3f} ms   R^2 {r2_ones:.6f}   "
          f"failures {fail_ones}/{args.repeats}")
    print(f"  ratios: numpy / compiled {ms_n / ms_c:.1f}x; curve_fit(physical p0) / compiled "
          f"{base_phys / ms_c:.2f}x; curve_fit(p0 = ones) / compiled {base_ones / ms_c:.2f}x")
    print(f"  the same bars, interleaved (stricter than issue 11's timing): median <= 0.5 ms: "
          f"{'met' if ms_c <= 0.5 else 'NOT met'}; >= 5x curve_fit from a physical start: "
          f"{'met' if base_phys / ms_c >= 5 else 'NOT met'}")
    # back to back: a program that fits many tables in a loop (or select, or compare) runs
    # fits one after another with warm caches; each timing a new seed, curve_fit likewise.
    # In blocks of BLOCK calls of one kind, then of the other, the first 2 of each block
    # not timed (the other kind just ran): both kinds sample the same stretches of time,
    # so a drift of this shared machine's speed (tens of % over a minute) hits both alike
    b_c, b_p = [], []
    for start in range(0, args.repeats, BLOCK - 2):
        n = min(BLOCK - 2, args.repeats - start)
        b_c += [time_fit(meas, "compiled", seed=1000 + start + i)[0]
                for i in range(-2, n)][2:]
        b_p += [time_curve_fit(x, y, phys, 1)[0] for _ in range(n + 2)][2:]
    bc, bp = statistics.median(b_c), statistics.median(b_p)
    print(f"terrazzo, {args.repeats} fits back to back (in blocks of {BLOCK} of each kind, "
          "medians):")
    print(f"  irreflect.fit, compiled kernel : median {bc:8.3f} ms (a new seed each fit)")
    print(f"  curve_fit, physical p0 (local) : median {bp:8.3f} ms")
    print(f"  ratio curve_fit(physical p0) / irreflect: {bp / bc:.2f}x")
    print(f"  target (issue 11, timed back to back as the issue's own 3.5 ms and 0.18 ms "
          f"were): median <= 0.5 ms: "
          f"{'met' if bc <= 0.5 else 'NOT met'}; >= 5x curve_fit from a physical start: "
          f"{'met' if bp / bc >= 5 else 'NOT met'}")

    # cold: every timed call (of both kinds alike) follows 10 ms of unrelated work, as a
    # single fit in a program doing other things would; on this shared machine whatever
    # a process has not touched for a few milliseconds has left the caches (probe below)
    probe_warm, probe_cold, k_c, k_p = [], [], [], []
    for i in range(args.repeats):
        np.ones(100).sum()
        t0 = time.perf_counter()
        np.ones(100).sum()
        probe_warm.append(time.perf_counter() - t0)
        _busy(0.01)
        t0 = time.perf_counter()
        np.ones(100).sum()
        probe_cold.append(time.perf_counter() - t0)
        _busy(0.01)
        k_c.append(time_fit(meas, "compiled", seed=2000 + i)[0])
        _busy(0.01)
        k_p.append(time_curve_fit(x, y, phys, 1)[0])
    kc, kp = statistics.median(k_c), statistics.median(k_p)
    print(f"terrazzo, {args.repeats} fits each after 10 ms of other work (both kinds alike, "
          "medians):")
    print(f"  irreflect.fit, compiled kernel : median {kc:8.3f} ms")
    print(f"  curve_fit, physical p0 (local) : median {kp:8.3f} ms")
    print(f"  ratio curve_fit(physical p0) / irreflect: {kp / kc:.2f}x")
    print(f"  (this machine: np.ones(100).sum() takes {statistics.median(probe_warm) * 1e6:.1f} "
          f"us warm, {statistics.median(probe_cold) * 1e6:.1f} us after 10 ms of other work)")
    print(f"  the same bars, cold (stricter than issue 11's timing): median <= 0.5 ms: "
          f"{'met' if kc <= 0.5 else 'NOT met'}; >= 5x curve_fit from a physical start: "
          f"{'met' if kp / kc >= 5 else 'NOT met'}")

    rows = {"compiled": [], "numpy": []}
    reached = {"compiled": 0, "numpy": 0}
    for seed in range(args.glossy):
        case = synthetic_material(seed, "glossy")
        for engine in rows:
            ms, res = time_fit(case.measurements, engine)
            rows[engine].append(ms)
            reached[engine] += res is not None and res.r2 >= case.r2_truth - 1e-4
    print(f"generated glossy materials (seeds 0-{args.glossy - 1}, "
          f"{', '.join(sorted({synthetic_material(s, 'glossy').grid for s in range(5)}))} "
          "grids, ...):")
    for engine, ms in rows.items():
        print(f"  {engine:<8}: median {np.median(ms):7.2f} ms, worst {np.max(ms):7.1f} ms; "
              f"reaches the generating curve's R^2 on {reached[engine]}/{args.glossy}")
    ms = rows["compiled"]
    print(f"  target (issue 11): median <= 2 ms and none over 50 ms: "
          f"{'met' if np.median(ms) <= 2 and np.max(ms) <= 50 else 'NOT met'}")

    sets = real_datasets()
    if sets:
        print("real sets (one fit each, after the warm-up):")
        for name, path in sets.items():
            table = read_measurements(path)
            line = []
            for engine in ("compiled", "numpy"):
                ms, res = time_fit(table, engine, 3)
                line.append(f"{engine} {ms:7.1f} ms")
            print(f"  {name:<26} {table.n_points:5d} points: " + ", ".join(line)
                  + f"  R^2 {res.r2:.4f}" if res is not None else "")
    if args.extended:
        extended(args.extended)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak memory (max RSS of this process): {peak:.0f} MB")
    print("paper (Table 4, MATLAB R2015, Core 2 Duo E8400): 273-660 ms per fit")


if __name__ == "__main__":
    main()
