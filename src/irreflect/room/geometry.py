"""Surfaces of a scene, their discretisation into cells, and line-of-sight geometry."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import IrreflectError
from .kernels import C_LIGHT, occluded
from .scene import Receiver, Scene
from .transport import CellPack, Faces, Tree


@dataclass(frozen=True)
class Cells:
    """Surface cells: centres (N, 3) m, normals (N, 3) pointing into the room, areas (N,) m^2,
    material index (N,), surface index (N,); half-sizes (N, 2) along the surface's two axes
    ``axes[:, :2]`` (global axis indices; ``axes[:, 2]`` the normal axis); ``grids``: per
    surface the (nu, nv) array of its cell indices (-1 where a box covers the cell)."""

    pos: np.ndarray
    normal: np.ndarray
    area: np.ndarray
    material: np.ndarray
    surface: np.ndarray
    cell_m: float
    half: np.ndarray = None
    axes: np.ndarray = None
    grids: tuple = ()
    faces: Faces | None = None

    @property
    def n(self) -> int:
        return int(self.pos.shape[0])

    def pack(self, boxes) -> CellPack:
        return CellPack(self.pos, self.normal, self.area, self.material, self.surface,
                        self.half, self.axes, np.asarray(boxes, float).reshape(-1, 2, 3))


def boxes_array(scene: Scene) -> np.ndarray:
    if not scene.boxes:
        return np.zeros((0, 2, 3))
    return np.array([[b.lo, b.hi] for b in scene.boxes], float)


def _rectangles(scene: Scene):
    """(axis, coordinate, normal sign, (lo, hi) of the other two axes, material name, label):
    the six room faces (label: the face's name), then the box faces that do not lie on a
    room face (label: (box index, face 0..5))."""
    size = scene.size
    rects = []
    for k, face in enumerate(("wall_x0", "wall_x1", "wall_y0", "wall_y1", "floor", "ceiling")):
        axis, high = divmod(k, 2)
        others = [a for a in range(3) if a != axis]
        rects.append((axis, float(size[axis]) if high else 0.0, -1.0 if high else 1.0,
                      [(0.0, float(size[a])) for a in others], scene.room_materials[k], face))
    for bi, b in enumerate(scene.boxes):
        for k in range(6):
            axis, high = divmod(k, 2)
            coord = float(b.hi[axis] if high else b.lo[axis])
            if coord <= 1e-12 or coord >= float(size[axis]) - 1e-12:
                continue  # lies on a room face: it faces the wall and sees nothing
            others = [a for a in range(3) if a != axis]
            rects.append((axis, coord, 1.0 if high else -1.0,
                          [(float(b.lo[a]), float(b.hi[a])) for a in others], b.materials[k],
                          (bi, k)))
    return rects


def discretize(scene: Scene, cell_m: float) -> Cells:
    """Cut every surface into cells of about ``cell_m`` metres (at least one per side).

    Room-surface cells whose centre a box covers (a desk standing on the floor) are dropped:
    no light reaches them.
    """
    if not cell_m > 0:
        raise IrreflectError(f"cell size must be > 0 m; found {cell_m}")
    names = list(scene.materials)
    index = {n: i for i, n in enumerate(names)}
    boxes = boxes_array(scene)
    pos, nrm, area, mat, surf, half, axes, grids = [], [], [], [], [], [], [], []
    f_axes, f_geo, f_dims = [], [], []
    start = 0
    rects = _rectangles(scene)
    for s, (axis, coord, sign, ranges, mname, _label) in enumerate(rects):
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
        keep = np.ones(len(p), bool)
        if s < 6 and len(boxes):
            for b in boxes:
                keep &= ~np.all((p >= b[0] - 1e-9) & (p <= b[1] + 1e-9), axis=1)
        grid = np.full(U.size, -1, np.int64)
        grid[keep] = start + np.arange(int(keep.sum()))
        grids.append(grid.reshape(nu, nv))
        f_axes.append([axis, others[0], others[1]])
        f_geo.append([a0, b0, du, dv])
        f_dims.append([nu, nv])
        p = p[keep]
        start += len(p)
        n = np.zeros((len(p), 3))
        n[:, axis] = sign
        pos.append(p)
        nrm.append(n)
        area.append(np.full(len(p), du * dv))
        mat.append(np.full(len(p), index[mname], np.int64))
        surf.append(np.full(len(p), s, np.int64))
        half.append(np.tile([du / 2, dv / 2], (len(p), 1)))
        axes.append(np.tile([others[0], others[1], axis], (len(p), 1)).astype(np.int64))
    offset = np.zeros(len(grids), np.int64)
    np.cumsum([g.size for g in grids[:-1]], out=offset[1:])
    boxsurf = np.full((len(scene.boxes), 6), -1, np.int64)
    for s, rect in enumerate(rects[6:], start=6):
        b, k = rect[5]
        boxsurf[b, k] = s
    faces = Faces(np.array(f_axes, np.int64), np.array(f_geo, float), np.array(f_dims, np.int64),
                  offset, np.concatenate([g.ravel() for g in grids]), boxsurf,
                  np.asarray(scene.size, float))
    return Cells(np.concatenate(pos), np.concatenate(nrm), np.concatenate(area),
                 np.concatenate(mat), np.concatenate(surf), float(cell_m),
                 np.concatenate(half), np.concatenate(axes), tuple(grids), faces)


def _groups(n: int) -> list[int]:
    """Sizes of the blocks that one quadtree level merges along a side of ``n``: pairs, with
    one block of 1 (or 3) in the middle when ``n`` is odd, so that the blocks are the same
    seen from either end (a mirror-symmetric room gets a mirror-symmetric tree; pairs from
    one end left an odd cell at the far end and broke the symmetry by 1e-3 per cell)."""
    if n % 2 == 0:
        return [2] * (n // 2)
    side = (n - 1) // 2
    if side % 2 == 0:
        return [2] * (side // 2) + [1] + [2] * (side // 2)
    return [2] * ((side - 1) // 2) + [3] + [2] * ((side - 1) // 2)


def build_tree(cells: Cells) -> tuple[Tree, np.ndarray]:
    """A tree per surface over its cell grid (cells are the leaves, nodes 0..N-1; inner
    nodes merge blocks of 2 x 2 (up to 3 x 3 in the middle of an odd side, :func:`_groups`)
    level by level up to one root per surface; a block with one cell is that cell). Returns
    the tree and the inner nodes in an order with children before parents."""
    N = cells.n
    width = 9
    cap = 2 * N + 8 * len(cells.grids) + 8
    lo = np.zeros((cap, 3))
    hi = np.zeros((cap, 3))
    lo[:N] = cells.pos - _extent(cells)
    hi[:N] = cells.pos + _extent(cells)
    child = np.full((cap, width), -1, np.int64)
    surf = np.zeros(cap, np.int64)
    surf[:N] = cells.surface
    leaf = np.zeros(cap, np.int64)
    leaf[:N] = np.arange(N)
    roots, order = [], []
    nxt = N
    for s, grid in enumerate(cells.grids):
        level = grid
        while level.shape[0] > 1 or level.shape[1] > 1:
            gu = np.cumsum([0] + _groups(level.shape[0]))
            gv = np.cumsum([0] + _groups(level.shape[1]))
            nu, nv = len(gu) - 1, len(gv) - 1
            kids = np.full((nu * nv, width), -1, np.int64)
            for a in range(nu):
                for b in range(nv):
                    block = level[gu[a]:gu[a + 1], gv[b]:gv[b + 1]].ravel()
                    block = block[block >= 0]  # valid children first, in their order
                    kids[a * nv + b, :block.size] = block
            n_kids = (kids >= 0).sum(axis=1)
            up = np.where(n_kids == 1, kids[:, 0], -1)
            many = np.nonzero(n_kids >= 2)[0]
            ids = nxt + np.arange(many.size)
            up[many] = ids
            k = kids[many]
            child[ids] = k
            valid = k >= 0
            safe = np.where(valid, k, k[:, :1])
            lo[ids] = np.min(lo[safe], axis=1)
            hi[ids] = np.max(hi[safe], axis=1)
            surf[ids] = s
            leaf[ids] = leaf[k[:, 0]]
            order.append(ids)
            nxt += many.size
            level = up.reshape(nu, nv)
        roots.append(int(level[0, 0]))
    lo, hi, child, surf, leaf = lo[:nxt], hi[:nxt], child[:nxt], surf[:nxt], leaf[:nxt]
    size = np.max(hi - lo, axis=1)
    order = np.concatenate(order) if order else np.zeros(0, np.int64)
    return Tree(lo, hi, child, surf, np.array(roots, np.int64), size, leaf), order


def _extent(cells: Cells) -> np.ndarray:
    ext = np.zeros_like(cells.pos)
    rows = np.arange(cells.n)
    ext[rows, cells.axes[:, 0]] = cells.half[:, 0]
    ext[rows, cells.axes[:, 1]] = cells.half[:, 1]
    return ext


def face_material_indices(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Material index of each room face and of each box face (order x0 x1 y0 y1 z0 z1)."""
    index = {n: i for i, n in enumerate(scene.materials)}
    room = np.array([index[m] for m in scene.room_materials], np.int64)
    box = np.array([[index[m] for m in b.materials] for b in scene.boxes], np.int64).reshape(-1, 6)
    return room, box


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
    if len(boxes) and occluded(tuple(map(float, emitter.position)),
                               tuple(map(float, receiver.position)), boxes):
        return 0.0, tau
    power = (emitter.power_w * (emitter.order + 1) / (2 * np.pi) * cos_e ** emitter.order
             * receiver.gain_area * cos_r / d**2)
    return power, tau
