"""The adaptive-campaign section of the report (``irreflect reproduce``): every dataset
used as the instrument of replayed measurement campaigns (issue 23)."""

from __future__ import annotations

import re
from dataclasses import dataclass

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


@dataclass(frozen=True)
class CampaignResults:
    """What the campaign section found (computed by :func:`compute`, written out by
    :func:`render`): the replays' budgets, every replayed dataset's result, the summary
    rows, the findings and the datasets that could not be replayed."""

    n_max: int
    generations: int
    replays: dict
    rows: list
    findings: list
    skipped: list


def section(ctx: ReportContext) -> Section:
    """Replays of the adaptive campaign, the paper's protocol, the glossy-aware protocol,
    random readings and select's hindsight subsets on every dataset."""
    return render(ctx, compute(ctx))


def compute(ctx: ReportContext) -> CampaignResults:
    """Replay every campaign on every dataset."""
    res = CampaignResults(12 if ctx.quick else 25, 5 if ctx.quick else 100, {}, [], [], [])
    for name, meas in ctx.datasets.items():
        ctx.progress(f"campaign: {name}")
        try:
            result = replay(meas, n_max=res.n_max, seed=ctx.seed, generations=res.generations,
                            reference=ctx.fits.get(name))
        except (IrreflectError, FitError) as exc:
            res.skipped.append(f"{name}: {' '.join(str(exc).split())}")
            continue
        res.replays[name] = result
        res.rows.append(_row(name, meas, result))
        res.findings.extend(_findings(ctx, name, result, res.n_max))
    return res


def _row(name, meas, result) -> dict:
    """The summary row of one dataset's replays."""
    curves = result.curves
    adaptive = curves["adaptive"]
    reached = adaptive.reached(result.target)
    stop = result.stop_n
    stop_r2 = adaptive.r2.get(stop, np.nan) if stop else np.nan
    return {
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
    }


def _findings(ctx: ReportContext, name: str, result, n_max: int) -> list:
    """Whether the adaptive campaign reaches the all-points fit by :data:`TARGET_N`."""
    curves = result.curves
    adaptive = curves["adaptive"]
    reached = adaptive.reached(result.target)
    if reached is not None and reached <= TARGET_N:
        return [Finding(2, name, (
            f"the adaptive campaign (`irreflect next`, no pilot scan) comes within "
            f"{TOLERANCE:g} of the all-points fit's R^2 ({result.reference_r2:.4f}) at "
            f"N = {reached} readings and stays there up to {n_max}"), key="campaign")]
    if ctx.quick:
        return []
    return [Finding(1, name, (
        f"the adaptive campaign does not stay within {TOLERANCE:g} of the all-points "
        f"fit's R^2 ({result.reference_r2:.4f}) by N = {TARGET_N}"
        + (f" (it does from N = {reached})" if reached else
           f" (R^2 {adaptive.r2.get(n_max, np.nan):.4f} at N = {n_max})")
        + "; the hindsight subsets show "
        + (f"N = {curves['hindsight'].reached(result.target)}"
           if curves["hindsight"].reached(result.target) else "no N")
        + " is possible with every reading known"
        + "".join(f"; {w}" for w in result.warnings)), key="campaign")]


def render(ctx: ReportContext, res: CampaignResults) -> Section:
    """The campaign section from its results: the summary table, figures and markdown."""
    n_max, generations, rows, skipped = res.n_max, res.generations, res.rows, res.skipped
    figures = {}
    for name, result in res.replays.items():
        key = _key(name)
        ax = plot_campaign(result)
        figures[key] = save_figure(ax.figure, ctx.figure_path(key))
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
        "every reading known (hindsight). After each reading the two-lobe model is fitted "
        "from the readings only (the adaptive campaign reports its quadrature estimate: the "
        "model fitted to the whole range as its design's posterior pictures it from the "
        "readings) and judged by R^2 against all points. `N within 0.01` is the "
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
                   markdown="\n".join(md), tables=tables, figures=figures,
                   findings=list(res.findings))
