"""Benchmark of the room simulation: accuracy and speed targets, irreflect beside baselines,
in one run.

Targets (issue 27), each printed with its measured value and PASS / FAIL:

1. Swapped links (emitter and receiver exchanged, the same order-1 pattern at both ends)
   equal within 1 % per order (recursive) and within 3 Monte Carlo standard errors (Monte
   Carlo), on a glossy scene (glossy floor and walls) and a Lambertian one (Barry's A with a
   desk).
2. Every reflection order of the recursive method at the default 0.25 m cells within 1 % of a
   converged Monte Carlo (millions of rays), Lambertian and glossy rooms, wide and narrow
   fields of view.
3. The office (103 receivers, 3 reflections, recursive, 0.125 m cells) under 30 s on 2 cores,
   and 100 receivers at most twice one receiver; the baseline is the code before this work
   (git commit BASELINE, extracted under /tmp and run with the same interpreter, on 4
   receivers: its time grows linearly with receivers, so 103 is extrapolated and labelled).
4. Barry's configuration A at 0.0625 m (28,160 cells) under 1 s, within 1 % per order of the
   exact sum over every cell pair at the same cells (the far-field grouping switched off).
5. The time ratio vlc-rm / irreflect at 0.125 m at least 30x (vlc-rm, an independent
   recursive-method implementation on PyPI, is installed into a scratch virtual environment
   under /tmp by this script; not a dependency of irreflect).

Timings on this shared 2-core machine are noisy: each is printed with the load average and
the process CPU time; ratios are against baselines measured in the same run.

    python experiments/bench_room.py [--parts swap orders office barry vlcrm montecarlo]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tarfile
import textwrap
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SCRATCH = Path("/tmp/irreflect-bench-vlcrm")
BASELINE = "708aae1"  # the code before the reciprocal model and the receiver-independent method
BASELINE_DIR = Path(f"/tmp/irreflect-baseline-{BASELINE}")
RESULTS = []


def target(name, measured, ok):
    RESULTS.append((name, measured, ok))
    print(f"  TARGET {'PASS' if ok else 'FAIL'}: {name}: {measured}", flush=True)


def load():
    return f"load average {os.getloadavg()[0]:.1f}"


def run_json(python, code, *args, env=None):
    out = subprocess.run([str(python), "-c", code, *map(str, args)], capture_output=True,
                         text=True, env=env, check=False)
    if out.returncode != 0:
        raise RuntimeError(out.stderr.strip().splitlines()[-1] if out.stderr else "failed")
    return json.loads(out.stdout.strip().splitlines()[-1])


# ----------------------------------------------------------------------------- 1. swapped links
def part_swap(rays):
    print("== 1. swapped links (same order-1 pattern at both ends), orders 1-3 ==")
    from dataclasses import replace

    from irreflect.room import Box, simulate
    from irreflect.room.validation import (
        barry_configuration_a,
        glossy_material,
        glossy_room,
        swap_ready,
    )

    lam = barry_configuration_a(receiver_fov_deg=90.0)
    lam = replace(lam, boxes=(Box("desk", np.array([1.5, 0.5, 0.0]), np.array([2.5, 1.2, 0.8]),
                                  ("walls",) * 6),))
    glossy = swap_ready(glossy_room(walls=glossy_material(0.6), receiver_pos=(2.9, 1.1, 0.9)))
    for label, scene in (("glossy floor and walls", glossy), ("Lambertian, with a desk", lam)):
        for method, kw in (("recursive", {"estimate_error": False}),
                           ("montecarlo", {"rays": rays, "seed": 4})):
            a = simulate(scene, method=method, bounces=3, **kw).link()
            b = simulate(scene.swapped(), method=method, bounces=3, **kw).link()
            rel = b.power_w[1:] / a.power_w[1:] - 1
            sig = np.hypot(a.stderr_w[1:], b.stderr_w[1:]) / a.power_w[1:]
            print(f"  {label}, {method}: swapped / direct - 1 per order "
                  + ", ".join(f"{r:+.4f}" for r in rel)
                  + ("" if method == "recursive" else
                     "  (3 sigma " + ", ".join(f"{3 * s:.4f}" for s in sig) + ")"))
            if method == "recursive":
                target(f"swapped links, recursive, {label}: every order within 1 %",
                       f"max |diff| {np.max(np.abs(rel)):.4f}", bool(np.all(np.abs(rel) < 0.01)))
            else:
                target(f"swapped links, Monte Carlo ({rays} rays), {label}: every order within "
                       "3 sigma", f"max |diff| / sigma {np.max(np.abs(rel) / sig):.2f}",
                       bool(np.all(np.abs(rel) < 3 * sig)))
    pa = simulate(glossy.with_brdf("paper"), method="montecarlo", bounces=3, rays=rays, seed=4)
    pb = simulate(glossy.with_brdf("paper").swapped(), method="montecarlo", bounces=3,
                  rays=rays, seed=4)
    rel = pb.link().power_w[1:] / pa.link().power_w[1:] - 1
    print("  the paper's form (--brdf paper), Monte Carlo, glossy: swapped / direct - 1 "
          + ", ".join(f"{r:+.4f}" for r in rel) + "  (not reciprocal)")


# ----------------------------------------------------------------------------- 2. every order
def part_orders(rays):
    print(f"== 2. every order at the default 0.25 m cells against Monte Carlo ({rays} rays) ==")
    from irreflect.report.room import convergence_cases
    from irreflect.room import simulate

    for label, scene in convergence_cases() + _krylon_case():
        t0 = time.perf_counter()
        rec = simulate(scene, method="recursive", bounces=3)
        t_rec = time.perf_counter() - t0
        seeds = (11, 12)
        mcs = [simulate(scene, method="montecarlo", bounces=3, rays=rays // 2, seed=s).link()
               for s in seeds]
        p = np.mean([m.power_w for m in mcs], axis=0)
        se = np.sqrt(np.sum([m.stderr_w ** 2 for m in mcs], axis=0)) / len(mcs)
        a = rec.link().power_w
        rel = a[1:] / p[1:] - 1
        est = rec.error_estimate[(0, 0)][1:]
        print(f"  {label}: recursive / MC - 1 per order " + ", ".join(f"{r:+.4f}" for r in rel)
              + "  (MC 1 sigma " + ", ".join(f"{s:.4f}" for s in se[1:] / p[1:])
              + "; recursive's own estimate " + ", ".join(f"{e:.4f}" for e in est)
              + f"; recursive {t_rec:.1f} s with its estimate)")
        target(f"every order within 1 % of converged Monte Carlo: {label}",
               f"max |diff| {np.max(np.abs(rel)):.4f}",
               bool(np.all(np.abs(rel) < 0.01 + 3 * se[1:] / p[1:])))


def _krylon_case():
    """The issue's own case when the real data are beside the checkout: the Krylon paint
    (fitted here) as floor, reflectance 0.5, Lambertian 0.6 walls, 4 x 4 x 3 m."""
    from irreflect.report.room import glossy_floor
    from irreflect.room.validation import glossy_room

    mat, note = glossy_floor(0.5)
    if mat is None:
        print(f"  (no real glossy floor: {note})")
        return []
    return [(f"real glossy floor {note}, Lambertian walls", glossy_room(floor=mat))]


# ----------------------------------------------------------------------------- 3. office
OFFICE = textwrap.dedent("""
    import json, sys, time, resource, warnings
    warnings.filterwarnings("ignore")
    from irreflect.room import load_scene, simulate
    scene = load_scene(sys.argv[1])
    n, cell = int(sys.argv[2]), float(sys.argv[3])
    est = sys.argv[4] == "1" if len(sys.argv) > 4 else None
    kw = {} if est is None else {"estimate_error": est}
    sub = scene.with_receivers(scene.receivers[:n])
    simulate(sub.with_receivers(sub.receivers[:1]), method="recursive", bounces=3, cell_m=1.0,
             **kw)  # load the compiled kernels
    c0, t0 = time.process_time(), time.perf_counter()
    res = simulate(sub, method="recursive", bounces=3, cell_m=cell, **kw)
    print(json.dumps({"seconds": time.perf_counter() - t0, "cpu": time.process_time() - c0,
                      "cells": res.n_cells, "gains": res.link(0, 0).power_w.tolist()}))
