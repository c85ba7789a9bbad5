"""The report's contract (:mod:`irreflect.report.base`), checked for every registered section.

Every section of :data:`irreflect.report.sections.SECTIONS` (and of ``SCENE_SECTIONS``) is
called once on one small context (two bundled datasets, quick budgets, the office scene)
and must return a Section with a title whose placeholders all resolve to what it made,
tables that format, figures that exist, and findings with a valid severity. A section
added to the registry is covered without editing this file. A section that raises stops
the report: nothing is turned into a silent "not available".
"""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pandas as pd
import pytest

from irreflect.data import bundled_dir, load_bundled
from irreflect.fitting import fit
from irreflect.paper import paper_tables_dir
from irreflect.report import SCENE_SECTIONS, SECTIONS, ReportContext, Section, reproduce
from irreflect.report.base import SEVERITIES, Finding, format_table

DATASETS = ("terrazzo", "plasterboard")
SCENE = bundled_dir() / "rooms" / "office.toml"
ALL = {**SECTIONS, **SCENE_SECTIONS}
PLACEHOLDER = re.compile(r"\{(table|figure):([^}]+)\}")


@pytest.fixture(scope="module")
def context(tmp_path_factory) -> ReportContext:
    datasets = {name: load_bundled(name) for name in DATASETS}
    return ReportContext(datasets=datasets, fits={n: fit(m) for n, m in datasets.items()},
                         out_dir=tmp_path_factory.mktemp("sections"), quick=True, seed=0,
                         paper_dir=paper_tables_dir(), reconstructions=frozenset(datasets),
                         scene=SCENE)


#: What does the fitting and simulation a section's ``compute`` may call and its ``render``
#: may not (the names as the sections import them).
HEAVY = ("fit", "compare_models", "run_selection", "compare_methods", "simulate", "replay",
         "evaluate_protocol", "glossy_protocol_for", "paper_protocol_for",
         "protocol_robustness", "diagnose", "hidden_case", "validation", "glossy_floor")


def _refuse(name):
    def refused(*args, **kwargs):
        raise AssertionError(f"render called {name}: fits and simulations belong in compute")
    return refused


@pytest.fixture(scope="module")
def made(context):
    """Each section's output, computed once for every test of this module, as
    ``render(ctx, compute(ctx))`` with every fitting and simulation function of the
    section's module refusing to run during ``render``."""
    cache: dict[str, Section] = {}

    def get(name: str) -> Section:
        if name not in cache:
            module = importlib.import_module(ALL[name].__module__)
            results = module.compute(context)
            with pytest.MonkeyPatch.context() as mp:
                for heavy in HEAVY:
                    if hasattr(module, heavy):
                        mp.setattr(module, heavy, _refuse(heavy))
                cache[name] = module.render(context, results)
        return cache[name]

    return get


def _params():
    return [pytest.param(name, marks=pytest.mark.slow) if name in SCENE_SECTIONS else name
            for name in ALL]


def test_the_registry_holds_functions_in_report_order():
    assert list(SECTIONS) == ["fits", "selection", "protocol", "campaign", "compare",
                             "diagnose"]
    assert list(SCENE_SECTIONS) == ["room"]
    assert not set(SECTIONS) & set(SCENE_SECTIONS)
    for name, function in ALL.items():
        assert callable(function), name
        assert function.__module__ == f"irreflect.report.{name}", (name, function.__module__)
        module = importlib.import_module(function.__module__)
        # every section is compute(ctx) -> results, then render(ctx, results) -> Section
        assert callable(getattr(module, "compute", None)), name
        assert callable(getattr(module, "render", None)), name


@pytest.mark.parametrize("name", _params())
def test_section_keeps_the_contract(made, context, name):
    section = made(name)
    assert isinstance(section, Section)
    assert section.key == name
    assert isinstance(section.title, str) and section.title.strip()
    assert isinstance(section.markdown, str) and section.markdown.strip()
    # every placeholder names something the section made, and everything it made is shown
    wanted = {(kind, key) for kind, key in PLACEHOLDER.findall(section.markdown)}
    made_ = {("table", k) for k in section.tables} | {("figure", k) for k in section.figures}
    assert wanted <= made_, sorted(wanted - made_)
    assert made_ <= wanted, sorted(made_ - wanted)


@pytest.mark.parametrize("name", _params())
def test_section_tables_format_and_figures_exist(made, context, name):
    section = made(name)
    for key, table in section.tables.items():
        assert re.fullmatch(r"[a-z0-9_]+", key), key  # the CSV file name
        assert isinstance(table, pd.DataFrame) and len(table.columns), key
        assert all(isinstance(c, str) for c in table.columns), (key, list(table.columns))
        assert len(set(table.columns)) == len(table.columns), (key, list(table.columns))
        shown = format_table(table)
        cells = [c for row in shown.itertuples(index=False) for c in row]
        assert all(isinstance(c, str) for c in cells), key
        assert not any(c.lower() in ("nan", "<na>", "nat") for c in cells), key  # n/a or empty
    for key, path in section.figures.items():
        assert re.fullmatch(r"[a-z0-9_]+", key), key
        path = Path(path)
        assert path.resolve().is_relative_to(context.out_dir.resolve()), (key, path)
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", key


@pytest.mark.parametrize("name", _params())
def test_section_findings_are_valid(made, context, name):
    for finding in made(name).findings:
        assert isinstance(finding, Finding)
        assert finding.severity in SEVERITIES, finding
        assert finding.dataset == "" or finding.dataset in context.datasets, finding
        assert finding.text.strip(), finding


