"""Reliability, second round (issue 24): outputs never replace inputs or special files,
inputs are regular files read within bounds, scenes read materials only from their folder,
every run within its budget, scenes / material files / checkpoints against their schemas,
the library's arguments checked. Property tests of the same surfaces: test_fuzz_inputs.py.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import synthetic

from irreflect import validation
from irreflect.cli import main
from irreflect.data import Measurements, bundled_dir, read_measurements
from irreflect.errors import FitError, IrreflectError

TERRAZZO = bundled_dir() / "terrazzo.csv"
ROOMS = bundled_dir() / "rooms"
TINY = ["--pop-size", "8", "--generations", "2", "--max-points", "12", "--quiet"]


def _run(argv) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in argv])
    return code, out.getvalue(), err.getvalue()


def _one_error(argv) -> str:
    code, _, err = _run(argv)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("irreflect: error: "), (code, err)
    assert "Traceback" not in err
    return lines[0]


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture
def data(tmp_path) -> Path:
    path = tmp_path / "mydata.csv"
    shutil.copy(TERRAZZO, path)
    return path


@pytest.fixture
def office(tmp_path) -> Path:
    """The bundled office scene and its material files, copied to a folder of its own."""
    folder = tmp_path / "scene"
    shutil.copytree(ROOMS, folder)
    return folder / "office.toml"


# ----------------------------------------------------------------------------- outputs
@pytest.mark.parametrize("argv", [
    ["protocol", "--lobe-from", "{data}", "--out", "{data}"],
    ["select", "{data}", *TINY, "--checkpoint", "{data}", "--out", "{tmp}/s"],
])
def test_an_output_never_replaces_an_input_of_the_same_run(data, tmp_path, argv):
    before = _digest(data)
    line = _one_error([a.format(data=data, tmp=tmp_path) for a in argv])
    assert "would be replaced by this run's output" in line and "mydata.csv" in line
    assert _digest(data) == before and len(data.read_text().splitlines()) == 133


def test_an_output_through_a_link_to_the_input_is_refused_too(data, tmp_path):
    link = tmp_path / "link.csv"
    link.symlink_to(data.name)  # in the same folder: followed, so it is the input itself
    before = _digest(data)
    line = _one_error(["protocol", "--lobe-from", data, "--out", link])
    assert "would be replaced" in line
    assert _digest(data) == before and link.is_symlink()


@pytest.mark.parametrize("special", ["fifo", "device", "stdout-link"])
def test_an_output_that_is_not_a_regular_file_is_refused(tmp_path, special):
    out = tmp_path / "out.csv"
    if special == "fifo":
        os.mkfifo(out)
    elif special == "device":
        out = Path("/dev/null")
    else:
        out.symlink_to("/proc/self/fd/1")
    line = _one_error(["protocol", "--gammas", "-20", "-40", "-60", "--format", "csv",
                       "--out", out])
    assert ("is a pipe (FIFO)" in line if special == "fifo" else
            "is a device" in line if special == "device" else "outside" in line)
    if special == "fifo":
        assert out.exists() and not out.is_file()
    if special == "stdout-link":
        assert out.is_symlink()


def test_an_output_folder_link_within_its_folder_is_written_through_and_kept(tmp_path):
    real = tmp_path / "real"
    assert _run(["compare", TERRAZZO, "--models", "phong", "--out", real])[0] == 0
    (real / "notes.txt").write_text("a user's notes")
    link = tmp_path / "latest"
    link.symlink_to("real")
    assert _run(["compare", TERRAZZO, "--models", "ward", "--out", link])[0] == 0
    assert link.is_symlink() and os.readlink(link) == "real"
    assert (real / "notes.txt").read_text() == "a user's notes"
    assert "ward" in (real / "comparison.csv").read_text()


def test_an_output_link_out_of_its_folder_is_refused(tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (tmp_path / "here").mkdir()
    link = tmp_path / "here" / "out"
    link.symlink_to(elsewhere)
    line = _one_error(["compare", TERRAZZO, "--out", link])
    assert "symlink" in line and "outside" in line
    assert list(elsewhere.iterdir()) == [] and link.is_symlink()


def test_two_runs_through_a_link_and_its_target_are_locked_out_of_each_other(tmp_path):
    target = tmp_path / "p.csv"
    link = tmp_path / "latest.csv"
    link.symlink_to("p.csv")
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys; from irreflect._atomic import claim_output\n"
         f"with claim_output({str(target)!r}, 'file'):\n"
         "    print('held', flush=True); sys.stdin.readline()"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        line = _one_error(["protocol", "--gammas", "-20", "-40", "-60", "--out", link])
        assert f"another irreflect run (pid {holder.pid})" in line
    finally:
        holder.communicate("\n", timeout=30)


@pytest.mark.parametrize("argv, words", [
    (["fit", "{data}", "--save", ""], "--save must name a file"),
    (["compare", "{data}", "--out", ""], "--out must name a folder"),
    (["diagnose", "{data}", "--out", ""], "--out must name a folder"),
    (["compare", "{data}", "--models", ""], "--models is empty"),
    (["diagnose", "{data}", "--extensions", " , "], "--extensions is empty"),
    (["protocol", "--gammas", "-20", "-40", "-60", "--out", ""], "--out must name a file"),
    (["fit", "{data}", "--reflectance", "0.5"], "add --save"),
    (["compare", "{data}", "--models", "two-lobe,phong,"], "has an empty name between its "
                                                          "commas"),
    (["compare", "{data}", "--models", "two-lobe,,phong"], "remove the extra comma"),
    (["diagnose", "{data}", "--extensions", "background,"], "has an empty name between its "
                                                           "commas"),
    (["campaign", "{data}", "--strategies", "adaptive,"], "--strategies 'adaptive,' has an "
                                                         "empty name"),
    (["evaluate-protocol", "{data}", "{data}", "--monte-carlo", "5", "--angle-error", "20"],
     "--angle-error (deg) must be a finite number >= 0 and <= 10; found 20"),
])
def test_empty_or_orphan_options_are_refused_not_ignored(data, tmp_path, argv, words):
    line = _one_error([a.format(data=data) for a in argv])
    assert words in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mydata.csv"]


@pytest.mark.parametrize("argv, words", [
    # was "material '--reflectance': reflectance must be in [0, 1] ..."
    (["fit", "{data}", "--reflectance", "1.5", "--save", "{out}.json"],
     "irreflect: error: --reflectance must be in [0, 1] (reflected power"),
    # was fitted and written as m.json, printed as "wrote .../m.json/"
    (["fit", "{data}", "--save", "{out}.json/"], "m.json/: ends in '/', so it names a folder; "
                                                 "expected a file name ending in .json"),
    (["protocol", "--gammas", "-20", "-40", "-60", "--out", "{out}.csv/"], "ends in '/'"),
])
def test_bad_output_options_are_named_as_options(data, tmp_path, argv, words):
    line = _one_error([a.format(data=data, out=tmp_path / "m") for a in argv])
    assert words in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mydata.csv"]


@pytest.mark.parametrize("argv, warning", [
    (["plot", "{data}", "--seed", "3", "--out", "{out}.png"],
     "--seed has no effect without --fit"),
    (["plot", "{data}", "--model", "phong", "--seed", "3", "--out", "{out}.png"],
     "--model and --seed have no effect without --fit"),
    (["compare", "{data}", "--models", "two-lobe,phong@20", "--phong-at-deg", "40"],
     "--phong-at-deg has no effect: no model of --models ends in '@'"),
])
def test_an_option_without_effect_is_named(data, tmp_path, argv, warning):
    code, _, err = _run([a.format(data=data, out=tmp_path / "fig") for a in argv])
    assert code == 0 and f"irreflect: warning: {warning}" in err


def test_options_that_take_effect_get_no_such_warning(data, tmp_path):
    for argv in (["plot", data, "--fit", "--seed", "3", "--out", tmp_path / "a.png"],
                 ["plot", data, "--out", tmp_path / "b.png"],
                 ["compare", data, "--models", "two-lobe,phong@", "--phong-at-deg", "40"]):
        code, _, err = _run(argv)
        assert code == 0 and "no effect" not in err, err


# ----------------------------------------------------------------------------- inputs
def _special(tmp_path: Path, kind: str, name: str) -> Path:
    path = tmp_path / name
    if kind == "fifo":
        os.mkfifo(path)
    else:
        path.symlink_to("/dev/zero")
    return path


@pytest.mark.parametrize("kind", ["fifo", "zero"])
@pytest.mark.parametrize("role", ["table", "scene", "protocol", "checkpoint"])
def test_special_files_as_inputs_are_refused_without_reading(tmp_path, kind, role):
    if role == "table":
        argv = ["fit", _special(tmp_path, kind, "t.csv")]
    elif role == "scene":
        argv = ["room", _special(tmp_path, kind, "s.toml"), "--out", tmp_path / "r"]
    elif role == "protocol":
        argv = ["evaluate-protocol", _special(tmp_path, kind, "p.csv"), TERRAZZO]
    else:
        argv = ["select", TERRAZZO, *TINY, "--checkpoint", _special(tmp_path, kind, "c.ckpt"),
                "--out", tmp_path / "s"]
    line = _one_error(argv)
    expected = ("pipe (FIFO)" if kind == "fifo" else
                "outside" if role == "checkpoint" else "a device")  # a link out of the folder
    assert expected in line


def test_a_material_file_that_is_a_fifo_in_the_scene_folder_is_refused(office):
    os.mkfifo(office.parent / "fifo.json")
    text = office.read_text().replace('file = "terrazzo.json"', 'file = "fifo.json"')
    office.write_text(text)
    line = _one_error(["room", office, "--out", office.parent / "r"])
    assert "fifo.json" in line and "pipe (FIFO)" in line


def test_tables_are_bounded_by_what_is_read(tmp_path, monkeypatch):
    monkeypatch.setattr("irreflect.data.MAX_FILE_BYTES", 2000)
    big = tmp_path / "big.csv"
    shutil.copy(TERRAZZO, big)  # about 5 KB
    line = _one_error(["fit", big])
    assert "more than 1 KB" in line and "subsample" in line


def test_a_parquet_of_compressed_text_is_refused_after_decoding_within_bounds(tmp_path,
                                                                            monkeypatch):
    import pyarrow as pa
    import pyarrow.parquet as pq

    monkeypatch.setattr("irreflect.data.MAX_DECODED_BYTES", 20 * 2**20)
    m = synthetic()
    rows = 200_000
    idx = np.arange(rows) % m.n_points
    text = pa.DictionaryArray.from_arrays(pa.array(np.zeros(rows, np.int32)),
                                          pa.array(["x" * 2000]))  # 400 MB once decoded
    table = pa.table({"gamma_deg": m.gamma_deg[idx], "theta_deg": m.theta_deg[idx],
                      "power": m.power[idx], "material": text})
    path = tmp_path / "bomb.parquet"
    pq.write_table(table, path, compression="zstd")
    assert path.stat().st_size < 2 * 2**20
    line = _one_error(["fit", path])
    assert "decode to more than 20 MB" in line


def test_a_small_parquet_with_text_columns_still_reads(tmp_path):
    m = synthetic()
    df = m.to_frame()
    df["material"] = "terrazzo"
    df["gamma_deg"] = df["gamma_deg"].map(str)  # numbers stored as text
    path = tmp_path / "t.parquet"
    df.to_parquet(path, index=False)
    back = read_measurements(path)
    assert back.n_points == m.n_points and back.material == "terrazzo"
    np.testing.assert_allclose(back.gamma_deg, m.gamma_deg)


# ----------------------------------------------------------------------------- checkpoints
def _checkpoint(tmp_path):
    from irreflect.selection import run_selection

    meas = synthetic(noise=0.004, seed=3, name="noisy")
    ckpt = tmp_path / "run.ckpt"
    run_selection(meas, pop_size=8, generations=2, max_points=14, seed=1, checkpoint=ckpt,
                  checkpoint_every=1)
    with np.load(ckpt, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    return meas, ckpt, arrays


def _write(ckpt, arrays, meta, digest=True):
    from irreflect.selection.checkpoint import _digest as array_digest

    if digest:
        meta["digest"] = array_digest(arrays, meta)
    arrays = dict(arrays, meta=np.array(json.dumps(meta)))
    with open(ckpt, "wb") as fh:
        np.savez(fh, **arrays)


@pytest.mark.parametrize("damage, message", [
    ("n_iter_text", "n_iter must be an integer"),
    ("n_iter_missing", "missing key 'n_iter'"),
    ("rng_huge", "state must be an integer from 0 to"),
    ("elites_shape", "do not fit together"),
    ("bare_npy", "a bare NumPy array"),
    ("bomb", "decompresses to more than"),
    ("nan_scores", "values out of range"),
])
def test_checkpoint_fields_are_checked_against_the_schema(tmp_path, monkeypatch, damage,
                                                          message):
    from irreflect.selection import run_selection

    meas, ckpt, arrays = _checkpoint(tmp_path)
    meta = json.loads(str(arrays.pop("meta")))
    if damage == "n_iter_text":
        meta["n_iter"] = "x"
    elif damage == "n_iter_missing":
        del meta["n_iter"]
    elif damage == "rng_huge":
        meta["rng"]["state"]["state"] = 2**300
    elif damage == "elites_shape":
        arrays["elites"] = arrays["elites"][:, :2]
    elif damage == "nan_scores":
        arrays["cache_scores"][0] = np.nan
    if damage == "bare_npy":
        with open(ckpt, "wb") as fh:
            np.save(fh, np.arange(5))
    elif damage == "bomb":
        monkeypatch.setattr("irreflect.selection.checkpoint.MAX_CHECKPOINT_BYTES", 4 * 2**20)
        with open(ckpt, "wb") as fh:
            np.savez_compressed(fh, pop_X=np.zeros(8 * 2**20, bool))
    else:
        _write(ckpt, arrays, meta)
    with pytest.raises(IrreflectError, match=message) as info:
        run_selection(meas, pop_size=8, generations=4, max_points=14, seed=1, checkpoint=ckpt)
    assert "\n" not in str(info.value) and "start afresh" in str(info.value)


# ----------------------------------------------------------------------------- materials
def _with_material(office: Path, value: str) -> Path:
    office.write_text(office.read_text().replace('file = "terrazzo.json"', f'file = "{value}"'))
    return office


@pytest.mark.parametrize("value", ["/etc/shadow", "/etc/passwd.json", "../outside.json",
                                   "sub/../../outside.json", "link.json"])
def test_scenes_read_material_files_only_inside_their_folder(office, tmp_path, value):
    outside = tmp_path / "outside.json"
    shutil.copy(office.parent / "terrazzo.json", outside)
    (office.parent / "link.json").symlink_to(outside)
    line = _one_error(["room", _with_material(office, value), "--out", tmp_path / "r"])
    assert f"material file '{value}' is outside the scene's folder" in line


def test_no_existence_oracle_outside_the_scene_folder(office, tmp_path):
    """The message is the same for a file that exists (not JSON) and one that does not."""
    (tmp_path / "exists.json").write_text("not json")
    original = office.read_text()
    lines = []
    for name in ("exists.json", "missing.json"):
        office.write_text(original)
        line = _one_error(["room", _with_material(office, f"../{name}"), "--out",
                           tmp_path / "r"])
        lines.append(line.replace(name, "X"))
    assert lines[0] == lines[1] and "outside the scene's folder" in lines[0]


def test_materials_dir_allows_another_folder(office, tmp_path):
    shared = tmp_path / "shared"
    shared.mkdir()
    shutil.copy(office.parent / "terrazzo.json", shared / "floor.json")
    scene = _with_material(office, str(shared / "floor.json"))
    from irreflect.room import load_scene

    with pytest.raises(IrreflectError, match="outside the scene's folder"):
        load_scene(scene)
    loaded = load_scene(scene, materials_dir=shared)
    assert loaded.materials["terrazzo"].model == "two-lobe"


def _material_doc() -> dict:
    return json.loads((ROOMS / "terrazzo.json").read_text())


@pytest.mark.parametrize("patch, message", [
    ({"params": {"u_as": "a"}}, "params.u_as must be a number"),
    ({"params": {"u_as": [1]}}, "params.u_as must be a number"),
    ({"params": {"u_as": None}}, "params.u_as must be a number"),
    ({"params": {"u_as": 10**400}}, "an integer of 401 digits"),
    ({"params": {"u_as": 5.0}}, "u_as of two-lobe must be a number from 0 to 1"),
    ({"reflectance": True}, "reflectance must be a number from 0 to 1 or \"K\""),
    ({"gamma_range_deg": ["a", "b"]}, "gamma_range_deg must be 2 numbers"),
    ({"gamma_range_deg": [70, 10]}, "min <= max"),
    ({"reflectence": 0.5}, "did you mean 'reflectance'"),
    ({"warnings": "one"}, "warnings must be a list of text"),
    ({"verdict": [1, 2]}, "verdict must be a fit's verdict"),
    ({"format_version": 7}, "format_version 7"),
])
def test_material_files_are_checked_against_their_schema(tmp_path, patch, message):
    from irreflect.room import load_material

    doc = _material_doc()
    for key, value in patch.items():
        if key == "params":
            doc["params"] = doc["params"] | value
        else:
            doc[key] = value
    path = tmp_path / "m.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(IrreflectError, match=message) as info:
        load_material(path, reflectance=0.5)
    assert "\n" not in str(info.value) and str(path) in str(info.value)


def test_a_fits_verdict_and_warnings_are_kept_in_a_material_file(tmp_path):
    from irreflect.room import load_material

    verdict = json.loads((ROOMS / "terrazzo.json").read_text())["verdict"]
    doc = _material_doc() | {"verdict": verdict, "warnings": ["ill-determined: v_nd"]}
    path = tmp_path / "m.json"
    path.write_text(json.dumps(doc))
    mat = load_material(path, reflectance=0.5)
    assert mat.metadata["verdict"]["summary"] == verdict["summary"]
    assert mat.metadata["warnings"] == ["ill-determined: v_nd"]
    doc["verdict"] = {"state": "usable"}  # not a verdict fit --save writes
    path.write_text(json.dumps(doc))
    with pytest.raises(IrreflectError, match="verdict: unknown key 'state'"):
        load_material(path, reflectance=0.5)


@pytest.mark.parametrize("kind", ["json", "toml"])
def test_deep_nesting_is_one_line_not_a_recursion_error(tmp_path, kind):
    from irreflect.room import load_material, load_scene

    if kind == "json":
        path = tmp_path / "deep.json"
        path.write_text("[" * 100_000 + "]" * 100_000)
        with pytest.raises(IrreflectError, match="nest more than 32 deep"):
            load_material(path)
    else:
        path = tmp_path / "deep.toml"
        path.write_text("a = " + "[" * 100_000 + "]" * 100_000 + "\n")
        with pytest.raises(IrreflectError, match="nest more than 32 deep"):
            load_scene(path)
        path.write_text("x = 1\n" + "[" + ".".join(["a"] * 100) + "]\nb = 1\n")
        with pytest.raises(IrreflectError, match="nest more than 32 deep"):
            load_scene(path)


# ----------------------------------------------------------------------------- scenes
def _office_doc() -> dict:
    return tomllib.loads((ROOMS / "office.toml").read_text())


def _set(doc, path, value):
    cur = doc
    for key in path[:-1]:
        cur = cur[key]
    if value is KeyError:
        del cur[path[-1]]
    else:
        cur[path[-1]] = value
    return doc


SCENE_CASES = [
    (("emitter",), 5, "top level: emitter must be an array of tables [[emitter]]"),
    (("room", "size_m"), [1e300, 5, 3], "[room]: size_m must be 3 numbers"),
    (("room", "size_m"), [1e7, 1e7, 1e7], "<= 1000"),
    (("emitter", 0, "half_power_angle_deg"), 1e-300, "half_power_angle_deg must be a number >= 1"),
    (("emitter", 0, "power_w"), 1e308, "power_w must be a number > 0 and <= 1e+06"),
    (("emitter", 0, "name"), "$\\frac{$", "[[emitter]] 1: name must be letters"),
    (("emitter", 0, "direction"), [0, 0, 0], "direction must be a direction, not [0, 0, 0]"),
    (("materials", "wood"), {"lambertian": True}, "lambertian must be a number"),
    (("materials", "wood"), {"model": "phong", "params": {"k_s": 0.1, "n": 2, "K": 1},
                             "reflectance": True}, "[materials.wood]: reflectance must be"),
    (("materials", "wood"), {"model": "phong", "params": {"k_s": 0.1, "n": 2, "K": 1},
                             "reflectance": 0.5, "gamma_max_deg": float("nan")},
     "gamma_max_deg must be a number > 0 and <= 90"),
    (("materials", "wood"), {"model": "phong", "params": {"k_s": {"a": 1}, "n": 2, "K": 1},
                             "reflectance": 0.5}, "k_s must be a number"),
    (("box", 0, "min_m"), [0, 0, 0], None),  # with max_m the room's size: filled below
    (("receiver", 0, "position_m"), [2.5, 2.5, 3.0], "the receiver sits on the ceiling"),
    (("receiver", 1, "position_m"), [2.5, 2.5, 2.9995], "is at emitter 'beacon'"),
    # 2 mm from a 1 cm^2 receiver the line-of-sight formula gave a gain of 7.96
    (("receiver", 1, "position_m"), [2.5, 2.5, 2.998], "the far-field line-of-sight formula "
                                                       "does not hold there"),
    (("receiver", 1, "direction"), [0, 0, -1], "faces into it"),  # on the desk's top
    (("receiver", 1, "name"), "barry_A", "receiver names must be distinct"),
    (("receiver", 1, "name"), "barry A", "give the same file name 'barry_A'"),
    (("receiver_grid", 0, "name"), "desk", "grid 'desk' has the name of a receiver"),
    (("receiver_grid", 0, "n"), [500, 500], "receivers is more than this machine's budget"),
    (("receiver_grid", 0, "n"), [True, 2], "n[1] must be an integer"),
    (("receiver_grid", 0, "x_m"), [1.0, 1.0], "x_m spans [1, 1], a single point, with"),
    (("simulation", "rays"), 1.5, "rays must be an integer"),
    (("simulation", "method"), "montecarl", "did you mean 'montecarlo'"),
]


@pytest.mark.parametrize("path, value, message", SCENE_CASES,
                         ids=[f"{'.'.join(map(str, p))}={str(v)[:20]}" for p, v, _ in SCENE_CASES])
def test_scene_keys_are_checked_against_the_schema_and_each_other(office, path, value, message):
    from irreflect.room import scene_from_dict

    doc = _set(_office_doc(), path, value)
    if path == ("box", 0, "min_m"):
        doc["box"][0]["max_m"] = [5.0, 5.0, 3.0]
        message = "the box fills the whole room"
    with pytest.raises(IrreflectError) as info:
        scene_from_dict(doc, path=str(office))
    text = str(info.value)
    assert message in text and text.startswith(f"{office}: ") and "\n" not in text


def test_a_second_emitter_of_the_same_name_is_refused(office):
    from irreflect.room import scene_from_dict

    doc = _office_doc()
    doc["emitter"].append(dict(doc["emitter"][0], position_m=[1.0, 1.0, 3.0]))
    with pytest.raises(IrreflectError, match="emitter names must be distinct; 'beacon'"):
        scene_from_dict(doc, path=str(office))


def test_toml_nan_and_booleans_in_a_scene_file_are_refused(office, tmp_path):
    text = office.read_text().replace("power_w = 1.0", "power_w = nan")
    office.write_text(text)
    assert "power_w must be a number > 0" in _one_error(["room", office, "--out", tmp_path / "r"])
    office.write_text(text.replace("power_w = nan", "power_w = true"))
    assert "found true (a boolean)" in _one_error(["room", office, "--out", tmp_path / "r"])


def test_room_figures_take_any_name_as_plain_text(tmp_path):
    """A scene built in Python skips the file schema: its names are still no mathtext."""
    from dataclasses import replace

    from irreflect.plots.room import write_figures
    from irreflect.room import simulate
    from irreflect.room.validation import barry_configuration_a

    scene = barry_configuration_a()
    scene = replace(scene, name="$\\frac{$",
                    emitters=(replace(scene.emitters[0], name="$x"),))
    result = simulate(scene, method="montecarlo", bounces=1, rays=200)
    written = result.write(tmp_path / "room", figures=write_figures)
    names = sorted(p.name for p in (tmp_path / "room").iterdir() if p.suffix == ".png")
    assert names and sorted(w for w in written if w.endswith(".png")) == names


# ----------------------------------------------------------------------------- budgets
@pytest.mark.parametrize("argv, option, bound", [
    (["room", "{scene}", "--rays", "1000000000000"], "--rays 1000000000000", "or less"),
    (["room", "{scene}", "--method", "recursive", "--cell", "0.005"], "--cell 0.005", "or more"),
    (["room", "{scene}", "--method", "recursive", "--cell", "1e-4"], "--cell 0.0001", "or more"),
    (["room", "{scene}", "--dt", "1e-9"], "--dt 1e-09", "or more"),
    (["select", "{data}", "--generations", "1000000000"], "--generations 1000000000", "or less"),
    (["select", "{data}", "--pop-size", "1208925819614629174706176"], "--pop-size", "or less"),
    (["protocol", "--design-from", "{data}", "--pop-size", "1000000000"], "--pop-size",
     "or less"),
    (["evaluate-protocol", "{tmp}/p.csv", "{data}", "--monte-carlo", "1000000000"],
     "--monte-carlo 1000000000", "or less"),
])
def test_every_budget_is_checked_before_the_work(office, data, tmp_path, monkeypatch, argv,
                                                 option, bound):
    monkeypatch.setattr("irreflect.fitting.api._fit_search", _must_not_run)
    monkeypatch.setattr("irreflect.room.engine._run", _must_not_run)
    monkeypatch.setattr("irreflect.room.recursive.prepare", _must_not_run)  # cells first
    argv = [a.format(scene=office, data=data, tmp=tmp_path) for a in argv]
    if argv[0] in ("room", "select"):
        argv += ["--out", str(tmp_path / "out")]
    if argv[0] == "evaluate-protocol":
        assert _run(["protocol", "--gammas", "-20", "-40", "-60", "--out", tmp_path / "p.csv"])[0] == 0
    line = _one_error(argv)
    assert line.startswith(f"irreflect: error: {option}") and "this machine's budget" in line
    assert bound in line and "IRREFLECT_BUDGET_" in line
    assert not (tmp_path / "out").exists()


def _must_not_run(*args, **kwargs):
    raise AssertionError("the work started before the budget was checked")


def test_the_largest_value_a_budget_names_is_accepted(office):
    """The value the message offers passes; one above it does not."""
    from irreflect.room import load_scene
    from irreflect.room.checks import CLI_OPTIONS, check_room_budget, resolve_settings

    scene = load_scene(office)
    line = ""
    try:
        check_room_budget(scene, resolve_settings(scene, {"rays": 10**12}), CLI_OPTIONS)
    except IrreflectError as exc:
        line = str(exc)
    largest = int(line.split("pass --rays ")[1].split()[0])
    assert largest == 10**9 // (103 * 3)
    check_room_budget(scene, resolve_settings(scene, {"rays": largest}), CLI_OPTIONS)
    with pytest.raises(IrreflectError, match="--rays"):
        check_room_budget(scene, resolve_settings(scene, {"rays": largest + 1}), CLI_OPTIONS)
    smallest = None
    try:
        check_room_budget(scene, resolve_settings(scene, {"method": "recursive",
                                                          "cell_m": 0.01}), CLI_OPTIONS)
    except IrreflectError as exc:
        smallest = float(str(exc).split("pass --cell ")[1].split()[0])
    check_room_budget(scene, resolve_settings(scene, {"method": "recursive",
                                                      "cell_m": smallest}), CLI_OPTIONS)


def test_a_budget_is_raised_by_its_environment_variable(office, monkeypatch):
    from irreflect.room import load_scene
    from irreflect.room.checks import check_room_budget, resolve_settings

    scene = load_scene(office)
    settings = resolve_settings(scene, {"rays": 10**7})
    with pytest.raises(IrreflectError, match="IRREFLECT_BUDGET_RAY_BOUNCES"):
        check_room_budget(scene, settings)
    monkeypatch.setenv("IRREFLECT_BUDGET_RAY_BOUNCES", "1e13")
    check_room_budget(scene, settings)
    monkeypatch.setenv("IRREFLECT_BUDGET_RAY_BOUNCES", "lots")
    with pytest.raises(IrreflectError, match="expected a number > 0"):
        check_room_budget(scene, settings)


@pytest.mark.parametrize("command", ["room", "select"])
def test_out_of_memory_names_the_option_that_sized_the_run(office, data, tmp_path, monkeypatch,
                                                           command):
    def no_memory(*args, **kwargs):
        raise MemoryError

    if command == "room":
        monkeypatch.setattr("irreflect.room.engine._run", no_memory)
        argv = ["room", office, "--out", tmp_path / "r", "--quiet"]
        named = "--dt"
    else:
        monkeypatch.setattr("irreflect.selection.run.run_selection", no_memory)
        monkeypatch.setattr("irreflect.cli.select.load_data", lambda *a, **k: synthetic())
        argv = ["select", data, *TINY, "--out", tmp_path / "s"]
        named = "--generations"
    code, _, err = _run(argv)
    # the room may warn first (a material's reciprocal form capped at grazing incidence)
    errors = [line for line in err.splitlines() if not line.startswith("irreflect: warning:")]
    assert code == 1 and len(errors) == 1 and "Traceback" not in err, err
    err = errors[0]
    assert "out of memory" in err and named in err and "subsample" not in err


# ----------------------------------------------------------------------------- the library
def _fit(**kw):
    from irreflect import fit

    return fit(synthetic(), engine="numpy", **kw)


def _fit_subsets(**kw):
    from irreflect import fit_subsets

    m = synthetic()
    return fit_subsets(m.gamma_deg, m.theta_deg, m.power, np.ones((1, m.n_points), bool), **kw)


def _room(name, *args, **kw):
    import irreflect.room as room

    return getattr(room, name)(*args, **kw)


def _barry():
    from irreflect.room.validation import barry_configuration_a

    return barry_configuration_a()


def _selection(**kw):
    from irreflect.selection import run_selection

    return run_selection(synthetic(), **kw)


def _diagnose(**kw):
    from irreflect.diagnose import diagnose

    return diagnose(synthetic(), **kw)


def _validate(frame):
    from irreflect import validate_table

    return validate_table(frame)


def _campaign(name):
    import irreflect.campaign as campaign

    return getattr(campaign, name)


def _compare(models):
    from irreflect.compare import compare_models

    return compare_models(synthetic(), models)


def _robustness(**kw):
    from irreflect.protocol import paper_protocol, protocol_robustness

    return protocol_robustness(paper_protocol([-20, -40, -60]), synthetic(), **kw)


API_CASES = [
    ("fit max_iter=-5", lambda: _fit(max_iter=-5), "max_iter must be an integer from 1"),
    ("fit use_sigma='no'", lambda: _fit(use_sigma="no"), "use_sigma must be True or False"),
    ("fit n_random_starts=-1", lambda: _fit(n_random_starts=-1), "n_random_starts must be"),
    ("fit n_keep='x'", lambda: _fit(n_keep="x"), "n_keep must be an integer"),
    ("fit options=dict", lambda: _fit(options={"seed": 0}),
     "options must be an irreflect.fitting.FitOptions (or None); found dict"),
    ("fit extra_starts", lambda: _fit(extra_starts=np.zeros((2, 9))), "extra_starts must be"),
    ("fit_subsets ftol=-1", lambda: _fit_subsets(ftol=-1), "ftol must be"),
    ("fit_subsets scan='yes'", lambda: _fit_subsets(scan="yes"), "scan must be True or False"),
    ("Measurements gamma -200", lambda: Measurements([-200.0], [0.0], [1.0]),
     "strictly between -90 and 90"),
    ("Measurements sigma 1e100", lambda: Measurements([-20.0], [5.0], [1.0], sigma=[1e100]),
     "above 1e12 times"),
    ("Measurements no points", lambda: Measurements([], [], []), "no points"),
    ("load_scene(None)", lambda: _room("load_scene", None), "expected a path to a scene"),
    ("simulate(None)", lambda: _room("simulate", None), "simulate expects a Scene"),
    ("simulate scheduler='nope'", lambda: _room("simulate", _barry(), scheduler="nope"),
     "not a scheduler address"),
    ("simulate rays=True", lambda: _room("simulate", _barry(), rays=True), "rays must be"),
    ("from_model params=None", lambda: _room("from_model", "two-lobe", None, 0.5),
     "params must be a table"),
    ("save_material(None)", lambda: _room("save_material", None, "x.json"),
     "expects a FitResult"),
    ("run_selection selector=5", lambda: _selection(selector=5), "unknown selector"),
    ("run_selection checkpoint_every=0", lambda: _selection(checkpoint_every=0),
     "checkpoint_every must be"),
    ("diagnose alpha=2", lambda: _diagnose(alpha=2), "alpha must be"),
    ("diagnose extensions=5", lambda: _diagnose(extensions=5), "extensions must be a list"),
    ("run_selection max_points=5", lambda: _selection(max_points=5),
     "max_points (--max-points) must be at least 8"),
    ("fit of duplicated rows", lambda: _validate(pd.concat([synthetic().to_frame()] * 2)),
     "(--average-duplicates; average_duplicates=True of read_measurements and validate_table)"),
    ("diagnose separate=-1", lambda: _diagnose(separate=-1),
     "separate must be an integer >= 0; found -1"),
    ("Instrument.from_table text", lambda: _campaign("Instrument").from_table(["a"], [0.0]),
     "gamma_deg must be numbers; found 'a'"),
    ("opening_design(None)", lambda: _campaign("opening_design")(None, 3),
     "opening_design expects an Instrument"),
    ("opening_design n=0", lambda: _campaign("opening_design")(
        _campaign("Instrument")(gammas_deg=(-10, -50)), 0), "must be an integer >= 1; found 0"),
    ("compare_models twice", lambda: _compare(["phong", "phong"]),
     "listed twice in models (--models)"),
    ("protocol_robustness n_trials='x'", lambda: _robustness(n_trials="x"), "n_trials must be"),
]


@pytest.mark.parametrize("name, call, words", API_CASES, ids=[c[0] for c in API_CASES])
def test_the_library_checks_its_arguments_with_its_own_errors(name, call, words):
    with pytest.raises((IrreflectError, FitError)) as info:
        call()
    assert words in str(info.value) and "\n" not in str(info.value)


def test_a_worker_runs_warnings_come_back_as_warnings_not_printed_text():
    import pickle
    import warnings

    from irreflect.errors import FitWarning
    from irreflect.selection.parallel import RunOutcome, _run_task, _Task, _warn_again

    meas = synthetic(noise=0.02, seed=3, name="noisy")  # 12-point fits that warn
    task = _Task(meas, 0, dict(pop_size=8, generations=2, max_points=12), True, None)
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        outcome = pickle.loads(pickle.dumps(_run_task(task)))  # as from a worker process
    assert isinstance(outcome, RunOutcome) and err.getvalue() == ""
    assert outcome.warned and all(issubclass(c, Warning) for c, _ in outcome.warned)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _warn_again([outcome])
    assert [str(w.message) for w in caught] == [m for _, m in outcome.warned]
    assert any(issubclass(w.category, FitWarning) for w in caught)


def test_a_table_with_sigma_far_above_its_power_is_refused(tmp_path):
    df = synthetic().to_frame()
    df["sigma"] = 1e100
    path = tmp_path / "s.csv"
    df.to_csv(path, index=False)
    line = _one_error(["select", path, *TINY, "--out", tmp_path / "s"])
    assert "above 1e12 times the largest power" in line


def test_budget_table_in_the_docs_lists_every_budget():
    docs = (Path(__file__).resolve().parents[1] / "docs" / "bad-input.md").read_text()
    for b in validation.BUDGETS.values():
        assert b.env in docs, b.env
    assert "IRREFLECT_BUDGET_POINTS_" in docs
    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    assert "docs/bad-input.md" in readme


def test_a_key_given_twice_in_a_material_file_is_refused_not_the_last_one_kept(tmp_path):
    from irreflect.room import load_material

    text = (ROOMS / "terrazzo.json").read_text()
    path = tmp_path / "m.json"
    path.write_text(text.replace('"reflectance": null', '"reflectance": 0.9, "reflectance": 0.2'))
    with pytest.raises(IrreflectError, match="key 'reflectance' appears twice"):
        load_material(path)


def test_a_protocol_of_more_points_than_a_protocol_lists_is_refused(tmp_path):
    m = synthetic()
    rows = pd.DataFrame({"gamma_deg": np.repeat(-np.linspace(1, 80, 200), 60),
                         "theta_deg": np.tile(np.linspace(-80, 80, 60), 200)})
    rows.to_csv(tmp_path / "p.csv", index=False)
    m.to_frame().to_csv(tmp_path / "dense.csv", index=False)
    line = _one_error(["evaluate-protocol", tmp_path / "p.csv", tmp_path / "dense.csv"])
    assert "12000 points is more than a protocol may list (10000)" in line


def test_a_link_planted_as_the_lock_file_truncates_nothing(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    (tmp_path / ".p.csv.irreflect-lock").symlink_to(victim)
    line = _one_error(["protocol", "--gammas", "-20", "-40", "-60", "--out", tmp_path / "p.csv"])
    assert "cannot take the lock" in line
    assert victim.read_text() == "precious" and not (tmp_path / "p.csv").exists()


def test_a_fifo_planted_as_an_output_folders_manifest_does_not_hang(tmp_path):
    out = tmp_path / "out"
    assert _run(["compare", TERRAZZO, "--models", "phong", "--out", out])[0] == 0
    manifest = out / ".irreflect-manifest.json"
    manifest.unlink()
    os.mkfifo(manifest)
    # in a child process: a hang fails the test (TimeoutExpired) instead of the suite
    proc = subprocess.run([sys.executable, "-m", "irreflect", "compare", str(TERRAZZO),
                           "--models", "phong", "--out", str(out)],
                          capture_output=True, text=True, timeout=120)
    assert "Traceback" not in proc.stderr
    assert proc.returncode in (0, 2), proc.stderr


# ----------------------------------------------------------------------------- next, campaign
@pytest.mark.parametrize("argv, words", [
    (["next", "{data}", "--out", ""], "--out must name a file"),
    (["campaign", "{data}", "--out", ""], "--out must name a folder"),
    (["next", "{data}", "--out", "{data}"], "is the input table"),
    (["next", "{data}", "--theta-step", "1e-9"], "pass --theta-step 0.002 or more"),
    (["campaign", "{data}", "--n-max", "1000000000"], "pass --n-max 2000 or less"),
    (["campaign", "{data}", "--generations", "1000000000"], "pass --generations 50000 or less"),
])
def test_next_and_campaign_refuse_empty_outputs_inputs_as_outputs_and_runs_above_budget(
        data, argv, words):
    before = _digest(data)
    line = _one_error([a.format(data=data) for a in argv])
    assert words in line
    assert _digest(data) == before


def test_an_output_never_replaces_a_bundled_table_read_by_name(tmp_path):
    bundled = bundled_dir() / "terrazzo.csv"
    before = _digest(bundled)
    for argv in (["next", "terrazzo", "--out", bundled],
                 ["protocol", "--lobe-from", "terrazzo", "--out", bundled],
                 ["diagnose", "terrazzo", "--separate-out", bundled]):
        line = _one_error(argv)
        assert "would be replaced by this run's output" in line
    assert _digest(bundled) == before


def test_a_material_files_verdict_is_checked_like_every_other_key(tmp_path):
    from irreflect.room import load_material

    doc = json.loads((ROOMS / "terrazzo.json").read_text())
    doc["verdict"]["summary"] = False
    (tmp_path / "m.json").write_text(json.dumps(doc))
    with pytest.raises(IrreflectError, match=r"verdict.summary must be text"):
        load_material(tmp_path / "m.json", reflectance=0.3)


def test_an_output_folder_of_another_command_is_not_replaced(tmp_path):
    # 'compare --out' into a 'diagnose' folder deleted the diagnosis without a word; a rerun
    # of the same command still replaces its own output
    from irreflect._atomic import MANIFEST

    out = tmp_path / "d_out"
    out.mkdir()
    (out / "diagnosis.json").write_text("{}\n")
    (out / MANIFEST).write_text(json.dumps({"written_by": "irreflect", "command": "diagnose",
                                            "files": ["diagnosis.json"]}))
    code, stdout, err = _run(["compare", TERRAZZO, "--models", "two-lobe", "--out", out])
    assert code == 2 and err.count("\n") == 1, err
    assert "holds the output of 'irreflect diagnose'" in err
    assert "this 'irreflect compare' run would replace" in err
    assert (out / "diagnosis.json").read_text() == "{}\n"
    (out / MANIFEST).write_text(json.dumps({"written_by": "irreflect", "command": "compare",
                                            "files": ["diagnosis.json"]}))
    code, _, err = _run(["compare", TERRAZZO, "--models", "two-lobe", "--out", out])
    assert code == 0, err
    assert (out / "comparison.json").exists() and not (out / "diagnosis.json").exists()


def test_the_near_field_limit_keeps_the_line_of_sight_gain_below_one(office):
    # a narrow beam (order 1000) on axis: the limit is where the far-field formula reaches
    # H = 1 (sqrt((m + 1) A / 2 pi) = 0.126 m for 1 cm^2); just beyond it the simulated
    # gain stays below 1 (energy: a receiver cannot collect more than the emitter sends)
    from irreflect.room import scene_from_dict, simulate

    doc = _office_doc()
    doc["emitter"][0]["lambertian_order"] = 1000
    doc["receiver"][1]["position_m"] = [2.5, 2.5, 3.0 - 0.13]
    doc["receiver"][1]["direction"] = [0, 0, 1]
    scene = scene_from_dict(doc, path=str(office))
    result = simulate(scene, method="montecarlo", bounces=1, rays=100, seed=0)
    summary = result.summary()
    los = float(summary[summary.receiver == "desk"].dc_gain_los.iloc[0])
    assert 0.9 < los < 1.0, los
    doc["receiver"][1]["position_m"] = [2.5, 2.5, 3.0 - 0.12]
    with pytest.raises(IrreflectError, match="closer than 0.126 m"):
        scene_from_dict(doc, path=str(office))


def test_a_separating_table_inside_the_output_folder_is_in_its_manifest(data, tmp_path):
    """diagnose --separate-out inside --out was written after the folder, outside its
    manifest: a rerun kept it as the user's own file beside the new run's."""
    out = tmp_path / "diag"
    argv = ["diagnose", data, "--extensions", "background", "--out", out]
    code, stdout, _ = _run(argv + ["--separate-out", out / "sep.csv"])
    assert code == 0 and f"wrote {out / 'sep.csv'}" in stdout
    manifest = json.loads((out / ".irreflect-manifest.json").read_text())
    assert "sep.csv" in manifest["files"] and "diagnosis.json" in manifest["files"]
    assert list(pd.read_csv(out / "sep.csv").columns[:2]) == ["gamma_deg", "theta_deg"]
    code, _, _ = _run(argv + ["--separate-out", out / "again.csv"])
    assert code == 0 and (out / "again.csv").is_file() and not (out / "sep.csv").exists()


def test_a_separating_table_that_is_the_output_folder_is_refused_up_front(data, tmp_path):
    """diagnose --out D --separate-out D worked for 4 s, then exited 1 with "cannot read or
    write .D.irreflect-tmp-...: Is a directory": the second claim of the same path reused
    the first, a folder, unchecked."""
    out = tmp_path / "d2"
    line = _one_error(["diagnose", data, "--out", out, "--separate-out", out])
    assert f"--separate-out {out}: is the --out folder of this run" in line
    assert [p.name for p in tmp_path.iterdir() if "d2" in p.name] == []  # nor a lock left


@pytest.mark.parametrize("values, instrument", [
    (["-2e1", "-40"], "angles of incidence -20, -40 deg"),
    (["-20,", "-40"], "angles of incidence -20, -40 deg"),
    (["-20,,-40"], "angles of incidence -20, -40 deg"),
    (["-1.5e1,-3e1"], "angles of incidence -15, -30 deg"),
])
def test_negative_numbers_in_any_spelling_are_values_not_options(tmp_path, values, instrument):
    """'--gammas -2e1 -40', '--gammas -20, -40' or '--theta-min -1e1' ended in "expected at
    least one argument": argparse took only -20 and -2.5 for negative numbers, anything else
    starting with '-' for an unknown option."""
    measured = tmp_path / "m.csv"
    measured.write_text("gamma_deg,theta_deg,power\n")
    code, out, err = _run(["next", measured, "--gammas", *values, "--theta-min", "-6e1"])
    assert code == 0, err
    assert instrument in out and "receiver -60..80 deg" in out


@pytest.mark.parametrize("argv, words", [
    (["--theta-min", "-inf"], "argument --theta-min: expected an angle in degrees strictly "
                              "between -90 and 90, found '-inf'"),
    (["--gammas", "-20x"], "found '-20x'"),
])
def test_a_malformed_negative_number_names_itself(tmp_path, argv, words):
    measured = tmp_path / "m.csv"
    measured.write_text("gamma_deg,theta_deg,power\n")
    assert words in _one_error(["next", measured, *argv])


def test_next_says_when_it_proposes_fewer_settings_than_asked(tmp_path):
    """'next --n 100000' printed "next 900 setting(s)" without a word on the rest."""
    measured = tmp_path / "m.csv"
    measured.write_text("gamma_deg,theta_deg,power\n")
    small = ["--gammas", "-30", "--theta-min", "-40", "--theta-max", "40", "--theta-step", "10"]
    code, out, err = _run(["next", measured, "--n", "50", *small])
    assert code == 0 and "next 8 setting(s)" in out
    assert ("note: --n 50 asked for more settings than are free: proposing 8, every setting "
            "not yet measured") in err
    code, out, err = _run(["next", measured, "--n", "50", *small, "--json"])
    assert code == 0 and any("proposing 8" in n for n in json.loads(out)["notes"])
    code, out, err = _run(["next", measured, "--n", "8", *small])
    assert code == 0 and "asked for more" not in err


@pytest.mark.parametrize("rows, words", [
    ([(-20, 20, 0.1), (-40, 40)], "found reading 2 with 2 value(s) after rows of 3"),
    ([(-20, 20, "1.2 mW")], "found '1.2 mW' in reading 1: give the number alone"),
    ((-20, 20, 0.1), "found one row of 3 numbers, not in a list: pass [(-20.0, 20.0, 0.1)]"),
    ({"gamma_deg": [-20], "theta_deg": [20], "power": [0.1]}, "found a dict: pass "
                                                               "pandas.DataFrame"),
    # records were told "found 'gamma_deg' in reading 1: give the number alone (power in
    # any one unit, without the unit's name)"
    ([{"gamma_deg": -20, "theta_deg": 20, "power": 0.1}], "found a dict as reading 1: pass "
                                                          "pandas.DataFrame(rows)"),
    # a table's row (df.iloc[0]) was taken by position and the fix offered was its values
    # in the Series' order: here (20.0, -20.0, 0.1), theta and gamma swapped
    (pd.Series({"theta_deg": 20.0, "gamma_deg": -20.0, "power": 0.1}),
     "found a pandas Series (one row of a table): pass a table, df.iloc[[i]]"),
    # rows of iterrows() were read by position: theta taken as gamma, silently
    ([row for _, row in pd.DataFrame({"theta_deg": [20.0, 40.0], "gamma_deg": [-20.0, -40.0],
                                      "power": [0.1, 0.2]}).iterrows()],
     "found a pandas Series as reading 1: pass pandas.DataFrame(rows)"),
])
def test_campaign_add_names_what_is_wrong_with_the_rows(rows, words):
    """A ragged list or a power with its unit was refused as "found list", a single reading
    not wrapped in a list as "found shape (3,)": neither said what to change."""
    from irreflect.campaign import Campaign, Instrument

    campaign = Campaign(Instrument(gammas_deg=(-20, -40, -60)))
    with pytest.raises(IrreflectError, match=r"^readings must be") as info:
        campaign.add(rows)
    assert words in str(info.value) and "\n" not in str(info.value)
    assert campaign.n_measured == 0


def test_a_table_mixing_signs_of_gamma_names_a_value_of_each_sign(tmp_path):
    """One gamma of 1e-12 (a rounding residue) among negative angles was refused as "mixes
    positive and negative angles of incidence" without saying where."""
    table = pd.read_csv(TERRAZZO)
    table.loc[40, "gamma_deg"] = 1e-12
    path = tmp_path / "mixed.csv"
    table.to_csv(path, index=False)
    line = _one_error(["fit", path])
    assert ("found 1 positive (first 1e-12 at data row 41 (line 42)) and 131 negative (first "
            "-10 at data row 1 (line 2))") in line


