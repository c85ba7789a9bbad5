"""Reliability (issue 12): checkpoints run no code, size budgets, output paths checked
before the work, output folders owned by one run, library errors in irreflect's style."""

from __future__ import annotations

import contextlib
import functools
import io
import json
import os
import pickle
import signal
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import synthetic

import irreflect
from irreflect import validation
from irreflect.cli import main
from irreflect.data import (
    Measurements,
    bundled_dir,
    read_measurements,
    validate_table,
    write_measurements,
)
from irreflect.errors import DataError, IrreflectError
from irreflect.fitting import fit, fit_subsets
from irreflect.selection import run_selection

TERRAZZO = str(bundled_dir() / "terrazzo.csv")
TINY = ["--pop-size", "8", "--generations", "2", "--max-points", "12", "--quiet"]


def _run(argv) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


def _one_error(argv) -> str:
    code, _, err = _run(argv)
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("irreflect: error: "), err
    return lines[0]


# ----------------------------------------------------------------------------- 1. checkpoints
class _Exploit:
    """Unpickling this runs a shell command that creates a file."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def test_a_malicious_checkpoint_runs_nothing_and_is_refused(tmp_path):
    marker = tmp_path / "pwned"
    ckpt = tmp_path / "run.ckpt"
    ckpt.write_bytes(pickle.dumps({"version": 1, "algorithm": _Exploit(marker)}))
    line = _one_error(["select", TERRAZZO, *TINY, "--checkpoint", str(ckpt),
                       "--out", str(tmp_path / "out")])
    assert "a pickle, which irreflect never loads" in line
    assert not marker.exists()
    assert not (tmp_path / "out").exists()
    # the same through the library
    with pytest.raises(IrreflectError, match="never loads"):
        run_selection(synthetic(noise=0.004, seed=3), pop_size=8, generations=2, max_points=12,
                      checkpoint=ckpt)
    assert not marker.exists()


def _small_checkpoint(tmp_path, seed=4, generations=3):
    meas = synthetic(noise=0.004, seed=3, name="noisy")
    ckpt = tmp_path / "run.ckpt"
    run_selection(meas, pop_size=12, generations=generations, max_points=16, seed=seed,
                  checkpoint=ckpt, checkpoint_every=1)
    return meas, ckpt


@pytest.mark.parametrize("damage, message", [
    ("random", "not a NumPy archive"),
    ("truncated", "truncated or corrupt"),
    ("foreign_npz", "no 'meta' array"),
    ("bad_tag", "no format tag"),
    ("bad_version", "format version 1"),
    ("bad_shape", "do not fit together"),
    ("edited_scores", "modified after it was written"),
    ("object_array", "pickle"),
])
def test_foreign_or_corrupt_checkpoints_are_one_line_errors(tmp_path, damage, message):
    meas, ckpt = _small_checkpoint(tmp_path)
    raw = ckpt.read_bytes()
    if damage == "random":
        ckpt.write_bytes(np.random.default_rng(0).bytes(300))
    elif damage == "truncated":
        ckpt.write_bytes(raw[: len(raw) // 2])
    elif damage == "foreign_npz":
        with open(ckpt, "wb") as fh:
            np.savez(fh, x=np.arange(3))
    elif damage == "object_array":
        with open(ckpt, "wb") as fh:
            np.savez(fh, meta=np.array([{"a": 1}], dtype=object))
    else:
        with np.load(ckpt, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        meta = json.loads(str(arrays["meta"]))
        if damage == "bad_tag":
            meta["format"] = "something-else"
        elif damage == "bad_version":
            meta["version"] = 1
        elif damage == "edited_scores":  # the fingerprint kept, the scores changed
            arrays["cache_scores"] = arrays["cache_scores"] * 0.5
        else:  # a shape that does not fit, with a digest that matches it
            from irreflect.selection.checkpoint import _digest

            arrays["pop_F"] = arrays["pop_F"][:-1]
            meta["digest"] = _digest(arrays, meta)
        arrays["meta"] = np.array(json.dumps(meta))
        with open(ckpt, "wb") as fh:
            np.savez(fh, **arrays)
    with pytest.raises(IrreflectError, match=message) as info:
        run_selection(meas, pop_size=12, generations=6, max_points=16, seed=4, checkpoint=ckpt)
    assert "\n" not in str(info.value)


def test_checkpoint_is_plain_data_and_resumes_to_the_identical_front(tmp_path):
    meas, ckpt = _small_checkpoint(tmp_path, generations=3)
    assert zipfile.is_zipfile(ckpt)
    with np.load(ckpt, allow_pickle=False) as z:  # every array loads without pickle
        meta = json.loads(str(z["meta"]))
        assert z["pop_X"].dtype == bool and z["pop_X"].shape[1] == meas.n_points
    assert meta["format"] == "irreflect-selection-checkpoint" and meta["generation"] == 3
    resumed = run_selection(meas, pop_size=12, generations=7, max_points=16, seed=4,
                            checkpoint=ckpt)
    straight = run_selection(meas, pop_size=12, generations=7, max_points=16, seed=4)
    assert resumed.settings["resumed_from_generation"] == 3
    pd.testing.assert_frame_equal(resumed.front, straight.front)
    assert resumed.evaluations == straight.evaluations
    assert resumed.cache_hits == straight.cache_hits
    for k in straight.masks:
        np.testing.assert_array_equal(resumed.masks[k], straight.masks[k])


# ----------------------------------------------------------------------------- 2. budgets
def _grid_table(path: Path, n_gamma: int, n_theta: int) -> Path:
    g, t = np.meshgrid(-np.linspace(5, 80, n_gamma), np.linspace(-85, 85, n_theta),
                       indexing="ij")
    # the power falls a little with |gamma|, as a material's does: a table the same at every
    # angle of incidence ties its maximum there, which reads as a saturated detector (a note)
    power = 0.1 + np.cos(np.radians(t.ravel())) ** 2 * (1 + 1e-3 * g.ravel())
    pd.DataFrame({"gamma_deg": g.ravel(), "theta_deg": t.ravel(), "power": power}).to_csv(
        path, index=False)
    return path


@pytest.fixture(scope="module")
def table_10_001(tmp_path_factory):
    folder = tmp_path_factory.mktemp("big")
    path = _grid_table(folder / "big.csv", 91, 110)  # 10,010 points
    assert read_measurements(path).n_points == 10_010
    return path


@pytest.mark.parametrize("command", ["diagnose", "reproduce", "select", "protocol"])
def test_tables_over_a_command_budget_are_refused_up_front(table_10_001, tmp_path, command,
                                                           monkeypatch):
    # the computation must not start: any fit would raise here (the search itself is
    # patched: a module imported meanwhile that binds `fit` would keep a patched `fit`)
    monkeypatch.setattr("irreflect.fitting.api._fit_search", _must_not_run)
    argv = {
        "diagnose": ["diagnose", str(table_10_001)],
        "reproduce": ["reproduce", "--data-dir", str(table_10_001.parent), "--out",
                      str(tmp_path / "r")],
        "select": ["select", str(table_10_001), "--out", str(tmp_path / "s")],
        "protocol": ["protocol", "--design-from", str(table_10_001)],
    }[command]
    line = _one_error(argv)
    assert "10010 measured points" in line and "subsample" in line
    if command == "select":
        assert "--max-points 30" in line  # the way out that keeps the table
    else:
        assert f"'{command}'" in line and str(validation.POINT_BUDGET[command]) in line
    assert list(tmp_path.iterdir()) == []


def test_select_accepts_a_large_table_with_max_points_and_caps_the_subset_size(table_10_001,
                                                                            tmp_path):
    line = _one_error(["select", str(table_10_001), "--max-points", "600", "--out",
                       str(tmp_path / "s")])
    assert "--max-points 600 is more than the 500 points" in line
    validation.check_selection_budget(10_010, 30)  # accepted: no error


def test_budgets_of_fit_and_select(monkeypatch, tmp_path):
    monkeypatch.setitem(validation.POINT_BUDGET, "fit", 100)
    monkeypatch.setitem(validation.POINT_BUDGET, "select", 100)
    for argv in (["fit", TERRAZZO],
                 ["select", TERRAZZO, "--max-points", "20", "--out", str(tmp_path / "s")]):
        line = _one_error(argv)
        assert "132 measured points is more than" in line and "(100 points)" in line


def test_a_pilot_scan_is_held_to_a_fit_budget_not_to_the_design_search_budget(monkeypatch):
    """'protocol --lobe-from' fits its pilot once: a 2,976-point held-out scan was refused
    by the 2,000 points of '--design-from' (which searches subsets of it). Its own budget is
    named in its error, with its own variable."""
    assert validation.point_budget("protocol-lobe-from") == validation.POINT_BUDGET["fit"]
    validation.check_points_budget(10_010, "protocol-lobe-from")  # accepted: no error
    with pytest.raises(validation.DataError, match="2,000|2000"):
        validation.check_points_budget(10_010, "protocol")
    monkeypatch.setitem(validation.POINT_BUDGET, "protocol-lobe-from", 100)
    line = _one_error(["protocol", "--lobe-from", TERRAZZO])
    assert "132 measured points is more than 'protocol --lobe-from' handles" in line
    assert "(100 points)" in line and "IRREFLECT_BUDGET_POINTS_PROTOCOL_LOBE_FROM=N" in line
    monkeypatch.setenv("IRREFLECT_BUDGET_POINTS_PROTOCOL_LOBE_FROM", "150")
    code, out, err = _run(["protocol", "--lobe-from", TERRAZZO])
    assert code == 0 and "glossy-aware protocol designed from terrazzo" in err


def test_caller_side_chunks_bound_each_subset_batch(monkeypatch):
    """Each fit_subsets call gets at most MAX_BATCH_VALUES (subsets x points x values per
    point), and the scores do not depend on the split (beyond rounding)."""
    from irreflect.selection import SubsetEvaluator, problem

    meas = synthetic(noise=0.004, seed=3)
    rng = np.random.default_rng(1)
    masks = np.zeros((30, meas.n_points), bool)
    for row in masks:
        row[rng.choice(meas.n_points, 40, replace=False)] = True
    whole, _ = SubsetEvaluator(meas.gamma_deg, meas.theta_deg, meas.power).fit_masks(masks)
    sizes = []
    real = problem.fit_subsets

    @functools.wraps(real)  # keeps the signature FitSettings filters its options by
    def spy(*args, **kwargs):
        sizes.append(len(args[3]))
        return real(*args, **kwargs)

    monkeypatch.setattr(problem, "fit_subsets", spy)
    per_point = problem.values_per_point(problem.SEARCH_FIT.kwargs())
    monkeypatch.setattr(problem, "MAX_BATCH_VALUES", per_point * 40 * 7)  # 7 subsets of 40
    split, _ = SubsetEvaluator(meas.gamma_deg, meas.theta_deg, meas.power).fit_masks(masks)
    assert max(sizes) == 7 and sum(sizes) == 30
    # the same fits up to rounding: the light search fits stop at a relative cost change of
    # 1e-6, and the batched data-driven starts are matrix products whose rounding depends
    # on the batch's shape
    np.testing.assert_allclose(split, whole, rtol=1e-5)


def test_pieces_are_also_bounded_by_the_table_size(monkeypatch):
    """A batch's masks span the whole table: on a large table a piece holds at most
    MAX_BATCH_VALUES mask values (subsets x table points), whatever the subset sizes."""
    from irreflect.selection import SubsetEvaluator, problem

    meas = synthetic(noise=0.004, seed=3)
    rng = np.random.default_rng(2)
    masks = np.zeros((20, meas.n_points), bool)
    for row in masks:
        row[rng.choice(meas.n_points, 10, replace=False)] = True
    sizes = []
    real = problem.fit_subsets

    @functools.wraps(real)
    def spy(*args, **kwargs):
        sizes.append(args[3].shape)
        return real(*args, **kwargs)

    monkeypatch.setattr(problem, "fit_subsets", spy)
    monkeypatch.setattr(problem, "MAX_BATCH_VALUES", meas.n_points * 8 * 6)
    # the numpy path holds about 8 values per table point and subset (weighted masks,
    # predictions on all points): 6 subsets per piece here, whatever their size
    settings = problem.FitSettings.of(**problem.SEARCH_FIT.kwargs(), engine="numpy")
    SubsetEvaluator(meas.gamma_deg, meas.theta_deg, meas.power,
                    settings=settings).fit_masks(masks)
    assert sum(s[0] for s in sizes) == 20
    assert max(s[0] for s in sizes) == 6 and all(s[1] == meas.n_points for s in sizes)


def test_point_masks_are_the_explicit_neighbours_in_unique_order():
    """PointMasks (a subset plus or minus each of some points, built piece by piece) gives
    the rows np.unique would give for the explicit array, and the same scores."""
    from irreflect.selection import SubsetEvaluator
    from irreflect.selection.problem import PointMasks

    meas = synthetic(noise=0.004, seed=5)
    rng = np.random.default_rng(4)
    base = np.zeros(meas.n_points, bool)
    base[rng.choice(meas.n_points, 12, replace=False)] = True
    for add, points in ((True, np.flatnonzero(~base)[::3]), (False, np.flatnonzero(base))):
        lazy = PointMasks(base, points[::-1].copy(), add=add)  # any order in
        explicit = np.repeat(base[None], points.size, axis=0)
        explicit[np.arange(points.size), points] = add
        explicit = np.unique(explicit, axis=0)
        np.testing.assert_array_equal(lazy.rows(np.arange(len(lazy))), explicit)
        np.testing.assert_array_equal(lazy.counts(), explicit.sum(axis=1))
        a, fa = SubsetEvaluator(meas.gamma_deg, meas.theta_deg, meas.power).fit_masks(lazy)
        b, fb = SubsetEvaluator(meas.gamma_deg, meas.theta_deg, meas.power).fit_masks(explicit)
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(fa, fb)


def test_difference_weights_are_sparse_and_equal_the_dense_definition():
    """The noise estimate's difference weights: a sparse (windows x n) matrix (a dense one
    is 3.2 GB at 20,000 points) equal to the textbook construction, window by window."""
    from irreflect.diagnose.workflow import difference_weights

    rng = np.random.default_rng(7)
    gamma = np.repeat([-10.0, -35.0, -60.0], 9)
    theta = np.concatenate([np.sort(rng.uniform(-80, 80, 9)) for _ in range(3)])
    theta[4] = theta[3]  # a repeated receiver angle: its windows are skipped
    order = rng.permutation(gamma.size)
    gamma, theta = gamma[order], theta[order]
    w = difference_weights(gamma, theta)
    assert hasattr(w, "tocsr") and w.nnz == 3 * w.shape[0]
    dense = []
    t = np.radians(theta)
    for g in np.unique(gamma):
        idx = np.flatnonzero(gamma == g)
        idx = idx[np.argsort(t[idx], kind="stable")]
        for s in range(idx.size - 2):
            win = idx[s:s + 3]
            x = t[win]
            if len(set(x.tolist())) < 3:
                continue
            v = np.array([1 / ((x[0] - x[1]) * (x[0] - x[2])), 1 / ((x[1] - x[0]) * (x[1] - x[2])),
                          1 / ((x[2] - x[0]) * (x[2] - x[1]))])
            row = np.zeros(gamma.size)
            row[win] = v / np.linalg.norm(v)
            dense.append(row)
    assert w.shape == (len(dense), gamma.size) == (7 + 5 + 7, 27)
    np.testing.assert_allclose(w.toarray(), np.array(dense), rtol=1e-12, atol=1e-15)


def _must_not_run(*args, **kwargs):
    raise AssertionError("the computation started before the check")


# ----------------------------------------------------------------------------- 4. output paths
@pytest.mark.parametrize("argv", [
    ["plot", TERRAZZO, "--fit", "--out", "{tmp}/folder"],
    ["protocol", "--design-from", TERRAZZO, "--out", "{tmp}/folder"],
    ["compare", TERRAZZO, "--out", "{tmp}/file.txt"],
    ["diagnose", TERRAZZO, "--out", "{tmp}/file.txt"],
    ["select", TERRAZZO, "--out", "{tmp}/file.txt"],
    ["select", TERRAZZO, "--checkpoint", "{tmp}/folder", "--out", "{tmp}/s"],
    ["reproduce", "--out", "{tmp}/file.txt"],
    ["reproduce", "--out", "{tmp}/file.txt/sub"],
    ["reproduce", "--out", "/proc/irreflect-report"],
])
def test_output_paths_are_checked_before_reading_or_computing(tmp_path, monkeypatch, argv):
    (tmp_path / "folder").mkdir()
    (tmp_path / "file.txt").write_text("x")
    monkeypatch.setattr("irreflect.data.read_measurements", _must_not_run)
    monkeypatch.setattr("irreflect.report.runner.read_measurements", _must_not_run)
    line = _one_error([a.format(tmp=tmp_path) for a in argv])
    assert "--out" in line or "--checkpoint" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file.txt", "folder"]


# ----------------------------------------------------------------------------- 6. ownership
def test_a_rerun_replaces_the_previous_runs_output_and_keeps_foreign_files(tmp_path):
    out = tmp_path / "out"
    assert _run(["select", TERRAZZO, "--seeds", "0", "1", "--workers", "1", *TINY,
                 "--out", str(out)])[0] == 0
    assert (out / "runs.csv").exists() and (out / "terrazzo" / "seed1").is_dir()
    (out / "notes").mkdir()
    (out / "notes" / "mine.txt").write_text("a user's file")
    assert _run(["select", TERRAZZO, "--seed", "2", *TINY, "--out", str(out)])[0] == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == [".irreflect-manifest.json", "notes", "optimal_points.csv",
                     "optimal_points.png", "pareto.csv", "pareto.png", "summary.json"]
    manifest = json.loads((out / ".irreflect-manifest.json").read_text())
    assert manifest["command"] == "select" and "runs.csv" not in manifest["files"]
    assert json.loads((out / "summary.json").read_text())["seed"] == 2
    assert [p.name for p in tmp_path.iterdir()] == ["out"]  # no lock or temporary left


PROTOCOL = ["protocol", "--gammas", "-20", "-40", "-60", "--out"]


def test_a_folder_holding_only_irreflect_outputs_is_taken_and_they_are_kept(tmp_path):
    """The README's tour: select --out out/select, then reproduce (here compare) --out out."""
    out = tmp_path / "out"
    assert _run(["compare", TERRAZZO, "--models", "phong", "--out", str(out / "cmp")])[0] == 0
    assert _run(["compare", TERRAZZO, "--models", "ward", "--out", str(out)])[0] == 0
    assert (out / "cmp" / "comparison.csv").exists() and (out / "comparison.csv").exists()
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "mine.txt").write_text("x")
    line = _one_error(["compare", TERRAZZO, "--out", str(tmp_path)])
    assert "holds files irreflect did not write (other" in line


