"""Scenes: a rectangular room, optional boxes (furniture), materials, emitters, receivers.

A scene is a TOML file (see ``datasets/rooms/office.toml``) or built in Python. Coordinates
in metres with the origin at a floor corner: ``x`` in [0, size_x], ``y`` in [0, size_y],
``z`` in [0, height] (floor at z = 0). Angles in degrees. Bad input is refused with one line
saying what was expected, what was found and how to fix it.

Room faces are named ``floor``, ``ceiling``, ``wall_x0`` (x = 0), ``wall_x1`` (x = size_x),
``wall_y0``, ``wall_y1``; ``walls`` sets the four walls at once. A material is the name of a
``[materials.NAME]`` table, ``"lambertian(RHO)"``, or the path of a material file written by
``irreflect fit --save`` (relative to the scene file) that carries its reflectance.

Every key is checked against the declared schema :data:`SCENE_SCHEMA` (types, ranges,
finiteness, list sizes; :mod:`irreflect.schema`) before anything is built; the rules that tie
keys together follow (positions inside the room and outside boxes, emitters and receivers
facing into the room, no receiver at an emitter, no box filling the room, names that are
distinct, also as file names). A scene reads material files only inside its own folder
(or ``materials_dir``): a path that leaves it, also through a symlink, is refused before
anything is opened, with the same message whether or not the file exists.
"""

from __future__ import annotations

import difflib
import math
import os
from collections import Counter
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .. import schema as sc
from .._inputs import parse_toml, read_text
from ..errors import IrreflectError, SceneError
from ..validation import budget
from .materials import (
    BRDFS,
    REFLECTANCE,
    Material,
    from_model,
    lambertian,
    load_material,
    parse_lambertian,
    with_brdf,
)

ROOM_FACES = ("wall_x0", "wall_x1", "wall_y0", "wall_y1", "floor", "ceiling")
BOX_FACES = ("x0", "x1", "y0", "y1", "bottom", "top")
METHODS = ("recursive", "montecarlo")


@dataclass(frozen=True)
class Emitter:
    """A Lambertian source: position (m), unit pointing direction, order ``m`` (Eq. 2),
    optical power (W) and modulation frequency (Hz, 0 = none)."""

    name: str
    position: np.ndarray
    direction: np.ndarray
    order: float
    power_w: float = 1.0
    modulation_hz: float = 0.0


@dataclass(frozen=True)
class Receiver:
    """A photodetector: position (m), unit facing direction, area (m^2), field of view
    (deg, half angle), optical filter gain and concentrator gain (dimensionless)."""

    name: str
    position: np.ndarray
    direction: np.ndarray
    area_m2: float = 1e-4
    fov_deg: float = 90.0
    filter_gain: float = 1.0
    concentrator_gain: float = 1.0
    grid: str | None = None
    grid_index: tuple[int, int] | None = None

    @property
    def gain_area(self) -> float:
        return self.area_m2 * self.filter_gain * self.concentrator_gain


@dataclass(frozen=True)
class Box:
    """An axis-aligned box (furniture) with a material name per face (x0, x1, y0, y1, bottom, top)."""

    name: str
    lo: np.ndarray
    hi: np.ndarray
    materials: tuple[str, ...]


@dataclass(frozen=True)
class Grid:
    """A receiver grid on a horizontal plane (for maps)."""

    name: str
    z_m: float
    x_m: np.ndarray
    y_m: np.ndarray


