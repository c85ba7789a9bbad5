"""``irreflect reproduce``: every capability on the bundled data, beside the paper's numbers.

Writes ``report.md``, a self-contained ``report.html`` (figures embedded), every table as
CSV under ``tables/`` and every figure under ``figures/``. Each capability contributes a
:class:`~irreflect.reporting.Section`; one that is not built yet appears as "not available
yet", never as invented numbers.
"""

from __future__ import annotations

import base64
import importlib
import importlib.util
import re
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from . import __version__, metrics
from ._atomic import atomic_directory, atomic_path, claim_output
from .data import BUNDLED, Measurements, bundled_dir, load_bundled, read_measurements
from .errors import FitWarning, IrreflectError
from .fitting import fit
from .paper import paper_tables_dir as _paper_tables_dir
from .protocol.points import protocol_mask
from .reporting import Finding, ReportContext, Section
from .validation import check_points_budget, check_seed, short_list

#: (key, title, "module:function") in report order; the first is this module's own.
PROVIDERS = (
    ("fits", "Fit quality, coefficients and fit time (Tables 2-4, Figs. 15-17, 20-23)",
     "irreflect.report:fits_section"),
    ("selection", "Which points matter: Pareto frontier, knee, Method A / B / 12 (Table 5, Figs. 18-19)",
     "irreflect.selection.report:reproduce_section"),
    ("protocol", "The 12-point protocol: points, evaluation and robustness",
     "irreflect.protocol:reproduce_section"),
    ("compare", "Model comparison: two-lobe vs Phong and the literature (Table 6, Fig. 25)",
     "irreflect.compare:reproduce_section"),
    ("diagnose", "What the model misses: the discrepancy workflow",
     "irreflect.diagnose:reproduce_section"),
)

def how_to_read(ctx: ReportContext, source: str) -> str:
    """The report's opening paragraph, true of the data this run used."""
    text = ("**How to read this.** The findings come first: what failed and where, then "
            "one section per question: does the two-component model fit (fit quality, "
            "coefficients, figures), which measurement points matter (the optimiser), what a "
            "technician should measure (the protocol), how the model compares with the "
            "literature's, and what it still misses (diagnostics). Columns headed *paper* are "
            "copied from the paper's tables (`../shared/paper/tables/`); columns headed *ours* "
            "are measured by this run. ")
    recon = [n for n in ctx.datasets if ctx.is_reconstruction(n)]
    measured = ctx.measured
    if recon and not measured:
        text += ("The datasets are the bundled **reconstructions** (the paper's raw data was "
                 "never published; see `datasets/README.md`): the paper's Table 3 model on its "
                 "sampling plan plus Gaussian noise. Agreement with the paper shows the "
                 "reconstruction and the method are consistent, not that the paper's "
                 "measurements were reproduced. ")
    elif measured and not recon:
        text += (f"The datasets are **measured** tables ({source}), not the paper's materials: "
                 "the paper's numbers are shown only where a table carries a paper material's "
                 "name, and everything else is what irreflect finds on these data. ")
    else:
        text += (f"Reconstructions (the paper's Table 3 model plus noise): {', '.join(recon)}; "
                 f"measured tables: {', '.join(measured)}. ")
    text += ("Every table is also a CSV in `tables/` (named under the table), holding exactly "
             "the numbers shown. In the HTML, click a figure to see it full size.\n")
    return text


FITTER_GUARANTEES = """\
**What the fitter guarantees.** `irreflect.fit` searches globally: data-driven starts from
a per-angle-of-incidence decomposition (the mirror peak, its width, the diffuse floor), a
screening of the whole shape space with lobe indices up to the mirror limit (10^6), a
Levenberg-Marquardt from the best candidates in different basins, and global scans along
every coordinate block until nothing improves. It is tested to reach at least the
generating curve's R^2 (minus 1e-4) on 300 generated glossy and matte materials and every
model on tables it generated, and at least the best of 50 random-start `least_squares`
runs on every real set (`tests/test_global_fit.py`). When a result is not all it seems,
it says so: it reports whether it converged and why it stopped, which coefficients sit on
a bound of their physical range and which the data leave ill-determined, and every
command prints those as warnings; a fit that cannot beat a constant, or a table with
constant power or no degree of freedom, is refused with a one-line error. The checks of
this run's all-point fits:"""


