"""Figures of a point selection: the Pareto frontier (Fig. 18) and the chosen points (Fig. 19).

Both draw on the axes they are given (or make them) and return them; nothing is shown or
written here (save with :func:`irreflect.plots.save_figure`).
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .run import knee_index  # noqa: E402


def plot_pareto(front, ax=None, *, title=None, label=None, log_y: bool = True,
                color=None, show_ideal: bool = True):
    """Frontier of (N, 1 - R^2) with the ideal point and the knee, as in the paper's Fig. 18.

    Parameters
    ----------
    front : DataFrame with ``n_points`` and ``one_minus_r2`` (a SelectionResult's ``front``)
    ax : Axes, optional
    log_y : 1 - R^2 on a logarithmic axis when it spans more than a decade
    """
    if ax is None:
        _, ax = plt.subplots(figsize=(6.0, 4.0))
    x = front["n_points"].to_numpy(float)
    y = front["one_minus_r2"].to_numpy(float)
    line, = ax.plot(x, y, "o-", ms=3.5, lw=1, color=color, label=label or "Pareto frontier")
    k = knee_index(x, y)
    if show_ideal:
        ax.plot([x.min()], [y.min()], "o", ms=9, color="tab:orange", label="ideal point")
        ax.plot([x[k]], [y[k]], "o", ms=9, mfc="none", mew=2, color="tab:red",
                label=f"knee: N = {int(x[k])}")
    else:
        ax.plot([x[k]], [y[k]], "o", ms=9, mfc="none", mew=2, color=line.get_color())
    if log_y and np.all(y > 0) and y.max() > 10 * y.min():
        ax.set_yscale("log")
    ax.set_xlabel("number of points N")
    ax.set_ylabel("1 - R$^2$ (fit on N points, R$^2$ on all points)")
    ax.grid(True, alpha=0.3, which="both")
    ax.legend(fontsize=8)
    if title:
        ax.set_title(title, fontsize=10)
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
    ax.plot(m.gamma_deg, m.theta_deg, ".", color="0.8", ms=4, label="measured")
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
        ax.set_title(title, fontsize=10)
    return ax
