"""Same numbers, and time, of the compiled fits of the diagnosis catalogue's models.

Fits the plain two-lobe model, each of its catalogue extensions ("two-lobe+<effect>")
and a few chains of two, with ``engine="compiled"``, on the tables the diagnosis sees:
``hidden_case(effect, seed)`` for every effect of the catalogue and none (seeds 0-3),
``synthetic_material(seed, "glossy" / "matte")`` (seeds 0-1) and every real table of
``../shared/datasets/real/cornell``. Prints one line per fit (cost, values, nfev,
starts, all to 17 digits) into ``--out``, and the time per model; with ``--compare
FILE`` (the ``--out`` of another commit) it prints the largest relative difference of
cost and values and fails when one exceeds 1e-10 or an evaluation count differs.

Run in two worktrees (before/after a change meant to keep the numbers), in the same
minutes, one worker:
    PYTHONPATH=src .venv/bin/python experiments/check_extended_fits.py --out /tmp/a.txt
    PYTHONPATH=src .venv/bin/python experiments/check_extended_fits.py --out /tmp/b.txt \\
        --compare /tmp/a.txt
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from irreflect.data import read_measurements
from irreflect.diagnose import CATALOGUE
from irreflect.diagnose.hidden import hidden_case
from irreflect.fitting import fit
from irreflect.synthetic import synthetic_material

REAL = Path(__file__).resolve().parents[1] / ".." / "shared" / "datasets" / "real" / "cornell"
PAIRS = ("angle_offset+background", "incidence_reflectance+specular_halo",
         "offspecular_peak+retroreflection", "angle_offset+offspecular_peak")


def tables(real_dir: Path):
    for effect in [None, *CATALOGUE]:
        for seed in range(4):
            yield f"hidden {effect} {seed}", hidden_case(effect, seed).measurements
    for kind in ("glossy", "matte"):
        for seed in range(2):
            yield f"synthetic {kind} {seed}", synthetic_material(seed, kind).measurements
    for path in sorted(real_dir.glob("*.csv")):
        yield f"real {path.name}", read_measurements(path)


def models():
    return ["two-lobe", *(f"two-lobe+{e}" for e in CATALOGUE), *(f"two-lobe+{p}" for p in PAIRS)]


def run(real_dir: Path):
    lines, times = [], {}
    for name, meas in tables(real_dir):
        for model in models():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                t0 = time.process_time()
                r = fit(meas, model, seed=0, engine="compiled")
                times[model] = times.get(model, 0.0) + time.process_time() - t0
            values = " ".join(repr(float(v)) for v in r.values)
            lines.append(f"{name}|{model}|{r.cost!r}|{r.nfev}|{r.n_starts}|{values}")
    return lines, times


def compare(lines, other):
    worst_cost = worst_value = 0.0
    bad = []
    mine = {ln.rsplit("|", 4)[0]: ln for ln in lines}
    for ln in other:
        key = ln.rsplit("|", 4)[0]
        a, b = ln.split("|"), mine[key].split("|")
        ca, cb = float(a[2]), float(b[2])
        worst_cost = max(worst_cost, abs(ca - cb) / max(abs(ca), 1e-300))
        va, vb = np.array(a[5].split(), float), np.array(b[5].split(), float)
        rel = np.abs(va - vb) / np.maximum(np.abs(va), 1e-300)
        worst_value = max(worst_value, float(rel.max()) if rel.size else 0.0)
        if a[3] != b[3] or a[4] != b[4]:
            bad.append(f"{key}: nfev/starts {a[3]}/{a[4]} -> {b[3]}/{b[4]}")
    print(f"compared {len(other)} fits: largest relative difference of the cost {worst_cost:.3g}, "
          f"of the values {worst_value:.3g}; {len(bad)} with other evaluation counts")
    for b in bad[:20]:
        print("  " + b)
    return worst_cost <= 1e-10 and worst_value <= 1e-10 and not bad


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--compare")
    ap.add_argument("--real", default=str(REAL))
    args = ap.parse_args(argv)
    fit(hidden_case(None, 0).measurements, "two-lobe+background", engine="compiled")  # warm
    lines, times = run(Path(args.real))
    Path(args.out).write_text("\n".join(lines) + "\n")
    for model, t in times.items():
        print(f"{model:48s} {t:8.2f} s CPU")
    print(f"{'all':48s} {sum(times.values()):8.2f} s CPU ({len(lines)} fits)")
    if args.compare:
        return 0 if compare(lines, Path(args.compare).read_text().splitlines()) else 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