# ----------------------------------------------------------------------------- helpers
def fmt(value) -> str:
    """The one formatter for numbers in tables (CSV and report show the same strings)."""
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        if not np.isfinite(value):
            return "n/a" if np.isnan(value) else ("inf" if value > 0 else "-inf")
        short = f"{value:.6g}"
        if float(short) == value and "e" not in short:
            return short  # the producer rounded it: show exactly that
        return f"{value:.4g}" if abs(value) >= 1e-3 or value == 0 else f"{value:.3e}"
    return "" if value is None else str(value)


def _decimals(text: str) -> int:
    return len(text.split(".", 1)[1]) if "." in text else 0


def format_column(values) -> list[str]:
    """One column's numbers in one format: the floats of a column are all in fixed point
    with as many decimals as its most precise value shows (0.99 beside 0.98986 becomes
    0.99000), or all in scientific notation with 4 significant digits when any value needs
    it (below 1e-3 or at least 1e6 in magnitude); integers, text and flags as :func:`fmt`."""
    values = list(values)
    floats = [v for v in values if isinstance(v, (float, np.floating))
              and not isinstance(v, bool) and np.isfinite(v)]
    if not floats or all(float(v).is_integer() for v in floats) and all(
            abs(v) < 1e6 for v in floats):
        return [fmt(v) for v in values]
    shown = [fmt(v) for v in floats]
    if any("e" in t for t in shown) or any(abs(v) >= 1e6 for v in floats):
        return [f"{float(v):.3e}" if (isinstance(v, (float, np.floating))
                                      and np.isfinite(v)) else fmt(v) for v in values]
    places = min(max(_decimals(t) for t in shown), 6)
    return [f"{float(v):.{places}f}" if (isinstance(v, (float, np.floating))
                                         and np.isfinite(v)) else fmt(v) for v in values]


def format_table(df: pd.DataFrame) -> pd.DataFrame:
    """The strings a table is shown with (and written to its CSV with): column by column
    (:func:`format_column`)."""
    out = pd.DataFrame(index=df.index)
    for i, column in enumerate(df.columns):
        out.insert(i, column, format_column(df.iloc[:, i].tolist()), allow_duplicates=True)
    return out


def markdown_table(df: pd.DataFrame) -> str:
    text = format_table(df)

    def cell(value) -> str:
        return str(value).replace("|", "\\|")

    header = "| " + " | ".join(cell(c) for c in text.columns) + " |"
    rule = "|" + "|".join("---" for _ in text.columns) + "|"
    rows = ["| " + " | ".join(cell(v) for v in row) + " |"
            for row in text.itertuples(index=False, name=None)]
    return "\n".join([header, rule, *rows])


# ----------------------------------------------------------------------------- fit section
def protocol_fails(r2: float, reference_r2: float) -> bool:
    """The rule of :func:`irreflect.protocol.evaluate.protocol_failure`: a fit on a
    protocol's points fails a material when its R^2 on all points falls more than
    ``max(0.02, 5 (1 - R^2_A))`` below the all-points fit's."""
    from .protocol.evaluate import FAILURE_MARGIN

    margin = max(FAILURE_MARGIN, 5.0 * (1.0 - reference_r2))
    return bool(not np.isfinite(r2) or r2 < reference_r2 - margin)


