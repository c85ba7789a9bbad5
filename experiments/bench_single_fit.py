"""Benchmark: the engine of a command that fits one table once (``irreflect fit``),
``numpy-first`` (what the CLI uses up to 5000 points) against ``numpy`` (what it used
before stop 42) and ``compiled``, each in a fresh process, as a user's command runs.

A fresh process pays the compiled kernel's load (about a second) before its first fit:
on a table the model fits at once, numpy is faster. On a table the model misfits, the fit
searches a second time, more widely (its retry), and numpy took 8-12 s where the kernel
takes under 1 s. ``numpy-first`` runs the first search with numpy and the second with the
kernel.

Tables: every real set in ``../shared/datasets/real`` and generated tables the model
misfits (``irreflect.synthetic``: foreign, hidden-effect and wild materials), written to
a temporary directory. Per table and engine: the whole process's wall time and the fit's
own time, and R^2 (the engines must agree). Then the totals and the ratio numpy /
numpy-first.

Run: ``.venv/bin/python experiments/bench_single_fit.py [--data-dir DIR]`` (about a
minute, and 5 s per table of DIR; one process at a time, on a quiet machine).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from irreflect.data import real_datasets, write_measurements

ENGINES = ("numpy", "numpy-first", "compiled")

CHILD = r"""
import json, sys, time, warnings
t0 = time.perf_counter()
warnings.simplefilter("ignore")
from irreflect.data import read_measurements
from irreflect.fitting import fit_averaged
m = read_measurements(sys.argv[1])
t1 = time.perf_counter()
r = fit_averaged(m, "two-lobe", 0.0, seed=0, engine=sys.argv[2])
t2 = time.perf_counter()
print(json.dumps({"n": m.n_points, "fit": t2 - t1, "r2": r.r2, "retried": bool(r.retried)}))
"""


def _tables(tmp: Path) -> list[Path]:
    from irreflect.diagnose.hidden import hidden_case
    from irreflect.synthetic import foreign_material, wild_material

    out = list(real_datasets().values())
    made = {
        "foreign-107": foreign_material(107).measurements,
        "foreign-602": foreign_material(602).measurements,
        "hidden-retroreflection-100": hidden_case("retroreflection", 100,
                                                  sigma_column=False).measurements,
        "hidden-offspecular_peak-703": hidden_case("offspecular_peak", 703,
                                                   sigma_column=False).measurements,
        "wild-104": wild_material(104).measurements,
        "wild-602": wild_material(602).measurements,
    }
    for name, meas in made.items():
        path = tmp / f"{name}.csv"
        write_measurements(meas, path)
        out.append(path)
    return out


def _run(path: Path, engine: str) -> dict:
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", CHILD, str(path), engine],
                          capture_output=True, text=True, check=True)
    row = json.loads(done.stdout.strip().splitlines()[-1])
    row["wall"] = time.perf_counter() - t0
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data-dir", type=Path, default=None,
                        help="more tables (every CSV in it), e.g. experiments/unseen_tables.py's")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tables = _tables(Path(tmp))
        if args.data_dir is not None:
            tables += sorted(args.data_dir.glob("*.csv"))
        print(f"{len(tables)} tables, one fresh process per table and engine "
              "(wall time includes the imports and, compiled, the kernel's load)\n")
        print(f"{'table':32s} {'points':>6s} {'retry':>5s}  "
              + "  ".join(f"{e:>20s}" for e in ENGINES))
        totals = dict.fromkeys(ENGINES, 0.0)
        worst = dict.fromkeys(ENGINES, 0.0)
        disagree = []
        for path in tables:
            rows = {e: _run(path, e) for e in ENGINES}
            for e in ENGINES:
                totals[e] += rows[e]["wall"]
                worst[e] = max(worst[e], rows[e]["wall"])
            r2 = [rows[e]["r2"] for e in ENGINES]
            if max(r2) - min(r2) > 1e-6:
                disagree.append(f"{path.stem} (R^2 {min(r2):.6f}-{max(r2):.6f})")
            cells = "  ".join(f"{rows[e]['wall']:6.2f} s ({rows[e]['fit']:5.2f} fit)"
                              for e in ENGINES)
            print(f"{path.stem[:32]:32s} {rows['numpy']['n']:6d} "
                  f"{'yes' if rows['numpy']['retried'] else 'no':>5s}  {cells}")
    print("\ntotal wall time: " + ", ".join(f"{e} {totals[e]:.1f} s" for e in ENGINES))
    print("slowest table:   " + ", ".join(f"{e} {worst[e]:.2f} s" for e in ENGINES))
    print(f"ratio numpy / numpy-first: total {totals['numpy'] / totals['numpy-first']:.2f}, "
          f"slowest {worst['numpy'] / worst['numpy-first']:.2f}")
    print("engines agree on R^2 within 1e-6 on every table" if not disagree else
          "R^2 differs between engines on: " + ", ".join(disagree))


if __name__ == "__main__":
    main()
