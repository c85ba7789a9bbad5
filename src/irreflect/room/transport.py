"""Compiled kernels of the recursive method: light carried from the emitter to the surface
cells, from cells to cells (once per emitter, for every receiver at once) and gathered by
each receiver (numba, see :mod:`.engine` for the method).

State. The light that *arrives* at the cells after ``k`` reflections is an
:class:`Arrivals`: per cell its power, delay moments (power x delay, power x delay^2), phasor,
earliest arrival, the scalars of the separable diffuse terms ``e_p = sum P_in amp_p cos^p
theta_in g(theta_in)`` (so that what a cell re-emits through those terms is exact whatever
the incidence), the power times the albedo at its incidence (the power reflected next),
for ``k = 1`` the delay histogram, and for cells whose material has lobes a map of where
the light came from (res x res equal-solid-angle bins of the
hemisphere, Shirley-Chiu's concentric map of the equal-area disk). What leaves the cells
is a :class:`Sources`: the same per node of a quadtree over every surface (cells are its
leaves) and, for lobed cells, the outgoing intensity map ``map @ K`` (``K``: the material's
lobes integrated over each bin, :func:`lobe_matrix`).

Geometry. A transfer between a source (cell or node) and a cell uses the centre of each
when they are far apart; the point value is then corrected by the ratio of a 2 x 2 Gauss
quadrature of both rectangles' Lambertian coupling to its point value when they are closer
than :data:`FAR` sizes; closer than :data:`NEAR` sizes both cells are split into Gauss
points (the light of each sub-pair deposited with its own direction and delay), and the
Lambertian part is scaled to the exact rectangle-to-rectangle form factor (contour
integral, :func:`rect_coupling`). Nodes of the quadtree stand for their cells when they look
smaller than ``theta_open`` radians from the receiving cell (Barnes-Hut), see
:func:`transfer`.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba import njit

from .kernels import (
    C_LIGHT,
    KIND_RECIPROCAL,
    N_VALUES,
    TERM_DIFFUSE,
    TERM_MIRROR,
    TWO_PI,
    _interp_gamma,
    _intersect,
    cap_at,
    comp,
    dot,
    half_cos,
    hot,
    material_value,
    mirror,
    occluded,
    pow_p,
    w_factor,
)
from .maps import from_square, map_bin, map_lookup, map_res, map_splat, to_square

#: bins per side of the direction maps (res^2 equal solid-angle bins over the hemisphere):
#: at most MAP_RES, at least MAP_RES_MIN; the scene's sharpest significant lobe sets it
#: (:func:`irreflect.room.recursive.map_resolution`); the kernels read it from the maps' size
MAP_RES = 40
MAP_RES_MIN = 16
#: closer than NEAR sizes (the longer side): both cells split into Gauss points; farther: the
#: point coupling with its second-order correction (:func:`taylor`)
NEAR = 3.0
#: average a map over the cells it is seen across (see :func:`lobe_split`)
MAP_SPLIT = False
#: Gauss points per side at most
SUB_MAX = 6
#: the per-pair helpers, inlined into their callers by numba (calls that pass the packed
#: tables cost more than the helpers' arithmetic)
hot_inline = njit(cache=True, nogil=True, _nrt=False, error_model="numpy", inline="always")
#: scalars of the separable diffuse terms (one per P_EXPONENTS)
N_P = 7

#: surface cells: ``pos`` (N, 3) centre, ``nrm`` (N, 3) normal into the room, ``area`` (N,),
#: ``mat`` (N,), ``surf`` (N,) surface index, ``half`` (N, 2) half-sizes along the surface's
#: two axes ``axes[:, 0:2]`` (global axis indices), ``axes[:, 2]`` the normal axis; ``boxes``
#: (B, 2, 3) the scene's boxes (what can hide one point from another)
CellPack = namedtuple("CellPack", ["pos", "nrm", "area", "mat", "surf", "half", "axes", "boxes"])
#: quadtree over every surface: nodes 0..N-1 are the cells; ``lo``/``hi`` (Nn, 3) the node's
#: box, ``child`` (Nn, 9) (-1: none; up to 3 x 3 children, see ``geometry.build_tree``), ``surf`` (Nn,), ``root`` (S,) the root of each surface,
#: ``size`` (Nn,) the node's longest side, ``leaf`` (Nn,) a cell below it (its surface's
#: material, normal and frame)
Tree = namedtuple("Tree", ["lo", "hi", "child", "surf", "root", "size", "leaf"])
#: the surfaces' grids, to find the cell a ray hits: per surface ``axes`` (S, 3) [normal axis,
#: u axis, v axis], ``geo`` (S, 4) [u0, v0, du, dv], ``dims`` (S, 2) [nu, nv], ``offset`` (S,)
#: into ``grid`` (cell index or -1 per grid slot); ``boxsurf`` (B, 6) the surface of each box
#: face (-1: on a room face), ``size`` (3,) the room
Faces = namedtuple("Faces", ["axes", "geo", "dims", "offset", "grid", "boxsurf", "size"])
#: per material: ``damp`` (M, N_P) amplitudes of the diffuse terms, ``lobed`` (M,) 1 when
#: light goes through direction maps, ``kmat`` (M, D, D) lobe matrices (zeros when unused),
#: ``plain`` (M,) 1 for Lambertian materials, ``rhocos`` (M, N_COS) the albedo over cos theta,
#: ``pmax`` (M,) the highest diffuse term (index into P_EXPONENTS) with a non-zero amplitude,
#: ``nmax`` (M,) the largest lobe index (0: no lobes)
MatExtra = namedtuple("MatExtra", ["damp", "lobed", "kmat", "plain", "rhocos", "pmax", "nmax"])
#: light arriving at the cells (see the module docstring); ``hist`` (N, T) or (N, 0),
#: ``amap`` (R, D) with ``arow`` (N,) the map row of each cell (-1: none)
Arrivals = namedtuple("Arrivals", ["power", "m1", "m2", "ph", "t0", "e", "refl", "hist",
                                   "amap", "arow"])
#: light leaving nodes: per node ``power``, ``m1``, ``m2``, ``ph``, ``t0``, ``e``, ``cen``
#: (power-weighted centre); ``orow`` (Nn,) row of ``out`` (R, D) the outgoing intensity map;
#: ``edir`` (N, 3) the incidence of light straight from the emitter (order 0); ``spread``
#: (Nn, 3) the power-weighted second moments of the node's light about ``cen`` along its
#: surface's two axes (s11, s22, s12); ``tn`` (Nn, 5) its delay statistics per unit power
#: (mean, mean square, phasor re, im, earliest); ``epos`` (8,) the emitter: position,
#: axis, Lambertian order, power
Sources = namedtuple("Sources", ["power", "m1", "m2", "ph", "t0", "e", "cen", "orow", "out",
                                 "edir", "spread", "tn", "epos"])
#: normalised delay histograms per cell, ragged: cell j's bins ``start[j] .. start[j] +
#: count[j]`` are ``data[offset[j] .. offset[j] + count[j]]``
Shapes = namedtuple("Shapes", ["data", "offset", "start", "count"])
#: scalar settings: bin width ``dt`` (s), ``omega`` (rad/s), ``theta_open`` (rad), ``order0``
#: (1: the sources were lit straight by the emitter), ``hist_on`` (1: deposit delay bins),
#: ``rays`` (1: the lobes of order-0 sources travel by :func:`lobe_rays`, pairs carry the rest)
Knobs = namedtuple("Knobs", ["dt", "omega", "theta_open", "order0", "hist_on", "rays"])
#: Gauss-Legendre nodes on [-1/2, 1/2] and weights (sum 1) for 1..SUB_MAX points
_GX = np.zeros((SUB_MAX + 1, SUB_MAX))
_GW = np.zeros((SUB_MAX + 1, SUB_MAX))
for _s in range(1, SUB_MAX + 1):
    _x, _w = np.polynomial.legendre.leggauss(_s)
    _GX[_s, :_s] = _x / 2
    _GW[_s, :_s] = _w / 2


@hot
def local(cells, j, w):
    """World direction ``w`` in cell ``j``'s frame (its surface's two axes and normal)."""
    a1 = cells.axes[j, 0]
    a2 = cells.axes[j, 1]
    return comp(w, a1), comp(w, a2), dot(w, (cells.nrm[j, 0], cells.nrm[j, 1], cells.nrm[j, 2]))


# ----------------------------------------------------------------------------- lobe matrix
@njit(cache=True)
def lobe_matrix(mats, m, res, kin):
    """``K`` (D, D): the outgoing intensity at the centre of out-bin b' per unit power
    arriving in in-bin b (normal +z), for the non-separable part of material ``m``.

    Reciprocal materials: every lobe term is integrated over the incident directions by a
    quadrature in its own coordinates about the mirror (retro) direction of the outgoing
    one, each quadrature point spread over the in-bins by the bilinear weights that the
    arrival maps use; then each row is scaled to the term sum's exact albedo at the in-bin's
    centre (``kin`` (D,) cos theta of the in-bins, the caller's). The paper's form (kinds 1,
    2): ``material_value`` averaged over 4 x 4 points of each in-bin, rows scaled to the
    material's albedo.
    """
    D = res * res
    K = np.zeros((D, D))
    omega_bin = TWO_PI / D
    if mats.kind[m] == KIND_RECIPROCAL:
        for bo in range(D):
            ox, oy, oz = from_square((bo // res + 0.5) / res, (bo % res + 0.5) / res)
            o = (ox, oy, oz)
            n = (0.0, 0.0, 1.0)
            go = cap_at(mats.gcos[m], oz)
            for t in range(mats.nterms[m]):
                kind = mats.tkind[m, t]
                if kind == TERM_DIFFUSE:
                    continue
                # the lobe narrowed by the spread the maps add (a bin's width, uniformly, where
                # light arrives and again where it leaves: variance bin^2 / 6 per axis)
                nn = N_VALUES[mats.tidx[m, t]]
                sharp = 1.0 / (nn + 1.0) - omega_bin / 6.0
                nn = 1.0 / sharp - 1.0 if sharp > 1.0 / (4.0 * (nn + 1.0)) else 4.0 * nn + 3.0
                axis = mirror(o, n) if kind == TERM_MIRROR else o
                # points about the axis: enough to put several in every bin the lobe covers
                psi90 = math.acos(min(0.1 ** (1.0 / (nn + 1.0)), 1.0))
                step = math.sqrt(omega_bin)
                n_t = min(max(int(2.0 * psi90 / step) + 2, 4), 40)
                n_a = min(max(int(TWO_PI * math.sin(psi90) / step) + 4, 8), 96)
                scale = mats.tamp[m, t] * TWO_PI / (nn + 1.0) * oz * go / n_a / omega_bin
                for it in range(n_t):
                    tt = (it + 0.5) / n_t
                    cpsi = tt ** (1.0 / (nn + 1.0))
                    for ia in range(n_a):
                        w = _cone_about(axis, n, cpsi, TWO_PI * (ia + 0.5) / n_a)
                        if w[2] <= 0.0:
                            continue
                        val = scale / n_t * cap_at(mats.gcos[m], w[2])
                        if kind == TERM_MIRROR:
                            val *= w_factor(mats.tq[m, t], half_cos(w, o))
                        u, v = to_square(w[0], w[1], w[2])
                        K[map_bin(u, v, res), bo] += val
        # rows to the exact albedo of the lobe terms at the in-bin's centre
        for b in range(D):
            g = math.acos(min(max(kin[b], 0.0), 1.0))
            target = 0.0
            for t in range(mats.nterms[m]):
                if mats.tkind[m, t] != TERM_DIFFUSE:
                    target += _interp_gamma(mats.talb[m], t, g)
            target *= cap_at(mats.gcos[m], kin[b])
            got = 0.0
            for bo in range(D):
                got += K[b, bo] * omega_bin
            if got > 0.0:
                f = target / got
                for bo in range(D):
                    K[b, bo] *= f
        return K
    # the paper's form
    sub = 4
    n = (0.0, 0.0, 1.0)
    for b in range(D):
        bi = b // res
        bj = b % res
        for si in range(sub):
            for sj in range(sub):
                wx, wy, wz = from_square((bi + (si + 0.5) / sub) / res, (bj + (sj + 0.5) / sub) / res)
                d = (-wx, -wy, -wz)
                for bo in range(D):
                    ox, oy, oz = from_square((bo // res + 0.5) / res, (bo % res + 0.5) / res)
                    K[b, bo] += material_value(mats, m, d, n, (ox, oy, oz)) / (sub * sub)
        g = math.acos(min(max(kin[b], 0.0), 1.0))
        target = _interp_gamma(mats.rhotab, m, g)
        got = 0.0
        for bo in range(D):
            got += K[b, bo] * omega_bin
        if got > 0.0:
            for bo in range(D):
                K[b, bo] *= target / got
    return K


@hot
def _cone_about(a, n, cos_psi, az):
    """Direction at angle ``acos(cos_psi)`` from unit ``a`` and azimuth ``az`` measured from
    the plane of ``a`` and the surface normal ``n`` (the plane of incidence). The frame turns
    with the geometry: a mirror image of the scene gives the mirror image of the directions
    of a turn set symmetric under ``az -> -az``, so mirror-symmetric rooms get
    mirror-symmetric results (a fixed frame broke this by up to 0.8 % at order 2). Falls
    back to :func:`_cone` when ``a`` is along ``n``."""
    c = a[0] * n[0] + a[1] * n[1] + a[2] * n[2]
    tx = n[0] - c * a[0]
    ty = n[1] - c * a[1]
    tz = n[2] - c * a[2]
    tn = math.sqrt(tx * tx + ty * ty + tz * tz)
    if tn < 1e-9:
        return _cone(a, cos_psi, az)
    return _cone_in(a, tx / tn, ty / tn, tz / tn, cos_psi, az)


@hot
def _cone(a, cos_psi, az):
    """As :func:`_cone_about`, azimuth from a tangent fixed by ``a`` alone."""
    if abs(a[2]) < 0.9:
        tx, ty, tz = -a[1], a[0], 0.0
    else:
        tx, ty, tz = 0.0, -a[2], a[1]
    tn = math.sqrt(tx * tx + ty * ty + tz * tz)
    return _cone_in(a, tx / tn, ty / tn, tz / tn, cos_psi, az)


@hot
def _cone_in(a, tx, ty, tz, cos_psi, az):
    """Direction at angle ``acos(cos_psi)`` from unit ``a``, azimuth ``az`` from the unit
    tangent ``t`` (perpendicular to ``a``) toward ``a x t``."""
    bx = a[1] * tz - a[2] * ty
    by = a[2] * tx - a[0] * tz
    bz = a[0] * ty - a[1] * tx
    s = math.sqrt(max(0.0, 1.0 - cos_psi * cos_psi))
    c1 = math.cos(az) * s
    s1 = math.sin(az) * s
    return (cos_psi * a[0] + c1 * tx + s1 * bx, cos_psi * a[1] + c1 * ty + s1 * by,
            cos_psi * a[2] + c1 * tz + s1 * bz)


# ----------------------------------------------------------------------------- form factors
@hot
def _psi(u, h):
    r2 = u * u + h * h
    lg = math.log(r2) if r2 > 0.0 else 0.0
    at = h * u * math.atan(u / h) if h > 0.0 else 0.0
    return 0.25 * (u * u - h * h) * lg - 0.75 * u * u + at


@hot
def _offset(p, a, delta):
    """Point ``p`` moved by ``delta`` along global axis ``a``."""
    if a == 0:
        return (p[0] + delta, p[1], p[2])
    if a == 1:
        return (p[0], p[1] + delta, p[2])
    return (p[0], p[1], p[2] + delta)


@hot
def _corner(cells, j, k):
    """Corner k (0..3, counter-clockwise in the surface's axes) of cell j."""
    s1 = -1.0 if (k == 0 or k == 3) else 1.0
    s2 = -1.0 if k < 2 else 1.0
    c = (cells.pos[j, 0], cells.pos[j, 1], cells.pos[j, 2])
    c = _offset(c, cells.axes[j, 0], s1 * cells.half[j, 0])
    return _offset(c, cells.axes[j, 1], s2 * cells.half[j, 1])


@hot
def _handed(cells, j):
    """+1 when axes (a1, a2, normal) are right-handed, else -1."""
    a1 = cells.axes[j, 0]
    a2 = cells.axes[j, 1]
    a3 = cells.axes[j, 2]
    # e_a1 x e_a2 = +e_a3 for (0,1,2) cyclic orders, -e_a3 otherwise
    cyc = 1.0 if (a1 + 1) % 3 == a2 else -1.0
    return 1.0 if cyc * cells.nrm[j, a3] > 0 else -1.0


@hot
def rect_coupling(cells, j, dst):
    """``int int cos cos / r^2 dA_j dA_l`` between cells ``j`` and ``dst`` (m^2, = pi A_j F_jl),
    exact for axis-aligned rectangles in full view of each other (contour integral: only
    the parallel edges contribute, each pair in closed form)."""
    total = 0.0
    hj = _handed(cells, j)
    hl = _handed(cells, dst)
    for ka in range(4):
        p0 = _corner(cells, j, ka if hj > 0 else 3 - ka)
        p1 = _corner(cells, j, (ka + 1) % 4 if hj > 0 else (3 - (ka + 1) % 4))
        ax = 0
        for a in range(1, 3):
            if abs(comp(p1, a) - comp(p0, a)) > abs(comp(p1, ax) - comp(p0, ax)):
                ax = a
        s1 = 1.0 if comp(p1, ax) > comp(p0, ax) else -1.0
        al0 = min(comp(p0, ax), comp(p1, ax))
        al1 = max(comp(p0, ax), comp(p1, ax))
        for kb in range(4):
            q0 = _corner(cells, dst, kb if hl > 0 else 3 - kb)
            q1 = _corner(cells, dst, (kb + 1) % 4 if hl > 0 else (3 - (kb + 1) % 4))
            if abs(comp(q1, ax) - comp(q0, ax)) < 1e-12:
                continue
            s2 = 1.0 if comp(q1, ax) > comp(q0, ax) else -1.0
            be0 = min(comp(q0, ax), comp(q1, ax))
            be1 = max(comp(q0, ax), comp(q1, ax))
            h2 = 0.0
            for a in range(3):
                if a != ax:
                    h2 += (comp(p0, a) - comp(q0, a)) ** 2
            h = math.sqrt(h2)
            integral = -(_psi(al1 - be1, h) - _psi(al1 - be0, h) - _psi(al0 - be1, h)
                         + _psi(al0 - be0, h))
            total += s1 * s2 * integral
    return 0.5 * total  # (1/2pi) * pi: pi A_j F_jl


@hot_inline
def _term_ray(axis, cpsi, turn, n, i, mats, m, t, kind):
    """One quadrature direction of a lobe term around ``axis`` and its weight (cosine at
    the surface, share cap, the mirror term's facet factor; -1 below the surface): the same
    in the pass that sums the quadrature and in the pass that deposits."""
    o = _cone_about(axis, n, cpsi, TWO_PI * turn)
    co = dot(o, n)
    if co <= 0.0:
        return o, -1.0
    w = co * cap_at(mats.gcos[m], co)
    if kind == TERM_MIRROR:
        w *= w_factor(mats.tq[m, t], half_cos(i, o))
    return o, w


@hot
def _sub_point(cells, j, s, k):
    """Gauss point ``k`` of ``s x s`` on cell ``j``: (position, weight fraction)."""
    i1 = k // s
    i2 = k % s
    p = (cells.pos[j, 0], cells.pos[j, 1], cells.pos[j, 2])
    p = _offset(p, cells.axes[j, 0], 2.0 * cells.half[j, 0] * _GX[s, i1])
    p = _offset(p, cells.axes[j, 1], 2.0 * cells.half[j, 1] * _GX[s, i2])
    return p, _GW[s, i1] * _GW[s, i2]


@hot
def _rect_point(lo, hi, nrm_axis, s, k):
    """Gauss point ``k`` of ``s x s`` on the axis-aligned rectangle [lo, hi] (flat along
    ``nrm_axis``): (position, weight fraction)."""
    a1 = 1 if nrm_axis == 0 else 0
    a2 = 1 if nrm_axis == 2 else 2
    i1 = k // s
    i2 = k % s
    p = (0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2]))
    p = _offset(p, a1, (hi[a1] - lo[a1]) * _GX[s, i1])
    p = _offset(p, a2, (hi[a2] - lo[a2]) * _GX[s, i2])
    return p, _GW[s, i1] * _GW[s, i2]


