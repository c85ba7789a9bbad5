"""Speed of the point selection: batched NSGA-II vs a plain elementwise pymoo problem.

Both runs use the same NSGA-II (pymoo), the same operators, population, generations and
seed, on the bundled 132-point terrazzo set. irreflect scores a whole population with one
batched call of ``fitting.fit_subsets``; the baseline is the textbook way: an
``ElementwiseProblem`` calling ``scipy.optimize.least_squares`` once per individual
(bounded trust-region reflective fit of the 7 natural parameters from one data-driven
start). Prints subset fits per second for both, the ratio and the hypervolumes of both
fronts (same reference point).

    .venv/bin/python experiments/bench_select.py                    # pop 100, 30 generations
    .venv/bin/python experiments/bench_select.py --default-runs     # + pop 100 x 200 gens on
                                                                    #   terrazzo and the dense
                                                                    #   1261-point wall paint
Run it when the machine is quiet: it measures wall time.
"""

from __future__ import annotations

import argparse
import resource
import time
import warnings

import numpy as np
from pymoo.algorithms.moo.nsga2 import NSGA2
from pymoo.core.problem import ElementwiseProblem
from scipy.optimize import least_squares

from irreflect import metrics
from irreflect.data import load_bundled, read_measurements, real_data_dir
from irreflect.models import estimate_specular_index, get_model, two_lobe_power
from irreflect.selection import hypervolume, non_dominated, run_selection
from irreflect.selection.problem import (
    VERIFY_FIT,
    MaskDuplicateElimination,
    SizeRepair,
    SizeVariedSampling,
    SubsetCrossover,
    SubsetEvaluator,
    SubsetMutation,
)


class ElementwiseSubsetProblem(ElementwiseProblem):
    """The baseline: one scipy least-squares fit per individual, in a Python loop."""

    def __init__(self, meas, n_min, n_max):
        super().__init__(n_var=meas.n_points, n_obj=2, n_ieq_constr=2, xl=0, xu=1, vtype=bool)
        self.meas = meas
        self.n_min, self.n_max = n_min, n_max
        self.candidates = np.ones(meas.n_points, bool)
        self.g = np.radians(meas.gamma_deg)
        self.t = np.radians(meas.theta_deg)
        spec = get_model("two-lobe").params
        self.lower = np.array([p.lower for p in spec])
        self.upper = np.array([p.upper for p in spec])
        self.fits = 0
        self.failed = 0
        self.best: dict[int, float] = {}
        self.best_mask: dict[int, np.ndarray] = {}

    def _evaluate(self, x, out, *args, **kwargs):
        mask = np.asarray(x, bool)
        k = int(mask.sum())
        g, t, p = self.g[mask], self.t[mask], self.meas.power[mask]
        n_s = estimate_specular_index(g, t, p)
        p0 = np.array([0.05, 0.0, 1.0, 0.0, n_s, 0.0, max(p.max(), 1e-12) * np.pi])
        p0 = np.clip(p0, self.lower + 1e-9, np.minimum(self.upper, 1e300) - 1e-9)
        self.fits += 1
        try:
            with warnings.catch_warnings(), np.errstate(all="ignore"):
                warnings.simplefilter("ignore")
                res = least_squares(lambda q: two_lobe_power(g, t, *q) - p, p0,
                                    bounds=(self.lower, self.upper), method="trf")
            pred = two_lobe_power(self.g, self.t, *res.x)
            score = 1.0 - metrics.r2(self.meas.power, pred)
            if not np.isfinite(score):
                raise ValueError
        except (ValueError, np.linalg.LinAlgError):
            score = 1.0
            self.failed += 1
        if k >= self.n_min and score < self.best.get(k, np.inf):
            self.best[k] = score
            self.best_mask[k] = mask.copy()
        out["F"] = [k, score]
        out["G"] = [self.n_min - k, k - self.n_max]


