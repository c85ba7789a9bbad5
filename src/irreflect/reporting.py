"""The contract between capabilities and the reproduction report (``irreflect reproduce``).

Each capability module exposes ``reproduce_section(ctx: ReportContext) -> Section``. The
report runner (:mod:`irreflect.report`) builds one context, calls every provider, writes
each section's tables as CSV (``out/tables/<name>.csv``) and renders them into
``report.md`` / ``report.html`` at the ``{table:<name>}`` placeholders of the section's
markdown, and figures at ``{figure:<name>}``. Tables hold exactly the (rounded) values
that are shown, so every number in the report is traceable to its CSV.

A section's text must be true of the data the run used: ``ctx.is_reconstruction(name)``
says whether a dataset is one of the bundled reconstructions (the paper's Table 3 model
plus noise) or a measured table. What a section finds that a reader should see first (a
protocol that fails a material, a fit that cannot be trusted) goes into its
``findings``; the report lists them all at the top, failures first.
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
    reconstructions : names of the datasets that are the bundled reconstructions (the
        paper's Table 3 model plus Gaussian noise); every other dataset was measured
    """

    datasets: dict[str, Measurements]
    fits: dict[str, FitResult]
    out_dir: Path
    quick: bool = False
    seed: int = 0
    paper_dir: Path | None = None
    progress: Callable[[str], None] = lambda message: None
    reconstructions: frozenset = frozenset()

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
    available: bool = True
    findings: list[Finding] = field(default_factory=list)
