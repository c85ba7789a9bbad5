"""The paper's published tables ship inside the package, unchanged, and the constants of
irreflect.paper equal them. Nothing here depends on ../shared being present."""

from __future__ import annotations

import hashlib
import re

import numpy as np
import pandas as pd
import pytest

from irreflect.errors import UnknownNameError
from irreflect.paper import (
    PAPER_TABLES,
    TABLE1,
    TABLE3,
    paper_table,
    paper_tables_dir,
    shared_dir,
)


def _recorded_sums() -> dict[str, str]:
    """file -> SHA-256 as recorded in the bundled README's table."""
    text = (paper_tables_dir() / "README.md").read_text()
    return dict(re.findall(r"^\| (table\d_\w+\.csv) \|.*\| ([0-9a-f]{64}) \|$", text, re.M))


def test_every_paper_table_ships_with_its_recorded_checksum():
    folder = paper_tables_dir()
    assert folder.name == "paper_tables" and folder.parent.name == "irreflect"
    sums = _recorded_sums()
    assert set(sums) == set(PAPER_TABLES) == {p.name for p in folder.glob("*.csv")}
    for name, digest in sums.items():
        assert hashlib.sha256((folder / name).read_bytes()).hexdigest() == digest, name
    # and, where the development checkout's copy of the paper sits beside it, the same bytes
    shared = shared_dir()
    source = None if shared is None else shared / "paper" / "tables"
    if source is not None and source.is_dir():
        for name in sums:
            assert (source / name).read_bytes() == (folder / name).read_bytes(), name


def test_table3_constants_are_the_papers():
    df = paper_table("table3_parameters.csv").set_index("material")
    assert set(df.index) == set(TABLE3)
    for name, values in TABLE3.items():
        np.testing.assert_array_equal(df.loc[name, ["u_as", "v_as", "u_nd", "v_nd", "u_ns", "v_ns",
                                                    "K"]].to_numpy(float), values)


def test_table1_constants_are_the_papers():
    df = paper_table("table1_protocol_12pt.csv")
    np.testing.assert_array_equal(df[["gamma_deg", "theta_deg"]].to_numpy(float),
                                  np.array(TABLE1, float))


def test_paper_numbers_read_back_as_printed():
    t2 = paper_table("table2_fit_quality_12pt.csv").set_index("material")
    assert t2.loc["terrazzo", "r2"] == 0.9831 and t2.loc["foam_board", "mse"] == 3.5177e-04
    t5 = paper_table("table5_methods_r2.csv")
    assert len(t5) == 9 and set(t5["method"].astype(str)) == {"A", "B", "12"}
    assert isinstance(paper_table("table7_literature_error_pct.csv"), pd.DataFrame)
    with pytest.raises(UnknownNameError, match="unknown paper table 'table8.csv'"):
        paper_table("table8.csv")