@pytest.mark.parametrize("kind", ["file", "dir"])
def test_a_second_run_into_the_same_output_refuses_while_the_first_runs(tmp_path, kind):
    out = tmp_path / ("p.csv" if kind == "file" else "out")
    argv = PROTOCOL + [str(out)] if kind == "file" else \
        ["compare", TERRAZZO, "--models", "phong", "--out", str(out)]
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys; from irreflect._atomic import claim_output\n"
         f"with claim_output({str(out)!r}, {kind!r}):\n"
         "    print('held', flush=True); sys.stdin.readline()"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        line = _one_error(argv)
        assert f"another irreflect run (pid {holder.pid}) is writing there now" in line
    finally:
        holder.communicate("\n", timeout=30)
    # the lock went with its holder: now the run goes through
    if kind == "file":
        assert _run(argv)[0] == 0 and out.read_text().startswith("gamma_deg,theta_deg")
    assert sorted(p.name for p in tmp_path.iterdir()) == (["p.csv"] if kind == "file" else [])


def test_leftovers_of_killed_runs_are_removed_by_the_next_run(tmp_path):
    from irreflect._atomic import atomic_directory

    out = tmp_path / "out"
    # a run killed (SIGKILL) while writing its output folder
    killed = subprocess.run(
        [sys.executable, "-c", "import os, signal; from irreflect._atomic import atomic_directory\n"
         f"with atomic_directory({str(out)!r}) as tmp:\n"
         "    (tmp / 'half.csv').write_text('1,2')\n"
         "    os.kill(os.getpid(), signal.SIGKILL)"])
    assert killed.returncode == -signal.SIGKILL
    left = [p.name for p in tmp_path.iterdir()]
    assert not out.exists() and any(n.startswith(".out.irreflect-tmp-") for n in left)
    # leftovers in the names of earlier versions (tempfile folders and checkpoint files)
    (tmp_path / ".out.k2j4_x9a").mkdir()
    (tmp_path / ".ck.ckpt.ab12cd34.tmp").write_text("x")
    with atomic_directory(out) as tmp:
        (tmp / "whole.csv").write_text("1,2")
    run_selection(synthetic(noise=0.004, seed=3), pop_size=8, generations=2, max_points=12,
                  checkpoint=tmp_path / "ck.ckpt")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ck.ckpt", "out"]
    assert sorted(p.name for p in out.iterdir()) == [".irreflect-manifest.json", "whole.csv"]


