"""Measurement protocols (issue 4): the paper's 12 points for any tool (and in any dense
dataset, :mod:`.points`), their evaluation against dense data, a Monte Carlo of goniometer
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
    "paper_protocol_for", "protocol_from_frame", "protocol_robustness",
    "read_protocol", "render", "sample_protocol", "to_csv_text", "to_dict", "to_json_text",
    "to_markdown", "write_protocol", "paper_protocol_points", "protocol_mask",
    "protocol_points_mask", "snap_points",
]
