"""Scenes: a rectangular room, optional boxes (furniture), materials, emitters, receivers.

A scene is a TOML file (see ``datasets/rooms/office.toml``) or built in Python. Coordinates
in metres with the origin at a floor corner: ``x`` in [0, size_x], ``y`` in [0, size_y],
``z`` in [0, height] (floor at z = 0). Angles in degrees. Bad input is refused with one line
saying what was expected, what was found and how to fix it.

Room faces are named ``floor``, ``ceiling``, ``wall_x0`` (x = 0), ``wall_x1`` (x = size_x),
``wall_y0``, ``wall_y1``; ``walls`` sets the four walls at once. A material is the name of a
``[materials.NAME]`` table, ``"lambertian(RHO)"``, or the path of a material file written by
``irreflect fit --save`` (relative to the scene file) that carries its reflectance.
"""

from __future__ import annotations

import difflib
import math
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import IrreflectError
from .materials import (
    BRDFS,
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


# ----------------------------------------------------------------------------- parsing
class _Ctx:
    def __init__(self, path):
        self.path = path
        self.base = Path(path).parent if path else Path.cwd()

    def fail(self, where: str, msg: str):
        prefix = f"{self.path}: " if self.path else ""
        raise IrreflectError(f"{prefix}{where}: {msg}")


def _number(ctx, where, key, value, *, lo=None, hi=None, lo_open=False, positive=False):
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        ctx.fail(where, f"{key} must be a finite number; found {value!r}")
    value = float(value)
    if positive and value <= 0:
        ctx.fail(where, f"{key} must be > 0; found {value:g}")
    if lo is not None and (value < lo or (lo_open and value == lo)):
        ctx.fail(where, f"{key} must be {'>' if lo_open else '>='} {lo:g}; found {value:g}")
    if hi is not None and value > hi:
        ctx.fail(where, f"{key} must be <= {hi:g}; found {value:g}")
    return value


def _vector(ctx, where, key, value, *, unit=False):
    if (not isinstance(value, list) or len(value) != 3
            or not all(isinstance(v, int | float) and not isinstance(v, bool)
                       and math.isfinite(v) for v in value)):
        ctx.fail(where, f"{key} must be 3 numbers [x, y, z]; found {value!r}")
    vec = np.array(value, float)
    if unit:
        norm = np.linalg.norm(vec)
        if norm == 0:
            ctx.fail(where, f"{key} must not be [0, 0, 0]: give the direction it faces, "
                            "e.g. [0, 0, -1] for down")
        vec = vec / norm
    return vec


def _check_keys(ctx, where, table, allowed, required=()):
    if not isinstance(table, dict):
        ctx.fail(where, f"expected a table of keys; found {table!r}")
    for key in required:
        if key not in table:
            ctx.fail(where, f"missing key '{key}' (expected {', '.join(required)})")
    unknown = [k for k in table if k not in allowed]
    if unknown:

        close = difflib.get_close_matches(unknown[0], allowed, n=1)
        hint = f"; did you mean '{close[0]}'?" if close else f"; allowed: {', '.join(allowed)}"
        ctx.fail(where, f"unknown key '{unknown[0]}'{hint}")


def _inside(ctx, where, key, pos, size):
    tol = 1e-9
    if np.any(pos < -tol) or np.any(pos > size + tol):
        ctx.fail(where, f"{key} {pos.tolist()} is outside the room [0..{size[0]:g}, "
                        f"0..{size[1]:g}, 0..{size[2]:g}]: move it inside")


def load_scene(path) -> Scene:
    """Read and validate a scene TOML file."""
    path = Path(path)
    if not path.exists():
        raise IrreflectError(f"{path}: no such file: expected a scene TOML file "
                             "(see datasets/rooms/office.toml)")
    try:
        doc = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise IrreflectError(f"{path}: not valid TOML ({exc}): fix the syntax") from exc
    except UnicodeDecodeError as exc:
        raise IrreflectError(f"{path}: not a text file; expected a scene TOML file") from exc
    return scene_from_dict(doc, path=str(path))


def scene_from_dict(doc: dict, path: str | None = None) -> Scene:
    """Build and validate a scene from the TOML structure (a dict)."""
    ctx = _Ctx(path)
    _check_keys(ctx, "top level", doc,
                ("scene", "room", "materials", "box", "emitter", "receiver", "receiver_grid",
                 "simulation"), ("room", "emitter"))
    info = doc.get("scene", {})
    _check_keys(ctx, "[scene]", info, ("name", "notes"))
    name = str(info.get("name", Path(path).stem if path else "scene"))

    room = doc["room"]
    _check_keys(ctx, "[room]", room, ("size_m", "materials"), ("size_m", "materials"))
    size = _vector(ctx, "[room]", "size_m", room["size_m"])
    if np.any(size <= 0):
        ctx.fail("[room]", f"size_m must be 3 positive lengths; found {size.tolist()}")

    # materials
    raw_mats = doc.get("materials", {})
    if not isinstance(raw_mats, dict):
        ctx.fail("[materials]", "expected tables [materials.NAME]")
    materials: dict[str, Material] = {}
    for mname, spec in raw_mats.items():
        materials[mname] = _material(ctx, mname, spec)

    def resolve(where, value) -> str:
        if not isinstance(value, str) or not value.strip():
            ctx.fail(where, f"material must be a name, \"lambertian(RHO)\" or a .json file; "
                            f"found {value!r}")
        if value in materials:
            return value
        rho = parse_lambertian(value)
        if rho is not None:
            key = f"lambertian({rho:g})"
            if key not in materials:
                try:
                    materials[key] = lambertian(rho, name=key)
                except IrreflectError as exc:
                    ctx.fail(where, str(exc))
            return key
        if value.lower().endswith(".json"):
            if value not in materials:
                try:
                    materials[value] = load_material(ctx.base / value, name=value)
                except IrreflectError as exc:
                    ctx.fail(where, str(exc))
            return value

        close = difflib.get_close_matches(value, list(materials), n=1)
        hint = f"did you mean '{close[0]}'?" if close else (
            "define it in [materials." + value + "] or use lambertian(RHO)")
        ctx.fail(where, f"unknown material '{value}': {hint}")
        return value  # unreachable

    room_mats = room["materials"]
    _check_keys(ctx, "[room.materials]", room_mats, ROOM_FACES + ("walls",))
    faces = []
    for face in ROOM_FACES:
        value = room_mats.get(face, room_mats.get("walls") if face.startswith("wall") else None)
        if value is None:
            ctx.fail("[room.materials]", f"no material for the {face}: set '{face}'"
                     + (" or 'walls'" if face.startswith("wall") else ""))
        faces.append(resolve(f"[room.materials] {face}", value))

    # boxes
    boxes = []
    for i, b in enumerate(_array_of_tables(ctx, doc, "box"), 1):
        where = f"[[box]] {i}"
        _check_keys(ctx, where, b, ("name", "min_m", "max_m", "material"),
                    ("min_m", "max_m", "material"))
        lo = _vector(ctx, where, "min_m", b["min_m"])
        hi = _vector(ctx, where, "max_m", b["max_m"])
        if np.any(hi <= lo):
            ctx.fail(where, f"max_m must exceed min_m on every axis; found min {lo.tolist()} "
                            f"max {hi.tolist()}")
        _inside(ctx, where, "min_m", lo, size)
        _inside(ctx, where, "max_m", hi, size)
        mspec = b["material"]
        if isinstance(mspec, dict):
            _check_keys(ctx, where + " material", mspec, BOX_FACES + ("sides",))
            names = []
            for face in BOX_FACES:
                value = mspec.get(face, mspec.get("sides") if face[0] in "xy" else None)
                if value is None:
                    ctx.fail(where, f"material has no entry for face '{face}'")
                names.append(resolve(f"{where} material {face}", value))
        else:
            names = [resolve(f"{where} material", mspec)] * 6
        boxes.append(Box(str(b.get("name", f"box{i}")), lo, hi, tuple(names)))
    for i in range(len(boxes)):
        for j in range(i + 1, len(boxes)):
            a, c = boxes[i], boxes[j]
            if np.all(a.lo < c.hi) and np.all(c.lo < a.hi):
                ctx.fail(f"[[box]] {j + 1}", f"box '{c.name}' overlaps box '{a.name}': boxes "
                                             "must not overlap (split or move them)")

    def not_in_box(where, pos):
        for b in boxes:
            if np.all(pos > b.lo + 1e-9) and np.all(pos < b.hi - 1e-9):
                ctx.fail(where, f"position {pos.tolist()} is inside box '{b.name}': move it "
                                "onto or out of the box")

    # emitters
    emitters = []
    for i, e in enumerate(_array_of_tables(ctx, doc, "emitter"), 1):
        where = f"[[emitter]] {i}"
        _check_keys(ctx, where, e, ("name", "position_m", "direction", "lambertian_order",
                                    "half_power_angle_deg", "power_w", "modulation_frequency_hz"),
                    ("position_m", "direction"))
        pos = _vector(ctx, where, "position_m", e["position_m"])
        _inside(ctx, where, "position_m", pos, size)
        not_in_box(where, pos)
        direction = _vector(ctx, where, "direction", e["direction"], unit=True)
        if ("lambertian_order" in e) == ("half_power_angle_deg" in e):
            ctx.fail(where, "give exactly one of lambertian_order (1 = Lambertian) or "
                            "half_power_angle_deg (60 = Lambertian)")
        if "lambertian_order" in e:
            order = _number(ctx, where, "lambertian_order", e["lambertian_order"], lo=0.0)
        else:
            half = _number(ctx, where, "half_power_angle_deg", e["half_power_angle_deg"],
                           lo=0.0, hi=90.0, lo_open=True)
            if half >= 90:
                ctx.fail(where, "half_power_angle_deg must be < 90")
            order = -math.log(2) / math.log(math.cos(math.radians(half)))  # Eq. 3
        power = _number(ctx, where, "power_w", e.get("power_w", 1.0), positive=True)
        fmod = _number(ctx, where, "modulation_frequency_hz", e.get("modulation_frequency_hz", 0.0),
                       lo=0.0)
        emitters.append(Emitter(str(e.get("name", f"emitter{i}")), pos, direction, order, power, fmod))
    if not emitters:
        ctx.fail("[[emitter]]", "the scene needs at least one emitter")

    # receivers
    receivers, grids = [], []
    rx_keys = ("name", "position_m", "direction", "area_m2", "fov_deg", "filter_gain",
               "concentrator_gain")

    def rx_common(where, r):
        area = _number(ctx, where, "area_m2", r.get("area_m2", 1e-4), positive=True)
        fov = _number(ctx, where, "fov_deg", r.get("fov_deg", 90.0), lo=0.0, hi=90.0, lo_open=True)
        filt = _number(ctx, where, "filter_gain", r.get("filter_gain", 1.0), lo=0.0)
        conc = _number(ctx, where, "concentrator_gain", r.get("concentrator_gain", 1.0), lo=0.0)
        direction = _vector(ctx, where, "direction", r.get("direction", [0, 0, 1]), unit=True)
        return direction, area, fov, filt, conc

    for i, r in enumerate(_array_of_tables(ctx, doc, "receiver"), 1):
        where = f"[[receiver]] {i}"
        _check_keys(ctx, where, r, rx_keys, ("position_m",))
        pos = _vector(ctx, where, "position_m", r["position_m"])
        _inside(ctx, where, "position_m", pos, size)
        not_in_box(where, pos)
        receivers.append(Receiver(str(r.get("name", f"rx{i}")), pos, *rx_common(where, r)))
    for i, g in enumerate(_array_of_tables(ctx, doc, "receiver_grid"), 1):
        where = f"[[receiver_grid]] {i}"
        _check_keys(ctx, where, g, ("name", "z_m", "x_m", "y_m", "n", "direction", "area_m2",
                                    "fov_deg", "filter_gain", "concentrator_gain"),
                    ("z_m", "n"))
        gname = str(g.get("name", f"grid{i}"))
        z = _number(ctx, where, "z_m", g["z_m"], lo=0.0, hi=float(size[2]))
        n = g["n"]
        if (not isinstance(n, list) or len(n) != 2
                or not all(isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= 500 for v in n)):
            ctx.fail(where, f"n must be [nx, ny], two integers 1..500; found {n!r}")
        xs = _range(ctx, where, "x_m", g.get("x_m", [0.0, float(size[0])]), float(size[0]), n[0])
        ys = _range(ctx, where, "y_m", g.get("y_m", [0.0, float(size[1])]), float(size[1]), n[1])
        common = rx_common(where, g)
        grids.append(Grid(gname, z, xs, ys))
        for iy, y in enumerate(ys):
            for ix, x in enumerate(xs):
                pos = np.array([x, y, z])
                if any(np.all(pos > b.lo - 1e-9) and np.all(pos < b.hi + 1e-9) for b in boxes):
                    continue  # inside furniture: no receiver there (a gap in the map)
                receivers.append(Receiver(f"{gname}[{ix},{iy}]", pos, *common, grid=gname,
                                          grid_index=(ix, iy)))
    if not receivers:
        ctx.fail("[[receiver]]", "the scene needs at least one [[receiver]] or [[receiver_grid]]")
    names = [r.name for r in receivers]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        ctx.fail("[[receiver]]", f"receiver names must be distinct; '{sorted(dup)[0]}' repeats")

    settings = _settings(ctx, doc.get("simulation", {}))
    return Scene(name=name, size=size, room_materials=tuple(faces), materials=materials,
                 emitters=tuple(emitters), receivers=tuple(receivers), boxes=tuple(boxes),
                 grids=tuple(grids), settings=settings, path=path)


def _range(ctx, where, key, value, top, n):
    if (not isinstance(value, list) or len(value) != 2
            or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)):
        ctx.fail(where, f"{key} must be [min, max] in metres; found {value!r}")
    lo, hi = float(value[0]), float(value[1])
    if not (0 <= lo <= hi <= top):
        ctx.fail(where, f"{key} must satisfy 0 <= min <= max <= {top:g}; found {value!r}")
    if n == 1:
        return np.array([(lo + hi) / 2])
    return np.linspace(lo, hi, n)