@dataclass(frozen=True)
class Scene:
    """Everything a room simulation needs. ``materials`` maps names to 3D materials;
    ``room_materials`` names the material of each room face (order of :data:`ROOM_FACES`)."""

    name: str
    size: np.ndarray
    room_materials: tuple[str, ...]
    materials: dict[str, Material]
    emitters: tuple[Emitter, ...]
    receivers: tuple[Receiver, ...]
    boxes: tuple[Box, ...] = ()
    grids: tuple[Grid, ...] = ()
    settings: dict = field(default_factory=dict)
    path: str | None = None

    @property
    def diagonal(self) -> float:
        return float(np.linalg.norm(self.size))

    def with_materials(self, mapping: dict[str, Material], name: str | None = None) -> Scene:
        """The same scene with some materials replaced (by material name)."""
        mats = dict(self.materials)
        for key, mat in mapping.items():
            if key not in mats:
                raise IrreflectError(f"scene has no material '{key}'; it has {', '.join(mats)}")
            mats[key] = mat.renamed(key)
        return replace(self, materials=mats, name=name or self.name)

    def lambertian_equivalent(self) -> Scene:
        """Every material replaced by a Lambertian one of the same total reflectance (the
        reflectance under diffuse illumination when it varies with the angle of incidence)."""
        return self.with_materials(
            {k: lambertian(m.reflectance if m.reflectance is not None else m.diffuse_reflectance)
             for k, m in self.materials.items()}, name=f"{self.name} (Lambertian)")

    def with_brdf(self, brdf: str) -> Scene:
        """The same scene with every fitted material in surface model ``brdf``
        ("reciprocal" or "paper", see :mod:`.materials`)."""
        mats = {k: with_brdf(m, brdf) for k, m in self.materials.items()}
        settings = {k: v for k, v in self.settings.items() if k != "brdf"}
        return replace(self, materials=mats, settings=settings)

    def with_receivers(self, receivers, grids=()) -> Scene:
        return replace(self, receivers=tuple(receivers), grids=tuple(grids))

    def swapped(self, emitter_order: float = 1.0) -> Scene:
        """Emitter and (single) receiver exchanged (for reciprocity checks): the new emitter
        has Lambertian order ``emitter_order``; the new receiver has the old receiver's area
        and gains and a 90 deg field of view."""
        if len(self.emitters) != 1 or len(self.receivers) != 1:
            raise IrreflectError("swapped() needs exactly one emitter and one receiver")
        e, r = self.emitters[0], self.receivers[0]
        return replace(self, emitters=(Emitter("swapped", r.position, r.direction, emitter_order,
                                               e.power_w, e.modulation_hz),),
                       receivers=(Receiver("swapped", e.position, e.direction, r.area_m2, 90.0,
                                           r.filter_gain, r.concentrator_gain),))

    def material_list(self) -> tuple[list[str], list[Material]]:
        names = list(self.materials)
        return names, [self.materials[n] for n in names]


# ----------------------------------------------------------------------------- schema
#: Smallest and largest side of a room (m).
ROOM_SIDE_M = (0.01, 1000.0)
MAX_EMITTERS = 64
MAX_BOXES = 256
MAX_GRIDS = 32
#: Receivers per grid axis (the total over the scene is the ``receivers`` budget).
MAX_GRID_AXIS = 1000
#: Closest an emitter and a receiver may be (m): at the emitter the line of sight is undefined.
MIN_DISTANCE_M = 1e-3
#: A receiver closer to an emitter than this many radii of its collecting area (its area
#: times its filter and concentrator gains) is refused: the line-of-sight formula is a far
#: field one (at 2 mm a 1 cm^2 receiver read a gain of 7.96).
FAR_FIELD_RADII = 10.0
_TOL = 1e-9

_COORD = sc.Number(lo=-1e6, hi=1e6, unit="m")
_POINT = sc.Vector(3, item=_COORD, what="[x, y, z] in metres")
_DIRECTION = sc.Vector(3, nonzero=True, what="[x, y, z]",
                       fix="give the direction it faces, e.g. [0, 0, -1] for down")
_MATERIAL_REF = sc.Text(max_len=1024, what='a material name, "lambertian(RHO)" or a .json file')
_MATERIAL = sc.Table({
    "file": sc.Text(max_len=1024, what="a .json file name"),
    "lambertian": sc.Number(lo=0.0, hi=1.0),
    "model": sc.Text(max_len=100, what="a model name (see 'irreflect models')"),
    "params": sc.MapOf(keys=sc.Text(max_len=64, what="a parameter name"), values=sc.Number(),
                       max_items=64, what="a table NAME = VALUE"),
    "reflectance": REFLECTANCE,
    "gamma_max_deg": sc.Number(lo=0.0, hi=90.0, lo_open=True, unit="degrees"),
    "notes": sc.Text(max_len=10_000, multiline=True),
}, what="a table with file, lambertian or model + params")
_BOX_FACES = sc.Table({face: _MATERIAL_REF for face in ("x0", "x1", "y0", "y1", "bottom", "top",
                                                        "sides")})
_BOX = sc.Table({
    "name": sc.Name(), "min_m": _POINT, "max_m": _POINT,
    "material": sc.AnyOf(shape=lambda v: _BOX_FACES if isinstance(v, dict) else _MATERIAL_REF,
                         expected="a material, or a table of materials per face"),
}, required=("min_m", "max_m", "material"))
_EMITTER = sc.Table({
    "name": sc.Name(), "position_m": _POINT, "direction": _DIRECTION,
    "lambertian_order": sc.Number(lo=0.0, hi=1e4),
    "half_power_angle_deg": sc.Number(lo=1.0, hi=90.0, hi_open=True, unit="degrees"),
    "power_w": sc.Number(lo=0.0, hi=1e6, lo_open=True, unit="W"),
    "modulation_frequency_hz": sc.Number(lo=0.0, hi=1e12, unit="Hz"),
}, required=("position_m", "direction"),
    defaults={"power_w": 1.0, "modulation_frequency_hz": 0.0})
