"""Surfaces of a scene, their discretisation into cells, and line-of-sight geometry."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import IrreflectError
from .kernels import C_LIGHT, occluded
from .scene import Receiver, Scene


@dataclass(frozen=True)
class Cells:
    """Surface cells: centres (N, 3) m, normals (N, 3) pointing into the room, areas (N,) m^2,
    material index (N,), surface index (N,)."""

    pos: np.ndarray
    normal: np.ndarray
    area: np.ndarray
    material: np.ndarray
    surface: np.ndarray
    cell_m: float

    @property
    def n(self) -> int:
        return int(self.pos.shape[0])


def boxes_array(scene: Scene) -> np.ndarray:
    if not scene.boxes:
        return np.zeros((0, 2, 3))
    return np.array([[b.lo, b.hi] for b in scene.boxes], float)


def _rectangles(scene: Scene):
    """(axis, coordinate, normal sign, (lo, hi) of the other two axes, material name)."""
    size = scene.size
    rects = []
    for k, face in enumerate(("wall_x0", "wall_x1", "wall_y0", "wall_y1", "floor", "ceiling")):
        axis, high = divmod(k, 2)
        others = [a for a in range(3) if a != axis]
        rects.append((axis, float(size[axis]) if high else 0.0, -1.0 if high else 1.0,
                      [(0.0, float(size[a])) for a in others], scene.room_materials[k], face))
    for b in scene.boxes:
        for k in range(6):
            axis, high = divmod(k, 2)
            coord = float(b.hi[axis] if high else b.lo[axis])
            if coord <= 1e-12 or coord >= float(size[axis]) - 1e-12:
                continue  # lies on a room face: it faces the wall and sees nothing
            others = [a for a in range(3) if a != axis]
            rects.append((axis, coord, 1.0 if high else -1.0,
                          [(float(b.lo[a]), float(b.hi[a])) for a in others], b.materials[k],
                          f"{b.name}:{k}"))
    return rects


def discretize(scene: Scene, cell_m: float) -> Cells:
    """Cut every surface into cells of about ``cell_m`` metres (at least one per side).

    Room-surface cells covered by a box (a desk standing on the floor) are dropped: no light
    reaches them.
    """
    if not cell_m > 0:
        raise IrreflectError(f"cell size must be > 0 m; found {cell_m}")
    names = list(scene.materials)
    index = {n: i for i, n in enumerate(names)}
    boxes = boxes_array(scene)
    pos, nrm, area, mat, surf = [], [], [], [], []
    for s, (axis, coord, sign, ranges, mname, _label) in enumerate(_rectangles(scene)):
        others = [a for a in range(3) if a != axis]
        (a0, a1), (b0, b1) = ranges
        nu = max(1, int(round((a1 - a0) / cell_m)))
        nv = max(1, int(round((b1 - b0) / cell_m)))
        du, dv = (a1 - a0) / nu, (b1 - b0) / nv
        u = a0 + (np.arange(nu) + 0.5) * du
        v = b0 + (np.arange(nv) + 0.5) * dv
        U, V = np.meshgrid(u, v, indexing="ij")
        p = np.zeros((U.size, 3))
        p[:, axis] = coord
        p[:, others[0]] = U.ravel()
        p[:, others[1]] = V.ravel()
        if s < 6 and len(boxes):
            covered = np.zeros(len(p), bool)
            for b in boxes:
                covered |= np.all((p >= b[0] - 1e-9) & (p <= b[1] + 1e-9), axis=1)
            p = p[~covered]
        n = np.zeros((len(p), 3))
        n[:, axis] = sign
        pos.append(p)
        nrm.append(n)
        area.append(np.full(len(p), du * dv))
        mat.append(np.full(len(p), index[mname], np.int64))
        surf.append(np.full(len(p), s, np.int64))
    return Cells(np.concatenate(pos), np.concatenate(nrm), np.concatenate(area),
                 np.concatenate(mat), np.concatenate(surf), float(cell_m))


def face_material_indices(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Material index of each room face and of each box face (order x0 x1 y0 y1 z0 z1)."""
    index = {n: i for i, n in enumerate(scene.materials)}
    room = np.array([index[m] for m in scene.room_materials], np.int64)
    box = np.array([[index[m] for m in b.materials] for b in scene.boxes], np.int64).reshape(-1, 6)
    return room, box


def _visible(p, qs, boxes) -> np.ndarray:
    if len(boxes) == 0:
        return np.ones(len(qs), bool)
    return np.array([not occluded(p[0], p[1], p[2], q[0], q[1], q[2], boxes) for q in qs])


def emitter_to_cells(scene: Scene, emitter, cells: Cells):
    """Power (W), delay (s) and unit propagation direction of the light reaching each cell
    straight from the emitter (Eq. 5 with the cell as receiver, Barry's h^(0))."""
    v = cells.pos - emitter.position
    d2 = np.einsum("ij,ij->i", v, v)
    d = np.sqrt(d2)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = v / d[:, None]
        cos_e = u @ emitter.direction
        cos_c = -np.einsum("ij,ij->i", u, cells.normal)
        ok = (d > 1e-9) & (cos_e > 0) & (cos_c > 0)
        power = np.where(ok, emitter.power_w * (emitter.order + 1) / (2 * np.pi)
                         * np.clip(cos_e, 0, None) ** emitter.order * cells.area
                         * np.clip(cos_c, 0, None) / d2, 0.0)
    vis = _visible(emitter.position, cells.pos, boxes_array(scene))
    power = np.where(vis, power, 0.0)
    return power, d / C_LIGHT, np.nan_to_num(u)


def cells_to_receiver(scene: Scene, receiver: Receiver, cells: Cells):
    """Per cell: ``A_R T_s g cos(psi) / d^2`` towards the receiver (0 outside the field of
    view, behind the cell or hidden), delay (s) and unit direction cell -> receiver."""
    v = receiver.position - cells.pos
    d2 = np.einsum("ij,ij->i", v, v)
    d = np.sqrt(d2)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = v / d[:, None]
        cos_r = -(u @ receiver.direction)
        cos_c = np.einsum("ij,ij->i", u, cells.normal)
        ok = (d > 1e-9) & (cos_r >= np.cos(np.radians(receiver.fov_deg))) & (cos_r > 0) & (cos_c > 0)
        gain = np.where(ok, receiver.gain_area * cos_r / d2, 0.0)
    gain = np.where(_visible(receiver.position, cells.pos, boxes_array(scene)), gain, 0.0)
    return gain, d / C_LIGHT, np.nan_to_num(u)


def line_of_sight(scene: Scene, emitter, receiver: Receiver):
    """Exact LoS: (DC gain times emitter power, i.e. received power in W; delay in s)."""
    v = receiver.position - emitter.position
    d = float(np.linalg.norm(v))
    tau = d / C_LIGHT
    if d == 0:
        return 0.0, 0.0
    u = v / d
    cos_e = float(u @ emitter.direction)
    cos_r = float(-(u @ receiver.direction))
    if cos_e <= 0 or cos_r <= 0 or cos_r < np.cos(np.radians(receiver.fov_deg)):
        return 0.0, tau
    boxes = boxes_array(scene)
    if len(boxes) and occluded(*emitter.position, *receiver.position, boxes):
        return 0.0, tau
    power = (emitter.power_w * (emitter.order + 1) / (2 * np.pi) * cos_e ** emitter.order
             * receiver.gain_area * cos_r / d**2)
    return power, tau
