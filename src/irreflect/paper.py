"""What the paper gives, in one place: its published tables (1-7) as data shipped inside the
package (:func:`paper_tables_dir`, :data:`PAPER_TABLES`), its Table 1 (the 12-point
protocol) and Table 3 (the fitted coefficients of its three materials) as constants, and
where the real measured data lie beside a checkout (``../shared``).

The tables are the paper's published numbers, not measurements (its raw data were never
published); ``irreflect/paper_tables/README.md`` names the source and the SHA-256 of every
file, and ``tests/test_paper.py`` checks the files and the constants against them.
"""

from __future__ import annotations

import os
from importlib import resources
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


#: The paper's tables shipped with irreflect: file -> (the paper's table, what it holds).
PAPER_TABLES: dict[str, tuple[str, str]] = {
    "table1_protocol_12pt.csv": ("Table 1", "the 12 (gamma, theta) points of the protocol"),
    "table2_fit_quality_12pt.csv": ("Table 2", "R^2, RMSE, MSE of the 12-point fit"),
    "table3_parameters.csv": ("Table 3", "fitted two-lobe coefficients per material"),
    "table4_fit_time_ms.csv": ("Table 4", "time of one fit (MATLAB, Core 2 Duo)"),
    "table5_methods_r2.csv": ("Table 5", "R^2 of Methods A, B and 12"),
    "table6_polar_error_pct.csv": ("Table 6", "polar-area error per gamma, two-lobe vs Phong"),
    "table7_literature_error_pct.csv": ("Table 7", "other models' errors (Karner et al. 1994)"),
}
#: Where the numbers come from (every file of :func:`paper_tables_dir`).
PAPER_SOURCE = ("De-La-Llana-Calvo et al., Modeling Infrared Signal Reflections to "
                "Characterize Indoor Multipath Propagation, Sensors 17(4), 847 (2017), "
                "doi:10.3390/s17040847")


def paper_tables_dir() -> Path:
    """The paper's published tables as CSV, shipped inside the package
    (``irreflect/paper_tables``, found through :mod:`importlib.resources`, so an installed
    package has them too); ``$IRREFLECT_PAPER_TABLES`` points elsewhere."""
    env = os.environ.get("IRREFLECT_PAPER_TABLES")
    return Path(env) if env else Path(str(resources.files("irreflect") / "paper_tables"))


def paper_table(filename: str):
    """One of the paper's tables (:data:`PAPER_TABLES`) as a pandas DataFrame."""
    import pandas as pd

    from .errors import unknown_name

    if filename not in PAPER_TABLES:
        raise unknown_name("paper table", filename, PAPER_TABLES)
    return pd.read_csv(paper_tables_dir() / filename)


def real_data_dir() -> Path | None:
    """The real measured data (``$IRREFLECT_REAL_DATA`` or ``../shared/datasets/real``)."""
    env = os.environ.get("IRREFLECT_REAL_DATA")
    if env and Path(env).is_dir():
        return Path(env)
    base = shared_dir()
    path = None if base is None else base / "datasets" / "real"
    return path if path is not None and path.is_dir() else None