_RECEIVER_KEYS = {
    "direction": _DIRECTION,
    "area_m2": sc.Number(lo=0.0, hi=1.0, lo_open=True, unit="m^2"),
    "fov_deg": sc.Number(lo=0.0, hi=90.0, lo_open=True, unit="degrees"),
    "filter_gain": sc.Number(lo=0.0, hi=1e6, lo_open=True),
    "concentrator_gain": sc.Number(lo=0.0, hi=1e6, lo_open=True),
}
_RECEIVER_DEFAULTS = {"direction": [0, 0, 1], "area_m2": 1e-4, "fov_deg": 90.0,
                      "filter_gain": 1.0, "concentrator_gain": 1.0}
_RECEIVER = sc.Table({"name": sc.Name(), "position_m": _POINT, **_RECEIVER_KEYS},
                     required=("position_m",), defaults=_RECEIVER_DEFAULTS)
_RANGE = sc.Vector(2, item=sc.Number(lo=0.0, hi=ROOM_SIDE_M[1]), what="[min, max] in metres")
_GRID = sc.Table({
    "name": sc.Name(), "z_m": sc.Number(lo=0.0, hi=ROOM_SIDE_M[1], unit="m"),
    "x_m": _RANGE, "y_m": _RANGE,
    "n": sc.ListOf(sc.Integer(lo=1, hi=MAX_GRID_AXIS), min_items=2, max_items=2,
                   what="[nx, ny], two integers"),
    **_RECEIVER_KEYS,
}, required=("z_m", "n"), defaults=_RECEIVER_DEFAULTS)
_SIMULATION = sc.Table({
    "method": sc.Choice(options=METHODS), "bounces": sc.Integer(lo=0, hi=50),
    "cell_m": sc.Number(lo=0.0, hi=ROOM_SIDE_M[1], lo_open=True, unit="m"),
    "rays": sc.Integer(lo=1, hi=10**12), "seed": sc.Integer(lo=0, hi=2**63 - 1),
    "time_resolution_ns": sc.Number(lo=0.0, hi=1e6, lo_open=True, unit="ns"),
    "brdf": sc.Choice(options=BRDFS),
})


def _array(item, what, max_items, min_items=0):
    return sc.ListOf(item, min_items=min_items, max_items=max_items,
                     what=f"an array of tables [[{what}]]")


#: The declared schema of a scene file: every key, its type, range and default.
SCENE_SCHEMA = sc.Table({
    "scene": sc.Table({"name": sc.Name(), "notes": sc.Text(max_len=100_000, multiline=True)}),
    "room": sc.Table({
        "size_m": sc.Vector(3, item=sc.Number(lo=ROOM_SIDE_M[0], hi=ROOM_SIDE_M[1]),
                            what="[x, y, z] in metres"),
        "materials": sc.Table({face: _MATERIAL_REF for face in ROOM_FACES + ("walls",)}),
    }, required=("size_m", "materials")),
    "materials": sc.MapOf(keys=sc.Name(), values=_MATERIAL, max_items=256,
                          what="tables [materials.NAME]"),
    "box": _array(_BOX, "box", MAX_BOXES),
    "emitter": _array(_EMITTER, "emitter", MAX_EMITTERS, min_items=1),
    "receiver": _array(_RECEIVER, "receiver", 100_000),
    "receiver_grid": _array(_GRID, "receiver_grid", MAX_GRIDS),
    "simulation": _SIMULATION,
}, required=("room", "emitter"))


_ARRAYS = ("box", "emitter", "receiver", "receiver_grid")


# ----------------------------------------------------------------------------- reading
class _Ctx:
    """Where a scene came from: its file (messages), its folder (material files) and the
    folders material files may be read from."""

    def __init__(self, path, materials_dir=None):
        self.path = path
        self.base = Path(path).parent if path else Path.cwd()
        self.roots = [self.base] + ([Path(materials_dir)] if materials_dir is not None else [])
        self.schema = sc.Context(path, "toml", _ARRAYS, SceneError)

    def fail(self, key, msg: str):
        """``FILE: TABLE: msg`` (``key`` names the table or array item)."""
        self.schema.fail(tuple(key), msg)

    def fail_value(self, key, msg: str):
        """``FILE: TABLE: KEY: msg`` (``key`` names a value: its table, then its name)."""
        key = tuple(key)
        j = 2 if len(key) > 2 and isinstance(key[1], int) else len(key) - 1
        self.schema.fail(key[:j], f"{sc.dotted(key[j:])}: {msg}")


