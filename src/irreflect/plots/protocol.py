"""Figures of protocols (drawn on given axes, never shown; save with
:func:`irreflect.plots.save_figure`)."""

from __future__ import annotations

import numpy as np

from .common import plain, plt

_STYLE = {
    "mirror": ("*", "tab:red"),
    "lobe_width": ("^", "tab:orange"),
    "diffuse": ("s", "tab:blue"),
    "central": ("D", "tab:green"),
    "optimised": ("o", "tab:purple"),
    "custom": ("o", "tab:gray"),
}


def plot_protocol(protocol, dense=None, ax=None, *, title=None):
    """Protocol points in the (gamma, theta) plane, as the paper's Fig. 19.

    Parameters
    ----------
    protocol : Protocol
    dense : Measurements, optional
        Drawn as small grey dots (the points a dense scan measured).
    ax : matplotlib Axes, optional

    Returns
    -------
    Axes
    """
    if ax is None:
        _, ax = plt.subplots(figsize=(6.0, 4.2))
    if dense is not None:
        ax.plot(np.abs(dense.gamma_deg), dense.theta_deg, ".", color="0.75", ms=4,
                label="dense scan", zorder=1)
    mags = np.abs(protocol.gamma_deg)
    for purpose in dict.fromkeys(protocol.purpose):
        marker, colour = _STYLE.get(purpose, ("o", "k"))
        sel = np.array([p == purpose for p in protocol.purpose])
        ax.plot(mags[sel], protocol.theta_deg[sel], marker, color=colour, ms=8, ls="none",
                label=purpose.replace("_", " "), zorder=3)
    adjusted = [i for i, a in enumerate(protocol.adjustment) if a]
    for i in adjusted:
        ax.annotate(f"{protocol.adjustment[i]} (asked {protocol.requested_theta_deg[i]:g})",
                    (mags[i], protocol.theta_deg[i]), textcoords="offset points",
                    xytext=(6, -10 if protocol.theta_deg[i] > 0 else 6), fontsize=7)
    gam = np.linspace(0, max(89.0, float(mags.max()) if mags.size else 0.0), 50)
    ax.plot(gam, gam, ":", color="tab:red", lw=0.8, label="mirror direction theta = -gamma")
    if np.isfinite(protocol.theta_min):
        for lim in (protocol.theta_min, protocol.theta_max):
            ax.axhline(lim, color="k", lw=0.6, ls="--")
    ax.set_xlabel("angle of incidence |gamma| (deg)")
    ax.set_ylabel("receiver angle theta (deg)")
    ax.set_xlim(0, max(70.0, float(mags.max()) + 5 if mags.size else 70.0))
    ax.set_ylim(-90, 90)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    if title:
        ax.set_title(plain(title), fontsize=10)
    return ax