def test_an_angle_written_minus_zero_is_zero(tmp_path):
    """A table whose normal-incidence rows say gamma -0.0 (a script's rounding) was
    reported as "angles of incidence -0, -10, ..."."""
    table = pd.read_csv(TERRAZZO)
    normal = table[table.gamma_deg == -10].assign(gamma_deg=-0.0, theta_deg=lambda t: -t.theta_deg)
    path = tmp_path / "zero.csv"
    pd.concat([normal, table]).to_csv(path, index=False)
    assert "-0.0," in path.read_text()
    meas = read_measurements(path)
    assert not np.any(np.signbit(meas.gamma_deg) & (meas.gamma_deg == 0))
    code, out, err = _run(["fit", path, "--model", "phong"])
    assert code == 0, err
    assert "angles of incidence 0, -10, -20" in out and "-0," not in out


def test_a_long_compare_says_which_model_it_fits_through_a_pipe(monkeypatch):
    """compare of a 200,000-point table (within its budget) ran 15 min through a pipe
    without a line: its progress bar was shown on a terminal only."""
    import irreflect.compare as compare_module

    code, _, err = _run(["compare", TERRAZZO, "--models", "two-lobe,phong"])
    assert code == 0 and "fitting" not in err  # a quick comparison stays silent
    monkeypatch.setattr(compare_module, "PROGRESS_LINES_AFTER_S", 0.0)
    code, out, err = _run(["compare", TERRAZZO, "--models", "two-lobe,phong"])
    assert code == 0 and "best by BIC" in out
    lines = err.splitlines()
    assert lines[0].startswith("compare terrazzo: [0/2] fitting two-lobe (")
    assert lines[1].startswith("compare terrazzo: [1/2] fitting phong (")
    assert lines[2].startswith("compare terrazzo: done (2/2 models, ")