def load_scene(path, *, materials_dir=None) -> Scene:
    """Read and validate a scene TOML file (see the module docstring).

    ``materials_dir``: a folder from which material files may be read besides the scene's
    own folder. ``path`` may name a bundled scene (``"office"``), as on the command line.
    """
    from ..data import find_bundled

    path = find_bundled(path, "scene") or path
    try:
        _refuse_other_files(path, None)
        text = read_text(path, "scene", "a scene TOML file (see datasets/rooms/office.toml)",
                         fix="a scene is a few KB of text")
        _refuse_other_files(path, text)
        doc = parse_toml(text, str(path), "a scene TOML file")
    except SceneError:
        raise
    except IrreflectError as exc:
        raise SceneError(str(exc)) from None
    return scene_from_dict(doc, path=str(path), materials_dir=materials_dir)


def _is_scene(text: str) -> bool:
    try:
        return "room" in parse_toml(text, "scene", "a scene TOML file")
    except IrreflectError:
        return False


def _refuse_other_files(path, text: str | None) -> None:
    """A measurement table or a material file given where a scene is expected is named as
    what it is, with the way from it to a scene (not "not valid TOML" or "missing key
    'room'"). ``text`` None: judged by the name alone, before reading."""
    import re

    from ..data import BUNDLED_SCENES

    if not isinstance(path, str | os.PathLike):
        return
    suffix = Path(path).suffix.lower()
    first = text.lstrip().split("\n", 1)[0] if text else ""
    columns = {c.strip().strip('"').lower() for c in re.split(r"[,;\t|]", first)}
    expected = (f"expected a scene .toml file (see datasets/rooms/office.toml) or the name of "
                f"a bundled scene ({', '.join(BUNDLED_SCENES)})")
    if {"gamma_deg", "theta_deg"} <= columns or suffix in (".csv", ".parquet", ".pq"):
        if text is None and suffix == ".csv":
            return  # read first: its header says what it is
        if suffix == ".csv" and not {"gamma_deg", "theta_deg"} <= columns and _is_scene(text):
            return  # a scene named .csv: read as one
        what = ("a measurement table (columns gamma_deg, theta_deg, power)"
                if {"gamma_deg", "theta_deg"} <= columns
                else f"a{'n empty' if text is not None and not text.strip() else ''} "
                     f"{suffix} file (a measurement table?)")
        fix = ("to simulate its material" if {"gamma_deg", "theta_deg"} <= columns
               else "if it is a material's measurement table, to simulate the material")
        raise SceneError(f"{path}: is {what}, not a scene: {expected}; {fix}, fit it with "
                         f"'irreflect fit {path} --save MATERIAL.json' "
                         "and name MATERIAL.json in a scene's [materials.NAME] table "
                         "(file = \"MATERIAL.json\")")
    if text is not None and (suffix == ".json" or first.startswith("{")):  # never TOML
        raise SceneError(f"{path}: is JSON (a material file of 'irreflect fit --save'?), not a "
                         f"scene: {expected}; name the material file in a scene's "
                         f"[materials.NAME] table (file = \"{Path(path).name}\") and pass "
                         "the scene")


def scene_from_dict(doc: dict, path: str | None = None, *, materials_dir=None) -> Scene:
    """Build and validate a scene from the TOML structure (a dict): the schema first, then
    the rules that tie keys together (see the module docstring)."""
    if materials_dir is not None:
        _check_materials_dir(materials_dir)
    if not isinstance(path, str | os.PathLike | None):
        raise SceneError(f"path must be the scene file's path (or None); found {path!r}")
    ctx = _Ctx(path, materials_dir)
    doc = sc.validate(SCENE_SCHEMA, doc, path, "toml", _ARRAYS, SceneError)
    size = np.array(doc["room"]["size_m"])
    materials = _Materials(ctx, doc.get("materials", {}))
    faces = _room_faces(ctx, doc["room"]["materials"], materials)
    boxes = _boxes(ctx, doc.get("box", []), size, materials)
    emitters = _emitters(ctx, doc["emitter"], size, boxes)
    receivers, grids = _receivers(ctx, doc, size, boxes)
    _check_names(ctx, emitters, receivers, grids)
    _check_distances(ctx, emitters, receivers)
    info = doc.get("scene", {})
    name = info.get("name") or _default_name(path)
    return Scene(name=name, size=size, room_materials=tuple(faces),
                 materials=materials.table, emitters=tuple(emitters),
                 receivers=tuple(receivers), boxes=tuple(boxes), grids=tuple(grids),
                 settings=dict(doc.get("simulation", {})), path=path)


