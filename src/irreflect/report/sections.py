"""The report's sections, in report order: name -> ``section(ctx: ReportContext) -> Section``.

Adding a section: a module beside this one with a ``section`` function (see
:mod:`irreflect.report.base` for what it must return) and one line here.
"""

from __future__ import annotations

from collections.abc import Callable

from . import campaign, compare, diagnose, fits, protocol, room, selection
from .base import ReportContext, Section

SectionFunction = Callable[[ReportContext], Section]

#: Every run's sections, after the findings and before the fit warnings.
SECTIONS: dict[str, SectionFunction] = {
    "fits": fits.section,
    "selection": selection.section,
    "protocol": protocol.section,
    "campaign": campaign.section,
    "compare": compare.section,
    "diagnose": diagnose.section,
}

#: Sections that need a room scene (``irreflect reproduce --scene SCENE.toml``,
#: ``ReportContext.scene``), after :data:`SECTIONS`.
SCENE_SECTIONS: dict[str, SectionFunction] = {
    "room": room.section,
}
