"""Figures of a model comparison (the paper's Fig. 25 and Table 6 as a chart) and the files
of ``irreflect compare --out``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.ticker import FuncFormatter, LogLocator

from .._atomic import atomic_directory
from .._jsonio import dumps
from ..compare import Comparison, at_label
from .common import plain, plot_polar_per_gamma, plt, save_figure

_STYLES = {"two-lobe": "-.", "phong": ":"}


def _curve_style(label: str) -> dict:
    """Line style of a model in every comparison figure: the two-lobe model dark, on top
    and dash-dotted; ``MODEL@G`` wide, light and solid underneath, so that where the two
    agree (Phong at its own incidence) both stay visible."""
    if label == "two-lobe":
        return {"ls": "-.", "lw": 1.6, "color": "tab:blue", "zorder": 4}
    if "@" in label:
        return {"ls": "-", "lw": 3.2, "color": "tab:orange", "alpha": 0.55, "zorder": 2}
    return {"ls": _STYLES.get(label, "--"), "lw": 1.1, "zorder": 3,
            "color": _COLOURS.get(label.partition(":")[0])}


#: One colour per literature model in every comparison figure (blue and orange are the
#: two-lobe model's and phong@G's).
_COLOURS = {"phong": "tab:green", "blinn-phong": "tab:red", "lafortune": "tab:purple",
            "ward": "tab:brown", "torrance-sparrow": "tab:pink", "oren-nayar": "tab:gray",
            "single-lobe": "tab:olive", "n-lobe": "tab:cyan"}


def plot_comparison_polar(comparison: Comparison, models=None, fig=None, *, gammas=None,
                          title=None):
    """Measured markers and every model's curve, one polar panel per angle of incidence
    (the paper's Fig. 25). ``models``: labels to draw (default all); ``gammas``: the
    angles of incidence (|gamma|, deg) to show (default all). Returns the Figure."""
    names = list(models) if models is not None else list(comparison.scores)
    curves = {n: comparison.scores[n].predict for n in names}
    styles = {n: _curve_style(n) for n in names}
    meas = comparison.measurements
    if gammas is not None:
        keep = np.isin(np.round(np.abs(meas.gamma_deg), 6), np.round(np.abs(gammas), 6))
        meas = meas.subset(keep)
    fig = plot_polar_per_gamma(meas, curves, fig=fig, styles=styles,
                               title=title or f"{comparison.data_name}: measured and fitted")
    # one legend for the figure, below the panels, instead of over the first panel
    first = fig.axes[0]
    if first.get_legend() is not None:
        handles, labels = first.get_legend_handles_labels()
        first.get_legend().remove()
        fig.legend(handles, labels, loc="lower center", ncol=min(len(labels), 5),
                   fontsize=8, frameon=False)
    return fig


def plot_errors_per_gamma(comparison: Comparison, ax=None, *, log=True, legend=True,
                          title=None):
    """Line chart of the relative polar-area error (%) against the angle of incidence,
    one line per model (Table 6 as a figure; section 5.3). Returns the Axes."""
    if ax is None:
        _, ax = plt.subplots(figsize=(7.5, 4.0))
    for label, s in comparison.scores.items():
        g = list(s.per_gamma_error_pct)
        style = _curve_style(label)
        ax.plot(g, list(s.per_gamma_error_pct.values()), style.get("ls", "-"), marker="o",
                ms=3, lw=style.get("lw", 1.2), color=style.get("color"),
                alpha=style.get("alpha", 1.0), zorder=style.get("zorder", 2), label=label)
    ax.set_xlabel("angle of incidence |gamma| (deg)")
    ax.set_ylabel("relative polar-area error (%)")
    if log:
        _log_axis(ax)
    ax.set_title(plain(title or f"{comparison.data_name}: error per angle of incidence (section 5.3)"),
                 fontsize=10)
    if legend:
        ax.legend(fontsize=7, ncol=2, frameon=False)
    ax.grid(alpha=0.3, which="both")
    return ax


def _log_axis(ax):
    """Log scale with plain numbers (1, 2, 5, 10, ...) as tick labels."""
    ax.set_yscale("log")
    ax.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.yaxis.set_minor_formatter(FuncFormatter(lambda v, _: ""))


def write_outputs(comparison: Comparison, out_dir) -> list[Path]:
    """Write ``comparison_polar.png``, ``comparison_errors.png``, ``comparison.csv`` and
    ``comparison.json`` into ``out_dir``, all or nothing."""
    out_dir = Path(out_dir)
    names = ["comparison_polar.png", "comparison_errors.png", "comparison.csv",
             "comparison.json"]
    with atomic_directory(out_dir, command="compare") as tmp:
        save_figure(plot_comparison_polar(comparison), tmp / names[0])
        save_figure(plot_errors_per_gamma(comparison), tmp / names[1])
        comparison.table().to_csv(tmp / names[2], float_format="%.6g")
        (tmp / names[3]).write_text(dumps(comparison.to_dict()))
    return [out_dir / n for n in names]


def plot_error_lines(comparisons: dict):
    """Line chart of the polar-area error against |gamma|, one panel per dataset, one
    legend for all panels (below them)."""
    n = len(comparisons)
    ncols = min(2, n)
    nrows = int(np.ceil(n / ncols))
    fig, axes = plt.subplots(nrows, ncols, figsize=(6.2 * ncols, 3.6 * nrows), squeeze=False)
    for ax, (name, comp) in zip(axes.flat, comparisons.items(), strict=False):
        at = at_label(comp)
        plot_errors_per_gamma(comp, ax=ax, legend=False,
                              title=name + (f" (phong@G: {at}, fitted at |gamma| = "
                                            f"{at.split('@')[1]} deg)" if at else ""))
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    handles, labels = {}, []
    for ax in list(axes.flat)[:n]:
        for h, label in zip(*ax.get_legend_handles_labels(), strict=True):
            label = "phong@G (fitted at one incidence)" if "@" in label else label
            if label not in handles:
                handles[label] = h
                labels.append(label)
    fig.tight_layout(rect=(0, 0.06 if nrows > 1 else 0.1, 1, 1))
    fig.legend([handles[lb] for lb in labels], labels, loc="lower center",
               ncol=min(len(labels), 5), fontsize=8, frameon=False)
    return fig
