"""Peak memory (RSS) and wall time of every command on large generated tables.

Generates two-lobe tables of 20,000 rows (40 gammas x 500 thetas) and 200,000 rows
(400 gammas x 500 thetas), runs every command on them in its own subprocess and prints
its exit code, wall time and peak RSS (``getrusage(RUSAGE_CHILDREN).ru_maxrss`` of a
wrapper process whose only child is the command: the largest process of its tree). A
command is either expected to finish within the documented budget or to refuse up front
(exit 2 with one line saying why and what to do); the last column says which happened.

    .venv/bin/python experiments/bench_memory.py                  # 20,000 and 200,000 rows
    .venv/bin/python experiments/bench_memory.py --rows 20000     # one size
    .venv/bin/python experiments/bench_memory.py --commands fit select
    .venv/bin/python experiments/bench_memory.py --room           # room runs: estimate vs RSS

``--room`` runs ``irreflect room`` at settings whose memory estimate (the one its budget
check uses, :func:`irreflect.room.checks.check_room_budget`) is a few hundred MB to a GB
and prints the estimate beside the measured peak RSS above the loaded interpreter: the
estimate must not be below what the run takes.

A watchdog kills a command whose process tree exceeds ``--kill-gb`` (default 8) of RSS or
runs longer than ``--timeout`` seconds (default 600), so that a regression cannot take the
machine down; such a run is reported as killed.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
import psutil

from irreflect.models import two_lobe_power

#: Table 3 of the paper for terrazzo (u_as, v_as, u_nd, v_nd, u_ns, v_ns, K)
TERRAZZO = (0.01713, -2.379, 1.021, 0.4283, 34.55, -0.3772, 0.4142)
SHAPES = {20_000: (40, 500), 200_000: (400, 500)}

WRAPPER = """
import resource, subprocess, sys
code = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                      text=True)
err = code.stderr.strip().splitlines()
print(code.returncode, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss,
      (err[-1] if err else "").replace("\\n", " "), sep="\\t")
"""


def make_table(n_rows: int, path: Path, seed: int = 0) -> Path:
    """A two-lobe table of ``n_rows`` = gammas x thetas with 1 % Gaussian noise."""
    n_gamma, n_theta = SHAPES.get(n_rows, (max(1, n_rows // 500), 500))
    gammas = -np.round(np.arange(1, n_gamma + 1) * 80.0 / n_gamma, 6)  # includes -10, -20, ...
    thetas = np.linspace(-85.0, 85.0, n_theta)
    g, t = (a.ravel() for a in np.meshgrid(gammas, thetas, indexing="ij"))
    clean = two_lobe_power(np.radians(g), np.radians(t), *TERRAZZO)
    rng = np.random.default_rng(seed)
    power = clean + rng.normal(0.0, 0.01 * clean.max(), clean.size)
    pd.DataFrame({"gamma_deg": g, "theta_deg": t, "power": np.abs(power)}).to_csv(
        path, index=False)
    return path


def commands(data: Path, folder: Path) -> dict[str, list[str]]:
    exe = [sys.executable, "-m", "irreflect.cli"]
    protocol = folder / "protocol.csv"
    if not protocol.exists():
        subprocess.run(exe + ["protocol", "--gammas", "-20", "-40", "-60", "--out",
                              str(protocol)], check=True, capture_output=True)
    data_dir = folder / "datadir"
    data_dir.mkdir(exist_ok=True)
    link = data_dir / data.name
    if not link.exists():
        link.symlink_to(data)
    out = folder / "out"
    return {
        "fit": exe + ["fit", str(data)],
        "plot": exe + ["plot", str(data), "--fit", "--out", str(out / "polar.png")],
        "compare": exe + ["compare", str(data)],
        "diagnose": exe + ["diagnose", str(data)],
        "select": exe + ["select", str(data), "--quiet", "--out", str(out / "select")],
        "select --max-points 30": exe + ["select", str(data), "--quiet", "--max-points", "30",
                                         "--out", str(out / "select30")],
        "protocol --design-from": exe + ["protocol", "--design-from", str(data), "--out",
                                         str(out / "designed.csv")],
        "evaluate-protocol": exe + ["evaluate-protocol", str(protocol), str(data)],
        "reproduce --quick": exe + ["reproduce", "--quick", "--no-progress", "--data-dir",
                                    str(data_dir), "--out", str(out / "report")],
    }


def run(argv: list[str], kill_bytes: float, timeout: float):
    """(exit code or 'killed: ...', seconds, peak RSS in MB, last stderr line)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-c", WRAPPER, *argv], stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    wrapper = psutil.Process(proc.pid)
    killed, seen = None, 0.0
    while proc.poll() is None:
        try:
            tree = [wrapper, *wrapper.children(recursive=True)]
            rss = sum(p.memory_info().rss for p in tree if p.is_running())
        except psutil.Error:
            rss = 0
        seen = max(seen, rss)
        elapsed = time.perf_counter() - t0
        if rss > kill_bytes or elapsed > timeout:
            killed = (f"killed at {rss / 2**30:.1f} GB" if rss > kill_bytes
                      else f"killed after {elapsed:.0f} s")
            for p in reversed(tree):
                try:
                    p.kill()
                except psutil.Error:
                    pass
            break
        time.sleep(0.05)
    out, _ = proc.communicate()
    seconds = time.perf_counter() - t0
    if killed:
        return killed, seconds, seen / 2**20, ""
    code, maxrss_kb, last = out.rstrip("\n").split("\t", 2)
    return int(code), seconds, int(maxrss_kb) / 1024, last


