"""Figures of room simulations: h(t), per-order DC gains, maps over receiver grids, and the
3D extension of a material. ``plot_*(..., ax=None) -> Axes``; nothing is shown or saved
behind the caller's back (use :func:`save`); :func:`write_figures` writes a
room run's set."""

from __future__ import annotations

import matplotlib.patches
import numpy as np

from ..room.results import grid_values, safe_name
from .common import plain, plt

_ORDER_LABEL = {0: "line of sight", 1: "1 reflection"}


def _ax(ax, figsize=(6.4, 4.0)):
    if ax is None:
        _, ax = plt.subplots(figsize=figsize, constrained_layout=True)
    return ax


def save(ax, path, dpi: int = 110) -> None:
    ax.figure.savefig(path, dpi=dpi)
    plt.close(ax.figure)


def plot_impulse_response(result, emitter=0, receiver=0, ax=None, *, max_order=None):
    """h(t) per order (W per ns per W emitted), stacked in time; LoS as a stem."""
    ax = _ax(ax)
    link = result.link(emitter, receiver)
    P = result.scene.emitters[link.emitter].power_w
    dt_ns = result.dt_s * 1e9
    t = np.arange(link.hist.shape[1]) * dt_ns
    top = len(link.power_w) - 1 if max_order is None else min(max_order, len(link.power_w) - 1)
    for k in range(1, top + 1):
        h = link.hist[k] / P / dt_ns
        if np.any(h > 0):
            ax.step(t, h, where="post", lw=1.0,
                    label=_ORDER_LABEL.get(k, f"{k} reflections") + f" (H = {link.power_w[k] / P:.3g})")
    total = link.hist[1:top + 1].sum(axis=0) / P / dt_ns
    if top >= 2:
        ax.step(t, total, where="post", color="k", lw=0.8, alpha=0.6, label="sum of reflections")
    if link.power_w[0] > 0:
        ax.axvline(link.los_delay_s * 1e9, color="C3", ls="--", lw=1,
                   label=f"line of sight (H = {link.power_w[0] / P:.3g})")
    nz = np.nonzero(link.hist.sum(axis=0))[0]
    if nz.size:
        ax.set_xlim(max(0.0, t[nz[0]] - 2), t[nz[-1]] + 2)
    ax.set_xlabel("delay t (ns)")
    ax.set_ylabel("h(t) (1/ns)")
    rx = result.scene.receivers[link.receiver]
    ax.set_title(plain(f"{result.scene.name}: {result.scene.emitters[link.emitter].name} -> {rx.name} "
                 f"({result.method})"), fontsize=9)
    ax.legend(fontsize=7)
    return ax


def plot_bounce_gains(result, emitter=0, receivers=None, ax=None):
    """DC gain per order (0 = line of sight) for some receivers: one marker per receiver and
    order on a logarithmic axis (points, not bars: a bar on a log axis has no baseline and
    its length exaggerates differences), with Monte Carlo error bars, and each order's
    share of the receiver's total gain written in the legend."""
    ax = _ax(ax)
    scene = result.scene
    receivers = list(range(len(scene.receivers))) if receivers is None else list(receivers)
    offsets = np.linspace(-0.15, 0.15, len(receivers)) if len(receivers) > 1 else [0.0]
    markers = ["o", "s", "^", "D", "v", "P"]
    for i, r in enumerate(receivers):
        link = result.link(emitter, r)
        P = scene.emitters[link.emitter].power_w
        gains = link.power_w / P
        orders = np.arange(len(gains))
        shown = gains > 0
        share = ", ".join(f"{100 * g / gains.sum():.0f}" for g in gains) if gains.sum() > 0 \
            else "n/a"
        ax.errorbar(orders[shown] + offsets[i], gains[shown],
                    yerr=(link.stderr_w / P)[shown] if np.any(link.stderr_w > 0) else None,
                    fmt=markers[i % len(markers)], ls=":", lw=0.8, ms=6, capsize=2,
                    label=plain(f"{scene.receivers[r].name}") + f" (share per order: {share} %)")
    ax.set_yscale("log")
    ax.set_xticks(np.arange(result.bounces + 1))
    ax.set_xticklabels(["LoS"] + [str(k) for k in range(1, result.bounces + 1)])
    ax.set_xlabel("reflections (order; LoS = line of sight)")
    ax.set_ylabel("DC gain H(0) (W/W, logarithmic axis)")
    ax.set_title(plain(f"{scene.name}: DC gain per order ({result.method})"), fontsize=9)
    ax.grid(True, axis="y", which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.18), frameon=False)
    return ax