def run_baseline(meas, pop, gens, seed):
    problem = ElementwiseSubsetProblem(meas, get_model("two-lobe").n_params + 1, meas.n_points)
    algorithm = NSGA2(pop_size=pop, sampling=SizeVariedSampling(np.ones((1, meas.n_points), bool)),
                      crossover=SubsetCrossover(), mutation=SubsetMutation(), repair=SizeRepair(),
                      eliminate_duplicates=MaskDuplicateElimination())
    algorithm.setup(problem, termination=("n_gen", gens), seed=seed, verbose=False)
    t0 = time.perf_counter()
    while algorithm.has_next():
        algorithm.next()
    seconds = time.perf_counter() - t0
    ns = np.array(sorted(problem.best))
    f = np.array([problem.best[k] for k in ns])
    keep = non_dominated(ns, f)
    # the same check irreflect applies to its own front: refit with the thorough settings
    checker = SubsetEvaluator(meas.gamma_deg, meas.theta_deg, meas.power, meas.sigma)
    checked, _ = checker.fit_masks(np.array([problem.best_mask[k] for k in ns]), VERIFY_FIT)
    keep_c = non_dominated(ns, checked)
    at12 = np.flatnonzero(ns == 12)
    return {"fits": problem.fits, "failed": problem.failed, "seconds": seconds,
            "hv": hypervolume(ns[keep], f[keep], meas.n_points),
            "hv_checked": hypervolume(ns[keep_c], checked[keep_c], meas.n_points),
            "best12": problem.best.get(12, np.nan),
            "best12_checked": checked[at12[0]] if at12.size else np.nan}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--pop-size", type=int, default=100)
    ap.add_argument("--generations", type=int, default=30)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--default-runs", action="store_true",
                    help="also time the default run (pop 100, 200 generations) on terrazzo and "
                         "on the dense RGL-EPFL wall paint")
    args = ap.parse_args()
    meas = load_bundled("terrazzo")
    pop, gens = args.pop_size, args.generations
    t0 = time.perf_counter()
    run_selection(meas, pop_size=10, generations=2, seed=99, enough=False)  # warm-up
    print(f"warm-up (imports, loading the compiled kernel from its cache, a 2-generation "
          f"run): {time.perf_counter() - t0:.2f} s")
    print(f"terrazzo ({meas.n_points} points), NSGA-II pop {pop}, {gens} generations, "
          f"seeds {args.seeds}")
    ours, theirs = [], []
    for seed in args.seeds:
        res = run_selection(meas, pop_size=pop, generations=gens, seed=seed)
        search_ns = np.array(sorted(res.search_best))
        search_f = np.array([res.search_best[k][0] for k in search_ns])
        keep = non_dominated(search_ns, search_f)
        hv_search = hypervolume(search_ns[keep], search_f[keep], meas.n_points)
        rate = res.evaluations / res.search_seconds
        ours.append((rate, res.hypervolume, res.best_score(12),
                     res.evaluations / max(1e-9, res.fit_seconds)))
        print(f"  seed {seed} irreflect batched : {res.evaluations:6d} fits in "
              f"{res.search_seconds:6.2f} s = {rate:6.0f} fits/s (fitting alone "
              f"{res.evaluations / max(1e-9, res.fit_seconds):.0f}); hypervolume "
              f"{hv_search:.5f} (checked {res.hypervolume:.5f}); 1-R2 at N=12 "
              f"{res.search_best.get(12, (np.nan,))[0]:.5f} (checked {res.best_score(12):.5f}); "
              f"whole run {res.seconds:.2f} s")
        base = run_baseline(meas, pop, gens, seed)
        brate = base["fits"] / base["seconds"]
        theirs.append((brate, base["hv_checked"], base["best12_checked"]))
        print(f"  seed {seed} elementwise scipy : {base['fits']:6d} fits in "
              f"{base['seconds']:6.2f} s = {brate:6.0f} fits/s ({base['failed']} failed); "
              f"hypervolume {base['hv']:.5f} (checked {base['hv_checked']:.5f}); 1-R2 at N=12 "
              f"{base['best12']:.5f} (checked {base['best12_checked']:.5f})")
    o, t = np.array(ours), np.array(theirs)
    print(f"  mean over seeds: irreflect {o[:, 0].mean():.0f} fits/s end to end "
          f"({o[:, 3].mean():.0f} fitting alone), baseline {t[:, 0].mean():.0f} fits/s, "
          f"speed-up {o[:, 0].mean() / t[:, 0].mean():.1f}x end to end; checked hypervolume "
          f"{o[:, 1].mean():.5f} vs {t[:, 1].mean():.5f}; checked 1-R2 at N=12 "
          f"{o[:, 2].mean():.5f} vs {t[:, 2].mean():.5f}")
    print(f"  targets (issue 11): fitting alone >= 20000 fits/s: "
          f"{'met' if o[:, 3].mean() >= 20000 else 'NOT met'}; end to end >= 5000 fits/s: "
          f"{'met' if o[:, 0].mean() >= 5000 else 'NOT met'}; >= 100x the baseline: "
          f"{'met' if o[:, 0].mean() >= 100 * t[:, 0].mean() else 'NOT met'}; hypervolume at "
          f"least the baseline's: {'met' if o[:, 1].mean() >= t[:, 1].mean() - 1e-5 else 'NOT met'}")
    if args.default_runs:
        tables = [("terrazzo", meas)]
        root = real_data_dir()
        if root is not None and (root / "rgl_epfl" / "rgl_colodur_napoli_4f.csv").exists():
            tables.append(("rgl_colodur_napoli_4f",
                           read_measurements(root / "rgl_epfl" / "rgl_colodur_napoli_4f.csv")))
        for name, table in tables:
            for max_points in (None, 30):
                t0 = time.perf_counter()
                r = run_selection(table, pop_size=100, generations=200, seed=args.seeds[0],
                                  max_points=max_points)
                seconds = time.perf_counter() - t0
                limit = 5.0 if name == "terrazzo" else 15.0
                target = (f"; target < {limit:g} s: {'met' if seconds < limit else 'NOT met'}"
                          if max_points is None else "")
                print(f"  default run (pop 100, 200 generations) on {name} ({table.n_points} "
                      f"points, max_points {max_points}): {seconds:.1f} s{target}, "
                      f"{r.evaluations} fits, {r.fits_per_second:.0f} fits/s, knee N = "
                      f"{r.knee_n}, hypervolume {r.hypervolume:.5f}, R2 at 12 = "
                      f"{1 - r.best_score(12):.5f} (search {r.search_seconds:.1f} s, fitting "
                      f"{r.fit_seconds:.1f} s)")

    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak memory (max RSS of this process): {peak:.0f} MB")


if __name__ == "__main__":
    main()