ROOM_CASES = [
    # (label, scene, extra options)
    ("Monte Carlo, office, 1 bounce, --dt 0.001", "office",
     ["--rays", "300", "--bounces", "1", "--dt", "0.001"]),
    ("Monte Carlo, office, 3 bounces, --dt 0.005", "office",
     ["--rays", "2000", "--bounces", "3", "--dt", "0.005"]),
    ("recursive, office (3 receivers), 4 bounces, --cell 0.25 --dt 0.02", "office3",
     ["--method", "recursive", "--bounces", "4", "--cell", "0.25", "--dt", "0.02"]),
]


def room_estimate(scene_path: Path, extra: list[str]) -> float:
    """The memory (bytes) the budget check counts for ``irreflect room`` with ``extra``."""
    from irreflect.room import load_scene
    from irreflect.room.checks import memory_estimate, resolve_settings

    scene = load_scene(scene_path)
    opts = dict(zip(extra[::2], extra[1::2], strict=True))
    keys = {"--rays": ("rays", int), "--bounces": ("bounces", int), "--dt":
            ("time_resolution_ns", float), "--cell": ("cell_m", float),
            "--method": ("method", str)}
    settings = resolve_settings(scene, {keys[k][0]: keys[k][1](v) for k, v in opts.items()})
    return memory_estimate(scene, settings)


def run_room(args) -> None:
    from irreflect.room import load_scene  # noqa: F401  (warms the import for the estimate)

    print(f"{'case':<62} {'estimate':>10} {'peak RSS':>10} {'above interpreter':>18}  exit")
    base = None
    with tempfile.TemporaryDirectory(prefix="bench_memory_room_") as tmp:
        folder = Path(tmp)
        rooms = Path(__file__).resolve().parents[1] / "datasets" / "rooms"
        for f in rooms.iterdir():
            (folder / f.name).write_bytes(f.read_bytes())
        text = (rooms / "office.toml").read_text()
        cut = text.index("[[receiver_grid]]")
        (folder / "office3.toml").write_text(text[:cut] + text[text.index("[simulation]"):])
        exe = [sys.executable, "-m", "irreflect.cli"]
        # the interpreter with the room simulation loaded: a run of no reflection
        code, _, base, _ = run(exe + ["room", str(folder / "office3.toml"), "--out",
                                      str(folder / "base"), "--quiet", "--no-figures",
                                      "--bounces", "0"], args.kill_gb * 2**30, args.timeout)
        for label, scene, extra in ROOM_CASES:
            path = folder / f"{scene}.toml"
            estimate = room_estimate(path, extra)
            argv = exe + ["room", str(path), "--out", str(folder / "out"), "--quiet",
                          "--no-figures", *extra]
            code, seconds, peak_mb, last = run(argv, args.kill_gb * 2**30, args.timeout)
            print(f"{label:<62} {estimate / 2**20:>7.0f} MB {peak_mb:>7.0f} MB "
                  f"{peak_mb - base:>15.0f} MB  {code} ({seconds:.0f} s) {last[:60]}",
                  flush=True)
    print(f"(the interpreter with the room simulation loaded, a run of 0 bounces: "
          f"{base:.0f} MB)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, nargs="+", default=[20_000, 200_000])
    parser.add_argument("--commands", nargs="+", default=None,
                        help="command names to run (default: all; e.g. fit select)")
    parser.add_argument("--kill-gb", type=float, default=8.0)
    parser.add_argument("--timeout", type=float, default=600.0)
    parser.add_argument("--room", action="store_true",
                        help="room runs: the budget's memory estimate beside the peak RSS")
    args = parser.parse_args()
    if args.room:
        run_room(args)
        return
    print(f"pid {os.getpid()}, {os.cpu_count()} CPUs, "
          f"{psutil.virtual_memory().total / 2**30:.0f} GB RAM")
    print(f"{'rows':>8}  {'command':<24} {'exit':>16} {'seconds':>8} {'peak RSS':>10}  outcome")
    with tempfile.TemporaryDirectory(prefix="bench_memory_") as tmp:
        for n_rows in args.rows:
            folder = Path(tmp) / f"rows{n_rows}"
            folder.mkdir()
            data = make_table(n_rows, folder / f"big{n_rows}.csv")
            for name, argv in commands(data, folder).items():
                if args.commands and name.split()[0] not in args.commands and \
                        name not in args.commands:
                    continue
                code, seconds, peak_mb, last = run(argv, args.kill_gb * 2**30, args.timeout)
                outcome = ("finished" if code == 0 else
                           f"refused: {last}" if code == 2 else
                           f"failed: {last}" if isinstance(code, int) else "")
                print(f"{n_rows:>8}  {name:<24} {code!s:>16} {seconds:>8.1f} "
                      f"{peak_mb:>8.0f} MB  {outcome}", flush=True)


if __name__ == "__main__":
    main()
