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