def fits_section(ctx: ReportContext) -> Section:
    """Tables 2-4 and Figs. 15-17, 20-23 from the two-lobe fits."""
    t2_paper = ctx.paper_table("table2_fit_quality_12pt.csv")
    t3_paper = ctx.paper_table("table3_parameters.csv")
    t4_paper = ctx.paper_table("table4_fit_time_ms.csv")
    rows2, rows3, rows4, figures, notes, findings = [], [], [], {}, [], []
    repeats = 5 if ctx.quick else 50
    md = []
    for name, meas in ctx.datasets.items():
        ctx.progress(f"fits: {name}")
        full = ctx.fits[name]
        mask, snaps = protocol_mask(meas)
        twelve = fit(meas.subset(mask), seed=ctx.seed, use_sigma=False) if mask.sum() >= 7 else None
        paper2 = t2_paper.set_index("material").loc[name] if (
            t2_paper is not None and name in set(t2_paper.material)) else None
        if twelve is not None:
            pred = twelve.predict(meas.gamma_deg, meas.theta_deg)
            r2_12 = metrics.r2(meas.power, pred)
            r2_all = metrics.r2(meas.power, full.predict(meas.gamma_deg, meas.theta_deg))
            rows2.append({
                "material": name, "points fitted": int(mask.sum()),
                "R^2 ours": round(r2_12, 4),
                "R^2 paper": paper2["r2"] if paper2 is not None else np.nan,
                "RMSE ours": round(metrics.rmse(meas.power, pred), 4),
                "RMSE paper": paper2["rmse"] if paper2 is not None else np.nan,
                "MSE ours": metrics.mse(meas.power, pred),
                "MSE paper": paper2["mse"] if paper2 is not None else np.nan,
                "R^2 all-points fit": round(r2_all, 4),
            })
            if protocol_fails(r2_12, r2_all):
                far = max((np.hypot(g - g2, t - t2) for g, t, g2, t2 in snaps), default=0.0)
                findings.append(Finding(0, name, (
                    "the paper's 12-point protocol fails: fitted on its 12 points (Tables 2 "
                    "and 5; " + (f"{len(snaps)} of them snapped to the nearest measured "
                                 f"angles, up to {far:.2g} deg away" if snaps
                                 else "every point measured") +
                    f") the model predicts all points with R^2 = {round(r2_12, 4):.4g}, "
                    f"against {round(r2_all, 4):.4g} for the fit on all points"),
                    key="paper-protocol"))
        if snaps:
            notes.append(f"{name}: protocol points snapped to the nearest measured point: "
                         + ", ".join(f"({g:g}, {t:g}) -> ({g2:g}, {t2:g})"
                                     for g, t, g2, t2 in snaps))
        for label, res in (("all points", full), ("12 points", twelve)):
            if res is None:
                continue
            row = {"material": name, "fitted on": label}
            row.update({k: v for k, v in res.params.items()})
            rows3.append(row)
            row = {"material": name, "fitted on": f"std. error ({label})"}
            row.update({k: v for k, v in res.stderrs.items()})
            rows3.append(row)
        if t3_paper is not None and name in set(t3_paper.material):
            row = {"material": name, "fitted on": "paper (12 points)"}
            row.update(t3_paper.set_index("material").loc[name].to_dict())
            rows3.append(row)
        sub = meas.subset(mask) if twelve is not None else meas
        times = []
        for i in range(repeats):
            t0 = time.perf_counter()
            fit(sub, seed=i, use_sigma=False)
            times.append((time.perf_counter() - t0) * 1e3)
        paper_ms = (t4_paper.set_index("material").loc[name, "fit_time_ms"]
                    if t4_paper is not None and name in set(t4_paper.material) else np.nan)
        rows4.append({"material": name, "points": sub.n_points,
                      "ours median (ms)": round(statistics.median(times), 2),
                      "paper (ms, MATLAB R2015, Core 2 Duo E8400)": paper_ms,
                      "repeats": repeats})
        figures.update(_fit_figures(ctx, name, meas, full, mask if twelve is not None else None,
                                    twelve))
    checks = []
    for name in ctx.datasets:
        res = ctx.fits[name]
        checks.append({"material": name, "converged": res.converged,
                       "at a bound": ", ".join(res.at_bound) or "none",
                       "ill-determined": ", ".join(res.ill_determined) or "none",
                       "warnings": " / ".join(res.warnings) or "none"})
        if not res.converged:
            findings.append(Finding(1, name, f"the two-lobe fit on all points did not "
                                             f"converge ({res.message})"))
    table2 = pd.DataFrame(rows2)
    if len(table2) and table2["R^2 paper"].isna().all():
        table2 = table2.drop(columns=["R^2 paper", "RMSE paper", "MSE paper"])
    tables = {"table2_fit_quality": table2, "table3_coefficients": pd.DataFrame(rows3),
              "table4_fit_time": pd.DataFrame(rows4), "fit_checks": pd.DataFrame(checks)}
    md.append(FITTER_GUARANTEES + "\n\n{table:fit_checks}\n\n")
    md.append("### Table 2: quality of the 12-point fit against all points\n\n"
              "The model is fitted on the 12 points of the paper's protocol (Table 1 where the "
              "dataset has its angles, each point snapped to the nearest measured one) and "
              "scored on every point of the dataset, as in the paper; the last column is the "
              "fit on all points.\n\n{table:table2_fit_quality}\n")
    if rows2:
        md.append(_table2_note(pd.DataFrame(rows2), ctx))
    md.append("\n### Table 3: model coefficients\n\n{table:table3_coefficients}\n\n"
              "The `std. error` rows are the fits' standard errors (from the covariance of "
              "the least-squares fit; the paper gives none). ")
    recon = [n for n in ctx.datasets if ctx.is_reconstruction(n)]
    if recon:
        md.append("The reconstructions (" + ", ".join(recon) + ") were generated from the "
                  "paper's Table 3, so their all-point fit should land near it within its "
                  "standard errors; the 12-point fit scatters more because 12 noisy points "
                  "determine 7 coefficients loosely.")
    if ctx.measured:
        md.append(("" if not recon else " ") + "The measured tables (" + ", ".join(ctx.measured)
                  + ") are not the paper's materials, so the paper has no row for them. A "
                  "standard error larger than its coefficient marks a coefficient these data "
                  "do not pin down (listed in the fit checks above).")
    md.append("\n")
    md.append("\n### Table 4: time of one fit\n\n{table:table4_fit_time}\n\n"
              "Different machines and languages: the paper's figure is MATLAB R2015 on a "
              "Core 2 Duo E8400; ours is the median wall time of `irreflect.fit` (with its "
              "global screening and restarts) on this machine. "
              "`.venv/bin/python experiments/bench_fit.py` compares with scipy's curve_fit in one run.\n")
    if notes:
        md.append("\n" + "\n".join(f"- {n}" for n in notes) + "\n")
    md.append("\n### Figures\n\nResiduals are *measured - model* everywhere in this report "
              "(red: the material reflects more than the model says). The residual maps and "
              "histogram show the fit on the 12 protocol points judged on all points (Figs. "
              "21-23 of the paper); colour and bin limits cover the central 98 % of the "
              "values, and points beyond them are drawn at the limit and named under the "
              "figure.\n")
    for name in ctx.datasets:
        md.append(f"\n**{name}**: polar diagram with the all-point fit (Figs. 15-17), "
                  f"3D surface (Fig. 20), residuals (Fig. 21), relative residuals (Fig. 22) "
                  f"and their histogram (Fig. 23).\n\n"
                  f"{{figure:polar_{name}}} {{figure:surface_{name}}}\n\n"
                  f"{{figure:residuals_{name}}} {{figure:relative_residuals_{name}}} "
                  f"{{figure:histogram_{name}}}\n")
        if figures.get(f"_outliers_{name}"):
            md.append(f"\n{figures[f'_outliers_{name}']}\n")
    figures = {k: v for k, v in figures.items() if not k.startswith("_")}
    return Section("fits", PROVIDERS[0][1], "".join(md), tables, figures, findings=findings)