def _default_name(path) -> str:
    stem = Path(path).stem if path else "scene"
    return "".join(c if c.isalnum() or c in sc.NAME_PUNCTUATION else "_" for c in stem)[:64] \
        or "scene"


def _check_materials_dir(folder) -> None:
    if not isinstance(folder, str | os.PathLike) or not Path(folder).is_dir():
        raise SceneError(f"--materials-dir {folder}: expected an existing folder of "
                             "material files")


# ----------------------------------------------------------------------------- materials
class _Materials:
    """The scene's materials by name: its [materials.NAME] tables, then every
    "lambertian(RHO)" and .json file the faces name."""

    def __init__(self, ctx: _Ctx, specs: dict):
        self.ctx = ctx
        self.table: dict[str, Material] = {}
        for name, spec in specs.items():
            self.table[name] = _material(ctx, name, spec)

    def resolve(self, key, value: str) -> str:
        """The material name a face uses (adding lambertian(RHO) and files as needed)."""
        ctx = self.ctx
        if not value.strip():
            ctx.fail_value(key, 'material must be a name, "lambertian(RHO)" or a .json file; '
                          "found an empty name")
        if value in self.table:
            return value
        try:
            rho = parse_lambertian(value)
        except IrreflectError as exc:
            ctx.fail_value(key, str(exc))
        if rho is not None:
            name = f"lambertian({rho:g})"
            if name not in self.table:
                try:
                    self.table[name] = lambertian(rho, name=name)
                except IrreflectError as exc:
                    ctx.fail_value(key, str(exc))
            return name
        if value.lower().endswith(".json"):
            file = material_path(ctx, key, value)
            try:
                self.table[value] = load_material(file, name=value)
            except IrreflectError as exc:
                ctx.fail_value(key, str(exc))
            return value
        close = difflib.get_close_matches(value, list(self.table), n=1)
        hint = f"did you mean '{close[0]}'?" if close else (
            f"define it in [materials.{value}] or use lambertian(RHO)")
        ctx.fail_value(key, f"unknown material '{value}': {hint}")
        return value  # unreachable


def material_path(ctx: _Ctx, key, value: str) -> Path:
    """The path of a material file named by a scene, refused (before anything is opened,
    with one message whether or not it exists) when it leaves the scene's folder and
    ``materials_dir``, by an absolute path, '..' or a symlink."""
    candidate = Path(value) if Path(value).is_absolute() else ctx.base / value
    lexical = Path(os.path.normpath(candidate.absolute()))
    real = Path(os.path.realpath(candidate))
    for root in ctx.roots:
        inside_lexically = _within(lexical, Path(os.path.normpath(root.absolute())))
        if inside_lexically and _within(real, Path(os.path.realpath(root))):
            return candidate
    folders = " or ".join(f"'{r}'" for r in ctx.roots)
    ctx.fail_value(key, f"material file '{value}' is outside the scene's folder {folders}: a scene "
                  "reads material files only from its own folder; copy the file there, or "
                  "allow another folder with 'irreflect room --materials-dir DIR' "
                  "(load_scene(path, materials_dir=DIR))")
    return candidate  # unreachable


def _within(path: Path, root: Path) -> bool:
    return path == root or root in path.parents


def _material(ctx: _Ctx, name: str, spec: dict) -> Material:
    key = ("materials", name)
    kinds = [k for k in ("file", "lambertian", "model") if k in spec]
    if len(kinds) != 1:
        ctx.fail(key, 'give exactly one of file = "MATERIAL.json", lambertian = RHO, or '
                      'model = "NAME" with params = {...}')
    try:
        if "file" in spec:
            file = material_path(ctx, (*key, "file"), spec["file"])
            return load_material(file, name=name, reflectance=spec.get("reflectance"))
        if "lambertian" in spec:
            return lambertian(spec["lambertian"], name=name)
        if "params" not in spec:
            ctx.fail(key, "model needs params = {NAME = VALUE, ...} (see 'irreflect models')")
        if "reflectance" not in spec:
            ctx.fail(key, 'give reflectance = RHO (total reflectance, 0..1) or "K"')
        # a coefficient outside the model's bounds: refused by from_model unless the model
        # then predicts negative power (unphysical: refused by irreflect room unless
        # --allow-unphysical), as for a material file
        return from_model(spec["model"], spec["params"], spec["reflectance"], name=name,
                          source=f"{spec['model']} (scene)",
                          gamma_max_deg=spec.get("gamma_max_deg"))
    except SceneError:
        raise
    except IrreflectError as exc:
        if ctx.path and str(exc).startswith(str(ctx.path)):
            raise
        ctx.fail(key, str(exc))
        raise  # unreachable


