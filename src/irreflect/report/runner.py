"""``irreflect reproduce``: every section on the bundled data, beside the paper's numbers.

Writes ``report.md``, a self-contained ``report.html`` (figures embedded), every table as
CSV under ``tables/`` and every figure under ``figures/``. The sections are those of
:data:`irreflect.report.sections.SECTIONS` (plus :data:`~irreflect.report.sections.SCENE_SECTIONS`
with a scene), in that order, after the findings; a section that fails stops the run with
its error (nothing is left out silently).
"""

from __future__ import annotations

import base64
import re
import sys
import time
import warnings
from pathlib import Path

import markdown as markdown_lib

from .. import __version__
from .._atomic import atomic_directory, atomic_path, claim_output
from .._progress import progress as progress_display
from ..data import BUNDLED, Measurements, bundled_dir, load_bundled, read_measurements
from ..errors import FitWarning, IrreflectError
from ..fitting import fit, weights_check
from ..paper import paper_tables_dir as _paper_tables_dir
from ..room.checks import material_notes
from ..room.scene import load_scene
from ..validation import check_points_budget, check_seed, short_list
from . import fit_warnings
from .base import SEVERITIES, Finding, ReportContext, Section, format_table, markdown_table
from .sections import SCENE_SECTIONS, SECTIONS


def how_to_read(ctx: ReportContext, source: str) -> str:
    """The report's opening paragraph, true of the data this run used."""
    text = ("**How to read this.** The findings come first: what failed and where, then "
            "one section per question: does the two-component model fit (fit quality, "
            "coefficients, figures), which measurement points matter (the optimiser), what a "
            "technician should measure (the protocol), how many readings a new material needs "
            "without a dense scan (adaptive campaigns), how the model compares with the "
            "literature's, and what it still misses (diagnostics). Columns headed *paper* are "
            "copied from the paper's published tables (shipped with irreflect in "
            "`irreflect/paper_tables/`; `irreflect datasets` lists them); columns headed *ours* "
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


# ----------------------------------------------------------------------------- runner
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
              scene=None, allow_unphysical: bool = False) -> dict:
    """Run every section and write the report; returns a summary dict. ``scene``: a room
    scene (TOML) whose multipath section is added (:mod:`irreflect.report.room`); a
    material whose model predicts negative power in it is refused unless
    ``allow_unphysical`` (:func:`irreflect.room.checks.material_notes`).
    ``progress``: a bar on a terminal, one line per step otherwise (False: silent)."""
    t_start = time.perf_counter()
    seed = check_seed(seed)
    out_dir = Path(out_dir)
    if scene is not None:  # refuse a bad scene, or an unphysical material, before any work
        material_notes(load_scene(scene), allow_unphysical)
    with claim_output(out_dir, "dir", "--out"):  # checked and locked before any work
        return _reproduce(out_dir, data_dir, quick, seed, progress, t_start, scene,
                          allow_unphysical)


def _reproduce(out_dir: Path, data_dir, quick, seed, progress, t_start, scene=None,
               allow_unphysical=False) -> dict:
    datasets, recon = _load_datasets(data_dir)
    if scene is not None:
        # a cold cache (a pip install: make venv builds it) is built here, announced, not
        # silently inside the room section a minute into the run
        from .._compiled import ensure_room_compiled
        from ..room.warm import warm

        ensure_room_compiled(warm)
    # a fit per dataset, each section once and once per dataset, the selection figures,
    # the PTFE table the comparison adds, the room section
    steps = (len(datasets) * (1 + 1) + len(SECTIONS) * (1 + len(datasets)) + len(datasets)
             + 1 + (5 if scene else 0))
    bar = progress_display(total=steps, desc="reproduce", unit="step", enabled=progress)

    def advance(message: str) -> None:
        bar.set_postfix_str(message)  # whole: a line per step through a pipe
        bar.update(1)

    sections: list[Section] = []
    caught_warnings = warnings.catch_warnings(record=True)
    caught = caught_warnings.__enter__()
    warnings.simplefilter("always")
    try:
        return _run_report(out_dir, datasets, recon, quick, seed, data_dir, t_start, bar,
                           advance, sections, caught, scene, allow_unphysical)
    finally:
        caught_warnings.__exit__(None, None, None)
        for w in caught:  # reader notes go on to the caller; fit warnings are in the report
            if not issubclass(w.category, FitWarning):
                warnings.warn(w.message, w.category, stacklevel=2)