""")


def baseline_src() -> Path | None:
    """The code at BASELINE, extracted from git under /tmp (None if git cannot)."""
    src = BASELINE_DIR / "src"
    if (src / "irreflect").is_dir():
        return src
    try:
        BASELINE_DIR.mkdir(parents=True, exist_ok=True)
        archive = BASELINE_DIR / "src.tar"
        subprocess.run(["git", "-C", str(ROOT), "archive", "-o", str(archive), BASELINE, "src"],
                       check=True, capture_output=True)
        with tarfile.open(archive) as tar:
            tar.extractall(BASELINE_DIR, filter="data")
        return src
    except (subprocess.CalledProcessError, OSError) as exc:
        print(f"  baseline {BASELINE} not available ({exc})")
        return None


def part_office():
    print("== 3. office: 103 receivers, 3 reflections, recursive, 0.125 m ==")
    scene = ROOT / "datasets" / "rooms" / "office.toml"
    ours = {n: run_json(sys.executable, OFFICE, scene, n, 0.125, "0") for n in (1, 103)}
    full = run_json(sys.executable, OFFICE, scene, 103, 0.125, "1")
    print(f"  irreflect: 1 receiver {ours[1]['seconds']:.1f} s (cpu {ours[1]['cpu']:.1f} s), 103 "
          f"receivers {ours[103]['seconds']:.1f} s (cpu {ours[103]['cpu']:.1f} s), {ours[103]['cells']} "
          f"cells; with the error estimate (default) {full['seconds']:.1f} s (cpu "
          f"{full['cpu']:.1f} s); {load()}")
    ratio = ours[103]["seconds"] / ours[1]["seconds"]
    target("103 receivers at most twice one receiver (recursive, 0.125 m)", f"{ratio:.2f}x",
           ratio <= 2.0)
    target("office, 103 receivers, 3 reflections, 0.125 m, under 30 s on 2 cores (default "
           "settings, error estimate included)", f"{full['seconds']:.1f} s", full["seconds"] < 30)
    src = baseline_src()
    if src is None:
        return
    env = dict(os.environ, PYTHONPATH=str(src))
    try:
        base = run_json(sys.executable, OFFICE, scene, 4, 0.125, env=env)
    except RuntimeError as exc:
        print(f"  baseline failed to run ({exc})")
        return
    per = base["seconds"] / 4
    print(f"  baseline {BASELINE}: 4 receivers {base['seconds']:.1f} s (cpu {base['cpu']:.1f} s) = "
          f"{per:.1f} s a receiver -> 103 receivers about {103 * per:.0f} s (extrapolated, linear in "
          f"receivers); ratio baseline / irreflect at 103 receivers about "
          f"{103 * per / ours[103]['seconds']:.0f}x")


# ----------------------------------------------------------------------------- 4. Barry 0.0625 m
BARRY = textwrap.dedent("""
    import json, sys, time, warnings
    warnings.filterwarnings("ignore")
    import numpy as np
    from irreflect.room import simulate
    from irreflect.room.validation import barry_configuration_a
    cell = float(sys.argv[1])
    scene = barry_configuration_a()
    simulate(scene, method="recursive", bounces=3, cell_m=1.0)  # load the compiled kernels
    c0, t0 = time.process_time(), time.perf_counter()
    res = simulate(scene, method="recursive", bounces=3, cell_m=cell, estimate_error=False)
    print(json.dumps({"seconds": time.perf_counter() - t0, "cpu": time.process_time() - c0,
                      "cells": res.n_cells, "gains": res.link().power_w.tolist()}))
