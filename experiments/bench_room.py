"""Benchmark of the room simulation, irreflect beside an independent implementation, one run.

1. Barry et al. (1993) configuration A (5 x 5 x 3 m, walls/ceiling 0.8, floor 0.3, emitter
   at (2.5, 2.5, 3) facing down, order 1, receiver at (0.5, 1, 0) facing up, 1 cm^2, 85 deg
   FOV), 3 bounces, recursive method: per-bounce DC gains, time and peak memory of irreflect
   and of `vlc-rm` (PyPI) at the same cells. vlc-rm is installed into a scratch virtual
   environment under /tmp by this script (it is not a dependency of irreflect); if that
   fails, only irreflect's figures are printed.
2. Memory against the number of cells (irreflect must not grow as cells^2).
3. Monte Carlo: ray-bounces per second on one core, Lambertian and fitted two-lobe rooms.
4. A 20 x 20 receiver grid in a 5 x 5 x 3 m room to 3 bounces: local process pool of 2
   workers, and a Dask cluster of 2 workers (--scheduler), results identical to serial.

    python experiments/bench_room.py [--cells 0.25 0.125] [--skip-vlcrm]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRATCH = Path("/tmp/irreflect-bench-vlcrm")

OURS = textwrap.dedent("""
    import json, resource, sys, time
    from irreflect.room import simulate
    from irreflect.room.validation import barry_configuration_a
    cell = float(sys.argv[1])
    scene = barry_configuration_a()
    simulate(scene, method="recursive", bounces=3, cell_m=1.0)  # load the compiled kernels
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    t0 = time.perf_counter()
    res = simulate(scene, method="recursive", bounces=3, cell_m=cell)
    seconds = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    link = res.link()
    print(json.dumps({"seconds": seconds, "peak_mb": peak, "base_mb": base, "cells": res.n_cells,
                      "gains": (link.power_w / scene.emitters[0].power_w).tolist(),
                      "mean_delay_ns": (link.m1 / link.power_w * 1e9).tolist()}))
""")

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
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):
        room.create_environment(tx, rx)
        model = Recursivemodel("A", tx, rx, room)
        model._compute_cir()
        model._compute_dcgain()
    seconds = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps({"seconds": seconds, "peak_mb": peak, "base_mb": base,
                      "cells": int(room.no_points) - 2,
                      "gains": [float(g) for g in model.h_dcgain[:, 0]]}))
""")


def run_json(python, code, *args, env=None):
    out = subprocess.run([str(python), "-c", code, *map(str, args)], capture_output=True,
                         text=True, env=env, check=False)
    if out.returncode != 0:
        raise RuntimeError(out.stderr.strip().splitlines()[-1] if out.stderr else "failed")
    return json.loads(out.stdout.strip().splitlines()[-1])


def vlcrm_python():
    """A scratch venv with vlc-rm (numpy < 2.3: luxpy, which vlc-rm imports, breaks on 2.4)."""
    py = SCRATCH / "bin" / "python"
    if py.exists():
        check = subprocess.run([str(py), "-c", "import vlc_rm.recursivemodel"],
                               capture_output=True, check=False)
        if check.returncode == 0:
            return py
    print(f"installing vlc-rm into the scratch environment {SCRATCH} ...", flush=True)
    subprocess.run([sys.executable, "-m", "venv", str(SCRATCH)], check=True)
    subprocess.run([str(py), "-m", "pip", "install", "--quiet", "vlc-rm", "numpy>=2,<2.3",
                    "matplotlib", "luxpy"], check=True, capture_output=True)
    return py


def part_barry(cells, skip_vlcrm):
    print("== Barry et al. (1993) configuration A, 3 bounces, recursive method ==")
    from irreflect.room.validation import barry_configuration_a, line_of_sight_closed_form

    scene = barry_configuration_a()
    los, tau = line_of_sight_closed_form(scene.emitters[0], scene.receivers[0])
    print(f"closed-form line of sight (Eq. 5): H = {los:.5g} at {tau * 1e9:.3f} ns")
    py = None
    if not skip_vlcrm:
        try:
            py = vlcrm_python()
        except (subprocess.CalledProcessError, OSError) as exc:
            print(f"vlc-rm could not be installed ({exc}); irreflect's figures only")
    for cell in cells:
        ours = run_json(sys.executable, OURS, cell)
        print(f"cells {cell:g} m: irreflect {ours['cells']} cells, {ours['seconds']:.2f} s, "
              f"peak RSS {ours['peak_mb']:.0f} MB ({ours['peak_mb'] - ours['base_mb']:.0f} MB above "
              f"the {ours['base_mb']:.0f} MB of the loaded interpreter)")
        gains = ours["gains"]
        line = "   irreflect H per order (LoS, 1, 2, 3): " + ", ".join(f"{g:.5g}" for g in gains)
        print(line)
        print("   irreflect mean delay per order (ns):   "
              + ", ".join(f"{d:.3f}" for d in ours["mean_delay_ns"]))
        if py is None:
            continue
        try:
            theirs = run_json(py, VLCRM, cell)
        except (RuntimeError, json.JSONDecodeError) as exc:
            print(f"   vlc-rm failed to run ({exc}); irreflect's figures only")
            continue
        print("   vlc-rm    H per order (LoS, 1, 2, 3): "
              + ", ".join(f"{g:.5g}" for g in theirs["gains"]))
        rel = [a / b - 1 for a, b in zip(gains, theirs["gains"], strict=False)]
        print("   difference irreflect / vlc-rm - 1:     " + ", ".join(f"{r:+.2e}" for r in rel))
        print(f"   vlc-rm {theirs['cells']} cells, {theirs['seconds']:.2f} s, peak RSS "
              f"{theirs['peak_mb']:.0f} MB ({theirs['peak_mb'] - theirs['base_mb']:.0f} MB above "
              f"its {theirs['base_mb']:.0f} MB interpreter)")
        print(f"   ratio: time vlc-rm / irreflect = {theirs['seconds'] / ours['seconds']:.1f}x; "
              f"peak memory irreflect / vlc-rm = {ours['peak_mb'] / theirs['peak_mb']:.3f} "
              f"(above interpreter: {(ours['peak_mb'] - ours['base_mb']) / max(theirs['peak_mb'] - theirs['base_mb'], 1):.3f})")
    print("Barry's published curves (Fig. 5 of the paper) carry no tabulated gains; the "
          "line of sight above is the closed form they start from.")


