"""The contract between the report's sections and its runner (``irreflect reproduce``).

Each section is a function ``section(ctx: ReportContext) -> Section`` in its own module of
:mod:`irreflect.report`, listed in :data:`irreflect.report.sections.SECTIONS`; every
section is written as ``compute(ctx)``, which does all its fitting, simulation and number
work and returns a small dataclass of results, and ``render(ctx, results) -> Section``, which
only writes tables, figures and markdown from them (``section = render(compute(ctx))``,
so a section's text can be changed or tested without refitting). The runner
(:mod:`irreflect.report.runner`) builds one context, calls every section, writes
each section's tables as CSV (``out/tables/<name>.csv``) and renders them into
``report.md`` / ``report.html`` at the ``{table:<name>}`` placeholders of the section's
markdown, and figures at ``{figure:<name>}``. Tables hold exactly the (rounded) values
that are shown, so every number in the report is traceable to its CSV.

A section's text must be true of the data the run used: ``ctx.is_reconstruction(name)``
says whether a dataset is one of the bundled reconstructions (the paper's Table 3 model
plus noise) or a measured table. What a section finds that a reader should see first (a
protocol that fails a material, a fit that cannot be trusted) goes into its
``findings``; the report lists them all at the top, failures first.

What a section promises (``tests/test_contracts_report.py`` checks it for every section):
its registry name as ``key`` and a title; every ``{table:x}`` / ``{figure:x}`` placeholder
of its markdown names a table or figure it returns, and everything it returns has its
placeholder (a section replaces the placeholders of what it could not make by a sentence
saying why); table and figure names are lower_snake_case and not used by another section
(they are file names); every table a DataFrame with distinct text column names that
:func:`format_table` shows without a "nan" (a missing value reads "n/a"); every figure a
PNG file under ``ctx.out_dir``; every finding's severity one of :data:`SEVERITIES` and its
dataset "" or one of the run's. A section that cannot run raises: the runner
never turns an error into a missing section. This module also holds the one formatter of
numbers in tables (:func:`fmt`, :func:`format_table`, :func:`markdown_table`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..data import Measurements
from ..fitting import FitResult


@dataclass
class ReportContext:
    """What every section gets.

    datasets : name -> Measurements (the bundled reconstructions, or the tables of
        ``--data-dir``)
    fits : name -> two-lobe FitResult on all points of that dataset (computed once)
    out_dir : the report folder; write figures with :meth:`figure_path`
    quick : small budgets (tests); sections must finish in seconds when set
    seed : seed for everything random
    paper_dir : the paper's published tables (:func:`irreflect.paper.paper_tables_dir`,
        shipped with the package); None leaves the paper's columns out
    progress : callable(str) that advances the run's progress display
    reconstructions : names of the datasets that are the bundled reconstructions (the
        paper's Table 3 model plus Gaussian noise); every other dataset was measured
    scene : a room scene (TOML) for the sections of :data:`~irreflect.report.sections.SCENE_SECTIONS`
        (``irreflect reproduce --scene``), else None
    allow_unphysical : simulate a scene material whose model predicts negative power
        (else refused, :func:`irreflect.room.checks.material_notes`)
    """

    datasets: dict[str, Measurements]
    fits: dict[str, FitResult]
    out_dir: Path
    quick: bool = False
    seed: int = 0
    paper_dir: Path | None = None
    progress: Callable[[str], None] = lambda message: None
    reconstructions: frozenset = frozenset()
    scene: Path | str | None = None
    allow_unphysical: bool = False

    def is_reconstruction(self, name: str) -> bool:
        """True for a bundled reconstruction, False for a measured table."""
        return name in self.reconstructions

    @property
    def all_reconstructions(self) -> bool:
        return bool(self.datasets) and all(n in self.reconstructions for n in self.datasets)

    @property
    def measured(self) -> list[str]:
        """Names of the measured (not reconstructed) datasets of the run."""
        return [n for n in self.datasets if n not in self.reconstructions]

    def figure_path(self, name: str) -> Path:
        path = self.out_dir / "figures" / f"{name}.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        return path

    def paper_table(self, filename: str) -> pd.DataFrame | None:
        if self.paper_dir is None or not (self.paper_dir / filename).exists():
            return None
        return pd.read_csv(self.paper_dir / filename)


#: Severity of a finding -> the heading it is listed under, most severe first.
SEVERITIES = {0: "What failed", 1: "Use with care", 2: "Results"}


@dataclass(frozen=True)
class Finding:
    """Something a reader should see first.

    severity : 0 a failure (a protocol or fit that does not describe the material),
        1 a limitation (a result to use with care), 2 a result
    dataset : the dataset it concerns ("" for the whole run)
    text : one sentence with its numbers
    """

    severity: int
    dataset: str
    text: str
    #: findings of one dataset with the same key (e.g. "paper-protocol") are one item
    key: str = ""


@dataclass
class Section:
    """One part of the report: markdown with ``{table:x}`` / ``{figure:y}`` placeholders."""

    key: str
    title: str
    markdown: str
    tables: dict[str, pd.DataFrame] = field(default_factory=dict)
    figures: dict[str, Path] = field(default_factory=dict)
    findings: list[Finding] = field(default_factory=list)


# ----------------------------------------------------------------------------- numbers
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