@pytest.mark.parametrize("column, values, words", [
    ("power", lambda p: [f"{x * 1000:.4f} mW" for x in p],
     "found '53.2560 mW' in data row 1 (line 2): write the numbers alone, without their unit "
     "'mW' (every row carries it"),
    ("power", lambda p: [f"{x:.6f}" for x in p[:3]] + ["1.2 mW"] + [f"{x:.6f}" for x in p[4:]],
     "found '1.2 mW' in data row 4 (line 5): 1 of 132 rows carry a unit ('mW'): write them as "
     "numbers alone, in the unit of the other rows"),
    ("power", lambda p: [f"{10 * np.log10(x):.2f} dBm" for x in p],
     "convert decibels to it (mW = 10^(dBm/10))"),
    ("theta_deg", lambda t: [f"{x:g} deg" for x in t], "write the angles alone, in degrees"),
])
def test_numbers_written_with_their_unit_are_named_as_such(tmp_path, column, values, words):
    """A power column of '53.2 mW' was refused with "fix or remove that row" though every
    row said the same; dBm would need converting, not just the unit removed."""
    table = pd.read_csv(TERRAZZO)
    table[column] = values(table[column].to_numpy())
    path = tmp_path / "units.csv"
    table.to_csv(path, index=False)
    line = _one_error(["fit", path])
    assert f"column '{column}' must be numeric" in line and words in line
    assert "fix or remove" not in line


