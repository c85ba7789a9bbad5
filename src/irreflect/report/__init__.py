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
