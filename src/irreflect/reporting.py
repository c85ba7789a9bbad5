"""The contract between capabilities and the reproduction report (``irreflect reproduce``).

Each capability module exposes ``reproduce_section(ctx: ReportContext) -> Section``. The
report runner (:mod:`irreflect.report`) builds one context, calls every provider, writes
each section's tables as CSV (``out/tables/<name>.csv``) and renders them into
``report.md`` / ``report.html`` at the ``{table:<name>}`` placeholders of the section's
markdown, and figures at ``{figure:<name>}``. Tables hold exactly the (rounded) values
that are shown, so every number in the report is traceable to its CSV.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from .data import Measurements
from .fitting import FitResult


@dataclass
class ReportContext:
    """What every section gets.

    datasets : name -> Measurements (the bundled reconstructions, or the tables of
        ``--data-dir``)
    fits : name -> two-lobe FitResult on all points of that dataset (computed once)
    out_dir : the report folder; write figures with :meth:`figure_path`
    quick : small budgets (tests); sections must finish in seconds when set
    seed : seed for everything random
    paper_dir : ``../shared/paper/tables`` when present, else None
    progress : callable(str) that advances the run's progress display
    """

    datasets: dict[str, Measurements]
    fits: dict[str, FitResult]
    out_dir: Path
    quick: bool = False
    seed: int = 0
    paper_dir: Path | None = None
    progress: Callable[[str], None] = lambda message: None

    def figure_path(self, name: str) -> Path:
        path = self.out_dir / "figures" / f"{name}.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        return path

    def paper_table(self, filename: str) -> pd.DataFrame | None:
        if self.paper_dir is None or not (self.paper_dir / filename).exists():
            return None
        return pd.read_csv(self.paper_dir / filename)


@dataclass
class Section:
    """One part of the report: markdown with ``{table:x}`` / ``{figure:y}`` placeholders."""

    key: str
    title: str
    markdown: str
    tables: dict[str, pd.DataFrame] = field(default_factory=dict)
    figures: dict[str, Path] = field(default_factory=dict)
    available: bool = True