def plot_map(result, summary, grid, column, emitter, ax=None, *, label=None, cmap="viridis",
             center=None):
    """A summary column over a receiver grid (``pcolormesh``), with emitters and boxes drawn."""
    ax = _ax(ax, figsize=(5.6, 4.6))
    x, y, values = grid_values(result, summary, grid, column, emitter)
    kw = {}
    if center is not None:
        lim = np.nanmax(np.abs(values - center)) or 1.0
        kw = {"vmin": center - lim, "vmax": center + lim}
        cmap = "RdBu_r"
    x, y, values = np.asarray(x), np.asarray(y), np.asarray(values)
    if np.size(x) > 1 and np.size(y) > 1:
        mesh = ax.pcolormesh(x, y, values, shading="nearest", cmap=cmap, **kw)
    else:  # a grid one receiver wide has no cells to shade: its receivers as squares
        xx, yy = np.meshgrid(x, y)
        mesh = ax.scatter(xx.ravel(), yy.ravel(), c=values.ravel(), s=90, marker="s",
                          cmap=cmap, edgecolors="k", linewidths=0.4, **kw)
    ax.figure.colorbar(mesh, ax=ax, label=label or column)
    for em in result.scene.emitters:  # white with a black edge: seen on every colour map
        ax.plot(em.position[0], em.position[1], "*", ms=14, mfc="white", mec="k", mew=1.0,
                ls="none", label=f"emitter '{em.name}' (seen from above)")
    for i, b in enumerate(result.scene.boxes):
        ax.add_patch(matplotlib.patches.Rectangle(
            (b.lo[0], b.lo[1]), b.hi[0] - b.lo[0], b.hi[1] - b.lo[1], fill=False,
            ec="magenta", lw=1.5, label="box (furniture), outline seen from above" if i == 0
            else "_box"))
    ax.set_xlim(0, result.scene.size[0])
    ax.set_ylim(0, result.scene.size[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(plain(f"{result.scene.name}: {label or column}\n{grid.name} at z = "
                       f"{grid.z_m:g} m, {emitter} ({result.method})"), fontsize=9)
    if ax.get_legend_handles_labels()[0]:  # below the map: a legend inside would hide cells
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2,
                  frameon=False)
    return ax


def plot_material_3d(material, gamma_deg: float, ax=None, azimuths=(0, 30, 60, 90)):
    """Slices of a material's 3D intensity at one angle of incidence: the plane of incidence
    (azimuth 0) and planes rotated about the normal, in polar form."""
    if ax is None:
        fig = plt.figure(figsize=(5.2, 4.4), constrained_layout=True)
        ax = fig.add_subplot(projection="polar")
    theta = np.linspace(-89.5, 89.5, 721)
    for az in azimuths:
        f = material.intensity(gamma_deg, theta, az)
        ax.plot(np.radians(theta), f, label=f"azimuth {az} deg")
    ax.set_theta_zero_location("N")
    ax.set_theta_direction(-1)  # positive theta (the mirror side) to the right
    ax.tick_params(labelsize=7)
    ax.set_thetamin(-90)
    ax.set_thetamax(90)
    ax.set_title(plain(f"{material.name}: 3D intensity, gamma = {gamma_deg:g} deg"),
                 fontsize=9)
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.05, 0.5), frameon=False,
              title="angle: receiver angle theta (deg)\nradius: intensity (1/sr per W)",
              title_fontsize=7, alignment="left")
    return ax


def write_figures(result, summary, singles, folder) -> list[str]:
    """A room run's figures into ``folder``: h(t) and the DC gain per order for up to six
    single receivers, and a map of the DC gain, range error and delay spread over every
    receiver grid, per emitter. Returns the file names."""
    out = []
    scene = result.scene

    def unique(name: str) -> str:  # names are distinct as files (the scene checks); in case
        stem, k = name[:-4], 2
        while name in out:
            name, k = f"{stem}_{k}.png", k + 1
        return name

    shown = singles[:6]
    for e, em in enumerate(scene.emitters):
        for r in shown:
            name = unique(f"impulse_{safe_name(em.name)}_{safe_name(scene.receivers[r].name)}.png")
            ax = plot_impulse_response(result, e, r)
            save(ax, folder / name)
            out.append(name)
        if shown:
            name = unique(f"bounce_gains_{safe_name(em.name)}.png")
            ax = plot_bounce_gains(result, e, shown)
            save(ax, folder / name)
            out.append(name)
        for grid in scene.grids:
            for column, label in (("dc_gain_total", "DC gain (total)"),
                                  ("range_error_m", "range error (m)"),
                                  ("rms_delay_spread_ns", "RMS delay spread (ns)")):
                if summary[column].isna().all():
                    continue
                name = unique(f"map_{column}_{safe_name(grid.name)}_{safe_name(em.name)}.png")
                ax = plot_map(result, summary, grid, column, em.name, label=label)
                save(ax, folder / name)
                out.append(name)
    return out