""")
EXACT = textwrap.dedent("""
    import json, sys, time, warnings
    warnings.filterwarnings("ignore")
    import numpy as np
    from irreflect.room import recursive as R
    from irreflect.room.geometry import boxes_array
    from irreflect.room.validation import barry_configuration_a
    cell = float(sys.argv[1])
    scene = barry_configuration_a()
    geo = R.prepare(scene, cell, boxes_array(scene))
    t0 = time.perf_counter()
    st = R.emitter_state(geo, scene.emitters[0], 3, 0.25e-9, 420, threads=2, theta_open=0.0)
    p = R.receiver_link(geo, st, scene.receivers[0], 420)[0]
    print(json.dumps({"seconds": time.perf_counter() - t0, "gains": p.tolist()}))
""")


def part_barry():
    print("== 4. Barry's configuration A at 0.0625 m, 3 reflections, recursive ==")
    ours = run_json(sys.executable, BARRY, 0.0625)
    exact = run_json(sys.executable, EXACT, 0.0625)
    rel = np.array(ours["gains"][1:]) / np.array(exact["gains"]) - 1
    print(f"  irreflect {ours['cells']} cells: {ours['seconds']:.2f} s (cpu {ours['cpu']:.2f} s; "
          f"{load()}); gains " + ", ".join(f"{g:.5g}" for g in ours["gains"]))
    print(f"  exact sum over every cell pair (no far-field groups): {exact['seconds']:.1f} s; "
          "grouped / exact - 1 per order " + ", ".join(f"{r:+.5f}" for r in rel))
    target("configuration A at 0.0625 m under 1 s", f"{ours['seconds']:.2f} s",
           ours["seconds"] < 1.0)
    target("configuration A at 0.0625 m within 1 % of the exact sum (every order)",
           f"max |diff| {np.max(np.abs(rel)):.5f}", bool(np.all(np.abs(rel) < 0.01)))
    src = baseline_src()
    if src is not None:
        try:
            base = run_json(sys.executable, BARRY.replace(", estimate_error=False", ""), 0.0625,
                            env=dict(os.environ, PYTHONPATH=str(src)))
            print(f"  baseline {BASELINE} at 0.0625 m: {base['seconds']:.2f} s (cpu "
                  f"{base['cpu']:.2f} s): ratio {base['seconds'] / ours['seconds']:.1f}x; its gains "
                  + ", ".join(f"{g:.5g}" for g in base["gains"]))
        except RuntimeError as exc:
            print(f"  baseline failed to run ({exc})")


# ----------------------------------------------------------------------------- 5. vlc-rm
VLCRM = textwrap.dedent("""
    import json, resource, sys, time, io, contextlib
    import numpy as np
    from vlc_rm.transmitter import Transmitter
    from vlc_rm.photodetector import Photodetector
    from vlc_rm.indoorenv import Indoorenv
    from vlc_rm.recursivemodel import Recursivemodel
    cell = float(sys.argv[1])
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    tx = Transmitter("led", position=[2.5, 2.5, 3], normal=[0, 0, -1], mlambert=1,
                     wavelengths=[620, 530, 475], fwhm=[20, 45, 20], luminous_flux=1)
    rx = Photodetector("pd", position=[0.5, 1.0, 0], normal=[0, 0, 1], area=1e-4, fov=85,
                       sensor="TCS3103-04")
    room = Indoorenv("A", size=[5, 5, 3], no_reflections=3, resolution=cell,
                     ceiling=[0.8] * 3, west=[0.8] * 3, north=[0.8] * 3, east=[0.8] * 3,
                     south=[0.8] * 3, floor=[0.3] * 3)
    t0, c0 = time.perf_counter(), time.process_time()
    with contextlib.redirect_stdout(io.StringIO()):
        room.create_environment(tx, rx)
        model = Recursivemodel("A", tx, rx, room)
        model._compute_cir()
        model._compute_dcgain()
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps({"seconds": seconds, "cpu": cpu, "peak_mb": peak, "base_mb": base,
                      "cells": int(room.no_points) - 2,
                      "gains": [float(g) for g in model.h_dcgain[:, 0]]}))
