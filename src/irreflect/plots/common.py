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

import matplotlib.lines  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402
import numpy as np  # noqa: E402

from .._atomic import atomic_path  # noqa: E402

#: ``radius="auto"`` draws the power on a logarithmic radius when the measured dynamic
#: range (:func:`dynamic_range`) exceeds this: on a glossy material a linear radius squashes
#: every diffuse point into the centre.
LOG_RADIUS_RANGE = 100.0
#: The unit every power axis carries: irreflect keeps the table's own power unit.
POWER_UNIT = "table's power units"


def dynamic_range(power) -> float:
    """Largest measured power over the 10th percentile of the positive ones (1 when there
    is nothing to compare)."""
    p = np.asarray(power, float)
    p = p[np.isfinite(p) & (p > 0)]
    if p.size < 2:
        return 1.0
    return float(p.max() / np.quantile(p, 0.1))


def _log_radius(power, radius: str) -> bool:
    if radius not in ("auto", "linear", "log"):
        raise ValueError(f"radius must be 'auto', 'linear' or 'log', found {radius!r}")
    return radius == "log" or (radius == "auto" and dynamic_range(power) > LOG_RADIUS_RANGE)


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


def _set_log_radius(ax, low: float, high: float) -> None:
    """A logarithmic radius from ``low`` to ``high`` with a few readable labels: at most
    four decades labelled, no minor-tick labels, and three plain labels when the range
    spans less than two decades (matplotlib's own labels then overprint each other, or
    label one tick only). A ``high`` not above ``low`` (a panel whose readings are all zero
    or negative) is raised to a decade above it: there is no range to draw."""
    high = high if high > low else 10.0 * low
    ax.set_rscale("log")
    ax.set_rlim(low, high)
    ticker = matplotlib.ticker
    if high / low < 100.0:
        ticks = np.geomspace(low * 1.05, high / 1.05, 3)
        ax.yaxis.set_major_locator(ticker.FixedLocator(ticks))
        ax.yaxis.set_major_formatter(ticker.FormatStrFormatter("%.2g"))
    else:
        ax.yaxis.set_major_locator(ticker.LogLocator(base=10.0, numticks=4))
    ax.yaxis.set_minor_locator(ticker.NullLocator())
    ax.yaxis.set_minor_formatter(ticker.NullFormatter())


class _PolarScale:
    """The radius of polar diagrams: linear from 0, or logarithmic from a floor below the
    smallest positive measured power; values below what can be drawn (negative, or under
    the floor) are drawn at the bottom and flagged."""

    def __init__(self, power, log: bool):
        p = np.asarray(power, float)
        positive = p[np.isfinite(p) & (p > 0)]
        self.log = log
        self.top = float(np.nanmax(p)) if p.size else 1.0
        self.floor = (float(positive.min()) / 2.0 if positive.size else 1e-3) if log else 0.0

    def clip(self, values) -> tuple[np.ndarray, np.ndarray]:
        """(values drawable on this radius, mask of those that were not)."""
        v = np.asarray(values, float)
        low = v < self.floor if self.log else v < 0.0
        return np.where(low, self.floor, v), low

    def apply(self, ax, top: float | None = None) -> None:
        top = max(top or 0.0, self.top)
        if self.log:
            _set_log_radius(ax, self.floor, top * 1.6)
        else:
            ax.set_rlim(0.0, top * 1.08 if top > 0 else 1.0)

    def caption(self) -> str:
        scale = (f"logarithmic radius from {self.floor:.2g}" if self.log else "linear radius")
        return f"radius: power ({POWER_UNIT}), {scale}"


def _curve(ax, scale, theta_deg, values, **kw):
    """A model curve on a polar axes; returns the angles where the model is not drawable
    (negative power; on a log radius also below the floor)."""
    drawn, low = scale.clip(values)
    ax.plot(np.radians(theta_deg), drawn, **kw)
    return np.asarray(theta_deg)[low], np.asarray(values)[low]


def _flag_undrawable_readings(ax, scale, theta_deg, colour, ms: float) -> None:
    """Open markers at the centre for readings the radius cannot show: zero or negative
    (noise around zero), or on a log radius below its floor; the legend says so (they sat
    at the centre as if measured there, unflagged)."""
    if len(theta_deg) == 0:
        return
    what = ("measured below the radius' floor or <= 0 (drawn at the centre, open)"
            if scale.log else "measured power < 0 (drawn at the centre, open)")
    ax.plot(np.radians(theta_deg), np.full(len(theta_deg), scale.floor), "o", ms=ms,
            mfc="none", color=colour, zorder=5, clip_on=False, label=what)