def test_averaged_duplicates_say_how_far_the_repeats_disagree(tmp_path):
    """--average-duplicates merged repeats 50 % apart with only "averaged 5 duplicated
    (gamma, theta) row(s)"."""
    table = pd.read_csv(TERRAZZO)[["gamma_deg", "theta_deg", "power"]]
    repeats = table.iloc[[4]].assign(power=lambda t: t.power * 1.5)
    path = tmp_path / "dups.csv"
    pd.concat([table, repeats]).to_csv(path, index=False)
    code, out, err = _run(["fit", path, "--model", "phong", "--average-duplicates"])
    assert code == 0, err
    assert ("averaged 1 duplicated (gamma, theta) row(s); the repeats of one setting differ by "
            "up to 0.0577 (40% of their mean,") in err and "at gamma -10, theta -30" in err
    same = tmp_path / "same.csv"
    pd.concat([table, table.iloc[[4]]]).to_csv(same, index=False)
    code, out, err = _run(["fit", same, "--model", "phong", "--average-duplicates"])
    assert code == 0 and "averaged 1 duplicated (gamma, theta) row(s) (equal powers)" in err


def test_a_reading_taken_at_the_instruments_angle_says_so_when_it_meets_another(tmp_path):
    """A reading at gamma -20.1 (the goniometer's jitter) is taken at -20; when one at -20
    holds the same theta, "reading (-20, 20) is given twice" named a row the file does not
    hold."""
    from irreflect.campaign import Campaign, Instrument

    campaign = Campaign(Instrument(gammas_deg=(-20, -40)))
    campaign.add([(-20, 20, 0.1)])
    with pytest.raises(IrreflectError, match=r"reading \(-20, 20\) is given twice \(gamma "
                                             r"-20\.1 is taken at -20, an angle of incidence"):
        campaign.add([(-20.1, 20, 0.2)])
    # a repeat of a reading the campaign holds: "average the repeated readings into one
    # row" could not be done through add (it replaces nothing)
    with pytest.raises(IrreflectError, match=r"is given twice: the campaign already holds it "
                                             r"\(one reading per setting\): leave the repeat "
                                             r"out, or average the two and build the "
                                             r"campaign anew"):
        campaign.add([(-20, 20, 0.2)])
    assert campaign.n_measured == 1
    measured = tmp_path / "m.csv"
    measured.write_text("gamma_deg,theta_deg,power\n-20,20,0.1\n-20.1,20,0.12\n-40,30,0.1\n")
    line = _one_error(["next", measured, "--gammas", "-20", "-40"])
    assert "is given twice (gamma -20.1 is taken at -20" in line


