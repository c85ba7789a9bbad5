"""Write measurement tables with a hidden effect (and what is hidden in them) to a folder.

The tables come from :func:`irreflect.diagnose.hidden.hidden_case`: the paper's two-lobe
model (Table 3 parameters of a random material, jittered) on a random goniometer grid with
random Gaussian noise (with or without a ``sigma`` column) plus nothing, one catalogue
effect with a random (detectable) magnitude, or an effect outside the catalogue (periodic
ripple, gamma-dependent asymmetric bump). For each table ``<kind>_<seed>.csv`` the truth
goes to ``truth.json`` (keyed by file name), so the diagnosis can be run blind::

    .venv/bin/python experiments/make_hidden_effects.py --out hidden --seeds 5
    .venv/bin/irreflect diagnose hidden/offspecular_peak_0.csv
    python -c "import json; print(json.load(open('hidden/truth.json'))['tables']['offspecular_peak_0.csv'])"
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from irreflect._atomic import atomic_directory
from irreflect.data import write_measurements
from irreflect.diagnose.hidden import KINDS, MAGNITUDES, hidden_case


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, metavar="DIR", help="folder for the tables")
    parser.add_argument("--seeds", type=int, default=5, help="tables per kind (seeds 0..N-1)")
    parser.add_argument("--kinds", default=",".join(KINDS),
                        help=f"comma-separated kinds (default all: {','.join(KINDS)})")
    args = parser.parse_args(argv)
    kinds = [k for k in args.kinds.split(",") if k]
    truth = {}
    with atomic_directory(Path(args.out)) as tmp:
        for kind in kinds:
            for seed in range(args.seeds):
                case = hidden_case(kind, seed)
                name = f"{kind}_{seed}.csv"
                write_measurements(case.measurements, tmp / name)
                truth[name] = case.truth
        (tmp / "truth.json").write_text(json.dumps(
            {"magnitudes": MAGNITUDES, "tables": truth}, indent=2) + "\n")
    print(f"wrote {len(truth)} tables and truth.json to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
