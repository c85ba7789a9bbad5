"""What every figure shares: the backend, :func:`save_figure`, polar diagrams, the 3D
surface, the residual map and histogram and their robust limits. Every ``plot_*`` draws on
the axes or figure it is given (or makes one) and returns it: no ``plt.show()``, no hidden
file writes. Angles in degrees on every axis.

Polar diagrams follow the paper's Figs. 15-17: the surface normal points up, positive
receiver angles (the mirror side) to the right.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")  # irreflect only ever draws to files

import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402
import numpy as np  # noqa: E402

from .._atomic import atomic_path  # noqa: E402


def plain(text):
    """``text`` as plain text in a figure: every ``$`` escaped, so that a name (a file
    stem, a scene's emitter) is never read as matplotlib mathtext (``$\\frac{$`` would stop
    the drawing). irreflect's own labels use no mathtext (R² is a character)."""
    return text if not isinstance(text, str) else text.replace("$", r"\$")


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
        ax.set_title(plain(title), fontsize=10)
    ax.legend(loc="lower left", bbox_to_anchor=(-0.12, -0.18), fontsize=7, ncol=3, frameon=False)
    return ax


def plot_polar_per_gamma(measurements, curves: dict, fig=None, *, title=None, styles=None):
    """One polar panel per angle of incidence: measured markers and one line per model
    (``curves``: label -> ``predict(gamma_deg, theta_deg)``), as in the paper's Fig. 25.
    ``styles``: label -> a format string ("--") or a dict of line keywords."""
    gammas = measurements.gammas
    ncols = min(3, len(gammas))
    nrows = int(np.ceil(len(gammas) / ncols))
    fig = fig or plt.figure(figsize=(4.0 * ncols, 3.2 * nrows))
    styles = styles or {}
    for i, g in enumerate(gammas):
        ax = _polar_axes(fig.add_subplot(nrows, ncols, i + 1, projection="polar"))
        sel = measurements.gamma_deg == g
        th = measurements.theta_deg[sel]
        ax.plot(np.radians(th), measurements.power[sel], "o", ms=3, color="k", label="measured",
                zorder=5)
        grid = np.linspace(th.min(), th.max(), 301)
        for label, predict in curves.items():
            style = styles.get(label, "-")
            if isinstance(style, dict):  # line keywords: ls, lw, color, alpha, zorder
                kw = {"ls": "-", "lw": 1.2} | style
                ax.plot(np.radians(grid), predict(np.full_like(grid, g), grid), label=label,
                        **kw)
            else:
                ax.plot(np.radians(grid), predict(np.full_like(grid, g), grid), style, lw=1.2,
                        label=label)
        ax.set_title(plain(f"gamma = {g:g} deg"), fontsize=9)
        if i == 0:
            ax.legend(loc="lower left", bbox_to_anchor=(-0.2, -0.25), fontsize=7, frameon=False)
    if title:
        fig.suptitle(plain(title), fontsize=11)
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
        ax.set_title(plain(title), fontsize=10)
    return ax


def robust_limit(values, coverage: float = 0.98):
    """Symmetric colour / bin limit: the ``coverage`` quantile of |values|, or their
    maximum when nothing sticks out beyond 1.5 times that quantile (or fewer than 20
    values)."""
    v = np.abs(np.asarray(values, float))
    v = v[np.isfinite(v)]
    if not v.size:
        return 1.0
    full = float(v.max())
    limit = float(np.quantile(v, coverage)) if v.size >= 20 else full
    if limit <= 0 or full <= 1.5 * limit:
        return full if full > 0 else 1.0
    return limit


def robust_limits(values, coverage: float = 0.98) -> tuple[float, list[int], int]:
    """The symmetric colour / bin limit of the residual figures (:func:`robust_limit`: the
    central ``coverage`` of ``|values|``), the indices of the outliers (beyond 1.5 times
    it, at most 5, largest first) and how many values lie beyond it in all. A single
    outlier (a near-zero measured power making a relative residual of -870 %) then no
    longer flattens the scale, and is named."""
    v = np.asarray(values, float)
    limit = robust_limit(v, coverage)
    finite = np.isfinite(v)
    n_beyond = int(np.sum(finite & (np.abs(v) > limit)))
    far = np.flatnonzero(finite & (np.abs(v) > 1.5 * limit))
    far = far[np.argsort(-np.abs(v[far]))][:5]
    return limit, [int(i) for i in far], n_beyond