def test_readings_closer_than_the_instruments_separation_are_noted(tmp_path):
    """Two readings 0.5 deg apart on an instrument whose readings stand at least 1 deg apart
    were fitted without a word (stop 47's fuzz); they are kept, and the note names them."""
    from irreflect.campaign import Campaign, Instrument
    from irreflect.data import DataNotice

    tool = Instrument(gammas_deg=(-30, -60), theta_min=-80, theta_max=80, theta_step=2.0)
    with pytest.warns(DataNotice, match=r"1 pair\(s\) of readings closer than the "
                                        r"instrument's min_separation .* 1 deg: at gamma -30, "
                                        r"theta 30 and 30\.5"):
        campaign = Campaign(tool).add([(-30, 30, 1.0), (-30, 30.5, 1.1), (-60, 10, 0.2)])
    assert campaign.n_measured == 3
    measured = tmp_path / "m.csv"
    measured.write_text("gamma_deg,theta_deg,power\n-30,30,1.0\n-30,34,1.1\n-60,10,0.2\n")
    code, out, err = _run(["next", measured, "--gammas", "-30", "-60", "--theta-step", "2",
                           "--min-separation", "5"])
    assert code == 0 and "theta 30 and 34" in err and "3 readings so far" in out
    code, out, err = _run(["next", measured, "--gammas", "-30", "-60", "--theta-step", "2"])
    assert code == 0 and "closer than" not in err


