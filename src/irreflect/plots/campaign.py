"""The figure of a replayed measurement campaign (drawn on given axes, never shown; save
with :func:`irreflect.plots.save_figure`)."""

from __future__ import annotations

import matplotlib.ticker
import numpy as np

from ..campaign.replay import NO_BOUND
from .common import plt

_STYLE = {
    "adaptive": dict(color="tab:red", marker="o", ls="-", lw=1.8, ms=4, zorder=5),
    "hindsight": dict(color="k", marker="", ls="--", lw=1.2, zorder=4),
    "random": dict(color="tab:gray", marker=".", ls=":", lw=1.0, zorder=3),
    "paper": dict(color="tab:blue", marker="s", ls="none", ms=8, zorder=6),
    "glossy": dict(color="tab:green", marker="D", ls="none", ms=7, zorder=6),
}
_LABEL = {
    "adaptive": "adaptive campaign (irreflect next)",
    "hindsight": "hindsight: select's best subsets",
    "random": "random readings (median of 3)",
    "paper": "the paper's 12-point protocol",
    "glossy": "glossy-aware protocol (from the dense scan)",
}


def plot_campaign(result, ax=None, *, title=None, span: float = 0.25):
    """R^2 against all points of the dense table versus the number of readings, one line
    (or marker, for the 12-point protocols) per strategy of a
    :class:`~irreflect.campaign.ReplayResult`, with the all-points fit's R^2, the target
    band (within 0.01 of it) and where the adaptive campaign's verdict said stop.

    The vertical axis shows ``span`` below the all-points R^2; lower values are drawn as
    triangles on the bottom edge with their value.

    Returns
    -------
    Axes
    """
    if ax is None:
        _, ax = plt.subplots(figsize=(7.0, 4.2))
    ref, target = result.reference_r2, result.target
    bottom = ref - span
    ns_all = [n for c in result.curves.values() for n in c.r2]
    left = min(ns_all) - 1 if ns_all else 7
    right = max(ns_all) + 1 if ns_all else 26
    ax.axhspan(target, ref, color="tab:green", alpha=0.12, lw=0,
               label="within 0.01 of the all-points fit")
    ax.axhline(ref, color="tab:green", lw=1.0, label=f"all points: R^2 {ref:.4f}")
    for name, curve in result.curves.items():
        if not curve.r2:
            continue
        ns = np.array(sorted(curve.r2))
        r2 = np.array([curve.r2[n] for n in ns], float)
        style = dict(_STYLE.get(name, dict(color="tab:purple", marker="o", ls="-")))
        shown = np.where(np.isfinite(r2), np.maximum(r2, bottom), np.nan)
        reached = curve.reached(target)
        label = _LABEL.get(name, name) + (f" (holds from N = {reached})" if reached else "")
        if NO_BOUND in curve.note:  # see replay_hindsight and _below_paper
            label += (f" ({NO_BOUND}: below the paper's 12 points)"
                      if "below the paper's" in curve.note
                      else f" ({NO_BOUND}: their thorough fits settle elsewhere)")
        ax.plot(ns, shown, label=label, **style)
        low = np.isfinite(r2) & (r2 < bottom)
        if low.any():
            ax.plot(ns[low], np.full(low.sum(), bottom), "v", color=style["color"], ms=7,
                    zorder=7)
            if style.get("ls") == "none":
                for n, v in zip(ns[low], r2[low], strict=True):
                    ax.annotate(f"{v:.3g}", (n, bottom), textcoords="offset points",
                                xytext=(4, 4), fontsize=7, color=style["color"])
    stop = result.stop_n
    if stop is not None:
        ax.axvline(stop, color="tab:red", lw=0.8, ls="-.",
                   label=f"adaptive verdict: stop at N = {stop}")
    ax.set_xlim(left, right)
    ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))
    ax.set_ylim(bottom - 0.01 * span, min(1.0, ref + 0.2 * span))
    ax.set_xlabel("number of readings N")
    ax.set_ylabel("R^2 against all points")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    ax.set_title(title or f"{result.dataset}: campaigns replayed on its {result.n_points} "
                          "points", fontsize=10)
    return ax