@hot
def _kernel(x, nx, y, ny):
    """``cos cos / r^2`` between points x (normal nx) and y (normal ny), 0 if back-facing."""
    v = (y[0] - x[0], y[1] - x[1], y[2] - x[2])
    d2 = dot(v, v)
    if d2 <= 0.0:
        return 0.0
    co = dot(nx, v)
    ci = -dot(ny, v)
    if co <= 0.0 or ci <= 0.0:
        return 0.0
    return co * ci / (d2 * d2)


# ----------------------------------------------------------------------------- the two helpers
@hot
def pair(x, y, nx, ny):
    """Geometry from point ``x`` (normal ``nx``) to point ``y`` (normal ``ny``): distance,
    unit direction x -> y, cos at x, cos at y (<= 0 when either faces away)."""
    v = (y[0] - x[0], y[1] - x[1], y[2] - x[2])
    d = math.sqrt(dot(v, v))
    if d <= 0.0:
        return 0.0, (0.0, 0.0, 0.0), -1.0, -1.0
    u = (v[0] / d, v[1] / d, v[2] / d)
    return d, u, dot(nx, u), -dot(ny, u)


@hot_inline
def deposit(arr, ext, mats, cells, dst, c, tstat, back, knobs, with_map):
    """Add power ``c`` (W) arriving at cell ``dst`` to its :class:`Arrivals`.

    ``tstat = (mean delay, mean squared delay, phasor re, phasor im, earliest delay)`` of the
    light when it arrives (per unit power); ``back`` the unit direction from ``dst`` towards
    where the light came from (world frame); ``with_map``: also add it to the cell's direction
    map (else the caller spreads it, :func:`map_footprint`).
    """
    mean, sq, pre, pim, first = tstat
    arr.power[dst] += c
    arr.m1[dst] += c * mean
    arr.m2[dst] += c * sq
    arr.ph[dst, 0] += c * pre
    arr.ph[dst, 1] += c * pim
    if first < arr.t0[dst]:
        arr.t0[dst] = first
    if knobs.hist_on:
        b = int(mean / knobs.dt)
        if b < arr.hist.shape[1]:
            arr.hist[dst, b] += c
    m = cells.mat[dst]
    ci = min(max(back[0] * cells.nrm[dst, 0] + back[1] * cells.nrm[dst, 1]
                 + back[2] * cells.nrm[dst, 2], 0.0), 1.0)
    if ext.plain[m]:
        arr.e[dst, 0] += c * ext.damp[m, 0]
        arr.refl[dst] += c * ext.rhocos[m, 0]
    else:
        g = cap_at(mats.gcos[m], ci) if mats.kind[m] == KIND_RECIPROCAL else 1.0
        for p in range(ext.pmax[m] + 1):
            a = ext.damp[m, p]
            if a > 0.0:
                arr.e[dst, p] += c * a * pow_p(ci, p) * g
        arr.refl[dst] += c * cap_at(ext.rhocos[m], ci)
    r = arr.arow[dst]
    if r >= 0 and with_map:
        x, y, z = local(cells, dst, back)
        u, v = to_square(x, y, z)
        map_splat(arr.amap[r], u, v, c)


