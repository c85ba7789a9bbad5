"""The discrepancy workflow's section of the reproduction report."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..diagnose.hidden import KINDS, OUTSIDE, hidden_case
from ..diagnose.workflow import (
    EFFECTS_FOUND,
    NO_MISSING_EFFECT,
    UNEXPLAINED,
    diagnose,
)
from ..errors import IrreflectError
from ..plots import save_figure
from ..plots.diagnose import plot_diagnosis_residuals
from .base import Finding, ReportContext, Section


def _effects_text(d) -> str:
    text = "; ".join(
        f"{e.name} (" + ", ".join(f"{k} = {v:.3g}" for k, v in e.params.items())
        + (f", LR {e.lr:.0f})" if np.isfinite(e.lr) else ")") for e in d.effects)
    if d.alternatives:
        alts = " or ".join(" + ".join(a) for a in d.alternatives)
        text = (text + "; " if text else "") + f"ambiguous: {alts}"
    return text or "-"


@dataclass
class DiagnoseRun:
    """What the section computes (:func:`compute`), before it is written (:func:`render`):
    every dataset's :class:`~irreflect.diagnose.workflow.Diagnosis`, the summary rows of
    the datasets that could not be diagnosed, the blind test's table (None in a quick
    run)."""

    results: dict
    failed: list
    blind: pd.DataFrame | None


def compute(ctx: ReportContext) -> DiagnoseRun:
    """Diagnose every dataset of the report and, in a full run, the blind test."""
    max_effects = 1 if ctx.quick else 3
    results, failed = {}, []
    for name, meas in ctx.datasets.items():
        ctx.progress(f"diagnose {name}")
        try:
            results[name] = diagnose(meas, seed=ctx.seed, max_effects=max_effects)
        except IrreflectError as exc:  # e.g. no sigma and too few receiver angles per gamma
            failed.append({"dataset": name, "points": meas.n_points,
                           "verdict": f"not diagnosed: {exc}"})
    blind = None
    if not ctx.quick:
        ctx.progress("diagnose: blind test on hidden effects")
        blind = _blind_table(seeds=4, first_seed=ctx.seed + 500)
    return DiagnoseRun(results, failed, blind)


def section(ctx: ReportContext) -> Section:
    """Diagnose every dataset of the report (and, in a full run, a blind test on tables with
    hidden effects): verdict, effects added, the gap before and after, residual maps."""
    return render(ctx, compute(ctx))


def _summary_tables(run: DiagnoseRun) -> dict:
    results, rows, cand_rows = run.results, list(run.failed), []
    for name, d in results.items():
        b, a = d.before, d.after
        rows.append({
            "dataset": name, "points": d.n_points,
            "noise sigma": float(f"{d.noise.value:.3g}"), "noise": d.noise.source,
            "chi2/dof before": round(b.lack_of_fit.ratio, 3),
            "p before": float(f"{b.lack_of_fit.p_value:.2g}"),
            "effects added": _effects_text(d),
            "chi2/dof after": round(a.lack_of_fit.ratio, 3),
            "RMSE before": float(f"{b.fit.rmse:.4g}"), "RMSE after": float(f"{a.fit.rmse:.4g}"),
            "R2 before": round(b.fit.r2, 5), "R2 after": round(a.fit.r2, 5),
            "verdict": d.verdict,
        })
        if d.candidates:
            for c in d.candidates[0]:
                cand_rows.append({"dataset": name, "candidate": c.name,
                                  "likelihood ratio": round(c.lr, 1)
                                  if np.isfinite(c.lr) else None,
                                  "p": float(f"{c.p_value:.2g}")
                                  if np.isfinite(c.p_value) else None,
                                  "share of excess explained": round(c.share_explained, 2),
                                  "decision": c.reason})
    tables = {"diagnose_summary": pd.DataFrame(rows),
              "diagnose_candidates": pd.DataFrame(cand_rows)}
    return tables


def _where(run: DiagnoseRun, ctx: ReportContext):
    """The markdown list of what each diagnosis found, and the findings."""
    results = run.results
    where_md, findings = [], []
    for name, d in results.items():
        kind = "reconstruction" if ctx.is_reconstruction(name) else "measured"
        misfit = d.before.fit.rmse / d.noise.value if d.noise.value > 0 else float("nan")
        head = (f"- **{name}** ({kind}; all-points RMSE {d.before.fit.rmse:.3g} = "
                f"{misfit:.3g} x the noise sigma {d.noise.value:.3g}, {d.noise.source}): "
                f"*{d.verdict}*. {d.summary}")
        where_md.append(head)
        where_md += [f"    - {w}" for w in d.where]
        if d.unexplained and not ctx.is_reconstruction(name):
            added = (f"after adding {', '.join(e.name for e in d.effects)}, "
                     if d.effects else "")
            findings.append(Finding(1, name, (
                f"{added}the two-lobe model leaves structure no catalogue effect explains "
                f"(chi2/dof {d.after.lack_of_fit.ratio:.3g}; all-points RMSE {misfit:.0f} "
                "times the noise)" + (f": {d.where[0]}" if d.where else ""))))
        elif d.effects or d.alternatives:
            findings.append(Finding(2, name, "missing effect found: " + _effects_text(d)))
    return where_md, findings


def render(ctx: ReportContext, run: DiagnoseRun) -> Section:
    """The section of :func:`compute`'s results: tables, residual maps, markdown."""
    results = run.results
    tables = _summary_tables(run)
    where_md, findings = _where(run, ctx)
    figures = {}
    if results:
        figures["diagnose_residuals"] = save_figure(plot_diagnosis_residuals(results),
                                                    ctx.figure_path("diagnose_residuals"))
    blind = ""
    if run.blind is not None:
        tables["diagnose_blind"] = run.blind
        blind = (
            "\n\nBlind test: tables made by the two-lobe model with one hidden effect (random "
            "material, grid, noise and magnitude; `irreflect.diagnose.hidden`), 4 per kind. "
            "Expected verdict: 'no missing effect' with nothing hidden, 'effects found' with "
            "a catalogue effect, 'unexplained structure remains' with an outside one (ripple, "
            "bump). For the rates over many seeds run `experiments/diagnose_rates.py`.\n\n"
            "{table:diagnose_blind}"
        )
    markdown = (
        "For each dataset the two-lobe fit is judged against the measurement noise (the "
        "table's `sigma` column when present, otherwise estimated from differences along "
        "theta, with a part proportional to the power when the data show one): lack of fit "
        "(chi2/dof, 1 = noise only), runs and clusters of the normalised residuals by gamma, "
        "theta, distance from the mirror and from the source direction. Explanations made "
        "of catalogue effects (incidence-dependent K, off-specular peak, retroreflection, "
        "receiver-angle offset, background, specular halo; one, then two, ...) are fitted "
        "on top and compared by likelihood ratio: the smallest explanations no further "
        "effect improves significantly (level 0.01, Bonferroni) are named; when several "
        "fit equally well the diagnosis says which, and where to measure to separate them "
        "(method: docs/diagnose.md)."
        + (" Quick run: at most one effect per dataset." if ctx.quick else "")
        + "\n\n{table:diagnose_summary}\n\nWhat each diagnosis found and where the "
        "residual structure lies:\n\n" + "\n".join(where_md)
        + ("\n\nThe measured tables' noise is estimated from differences along theta; on "
           "tables resampled onto a fine grid (the RGL-EPFL scans are interpolated) that "
           "estimate is tiny, so any misfit is significant: read chi2/dof there as the "
           "misfit's size relative to that smoothness, not as a test against instrument noise."
           if any(n.startswith("rgl_") for n in results) else "")
        + "\n\nCandidates of the first round:\n\n"
        "{table:diagnose_candidates}\n\n"
        "Normalised residual maps, (measured - model) / sigma (red: measured above the model; "
        "dashed: mirror direction; dotted: source direction):\n\n{figure:diagnose_residuals}"
        + blind
    )
    return Section(key="diagnose", title="What the model misses: discrepancy diagnosis",
                   markdown=markdown, tables=tables, figures=figures, findings=findings)


def _blind_table(seeds: int, first_seed: int) -> pd.DataFrame:
    rows = []
    for kind in KINDS:
        named = right = verdicts = 0
        for seed in range(first_seed, first_seed + seeds):
            case = hidden_case(kind, seed)
            d = diagnose(case.measurements, seed=seed)
            first = d.effects[0].name if d.effects else None
            named += first is not None
            right += first == case.effect
            expected = {"none": NO_MISSING_EFFECT, "outside": UNEXPLAINED}.get(
                case.truth["kind"], EFFECTS_FOUND)
            verdicts += d.verdict == expected
        catalogue = kind not in ("none",) + OUTSIDE
        rows.append({"hidden": kind, "tables": seeds, "an effect named": named,
                     "hidden effect named first": right if catalogue else None,
                     "expected verdict": verdicts})
    return pd.DataFrame(rows)
