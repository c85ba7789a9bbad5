"""What ships with irreflect is reachable by name from any folder, and listed with its
origin and path by ``irreflect datasets``."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import numpy as np
import pytest

from irreflect.cli import main
from irreflect.data import (
    BUNDLED,
    bundled_dir,
    bundled_files,
    find_bundled,
    read_measurements,
    resolve_scene,
)
from irreflect.errors import DataError
from irreflect.paper import PAPER_TABLES, paper_tables_dir
from tests.helpers import tiny_room


def _run(argv):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


def test_bundled_tables_and_scenes_by_name_from_another_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for name in BUNDLED:
        for text in (name, f"{name}.csv"):
            meas = read_measurements(text)
            assert meas.name == name and meas.n_points in (102, 132)
    assert resolve_scene("office") == bundled_dir() / "rooms" / "office.toml"
    assert resolve_scene("office.toml").exists()
    assert find_bundled("granite") is None and find_bundled("sub/terrazzo") is None


def test_a_file_of_that_name_wins_over_the_bundled_one(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    Path("terrazzo.csv").write_text("gamma_deg,theta_deg,power\n" + "".join(
        f"-{g},{t},{1 + 0.01 * t}\n" for g in (20, 40) for t in range(-40, 50, 10)))
    assert read_measurements("terrazzo.csv").n_points == 18  # the local file, not 132 points
    assert read_measurements("terrazzo").n_points == 132  # no file named 'terrazzo' here


def test_a_missing_path_that_names_a_bundled_file_says_to_use_the_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, out, err = _run(["fit", "datasets/terrazzo.csv"])
    assert code == 2 and out == "" and err.count("\n") == 1
    assert "datasets/terrazzo.csv: no such file" in err
    assert "reachable by name: write 'terrazzo'" in err
    with pytest.raises(DataError, match="or the name of a bundled dataset: terrazzo"):
        read_measurements("granite.csv")
    code, _, err = _run(["room", "rooms/office.toml", "--out", str(tmp_path / "r")])
    assert code == 2 and "write 'office' instead" in err and not (tmp_path / "r").exists()


def test_fit_by_name_gives_the_same_fit_as_by_path(tmp_path, monkeypatch):
    code, by_path, _ = _run(["fit", str(bundled_dir() / "plasterboard.csv"), "--json"])
    monkeypatch.chdir(tmp_path)
    code2, by_name, _ = _run(["fit", "plasterboard", "--json"])
    assert code == code2 == 0
    a, b = json.loads(by_path), json.loads(by_name)
    assert a["params"] == b["params"] and a["r2"] == b["r2"]


def test_datasets_lists_every_shipped_file_with_origin_and_path():
    files = bundled_files()
    names = {f.name for f in files}
    assert set(BUNDLED) | {"office"} <= names
    assert {f"{p.removesuffix('.csv')}" for p in PAPER_TABLES} <= names
    for f in files:
        assert f.path.exists(), f
        assert f.origin
    code, out, err = _run(["datasets"])
    assert code == 0 and err == ""
    for f in files:
        assert f.name in out and str(f.path) in out
    assert "reconstruction of the paper's terrazzo, not a measurement" in out
    assert "(132 points)" in out and "Sensors 17(4), 847 (2017)" in out
    code, out, _ = _run(["datasets", "--path", "table5_methods_r2"])
    assert code == 0 and Path(out.strip()) == paper_tables_dir() / "table5_methods_r2.csv"
    code, out, _ = _run(["datasets", "--json"])
    doc = json.loads(out)
    assert {d["name"]: d["points"] for d in doc["bundled"] if d["kind"] == "table"} == {
        "terrazzo": 132, "plasterboard": 102, "foam_board": 132}
    code, _, err = _run(["datasets", "--path", "terazzo"])
    assert code == 2 and "Did you mean 'terrazzo'?" in err


def test_the_kernel_cache_is_inspected_and_a_warm_one_not_rebuilt():
    from irreflect._compiled import ensure_compiled, kernel_cache
    from irreflect.fitting import warm

    first = io.StringIO()
    seconds = ensure_compiled(warm, first)  # `make venv` warmed it: normally nothing to build
    if seconds is not None:  # a cold cache (the kernel's source changed): built, announced
        assert "compiling the fitting kernel" in first.getvalue()
    folder, cold = kernel_cache()
    assert folder is not None and folder.is_dir() and cold is False
    assert any(folder.glob("finish_kernel.tl_finish-*.nbi"))  # numba's index of the entry point
    again = io.StringIO()
    assert ensure_compiled(warm, again) is None and again.getvalue() == ""


def test_a_cold_kernel_cache_is_announced_by_the_first_compiled_fit(monkeypatch, capsys):
    """``irreflect fit`` is not among the commands that build the kernel up front (a small
    table is fitted with numpy), but a table whose search runs compiled sat 1-3 min in a
    silent build on a cold cache (stop 48's audit, a fresh worktree: 100 s, no word). The
    first compiled fit of a process now announces the build, and only the first."""
    import irreflect
    import irreflect._compiled as compiled

    looks = []
    monkeypatch.setattr(compiled, "kernel_cache", lambda: looks.append(1) or (Path("c"), True))
    monkeypatch.setattr(compiled, "_LOOKED", [False])
    table = read_measurements(bundled_dir() / "terrazzo.csv")
    irreflect.fit(table, engine="numpy", seed=0)
    assert capsys.readouterr().err == "" and not looks  # numpy: nothing to build
    irreflect.fit(table, engine="compiled", seed=0)
    irreflect.fit(table, engine="compiled", seed=1)
    err = capsys.readouterr().err
    assert looks == [1] and err.count("compiling the fitting kernel (once") == 1
    assert err.index("compiling the fitting kernel") < err.index("fitting kernel compiled in")


def test_a_cold_kernel_cache_is_announced_by_a_direct_call_of_fit_subsets(monkeypatch, capsys):
    """The commands that fit subsets (select, campaign, protocol --design-from) build the
    kernel up front; a script calling ``fit_subsets`` itself sat in a silent build on a cold
    cache (stop 48's note). Its compiled batch now announces it once, as ``fit`` does."""
    import irreflect._compiled as compiled
    from irreflect.fitting import fit_subsets

    looks = []
    monkeypatch.setattr(compiled, "kernel_cache", lambda: looks.append(1) or (Path("c"), True))
    monkeypatch.setattr(compiled, "_LOOKED", [False])
    table = read_measurements(bundled_dir() / "terrazzo.csv")
    masks = np.zeros((2, table.n_points), bool)
    masks[0, ::3] = masks[1, 1::3] = True
    args = (table.gamma_deg, table.theta_deg, table.power, masks)
    fit_subsets(*args, engine="numpy")
    assert capsys.readouterr().err == "" and not looks
    first = fit_subsets(*args, engine="compiled")
    fit_subsets(*args, engine="compiled")
    err = capsys.readouterr().err
    assert looks == [1] and err.count("compiling the fitting kernel (once") == 1
    assert not first.failed.any()


def _cold_room_cache(monkeypatch) -> list:
    """The room kernels' cache made to look cold, and their build replaced by a note in the
    list returned ("built" for each build)."""
    import irreflect._compiled as compiled
    import irreflect.room.warm as room_warm

    calls = []
    real = compiled.kernel_cache
    monkeypatch.setattr(compiled, "kernel_cache", lambda entry=compiled.ENTRY_POINTS,
                        package="irreflect.fitting": (Path("c"), True)
                        if package == "irreflect.room" else real(entry, package))
    monkeypatch.setattr(room_warm, "warm", lambda: calls.append("built"))
    return calls


def test_the_room_kernels_are_compiled_by_the_install_and_a_cold_cache_is_announced(
        tmp_path, monkeypatch, capsys):
    """The room's compiled kernels were built by the first simulation, in silence: a
    minute on a fresh install (57 s here), inside whichever test or `irreflect room` ran
    first. `make venv` now builds them (irreflect.room.warm), and `irreflect room` on a cold
    cache says so before it simulates."""
    import irreflect._compiled as compiled
    import irreflect.room.warm as room_warm

    built = io.StringIO()
    compiled.ensure_room_compiled(room_warm.warm, built)  # normally warm: nothing built
    folder, cold = compiled.kernel_cache(compiled.ROOM_ENTRY_POINTS, "irreflect.room")
    assert cold is False and folder is not None
    assert any(folder.glob("transport.lobe_matrix-*.nbi"))
    assert compiled.ensure_room_compiled(room_warm.warm, io.StringIO()) is None

    calls = _cold_room_cache(monkeypatch)
    scene = tmp_path / "scene.toml"
    scene.write_text(tiny_room())
    code = main(["room", str(scene), "--out", str(tmp_path / "out"), "--rays", "500",
                 "--no-figures", "--quiet"])
    err = capsys.readouterr().err
    assert code == 0 and calls == ["built"]
    assert err.count("compiling the room simulation's kernels (once") == 1
    assert "room kernels compiled in" in err


def test_reproduce_with_a_scene_builds_a_cold_room_cache_before_its_first_fit(
        tmp_path, monkeypatch, capsys):
    """`irreflect reproduce --scene` on a pip install (no `make venv` to build the room
    kernels) compiled them silently inside its room section, a minute into the report. Now
    a cold cache is built, announced, once the datasets are read and before any fit."""
    import irreflect.report.runner as runner

    calls = _cold_room_cache(monkeypatch)

    class Reached(Exception):
        pass

    def first_work(*args, **kwargs):  # where the fits begin
        calls.append("report")
        raise Reached

    monkeypatch.setattr(runner, "_run_report", first_work)
    scene = tmp_path / "scene.toml"
    scene.write_text(tiny_room())
    with pytest.raises(Reached):
        runner.reproduce(out_dir=tmp_path / "out", scene=scene, progress=False)
    assert calls == ["built", "report"]
    assert capsys.readouterr().err.count("compiling the room simulation's kernels (once") == 1
    calls.clear()  # without a scene nothing is built
    with pytest.raises(Reached):
        runner.reproduce(out_dir=tmp_path / "out2", progress=False)
    assert calls == ["report"]
