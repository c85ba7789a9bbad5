"""Property tests of the files a run reads besides tables: room scenes, material files and
selection checkpoints (tables and options: test_fuzz_cli.py; one case at a time:
test_hostile.py; a longer run of every command: experiments/fuzz_inputs.py).

Each test starts from a valid document and applies one to three random mutations
(hypothesis, derandomized): a value replaced by junk of another type or out of range (NaN,
infinities, 1e300, 10**400, booleans, text, lists, tables, deep nesting), a key deleted, an
unknown key added, a list item duplicated, bytes of the file flipped or cut. The property:
the reader returns an object that satisfies the documented invariants, or raises a
one-line :class:`~irreflect.errors.IrreflectError` that names the file; never another
exception. Mutations that break a documented rule (a required key deleted, an unknown key,
a boolean or NaN where a number goes, an edited checkpoint) must be refused: no silent
accept.
"""

from __future__ import annotations

import copy
import json
import math
import os
import shutil
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w
from conftest import synthetic
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from irreflect.data import bundled_dir
from irreflect.errors import IrreflectError

ROOMS = bundled_dir() / "rooms"
#: Examples per property (IRREFLECT_FUZZ_EXAMPLES raises it for a longer local run).
EXAMPLES = int(os.environ.get("IRREFLECT_FUZZ_EXAMPLES", "60"))
FUZZ = settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.function_scoped_fixture])