def _run_report(out_dir, datasets, recon, quick, seed, data_dir, t_start, bar, advance,
                sections, caught, scene=None, allow_unphysical=False) -> dict:
    with atomic_directory(out_dir, command="reproduce") as tmp:
        fits = {}
        tagged = []  # (step of the run, fit warning)

        def tag(stage: str, start: int) -> None:
            tagged.extend((stage, str(w.message)) for w in caught[start:]
                          if issubclass(w.category, FitWarning))

        start = len(caught)
        for name, meas in datasets.items():
            advance(f"fit {name}")
            fits[name] = fit(meas, seed=seed)
            text, _ = weights_check(meas, fits[name], seed=seed)
            if text:  # a weighted fit its sigma column decided: in the report's warnings
                warnings.warn(FitWarning(f"{meas.name}, {fits[name].model}: {text}"),
                              stacklevel=2)
        tag("fit", start)
        ctx = ReportContext(datasets=datasets, fits=fits, out_dir=tmp, quick=quick, seed=seed,
                            paper_dir=_paper_tables_dir(), progress=advance,
                            reconstructions=recon, scene=scene,
                            allow_unphysical=allow_unphysical)
        run = dict(SECTIONS) | (dict(SCENE_SECTIONS) if scene is not None else {})
        for key, section in run.items():
            advance(key)
            start = len(caught)
            sections.append(section(ctx))
            tag(key, start)
        notes = fit_warnings.collect(tagged)
        sections.append(_warnings_section(notes, list(datasets)))
        extra = fit_warnings.findings(notes, list(datasets))
        # counted as the findings section lists them: one per dataset and kind (two
        # sections' findings on one protocol were "2 failure(s) listed first" over one item)
        n_fail = sum(f.severity == 0 for f in merged_findings(sections, ctx, extra))
        sections.insert(0, findings_section(sections, ctx, extra=extra))
        seconds = time.perf_counter() - t_start
        source = ("the bundled reconstructions, datasets/" if data_dir is None
                  else f"the tables of {data_dir}")
        _write_outputs(tmp, sections, ctx, seconds, quick, source)
    bar.close()
    seconds = time.perf_counter() - t_start
    n_groups = len(sections[-1].tables.get("fit_warnings", ()))
    print(f"irreflect reproduce: wrote {out_dir}/report.md and {out_dir}/report.html "
          f"({sum(len(s.tables) for s in sections)} tables, "
          f"{sum(len(s.figures) for s in sections)} figures) in {seconds:.1f} s"
          + (f"; {n_fail} failure(s) listed first in the report" if n_fail else "")
          + (f"; {len(notes)} fit warning(s) in {n_groups} group(s) (by table, model and "
             "kind), counted in the findings and listed in the report's last section"
             if notes else ""),
          file=sys.stderr)
    return {"seconds": seconds, "sections": [s.key for s in sections],
            "failures": [f"{f.dataset}: {f.text}" for s in sections for f in s.findings
                         if f.severity == 0]}


def merged_findings(sections: list[Section], ctx: ReportContext, extra=()) -> list:
    """Every section's findings and ``extra``, one per (dataset, key) (the most severe
    first, texts joined), failures first, then by dataset."""
    order = {name: i for i, name in enumerate(ctx.datasets)}
    merged: dict = {}
    for f in [f for s in sections for f in s.findings] + list(extra):
        k = (f.dataset, f.key) if f.key else (f.dataset, f.text)
        if k in merged:
            first = merged[k]
            a, b = (first, f) if first.severity <= f.severity else (f, first)
            merged[k] = Finding(a.severity, a.dataset, a.text + "; " + b.text, a.key)
        else:
            merged[k] = f
    return sorted(merged.values(),
                  key=lambda f: (f.severity, order.get(f.dataset, len(order)), f.dataset))


def findings_section(sections: list[Section], ctx: ReportContext, extra=()) -> Section:
    """What the run found, failures first: every section's findings in one list, and
    ``extra`` ones (the run's fit warnings, counted per table:
    :func:`irreflect.report.fit_warnings.findings`). It says that nothing failed only when
    nothing failed and nothing warned."""
    items = merged_findings(sections, ctx, extra)
    if not items:
        return Section("findings", "What this run found",
                       "Nothing failed and no fit warned; the sections below give the numbers.")
    md = []
    for severity, label in SEVERITIES.items():
        group = [f for f in items if f.severity == severity]
        if not group:
            continue
        md.append(f"**{label}**\n")
        md += [f"- {'**' + f.dataset + '**: ' if f.dataset else ''}{f.text}" for f in group]
        md.append("")
    failed = sum(f.severity == 0 for f in items)
    cautions = sum(f.severity == 1 for f in items)
    if not failed:
        md.insert(0, ("No protocol or fit failed outright, but "
                      f"{cautions} result(s) need care (below, with the fit warnings counted "
                      "per table; every warning is in the [fit warnings](#sec-warnings))."
                      if cautions else "Nothing failed and no fit warned on these data.")
                  + "\n")
    return Section("findings", "What this run found", "\n".join(md))


def _warnings_section(notes: list, names: list[str]) -> Section:
    """The run's fit warnings grouped by table, model, kind and coefficients, counted."""
    if not notes:
        return Section("warnings", "Fit warnings", "No fit of this run raised a warning.")
    table = fit_warnings.group(notes, names)
    return Section(
        "warnings", "Fit warnings",
        f"{len(notes)} fits of this run are not all they seem (not converged, a coefficient "
        "at a bound of its physical range, ill-determined coefficients, an unphysical "
        f"share). They are grouped here into {len(table)} rows: one per table, model, kind "
        "of warning and coefficients concerned, with how many fits raised it, in which steps "
        "of the run, and the first one's detail as the commands print it. A table named "
        "'<what> on <dataset>' is a subset of that dataset (e.g. the protocol's 12 points); "
        "the others are tables a section generated or added (the diagnosis's blind test, a "
        "reference material).\n\n{table:fit_warnings}\n",
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
        f"{i}. [{s.title}](#{_anchor(s.key)})"
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

    body = markdown_lib.markdown(md, extensions=["tables"])
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


