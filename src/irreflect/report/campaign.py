"""The adaptive-campaign section of the report (``irreflect reproduce``): every dataset
used as the instrument of replayed measurement campaigns (issue 23)."""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from ..campaign import TOLERANCE, replay
from ..errors import FitError, IrreflectError
from ..plots import save_figure
from ..plots.campaign import plot_campaign
from .base import Finding, ReportContext, Section

#: The issue's bar: the adaptive campaign within 0.01 of the all-points fit by this N.
TARGET_N = 15


def _key(name: str) -> str:
    return "campaign_" + re.sub(r"[^a-z0-9]+", "_", name.lower()).strip("_")


def _n(value) -> int | str:
    return "never" if value is None else int(value)


def section(ctx: ReportContext) -> Section:
    """Replays of the adaptive campaign, the paper's protocol, the glossy-aware protocol,
    random readings and select's hindsight subsets on every dataset."""
    n_max = 12 if ctx.quick else 25
    generations = 5 if ctx.quick else 100
    rows, figures, findings, skipped = [], {}, [], []
    for name, meas in ctx.datasets.items():
        ctx.progress(f"campaign: {name}")
        try:
            result = replay(meas, n_max=n_max, seed=ctx.seed, generations=generations,
                            reference=ctx.fits.get(name))
        except (IrreflectError, FitError) as exc:
            skipped.append(f"{name}: {' '.join(str(exc).split())}")
            continue
        curves = result.curves
        adaptive = curves["adaptive"]
        reached = adaptive.reached(result.target)
        stop = result.stop_n
        stop_r2 = adaptive.r2.get(stop, np.nan) if stop else np.nan
        rows.append({
            "dataset": name,
            "points": meas.n_points,
            "R^2 all points": round(result.reference_r2, 4),
            "adaptive: N within 0.01": _n(reached),
            "random: N within 0.01": _n(curves["random"].reached(result.target)),
            "hindsight: N within 0.01": _n(curves["hindsight"].reached(result.target)),
            "R^2 at 12, adaptive": round(adaptive.r2.get(12, np.nan), 4),
            "R^2 at 12, paper's protocol": round(curves["paper"].r2.get(12, np.nan), 4),
            "R^2 at 12, glossy-aware": round(curves["glossy"].r2.get(12, np.nan), 4),
            "R^2 at 12, hindsight": round(curves["hindsight"].r2.get(12, np.nan), 4),
            "verdict stops at N": _n(stop),
            "R^2 at the stop": round(float(stop_r2), 4),
        })
        key = _key(name)
        ax = plot_campaign(result)
        figures[key] = save_figure(ax.figure, ctx.figure_path(key))
        if reached is not None and reached <= TARGET_N:
            findings.append(Finding(2, name, (
                f"the adaptive campaign (`irreflect next`, no pilot scan) comes within "
                f"{TOLERANCE:g} of the all-points fit's R^2 ({result.reference_r2:.4f}) at "
                f"N = {reached} readings and stays there up to {n_max}"), key="campaign"))
        elif not ctx.quick:
            findings.append(Finding(1, name, (
                f"the adaptive campaign does not stay within {TOLERANCE:g} of the all-points "
                f"fit's R^2 ({result.reference_r2:.4f}) by N = {TARGET_N}"
                + (f" (it does from N = {reached})" if reached else
                   f" (R^2 {adaptive.r2.get(n_max, np.nan):.4f} at N = {n_max})")
                + "; the hindsight subsets show "
                + (f"N = {curves['hindsight'].reached(result.target)}"
                   if curves["hindsight"].reached(result.target) else "no N")
                + " is possible with every reading known"), key="campaign"))
    tables = {}
    md = [
        "How many readings does a new material need, without a dense scan to start from? "
        "Each dataset is used as the instrument (a reading is its own point at the "
        "requested angles) and campaigns are replayed on it: the **adaptive campaign** of "
        "`irreflect next` (an opening design over three angles of incidence, then each "
        "reading where it most shrinks the uncertainty of the predicted curve over the "
        "whole range), **the paper's 12-point protocol**, the **glossy-aware protocol** "
        "(designed from the dense table itself: a pilot scan a new user does not have), "
        "**random readings** and, as the bound, `select`'s **best subsets** found with "
        "every reading known (hindsight). After each reading the two-lobe model is fitted on "
        "the readings only and judged by R^2 against all points. `N within 0.01` is the "
        "first N from which R^2 stays within 0.01 of the all-points fit up to N = "
        f"{n_max}; the verdict is the campaign's own stopping rule (`irreflect next` prints "
        "it). `irreflect campaign DATA` replays one table.",
        "",
    ]
    if rows:
        tables["campaign_summary"] = pd.DataFrame(rows)
        md += ["{table:campaign_summary}", ""]
        md += [f"{{figure:{k}}}" for k in figures]
    if ctx.quick:
        md += ["", f"(Quick run: {n_max} readings, hindsight search of {generations} "
                   "generations.)"]
    if skipped:
        md += ["", "Not replayed: " + "; ".join(skipped)]
    if not rows and not skipped:
        md += ["No dataset to replay."]
    return Section(key="campaign", title="Measuring a new material: adaptive campaigns",
                   markdown="\n".join(md), tables=tables, figures=figures, findings=findings)