""")
OURS_DEFAULT = BARRY.replace(", estimate_error=False", "").replace(
    '"gains": res.link().power_w.tolist()}',
    '"gains": res.link().power_w.tolist(), '
    '"peak_mb": __import__("resource").getrusage(__import__("resource").RUSAGE_SELF).ru_maxrss / 1024}')


def vlcrm_python():
    """A scratch venv with vlc-rm (numpy < 2.3: luxpy, which vlc-rm imports, breaks on 2.4)."""
    py = SCRATCH / "bin" / "python"
    if py.exists():
        check = subprocess.run([str(py), "-c", "import vlc_rm.recursivemodel"],
                               capture_output=True, check=False)
        if check.returncode == 0:
            return py
    print(f"  installing vlc-rm into the scratch environment {SCRATCH} ...", flush=True)
    subprocess.run([sys.executable, "-m", "venv", str(SCRATCH)], check=True)
    subprocess.run([str(py), "-m", "pip", "install", "--quiet", "vlc-rm", "numpy>=2,<2.3",
                    "matplotlib", "luxpy"], check=True, capture_output=True)
    return py


def part_vlcrm(cells):
    print("== 5. Barry's configuration A beside vlc-rm (3 reflections, same cells) ==")
    from irreflect.room.validation import barry_configuration_a, line_of_sight_closed_form

    scene = barry_configuration_a()
    los, tau = line_of_sight_closed_form(scene.emitters[0], scene.receivers[0])
    print(f"  closed-form line of sight (Eq. 5): H = {los:.5g} at {tau * 1e9:.3f} ns")
    try:
        py = vlcrm_python()
    except (subprocess.CalledProcessError, OSError) as exc:
        print(f"  vlc-rm could not be installed ({exc}); no comparison")
        return
    for cell in cells:
        ours = run_json(sys.executable, OURS_DEFAULT, cell)
        theirs = run_json(py, VLCRM, cell)
        ratio = theirs["seconds"] / ours["seconds"]
        print(f"  {cell:g} m: irreflect {ours['cells']} cells {ours['seconds']:.2f} s (cpu "
              f"{ours['cpu']:.2f} s; default, with its error estimate; {load()}), vlc-rm "
              f"{theirs['cells']} cells {theirs['seconds']:.2f} s (cpu {theirs['cpu']:.2f} s): "
              f"{ratio:.1f}x in time, {theirs['cpu'] / ours['cpu']:.1f}x in CPU time; peak RSS "
              f"irreflect {ours['peak_mb']:.0f} MB, vlc-rm {theirs['peak_mb']:.0f} MB")
        print("    H per order (LoS, 1, 2, 3): irreflect " + ", ".join(f"{g:.5g}" for g in ours["gains"])
              + "; vlc-rm " + ", ".join(f"{g:.5g}" for g in theirs["gains"])
              + " (vlc-rm keeps Barry's point coupling between near cells)")
        if cell == 0.125:
            target("time vlc-rm / irreflect at 0.125 m at least 30x", f"{ratio:.1f}x", ratio >= 30)


# ----------------------------------------------------------------------------- Monte Carlo
def part_montecarlo():
    print("== Monte Carlo, one process ==")
    from irreflect.room import load_scene, simulate
    from irreflect.room.validation import barry_configuration_a

    office = load_scene(ROOT / "datasets" / "rooms" / "office.toml")
    office = office.with_receivers(office.receivers[:1])
    for name, scene in (("Lambertian (Barry A)", barry_configuration_a()),
                        ("fitted materials, reciprocal form (office)", office),
                        ("fitted materials, paper's form (office)", office.with_brdf("paper"))):
        simulate(scene, method="montecarlo", bounces=3, rays=100)
        t0 = time.perf_counter()
        res = simulate(scene, method="montecarlo", bounces=3, rays=200_000, seed=0)
        sec = time.perf_counter() - t0
        rel = res.link().stderr_w[1:] / res.link().power_w[1:]
        print(f"  {name}: 200000 rays x 3 bounces in {sec:.2f} s = {res.ray_bounces_per_s:,.0f} "
              "ray-bounces/s; relative standard error per order "
              + ", ".join(f"{r:.2%}" for r in rel))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--parts", nargs="+",
                   default=["swap", "orders", "office", "barry", "vlcrm", "montecarlo"])
    p.add_argument("--rays", type=int, default=4_000_000, help="converged Monte Carlo rays")
    p.add_argument("--swap-rays", type=int, default=1_000_000)
    p.add_argument("--cells", type=float, nargs="+", default=[0.25, 0.125])
    args = p.parse_args(argv)
    print(f"machine: {os.cpu_count()} CPUs; {load()}", flush=True)
    if "swap" in args.parts:
        part_swap(args.swap_rays)
    if "orders" in args.parts:
        part_orders(args.rays)
    if "office" in args.parts:
        part_office()
    if "barry" in args.parts:
        part_barry()
    if "vlcrm" in args.parts:
        part_vlcrm(args.cells)
    if "montecarlo" in args.parts:
        part_montecarlo()
    print("== targets ==")
    for name, measured, ok in RESULTS:
        print(f"  {'PASS' if ok else 'FAIL'}  {name}: {measured}")


if __name__ == "__main__":
    main()
