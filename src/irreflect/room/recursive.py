"""Barry's recursive method, receiver-independent: the light arriving at every surface cell
after 0, 1, ..., K-1 reflections is carried once per emitter (:func:`emitter_state`), and
each receiver gathers it (:func:`receiver_link`), so that a hundred receivers cost little
more than one.

Per reflection order the state is the light *arriving* at each cell (:class:`~.transport.Arrivals`):
power, exact delay moments and phasor, the scalars of the material's separable diffuse
terms (exact whatever the directions the light came from), and for materials with lobes a
map of the directions it came from. What a cell sends on is computed from that state: the
diffuse terms from their scalars, the lobes from the map through the material's lobe
matrix (:func:`~.transport.lobe_matrix`), and the first reflection of the emitter's light
from the exact BRDF at its exact incidence. Cell-to-cell legs use a quadtree over every
surface (Barnes-Hut: far groups of cells act as one source, ``theta_open``), with the
near-field quadrature of :mod:`.transport`.

Delays. The first two orders keep exact delay histograms (each cell's arrival histogram of
once-reflected light is built pair by pair and shifted to the receiver); from the third
order on, each cell's arrival-time distribution is represented by its exact power, mean,
variance and earliest arrival (a shifted gamma distribution) when it is shifted to the
receiver. DC gains, delay moments and phasors are sums over cell paths at every order
(up to the quadrature and far-field approximations, whose error the engine estimates).
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from . import gather as G
from . import kernels as K
from . import transport as T
from .geometry import Cells, build_tree, discretize

#: far-field opening angle of the quadtree (radians): a group of cells smaller than this
#: seen from a receiving cell acts as one source (with the second-order correction; on
#: Barry's configuration A its error against the exact sum over every cell pair is at most
#: 2e-4 per order at 0.0625-0.25 m; 0.3 gives 2e-5 at 2.2x the time, 0.8 3e-3)
THETA_OPEN = 0.6
#: the same for cells with direction maps (their arrivals keep each source's direction)
THETA_OPEN_MAPS = 0.3
#: rays per lobed cell that carry the lobes of its once-reflected emitter light
LOBE_RAYS = 256
#: carry the lobes of twice-and-more reflected light by one ray per map bin (else by pairs)
MAP_RAYS = True


@dataclass
class Geometry:
    """Cells, their quadtree and the material tables of one scene at one cell size."""

    cells: Cells
    pack: T.CellPack
    tree: T.Tree
    order: np.ndarray
    mats: K.MatPack
    ext: T.MatExtra
    boxes: np.ndarray
    lobed_cells: np.ndarray
    map_res: int = T.MAP_RES

    @property
    def n(self) -> int:
        return self.cells.n


def material_extra(materials, mats: K.MatPack, map_res: int = T.MAP_RES) -> T.MatExtra:
    """Per material: the amplitudes of its separable diffuse terms, whether its light goes
    through direction maps, and its lobe matrix (:func:`~.transport.lobe_matrix`)."""
    M = len(materials)
    D = map_res * map_res
    damp = np.zeros((M, T.N_P))
    lobed = np.zeros(M, np.int64)
    for m, mat in enumerate(materials):
        if mat.kind == K.KIND_LAMBERTIAN:
            damp[m, 0] = mat.reflectance / np.pi
        elif mat.kind == K.KIND_RECIPROCAL:
            for kind, idx, _q, amp in mat.terms:
                if int(kind) == K.TERM_DIFFUSE:
                    damp[m, int(idx)] += amp
                else:
                    lobed[m] = 1
        else:
            lobed[m] = 1
    kmat = np.zeros((M, D, D) if lobed.any() else (M, 1, 1), np.float32)
    if lobed.any():
        kin = np.array([T.from_square((b // map_res + 0.5) / map_res,
                                      (b % map_res + 0.5) / map_res)[2] for b in range(D)])
        for m in np.nonzero(lobed)[0]:
            kmat[m] = _lobe_matrix_cached(materials[m], mats, int(m), kin)
    plain = np.array([m.kind == K.KIND_LAMBERTIAN for m in materials], np.int64)
    cos_nodes = np.linspace(0.0, 1.0, K.N_COS)
    rhocos = np.array([np.interp(np.arccos(cos_nodes), K.GAMMA_NODES, m.rho_table)
                       for m in materials]).reshape(M, K.N_COS)
    pmax = np.array([int(np.max(np.nonzero(damp[m])[0], initial=0)) for m in range(M)], np.int64)
    nmax = np.array([_largest_lobe(m) for m in materials])
    return T.MatExtra(damp, lobed, kmat, plain, rhocos, pmax, nmax)


def _largest_lobe(mat) -> float:
    """The largest lobe index of a material (0: none): the sharpest feature of its light."""
    if mat.kind == K.KIND_RECIPROCAL:
        lobes = [K.N_VALUES[int(i)] for kind, i, _q, _a in mat.terms if int(kind) != K.TERM_DIFFUSE]
        return float(max(lobes, default=0.0))
    if mat.kind == K.KIND_LOBES:
        g = np.cos(np.minimum(K.GAMMA_NODES, mat.gamma_max_rad))
        return float(max(np.max(u * g ** v) for _t, _a, _b, u, v in mat.lobes))
    if mat.kind == K.KIND_TABLE:
        return 1000.0
    return 0.0


_KMAT_CACHE: dict = {}


def _lobe_matrix_cached(material, mats, m, kin):
    res = int(round(np.sqrt(kin.size)))
    key = (res, material.kind, material.terms.tobytes(), material.rho_table.tobytes(),
           None if material.energy_cap is None else material.energy_cap.tobytes(),
           material.model, tuple(sorted((material.params or {}).items())))
    hit = _KMAT_CACHE.get(key)
    if hit is None:
        hit = T.lobe_matrix(mats, m, res, kin)
        if len(_KMAT_CACHE) > 16:
            _KMAT_CACHE.clear()
        _KMAT_CACHE[key] = hit
    return hit


#: map resolutions tried, coarse first; the first whose added spread is small enough is used
MAP_LEVELS = (16, 24, 32, 40)
#: the largest mean relative broadening of the lobes by the maps (see :func:`map_resolution`)
MAP_BLUR = 0.035


def map_resolution(materials) -> int:
    """Bins per side of the direction maps for these materials. The maps widen a lobe of
    index n by about a bin: its variance ``1 / (n + 1)`` grows by ``bin^2 / 4`` (bin^2 =
    2 pi / res^2), a relative change ``min(1, (n + 1) bin^2 / 4)``. Weighted by each term's
    share of the material's albedo and summed, this is the resolution's cost in fidelity;
    the coarsest of :data:`MAP_LEVELS` that keeps it under :data:`MAP_BLUR` for every
    material is used (nearly diffuse materials: 16 or 24; a medium-gloss paint: 40, where
    orders 1-3 came within 0.8 % of Monte Carlo)."""
    need = MAP_LEVELS[0]
    for mat in materials:
        if mat.kind in (K.KIND_LOBES, K.KIND_TABLE):
            return MAP_LEVELS[-1]
        if mat.kind != K.KIND_RECIPROCAL:
            continue
        share = mat.term_albedo.mean(axis=1)
        share = share / max(share.sum(), 1e-300)
        n = np.array([K.N_VALUES[int(i)] if int(k) != K.TERM_DIFFUSE else 0.0
                      for k, i, _q, _a in mat.terms])
        lobe = mat.terms[:, 0].astype(int) != K.TERM_DIFFUSE
        for res in MAP_LEVELS:
            blur = np.minimum(1.0, (n + 1) * (2 * np.pi / res ** 2) / 4)
            if np.sum((share * blur)[lobe]) <= MAP_BLUR or res == MAP_LEVELS[-1]:
                need = max(need, res)
                break
    return int(need)


def prepare(scene, cell_m: float, boxes: np.ndarray, map_res: int | None = None) -> Geometry:
    _, materials = scene.material_list()
    cells = discretize(scene, cell_m)
    tree, order = build_tree(cells)
    mats = K.pack_materials(materials)
    res = map_res or map_resolution(materials)
    ext = material_extra(materials, mats, res)
    lobed_cells = np.nonzero(ext.lobed[cells.material])[0]
    return Geometry(cells, cells.pack(boxes), tree, order, mats, ext, boxes, lobed_cells, res)


def in_chunks(n, threads, fn, size=None):
    """Run ``fn(start, stop)`` over [0, n) in chunks, on ``threads`` threads (nogil kernels)."""
    size = size or max(1, min(256, -(-n // (8 * max(threads, 1)))))
    bounds = [(i, min(i + size, n)) for i in range(0, n, size)]
    if threads <= 1 or len(bounds) == 1:
        for a, b in bounds:
            fn(a, b)
        return
    with ThreadPoolExecutor(max_workers=threads) as pool:
        list(pool.map(lambda ab: fn(*ab), bounds))


# ----------------------------------------------------------------------------- state
def _arrivals(geo: Geometry, hist_bins: int, maps: bool) -> T.Arrivals:
    N = geo.n
    D = geo.map_res * geo.map_res
    arow = np.full(N, -1, np.int64)
    if maps and geo.lobed_cells.size:
        arow[geo.lobed_cells] = np.arange(geo.lobed_cells.size)
        amap = np.zeros((geo.lobed_cells.size, D), np.float32)
    else:
        amap = np.zeros((0, D), np.float32)
    return T.Arrivals(np.zeros(N), np.zeros(N), np.zeros(N), np.zeros((N, 2)),
                      np.full(N, np.inf), np.zeros((N, T.N_P)), np.zeros(N),
                      np.zeros((N, hist_bins), np.float32), amap, arow)


def _sources(geo: Geometry, arr: T.Arrivals, edir, epos=None) -> T.Sources:
    """What leaves each node: the arrivals summed up the quadtree, and for lobed cells the
    outgoing map ``map @ K`` (summed up the tree too)."""
    tree = geo.tree
    N = geo.n
    Nn = tree.lo.shape[0]
    D = geo.map_res * geo.map_res

    def grow(a, shape, fill=0.0):
        out = np.full(shape, fill)
        out[:N] = a
        return out

    power = grow(arr.power, Nn)
    t0 = grow(np.where(np.isfinite(arr.t0), arr.t0, 0.0), Nn)
    orow = np.full(Nn, -1, np.int64)
    if arr.amap.shape[0]:
        rows = arr.arow
        lobed_nodes = np.nonzero(geo.ext.lobed[geo.cells.material[tree.leaf]])[0]
        inner = lobed_nodes[lobed_nodes >= N]
        orow[:N] = rows
        orow[inner] = arr.amap.shape[0] + np.arange(inner.size)
        out = np.zeros((arr.amap.shape[0] + inner.size, D), np.float32)
        mat_of_row = geo.cells.material[geo.lobed_cells]
        for m in np.unique(mat_of_row):
            sel = np.nonzero(mat_of_row == m)[0]
            out[sel] = arr.amap[sel] @ geo.ext.kmat[m]
    else:
        out = np.zeros((0, D), np.float32)
    spread = np.zeros((Nn, 3))
    spread[:N, 0] = geo.cells.half[:, 0] ** 2 / 3.0
    spread[:N, 1] = geo.cells.half[:, 1] ** 2 / 3.0
    src = T.Sources(power, grow(arr.m1, Nn), grow(arr.m2, Nn), grow(arr.ph, (Nn, 2)), t0,
                    grow(arr.e, (Nn, T.N_P)), grow(geo.cells.pos, (Nn, 3)), orow, out,
                    edir if edir is not None else np.zeros((N, 3)), spread, np.zeros((Nn, 5)),
                    np.zeros(8) if epos is None else np.asarray(epos, float))
    if geo.order.size:
        T.aggregate(tree, src, geo.order, geo.cells.axes)
    P = np.where(src.power > 0, src.power, 1.0)
    src.tn[:] = np.column_stack([src.m1 / P, src.m2 / P, src.ph[:, 0] / P, src.ph[:, 1] / P,
                                 src.t0])
    return src


def _ragged(start, count) -> T.Shapes:
    offset = np.zeros(count.size, np.int64)
    np.cumsum(count[:-1], out=offset[1:])
    return T.Shapes(np.zeros(int(count.sum()), np.float32), offset, start.astype(np.int64),
                    count.astype(np.int64))


def _hist_shapes(arr: T.Arrivals, n_bins: int) -> T.Shapes:
    """Normalised arrival histograms of once-reflected light (exact, binned)."""
    h = arr.hist[:, :n_bins]
    nz = h > 0
    any_ = nz.any(axis=1) & (arr.power > 0)
    first = np.where(any_, np.argmax(nz, axis=1), 0)
    last = np.where(any_, h.shape[1] - 1 - np.argmax(nz[:, ::-1], axis=1), -1)
    shapes = _ragged(first, np.where(any_, last - first + 1, 0))
    G.hist_fill(np.where(any_, arr.power, 0.0), h, shapes)
    return shapes


def _gamma_shapes(arr: T.Arrivals, dt: float, n_bins: int) -> T.Shapes:
    """Arrival histograms rebuilt from each cell's exact power, mean, variance and earliest
    arrival: ``t0 + Gamma(k, theta)`` with the same mean and variance (a point mass at the
    mean when the spread is under a twentieth of a bin), see :func:`~.transport.gamma_fill`."""
    N = arr.power.shape[0]
    start = np.zeros(N, np.int64)
    count = np.zeros(N, np.int64)
    for j in np.nonzero(arr.power > 0)[0]:
        start[j], count[j], _, _ = G.gamma_window(arr.power, arr.m1, arr.m2, arr.t0, dt,
                                                  n_bins, j)
    shapes = _ragged(start, count)
    G.gamma_fill(arr.power, arr.m1, arr.m2, arr.t0, dt, n_bins, shapes)
    return shapes


@dataclass
class EmitterState:
    """Receiver-independent light of one emitter: per order k = 0..K-1 the light leaving
    the cells after k reflections (k = 0: straight from the emitter), its delay shapes and
    kernel settings; ``reflected[k]`` the power left after k + 1 reflections."""

    sources: list = field(default_factory=list)
    shapes: list = field(default_factory=list)
    knobs: list = field(default_factory=list)
    reflected: np.ndarray | None = None
    arrived: np.ndarray | None = None


def emitter_state(geo: Geometry, emitter, bounces: int, dt: float, n_bins: int,
                  threads: int = 1, theta_open: float | None = None,
                  lobe_rays: int | None = None) -> EmitterState:
    """Carry the emitter's light over the cells for ``bounces`` reflections (``lobe_rays``:
    rays per lobed cell for its once-reflected emitter light, default :data:`LOBE_RAYS`)."""
    lobe_rays = int(lobe_rays or LOBE_RAYS)
    omega = 2 * math.pi * emitter.modulation_hz
    N = geo.n
    lobed = geo.lobed_cells.size > 0
    theta = theta_open if theta_open is not None else (THETA_OPEN_MAPS if lobed else THETA_OPEN)
    st = EmitterState(reflected=np.zeros(bounces), arrived=np.zeros(bounces))
    if bounces < 1:
        return st
    arr = _arrivals(geo, 0, False)
    edir = np.zeros((N, 3))
    knobs0 = T.Knobs(dt, omega, theta, 1, 0, 0)
    rays = int(any(geo.mats.kind[m] == K.KIND_RECIPROCAL and geo.ext.lobed[m]
                   for m in range(geo.mats.kind.size)))
    em = (np.asarray(emitter.position, float), np.asarray(emitter.direction, float),
          (float(emitter.order), float(emitter.power_w)))
    in_chunks(N, threads, lambda a, b: T.from_emitter(a, b, geo.pack, geo.mats, geo.ext, em,
                                                        edir, arr, knobs0))
    src = _sources(geo, arr, edir, np.concatenate([emitter.position, emitter.direction,
                                                   [emitter.order, emitter.power_w]]))
    st.sources.append(src)
    st.shapes.append(_ragged(np.zeros(N, np.int64), np.zeros(N, np.int64)))
    st.knobs.append(knobs0)
    st.reflected[0] = arr.refl.sum()
    st.arrived[0] = arr.power.sum()
    for k in range(1, bounces):
        first = k == 1
        legs_bins = int(math.ceil((k + 1) * _diag(geo) / K.C_LIGHT / dt)) + 2
        arr = _arrivals(geo, legs_bins if first else 0, True)
        knobs = T.Knobs(dt, omega, theta, 1 if first else 0, 1 if first else 0,
                        rays if first else int(MAP_RAYS and geo.lobed_cells.size > 0))
        in_chunks(N, threads, lambda a, b, s=src, ar=arr, kn=knobs: T.transfer(
            a, b, geo.pack, geo.tree, geo.mats, geo.ext, s, ar, kn, np.empty(4096, np.int64)))
        if first and rays:
            _rays(N, threads, arr, lambda a, b, ar, s=src, kn=knobs: T.lobe_rays(
                a, b, geo.pack, geo.cells.faces, geo.mats, geo.ext, s, ar, kn, lobe_rays))
        if not first and knobs.rays:
            _rays(N, threads, arr, lambda a, b, ar, s=src, kn=knobs: T.map_rays(
                a, b, geo.pack, geo.cells.faces, geo.mats, geo.ext, s, ar, kn))
        src = _sources(geo, arr, None)
        st.sources.append(src)
        st.shapes.append(_hist_shapes(arr, n_bins) if first else _gamma_shapes(arr, dt, n_bins))
        st.knobs.append(T.Knobs(dt, omega, theta, 0, 0, 0))
        st.reflected[k] = arr.refl.sum()
        st.arrived[k] = arr.power.sum()
    return st


def _rays(n, threads, arr: T.Arrivals, fn) -> None:
    """Run ``fn(start, stop, arrivals)`` (ray kernels, which deposit anywhere) over [0, n) on
    ``threads`` threads, each into its own arrivals, summed into ``arr`` at the end."""
    if threads <= 1 or n < 2:
        fn(0, n, arr)
        return
    parts = [arr] + [T.Arrivals(*(np.zeros_like(a) if k != "arow" else a
                                  for k, a in zip(T.Arrivals._fields, arr, strict=True)))
                     for _ in range(threads - 1)]
    for extra in parts[1:]:
        extra.t0[:] = np.inf
    bounds = np.linspace(0, n, threads + 1).astype(int)
    with ThreadPoolExecutor(max_workers=threads) as pool:
        list(pool.map(lambda k: fn(bounds[k], bounds[k + 1], parts[k]), range(threads)))
    for extra in parts[1:]:
        for name in ("power", "m1", "m2", "ph", "e", "refl", "hist", "amap"):
            getattr(arr, name)[...] += getattr(extra, name)
        np.minimum(arr.t0, extra.t0, out=arr.t0)


def _diag(geo: Geometry) -> float:
    return float(np.linalg.norm(geo.cells.pos.max(axis=0) - geo.cells.pos.min(axis=0))) + 1.0


def receiver_link(geo: Geometry, st: EmitterState, receiver, n_bins: int):
    """Orders 1..K at one receiver: (power (K,), m1, m2, phasor (K,), hist (K, T))."""
    Kb = len(st.sources)
    power = np.zeros(Kb)
    m1 = np.zeros(Kb)
    m2 = np.zeros(Kb)
    ph = np.zeros(Kb, complex)
    hist = np.zeros((Kb, n_bins))
    rx = (np.asarray(receiver.position, float), np.asarray(receiver.direction, float),
          (float(receiver.gain_area), float(np.cos(np.radians(receiver.fov_deg)))))
    for k in range(Kb):
        sums = np.zeros(5)
        G.gather(geo.pack, geo.mats, geo.ext, st.sources[k], rx, st.shapes[k], st.knobs[k],
                 (hist[k], sums))
        power[k], m1[k], m2[k] = sums[0], sums[1], sums[2]
        ph[k] = sums[3] + 1j * sums[4]
    return power, m1, m2, ph, hist


__all__ = ["Geometry", "EmitterState", "prepare", "emitter_state", "receiver_link",
           "material_extra", "THETA_OPEN", "THETA_OPEN_MAPS"]
