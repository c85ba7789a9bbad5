"""`irreflect reproduce --quick` on a measured table (Cornell's Cayman gloss paint): the
report speaks of measurements, names the failed protocol first and agrees with `select`.
(A file of its own so that its report and test_report.py's run on both test workers.)"""

from __future__ import annotations

import pandas as pd
import pytest

from irreflect.cli import main
from tests.test_report import _assert_one_answer, _select_like_the_report


# ----------------------------------------------------------------------------- real data
@pytest.fixture(scope="module")
def real_report_dir(tmp_path_factory):
    from irreflect.data import real_data_dir

    root = real_data_dir()
    if root is None:
        pytest.skip("real data not found: ../shared/datasets/real is absent")
    data = tmp_path_factory.mktemp("cornell")
    # the glossy Cayman paint: the paper's protocol misses its sub-degree specular lobe
    (data / "cornell_cayman.csv").write_bytes(
        (root / "cornell" / "cornell_cayman.csv").read_bytes())
    out = tmp_path_factory.mktemp("real_report")
    assert main(["reproduce", "--quick", "--data-dir", str(data), "--out", str(out),
                 "--no-progress"]) == 0
    return out


@pytest.mark.real
def test_report_on_measured_data_speaks_of_measurements(real_report_dir):
    md = (real_report_dir / "report.md").read_text()
    for wording in ("reconstruct", "bundled", "noise floor", "Gaussian noise",
                    "(no bundled material"):
        assert wording.lower() not in md.lower(), wording
    assert "**measured** tables" in md


@pytest.mark.real
def test_select_and_the_report_agree_on_a_measured_gloss_paint(real_report_dir, tmp_path):
    from irreflect.data import real_data_dir

    md = (real_report_dir / "report.md").read_text()
    table = real_data_dir() / "cornell" / "cornell_cayman.csv"
    summary = _select_like_the_report(str(table), tmp_path, md)
    _assert_one_answer(real_report_dir, summary, "cornell_cayman")


@pytest.mark.real
def test_report_on_measured_data_names_the_failed_protocol_first(real_report_dir):
    md = (real_report_dir / "report.md").read_text()
    findings = md.split('<a id="sec-findings"></a>', 1)[1].split("\n## ", 1)[0]
    assert findings.index("**What failed**") < findings.index("**Results**")
    failed = findings.split("**What failed**", 1)[1].split("**", 1)[1]
    assert failed.startswith("cornell_cayman**: the paper's 12-point protocol fails")
    # both evaluations of the protocol, with their numbers, and the cause
    t2 = pd.read_csv(real_report_dir / "tables" / "table2_fit_quality.csv")
    ev = pd.read_csv(real_report_dir / "tables" / "protocol_evaluation.csv")
    assert f"R^2 = {t2['R^2 ours'].iloc[0]:.4g}" in findings
    assert f"R^2 = {ev['R^2 protocol'].iloc[0]:.4g}" in findings
    assert "specular lobe" in findings and ev["verdict"].iloc[0] == "fails"
    assert t2["R^2 ours"].iloc[0] < t2["R^2 all-points fit"].iloc[0] - 0.5