def _table2_note(df: pd.DataFrame, ctx: ReportContext) -> str:
    lines = []
    for _, row in df.iterrows():
        if np.isfinite(row["R^2 paper"]):
            diff = row["R^2 ours"] - row["R^2 paper"]
            lines.append(f"{row['material']}: R^2 {row['R^2 ours']:.4f} vs the paper's "
                         f"{row['R^2 paper']:.4f} ({diff:+.4f})")
    out = ""
    if lines:
        recon = all(ctx.is_reconstruction(r) for r in df["material"]
                    if np.isfinite(df.set_index("material").loc[r, "R^2 paper"]))
        why = ("our data are the paper's Table 3 model plus Gaussian noise chosen to give "
               "RMSEs of the same order as Table 2; the paper's data had their own noise and "
               "model error" if recon else
               "these tables carry a paper material's name but are other measurements")
        out += "\nWhere the numbers differ: " + why + ". " + "; ".join(lines) + ".\n"
    failed = [f"{r['material']} (R^2 {r['R^2 ours']:.4g} against {r['R^2 all-points fit']:.4g} "
              "on all points)" for _, r in df.iterrows()
              if protocol_fails(r["R^2 ours"], r["R^2 all-points fit"])]
    if failed:
        out += ("\n**The paper's protocol fails** " + "; ".join(failed) + ": its 12 points "
                "do not pin the model down on these materials (a narrow specular lobe between "
                "the protocol's receiver angles, or angles the table lacks). The protocol "
                "section below names the cause per material and tries a glossy-aware "
                "protocol.\n")
    return out


def robust_limits(values, coverage: float = 0.98) -> tuple[float, list[int], int]:
    """The symmetric colour / bin limit of the residual figures
    (:func:`irreflect.plots.robust_limit`: the central ``coverage`` of ``|values|``), the
    indices of the outliers (beyond 1.5 times it, at most 5, largest first) and how many
    values lie beyond it in all. A single outlier (a near-zero measured power making a
    relative residual of -870 %) then no longer flattens the scale, and is named."""
    from .plots import robust_limit

    v = np.asarray(values, float)
    limit = robust_limit(v, coverage)
    finite = np.isfinite(v)
    n_beyond = int(np.sum(finite & (np.abs(v) > limit)))
    far = np.flatnonzero(finite & (np.abs(v) > 1.5 * limit))
    far = far[np.argsort(-np.abs(v[far]))][:5]
    return limit, [int(i) for i in far], n_beyond


