"""Findings of the third held-out pass (``experiments/unseen_tables3.py``): what a table no
model fits is told, in fit, compare and diagnose."""

from __future__ import annotations

import numpy as np
import pytest

from irreflect.cli import main
from irreflect.errors import FitError
from irreflect.fitting import fit
from irreflect.fitting.shape_hint import GENERIC_ADVICE


def _velvet(path):
    """Power rising toward grazing receivers at every angle of incidence (velvet, cloth),
    in the paper's convention: no model of irreflect beats a constant on it."""
    rng = np.random.default_rng(111)
    rows = []
    for g in (-10, -20, -30, -40, -50, -60):
        for t in range(-84, 85, 4):
            tr = np.radians(t)
            p = (0.15 * np.cos(np.radians(g)) * np.cos(tr)
                 + 0.6 * np.cos(np.radians(g)) * abs(np.sin(tr)) ** 4.5 * np.cos(tr) ** 0.2
                 + 0.03 * np.exp(-0.5 * ((-g - t) / 20) ** 2))
            rows.append(f"{g},{t},{p * (1 + 0.02 * rng.normal()):.6g}\n")
    path.write_text("gamma_deg,theta_deg,power\n" + "".join(rows))
    return path


def test_a_fit_that_cannot_beat_a_constant_says_where_the_table_peaks(tmp_path):
    table = _velvet(tmp_path / "velvet.csv")
    with pytest.raises(FitError) as info:
        fit(str(table), seed=0)
    text = str(info.value)
    assert "cannot beat a constant" in text
    assert GENERIC_ADVICE not in text  # the angles follow the convention: not blamed
    assert "peak at grazing receivers" in text and "angles of incidence" in text


def test_compare_with_no_model_fitted_is_a_fit_failure_said_once(tmp_path, capsys):
    table = _velvet(tmp_path / "velvet.csv")
    assert main(["compare", str(table), "--models", "two-lobe,phong,ward"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("irreflect: fit failed: velvet: no model")
    assert "none beats a constant (two-lobe R^2 " in err[0]
    assert err[0].count("peak at grazing receivers") == 1
    assert len(err[0]) < 800


def test_diagnose_names_the_grazing_peak_not_an_offset(tmp_path, capsys):
    table = _velvet(tmp_path / "velvet.csv")
    assert main(["diagnose", str(table)]) == 1
    err = capsys.readouterr().err
    assert "peak at grazing receivers" in err and "dominated by an offset" not in err


def test_a_sigma_column_of_zeros_is_told_as_a_column_not_one_row(tmp_path, capsys):
    rows = "".join(f"-{g},{t},{1 + 0.01 * t},0\n" for g in (10, 30, 50) for t in range(-60, 61, 10))
    table = tmp_path / "zeros.csv"
    table.write_text("gamma_deg,theta_deg,power,sigma\n" + rows)
    assert main(["fit", str(table)]) == 2
    err = capsys.readouterr().err
    assert "found <= 0 in all 39 rows" in err and "delete the sigma column" in err
    some = tmp_path / "some.csv"
    some.write_text("gamma_deg,theta_deg,power,sigma\n"
                    + rows.replace(",0\n", ",0.01\n").replace(",0.01\n", ",0\n", 3))
    assert main(["fit", str(some)]) == 2
    assert "in data row 1 (line 2) and 2 more row(s) (of 39)" in capsys.readouterr().err