@hot
def map_footprint(arr, cells, dst, c, rect, x0):
    """Add power ``c`` to cell ``dst``'s direction map spread over the source it came from:
    ``rect = (lo, hi, normal axis)`` the source's rectangle (a cell or a node), ``x0`` its
    centre; split into k x k Gauss points when it looks wider than a bin (so that a regular
    lattice of sources does not leave empty and doubled bins)."""
    r = arr.arow[dst]
    if r < 0:
        return
    lo, hi, nax = rect
    y = (cells.pos[dst, 0], cells.pos[dst, 1], cells.pos[dst, 2])
    v = (x0[0] - y[0], x0[1] - y[1], x0[2] - y[2])
    d = math.sqrt(dot(v, v))
    ext = 0.0
    for a in range(3):
        ext = max(ext, hi[a] - lo[a])
    bin_angle = math.sqrt(TWO_PI / arr.amap.shape[1])
    k = min(max(int(math.ceil(1.5 * ext / max(d, 1e-12) / bin_angle)), 1), SUB_MAX)
    if k == 1:
        x, yy, z = local(cells, dst, (v[0] / d, v[1] / d, v[2] / d))
        u, w = to_square(x, yy, z)
        map_splat(arr.amap[r], u, w, c)
        return
    for q in range(k * k):
        p, wq = _rect_point(lo, hi, nax, k, q)
        b = (p[0] - y[0], p[1] - y[1], p[2] - y[2])
        nb = math.sqrt(dot(b, b))
        x, yy, z = local(cells, dst, (b[0] / nb, b[1] / nb, b[2] / nb))
        if z <= 0.0:
            continue
        u, w = to_square(x, yy, z)
        map_splat(arr.amap[r], u, w, c * wq)