def _fit_figures(ctx, name, meas, full, mask, twelve):
    from .plots import (
        plot_polar,
        plot_residual_histogram,
        plot_residual_map,
        plot_surface,
        save_figure,
    )

    out = {}
    ax = plot_polar(meas, full.predict, title=f"{name}: two-lobe fit on all points, "
                                               f"R^2 = {full.r2:.4f}")
    out[f"polar_{name}"] = save_figure(ax.figure, ctx.figure_path(f"polar_{name}"))
    shown = twelve or full
    which = "fit on the 12 protocol points" if twelve else "fit on all points"
    ax = plot_surface(meas, shown.predict, highlight=mask,
                      title=f"{name}: model from {'the 12 points' if twelve else 'all points'}")
    out[f"surface_{name}"] = save_figure(ax.figure, ctx.figure_path(f"surface_{name}"))
    pred = shown.predict(meas.gamma_deg, meas.theta_deg)
    resid = meas.power - pred
    r2 = metrics.r2(meas.power, pred)
    ax = plot_residual_map(meas, resid, title=f"{name}: residuals of the {which} "
                                              f"(R$^2$ = {r2:.4g} on all points)",
                           label="measured - model (power)", robust=True)
    out[f"residuals_{name}"] = save_figure(ax.figure, ctx.figure_path(f"residuals_{name}"))
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = 100 * resid / meas.power
    ax = plot_residual_map(meas, rel, title=f"{name}: relative residuals of the {which}",
                           label="(measured - model) / measured (%)", robust=True)
    out[f"relative_residuals_{name}"] = save_figure(
        ax.figure, ctx.figure_path(f"relative_residuals_{name}"))
    ax = plot_residual_histogram(rel, title=f"{name}: relative residuals of the {which}",
                                 label="(measured - model) / measured (%)", robust=True)
    out[f"histogram_{name}"] = save_figure(ax.figure, ctx.figure_path(f"histogram_{name}"))
    notes = []
    top = float(np.max(np.abs(meas.power)))
    for label, values, unit in (("residual", resid, ""), ("relative residual", rel, " %")):
        limit, far, n_beyond = robust_limits(values)
        if far:
            pts = ", ".join(
                f"{values[i]:+.3g}{unit} at (gamma {meas.gamma_deg[i]:g}, theta "
                f"{meas.theta_deg[i]:g}; measured power {meas.power[i]:.3g}"
                + (", near zero" if abs(meas.power[i]) < 0.02 * top else "") + ")"
                for i in far)
            notes.append(f"{n_beyond} {label}(s) beyond the colour limit +-{limit:.3g}{unit}, "
                         f"the largest {pts}")
    if notes:
        out[f"_outliers_{name}"] = f"*{name}, drawn at the limit:* " + "; ".join(notes) + "."
    return out


# ----------------------------------------------------------------------------- runner
def _provider(spec: str):
    module_name, func = spec.split(":")
    parent = module_name.rsplit(".", 1)[0]
    if importlib.util.find_spec(parent) is None or importlib.util.find_spec(module_name) is None:
        return None
    module = importlib.import_module(module_name)
    return getattr(module, func, None)


def load_datasets(data_dir=None) -> dict[str, Measurements]:
    """The bundled datasets, or every table of ``data_dir``, each refused up front when it
    is larger than the report's budget (:data:`irreflect.validation.POINT_BUDGET`)."""
    return _load_datasets(data_dir)[0]