def _array_of_tables(ctx, doc, key):
    value = doc.get(key, [])
    if isinstance(value, dict):
        ctx.fail(f"[{key}]", f"write [[{key}]] (an array of tables), not [{key}]")
    return value


def _material(ctx, name, spec) -> Material:
    where = f"[materials.{name}]"
    if not isinstance(spec, dict):
        ctx.fail(where, f"expected a table with file, lambertian or model + params; found {spec!r}")
    _check_keys(ctx, where, spec, ("file", "lambertian", "model", "params", "reflectance",
                                   "gamma_max_deg", "notes"))
    kinds = [k for k in ("file", "lambertian", "model") if k in spec]
    if len(kinds) != 1:
        ctx.fail(where, "give exactly one of file = \"MATERIAL.json\", lambertian = RHO, or "
                        "model = \"NAME\" with params = {...}")
    try:
        if "file" in spec:
            return load_material(ctx.base / str(spec["file"]), name=name,
                                 reflectance=spec.get("reflectance"))
        if "lambertian" in spec:
            return lambertian(spec["lambertian"], name=name)
        if "params" not in spec or not isinstance(spec["params"], dict):
            ctx.fail(where, "model needs params = {NAME = VALUE, ...} (see 'irreflect models')")
        if "reflectance" not in spec:
            ctx.fail(where, "give reflectance = RHO (total reflectance, 0..1) or \"K\"")
        return from_model(str(spec["model"]), spec["params"], spec["reflectance"], name=name,
                          source=f"{spec['model']} (scene)", gamma_max_deg=spec.get("gamma_max_deg"))
    except IrreflectError as exc:
        if ctx.path and str(exc).startswith(str(ctx.path)):
            raise
        ctx.fail(where, str(exc))
        raise  # unreachable