# ----------------------------------------------------------------------------- 8. library API
def test_library_entry_points_raise_irreflect_errors(tmp_path):
    meas = synthetic(noise=0.004, seed=3)
    df = meas.to_frame()
    result = fit(meas)
    n = meas.n_points
    cases = [
        (lambda: read_measurements(df), "for a DataFrame use validate_table"),
        (lambda: validate_table(df.set_axis(pd.MultiIndex.from_product([["a"], df.columns]),
                                            axis=1)), "multi-level column names"),
        (lambda: validate_table(df.set_axis([0, 1, 2], axis=1)), "missing column 'gamma_deg'"),
        (lambda: validate_table(df.assign(power=df["power"] + 1j)), "complex numbers"),
        (lambda: validate_table(df.assign(power=df["power"] > 0.1)), "true/false"),
        (lambda: write_measurements(meas, tmp_path), "is a folder"),
        (lambda: write_measurements(meas, tmp_path / "m.xlsx"), "ending in .csv or .parquet"),
        (lambda: write_measurements([1, 2], tmp_path / "m.csv"), "expects Measurements"),
        (lambda: Measurements([-10, -20], [0, 5, 10], [1, 2, 3]), "found lengths"),
        (lambda: Measurements([-10, -20], [0, 5], ["a", "b"]), "must be numbers"),
        (lambda: fit_subsets(meas.gamma_deg, meas.theta_deg, meas.power[:-1],
                             np.ones((2, n), bool)), "found lengths"),
        (lambda: fit_subsets(meas.gamma_deg, meas.theta_deg, meas.power,
                             np.ones((2, n + 1), bool)), f"\\(subsets, {n}\\) boolean array"),
        (lambda: fit_subsets(meas.gamma_deg, meas.theta_deg, meas.power,
                             np.full((2, n), 0.5)), "true/false"),
        (lambda: result.predict("a", "b"), "must be numbers"),
        (lambda: result.predict(gamma_deg=95, theta_deg=0), "found 95"),
        (lambda: result.predict([-10, -20], [0, 1, 2]), "same shape"),
        (lambda: fit(meas, seed=-1), "seed must be an integer >= 0; found -1"),
        (lambda: fit(meas, seed=1.5), "seed must be an integer"),
        (lambda: run_selection(meas, seed=-2), "seed must be an integer >= 0"),
        (lambda: irreflect.fit(42), "expected a measurement table"),
    ]
    for call, message in cases:
        with pytest.raises(IrreflectError, match=message) as info:
            call()
        assert "\n" not in str(info.value)
    # lists are accepted where arrays are, and the predictions keep their shape
    m = Measurements([-10, -20], [0, 5], [1, 2])
    assert m.power.dtype == float and m.n_points == 2
    assert result.predict(np.full((2, 3), -30.0), np.zeros((2, 3))).shape == (2, 3)