def _load_datasets(data_dir=None) -> tuple[dict[str, Measurements], frozenset]:
    """:func:`load_datasets` and the names of those that are the bundled reconstructions
    (read from the bundled folder), as opposed to measured tables."""
    if data_dir is None:
        return {name: load_bundled(name) for name in BUNDLED}, frozenset(BUNDLED)
    data_dir = Path(data_dir)
    if not data_dir.is_dir():
        raise IrreflectError(f"--data-dir {data_dir}: not a folder; expected a folder of "
                             "CSV or Parquet measurement tables")
    files = sorted([*data_dir.glob("*.csv"), *data_dir.glob("*.parquet")])
    if not files:
        raise IrreflectError(f"--data-dir {data_dir}: no .csv or .parquet tables found")
    stems = [p.stem for p in files]
    if len(set(stems)) < len(stems):
        twice = sorted({s for s in stems if stems.count(s) > 1})
        raise IrreflectError(f"--data-dir {data_dir}: tables {short_list(twice)} exist as both "
                             ".csv and .parquet: keep one of each")
    out, recon = {}, set()
    bundled = bundled_dir().resolve()
    for p in files:
        out[p.stem] = read_measurements(p)
        check_points_budget(out[p.stem].n_points, "reproduce", str(p))
        if p.stem in BUNDLED and p.resolve().parent == bundled:
            recon.add(p.stem)
    return out, frozenset(recon)


def reproduce(out_dir="out", data_dir=None, quick=False, seed=0, progress=True,
              scene=None) -> dict:
    """Run every capability and write the report; returns a summary dict. ``scene``: a room
    scene (TOML) whose multipath section is added (:mod:`irreflect.room.report`).
    ``progress``: a bar on a terminal, one line per step otherwise (False: silent)."""
    t_start = time.perf_counter()
    seed = check_seed(seed)
    out_dir = Path(out_dir)
    if scene is not None:
        from .room.scene import load_scene

        load_scene(scene)  # refuse a bad scene before any work
    with claim_output(out_dir, "dir", "--out"):  # checked and locked before any work
        return _reproduce(out_dir, data_dir, quick, seed, progress, t_start, scene)


def _reproduce(out_dir: Path, data_dir, quick, seed, progress, t_start, scene=None) -> dict:
    from ._progress import progress as progress_display

    datasets, recon = _load_datasets(data_dir)
    # a fit per dataset, each provider once and once per dataset, the selection figures,
    # the PTFE table the comparison adds, the room section
    steps = (len(datasets) * (1 + 1) + len(PROVIDERS) * (1 + len(datasets)) + len(datasets)
             + 1 + (5 if scene else 0))
    bar = progress_display(total=steps, desc="reproduce", unit="step", enabled=progress)

    def advance(message: str) -> None:
        bar.set_postfix_str(message[:60])
        bar.update(1)

    sections: list[Section] = []
    caught_warnings = warnings.catch_warnings(record=True)
    caught = caught_warnings.__enter__()
    warnings.simplefilter("always")
    try:
        return _run_report(out_dir, datasets, recon, quick, seed, data_dir, t_start, bar,
                           advance, sections, caught, scene)
    finally:
        caught_warnings.__exit__(None, None, None)
        for w in caught:  # reader notes go on to the caller; fit warnings are in the report
            if not issubclass(w.category, FitWarning):
                warnings.warn(w.message, w.category, stacklevel=2)


def _run_report(out_dir, datasets, recon, quick, seed, data_dir, t_start, bar, advance,
                sections, caught, scene=None) -> dict:
    with atomic_directory(out_dir, command="reproduce") as tmp:
        fits = {}
        for name, meas in datasets.items():
            advance(f"fit {name}")
            fits[name] = fit(meas, seed=seed)
        ctx = ReportContext(datasets=datasets, fits=fits, out_dir=tmp, quick=quick, seed=seed,
                            paper_dir=_paper_tables_dir(), progress=advance,
                            reconstructions=recon)
        for key, title, spec in PROVIDERS:
            advance(key)
            func = _provider(spec)
            if func is None:
                sections.append(Section(key, title, "*Not available yet: this capability has "
                                        "not been built.*", available=False))
                continue
            section = func(ctx)
            section.title = section.title or title
            sections.append(section)
        if scene is not None:
            from .room.report import room_section

            advance("room")
            sections.append(room_section(ctx, scene))
        fit_warnings = list(dict.fromkeys(str(w.message) for w in caught
                                          if issubclass(w.category, FitWarning)))
        sections.append(_warnings_section(fit_warnings))
        sections.insert(0, findings_section(sections, ctx))
        seconds = time.perf_counter() - t_start
        source = ("the bundled reconstructions, datasets/" if data_dir is None
                  else f"the tables of {data_dir}")
        _write_outputs(tmp, sections, ctx, seconds, quick, source)
    bar.close()
    seconds = time.perf_counter() - t_start
    n_warn = len(sections[-1].tables.get("fit_warnings", ()))
    n_fail = sum(f.severity == 0 for s in sections for f in s.findings)
    print(f"irreflect reproduce: wrote {out_dir}/report.md and {out_dir}/report.html "
          f"({sum(len(s.tables) for s in sections)} tables, "
          f"{sum(len(s.figures) for s in sections)} figures) in {seconds:.1f} s"
          + (f"; {n_fail} failure(s) listed first in the report" if n_fail else "")
          + (f"; {n_warn} fit warning(s), listed in the report's last section" if n_warn else ""),
          file=sys.stderr)
    return {"seconds": seconds, "sections": [s.key for s in sections if s.available],
            "unavailable": [s.key for s in sections if not s.available],
            "failures": [f"{f.dataset}: {f.text}" for s in sections for f in s.findings
                         if f.severity == 0]}