def plot_residual_map(gamma_deg, theta_deg, values, ax=None, *, title=None,
                      label="measured - model", symmetric=True, robust: bool = False,
                      limit: float | None = None, source_line: bool = False,
                      colorbar: bool = True):
    """Residuals over the (theta, gamma) plane (the paper's Figs. 21-22; the diagnosis's
    normalised residual maps).

    Parameters
    ----------
    gamma_deg, theta_deg : array-like, degrees
        Angle of incidence and receiver angle of every point.
    values : array-like
        *measured - model* (the sign used everywhere in irreflect; say so in ``label``,
        the colour bar's label), in power units, percent or noise sigmas.
    robust : the colour scale covers the central 98 % of |values| and the rest is drawn at
        the limit (a single point with a near-zero measured power no longer flattens the
        map); the colour bar then has arrows.
    limit : a fixed symmetric colour limit (e.g. 4 for residuals in noise sigmas); values
        beyond are drawn at it.
    source_line : also mark the source direction (``theta = gamma``) beside the mirror
        direction, and frame the plot around both (the diagnosis's maps).

    Red = measured above the model. The legend sits above the axes, clear of every row of
    points. Returns the Axes.
    """
    g = np.asarray(gamma_deg, float)
    t = np.asarray(theta_deg, float)
    values = np.asarray(values, float)
    if ax is None:
        ax = plt.figure(figsize=(6.4, 3.6 if source_line else 4.0)).add_subplot()
    if limit is not None:
        vmin, vmax = -limit, limit
    elif symmetric:
        vmax = robust_limit(values) if robust else float(np.nanmax(np.abs(values)))
        vmin = -vmax
    else:
        vmin = vmax = None
    shown = np.clip(values, vmin, vmax) if vmax is not None else values
    if limit is not None:  # residuals in noise sigmas: a diverging map without edges
        size = 28 if g.size <= 300 else 6
        sc = ax.scatter(t, g, c=shown, cmap="RdBu_r", vmin=vmin, vmax=vmax, s=size,
                        edgecolors="none")
    else:
        few = g.size <= 400
        sc = ax.scatter(t, g, c=shown, cmap="coolwarm", vmin=vmin, vmax=vmax,
                        s=28 if few else 6, edgecolor="k" if few else "none", linewidth=0.3)
    if source_line:
        span = np.array([g.min() - 3, g.max() + 3])
        ax.plot(-span, span, "k--", lw=0.8, label="mirror direction")
        ax.plot(span, span, ":", color="0.4", lw=0.9, label="source direction")
        ax.set_ylim(span[0], span[1])
        ax.set_xlim(min(t.min(), -span.max()) - 3, max(t.max(), -span.min()) + 3)
    else:
        mirror = np.unique(g)
        ax.plot(-mirror, mirror, ":", color="0.4", lw=1, label="mirror direction theta = -gamma")
    clipped = vmax is not None and (limit is not None or robust) and \
        np.nanmax(np.abs(values)) > vmax
    if colorbar:
        ax.figure.colorbar(sc, ax=ax, label=label, extend="both" if clipped else "neither",
                           **({"shrink": 0.9} if source_line else {}))
    ax.set_xlabel("receiver angle theta (deg)")
    ax.set_ylabel("angle of incidence gamma (deg)")
    if source_line:
        ax.legend(loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=2, fontsize=7,
                  frameon=False, borderaxespad=0.2)
    else:
        ax.legend(fontsize=7, loc="lower left", bbox_to_anchor=(0.0, 1.0), frameon=False,
                  borderaxespad=0.2)
    if title:
        ax.set_title(plain(title), fontsize=10, pad=18 if source_line else 16)
    return ax


#: The diagnosis's maps: residuals in noise sigmas, clipped at 4, source direction marked.
NORMALIZED = {"limit": 4.0, "label": "(measured - model) / sigma", "source_line": True}


def plot_residual_histogram(values, ax=None, *, title=None,
                            label="(measured - model) / measured (%)", robust: bool = False):
    """Histogram of (normalised) residuals (the paper's Fig. 23). With ``robust``, the
    bins cover the central 98 % of |values| and values beyond fall into the end bins
    (their count is written on the figure)."""
    if ax is None:
        ax = plt.figure(figsize=(5.0, 3.2)).add_subplot()
    values = np.asarray(values, float)
    values = values[np.isfinite(values)]
    bins = min(30, max(8, values.size // 5))
    if robust and values.size:
        limit = robust_limit(values)
        outside = int(np.sum(np.abs(values) > limit))
        ax.hist(np.clip(values, -limit, limit), bins=bins, range=(-limit, limit),
                color="tab:blue", edgecolor="white")
        if outside:
            ax.text(0.99, 0.97, f"{outside} value(s) beyond +-{limit:.3g}\nin the end bins",
                    transform=ax.transAxes, ha="right", va="top", fontsize=7)
    else:
        ax.hist(values, bins=bins, color="tab:blue", edgecolor="white")
    ax.set_xlabel(label)
    ax.set_ylabel("number of points")
    if title:
        ax.set_title(plain(title), fontsize=10)
    return ax