def _flag_negative(ax, scale, theta_deg, values) -> bool:
    """Red downward triangles at the bottom of the radius where a model predicts negative
    power (no power can be negative: such a fit is flawed there); True when any."""
    theta_deg = np.asarray(theta_deg, float)
    values = np.asarray(values, float)
    neg = values < 0
    if not neg.any():
        return False
    # one marker per stretch of negative values, at its most negative point
    idx = np.flatnonzero(neg)
    runs = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)
    at = [r[np.argmin(values[r])] for r in runs]
    ax.plot(np.radians(theta_deg[at]), np.full(len(at), scale.floor if scale.log else 0.0),
            "v", ms=7, color="red", mec="k", mew=0.5, zorder=6, clip_on=False,
            label="model predicts power < 0 here (drawn at the centre)")
    return True


def _flag_unmeasured_peak(ax, scale, theta_grid, curve, theta_measured, power_measured,
                          colour) -> bool:
    """An open diamond at a model peak that rises above every measured power of that
    incidence (by 20 %) more than 1 deg from any measured point: the fit puts power where
    nothing was measured. True when drawn."""
    if not np.isfinite(curve).any() or theta_measured.size == 0:
        return False
    k = int(np.nanargmax(curve))
    peak_theta, peak = float(theta_grid[k]), float(curve[k])
    near = float(np.min(np.abs(theta_measured - peak_theta)))
    if near <= 1.0 or peak <= 1.2 * float(np.nanmax(power_measured)):
        return False
    ax.plot([np.radians(peak_theta)], [scale.clip([peak])[0][0]], "D", ms=8, mfc="none",
            mew=1.5, color=colour, zorder=6,
            label="model peak with no measured point near it")
    return True


def _dedupe_legend(handles, labels):
    seen, out_h, out_l = set(), [], []
    for h, lb in zip(handles, labels, strict=True):
        if lb in seen or lb.startswith("_"):
            continue
        seen.add(lb)
        out_h.append(h)
        out_l.append(lb)
    return out_h, out_l


def plot_polar(measurements, predict=None, ax=None, *, label="fit", title=None,
               radius: str = "auto"):
    """Measured power per angle of incidence in polar form, with fitted curves.

    Parameters
    ----------
    measurements : Measurements
    predict : callable, optional
        ``predict(gamma_deg, theta_deg) -> power`` (e.g. ``FitResult.predict``) drawn as a
        line over the measured markers of each angle of incidence.
    ax : polar Axes, optional
    radius : ``"auto"`` (default: logarithmic when the measured dynamic range exceeds
        :data:`LOG_RADIUS_RANGE`, as on glossy materials, else linear), ``"linear"`` or
        ``"log"``.

    Every measured point is a marker (open, at the centre, where the radius cannot show it:
    a reading <= 0, or below a log radius' floor); a model peak with no measured point near it is
    marked (open diamond) and negative predicted power is flagged (red triangles at the
    centre); the legend, to the right of the diagram, names every marker.
    """
    ax = _polar_axes(ax)
    scale = _PolarScale(measurements.power, _log_radius(measurements.power, radius))
    colours = plt.cm.viridis(np.linspace(0, 0.9, len(measurements.gammas)))
    top = 0.0
    for colour, g in zip(colours, measurements.gammas, strict=True):
        sel = measurements.gamma_deg == g
        th = measurements.theta_deg[sel]
        p = measurements.power[sel]
        shown, low = scale.clip(p)
        ax.plot(np.radians(th[~low]), shown[~low], "o", ms=3.5, color=colour,
                label=f"gamma = {g:g} deg, measured" if predict is not None
                else f"gamma = {g:g} deg")
        _flag_undrawable_readings(ax, scale, th[low], colour, ms=3.5)
        if predict is not None:
            grid = np.linspace(th.min(), th.max(), 721)
            curve = np.asarray(predict(np.full_like(grid, g), grid), float)
            _curve(ax, scale, grid, curve, ls="-", lw=1.2, color=colour)
            _flag_negative(ax, scale, grid, curve)
            if _flag_unmeasured_peak(ax, scale, grid, curve, th, p, colour):
                top = max(top, float(np.nanmax(curve)))
    scale.apply(ax, top)
    if title:
        ax.set_title(plain(title), fontsize=10)
    handles, labels = _dedupe_legend(*ax.get_legend_handles_labels())
    if predict is not None:
        handles.append(matplotlib.lines.Line2D([], [], color="0.3", lw=1.2))
        labels.append(f"lines: {label} (colour of its gamma)")
    # the axes' caption is the legend's title: beside the diagram, never over the legend
    # (a polar axes' x label sits a whole circle below a half-circle diagram)
    ax.legend(handles, labels, loc="center left", bbox_to_anchor=(1.04, 0.5), fontsize=7,
              frameon=False, title=f"angle: receiver angle theta (deg)\n{scale.caption()}",
              title_fontsize=7, alignment="left")
    return ax


