"""The reproduction report (``irreflect reproduce``): a contract, a runner and one module
per section.

:mod:`.base`
    The contract (:class:`ReportContext`, :class:`Section`, :class:`Finding`) and the one
    formatter of numbers in tables (:func:`fmt`, :func:`format_table`, :func:`markdown_table`).
:mod:`.runner`
    :func:`reproduce`: the context, every section in order, the findings and warnings
    sections, ``report.md``, ``report.html``, ``tables/*.csv``.
:mod:`.sections`
    The registry :data:`SECTIONS` (name -> ``section(ctx) -> Section``, in report order) and
    :data:`SCENE_SECTIONS` (run with ``--scene``).
:mod:`.fits`, :mod:`.selection`, :mod:`.protocol`, :mod:`.compare`, :mod:`.diagnose`, :mod:`.room`
    One section each.

Adding a section is one module with a ``section(ctx: ReportContext) -> Section`` function
plus one line in :data:`SECTIONS`; ``tests/test_contracts_report.py`` then checks it.
"""

import importlib

from .base import Finding, ReportContext, Section, fmt, format_table, markdown_table

#: Loaded on first use: the sections import every capability and the plotting stack, which
#: ``irreflect --help`` (it imports this package for its ``register``) must not pay for.
_LAZY = {"reproduce": "runner", "findings_section": "runner", "load_datasets": "runner",
         "PAGE_WIDTH_PX": "runner", "SECTIONS": "sections", "SCENE_SECTIONS": "sections"}

__all__ = ["Finding", "ReportContext", "Section", "fmt", "format_table", "markdown_table",
           *_LAZY]


def __getattr__(name):
    if name in _LAZY:
        return getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# moved to cli/ on the cli branch; kept here (verbatim) until the merge
# ----------------------------------------------------------------------------- CLI
def _cmd_reproduce(args) -> int:
    from .runner import reproduce

    reproduce(out_dir=args.out, data_dir=args.data_dir, quick=args.quick, seed=args.seed,
              progress=not args.no_progress, scene=args.scene)
    return 0


def register(sub) -> None:
    from ..cli import SEED

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