def test_an_angle_of_incidence_given_twice_is_refused():
    """``next --gammas -20 -20 -40`` quietly became two angles where ``protocol`` refuses
    the same list: a repeated angle is likely a typo for another one."""
    from irreflect.campaign import Instrument

    with pytest.raises(IrreflectError, match=r"list -20 deg 2 times; found -20, -20, -40: "
                                             r"give each angle once"):
        Instrument(gammas_deg=(-20, -20, -40))
    with pytest.raises(IrreflectError, match=r"list -20 deg 2 times"):
        Instrument(gammas_deg=(20, 20.0000000001, 40))
    assert Instrument(gammas_deg=(20, 40)).gammas_deg == (-20.0, -40.0)
    line = _one_error(["next", "-", "--gammas", "-20", "-20", "-40"])
    assert "list -20 deg 2 times" in line


def test_one_reading_is_one_reading(tmp_path):
    """'1 readings so far' read wrongly."""
    measured = tmp_path / "m.csv"
    measured.write_text("gamma_deg,theta_deg,power\n-30,30,1.0\n")
    code, out, _ = _run(["next", measured, "--gammas", "-30", "-60"])
    assert code == 0 and "m: 1 reading so far" in out and "verdict: continue: 1 reading;" in out


def test_plot_fit_says_when_the_sigma_column_decides_and_takes_ignore_sigma(tmp_path):
    """``plot --fit`` on a table with a sigma column that grows with the power drew the
    weighted fit (title R^2 0.51, where the unweighted fit reaches 0.99) without a word,
    and had no ``--ignore-sigma`` to draw the curve of power: ``fit`` warns of the same
    fit and offers the option."""
    from tests.test_fitting import _lorentzian_lobe_table

    path = tmp_path / "lorentz.csv"
    _lorentzian_lobe_table(sigma_rel=0.02).to_frame().to_csv(path, index=False)
    code, out, err = _run(["plot", path, "--fit", "--out", tmp_path / "w.png"])
    assert code == 0 and "the points of smallest sigma decide it" in err
    assert "irreflect plot --fit --ignore-sigma" in err
    code, out, err = _run(["plot", path, "--fit", "--ignore-sigma", "--out", tmp_path / "u.png"])
    assert code == 0 and "smallest sigma" not in err and (tmp_path / "u.png").exists()


