"""Measurement protocols (issue 4): the paper's 12 points for any tool, protocols designed
from a pilot scan, their evaluation against dense data, a Monte Carlo of goniometer
errors, and exports a technician can follow (CSV, JSON, Markdown checklist). The figure of
a protocol is :func:`irreflect.plots.protocol.plot_protocol`; the report section
:mod:`irreflect.report.protocol`.
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
from .design import choose_gamma_settings, design_protocol, tool_mask
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
from .robustness import RobustnessResult, protocol_robustness

__all__ = [
    "ORDER_RULE", "PAPER_RULE", "PURPOSES", "SCHEMA_VERSION", "Protocol", "ProtocolEvaluation",
    "RobustnessResult", "as_protocol", "choose_gamma_settings", "design_protocol",
    "evaluate_protocol", "measurement_permutation", "normalise_gammas", "paper_protocol",
    "paper_protocol_for", "protocol_from_frame", "protocol_robustness",
    "read_protocol", "render", "sample_protocol", "to_csv_text", "to_dict", "to_json_text",
    "to_markdown", "tool_mask", "write_protocol", "register",
]


def register(sub) -> None:
    """Add ``irreflect protocol`` and ``irreflect evaluate-protocol``."""
    from .cli import register as _register

    _register(sub)
