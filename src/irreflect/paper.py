"""What the paper gives, in one place: its Table 1 (the 12-point protocol), its Table 3 (the
fitted coefficients of its three materials), and where its tables and the real measured
data lie beside a checkout (``../shared``).

The constants are copied from the paper (``../shared/paper/tables``) so that irreflect runs
without that folder; ``tests/test_paper.py`` checks them against it when it is present.
"""

from __future__ import annotations

import os
from pathlib import Path

#: Table 3: two-lobe coefficients (u_as, v_as, u_nd, v_nd, u_ns, v_ns, K) per material.
TABLE3: dict[str, tuple[float, ...]] = {
    "terrazzo": (0.01713, -2.379, 1.021, 0.4283, 34.55, -0.3772, 0.4142),
    "plasterboard": (0.001284, -4.911, 1.083, 0.4636, 33.41, 1.382, 0.5215),
    "foam_board": (0.01742, -3.103, 1.457, 1.005, 102.0, 0.731, 0.3879),
}
#: Table 1: the 12-point protocol (gamma, theta) in degrees, in the paper's order.
TABLE1: tuple[tuple[float, float], ...] = (
    (-20, 20), (-20, 10), (-20, 30), (-20, -40), (-20, 70), (-40, -20), (-40, 60),
    (-60, 60), (-60, 50), (-60, 70), (-60, 0), (-60, -70),
)
#: The angles of incidence of Table 1 and the receiver range of the paper's tool (deg).
TABLE1_GAMMAS = (-20.0, -40.0, -60.0)
TOOL_THETA_RANGE = (-70.0, 70.0)


def _checkout_root() -> Path:
    return Path(__file__).resolve().parents[2]


def shared_dir() -> Path | None:
    """``../shared`` beside the checkout (or the folder ``$IRREFLECT_SHARED``), if present."""
    env = os.environ.get("IRREFLECT_SHARED")
    root = _checkout_root()
    for c in ([Path(env)] if env else []) + [root.parent / "shared", root.parent.parent / "shared"]:
        if c.is_dir():
            return c
    return None


def paper_tables_dir() -> Path | None:
    """The paper's tables as CSV (``../shared/paper/tables``), if present."""
    base = shared_dir()
    path = None if base is None else base / "paper" / "tables"
    return path if path is not None and path.is_dir() else None


def real_data_dir() -> Path | None:
    """The real measured data (``$IRREFLECT_REAL_DATA`` or ``../shared/datasets/real``)."""
    env = os.environ.get("IRREFLECT_REAL_DATA")
    if env and Path(env).is_dir():
        return Path(env)
    base = shared_dir()
    path = None if base is None else base / "datasets" / "real"
    return path if path is not None and path.is_dir() else None
