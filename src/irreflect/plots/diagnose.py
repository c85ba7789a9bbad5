"""Figures of the discrepancy workflow: residual maps over (gamma, theta) and polar fits.

Every ``plot_*`` draws on the axes / figure it is given (or makes one) and returns it; none
calls ``plt.show()``. :func:`write_outputs` writes the files of ``irreflect diagnose --out``. One
residual map is :func:`irreflect.plots.plot_residual_map` with :data:`~irreflect.plots.NORMALIZED`.
Angles in degrees on every axis.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._atomic import atomic_directory
from .._jsonio import dumps
from .common import NORMALIZED, plain, plot_polar_per_gamma, plot_residual_map, plt, save_figure


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
    fig.suptitle(plain(f"{diagnosis.name}: {diagnosis.verdict}"), fontsize=11)
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


def write_outputs(diagnosis, measurements, out_dir) -> list[Path]:
    """Residual maps before/after (``residuals_before.png``, ``residuals_after.png``), the
    polar fits (``polar_fits.png``) and ``diagnosis.json``, written into ``out_dir`` all
    together or not at all. Returns the final paths."""
    out = Path(out_dir)
    names = []
    with atomic_directory(out, command="diagnose") as tmp:
        for label, a in (("before", diagnosis.before), ("after", diagnosis.after)):
            fig, ax = plt.subplots(figsize=(6.4, 3.8))
            plot_residual_map(a.fit.gamma_deg, a.fit.theta_deg, a.residuals_z, ax=ax,
                              title=f"{diagnosis.name} {label}: {a.model_name}, chi2/dof "
                                    f"{a.lack_of_fit.ratio:.3g}", **NORMALIZED)
            save_figure(fig, tmp / f"residuals_{label}.png")
            names.append(f"residuals_{label}.png")
        save_figure(plot_diagnosis_polar(diagnosis, measurements), tmp / "polar_fits.png")
        names.append("polar_fits.png")
        (tmp / "diagnosis.json").write_text(dumps(diagnosis.to_dict()))
        names.append("diagnosis.json")
    return [out / n for n in names]
