"""Measurement protocols (issue 4): the paper's 12 points for any tool (and in any dense
dataset, :mod:`.points`), their evaluation against dense data, a Monte Carlo of goniometer
errors, and exports a technician can follow (CSV, JSON, Markdown checklist).
"""

from .core import (
    ORDER_RULE,
    PAPER_RULE,
    PURPOSES,
    Protocol,
    measurement_permutation,
    normalise_gammas,
    paper_protocol,
    protocol_from_frame,
)
from .evaluate import ProtocolEvaluation, evaluate_protocol, paper_protocol_for, sample_protocol
from .export import (
    SCHEMA_VERSION,
    as_protocol,
    read_protocol,
    render,
    to_csv_text,
    to_dict,
    to_json_text,
    to_markdown,
    write_protocol,
)
from .points import paper_protocol_points, protocol_mask, protocol_points_mask, snap_points
from .robustness import RobustnessResult, protocol_robustness

__all__ = [
    "ORDER_RULE", "PAPER_RULE", "PURPOSES", "SCHEMA_VERSION", "Protocol", "ProtocolEvaluation",
    "RobustnessResult", "as_protocol",
    "evaluate_protocol", "measurement_permutation", "normalise_gammas", "paper_protocol",
    "paper_protocol_for", "plot_protocol", "protocol_from_frame", "protocol_robustness",
    "read_protocol", "render", "sample_protocol", "to_csv_text", "to_dict", "to_json_text",
    "to_markdown", "write_protocol", "paper_protocol_points", "protocol_mask",
    "protocol_points_mask", "snap_points", "reproduce_section", "register",
]


def register(sub) -> None:
    """Add ``irreflect protocol`` and ``irreflect evaluate-protocol``."""
    from .cli import register as _register

    _register(sub)


def reproduce_section(ctx):
    """The protocol section of the reproduction report (see :mod:`irreflect.reporting`)."""
    from .report import reproduce_section as _section

    return _section(ctx)


def plot_protocol(protocol, dense=None, ax=None, **kwargs):
    """Protocol points in the (gamma, theta) plane (see :func:`.plot.plot_protocol`)."""
    from .plot import plot_protocol as _plot

    return _plot(protocol, dense, ax, **kwargs)