SEVERITY = {0: "What failed", 1: "Use with care", 2: "Results"}


def findings_section(sections: list[Section], ctx: ReportContext) -> Section:
    """What the run found, failures first: every section's findings in one list."""
    items = [f for s in sections for f in s.findings]
    if not items:
        return Section("findings", "What this run found",
                       "Nothing failed; the sections below give the numbers.")
    order = {name: i for i, name in enumerate(ctx.datasets)}
    merged: dict = {}
    for f in items:  # one item per (dataset, key): the most severe first, texts joined
        k = (f.dataset, f.key) if f.key else (f.dataset, f.text)
        if k in merged:
            first = merged[k]
            a, b = (first, f) if first.severity <= f.severity else (f, first)
            merged[k] = Finding(a.severity, a.dataset, a.text + "; " + b.text, a.key)
        else:
            merged[k] = f
    items = sorted(merged.values(),
                   key=lambda f: (f.severity, order.get(f.dataset, len(order)), f.dataset))
    md = []
    for severity, label in SEVERITY.items():
        group = [f for f in items if f.severity == severity]
        if not group:
            continue
        md.append(f"**{label}**\n")
        md += [f"- {'**' + f.dataset + '**: ' if f.dataset else ''}{f.text}" for f in group]
        md.append("")
    if not any(f.severity == 0 for f in items):
        md.insert(0, "Nothing failed on these data.\n")
    return Section("findings", "What this run found", "\n".join(md))


def _warnings_section(messages: list[str]) -> Section:
    """Every distinct fit warning of the run (which fit, what is doubtful about it)."""
    if not messages:
        return Section("warnings", "Fit warnings", "No fit of this run raised a warning.")
    table = pd.DataFrame({"warning": messages})
    return Section(
        "warnings", "Fit warnings",
        "Every fit of this run that is not all it seems (not converged, a coefficient at a "
        "bound of its physical range, ill-determined coefficients, an unphysical share), one "
        "line each, as the commands print them:\n\n{table:fit_warnings}\n",
        tables={"fit_warnings": table})


def _anchor(key: str) -> str:
    return "sec-" + re.sub(r"[^a-z0-9]+", "-", key.lower()).strip("-")


def _write_outputs(tmp: Path, sections, ctx: ReportContext, seconds, quick, source):
    tables_dir = tmp / "tables"
    tables_dir.mkdir(exist_ok=True)
    parts = [f"# irreflect reproduction report\n\nirreflect {__version__}; datasets: "
             f"{', '.join(ctx.datasets)} ({source}); {'quick budget; ' if quick else ''}"
             f"total time {seconds:.1f} s.\n\n{how_to_read(ctx, source)}\n"]
    parts.append("## Contents\n\n" + "\n".join(
        f"{i}. [{s.title}](#{_anchor(s.key)}){'' if s.available else ' (not available yet)'}"
        for i, s in enumerate(sections, 1)) + "\n")
    for s in sections:
        body = s.markdown
        for tname, df in s.tables.items():
            text = format_table(df)
            with atomic_path(tables_dir / f"{tname}.csv") as t:
                text.to_csv(t, index=False)
            body = body.replace("{table:" + tname + "}",
                                markdown_table(df) + f"\n\n*Table file: `tables/{tname}.csv`*")
        for fname, path in s.figures.items():
            rel = Path(path).resolve().relative_to(tmp.resolve())
            body = body.replace("{figure:" + fname + "}", f"![{fname}]({rel.as_posix()})")
        body = re.sub(r"\{(table|figure):[^}]+\}", "*(missing)*", body)
        parts.append(f'## <a id="{_anchor(s.key)}"></a>{s.title}\n\n{body}\n')
    md = "\n".join(parts)
    (tmp / "report.md").write_text(md)
    (tmp / "report.html").write_text(_html(md, tmp))


