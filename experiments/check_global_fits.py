"""The whole matrix of the fitter's global check on real data: every registered model on
every real set in ``../shared/datasets/real``, irreflect's cost against the best of 50
random-start bounded ``scipy.optimize.least_squares`` runs (``tests/helpers.py``; the test
suite runs the same check, leaving out n-lobe on the 1000+-point sets for time).

    .venv/bin/python experiments/check_global_fits.py [--starts 50] [--models a,b]

Prints one line per (set, model): irreflect's cost, the reference's, their ratio, and
whether irreflect is at least as good (ratio <= 1 + 1e-6); the count of failures last.
Takes several minutes (the reference is the slow part).
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests.helpers

from irreflect import fit  # noqa: E402
from irreflect.data import read_measurements, real_datasets  # noqa: E402
from irreflect.errors import FitError, FitWarning  # noqa: E402
from irreflect.models import model_names  # noqa: E402
from tests.helpers import least_squares_reference  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--starts", type=int, default=50)
    ap.add_argument("--models", default=None, help="comma-separated (default: every model)")
    args = ap.parse_args(argv)
    models = args.models.split(",") if args.models else model_names()
    sets = real_datasets()
    if not sets:
        print("no real data found beside the checkout (../shared/datasets/real)")
        return 1
    worse = 0
    print(f"{'set':<26} {'model':<26} {'irreflect':>12} {'reference':>12} {'ratio':>9}  ok")
    for name, path in sorted(sets.items()):
        meas = read_measurements(path)
        for model in models:
            t0 = time.perf_counter()
            reference = least_squares_reference(model, meas, n_starts=args.starts, seed=1)
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", FitWarning)
                    ours = fit(meas, model, use_sigma=False).cost
            except FitError:
                ours = float("nan")  # cannot beat a constant: the reference must not either
            ratio = ours / reference
            constant = 0.5 * float(((meas.power - meas.power.mean()) ** 2).sum())
            ok = (ratio <= 1 + 1e-6 if ours == ours  # else: no fit beats a constant
                  else reference >= constant * (1 - 1e-9))
            worse += not ok
            print(f"{name:<26} {model:<26} {ours:12.6g} {reference:12.6g} {ratio:9.6f}  "
                  f"{'yes' if ok else 'NO'}  ({time.perf_counter() - t0:.0f} s)", flush=True)
    print(f"{worse} case(s) where irreflect is worse than the reference")
    return 1 if worse else 0


if __name__ == "__main__":
    sys.exit(main())
