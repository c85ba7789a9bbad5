"""Figures of the discrepancy workflow: residual maps over (gamma, theta) and polar fits.

Every function draws on the axes / figure it is given (or makes one) and returns it; none
calls ``plt.show()`` or writes files (save with :func:`irreflect.plots.save_figure`).
Angles in degrees on every axis.
"""

from __future__ import annotations

import numpy as np

from ..plots import plot_polar_per_gamma, plt


def plot_residual_map(gamma_deg, theta_deg, normalized_residuals, ax=None, *, title=None,
                      limit: float = 4.0, colorbar: bool = True):
    """Normalised residuals ``(measured - model) / sigma`` over (theta, gamma).

    Parameters
    ----------
    gamma_deg, theta_deg : array-like, degrees
        Angle of incidence and receiver angle of every point.
    normalized_residuals : array-like
        Residuals in units of the noise sigma (dimensionless); the colour scale is clipped
        at +-``limit``.
    ax : Axes, optional

    Returns
    -------
    Axes
        Red = measured above the model. The dashed lines mark the mirror direction
        (``theta = -gamma``) and the source direction (``theta = gamma``).
    """
    if ax is None:
        _, ax = plt.subplots(figsize=(6.4, 3.6))
    g = np.asarray(gamma_deg, float)
    t = np.asarray(theta_deg, float)
    z = np.asarray(normalized_residuals, float)
    size = 28 if g.size <= 300 else 6
    sc = ax.scatter(t, g, c=np.clip(z, -limit, limit), cmap="RdBu_r", vmin=-limit, vmax=limit,
                    s=size, edgecolors="none")
    span = np.array([g.min() - 3, g.max() + 3])
    ax.plot(-span, span, "k--", lw=0.8, label="mirror direction")
    ax.plot(span, span, ":", color="0.4", lw=0.9, label="source direction")
    ax.set_ylim(span[0], span[1])
    ax.set_xlim(min(t.min(), -span.max()) - 3, max(t.max(), -span.min()) + 3)
    ax.set_xlabel("receiver angle theta (deg)")
    ax.set_ylabel("angle of incidence gamma (deg)")
    ax.legend(loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=2, fontsize=7,
              frameon=False, borderaxespad=0.2)
    if colorbar:
        ax.figure.colorbar(sc, ax=ax, label="(measured - model) / sigma", shrink=0.9,
                           extend="both" if np.nanmax(np.abs(z)) > limit else "neither")
    if title:
        ax.set_title(title, fontsize=10, pad=18)
    return ax


def plot_residual_maps(diagnosis, fig=None, *, limit: float = 4.0):
    """Residual maps of the base model and of the final (extended) model side by side."""
    fig = fig or plt.figure(figsize=(12.0, 3.8))
    before, after = diagnosis.before, diagnosis.after
    for i, (label, a) in enumerate((("before", before), ("after", after))):
        ax = fig.add_subplot(1, 2, i + 1)
        plot_residual_map(a.fit.gamma_deg, a.fit.theta_deg, a.residuals_z, ax=ax, limit=limit,
                          title=f"{label}: {a.model_name}, chi2/dof {a.lack_of_fit.ratio:.3g}")
    fig.suptitle(f"{diagnosis.name}: {diagnosis.verdict}", fontsize=11)
    fig.tight_layout()
    return fig


def plot_diagnosis_polar(diagnosis, measurements, fig=None):
    """Polar diagram per angle of incidence with the base and the extended fits."""
    curves = {f"base ({diagnosis.before.model_name})": diagnosis.before.fit.predict}
    if len(diagnosis.steps) > 1:
        curves[f"extended ({diagnosis.after.model_name})"] = diagnosis.after.fit.predict
    fig = plot_polar_per_gamma(measurements, curves, fig=fig,
                               title=f"{diagnosis.name}: {diagnosis.verdict}",
                               styles={k: s for k, s in zip(curves, ("--", "-"), strict=False)})
    # a sharp model peak between receivers must not squash the measured curve
    polar = [ax for ax in fig.axes if ax.name == "polar"]
    for ax, g in zip(polar, measurements.gammas, strict=False):
        top = float(np.max(measurements.power[measurements.gamma_deg == g]))
        if top > 0:
            ax.set_rmax(1.25 * top)
    return fig