def test_evaluate_protocol_names_points_beyond_the_measured_theta_range(tmp_path):
    """A protocol point at theta 73 on a table measured to 70 deg took the power read at 70
    and was listed among the angles 'interpolated along theta': it was not interpolated
    but carried over from another receiver angle. It is now said so."""
    protocol = tmp_path / "p.csv"
    code, _, _ = _run(["protocol", "--gammas", "-20", "-40", "-60", "--theta-min", "-73",
                       "--theta-max", "73", "--out", protocol])
    assert code == 0 and "-20,73," in protocol.read_text()
    code, out, err = _run(["evaluate-protocol", protocol, TERRAZZO])
    assert code == 0, err
    assert "beyond the measured theta range" in out
    assert "(-20, 73) gap 3.00: the reading at theta 70 carried over" in out


def test_the_mirror_peak_hint_names_the_model_that_failed():
    """A single-lobe fit of a glossy table that cannot beat a constant was told "try the
    model with '+background', e.g. --model two-lobe+background" (stop 48's audit): the
    example names the model that failed, and the hint names a lacking lobe too."""
    from irreflect.fitting.shape_hint import GENERIC_ADVICE, explained

    glossy = synthetic()  # terrazzo's coefficients: peaks at the mirror
    for model in ("single-lobe", "phong+background", "two-lobe"):
        exc = FitError(f"fit of '{model}' to t cannot beat a constant (R^2 = -0.1 <= 0): "
                       f"{GENERIC_ADVICE}")
        text = str(explained(exc, glossy))
        base = model.split("+")[0]
        assert f"e.g. --model {base}+background; or a lobe it lacks" in text, text