@hot
def _shift(tstat, tau, omega):
    """Delay statistics after a further flight of ``tau`` seconds."""
    mean, sq, pre, pim, first = tstat
    cr = 1.0
    cim = 0.0
    if omega > 0.0:
        cr = math.cos(omega * tau)
        cim = -math.sin(omega * tau)
    return (mean + tau, sq + 2.0 * mean * tau + tau * tau, pre * cr - pim * cim,
            pre * cim + pim * cr, first + tau)


@hot
def _tstat(src, J):
    return src.tn[J, 0], src.tn[J, 1], src.tn[J, 2], src.tn[J, 3], src.tn[J, 4]


@hot_inline
def emit(src, ext, mats, cells, j, x, u, co, knobs):
    """Intensity (W/sr) leaving cell ``j`` from its point ``x`` along unit ``u`` (``co`` = cos
    to its normal): (Lambertian part, the rest). Order 0 (``knobs.order0``) lobed cells
    re-emit their emitter light with the exact BRDF at its incidence at ``x`` (from the
    emitter at ``src.epos``)."""
    if co <= 0.0:
        return 0.0, 0.0
    m = cells.mat[j]
    if exact_order0(knobs, ext, mats, m):
        lam = src.e[j, 0] * co * _cap(mats, m, co)
        n = (cells.nrm[j, 0], cells.nrm[j, 1], cells.nrm[j, 2])
        power = src.power[j]
        dv = (x[0] - src.epos[0], x[1] - src.epos[1], x[2] - src.epos[2])
        dn = math.sqrt(dot(dv, dv))
        d = (dv[0] / dn, dv[1] / dn, dv[2] / dn)
        ce = d[0] * src.epos[3] + d[1] * src.epos[4] + d[2] * src.epos[5]
        cc = -dot(d, n)
        if ce > 0.0 and cc > 0.0:
            # the emitter's irradiance at x, not the cell's mean
            order = src.epos[6]
            power = (src.epos[7] * (order + 1.0) / TWO_PI * math.exp(order * math.log(ce))
                     * cc / (dn * dn) * cells.area[j])
            lam = lam * power / src.power[j]
        return lam, power * material_value(mats, m, d, n, u) - lam
    lam, rest = emit_diffuse(src, mats, m, j, co)
    r = src.orow[j]
    if r >= 0 and not knobs.rays:
        x, y, z = local(cells, j, u)
        uu, vv = to_square(x, y, z)
        rest += map_lookup(src.out[r], uu, vv)
    return lam, rest


@hot
def _cap(mats, m, c):
    return cap_at(mats.gcos[m], c) if mats.kind[m] == KIND_RECIPROCAL else 1.0


@hot
def exact_order0(knobs, ext, mats, m):
    """Whether a pair carries the whole light of a lobed cell lit straight by the emitter
    (its exact BRDF at the exact incidence): yes unless :func:`lobe_rays` carries the lobes
    (reciprocal materials, ``knobs.rays``)."""
    return knobs.order0 and ext.lobed[m] and not (knobs.rays and mats.kind[m] == KIND_RECIPROCAL)


