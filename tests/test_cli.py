"""The core commands: fit and plot, their outputs and their one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from irreflect.cli import main
from irreflect.data import bundled_dir

TERRAZZO = bundled_dir() / "terrazzo.csv"


def test_fit_json_has_the_documented_keys(capsys):
    assert main(["fit", str(bundled_dir() / "terrazzo.csv"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert {"model", "params", "stderr", "r2", "rmse", "mse", "n_points", "fit_ms"} <= set(out)
    assert out["model"] == "two-lobe" and out["n_points"] == 132
    assert set(out["params"]) == {"u_as", "v_as", "u_nd", "v_nd", "u_ns", "v_ns", "K"}
    assert 0.98 < out["r2"] < 1.0


def test_fit_warns_when_the_sigma_column_decides_the_fit(tmp_path, capsys):
    from tests.test_fitting import _lorentzian_lobe_table

    path = tmp_path / "lorentz.csv"
    _lorentzian_lobe_table(sigma_rel=0.02).to_frame().to_csv(path, index=False)
    material = tmp_path / "m.json"
    assert main(["fit", str(path), "--save", str(material)]) == 0
    captured = capsys.readouterr()
    assert "the points of smallest sigma decide it" in captured.err
    assert "irreflect fit --ignore-sigma" in captured.err
    assert "smallest sigma decide it" in material.read_text()  # the file carries it
    # one warning of the misfit beyond the noise, not two: the fit's chi^2/dof note is
    # folded into it (stop 52: "reduced chi^2 59" and "chi^2/dof 59" on two lines)
    assert "depart from the fit by chi^2/dof" not in captured.err
    assert "depart from the fit by chi^2/dof" not in material.read_text()
    assert captured.err.count("reduced chi^2") == 1
    assert "standard errors take sigma as given" in captured.err
    assert main(["plot", str(path), "--fit", "--out", str(tmp_path / "p.png")]) == 0
    err = capsys.readouterr().err  # plot --fit warns as fit does, once
    assert "irreflect plot --fit --ignore-sigma" in err and err.count("reduced chi^2") == 1
    assert "depart from the fit by chi^2/dof" not in err
    assert main(["fit", str(path), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["r2"] < 0.9 and d["unweighted_r2"] > 0.98
    assert main(["fit", str(path), "--ignore-sigma", "--json"]) == 0
    captured = capsys.readouterr()
    d2 = json.loads(captured.out)
    assert d2["r2"] == pytest.approx(d["unweighted_r2"], abs=1e-9)
    assert "unweighted_r2" not in d2 and "smallest sigma" not in captured.err
    # on a table without a sigma column the option does nothing, and says so
    bare = tmp_path / "bare.csv"
    lines = [",".join(x.split(",")[:3]) for x in path.read_text().splitlines()]
    bare.write_text("\n".join(lines) + "\n")
    assert main(["fit", str(bare), "--ignore-sigma"]) == 0
    err = capsys.readouterr().err
    assert "irreflect: warning: --ignore-sigma has no effect: bare has no sigma column" in err


def test_compare_select_and_diagnose_say_when_the_sigma_column_decides(tmp_path, capsys):
    # compare ranked the sigma-weighted fits without a word (held-out ggx-sigma-col:
    # two-lobe R^2 0.271 weighted, 0.987 unweighted); select and diagnose build on that fit
    from tests.test_fitting import _lorentzian_lobe_table

    path = tmp_path / "lorentz.csv"
    _lorentzian_lobe_table(sigma_rel=0.02).to_frame().to_csv(path, index=False)
    assert main(["compare", str(path), "--models", "two-lobe,phong", "--json"]) == 0
    captured = capsys.readouterr()
    d = json.loads(captured.out)
    (warning,) = d["warnings"]
    assert "two-lobe: R^2 " in warning and "--ignore-sigma" in warning
    assert warning in captured.err
    weighted = d["models"]["two-lobe"]["r2"]
    assert main(["compare", str(path), "--models", "two-lobe,phong", "--json",
                 "--ignore-sigma"]) == 0
    d2 = json.loads(capsys.readouterr().out)
    assert d2["warnings"] == [] and d2["models"]["two-lobe"]["r2"] > weighted + 0.05
    assert main(["diagnose", str(path), "--max-effects", "0"]) == 0
    assert "lorentz, two-lobe on all points: weighted by the sigma column" in (
        capsys.readouterr().err)
    assert main(["diagnose", str(path), "--max-effects", "0", "--ignore-sigma"]) == 0
    assert "sigma column" not in capsys.readouterr().err
    # without a sigma column: nothing to say
    assert main(["compare", "terrazzo", "--models", "two-lobe", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["warnings"] == []


def test_fit_carries_a_clipped_top_into_the_material_file(tmp_path, capsys):
    import numpy as np
    import pandas as pd

    t = np.arange(-80.0, 81.0, 2.0)
    frames = []
    for g in (-20.0, -40.0, -60.0):
        p = 0.2 * np.cos(np.radians(t)) + 4 * np.exp(-0.5 * ((t + g) / 5) ** 2)
        frames.append(pd.DataFrame({"gamma_deg": g, "theta_deg": t, "power": p}))
    table = pd.concat(frames)
    table["power"] = np.minimum(table["power"], 3.0)  # the detector's top
    path = tmp_path / "clipped.csv"
    table.to_csv(path, index=False)
    material = tmp_path / "m.json"
    assert main(["fit", str(path), "--save", str(material)]) == 0
    err = capsys.readouterr().err
    assert err.count("a saturated detector?") == 1  # said once, when the table was read
    saved = json.loads(material.read_text())["warnings"]
    clipped = int((table["power"] == 3.0).sum())
    assert any(w.startswith(f"clipped: {clipped} readings") and "saturated detector" in w
               for w in saved), saved


def test_fit_report_is_readable(capsys):
    assert main(["fit", str(bundled_dir() / "plasterboard.csv"), "--model", "phong"]) == 0
    out = capsys.readouterr().out
    assert "model phong" in out and "k_s" in out and "polar-area error" in out


def test_plot_writes_a_png(tmp_path):
    out = tmp_path / "polar.png"
    assert main(["plot", str(bundled_dir() / "foam_board.csv"), "--fit", "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(
    "args, message",
    [
        (["fit", "missing.csv"], "no such file"),
        (["fit", "{data}", "--model", "phong2"], "unknown model 'phong2'"),
        (["plot", "{data}", "--out", "{tmp}/x.txt"], "expected a file name ending in .png"),
    ],
)
def test_user_errors_exit_2_with_one_line_and_no_file(tmp_path, capsys, args, message):
    args = [a.format(data=bundled_dir() / "terrazzo.csv", tmp=tmp_path) for a in args]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_console_script_prints_no_traceback(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("gamma_deg,theta_deg,power\n-10,0,1\n-10,5,x\n")
    proc = subprocess.run([sys.executable, "-m", "irreflect.cli", "fit", str(bad)],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert "'power' must be numeric; found 'x' in data row 2" in proc.stderr


def test_too_few_points_for_the_model(tmp_path, capsys):
    small = tmp_path / "small.csv"
    small.write_text("gamma_deg,theta_deg,power\n" + "".join(
        f"-20,{t},{0.1 + t / 1000}\n" for t in range(-30, 30, 10)))
    assert main(["fit", str(small)]) == 2
    assert "found 6 points while at least 8 are needed" in capsys.readouterr().err


def test_every_command_is_listed_and_each_builds_alone():
    from irreflect.cli import COMMANDS, build_parser

    full = build_parser()
    listed = set(full._subparsers._group_actions[0].choices)
    assert listed == set(COMMANDS)
    for command in COMMANDS:
        alone = build_parser(command)
        assert command in alone._subparsers._group_actions[0].choices


def test_every_option_says_what_it_does_and_its_default():
    import argparse

    from irreflect.cli import build_parser

    sub = build_parser()._subparsers._group_actions[0]
    missing = []
    for command, parser in sub.choices.items():
        for action in parser._actions:
            if not action.option_strings or isinstance(action, argparse._HelpAction):
                continue
            text = action.help or ""
            flag = isinstance(action, argparse._StoreTrueAction | argparse._StoreFalseAction)
            if not text or not (flag or action.required or "default" in text
                                or "required" in text):
                missing.append(f"{command} {action.option_strings[0]}: {text!r}")
    assert not missing, missing


def test_progress_is_lines_through_a_pipe_and_a_bar_on_a_terminal(capsys):
    import io

    from irreflect._progress import progress

    bar = progress(total=8, desc="reproduce", unit="step")  # stderr is captured: no tty
    for stage in ("fit a", "fit b", "selection: a"):
        bar.set_postfix_str(stage)
        bar.update(1)
    bar.set_postfix_str("search status", refresh=False)  # a status, not a stage
    bar.update(5)
    bar.close()
    err = capsys.readouterr().err
    assert "\r" not in err
    lines = err.splitlines()
    assert lines[:3] == ["reproduce: [1/8] fit a", "reproduce: [2/8] fit b",
                         "reproduce: [3/8] selection: a"]
    assert lines[-1].startswith("reproduce: done (8/8 step") and len(lines) == 4

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    tty = Terminal()
    bar = progress(total=2, desc="x", stream=tty)
    bar.update(2)
    bar.close()
    assert "\r" in tty.getvalue() and "100%" in tty.getvalue()


def test_fit_takes_the_one_grammar_with_at_gamma(capsys):
    """``fit --model phong@10`` fits the |gamma| = 10 deg points only (the paper's Phong)."""
    import json

    from irreflect import fit, read_measurements

    assert main(["fit", str(TERRAZZO), "--model", "phong@10", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    meas = read_measurements(TERRAZZO)
    n10 = int((abs(meas.gamma_deg) == 10).sum())
    assert doc["model"] == "phong@10" and doc["n_points"] == n10 < meas.n_points
    # the same as fitting the subset by hand
    alone = fit(meas.subset(abs(meas.gamma_deg) == 10), "phong")
    assert doc["r2"] == pytest.approx(alone.r2, abs=1e-9)
    assert doc["on_all_points"]["n_points"] == meas.n_points
    assert doc["on_all_points"]["r2"] < alone.r2  # one incidence does not describe all
    assert main(["fit", str(TERRAZZO), "--model", "phong@15"]) == 2
    err = capsys.readouterr().err
    assert "no measurements at |gamma| = 15 deg" in err and "10, 20, 30" in err
    assert main(["select", str(TERRAZZO), "--model", "phong@10", "--out", "never"]) == 2
    assert "'@10' chooses the points" in capsys.readouterr().err


def test_the_public_api_resolves_every_name():
    import irreflect

    for name in irreflect.__all__:
        assert getattr(irreflect, name) is not None, name
    assert irreflect.get_model("two-lobe+background").n_params == 8


def test_a_closed_pipe_ends_quietly(monkeypatch, capsys):
    """``irreflect ... | head``: the reader leaves, the command stops without an error."""
    import io

    class ClosedPipe(io.StringIO):
        def write(self, text):
            raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr("sys.stdout", ClosedPipe())
    assert main(["models"]) == 141
    assert capsys.readouterr().err == ""


def test_compare_leaves_out_a_model_that_cannot_be_fitted_and_says_so(tmp_path, capsys):
    """A model that cannot be fitted (here more parameters than points) is left out with a
    warning on stderr and listed as skipped; the others are compared (exit 0). When none
    fits, the command fails with one line."""
    table = tmp_path / "six.csv"  # 6 points: phong (3 parameters) fits, two-lobe (7) cannot
    table.write_text("gamma_deg,theta_deg,power\n" + "".join(
        f"-20,{t},{0.2 + 0.5 * max(0.0, 1 - abs(t - 20) / 30):.4f}\n"
        for t in range(-30, 30, 10)))
    assert main(["compare", str(table), "--models", "phong,two-lobe", "--json"]) == 0
    captured = capsys.readouterr()
    out = json.loads(captured.out)
    assert list(out["models"]) == ["phong"]
    assert "two-lobe" in out["skipped"]
    assert "warning: six: two-lobe left out of the comparison" in captured.err
    assert main(["compare", str(table), "--models", "two-lobe"]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no model could be fitted" in err[0]


def test_ignore_sigma_reads_a_table_whose_sigma_column_would_be_refused(tmp_path, capsys):
    # unseen_tables3 sigma_all_zero: the column was checked (and refused) before
    # --ignore-sigma applied, so the option could not get around it
    import pandas as pd

    frame = pd.read_csv(TERRAZZO, comment="#")
    frame["sigma"] = 0.0
    path = tmp_path / "zeros.csv"
    frame.to_csv(path, index=False)
    assert main(["fit", str(path)]) == 2
    assert "sigma" in capsys.readouterr().err
    assert main(["fit", str(path), "--ignore-sigma", "--json"]) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["n_points"] == len(frame)
    assert "has no effect" not in captured.err
    assert main(["compare", str(path), "--models", "two-lobe", "--ignore-sigma"]) == 0
    assert "has no effect" not in capsys.readouterr().err