# ----------------------------------------------------------------------------- geometry
def _room_faces(ctx: _Ctx, spec: dict, materials: _Materials) -> list[str]:
    faces = []
    for face in ROOM_FACES:
        given = face if face in spec or not face.startswith("wall") else "walls"
        if given not in spec:
            ctx.fail(("room", "materials"), f"no material for the {face}: set '{face}'"
                     + (" or 'walls'" if face.startswith("wall") else ""))
        faces.append(materials.resolve(("room", "materials", given), spec[given]))
    return faces


def _inside(ctx, key, name, pos, size):
    if np.any(pos < -_TOL) or np.any(pos > size + _TOL):
        ctx.fail(key, f"{name} {list(map(float, pos))} is outside the room [0..{size[0]:g}, "
                      f"0..{size[1]:g}, 0..{size[2]:g}]: move it inside")


def _boxes(ctx: _Ctx, specs: list, size, materials: _Materials) -> list[Box]:
    boxes = []
    for i, b in enumerate(specs):
        key = ("box", i)
        lo, hi = np.array(b["min_m"]), np.array(b["max_m"])
        if np.any(hi <= lo):
            ctx.fail(key, f"max_m must exceed min_m on every axis; found min {lo.tolist()} "
                          f"max {hi.tolist()}")
        _inside(ctx, key, "min_m", lo, size)
        _inside(ctx, key, "max_m", hi, size)
        if np.all(lo <= _TOL) and np.all(hi >= size - _TOL):
            ctx.fail(key, "the box fills the whole room: nothing is left to light; make it "
                          "smaller than the room")
        names = _box_materials(ctx, key, b["material"], materials)
        boxes.append(Box(b.get("name", f"box{i + 1}"), lo, hi, tuple(names)))
    for j, c in enumerate(boxes):
        for a in boxes[:j]:
            if np.all(a.lo < c.hi) and np.all(c.lo < a.hi):
                ctx.fail(("box", j), f"box '{c.name}' overlaps box '{a.name}': boxes must not "
                                     "overlap (split or move them)")
    return boxes


def _box_materials(ctx, key, spec, materials: _Materials) -> list[str]:
    if not isinstance(spec, dict):
        return [materials.resolve((*key, "material"), spec)] * 6
    names = []
    for face in BOX_FACES:
        value = spec.get(face, spec.get("sides") if face[0] in "xy" else None)
        if value is None:
            ctx.fail(key, f"material has no entry for face '{face}'")
        names.append(materials.resolve((*key, "material", face), value))
    return names


def _check_placement(ctx, key, pos, direction, size, boxes, what: str, fov_deg=90.0) -> None:
    """``pos`` inside the room and not inside a box, and ``direction`` not turned away
    from the room by the wall, floor, ceiling or box face it sits on (an emitter pointing
    straight into it sends nothing into the room; a receiver turned away by more than its
    field of view receives nothing)."""
    _inside(ctx, key, "position_m", pos, size)
    for b in boxes:
        if np.all(pos > b.lo + _TOL) and np.all(pos < b.hi - _TOL):
            ctx.fail(key, f"position {list(map(float, pos))} is inside box '{b.name}': move it "
                          "onto or out of the box")
    # what a source or detector on this surface must not face: cos(angle to the normal
    # into the room) at most this
    worst = -1.0 + 1e-9 if what == "emitter" else -math.sin(math.radians(fov_deg)) + 1e-9
    for surface, normal in _surfaces_at(pos, size, boxes):
        if float(direction @ normal) <= worst:
            ctx.fail(key, f"the {what} sits on {surface} and faces into it, so no light "
                          f"{'leaves it' if what == 'emitter' else 'reaches it'}: turn its "
                          f"direction into the room, e.g. direction = "
                          f"{[int(v) for v in normal]}")


_FACE_NAMES = (("the wall x = 0", "the wall x = size_x"), ("the wall y = 0", "the wall y = size_y"),
               ("the floor", "the ceiling"))