# ----------------------------------------------------------------------------- mutations
JUNK = st.one_of(
    st.booleans(),
    st.integers(-(10**30), 10**30),
    st.sampled_from([10**400, -(10**400), 2**63, 0, -1]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([1e300, -1e300, 1e-300, 5e-324, math.nan, math.inf, -math.inf]),
    st.text(max_size=12),
    st.sampled_from(["$\\frac{$", "../../etc/passwd", "/dev/zero", "", " ", "a\x00b",
                     "lambertian(2)", "lambertian(nan)", "x.json"]),
    st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=4),
    st.lists(st.integers(-3, 3), max_size=4),
    st.dictionaries(st.text(max_size=4), st.integers(), max_size=2),
    st.just([[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[1]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]),
)


def _paths(doc, prefix=()):
    """Every key path of a document (tables and lists, and their leaves)."""
    out = []
    items = doc.items() if isinstance(doc, dict) else enumerate(doc) \
        if isinstance(doc, list) else ()
    for key, value in items:
        out.append((*prefix, key))
        out.extend(_paths(value, (*prefix, key)))
    return out


def _get(doc, path):
    for key in path:
        doc = doc[key]
    return doc


def _is_number(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


@st.composite
def mutated(draw, base: dict, required: frozenset, nan_ok=frozenset()):
    """(document, must_refuse, what): ``base`` with one to three mutations. ``nan_ok``: the
    keys (generic paths) whose numbers may be NaN or infinite. ``must_refuse``: a mutation
    that breaks a documented rule is still in the final document."""
    doc = copy.deepcopy(base)
    marks, done = [], []  # (kind, path, object) of rule-breaking mutations
    for _ in range(draw(st.integers(1, 3))):
        paths = _paths(doc)
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent, key = _get(doc, path[:-1]), path[-1]
        old = parent[key]
        kind = draw(st.sampled_from(["junk", "junk", "delete", "unknown", "scale",
                                     "duplicate"]))
        if kind == "junk":
            new = copy.deepcopy(draw(JUNK))  # never the same object twice
            parent[key] = new
            nonfinite = isinstance(new, float) and not math.isfinite(new)
            try:  # the rules are those of the key in the valid document
                orig = _get(base, path)
            except (KeyError, IndexError, TypeError):
                orig = None
            breaks = (_is_number(orig) and (isinstance(new, bool | str | list | dict) or (
                nonfinite and _generic(path)[:1] not in nan_ok))) or (
                isinstance(orig, str) and not isinstance(new, str))
            if breaks:
                marks.append(("junk", path, new))
        elif kind == "delete" and isinstance(parent, dict):
            del parent[key]
            if _generic(path) in required:
                marks.append(("delete", path, None))
        elif kind == "unknown" and isinstance(old, dict):
            name = draw(st.sampled_from(["colour", "positon_m", "reflectence", "x"]))
            old[name] = 1
            marks.append(("unknown", (*path, name), old))
        elif kind == "scale" and _is_number(old):
            factor = draw(st.sampled_from([-1, 0, 1e-300, 1e300, 10**400]))
            try:
                parent[key] = old * factor
            except OverflowError:  # a float times 10**400
                parent[key] = math.inf if old > 0 else -math.inf if old < 0 else 0.0
        elif kind == "duplicate" and isinstance(parent, list):
            parent.append(copy.deepcopy(old))
        else:
            continue
        shown = f" = {parent[key]!r:.30}" if kind in ("junk", "scale") else ""
        done.append(f"{kind} {'.'.join(map(str, path))}{shown}")
    return doc, any(_still_there(doc, mark) for mark in marks), "; ".join(done)


def _still_there(doc, mark) -> bool:
    """Whether a rule-breaking mutation survived the later ones."""
    kind, path, obj = mark
    try:
        parent = _get(doc, path[:-1])
    except (KeyError, IndexError, TypeError):
        return False
    if kind == "delete":
        return isinstance(parent, dict) and path[-1] not in parent
    if kind == "unknown":
        return parent is obj and path[-1] in parent
    try:
        return parent[path[-1]] is obj
    except (KeyError, IndexError, TypeError):
        return False


def _generic(path) -> tuple:
    """A key path with list indices replaced by '*' (to compare with the required keys)."""
    return tuple("*" if isinstance(k, int) else k for k in path)


def _assert_one_line(exc: BaseException, source) -> None:
    text = str(exc)
    assert "\n" not in text and text.strip(), text
    assert str(source) in text, text


# ----------------------------------------------------------------------------- scenes
OFFICE = tomllib.loads((ROOMS / "office.toml").read_text())
SCENE_REQUIRED = frozenset({
    ("room",), ("emitter",), ("room", "size_m"), ("room", "materials"),
    ("emitter", "*", "position_m"), ("emitter", "*", "direction"),
    ("receiver", "*", "position_m"), ("receiver_grid", "*", "z_m"), ("receiver_grid", "*", "n"),
    ("box", "*", "min_m"), ("box", "*", "max_m"), ("box", "*", "material"),
    ("materials", "plasterboard"), ("materials", "foam_board"), ("materials", "terrazzo"),
    ("materials", "plasterboard", "file"), ("materials", "terrazzo", "file"),
    ("materials", "foam_board", "file"), ("materials", "wood", "lambertian"),
    ("room", "materials", "walls"), ("room", "materials", "floor"),
    ("room", "materials", "ceiling"),
})


@pytest.fixture(scope="module")
def scene_dir(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("scene")
    for f in ROOMS.glob("*.json"):
        shutil.copy(f, folder / f.name)
    return folder


def _check_scene(scene) -> None:
    """The invariants of a scene that loaded."""
    from irreflect.room.results import safe_name
    from irreflect.validation import budget

    size = scene.size
    assert np.all(np.isfinite(size)) and np.all(size > 0)
    for group in (scene.emitters, scene.receivers):
        names = [x.name for x in group]
        assert len(set(names)) == len(names)
        assert len({safe_name(n).lower() for n in names}) == len(names)
        for x in group:
            assert "$" not in x.name
            assert np.all(np.isfinite(x.position)) and np.all(x.position >= -1e-9)
            assert np.all(x.position <= size + 1e-9)
            assert abs(np.linalg.norm(x.direction) - 1) < 1e-9
    for e in scene.emitters:
        assert 0 < e.power_w <= 1e6 and math.isfinite(e.order) and e.order >= 0
        d = np.linalg.norm(np.array([r.position for r in scene.receivers]) - e.position, axis=1)
        assert d.min() >= 1e-3
    for r in scene.receivers:
        assert 0 < r.fov_deg <= 90 and 0 < r.gain_area < math.inf
    assert len(scene.receivers) <= budget("receivers")
    for m in scene.materials.values():
        assert np.all(np.isfinite(m.rho_table)) and np.all((m.rho_table >= 0) & (m.rho_table <= 1))
        assert np.all(np.isfinite(m.norm_table)) and np.all(m.norm_table >= 0)
    for key, value in scene.settings.items():
        assert not isinstance(value, bool) and (isinstance(value, str) or math.isfinite(value)), key


@FUZZ
@given(case=mutated(OFFICE, SCENE_REQUIRED))
def test_mutated_scenes_load_validly_or_are_refused_in_one_line(scene_dir, case):
    from irreflect.room import load_scene, scene_from_dict

    doc, must_refuse, what = case
    path = scene_dir / "office.toml"
    try:
        scene = scene_from_dict(copy.deepcopy(doc), path=str(path))
    except IrreflectError as exc:
        _assert_one_line(exc, path)
        refused = str(exc)
    else:
        assert not must_refuse, f"silently accepted: {what}"
        _check_scene(scene)
        refused = None
    # the same document as a TOML file: the same verdict (when TOML can hold it)
    try:
        text = tomli_w.dumps(doc)
    except (TypeError, ValueError):
        return
    path.write_text(text)
    try:
        load_scene(path)
        assert refused is None, f"the file was accepted, the dict refused: {refused}"
    except IrreflectError as exc:
        _assert_one_line(exc, path)
        assert refused is not None, f"the dict was accepted, the file refused: {exc}"


@FUZZ
@given(data=st.binary(max_size=300), cut=st.integers(0, 2000))
def test_damaged_scene_files_are_refused_in_one_line(scene_dir, data, cut):
    from irreflect.room import load_scene

    text = (ROOMS / "office.toml").read_bytes()
    path = scene_dir / "damaged.toml"
    path.write_bytes(text[:cut] + data + text[cut:])
    try:
        _check_scene(load_scene(path))
    except IrreflectError as exc:
        _assert_one_line(exc, path)


# ----------------------------------------------------------------------------- material files
MATERIAL = json.loads((ROOMS / "terrazzo.json").read_text()) | {"reflectance": 0.3}
MATERIAL_REQUIRED = frozenset({("format",), ("format_version",), ("model",), ("params",),
                               ("params", "u_as"), ("params", "v_as"), ("params", "u_nd"),
                               ("params", "v_nd"), ("params", "u_ns"), ("params", "v_ns"),
                               ("params", "K"), ("reflectance",)})


def _check_material(mat) -> None:
    from irreflect.models import get_model

    model = get_model(mat.model)
    outside = [p.name for p in model.params
               if not p.lower - 1e-6 <= mat.params[p.name] <= p.upper + 1e-6]
    # a coefficient outside its bounds is kept only when it makes the model predict negative
    # power: the material is then marked unphysical (irreflect room refuses it unless
    # --allow-unphysical)
    assert not outside or "predicts negative power" in mat.metadata.get("unphysical", ""), \
        outside
    assert np.all(np.isfinite(mat.rho_table)) and np.all((mat.rho_table >= 0)
                                                          & (mat.rho_table <= 1 + 1e-9))
    assert np.all(np.isfinite(mat.norm_table))


@FUZZ
@given(case=mutated(MATERIAL, MATERIAL_REQUIRED,
                   nan_ok=frozenset({("stderr",), ("r2",), ("rmse",)})))
def test_mutated_material_files_load_validly_or_are_refused_in_one_line(tmp_path, case):
    from irreflect.room import load_material

    doc, must_refuse, what = case
    path = tmp_path / "m.json"
    try:
        path.write_text(json.dumps(doc))
    except ValueError:  # a value JSON cannot hold
        return
    try:
        mat = load_material(path)
    except IrreflectError as exc:
        _assert_one_line(exc, path)
    else:
        assert not must_refuse, f"silently accepted: {what}"
        _check_material(mat)


# ----------------------------------------------------------------------------- checkpoints
@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    from irreflect.selection import run_selection

    folder = tmp_path_factory.mktemp("ckpt")
    meas = synthetic(noise=0.004, seed=3, name="noisy")
    path = folder / "run.ckpt"
    run_selection(meas, pop_size=8, generations=2, max_points=14, seed=1, checkpoint=path,
                  checkpoint_every=1)
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays["meta"]))
    return meas, path.read_bytes(), arrays, meta


ARRAY_DAMAGE = ["nan", "negative", "truncate", "extend", "dtype", "transpose", "zero"]


@st.composite
def checkpoint_damage(draw, names):
    kind = draw(st.sampled_from(["meta", "array", "array+digest", "bytes"]))
    if kind == "meta":
        return kind, draw(st.sampled_from(["junk", "delete", "unknown"])), \
            copy.deepcopy(draw(JUNK)), None
    if kind == "bytes":
        return kind, draw(st.integers(0, 10**6)), draw(st.binary(min_size=1, max_size=16)), \
            draw(st.booleans())
    return kind, draw(st.sampled_from(names)), draw(st.sampled_from(ARRAY_DAMAGE)), None


def _damage_array(arr: np.ndarray, how: str) -> np.ndarray:
    arr = arr.copy()
    if how == "nan" and arr.dtype.kind == "f" and arr.size:
        arr.flat[0] = np.nan
    elif how == "negative" and arr.dtype.kind in "fi" and arr.size:
        arr.flat[0] = -5
    elif how == "truncate" and arr.ndim and len(arr):
        arr = arr[:-1]
    elif how == "extend" and arr.ndim:
        arr = np.concatenate([arr, arr[:1]]) if len(arr) else arr
    elif how == "dtype":
        arr = arr.astype(np.float32 if arr.dtype.kind != "f" else np.int8)
    elif how == "transpose" and arr.ndim == 2:
        arr = arr.T.copy()
    elif how == "zero":
        arr = np.zeros_like(arr)
    return arr


@settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_damaged_checkpoints_are_refused_in_one_line(checkpoint, tmp_path, data):
    from irreflect.selection.checkpoint import _digest, load_checkpoint

    meas, raw, arrays, meta = checkpoint
    names = sorted(k for k in arrays if k != "meta")
    kind, where, how, extra = data.draw(checkpoint_damage(names))
    path = tmp_path / "run.ckpt"
    arrays = dict(arrays)
    meta = copy.deepcopy(meta)
    must_refuse = True
    if kind == "bytes":  # the zip's own fields may change harmlessly: checked below
        pos = where % len(raw)
        damaged = raw[:pos] + how + raw[pos + len(how):] if extra else raw[:pos]
        must_refuse = False
        path.write_bytes(damaged)
    else:
        if kind == "meta":
            key = data.draw(st.sampled_from([p for p in _paths(meta) if p[0] != "digest"]))
            parent = _get(meta, key[:-1])
            if where == "junk":
                must_refuse = json.dumps(parent[key[-1]]) != json.dumps(how)
                parent[key[-1]] = how
            elif where == "delete":
                del parent[key[-1]]
            elif isinstance(parent, dict):
                parent["surplus"] = 1
        else:
            arrays[where] = _damage_array(arrays[where], how)
            before = checkpoint[2][where]
            unchanged = (arrays[where].dtype == before.dtype
                         and arrays[where].shape == before.shape
                         and arrays[where].tobytes() == before.tobytes())
            if kind == "array+digest":
                meta["digest"] = _digest(arrays, meta)
                must_refuse = False  # a consistent edit may be valid; it must not crash
            else:
                must_refuse = not unchanged
        arrays["meta"] = np.array(json.dumps(meta))
        with open(path, "wb") as fh:
            np.savez(fh, **arrays)
    try:
        state = load_checkpoint(path, checkpoint[3]["fingerprint"], meas.n_points, 5)
    except IrreflectError as exc:
        _assert_one_line(exc, path)
    else:
        assert not must_refuse, f"silently accepted: {kind} {where} {how!r}"
        assert state["pop_X"].shape[1] == meas.n_points
        assert np.all(np.isfinite(state["cache_scores"]))
        if kind == "bytes":  # accepted: then what it holds is what was written
            for name, arr in checkpoint[2].items():
                if name != "meta":
                    assert state[name].tobytes() == arr.tobytes(), name


def test_a_checkpoint_edited_consistently_still_resumes_or_is_refused(checkpoint, tmp_path):
    """Resuming goes through restore(): a checkpoint that passes the loader resumes."""
    from irreflect.selection import run_selection

    meas, raw, arrays, meta = checkpoint
    path = tmp_path / "run.ckpt"
    path.write_bytes(raw)
    result = run_selection(meas, pop_size=8, generations=3, max_points=14, seed=1,
                           checkpoint=path)
    assert result.settings["resumed_from_generation"] == 2