@hot
def lobe_split(ext, mats, cells, src, knobs, j, size, d):
    """Gauss points per side over which the lobes of cell ``j``'s outgoing light are averaged
    when seen across ``size`` at distance ``d``: for the exact BRDF, points a third of the
    sharpest lobe's width apart (its index ``ext.nmax``); for a map, a bin apart."""
    m = cells.mat[j]
    if exact_order0(knobs, ext, mats, m):
        n = ext.nmax[m]
        if n <= 0.0:
            return 1
        return min(max(int(math.ceil(1.5 * size / d * math.sqrt(n + 1.0))), 1), SUB_MAX)
    if src.orow[j] >= 0 and MAP_SPLIT:  # a map: its features are a bin wide at most
        return min(max(int(math.ceil(size / d / math.sqrt(TWO_PI / src.out.shape[1]))), 1),
                   SUB_MAX)
    return 1


@hot
def emit_diffuse(src, mats, m, J, co):
    """The separable diffuse terms' intensity from node ``J`` (material ``m``):
    (Lambertian part, the rest)."""
    g = _cap(mats, m, co)
    rest = 0.0
    for p in range(1, N_P):
        if src.e[J, p] != 0.0:
            rest += src.e[J, p] * pow_p(co, p)
    return src.e[J, 0] * co * g, rest * co * g


# ----------------------------------------------------------------------------- transfer
@hot
def _behind(tree, J, x, n):
    """-1: node J entirely behind the plane (x, n); 0 straddling; 1 entirely in front."""
    lo_d = 1e300
    hi_d = -1e300
    for k in range(8):
        p0 = tree.lo[J, 0] if (k & 1) == 0 else tree.hi[J, 0]
        p1 = tree.lo[J, 1] if (k & 2) == 0 else tree.hi[J, 1]
        p2 = tree.lo[J, 2] if (k & 4) == 0 else tree.hi[J, 2]
        s = (p0 - x[0]) * n[0] + (p1 - x[1]) * n[1] + (p2 - x[2]) * n[2]
        lo_d = min(lo_d, s)
        hi_d = max(hi_d, s)
    if hi_d <= 1e-12:
        return -1
    if lo_d >= -1e-12:
        return 1
    return 0


@hot
def _maybe_blocked(tree, J, y, boxes):
    """Whether a box could cut a segment between node J and point y (their joint bounding
    box meets a box's interior)."""
    for b in range(boxes.shape[0]):
        hit = True
        for a in range(3):
            lo = min(tree.lo[J, a], comp(y, a))
            hi = max(tree.hi[J, a], comp(y, a))
            if hi <= boxes[b, 0, a] + 1e-9 or lo >= boxes[b, 1, a] - 1e-9:
                hit = False
                break
        if hit:
            return True
    return False


@hot
def taylor(x, nx, xa, sig, y, ny, ya, yh):
    """Second-order correction of the point coupling ``cos cos / r^2`` between a source
    spread about ``x`` (normal ``nx``, in-plane axes ``xa``, power-weighted second moments
    ``sig = (s11, s22, s12)`` along them) and a uniform rectangle about ``y`` (normal ``ny``,
    axes ``ya``, half-sides ``yh``): the factor ``1 + sum of sigma K'' / 2K`` (the first
    moments vanish about the centroid), clamped to [1/4, 4]. Its error falls as
    (size / distance)^4: under 0.5 % at three sizes, 0.1 % at five."""
    v = (y[0] - x[0], y[1] - x[1], y[2] - x[2])
    r2 = dot(v, v)
    A = dot(nx, v)
    B = -dot(ny, v)
    if A <= 0.0 or B <= 0.0:
        return 1.0
    inv = 1.0 / r2
    corr = 1.0
    b1 = comp(ny, xa[0])
    b2 = comp(ny, xa[1])
    g1 = -comp(v, xa[0])  # d|v|^2 / ds along +t is -2 v.t
    g2 = -comp(v, xa[1])
    k11 = -8.0 * b1 * g1 * inv / B + 24.0 * g1 * g1 * inv * inv - 4.0 * inv
    k22 = -8.0 * b2 * g2 * inv / B + 24.0 * g2 * g2 * inv * inv - 4.0 * inv
    k12 = -4.0 * (b1 * g2 + b2 * g1) * inv / B + 24.0 * g1 * g2 * inv * inv
    corr += 0.5 * (sig[0] * k11 + sig[1] * k22) + sig[2] * k12
    a = comp(nx, ya[0])
    g = comp(v, ya[0])
    corr += 0.5 * (yh[0] * yh[0] / 3.0) * (-8.0 * a * g * inv / A + 24.0 * g * g * inv * inv
                                           - 4.0 * inv)
    a = comp(nx, ya[1])
    g = comp(v, ya[1])
    corr += 0.5 * (yh[1] * yh[1] / 3.0) * (-8.0 * a * g * inv / A + 24.0 * g * g * inv * inv
                                           - 4.0 * inv)
    return min(max(corr, 0.25), 4.0)


@hot
def transfer(l0, l1, cells, tree, mats, ext, src, arr, knobs, stack):
    """Carry the light leaving every source node to cells ``l0..l1`` (one more leg).

    For each receiving cell the quadtree of every other surface it faces is walked from the
    root: a node is used as one source when it looks smaller than ``theta_open`` (its
    longest side over its distance), is farther than NEAR sizes of the receiving cell,
    lies wholly in front of the cell, no box can cut the way and its light is a sum over
    its cells (not for light straight from the emitter on lobed materials); otherwise its
    children are visited.
    ``stack``: int64 work space (4096).
    """
    N = cells.pos.shape[0]
    S = tree.root.shape[0]
    boxes = cells.boxes
    has_boxes = boxes.shape[0] > 0
    for dst in range(l0, l1):
        y = (cells.pos[dst, 0], cells.pos[dst, 1], cells.pos[dst, 2])
        ny = (cells.nrm[dst, 0], cells.nrm[dst, 1], cells.nrm[dst, 2])
        size_l = 2.0 * max(cells.half[dst, 0], cells.half[dst, 1])
        for s in range(S):
            if s == cells.surf[dst]:
                continue
            J = tree.root[s]
            if _behind(tree, J, y, ny) < 0:
                continue
            stack[0] = J
            top = 1
            while top > 0:
                top -= 1
                J = stack[top]
                if src.power[J] <= 0.0:
                    continue
                if J < N:
                    _cell_to_cell(cells, tree, mats, ext, src, arr, knobs, boxes, J, dst)
                    continue
                m = cells.mat[tree.leaf[J]]
                v = (src.cen[J, 0] - y[0], src.cen[J, 1] - y[1], src.cen[J, 2] - y[2])
                dist = math.sqrt(dot(v, v))
                split = (tree.size[J] > knobs.theta_open * dist
                         or dist < NEAR * size_l
                         or exact_order0(knobs, ext, mats, m))
                if not split:
                    side = _behind(tree, J, y, ny)
                    if side < 0:
                        continue
                    split = side == 0 or (has_boxes and _maybe_blocked(tree, J, y, boxes))
                if split:
                    for k in range(tree.child.shape[1]):
                        ch = tree.child[J, k]
                        if ch >= 0:
                            stack[top] = ch
                            top += 1
                    continue
                _node_to_cell(cells, tree, mats, ext, src, arr, knobs, J, dst)