def _settings(ctx, sim) -> dict:
    where = "[simulation]"
    _check_keys(ctx, where, sim, ("method", "bounces", "cell_m", "rays", "seed",
                                  "time_resolution_ns", "brdf"))
    out = {}
    if "method" in sim:
        if sim["method"] not in METHODS:
            ctx.fail(where, f"method must be one of {', '.join(METHODS)}; found {sim['method']!r}")
        out["method"] = sim["method"]
    if "brdf" in sim:
        if sim["brdf"] not in BRDFS:
            ctx.fail(where, f"brdf must be one of {', '.join(BRDFS)}; found {sim['brdf']!r}")
        out["brdf"] = sim["brdf"]
    for key, lo in (("bounces", 0), ("rays", 1), ("seed", 0)):
        if key in sim:
            v = sim[key]
            if not isinstance(v, int) or isinstance(v, bool) or v < lo:
                ctx.fail(where, f"{key} must be an integer >= {lo}; found {v!r}")
            out[key] = v
    for key in ("cell_m", "time_resolution_ns"):
        if key in sim:
            out[key] = _number(ctx, where, key, sim[key], positive=True)
    return out


__all__ = ["Scene", "Emitter", "Receiver", "Box", "Grid", "load_scene", "scene_from_dict",
           "ROOM_FACES", "BOX_FACES", "METHODS"]
