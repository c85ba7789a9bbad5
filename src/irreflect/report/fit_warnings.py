"""The run's fit warnings, counted and grouped: by table, model and kind of warning.

Every fit of a report run that is not all it seems raises a
:class:`~irreflect.errors.FitWarning` (``"<table>, <model>: <kind>: <detail>"``). The same
table is fitted by several sections (the report's common fit, the protocol's 12 points,
the comparison, the diagnosis), so the raw list repeats itself with numbers that differ in
the fourth digit. :func:`collect` tags each warning with the step of the run that raised it;
:func:`group` makes one row per (table, model, kind, coefficients) with a count;
:func:`findings` gives one "use with care" line per table of the run (and one for the
tables the sections generate or add themselves), so the report's first section never reads
as if nothing were doubtful while fits warned.
"""

from __future__ import annotations

import re
from collections import Counter
from dataclasses import dataclass

import pandas as pd

from .base import Finding

_MESSAGE = re.compile(r"^(?P<source>.*?), (?P<model>\S+): (?P<kind>[^:]+): (?P<detail>.*)$")
_COEFFICIENT = re.compile(r"(?:^|, )(\w+) = ")

#: Step of the run -> how the report names it.
STAGE_NAMES = {"fit": "the common fit", "fits": "fit quality", "selection": "point selection",
               "protocol": "protocol", "compare": "model comparison",
               "diagnose": "diagnosis", "room": "room"}


@dataclass(frozen=True)
class FitNote:
    """One fit warning of the run: the step that raised it and its parts."""

    stage: str
    source: str
    model: str
    kind: str
    detail: str

    @property
    def coefficients(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(_COEFFICIENT.findall(self.detail)))

    def dataset(self, names) -> str:
        """The run's dataset the warning concerns ("" for a table a section made or added):
        the table itself, or a subset of it named '<what> on <dataset>'."""
        for name in names:
            if self.source == name or self.source.endswith(f" on {name}"):
                return name
        return ""


def parse(message: str, stage: str) -> FitNote:
    """Split ``"<table>, <model>: <kind>: <detail>"``; anything else is kept whole."""
    m = _MESSAGE.match(message)
    if m is None:
        return FitNote(stage, "", "", "other", message)
    return FitNote(stage, m["source"], m["model"], m["kind"].strip(), m["detail"].strip())


def collect(tagged) -> list[FitNote]:
    """``tagged``: (stage, message) pairs; distinct messages of a stage are kept once."""
    seen, out = set(), []
    for stage, message in tagged:
        if (stage, message) in seen:
            continue
        seen.add((stage, message))
        out.append(parse(message, stage))
    return out


def _stage(stage: str) -> str:
    return STAGE_NAMES.get(stage, stage)


def group(notes: list[FitNote], names) -> pd.DataFrame:
    """One row per (table, model, kind of warning, coefficients concerned): how many fits
    raised it and in which steps, with the first one's detail; the run's datasets first."""
    order = {n: i for i, n in enumerate(names)}
    rows: dict = {}
    for n in notes:
        key = (n.source, n.model, n.kind, n.coefficients)
        row = rows.get(key)
        if row is None:
            rows[key] = row = {"table": n.source or "(unnamed)", "model": n.model,
                               "warning": n.kind, "coefficients": ", ".join(n.coefficients),
                               "fits": 0, "raised in": [], "first detail": n.detail,
                               "_rank": order.get(n.dataset(names), len(order))}
        row["fits"] += 1
        if _stage(n.stage) not in row["raised in"]:
            row["raised in"].append(_stage(n.stage))
    table = sorted(rows.values(), key=lambda r: (r["_rank"], r["table"] not in names,
                                                 r["table"], r["model"], r["warning"]))
    for r in table:
        r["raised in"] = ", ".join(r["raised in"])
        del r["_rank"]
    return pd.DataFrame(table, columns=["table", "model", "warning", "coefficients", "fits",
                                        "raised in", "first detail"])


def _kinds(notes: list[FitNote]) -> str:
    counts = Counter(n.kind for n in notes)
    parts = []
    for kind, count in counts.most_common():
        coefs = sorted({c for n in notes if n.kind == kind for c in n.coefficients})
        parts.append(f"{count} {kind}" + (f" ({', '.join(coefs)})" if coefs else ""))
    return "; ".join(parts)


def findings(notes: list[FitNote], names) -> list[Finding]:
    """One 'use with care' finding per dataset of the run that has fit warnings, and one
    for the tables the sections generated or added (blind tests, a reference material)."""
    out = []
    for name in names:
        mine = [n for n in notes if n.dataset(names) == name]
        if not mine:
            continue
        stages = ", ".join(dict.fromkeys(_stage(n.stage) for n in mine))
        models = ", ".join(dict.fromkeys(n.model for n in mine))
        out.append(Finding(1, name, f"{len(mine)} fit warning(s) ({models}; in {stages}): "
                                    f"{_kinds(mine)}; grouped in the table of fit warnings",
                           key="fit-warnings"))
    others = [n for n in notes if not n.dataset(names)]
    if others:
        by_stage: dict[str, set] = {}
        for n in others:
            by_stage.setdefault(_stage(n.stage), set()).add(n.source or "(unnamed)")
        where = "; ".join(f"{stage}: {len(tables)} table(s)" for stage, tables in by_stage.items())
        out.append(Finding(1, "", f"{len(others)} fit warning(s) on tables the sections "
                                  f"generated or added themselves ({where}): {_kinds(others)}",
                           key="fit-warnings"))
    return out