@hot
def _axes2(cells, j):
    return (cells.axes[j, 0], cells.axes[j, 1])


@hot_inline
def _node_to_cell(cells, tree, mats, ext, src, arr, knobs, J, dst):
    """One inner node J as a single source for cell dst (far field): the point coupling at
    J's power-weighted centre with the second-order correction of :func:`taylor`."""
    x = (src.cen[J, 0], src.cen[J, 1], src.cen[J, 2])
    y = (cells.pos[dst, 0], cells.pos[dst, 1], cells.pos[dst, 2])
    f = tree.leaf[J]
    nx = (cells.nrm[f, 0], cells.nrm[f, 1], cells.nrm[f, 2])
    ny = (cells.nrm[dst, 0], cells.nrm[dst, 1], cells.nrm[dst, 2])
    d, u, co, ci = pair(x, y, nx, ny)
    if co <= 0.0 or ci <= 0.0:
        return
    lam, rest = emit_diffuse(src, mats, cells.mat[f], J, co)
    r = src.orow[J]
    if r >= 0 and not knobs.rays:
        xl, yl, zl = local(cells, f, u)
        uu, vv = to_square(xl, yl, zl)
        rest += map_lookup(src.out[r], uu, vv)
    corr = taylor(x, nx, _axes2(cells, f), (src.spread[J, 0], src.spread[J, 1], src.spread[J, 2]),
                  y, ny, _axes2(cells, dst), (cells.half[dst, 0], cells.half[dst, 1]))
    c = (lam + rest) * cells.area[dst] * ci / (d * d) * corr
    if c > 0.0:
        deposit(arr, ext, mats, cells, dst, c, _shift(_tstat(src, J), d / C_LIGHT, knobs.omega),
                (-u[0], -u[1], -u[2]), knobs, False)
        map_footprint(arr, cells, dst, c, (tree.lo[J], tree.hi[J], cells.axes[f, 2]), x)


@hot_inline
def _cell_to_cell(cells, tree, mats, ext, src, arr, knobs, boxes, j, dst):
    """Cell j as source for cell dst: the point pair with the second-order correction of
    :func:`taylor` when farther than NEAR sizes, else Gauss sub-pairs with the Lambertian
    part scaled to the exact rectangle coupling (:func:`rect_coupling`)."""
    xj = (cells.pos[j, 0], cells.pos[j, 1], cells.pos[j, 2])
    yl = (cells.pos[dst, 0], cells.pos[dst, 1], cells.pos[dst, 2])
    nx = (cells.nrm[j, 0], cells.nrm[j, 1], cells.nrm[j, 2])
    ny = (cells.nrm[dst, 0], cells.nrm[dst, 1], cells.nrm[dst, 2])
    d, u, co, ci = pair(xj, yl, nx, ny)
    size = max(tree.size[j], tree.size[dst])
    has_boxes = boxes.shape[0] > 0
    if d >= NEAR * size:
        if co <= 0.0 or ci <= 0.0:
            return
        if has_boxes and occluded(xj, yl, boxes):
            return
        lam, rest = emit(src, ext, mats, cells, j, xj, u, co, knobs)
        hj0 = cells.half[j, 0]
        hj1 = cells.half[j, 1]
        corr = taylor(xj, nx, _axes2(cells, j), (hj0 * hj0 / 3.0, hj1 * hj1 / 3.0, 0.0), yl, ny,
                      _axes2(cells, dst), (cells.half[dst, 0], cells.half[dst, 1]))
        c = (lam + rest) * cells.area[dst] * ci / (d * d) * corr
        sl = lobe_split(ext, mats, cells, src, knobs, j, size, d) if rest > 0.02 * lam else 1
        if sl > 1:
            # a lobe narrower than the cell looks: average it over Gauss points of the cell
            rs = 0.0
            for b in range(sl * sl):
                yb, wb = _sub_point(cells, dst, sl, b)
                db, ub, cob, cib = pair(xj, yb, nx, ny)
                if cob > 0.0 and cib > 0.0:
                    _, rb = emit(src, ext, mats, cells, j, xj, ub, cob, knobs)
                    rs += wb * rb * cib / (db * db)
            c = lam * cells.area[dst] * ci / (d * d) * corr + rs * cells.area[dst]
        if c > 0.0:
            deposit(arr, ext, mats, cells, dst, c, _shift(_tstat(src, j), d / C_LIGHT, knobs.omega),
                    (-u[0], -u[1], -u[2]), knobs, False)
            map_footprint(arr, cells, dst, c, (tree.lo[j], tree.hi[j], cells.axes[j, 2]), xj)
        return
    if _behind(tree, j, yl, ny) < 0 or _behind(tree, dst, xj, nx) < 0:
        return
    tj = _tstat(src, j)
    s = min(max(int(math.ceil(3.0 * size / max(d, 1e-12))), 2), 4)
    s = max(s, lobe_split(ext, mats, cells, src, knobs, j, size, max(d, 0.5 * size)))
    exact = -1.0
    if not (has_boxes and _maybe_blocked(tree, j, yl, boxes)) and \
            _behind(tree, j, yl, ny) > 0 and _behind(tree, dst, xj, nx) > 0:
        exact = rect_coupling(cells, j, dst)
    quad = 0.0
    if exact >= 0.0:
        for a in range(s * s):
            xa, wa = _sub_point(cells, j, s, a)
            for b in range(s * s):
                yb, wb = _sub_point(cells, dst, s, b)
                quad += wa * wb * _kernel(xa, nx, yb, ny)
        quad *= cells.area[j] * cells.area[dst]
    scale = exact / quad if (exact >= 0.0 and quad > 0.0) else 1.0
    if exact >= 0.0 and ext.plain[cells.mat[j]] and ext.plain[cells.mat[dst]] and \
            not knobs.hist_on and src.orow[j] < 0:
        # Lambertian to Lambertian, in full view: the exact coupling as one deposit (where
        # the light came from does not matter to a Lambertian cell)
        c = src.e[j, 0] / cells.area[j] * exact
        if c > 0.0:
            deposit(arr, ext, mats, cells, dst, c, _shift(tj, d / C_LIGHT, knobs.omega),
                    (-u[0], -u[1], -u[2]), knobs, True)
        return
    for a in range(s * s):
        xa, wa = _sub_point(cells, j, s, a)
        for b in range(s * s):
            yb, wb = _sub_point(cells, dst, s, b)
            dd, uu, cco, cci = pair(xa, yb, nx, ny)
            if cco <= 0.0 or cci <= 0.0:
                continue
            if has_boxes and occluded(xa, yb, boxes):
                continue
            lam, rest = emit(src, ext, mats, cells, j, xa, uu, cco, knobs)
            c = (lam * scale + rest) * wa * wb * cells.area[dst] * cci / (dd * dd)
            if c > 0.0:
                deposit(arr, ext, mats, cells, dst, c, _shift(tj, dd / C_LIGHT, knobs.omega),
                        (-uu[0], -uu[1], -uu[2]), knobs, True)