def plot_polar_per_gamma(measurements, curves: dict, fig=None, *, title=None, styles=None,
                         radius: str = "auto"):
    """One polar panel per angle of incidence: measured markers and one line per model
    (``curves``: label -> ``predict(gamma_deg, theta_deg)``), as in the paper's Fig. 25.
    ``styles``: label -> a format string ("--") or a dict of line keywords. ``radius`` as
    in :func:`plot_polar`. One legend for the figure, below the panels; a panel where a
    model predicts negative power says so in its title (and red triangles mark where)."""
    gammas = measurements.gammas
    ncols = min(3, len(gammas))
    nrows = int(np.ceil(len(gammas) / ncols))
    fig = fig or plt.figure(figsize=(4.0 * ncols, 3.2 * nrows + 0.8))
    styles = styles or {}
    scale = _PolarScale(measurements.power, _log_radius(measurements.power, radius))
    handles, labels = [], []
    for i, g in enumerate(gammas):
        ax = _polar_axes(fig.add_subplot(nrows, ncols, i + 1, projection="polar"))
        sel = measurements.gamma_deg == g
        th = measurements.theta_deg[sel]
        shown, low = scale.clip(measurements.power[sel])
        ax.plot(np.radians(th[~low]), shown[~low], "o", ms=3, color="k", label="measured",
                zorder=5)
        _flag_undrawable_readings(ax, scale, th[low], "k", ms=3)
        grid = np.linspace(th.min(), th.max(), 721)
        negative = []
        top = float(np.max(measurements.power[sel]))
        for label, predict in curves.items():
            values = np.asarray(predict(np.full_like(grid, g), grid), float)
            style = styles.get(label, "-")
            kw = ({"ls": "-", "lw": 1.2} | style) if isinstance(style, dict) else {
                "ls": style if style in ("-", "--", "-.", ":") else "-", "lw": 1.2}
            _curve(ax, scale, grid, values, label=label, **kw)
            if _flag_negative(ax, scale, grid, values):
                negative.append(label)
        if top <= scale.floor:  # nothing drawable measured here (all zero or negative):
            top = scale.top     # the whole table's radius, as in a single diagram
        # a sharp model peak between receivers must not squash the measured curve
        if scale.log:
            _set_log_radius(ax, scale.floor, top * 1.6)
        else:
            ax.set_rlim(0.0, 1.25 * top if top > 0 else 1.0)
        ax.set_title(plain(f"gamma = {g:g} deg") + (f"\n{', '.join(negative)}: power < 0"
                                             if negative else ""),
                     fontsize=9, color="red" if negative else "k")
        for h, lb in zip(*ax.get_legend_handles_labels(), strict=True):
            if lb not in labels:
                handles.append(h)
                labels.append(lb)
    heading = (plain(title) + "\n" if title else "") + f"receiver angle theta (deg); " \
        f"{scale.caption()}"
    # above the figure's top edge (the saved figure's tight box takes it in): the first
    # row's panel titles stand high above their half discs, up to that edge
    fig.suptitle(heading, fontsize=10 if title else 9, y=1.0, va="bottom")
    _polar_grid_layout(fig, nrows, heading.count("\n") + 1,
                       max(ax.get_title().count("\n") + 1 for ax in fig.axes),
                       0.3 + 0.22 * np.ceil(len(labels) / 4))
    fig.legend(handles, labels, loc="lower center", ncol=min(len(labels), 4), fontsize=8,
               frameon=False)
    return fig


def _polar_grid_layout(fig, nrows: int, heading_lines: int, title_lines: int,
                       legend_inches: float) -> None:
    """The margins ``tight_layout`` would give a grid of polar panels, set directly (in
    inches: the heading's lines, and the first row's panel titles and 0-deg labels above
    them; the figure legend's rows below): ``tight_layout`` measures every tick label of
    every polar panel, about 1.7 s of a five-panel figure, and the saved figure's tight
    bounding box catches anything that still sticks out. In inches, not shares of the
    height: a tall grid of many angles of incidence kept a blank band of a tenth of its
    height below, and its heading sat on the first row's titles."""
    width, height = fig.get_size_inches()
    top = 0.5 + 0.16 * (title_lines - 1)  # the heading stands above the top edge
    bottom = legend_inches + 0.15
    side = 0.45
    fig.subplots_adjust(left=side / width, right=1.0 - side / width,
                        bottom=bottom / height, top=1.0 - top / height,
                        wspace=0.25, hspace=0.2 + 0.1 * (title_lines - 1) if nrows > 1 else 0.2)


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
    ax.set_zlabel("power (table's power units)")
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
NORMALIZED = {"limit": 4.0, "label": "(measured - model) / sigma (noise sigmas)",
              "source_line": True}


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
    ax.set_ylabel("number of points (count)")
    if title:
        ax.set_title(plain(title), fontsize=10)
    return ax
