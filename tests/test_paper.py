"""The paper's constants in irreflect.paper equal the paper's tables (when beside the checkout)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from irreflect.paper import TABLE1, TABLE3, paper_tables_dir


@pytest.fixture
def tables():
    folder = paper_tables_dir()
    if folder is None:
        pytest.skip("../shared/paper/tables not found")
    return folder


def test_table3_is_the_papers(tables):
    df = pd.read_csv(tables / "table3_parameters.csv").set_index("material")
    assert set(df.index) == set(TABLE3)
    for name, values in TABLE3.items():
        np.testing.assert_array_equal(df.loc[name, ["u_as", "v_as", "u_nd", "v_nd", "u_ns", "v_ns",
                                                    "K"]].to_numpy(float), values)


def test_table1_is_the_papers(tables):
    df = pd.read_csv(tables / "table1_protocol_12pt.csv")
    np.testing.assert_array_equal(df[["gamma_deg", "theta_deg"]].to_numpy(float),
                                  np.array(TABLE1, float))