def _surfaces_at(pos, size, boxes):
    """(name, unit normal into the room) of every room or box face ``pos`` lies on."""
    for axis in range(3):
        normal = np.zeros(3)
        normal[axis] = 1.0
        if abs(pos[axis]) <= _TOL:
            yield _FACE_NAMES[axis][0], normal
        if abs(pos[axis] - size[axis]) <= _TOL:
            yield _FACE_NAMES[axis][1], -normal
        for b in boxes:
            if not _strictly_within(pos, b, axis):
                continue
            if abs(pos[axis] - b.lo[axis]) <= _TOL:
                yield f"a face of box '{b.name}'", -normal
            if abs(pos[axis] - b.hi[axis]) <= _TOL:
                yield f"a face of box '{b.name}'", normal


def _strictly_within(pos, box: Box, axis: int) -> bool:
    """``pos`` lies inside the face of ``box`` normal to ``axis`` (not on its edge)."""
    others = [a for a in range(3) if a != axis]
    return all(box.lo[a] + _TOL < pos[a] < box.hi[a] - _TOL for a in others)


def _emitters(ctx: _Ctx, specs: list, size, boxes) -> list[Emitter]:
    emitters = []
    for i, e in enumerate(specs):
        key = ("emitter", i)
        pos, direction = np.array(e["position_m"]), _unit(e["direction"])
        _check_placement(ctx, key, pos, direction, size, boxes, "emitter")
        if ("lambertian_order" in e) == ("half_power_angle_deg" in e):
            ctx.fail(key, "give exactly one of lambertian_order (1 = Lambertian) or "
                          "half_power_angle_deg (60 = Lambertian)")
        order = e.get("lambertian_order")
        if order is None:  # Eq. 3; the schema keeps the angle within [1, 90) degrees
            order = -math.log(2) / math.log(math.cos(math.radians(e["half_power_angle_deg"])))
        emitters.append(Emitter(e.get("name", f"emitter{i + 1}"), pos, direction, float(order),
                                e["power_w"], e["modulation_frequency_hz"]))
    return emitters


def _unit(vector) -> np.ndarray:
    """A direction scaled to unit length (scaled by its largest component first, so that
    neither 1e308 nor 1e-320 components overflow or vanish)."""
    v = np.array(vector, float)
    v = v / np.max(np.abs(v))
    return v / np.linalg.norm(v)


def _receivers(ctx: _Ctx, doc: dict, size, boxes):
    specs, grid_specs = doc.get("receiver", []), doc.get("receiver_grid", [])
    total = len(specs) + sum(g["n"][0] * g["n"][1] for g in grid_specs)
    limit = budget("receivers")
    if total > limit:
        ctx.fail(("receiver_grid",) if grid_specs else ("receiver",),
                 f"{total} receivers is more than this machine's budget of {limit:,.0f} "
                 "receivers per scene: use fewer grid points (n = [nx, ny]) or receivers "
                 "(or raise the budget: IRREFLECT_BUDGET_RECEIVERS=N)")
    receivers = []
    for i, r in enumerate(specs):
        key = ("receiver", i)
        pos, common = np.array(r["position_m"]), _rx_common(r)
        _check_placement(ctx, key, pos, common[0], size, boxes, "receiver", r["fov_deg"])
        receivers.append(Receiver(r.get("name", f"rx{i + 1}"), pos, *common))
    grids = []
    for i, g in enumerate(grid_specs):
        grid, members = _grid(ctx, i, g, size, boxes)
        grids.append(grid)
        receivers.extend(members)
    if not receivers:
        ctx.fail((), "the scene needs at least one [[receiver]] or [[receiver_grid]] (with a "
                     "point outside the boxes)")
    return receivers, grids


def _rx_common(r: dict):
    return (_unit(r["direction"]), r["area_m2"], r["fov_deg"], r["filter_gain"],
            r["concentrator_gain"])


def _grid(ctx: _Ctx, i: int, g: dict, size, boxes):
    key = ("receiver_grid", i)
    name = g.get("name", f"grid{i + 1}")
    z = g["z_m"]
    if z > size[2] + _TOL:
        ctx.fail(key, f"z_m {z:g} is above the ceiling ({size[2]:g} m): move the grid inside")
    nx, ny = g["n"]
    xs = _span(ctx, key, "x_m", g.get("x_m", (0.0, float(size[0]))), float(size[0]), nx)
    ys = _span(ctx, key, "y_m", g.get("y_m", (0.0, float(size[1]))), float(size[1]), ny)
    common = _rx_common(g)
    members = []
    for iy, y in enumerate(ys):
        for ix, x in enumerate(xs):
            pos = np.array([x, y, z])
            if any(np.all(pos > b.lo - _TOL) and np.all(pos < b.hi + _TOL) for b in boxes):
                continue  # inside furniture: no receiver there (a gap in the map)
            members.append(Receiver(f"{name}[{ix},{iy}]", pos, *common, grid=name,
                                    grid_index=(ix, iy)))
    corners = {(0, 0), (nx - 1, 0), (0, ny - 1), (nx - 1, ny - 1)}
    for m in members:  # the grid's extreme points: on a wall if any point is
        if m.grid_index in corners:
            _check_placement(ctx, key, m.position, common[0], size, (), "receiver grid",
                             g["fov_deg"])
    return Grid(name, z, xs, ys), members


