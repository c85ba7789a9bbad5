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
        added = len(d.steps) > 1
        for j, (label, a) in enumerate((("before", d.before), ("after", d.after))):
            ax = fig.add_subplot(n, 2, 2 * i + j + 1)
            if j == 1 and not added:  # the same fit twice would be a duplicate panel
                _nothing_added(ax, name, d)
                continue
            plot_residual_map(a.fit.gamma_deg, a.fit.theta_deg, a.residuals_z, ax=ax,
                              title=f"{name} {label if added else 'base model, final'}: "
                                    f"{a.model_name}, chi2/dof {a.lack_of_fit.ratio:.3g}",
                              **NORMALIZED)
    fig.tight_layout()
    return fig


def _nothing_added(ax, name: str, diagnosis) -> None:
    """The 'after' cell of a diagnosis that added no effect: a sentence, not a copy."""
    ax.axis("off")
    ax.text(0.5, 0.5, f"{name}: no effect added ({diagnosis.verdict})\nthe base model's "
                      "residuals (left) are the final ones", ha="center", va="center",
            fontsize=9, transform=ax.transAxes, wrap=True)


def plot_residual_maps(diagnosis, fig=None, *, limit: float = 4.0):
    """Residual maps of the base model and of the final (extended) model side by side
    (one map when no effect was added: the same fit twice would be a duplicate panel)."""
    added = len(diagnosis.steps) > 1
    fig = fig or plt.figure(figsize=(12.0 if added else 6.4, 3.8))
    before, after = diagnosis.before, diagnosis.after
    panels = (("before", before), ("after", after)) if added else (("base model", before),)
    for i, (label, a) in enumerate(panels):
        ax = fig.add_subplot(1, len(panels), i + 1)
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
    return plot_polar_per_gamma(measurements, curves, fig=fig,
                                title=f"{diagnosis.name}: {diagnosis.verdict}",
                                styles={k: s for k, s in zip(curves, ("--", "-"),
                                                             strict=False)})


def plot_separation(diagnosis, measurements, fig=None, *, max_panels: int = 3):
    """When the diagnosis is ambiguous: the alternatives' predicted power along theta at
    the angles of incidence of the proposed separating measurements (the measured points
    where that angle was measured; the proposals as vertical lines). Returns the Figure."""
    gammas = list(dict.fromkeys(r["gamma_deg"] for r in diagnosis.separating))[:max_panels]
    fig = fig or plt.figure(figsize=(5.0 * max(len(gammas), 1), 3.6))
    t = np.arange(np.floor(measurements.theta_deg.min()),
                  np.ceil(measurements.theta_deg.max()) + 0.25, 0.25)
    for i, g in enumerate(gammas):
        ax = fig.add_subplot(1, max(len(gammas), 1), i + 1)
        for name, a in diagnosis.alternative_fits.items():
            ax.plot(t, a.fit.predict(np.full_like(t, g), t), label=f"+ {name}")
        sel = measurements.gamma_deg == g
        if np.any(sel):
            ax.plot(measurements.theta_deg[sel], measurements.power[sel], "k.", label="measured")
        for r in diagnosis.separating:
            if r["gamma_deg"] == g:
                ax.axvline(r["theta_deg"], color="0.5", ls=":", lw=1)
                ax.annotate(f"x{r['readings']}: {r['separation_sigma']:.1f} sigma",
                            (r["theta_deg"], 1.0),
                            xycoords=("data", "axes fraction"), fontsize=8, ha="center",
                            va="bottom")
        ax.set_yscale("symlog", linthresh=max(float(np.percentile(np.abs(
            measurements.power), 20)), 1e-12))
        ax.set_xlabel("receiver angle theta (deg)")
        ax.set_ylabel("power (table units)")
        ax.set_title(f"gamma {g:g} deg" + ("" if np.any(sel) else " (not measured)"),
                     fontsize=10)
        if i == 0:
            ax.legend(fontsize=8)
    fig.suptitle(f"{diagnosis.name}: measurements that would separate the alternatives",
                 fontsize=11)
    fig.tight_layout()
    return fig


def write_outputs(diagnosis, measurements, out_dir, extra_tables=None) -> list[Path]:
    """Residual maps before/after (``residuals_before.png``, and ``residuals_after.png``
    when an effect was added: otherwise it would be the same map), the polar fits
    (``polar_fits.png``), when the diagnosis is ambiguous the alternatives at the proposed
    separating measurements (``separation.png``, and ``separating.csv``: the settings as a
    measurement plan, ``gamma_deg, theta_deg, readings, why, separation_sigma``) and
    ``diagnosis.json``, written into ``out_dir`` all together or not at all, with
    ``extra_tables`` (``{path relative to out_dir: DataFrame}``, written as CSV: a
    ``--separate-out`` inside the folder belongs to its manifest). Returns the final
    paths."""
    out = Path(out_dir)
    names = []
    maps = (("before", diagnosis.before), ("after", diagnosis.after))
    with atomic_directory(out, command="diagnose") as tmp:
        for label, a in maps[: 2 if len(diagnosis.steps) > 1 else 1]:
            fig, ax = plt.subplots(figsize=(6.4, 3.8))
            plot_residual_map(a.fit.gamma_deg, a.fit.theta_deg, a.residuals_z, ax=ax,
                              title=f"{diagnosis.name} {label}: {a.model_name}, chi2/dof "
                                    f"{a.lack_of_fit.ratio:.3g}", **NORMALIZED)
            save_figure(fig, tmp / f"residuals_{label}.png")
            names.append(f"residuals_{label}.png")
        save_figure(plot_diagnosis_polar(diagnosis, measurements), tmp / "polar_fits.png")
        names.append("polar_fits.png")
        if diagnosis.separating:
            save_figure(plot_separation(diagnosis, measurements), tmp / "separation.png")
            diagnosis.separating_table().to_csv(tmp / "separating.csv", index=False)
            names += ["separation.png", "separating.csv"]
        (tmp / "diagnosis.json").write_text(dumps(diagnosis.to_dict()))
        names.append("diagnosis.json")
        for rel, table in (extra_tables or {}).items():
            (tmp / rel).parent.mkdir(parents=True, exist_ok=True)
            table.to_csv(tmp / rel, index=False)
            if rel not in names:
                names.append(rel)
    return [out / n for n in names]
