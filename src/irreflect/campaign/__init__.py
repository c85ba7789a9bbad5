"""Adaptive measurement campaigns (issue 23): which reading to take next on a new material,
and when to stop, without a dense scan to start from.

:class:`Campaign` (``propose(k)``, ``add(rows)``, ``verdict()``) on an :class:`Instrument`
(the angles of incidence it can set, the receiver's range and step, the cost of changing
the angle of incidence); :mod:`.design` holds the opening design and the adaptive rule;
:func:`replay` replays campaigns (adaptive, the paper's protocol, the glossy-aware one,
random readings, ``select``'s hindsight subsets) against a dense table used as the
instrument. The commands are ``irreflect next`` and ``irreflect campaign``; the figure is
:func:`irreflect.plots.campaign.plot_campaign`, the report section
:mod:`irreflect.report.campaign`.
"""

from .core import STOP_TOLERANCE, Campaign, Verdict
from .design import DEFAULT_RULE, DesignRule, opening_design
from .instrument import Instrument
from .replay import (
    METHODS,
    STRATEGIES,
    TOLERANCE,
    DenseInstrument,
    ReplayResult,
    StrategyCurve,
    replay,
    replay_adaptive,
)

__all__ = ["DEFAULT_RULE", "METHODS", "STOP_TOLERANCE", "STRATEGIES", "TOLERANCE",
           "Campaign", "DenseInstrument", "DesignRule", "Instrument", "ReplayResult",
           "StrategyCurve", "Verdict", "opening_design", "replay", "replay_adaptive"]