def _span(ctx, key, name, value, top, n):
    lo, hi = value
    if not (0 <= lo <= hi <= top + _TOL):
        ctx.fail(key, f"{name} must satisfy 0 <= min <= max <= {top:g}; found "
                      f"[{lo:g}, {hi:g}]")
    if n == 1:
        return np.array([(lo + hi) / 2])
    if hi - lo <= _TOL:
        ctx.fail(key, f"{name} spans [{lo:g}, {hi:g}], a single point, with {n} receivers "
                      f"along it: they would all stand at one spot; widen {name} or set that "
                      "axis's count in n to 1")
    return np.linspace(lo, hi, n)


# ----------------------------------------------------------------------------- cross-checks
def _check_names(ctx: _Ctx, emitters, receivers, grids) -> None:
    """Distinct names, also as file names (figures are named after emitters, receivers and
    grids: 'a b' and 'a_b' would overwrite each other's)."""
    from .results import safe_name

    for what, key, names in (("emitter", "emitter", [e.name for e in emitters]),
                             ("receiver", "receiver", [r.name for r in receivers]),
                             ("grid", "receiver_grid", [g.name for g in grids])):
        counts = Counter(names)
        dup = next((n for n, k in counts.items() if k > 1), None)
        if dup is not None:
            ctx.fail((key,), f"{what} names must be distinct; '{dup}' is used "
                             f"{counts[dup]} times: rename them")
        files: dict[str, str] = {}
        for n in names:
            stem = safe_name(n).lower()
            if stem in files:
                ctx.fail((key,), f"{what} names '{files[stem]}' and '{n}' give the same file "
                                 f"name '{safe_name(n)}' (figures would overwrite each other): "
                                 "rename one")
            files[stem] = n
    single = {r.name for r in receivers if r.grid is None}
    both = sorted(single & {g.name for g in grids})
    if both:  # the results name both alike: which is which?
        ctx.fail(("receiver_grid",), f"grid '{both[0]}' has the name of a receiver: a receiver "
                                     "and a grid must not share a name (rows and figures are "
                                     "named after both): rename one")


def _check_distances(ctx: _Ctx, emitters, receivers) -> None:
    """No receiver at an emitter (the line of sight would be undefined)."""
    if not emitters or not receivers:
        return
    pos_r = np.array([r.position for r in receivers])
    gain_area = np.array([r.gain_area for r in receivers])
    for i, e in enumerate(emitters):
        d = np.linalg.norm(pos_r - e.position, axis=1)
        j = int(np.argmin(d))
        if d[j] < MIN_DISTANCE_M:
            ctx.fail(("emitter", i), f"receiver '{receivers[j].name}' is at emitter '{e.name}' "
                                     f"(distance {d[j]:.3g} m, less than {MIN_DISTANCE_M:g} m): "
                                     "the line of sight is undefined; move one of them")
            continue
        # the far field of the line-of-sight formula (Eq. 1): the receiver well beyond its
        # own size, and a gain that cannot pass 1 even on the beam's axis
        near = np.maximum(FAR_FIELD_RADII * np.sqrt(gain_area / np.pi),
                          np.sqrt((e.order + 1.0) * gain_area / (2.0 * np.pi)))
        k = int(np.argmax(near - d))
        if d[k] < near[k]:
            ctx.fail(("emitter", i),
                     f"receiver '{receivers[k].name}' is {d[k]:.3g} m from emitter '{e.name}', "
                     f"closer than {near[k]:.3g} m ({FAR_FIELD_RADII:g} times the radius of its "
                     "collecting area, gains included): the far-field line-of-sight formula "
                     "does not hold there (it can give a gain above 1); move them apart")


__all__ = ["Scene", "Emitter", "Receiver", "Box", "Grid", "load_scene", "scene_from_dict",
           "SCENE_SCHEMA", "ROOM_FACES", "BOX_FACES", "METHODS"]