#: A figure wider than this many pixels (or this much wider than high) gets a full row of
#: the HTML page, at its own size up to the page's width; others half a row (48 %), two
#: side by side, so that no figure is shown at less than 80 % of its size.
WIDE_FIGURE_PX = 720
WIDE_FIGURE_ASPECT = 2.0
PAGE_WIDTH_PX = 1200


def png_size(data: bytes) -> tuple[int, int]:
    """(width, height) in pixels from a PNG's header (0, 0 if it is not a PNG)."""
    if data[:8] != b"\x89PNG\r\n\x1a\n" or len(data) < 24:
        return 0, 0
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


def is_wide(width: int, height: int) -> bool:
    return width > WIDE_FIGURE_PX or (height > 0 and width / height >= WIDE_FIGURE_ASPECT)


_ZOOM_SCRIPT = (
    "<div id='zoom' title='click or Esc to close'><img alt=''></div><script>"
    "(function(){var z=document.getElementById('zoom');"
    "document.querySelectorAll('img.fig').forEach(function(i){"
    "i.addEventListener('click',function(){z.firstChild.src=i.src;z.style.display='block';});});"
    "z.addEventListener('click',function(){z.style.display='none';});"
    "document.addEventListener('keydown',function(e){if(e.key==='Escape'){"
    "z.style.display='none';}});})();</script>")


def _html(md: str, root: Path) -> str:
    import markdown

    def embed(match):
        alt, src = match.group(1), match.group(2)
        path = root / src
        if not path.exists():
            return match.group(0)
        raw = path.read_bytes()
        width, height = png_size(raw)
        wide = is_wide(width, height)
        share = 100 if wide else 48
        data = base64.b64encode(raw).decode()
        return (f'<img class="fig {"wide" if wide else "half"}" alt="{alt}" '
                f'width="{width}" height="{height}" '
                f'src="data:image/png;base64,{data}" '
                f'style="max-width:{share}%;height:auto" title="click to see it full size">')

    body = markdown.markdown(md, extensions=["tables"])
    body = re.sub(r'<img alt="([^"]*)" src="([^"]+)"\s*/?>', embed, body)
    style = (f"body{{font-family:sans-serif;max-width:{PAGE_WIDTH_PX}px;margin:2em auto;"
             "line-height:1.45}"
             "table{border-collapse:collapse;margin:1em 0;font-size:90%}"
             "td,th{border:1px solid #bbb;padding:3px 8px;text-align:right}"
             "th{background:#eee}code{background:#f4f4f4}"
             "img.fig{cursor:zoom-in;vertical-align:top}"
             "#zoom{display:none;position:fixed;inset:0;background:rgba(0,0,0,.85);"
             "overflow:auto;z-index:10;cursor:zoom-out}"
             "#zoom img{display:block;margin:2em auto;background:#fff;max-width:none}")
    return (f"<!doctype html><html><head><meta charset='utf-8'><title>irreflect report</title>"
            f"<style>{style}</style></head><body>{body}{_ZOOM_SCRIPT}</body></html>")


# ----------------------------------------------------------------------------- CLI
def _cmd_reproduce(args) -> int:
    reproduce(out_dir=args.out, data_dir=args.data_dir, quick=args.quick, seed=args.seed,
              progress=not args.no_progress, scene=args.scene)
    return 0


def register(sub) -> None:
    from .cli import SEED

    p = sub.add_parser("reproduce", help="reproduce the paper's tables and figures beside its numbers",
                       description="Run every capability on the bundled datasets (or every table "
                                   "of --data-dir) and write report.md, report.html, tables/*.csv "
                                   "and figures/*.png to --out.")
    p.add_argument("--data-dir", default=None, help="folder of measurement tables (default: bundled)")
    p.add_argument("--out", default="out", help="output folder (default out/)")
    p.add_argument("--quick", action="store_true", help="small optimiser budgets (about a minute)")
    p.add_argument("--seed", type=SEED, default=0,
                   help="seed of every fit and search (default 0)")
    p.add_argument("--no-progress", action="store_true",
                   help="no progress display (a bar on a terminal, one line per step through "
                        "a pipe)")
    p.add_argument("--scene", default=None, metavar="SCENE.toml",
                   help="add the room multipath section for this scene (irreflect room; "
                        "default: none)")
    p.set_defaults(handler=_cmd_reproduce)


__all__ = ["reproduce", "fits_section", "protocol_mask", "markdown_table", "fmt"]
