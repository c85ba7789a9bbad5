"""Figures of the discrepancy workflow: residual maps over (gamma, theta) and polar fits.

Every function draws on the axes / figure it is given (or makes one) and returns it; none
calls ``plt.show()`` or writes files (save with :func:`irreflect.plots.save_figure`). One
residual map is :func:`irreflect.plots.plot_residual_map` with :data:`~irreflect.plots.NORMALIZED`.
Angles in degrees on every axis.
"""

from __future__ import annotations

import numpy as np

from .common import NORMALIZED, plot_polar_per_gamma, plot_residual_map, plt


def plot_diagnosis_residuals(diagnoses: dict, fig=None):
    """Normalised residual maps before and after, one row per diagnosis (the report's
    figure; ``diagnoses``: name -> Diagnosis). Returns the Figure."""
    n = len(diagnoses)
    fig = fig or plt.figure(figsize=(12.0, 3.4 * n))
    for i, (name, d) in enumerate(diagnoses.items()):
        for j, (label, a) in enumerate((("before", d.before), ("after", d.after))):
            ax = fig.add_subplot(n, 2, 2 * i + j + 1)
            plot_residual_map(a.fit.gamma_deg, a.fit.theta_deg, a.residuals_z, ax=ax,
                              title=f"{name} {label}: {a.model_name}, chi2/dof "
                                    f"{a.lack_of_fit.ratio:.3g}", **NORMALIZED)
    fig.tight_layout()
    return fig


def plot_residual_maps(diagnosis, fig=None, *, limit: float = 4.0):
    """Residual maps of the base model and of the final (extended) model side by side."""
    fig = fig or plt.figure(figsize=(12.0, 3.8))
    before, after = diagnosis.before, diagnosis.after
    for i, (label, a) in enumerate((("before", before), ("after", after))):
        ax = fig.add_subplot(1, 2, i + 1)
        plot_residual_map(a.fit.gamma_deg, a.fit.theta_deg, a.residuals_z, ax=ax,
                          title=f"{label}: {a.model_name}, chi2/dof {a.lack_of_fit.ratio:.3g}",
                          **(NORMALIZED | {"limit": limit}))
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
