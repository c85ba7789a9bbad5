"""Figures of a point selection: the Pareto frontier (Fig. 18) and the chosen points (Fig. 19).

Every ``plot_*`` draws on the axes (or figure) it is given, or makes them, and returns
them; nothing is shown. :func:`write_outputs` writes the files of one ``irreflect select``
run (tables, summary and figures) into a folder it is given.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.ticker import FuncFormatter

from .._jsonio import dumps
from ..selection.run import PAPER_N
from .common import plain, plt, save_figure


def _log_n_axis(ax, lo: float, hi: float) -> None:
    """Logarithmic N axis with plain integer ticks (7, 10, 12, 20, 50, ...)."""
    ax.set_xscale("log")
    steps = ((7, 8, 10, 12, 15, 20, 30, 50, 100, 200, 500, 1000, 2000) if hi < 300 else
             (7, 12, 20, 50, 100, 200, 500, 1000, 2000))
    ticks = [t for t in steps if lo <= t <= hi]
    ax.set_xticks(ticks)
    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.xaxis.set_minor_formatter(FuncFormatter(lambda v, _: ""))
    ax.set_xlim(lo, hi)


def plot_pareto(result, ax=None, *, title=None, label=None, log_y: bool = True, color=None,
                show_ideal: bool = True, knee_n: int | None = None, methods: dict | None = None,
                legend_below: bool = False):
    """The frontier of (N, 1 - R^2), as in the paper's Fig. 18, explained.

    Parameters
    ----------
    result : SelectionResult (everything below is drawn), or a frontier DataFrame with
        ``n_points`` and ``one_minus_r2`` (only the frontier and, with ``knee_n``, the knee)
    ax : Axes, optional
    log_y : 1 - R^2 on a logarithmic axis
    methods : optional Methods A/B/12 (:func:`~irreflect.selection.compare_methods`): the
        paper's protocol (Method 12) is drawn at N = 12

    A SelectionResult shows the ideal point (fewest points, the all-points fit's 1 - R^2),
    the knee (closest to it in the fixed normalisation of
    :func:`~irreflect.selection.front.knee_coordinates`), the noise-aware "enough points"
    with its range and its threshold (the all-points RMSE plus the noise), the best 12
    points, and the all-points fit. N is on a logarithmic axis.
    """
    if ax is None:
        _, ax = plt.subplots(figsize=(6.4, 5.6 if legend_below else 4.2))
    front = result if not hasattr(result, "front") else result.front
    summary = getattr(result, "front_summary", None)
    knee_n = getattr(result, "knee_n", knee_n)
    x = front["n_points"].to_numpy(float)
    y = front["one_minus_r2"].to_numpy(float)
    line, = ax.plot(x, y, "o-", ms=3.5, lw=1, color=color or "tab:blue",
                    label=label or "Pareto frontier (best subset per N)", zorder=3)
    n_total = summary.n_total if summary is not None else x.max()
    lo = max(min(x.min(), 7) * 0.9, 1)
    _log_n_axis(ax, lo, n_total * 1.12)
    if summary is not None:
        ax.axhline(summary.reference, color="0.35", ls=":", lw=1,
                   label=f"fit on all {n_total} points: 1 - R² = {summary.reference:.4g}")
    # the ideal point is a star drawn on top of everything: where the knee falls on it
    # (the knee is the frontier point closest to it), the knee's open ring surrounds it
    ideal = dict(marker="*", ms=10, color="gold", mec="k", mew=0.8, ls="none", zorder=8)
    if summary is not None and show_ideal:
        ax.plot([summary.n_min], [summary.reference],
                label="ideal point (fewest points, all-points quality)", **ideal)
    elif show_ideal:
        ax.plot([x.min()], [y.min()], label="ideal point", **ideal)
    if knee_n is not None and knee_n in set(x.astype(int)):
        k = int(np.flatnonzero(x == knee_n)[0])
        ax.plot([x[k]], [y[k]], "o", ms=15, mfc="none", mew=2, color="tab:red",
                label=f"knee: N = {knee_n} (closest to the ideal point)", zorder=6)
    enough = getattr(result, "enough", None)
    threshold = None
    if enough is not None:
        threshold = enough.threshold_one_minus_r2(result.measurements.power)
        # drawn in the axis' own quantity: the 1 - R^2 a fit with that RMSE would have
        ax.axhline(threshold, color="tab:green", ls="--", lw=1,
                   label=f"enough-points threshold: 1 - R² = {threshold:.3g}, a fit whose "
                         f"RMSE is the all-points {enough.rmse_all:.3g} + noise sigma "
                         f"{enough.sigma:.3g}")
        if enough.n is not None:
            hi = enough.n_high if enough.n_high is not None else x.max()
            low = enough.n_low if enough.n_low is not None else enough.n
            ax.axvspan(low - 0.3, hi + 0.3, color="tab:green", alpha=0.12, lw=0)
            ax.axvline(enough.n, color="tab:green", lw=1.5,
                       label=f"enough points: {enough.range_text()}")
    if hasattr(result, "best_mask") and result.best_mask(PAPER_N) is not None:
        b = result.best_score(PAPER_N)
        ax.plot([PAPER_N], [b], "s", ms=9, mfc="none", mew=1.8, color="tab:purple",
                label=f"best {PAPER_N} points: R² = {1 - b:.5f}", zorder=5)
    # the vertical range follows the frontier (and the lines drawn across it), not a
    # protocol that fails: that one is drawn at the top edge when it lies above
    finite = y[np.isfinite(y) & (y > 0)]
    levels = list(finite) + ([summary.reference] if summary is not None else []) \
        + ([threshold] if threshold is not None and np.isfinite(threshold) else [])
    levels = [v for v in levels if v > 0]
    y_lo, y_hi = (min(levels) / 1.08, max(levels) * 1.25) if levels else (None, None)
    if methods is not None and methods.get("12", {}).get("r2") is not None:
        e12 = 1.0 - methods["12"]["r2"]
        above = y_hi is not None and e12 > y_hi
        ax.plot([PAPER_N], [y_hi / 1.03 if above else e12], "^" if above else "X", ms=8,
                color="tab:brown", zorder=5,
                label=f"paper's protocol: R² = {methods['12']['r2']:.4g}"
                      + (" (above the axis)" if above else ""))
    if log_y and finite.size:
        ax.set_yscale("log")
    if y_lo is not None:
        ax.set_ylim(y_lo, y_hi)
    ax.set_xlabel("number of points N (points, logarithmic axis)")
    ax.set_ylabel("1 - R² (unitless; fit on N points, judged on all)")
    ax.grid(True, alpha=0.3, which="both")
    if legend_below:
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=1,
                  frameon=False)
    else:
        ax.legend(fontsize=7, loc="upper right", framealpha=0.85)
    if title:
        ax.set_title(plain(title), fontsize=10)
    return ax


def plot_points(measurements, masks: dict, ax=None, *, title=None):
    """Chosen points in the (gamma, theta) plane over all measured points (Fig. 19).

    masks : label -> (n,) bool mask of ``measurements``, or label -> (Measurements, mask)
        for sets chosen on other tables (several materials in one figure, as in Fig. 19);
        each set is drawn with its own marker, slightly offset in gamma so that sets
        sharing a point stay visible.
    """
    if ax is None:
        _, ax = plt.subplots(figsize=(6.0, 4.4))
    m = measurements
    ax.plot(m.gamma_deg, m.theta_deg, ".", color="0.8", ms=4 if m.n_points < 400 else 1.5,
            label="measured")
    g = np.linspace(m.gamma_deg.min(), m.gamma_deg.max(), 2)
    ax.plot(g, -g, "--", color="0.6", lw=0.8, label="mirror direction theta = -gamma")
    markers = ["o", "s", "^", "D", "v", "P"]
    spread = np.linspace(-1.2, 1.2, max(len(masks), 1)) if len(masks) > 1 else [0.0]
    for (label, item), marker, dx in zip(masks.items(), markers * 4, spread, strict=False):
        table, mask = item if isinstance(item, tuple) else (m, item)
        mask = np.asarray(mask, bool)
        ax.plot(table.gamma_deg[mask] + dx, table.theta_deg[mask], marker, ms=7, mfc="none",
                mew=1.5, label=f"{label} ({int(mask.sum())} points)")
    ax.set_xlabel("angle of incidence gamma (deg)")
    ax.set_ylabel("receiver angle theta (deg)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    if title:
        ax.set_title(plain(title), fontsize=10)
    return ax


def plot_selection(result, fig=None, *, methods: dict | None = None, protocol_mask=None):
    """One figure per material: the explained frontier (:func:`plot_pareto`) and, beside
    it, where the knee's, the "enough points'" and the best 12 points lie (Fig. 19).
    Returns the Figure."""
    fig = fig or plt.figure(figsize=(12.5, 5.6))
    left = fig.add_subplot(1, 2, 1)
    right = fig.add_subplot(1, 2, 2)
    meas = result.measurements
    enough = result.enough
    title = (f"{meas.name}: knee N = {result.knee_n}"
             + (f", enough points {enough.range_text()}" if enough is not None else ""))
    plot_pareto(result, ax=left, methods=methods, title=title, legend_below=True)
    masks = {}
    if result.best_mask(PAPER_N) is not None:
        masks[f"best {PAPER_N}"] = result.best_mask(PAPER_N)
    if result.knee_n != PAPER_N and result.best_mask(result.knee_n) is not None:
        masks["knee"] = result.best_mask(result.knee_n)
    if enough is not None and enough.n is not None and enough.n not in (PAPER_N, result.knee_n) \
            and enough.n in result.masks and enough.n <= 3 * PAPER_N:  # more would hide the rest
        masks["enough points"] = result.masks[enough.n]
    if protocol_mask is not None:
        masks["paper's protocol"] = protocol_mask
    plot_points(meas, masks, ax=right, title=f"{meas.name}: where those points lie")
    fig.tight_layout()
    return fig


# ----------------------------------------------------------------------------- output files
#: The files :func:`write_outputs` writes for one run.
OUTPUT_FILES = ("pareto.csv", "optimal_points.csv", "summary.json", "pareto.png",
                "optimal_points.png")


def _points_text(meas, mask) -> str:
    return ";".join(f"({g:g},{t:g})" for g, t in zip(meas.gamma_deg[mask], meas.theta_deg[mask],
                                                        strict=True))


def write_outputs(result, methods: dict | None, directory) -> list[Path]:
    """Write one run's files (:data:`OUTPUT_FILES`) into ``directory``: the frontier with
    its points (``pareto.csv``), the optimal points, ``summary.json`` and the frontier and
    points figures (Figs. 18-19). Not atomic by itself: the caller writes into
    :func:`irreflect._atomic.atomic_directory`. Returns the paths."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    meas = result.measurements
    front = result.front.copy()
    front["points"] = [_points_text(meas, result.masks[int(k)]) for k in front["n_points"]]
    front.to_csv(directory / "pareto.csv", index=False)
    n_opt = result.optimal_n
    result.points(n_opt).to_csv(directory / "optimal_points.csv", index=False)
    (directory / "summary.json").write_text(dumps(result.summary(methods)))
    ax = plot_pareto(result, methods=methods, legend_below=True,
                     title=f"{meas.name}: Pareto frontier ({result.selector}, seed {result.seed})")
    save_figure(ax.figure, directory / "pareto.png")
    masks = {"best subset": result.best_mask(n_opt)}
    if result.knee_n != n_opt:
        masks["knee of the frontier"] = result.best_mask(result.knee_n)
    ax = plot_points(meas, masks, title=f"{meas.name}: chosen points")
    save_figure(ax.figure, directory / "optimal_points.png")
    return [directory / name for name in OUTPUT_FILES]