def test_a_shifted_csv_is_refused_not_read_as_shifted_columns(tmp_path):
    path = tmp_path / "shifted.csv"
    path.write_text("gamma_deg,theta_deg,power\n-10,0,0.5,0.01\n-10,5,0.4,0.01\n")
    with pytest.raises(DataError, match=r"line 2 \(data row 1\) has 4 fields, the header 3"):
        read_measurements(path)


def test_parquet_messages_name_rows_not_csv_lines(tmp_path):
    df = synthetic(noise=0.004, seed=3).to_frame()
    df["power"] = df["power"].astype(str)
    df.loc[4, "power"] = "n/a?"
    path = tmp_path / "t.parquet"
    df.to_parquet(path)
    with pytest.raises(DataError, match="in data row 5: fix") as info:
        read_measurements(path)
    assert "line" not in str(info.value)


def test_numpy_screening_is_scored_in_pieces_with_the_same_costs(monkeypatch):
    """The numpy path scores screening candidates in pieces of at most
    SCREEN_PIECE_VALUES basis values (a 200,000-point table with hundreds of candidates
    would otherwise hold gigabytes); the costs equal those of one batch."""
    from irreflect.fitting import screening as fitting
    from irreflect.models import Geometry, get_model

    meas = synthetic(noise=0.004, seed=8)
    model = get_model("lafortune")
    geom = Geometry.of(np.radians(meas.gamma_deg)[None], np.radians(meas.theta_deg)[None])
    sw = np.ones((1, meas.n_points))
    z = fitting.screen_samples(model, 40, 3)
    yw = np.broadcast_to(meas.power[None], (len(z), meas.n_points))
    whole = fitting._screen_costs(model, geom, z, sw, yw)
    pieces = []
    real = fitting._screen_piece

    def spy(model_, geom_, z_, sw_, yw_):
        pieces.append(len(z_))
        return real(model_, geom_, z_, sw_, yw_)

    monkeypatch.setattr(fitting, "_screen_piece", spy)
    monkeypatch.setattr(fitting, "SCREEN_PIECE_VALUES", meas.n_points * model.n_linear * 7)
    split = fitting._screen_costs(model, geom, z, sw, yw)
    assert pieces == [7] * 5 + [5]
    np.testing.assert_allclose(split, whole, rtol=1e-12)
    assert np.isfinite(whole).sum() > 20
