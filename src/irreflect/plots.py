"""Figures. Every ``plot_*`` draws on the axes or figure it is given (or makes one) and
returns it: no ``plt.show()``, no hidden file writes. Angles in degrees on every axis.

Polar diagrams follow the paper's Figs. 15-17: the surface normal points up, positive
receiver angles (the mirror side) to the right.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")  # irreflect only ever draws to files

import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402
import numpy as np  # noqa: E402

from ._atomic import atomic_path  # noqa: E402


def _polar_axes(ax=None, fig=None):
    if ax is None:
        fig = fig or plt.figure(figsize=(6.4, 4.6))
        ax = fig.add_subplot(projection="polar")
    ax.set_theta_zero_location("N")
    ax.set_theta_direction(-1)
    ax.set_thetamin(-90)
    ax.set_thetamax(90)
    ax.yaxis.set_major_locator(matplotlib.ticker.MaxNLocator(4))
    ax.tick_params(axis="y", labelsize=7)
    return ax


def plot_polar(measurements, predict=None, ax=None, *, label="fit", title=None):
    """Measured power per angle of incidence in polar form, with fitted curves.

    Parameters
    ----------
    measurements : Measurements
    predict : callable, optional
        ``predict(gamma_deg, theta_deg) -> power`` (e.g. ``FitResult.predict``) drawn as a
        line over the measured markers of each angle of incidence.
    ax : polar Axes, optional
    """
    ax = _polar_axes(ax)
    colours = plt.cm.viridis(np.linspace(0, 0.9, len(measurements.gammas)))
    for colour, g in zip(colours, measurements.gammas, strict=True):
        sel = measurements.gamma_deg == g
        th = measurements.theta_deg[sel]
        ax.plot(np.radians(th), measurements.power[sel], "o", ms=3.5, color=colour,
                label=f"gamma = {g:g} deg")
        if predict is not None:
            grid = np.linspace(th.min(), th.max(), 301)
            ax.plot(np.radians(grid), predict(np.full_like(grid, g), grid), "-", lw=1.2,
                    color=colour)
    ax.set_xlabel("receiver angle theta (deg); radius: power")
    if title:
        ax.set_title(title, fontsize=10)
    ax.legend(loc="lower left", bbox_to_anchor=(-0.12, -0.18), fontsize=7, ncol=3, frameon=False)
    return ax


def plot_polar_per_gamma(measurements, curves: dict, fig=None, *, title=None, styles=None):
    """One polar panel per angle of incidence: measured markers and one line per model
    (``curves``: label -> ``predict(gamma_deg, theta_deg)``), as in the paper's Fig. 25."""
    gammas = measurements.gammas
    ncols = min(3, len(gammas))
    nrows = int(np.ceil(len(gammas) / ncols))
    fig = fig or plt.figure(figsize=(4.0 * ncols, 3.2 * nrows))
    styles = styles or {}
    for i, g in enumerate(gammas):
        ax = _polar_axes(fig.add_subplot(nrows, ncols, i + 1, projection="polar"))
        sel = measurements.gamma_deg == g
        th = measurements.theta_deg[sel]
        ax.plot(np.radians(th), measurements.power[sel], "o", ms=3, color="k", label="measured")
        grid = np.linspace(th.min(), th.max(), 301)
        for label, predict in curves.items():
            ax.plot(np.radians(grid), predict(np.full_like(grid, g), grid),
                    styles.get(label, "-"), lw=1.2, label=label)
        ax.set_title(f"gamma = {g:g} deg", fontsize=9)
        if i == 0:
            ax.legend(loc="lower left", bbox_to_anchor=(-0.2, -0.25), fontsize=7, frameon=False)
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    return fig


def save_figure(fig_or_ax, path, dpi: int = 110):
    """Write a figure atomically and close it."""
    fig = fig_or_ax.figure if hasattr(fig_or_ax, "figure") and not hasattr(fig_or_ax, "savefig") \
        else fig_or_ax
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, bbox_inches="tight", format=str(path).rsplit(".", 1)[-1])
    plt.close(fig)
    return path


def plot_surface(measurements, predict, ax=None, *, highlight=None, title=None):
    """3D P(gamma, theta) surface of the model with the measured points (the paper's Fig. 20).

    ``highlight``: optional bool mask of points drawn as green circles (e.g. the points
    the model was fitted on); the others are red crosses.
    """
    if ax is None:
        fig = plt.figure(figsize=(6.4, 4.8))
        ax = fig.add_subplot(projection="3d")
    g = np.linspace(measurements.gamma_deg.min(), measurements.gamma_deg.max(), 40)
    t = np.linspace(measurements.theta_deg.min(), measurements.theta_deg.max(), 81)
    gg, tt = np.meshgrid(g, t)
    ax.plot_surface(gg, tt, predict(gg, tt), cmap="viridis", alpha=0.55, linewidth=0)
    mask = np.zeros(measurements.n_points, bool) if highlight is None else np.asarray(highlight)
    ax.scatter(measurements.gamma_deg[~mask], measurements.theta_deg[~mask],
               measurements.power[~mask], marker="x", color="tab:red", s=12, label="measured")
    if mask.any():
        ax.scatter(measurements.gamma_deg[mask], measurements.theta_deg[mask],
                   measurements.power[mask], marker="o", color="tab:green", s=30,
                   label="fitted points")
    ax.set_xlabel("gamma (deg)")
    ax.set_ylabel("theta (deg)")
    ax.set_zlabel("power")
    ax.legend(fontsize=7)
    if title:
        ax.set_title(title, fontsize=10)
    return ax


def plot_residual_map(measurements, values, ax=None, *, title=None, label="residual",
                      symmetric=True):
    """Residuals (or normalised residuals) over the (gamma, theta) plane (Figs. 21-22)."""
    if ax is None:
        ax = plt.figure(figsize=(6.4, 3.6)).add_subplot()
    values = np.asarray(values, float)
    vmax = np.nanmax(np.abs(values)) if symmetric else None
    sc = ax.scatter(measurements.theta_deg, measurements.gamma_deg, c=values, cmap="coolwarm",
                    vmin=-vmax if symmetric else None, vmax=vmax, s=28, edgecolor="k",
                    linewidth=0.3)
    mirror = np.unique(measurements.gamma_deg)
    ax.plot(-mirror, mirror, ":", color="0.4", lw=1, label="mirror direction theta = -gamma")
    ax.figure.colorbar(sc, ax=ax, label=label)
    ax.set_xlabel("receiver angle theta (deg)")
    ax.set_ylabel("angle of incidence gamma (deg)")
    ax.legend(fontsize=7, loc="lower left")
    if title:
        ax.set_title(title, fontsize=10)
    return ax


def plot_residual_histogram(values, ax=None, *, title=None, label="relative residual (%)"):
    """Histogram of (normalised) residuals (the paper's Fig. 23)."""
    if ax is None:
        ax = plt.figure(figsize=(5.0, 3.2)).add_subplot()
    values = np.asarray(values, float)
    values = values[np.isfinite(values)]
    ax.hist(values, bins=min(30, max(8, values.size // 5)), color="tab:blue", edgecolor="white")
    ax.set_xlabel(label)
    ax.set_ylabel("number of points")
    if title:
        ax.set_title(title, fontsize=10)
    return ax