def part_memory(cells):
    print("== irreflect memory against the number of cells (3 bounces) ==")
    prev = None
    for cell in cells:
        r = run_json(sys.executable, OURS, cell)
        extra = r["peak_mb"] - r["base_mb"]
        growth = "" if prev is None else (f"  cells x{r['cells'] / prev[0]:.1f} -> memory above "
                                         f"interpreter x{extra / max(prev[1], 1e-9):.1f}")
        print(f"  {cell:g} m: {r['cells']} cells, {r['seconds']:.2f} s, peak RSS {r['peak_mb']:.0f} MB "
              f"({extra:.0f} MB above the interpreter){growth}")
        prev = (r["cells"], extra)


def part_montecarlo():
    print("== Monte Carlo, one core ==")
    from irreflect.room import load_scene, simulate
    from irreflect.room.validation import barry_configuration_a

    office = load_scene(ROOT / "datasets" / "rooms" / "office.toml")
    office = office.with_receivers(office.receivers[:1])
    for name, scene in (("Lambertian (Barry A)", barry_configuration_a()),
                        ("fitted two-lobe materials (office)", office)):
        simulate(scene, method="montecarlo", bounces=3, rays=100)  # load kernels
        t0 = time.perf_counter()
        res = simulate(scene, method="montecarlo", bounces=3, rays=200_000, seed=0)
        sec = time.perf_counter() - t0
        link = res.link()
        rel = link.stderr_w[1:] / link.power_w[1:]
        print(f"  {name}: 200000 rays x 3 bounces in {sec:.2f} s = "
              f"{res.ray_bounces_per_s:,.0f} ray-bounces/s; relative standard error per order "
              + ", ".join(f"{r:.2%}" for r in rel))


def grid_scene():
    from irreflect.room import load_scene

    office = load_scene(ROOT / "datasets" / "rooms" / "office.toml")
    import numpy as np

    from irreflect.room.scene import Grid, Receiver

    xs = np.linspace(0.125, 4.875, 20)
    grid = Grid("grid20", 0.8, xs, xs)
    rx = office.receivers[0]
    receivers = [Receiver(f"g[{i},{j}]", np.array([x, y, 0.8]), rx.direction, rx.area_m2,
                          rx.fov_deg, grid="grid20", grid_index=(i, j))
                 for j, y in enumerate(xs) for i, x in enumerate(xs)]
    from dataclasses import replace

    return replace(office.with_receivers(receivers, (grid,)), boxes=())


def part_grid(workers):
    print("== 20 x 20 receiver grid, 5 x 5 x 3 m room (fitted two-lobe materials), 3 bounces, "
          "Monte Carlo 20000 rays per receiver ==")
    import numpy as np

    from irreflect.room import simulate

    scene = grid_scene()
    kw = dict(method="montecarlo", bounces=3, rays=20000, seed=0)
    t0 = time.perf_counter()
    pooled = simulate(scene, workers=workers, **kw)
    t_pool = time.perf_counter() - t0
    print(f"  local pool of {workers} workers: {t_pool:.1f} s for {len(scene.receivers)} receivers "
          f"(including the workers' start-up)")
    try:
        import distributed
    except ImportError:
        print("  dask.distributed not installed: no cluster run")
        return
    with distributed.LocalCluster(n_workers=workers, threads_per_worker=1,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        t0 = time.perf_counter()
        dasked = simulate(scene, scheduler=client, **kw)
        t_dask = time.perf_counter() - t0
    same = all(np.array_equal(pooled.links[k].power_w, dasked.links[k].power_w) for k in pooled.links)
    print(f"  Dask cluster of {workers} workers (--scheduler): {t_dask:.1f} s; identical to the pool: "
          f"{same}")
    summary = pooled.summary()
    print(f"  DC gain {summary.dc_gain_total.min():.3g}..{summary.dc_gain_total.max():.3g}, "
          f"range error at 10 MHz {summary.range_error_m.min() * 100:+.1f}.."
          f"{summary.range_error_m.max() * 100:+.1f} cm")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cells", type=float, nargs="+", default=[0.25, 0.125])
    p.add_argument("--memory-cells", type=float, nargs="+", default=[0.25, 0.125, 0.0625])
    p.add_argument("--skip-vlcrm", action="store_true")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--parts", nargs="+", default=["barry", "memory", "montecarlo", "grid"])
    args = p.parse_args(argv)
    print(f"machine: {os.cpu_count()} CPUs; load average {os.getloadavg()[0]:.1f}")
    if "barry" in args.parts:
        part_barry(args.cells, args.skip_vlcrm)
    if "memory" in args.parts:
        part_memory(args.memory_cells)
    if "montecarlo" in args.parts:
        part_montecarlo()
    if "grid" in args.parts:
        part_grid(args.workers)


if __name__ == "__main__":
    main()
