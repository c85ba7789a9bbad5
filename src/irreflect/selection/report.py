"""The point-selection section of the reproduction report: Figs. 18-19 and Table 5."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

from ..errors import FitError, IrreflectError  # noqa: E402
from ..plots import save_figure  # noqa: E402
from ..reporting import ReportContext, Section  # noqa: E402
from .plots import plot_pareto, plot_points  # noqa: E402
from .run import PAPER_N, compare_methods, knee_point, run_selection  # noqa: E402

#: The knees the paper reports in its text (section 4.3): 12 for terrazzo, 11 for the others.
PAPER_KNEE = {"terrazzo": 12, "plasterboard": 11, "foam_board": 11}

QUICK = dict(pop_size=30, generations=25, max_points=24)
FULL = dict(pop_size=100, generations=100)
#: The knee is also given on the frontier cut at this N (it depends on the range of N).
KNEE_CUT = 30


def reproduce_section(ctx: ReportContext) -> Section:
    """Pareto frontier per dataset (Fig. 18), the best 12 points (Fig. 19), Table 5."""
    budget = QUICK if ctx.quick else FULL
    paper5 = ctx.paper_table("table5_methods_r2.csv")
    results, methods, skipped = {}, {}, []
    for name, meas in ctx.datasets.items():
        ctx.progress(f"selection: {name}")
        try:
            res = run_selection(meas, "two-lobe", seed=ctx.seed, **budget)
            # Method A is the report's common fit on all points
            methods[name] = compare_methods(meas, res, "two-lobe", seed=ctx.seed,
                                            full_fit=ctx.fits.get(name))
        except (IrreflectError, FitError) as exc:
            skipped.append(f"{name}: {exc}")
            continue
        results[name] = res
    if not results:
        return Section("selection", "", "No dataset could be searched: " + "; ".join(skipped))

    front_rows, table5_rows = [], []
    for name, res in results.items():
        m = methods[name]
        knee_r2 = float(res.front.set_index("n_points").loc[res.knee_n, "r2"])
        cut = res.front[res.front["n_points"] <= KNEE_CUT]
        front_rows.append({
            "dataset": name, "n_measured": res.measurements.n_points,
            "knee_n_ours": res.knee_n, f"knee_n_ours_n_le_{KNEE_CUT}":
                knee_point(cut) if len(cut) else None,
            "knee_n_paper": PAPER_KNEE.get(name),
            "r2_at_knee_ours": round(knee_r2, 5),
            "n_within_0_001_of_A": _smallest_n(res.front, m["A"]["r2"] - 0.001),
            "front_points": len(res.front), "subset_fits": res.evaluations,
            "failed_fits": res.failed_fits, "fits_per_s": round(res.fits_per_second),
            "hypervolume": round(res.hypervolume, 5), "seconds": round(res.seconds, 1),
        })
        for key, label in (("A", "A"), ("B", "B"), ("12", "12")):
            row = {"dataset": name, "method": label,
                   "r2_ours": None if m[key]["r2"] is None else round(m[key]["r2"], 5),
                   "n_points_fitted": m[key]["n_points"],
                   "n_points_total": res.measurements.n_points}
            if paper5 is not None:
                hit = paper5[(paper5["material"] == name) & (paper5["method"] == label)]
                row["r2_paper"] = float(hit["r2"].iloc[0]) if len(hit) else None
            row["order_A_B_12"] = "holds" if m["order_holds"] else "violated"
            table5_rows.append(row)
    fronts = pd.DataFrame(front_rows)
    table5 = pd.DataFrame(table5_rows)

    figures = {"pareto_fronts": _figure_fronts(ctx, results),
               "optimal_points": _figure_points(ctx, results)}
    best_rows = []
    for name, res in results.items():
        mask = res.best_mask(PAPER_N)
        if mask is None:
            continue
        meas = res.measurements
        best_rows.append({"dataset": name, "points_gamma_theta_deg": "; ".join(
            f"({g:g}, {t:g})" for g, t in zip(meas.gamma_deg[mask], meas.theta_deg[mask],
                                              strict=True))})
    best = pd.DataFrame(best_rows)

    md = [
        "The optimiser searches subsets of each dense set for the fewest points whose fit "
        "(on those points only) still describes all points: objectives N and 1 - R^2, "
        f"NSGA-II (pymoo), population {budget['pop_size']}, {budget['generations']} "
        f"generations, seed {ctx.seed}"
        + (f", at most {budget['max_points']} points" if "max_points" in budget else "")
        + ". Every subset on the frontier was fitted again with the full fitter's global "
        "screening before being reported; the knee is the frontier point closest to the "
        "ideal point in normalised objective space (Fig. 18). Normalising N over the whole "
        f"frontier (7 to all points) or over N <= {KNEE_CUT} moves the knee: both are shown. "
        "`n_within_0_001_of_A` is the fewest points whose fit comes within 0.001 of Method "
        "A's R^2.",
        "",
        "{table:selection_fronts}",
        "",
        "{figure:pareto_fronts}",
        "",
        "The best 12 points per material (Fig. 19):",
        "",
        "{table:selection_best12}",
        "",
        "{figure:optimal_points}",
        "",
        "Table 5: R^2 on all points of Method A (fit on all points), B (the optimiser's best "
        "12 points) and 12 (the paper's protocol, Table 1, snapped to the nearest measured "
        "point), each fitted on its own points only.",
        "",
        "{table:selection_table5}",
        "",
        _order_text(methods, results),
        "",
        "*Why the knee can differ from the paper's 11-12:* the bundled sets are "
        "reconstructions, the two-lobe model plus Gaussian noise, so the model is exact up to "
        "noise and a handful of well-placed points already fix it: the frontier is flat "
        "beyond ~10 points and the knee of a flat frontier is set by small noise "
        "differences. The paper's real measurements contain what the model misses, which "
        "makes its frontier bend later.",
    ]
    if skipped:
        md += ["", "Not searched: " + "; ".join(skipped)]
    return Section(
        key="selection",
        title="",
        markdown="\n".join(md),
        tables={"selection_fronts": fronts, "selection_table5": table5,
                "selection_best12": best},
        figures=figures,
    )


def _smallest_n(front: pd.DataFrame, r2: float):
    hit = front[front["r2"] >= r2]
    return int(hit["n_points"].min()) if len(hit) else None


def _order_text(methods: dict, results: dict) -> str:
    parts = []
    for name in results:
        m = methods[name]
        parts.append(f"{name}: {m['note']}")
    return ("A >= B >= 12, expected from a sound fitter (A is the least-squares optimum on "
            "exactly the points R^2 is computed on): " + "; ".join(parts) + ". The paper's "
            "Table 5 has B above A, which a fit reaching its global optimum on all points "
            "cannot give.")


def _figure_fronts(ctx: ReportContext, results: dict):
    k = len(results)
    fig, axes = plt.subplots(1, k, figsize=(4.6 * k, 3.8), squeeze=False)
    for ax, (name, res) in zip(axes[0], results.items(), strict=True):
        plot_pareto(res.front, ax=ax, title=f"{name}: knee N = {res.knee_n}")
    fig.tight_layout()
    return save_figure(fig, ctx.figure_path("selection_pareto_fronts"))


def _figure_points(ctx: ReportContext, results: dict):
    items = {name: (res.measurements, res.best_mask(PAPER_N)) for name, res in results.items()
             if res.best_mask(PAPER_N) is not None}
    first = next(iter(results.values())).measurements
    ax = plot_points(first, items, title=f"best {PAPER_N} points per material")
    if len(items) > 1:
        ax.set_title(f"best {PAPER_N} points per material (grey: {first.name}'s grid)",
                     fontsize=10)
    return save_figure(ax.figure, ctx.figure_path("selection_optimal_points"))