@pytest.mark.slow
def test_sections_name_their_tables_and_figures_apart(made):
    """Tables and figures share one folder each: no two sections may use one name."""
    tables, figures = {}, {}
    for name in ALL:
        section = made(name)
        for key in section.tables:
            assert key not in tables, (key, tables.get(key), name)
            tables[key] = name
        for key in section.figures:
            assert key not in figures, (key, figures.get(key), name)
            figures[key] = name


def test_report_compare_section(made, context):
    """The comparison section's numbers (moved here from test_compare.py: the section is
    computed once, on this module's context, for this and the contract tests above)."""
    section = made("compare")
    t6 = section.tables["compare_table6"]
    assert len(t6) == 12 and set(t6["material"]) == {"terrazzo", "plasterboard"}
    # reuses the context's two-lobe fit, scored on the same data
    terr = t6[t6["material"] == "terrazzo"].set_index("gamma_deg")
    expected = context.fits["terrazzo"].polar_errors()
    assert terr.loc[60.0, "two-lobe (ours)"] == pytest.approx(expected[60.0], abs=0.006)
    assert (terr["phong@10 (ours)"].iloc[-1] > 5 * terr["two-lobe (ours)"].iloc[-1])
    models = section.tables["compare_models"]
    assert {"two-lobe", "phong@10", "lafortune", "torrance-sparrow"} <= set(models["model"])
    assert terr.loc[60.0, "phong@10 (paper)"] == pytest.approx(45.3)
    # the noise floor: the generating curve is no better than our two-lobe fit, on average
    assert terr["noise floor (ours)"].mean() > 0.8 * terr["two-lobe (ours)"].mean()


def test_report_diagnose_section(made):
    """The diagnosis section's numbers (moved here from test_diagnose.py, where it ran on
    terrazzo and foam board: the section is computed once, on this module's context)."""
    from irreflect.diagnose import CATALOGUE, NO_MISSING_EFFECT

    section = made("diagnose")
    table = section.tables["diagnose_summary"]
    assert list(table["dataset"]) == list(DATASETS)
    assert set(table["verdict"]) == {NO_MISSING_EFFECT}
    assert table["chi2/dof before"].between(0.6, 1.5).all()
    assert Path(section.figures["diagnose_residuals"]).stat().st_size > 10_000
    # each catalogue effect and the gain drift (both sets have 3 or more angles of
    # incidence with 3 or more readings each) tried once on each of the two sets
    assert len(section.tables["diagnose_candidates"]) == 2 * (len(CATALOGUE) + 1)
    assert (section.tables["diagnose_candidates"].iloc[:, :3].astype(str)
            .apply(lambda r: r.str.contains("gain_drift")).any(axis=1).sum() == 2)


def test_report_room_section(made):
    """The room section's numbers (moved here from test_room.py: the section is computed
    once, for this and the contract tests above)."""
    section = made("room")
    comp = section.tables["room_comparison"]
    lam = comp[comp.surfaces.str.startswith("Lambertian")]
    assert (lam["d DC gain vs Lambertian %"] == 0).all()
    assert comp["range error (cm)"].notna().all() and (comp["range error (cm)"] > 0).all()
    barry = section.tables["room_barry_a"]
    assert barry.loc[0, "closed form"] == pytest.approx(1.2318e-6, rel=1e-4)
    one = section.tables["room_one_bounce"]
    assert abs(one["relative error"]).is_monotonic_decreasing
    swap = section.tables["room_swapped"]
    rec = swap[swap.method == "recursive"]
    assert (abs(rec["swapped / direct - 1"]) < 0.01).all()
    conv = section.tables["room_convergence"]
    assert {"order", "recursive / Monte Carlo - 1", "Monte Carlo 3 sigma"} <= set(conv.columns)
    for key in ("room_impulse", "room_map_range_change"):
        assert Path(section.figures[key]).exists()
    for name in ("room_scene", "room_comparison", "room_barry_a", "room_checks", "room_swapped",
                 "room_convergence", "room_materials"):
        assert "{table:" + name + "}" in section.markdown


def test_a_failing_section_stops_the_report(tmp_path, monkeypatch):
    def broken(ctx):
        raise RuntimeError("section broke")

    data = tmp_path / "data"
    data.mkdir()
    (data / "terrazzo.csv").write_bytes((bundled_dir() / "terrazzo.csv").read_bytes())
    monkeypatch.setattr("irreflect.report.runner.SECTIONS", {"broken": broken})
    out = tmp_path / "out"
    with pytest.raises(RuntimeError, match="section broke"):
        reproduce(out_dir=out, data_dir=data, quick=True, progress=False)
    assert not out.exists()  # nothing half-written, and no "not available" page


def test_the_registry_is_what_reproduce_runs(tmp_path, monkeypatch):
    calls = []

    def tiny(ctx):
        calls.append(sorted(ctx.datasets))
        return Section("tiny", "A tiny section", "One table:\n\n{table:tiny_table}\n",
                       tables={"tiny_table": pd.DataFrame({"value": [1.5]})})

    data = tmp_path / "data"
    data.mkdir()
    (data / "terrazzo.csv").write_bytes((bundled_dir() / "terrazzo.csv").read_bytes())
    monkeypatch.setattr("irreflect.report.runner.SECTIONS", {"tiny": tiny})
    summary = reproduce(out_dir=tmp_path / "out", data_dir=data, quick=True, progress=False)
    assert calls == [["terrazzo"]]
    assert summary["sections"] == ["findings", "tiny", "warnings"]
    md = (tmp_path / "out" / "report.md").read_text()
    assert "A tiny section" in md and "| 1.5 |" in md
    assert (tmp_path / "out" / "tables" / "tiny_table.csv").read_text() == "value\n1.5\n"