# ----------------------------------------------------------------------------- lobes by rays
@hot
def cell_at(faces, surf, p):
    """The cell of surface ``surf`` at point ``p`` (-1 where a box covers it)."""
    ua = faces.axes[surf, 1]
    va = faces.axes[surf, 2]
    iu = int((comp(p, ua) - faces.geo[surf, 0]) / faces.geo[surf, 2])
    iv = int((comp(p, va) - faces.geo[surf, 1]) / faces.geo[surf, 3])
    iu = min(max(iu, 0), faces.dims[surf, 0] - 1)
    iv = min(max(iv, 0), faces.dims[surf, 1] - 1)
    return faces.grid[faces.offset[surf] + iu * faces.dims[surf, 1] + iv]


@hot
def lobe_rays(j0, j1, cells, faces, mats, ext, src, arr, knobs, budget):
    """The lobes of light straight from the emitter, reflected by lobed cells ``j0..j1``, sent
    along deterministic rays: per lobe term, ``budget`` x its share of the lobes' albedo
    (at least 16) directions stratified in the lobe's own coordinates (uniform in ``cos^(n+1)``
    of the angle from its axis, and in azimuth), from each of the cell's 2 x 2 Gauss points (a quarter each),
    each carrying its share of the term's exact reflected power to the cell it hits (its
    direction and delay exact). A lobe narrower than the cells still lands where it should,
    and every term's power arrives whole. Deposits go to any cell: run on one thread."""
    for j in range(j0, j1):
        m = cells.mat[j]
        if not ext.lobed[m] or src.power[j] <= 0.0 or mats.kind[m] != KIND_RECIPROCAL:
            continue
        n = (cells.nrm[j, 0], cells.nrm[j, 1], cells.nrm[j, 2])
        i = (-src.edir[j, 0], -src.edir[j, 1], -src.edir[j, 2])
        ci = min(max(dot(i, n), 0.0), 1.0)
        if ci <= 0.0:
            continue
        g = math.acos(ci)
        gi = cap_at(mats.gcos[m], ci)
        total_alb = 0.0
        for t in range(mats.nterms[m]):
            if mats.tkind[m, t] != TERM_DIFFUSE:
                total_alb += _interp_gamma(mats.talb[m], t, g)
        if total_alb <= 0.0:
            continue
        tj = _tstat(src, j)
        mi = mirror(i, n)
        for t in range(mats.nterms[m]):
            kind = mats.tkind[m, t]
            if kind == TERM_DIFFUSE:
                continue
            alb = _interp_gamma(mats.talb[m], t, g)
            if alb <= 0.0:
                continue
            nn = N_VALUES[mats.tidx[m, t]]
            rays = max(16, int(budget * alb / total_alb))
            n_a = max(4, int(math.sqrt(rays * 2.0)))
            n_t = max(4, rays // n_a)
            axis = mi if kind == TERM_MIRROR else i
            # first pass: the quadrature's sum, to give the term its exact albedo
            qsum = 0.0
            for it in range(n_t):
                cpsi = ((it + 0.5) / n_t) ** (1.0 / (nn + 1.0))
                for ia in range(n_a):
                    o, w = _term_ray(axis, cpsi, (ia + 0.5 * (it % 2)) / n_a, n, i, mats,
                                     m, t, kind)
                    if w < 0.0:
                        continue
                    qsum += w
            if qsum <= 0.0:
                continue
            unit = src.power[j] * gi * alb / qsum
            for it in range(n_t):
                cpsi = ((it + 0.5) / n_t) ** (1.0 / (nn + 1.0))
                for ia in range(n_a):
                    o, w = _term_ray(axis, cpsi, (ia + 0.5 * (it % 2)) / n_a, n, i, mats,
                                     m, t, kind)
                    if w < 0.0:
                        continue
                    for k in range(4):
                        x, _ = _sub_point(cells, j, 2, k)
                        _ray_deposit(arr, ext, mats, cells, faces, x, n, o, 0.25 * unit * w, tj,
                                     knobs)


@hot
def _face_span(faces, surf, p):
    """The grid slots (iu0, iu1, iv0, iv1) of surface ``surf`` at point ``p``: iu0 == iu1
    unless ``p`` lies within 1e-9 m of the boundary between two columns (then both; the
    same along v), so that a ray landing on a cell boundary is shared between the cells
    whichever way rounding falls (a mirror-symmetric room's rays land on its symmetry lines)."""
    iu0, iu1 = _span1((comp(p, faces.axes[surf, 1]) - faces.geo[surf, 0]), faces.geo[surf, 2],
                      faces.dims[surf, 0])
    iv0, iv1 = _span1((comp(p, faces.axes[surf, 2]) - faces.geo[surf, 1]), faces.geo[surf, 3],
                      faces.dims[surf, 1])
    return iu0, iu1, iv0, iv1


@hot
def _span1(x, width, n):
    """Slot of offset ``x`` on a row of ``n`` slots ``width`` wide: (i, i), or (i - 1, i)
    within 1e-9 m of the boundary between them."""
    f = x / width
    i = min(max(int(f), 0), n - 1)
    r = int(f + 0.5)
    if 0 < r < n and abs(x - r * width) < 1e-9:
        return r - 1, r
    return i, i


@hot_inline
def _ray_surfaces(cells, faces, x, n, o):
    """The surface a ray from ``x`` (lifted 1e-9 m along the normal ``n``) in direction
    ``o`` hits first, a second room face when the hit is on an edge of the room (within
    1e-9 m of it; -1 otherwise), the hit point and the distance; surface -1 when it leaves
    through an opening or hits none."""
    x = (x[0] + 1e-9 * n[0], x[1] + 1e-9 * n[1], x[2] + 1e-9 * n[2])
    dist, _, box, face = _intersect(x, o, faces.size, cells.boxes)
    if not dist < 1e300:
        return -1, -1, x, 0.0
    surf = face if box < 0 else faces.boxsurf[box, face]
    p = (x[0] + dist * o[0], x[1] + dist * o[1], x[2] + dist * o[2])
    other = -1
    if box < 0:
        axis = face // 2
        for a in range(3):
            if a == axis:
                continue
            if comp(p, a) < 1e-9:
                other = 2 * a
            elif comp(p, a) > faces.size[a] - 1e-9:
                other = 2 * a + 1
    return surf, other, p, dist


@hot_inline
def _surface_deposit(arr, ext, mats, cells, faces, surf, p, c, ts, back, knobs):
    """Power ``c`` landing at point ``p`` of surface ``surf``: to its cell, or shared
    equally between the cells whose boundary it lies on (:func:`_face_span`); a share on a
    cell that a box covers is lost."""
    i0, i1, j0, j1 = _face_span(faces, surf, p)
    share = c / ((i1 - i0 + 1) * (j1 - j0 + 1))
    for i in range(i0, i1 + 1):
        for j in range(j0, j1 + 1):
            dst = faces.grid[faces.offset[surf] + i * faces.dims[surf, 1] + j]
            if dst >= 0:
                deposit(arr, ext, mats, cells, dst, share, ts, back, knobs, True)


@hot_inline
def _ray_deposit(arr, ext, mats, cells, faces, x, n, o, c, tj, knobs):
    """Send power ``c`` from point ``x`` (normal ``n``) along ``o`` to the cell it hits (half
    to each face on a room edge, shared between cells on a cell boundary)."""
    surf, other, p, dist = _ray_surfaces(cells, faces, x, n, o)
    if surf < 0:
        return
    ts = _shift(tj, dist / C_LIGHT, knobs.omega)
    back = (-o[0], -o[1], -o[2])
    if other >= 0:
        _surface_deposit(arr, ext, mats, cells, faces, surf, p, 0.5 * c, ts, back, knobs)
        _surface_deposit(arr, ext, mats, cells, faces, other, p, 0.5 * c, ts, back, knobs)
        return
    _surface_deposit(arr, ext, mats, cells, faces, surf, p, c, ts, back, knobs)


@hot
def map_rays(j0, j1, cells, faces, mats, ext, src, arr, knobs):
    """The lobes of cells ``j0..j1``' outgoing light (their out-maps) sent along one ray per
    map bin (the bin's centre direction, from each of the cell's 2 x 2 Gauss points), each
    carrying the bin's intensity times its solid angle to the cell it hits. Deposits go to
    any cell: run on one thread."""
    res = map_res(src.out[0]) if src.out.shape[0] else 1
    omega_bin = TWO_PI / (res * res)
    for j in range(j0, j1):
        r = src.orow[j]
        if r < 0 or src.power[j] <= 0.0:
            continue
        n = (cells.nrm[j, 0], cells.nrm[j, 1], cells.nrm[j, 2])
        a1 = cells.axes[j, 0]
        a2 = cells.axes[j, 1]
        tj = _tstat(src, j)
        for b in range(res * res):
            val = src.out[r, b]
            if val <= 0.0:
                continue
            lx, ly, lz = from_square((b // res + 0.5) / res, (b % res + 0.5) / res)
            o = _offset(_offset(scaled3(n, lz), a1, lx), a2, ly)
            for k in range(4):
                x, _ = _sub_point(cells, j, 2, k)
                _ray_deposit(arr, ext, mats, cells, faces, x, n, o, 0.25 * val * omega_bin, tj,
                             knobs)


@hot
def scaled3(v, s):
    return (v[0] * s, v[1] * s, v[2] * s)


# ----------------------------------------------------------------------------- emitter
@hot
def from_emitter(l0, l1, cells, mats, ext, emitter, edir, arr, knobs):
    """Light straight from a point emitter ``emitter = (position, axis, (Lambertian order,
    power))`` arriving at cells ``l0..l1`` (Gauss points on cells closer than 6 sizes);
    writes each cell's incidence (propagation direction to its centre) into ``edir``."""
    epos, eaxis, epar = emitter
    order, power = epar
    e0 = (epos[0], epos[1], epos[2])
    ax = (eaxis[0], eaxis[1], eaxis[2])
    boxes = cells.boxes
    has_boxes = boxes.shape[0] > 0
    for dst in range(l0, l1):
        ny = (cells.nrm[dst, 0], cells.nrm[dst, 1], cells.nrm[dst, 2])
        v = (cells.pos[dst, 0] - e0[0], cells.pos[dst, 1] - e0[1], cells.pos[dst, 2] - e0[2])
        dc = math.sqrt(dot(v, v))
        if dc <= 0.0:
            continue
        edir[dst, 0] = v[0] / dc
        edir[dst, 1] = v[1] / dc
        edir[dst, 2] = v[2] / dc
        size = 2.0 * max(cells.half[dst, 0], cells.half[dst, 1])
        s = 1
        if dc < 6.0 * size:
            s = min(max(int(math.ceil(6.0 * size / dc)), 2), SUB_MAX)
        for k in range(s * s):
            yk, wk = _sub_point(cells, dst, s, k)
            d, u, ce, cc = pair(e0, yk, ax, ny)
            if ce <= 0.0 or cc <= 0.0:
                continue
            if has_boxes and occluded(e0, yk, boxes):
                continue
            c = (power * (order + 1.0) / TWO_PI * math.exp(order * math.log(ce))
                 * cells.area[dst] * wk * cc / (d * d))
            deposit(arr, ext, mats, cells, dst, c, _shift((0.0, 0.0, 1.0, 0.0, 0.0), d / C_LIGHT,
                                                        knobs.omega), (-u[0], -u[1], -u[2]), knobs,
                    True)


# ----------------------------------------------------------------------------- nodes
@hot
def aggregate(tree, src, order, axes):
    """Fill the inner nodes of ``src`` from their children, in ``order`` (children before
    parents): sums of power, moments, phasor and diffuse scalars, earliest delay, power-weighted
    centre and second moments about it (``axes``: the cells' surface axes), summed outgoing
    maps."""
    for J in order:
        P = 0.0
        cx = 0.0
        cy = 0.0
        cz = 0.0
        t0 = 1e300
        for k in range(tree.child.shape[1]):
            ch = tree.child[J, k]
            if ch < 0:
                continue
            p = src.power[ch]
            P += p
            src.m1[J] += src.m1[ch]
            src.m2[J] += src.m2[ch]
            src.ph[J, 0] += src.ph[ch, 0]
            src.ph[J, 1] += src.ph[ch, 1]
            for q in range(src.e.shape[1]):
                src.e[J, q] += src.e[ch, q]
            cx += p * src.cen[ch, 0]
            cy += p * src.cen[ch, 1]
            cz += p * src.cen[ch, 2]
            if p > 0.0:
                t0 = min(t0, src.t0[ch])
            r = src.orow[J]
            rc = src.orow[ch]
            if r >= 0 and rc >= 0:
                for b in range(src.out.shape[1]):
                    src.out[r, b] += src.out[rc, b]
        src.power[J] = P
        src.t0[J] = t0
        if P > 0.0:
            src.cen[J, 0] = cx / P
            src.cen[J, 1] = cy / P
            src.cen[J, 2] = cz / P
        else:
            for a in range(3):
                src.cen[J, a] = 0.5 * (tree.lo[J, a] + tree.hi[J, a])
        # second moments about the new centre (parallel axes)
        f = tree.leaf[J]
        a1 = axes[f, 0]
        a2 = axes[f, 1]
        s11 = 0.0
        s22 = 0.0
        s12 = 0.0
        for k in range(tree.child.shape[1]):
            ch = tree.child[J, k]
            if ch < 0:
                continue
            w = src.power[ch] / P if P > 0.0 else 0.25
            d1 = src.cen[ch, a1] - src.cen[J, a1]
            d2 = src.cen[ch, a2] - src.cen[J, a2]
            s11 += w * (src.spread[ch, 0] + d1 * d1)
            s22 += w * (src.spread[ch, 1] + d2 * d2)
            s12 += w * (src.spread[ch, 2] + d1 * d2)
        src.spread[J, 0] = s11
        src.spread[J, 1] = s22
        src.spread[J, 2] = s12

