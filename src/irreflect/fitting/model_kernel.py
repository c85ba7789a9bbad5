"""The models in the compiled kernel (numba): the paper's two-lobe model (Eqs. 19-22) and the
diagnosis catalogue's extensions as a chain of codes (:func:`model_code`), evaluated point
by point with their derivatives; the table's geometry (:func:`kernel_geometry`), the
model's curve (:func:`predict`) and its Jacobian in (z, alpha) (:func:`jacobian_full`).
The numpy side of the same step is the models' own ``basis`` (:mod:`irreflect.models`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .kernel_math import _cos_parts, _lobe, _saturates, _share_at_normal, fexp
from .kernel_types import KGeo, KTable

# extension codes (the order they wrap the model is kept in an array)
EXT_INCIDENCE, EXT_TILT, EXT_RETRO, EXT_OFFSET, EXT_BACKGROUND, EXT_HALO = 1, 2, 3, 4, 5, 6
EXT_CODES = {"incidence_reflectance": EXT_INCIDENCE, "offspecular_peak": EXT_TILT,
             "retroreflection": EXT_RETRO, "angle_offset": EXT_OFFSET,
             "background": EXT_BACKGROUND, "specular_halo": EXT_HALO}
# new nonlinear coordinates and linear columns each extension adds
_EXT_P = {EXT_INCIDENCE: 1, EXT_TILT: 1, EXT_RETRO: 1, EXT_OFFSET: 1, EXT_BACKGROUND: 0,
          EXT_HALO: 1}
_EXT_L = {EXT_INCIDENCE: 0, EXT_TILT: 0, EXT_RETRO: 1, EXT_OFFSET: 0, EXT_BACKGROUND: 1,
          EXT_HALO: 1}
GEOMETRY_STEP = 1e-7  # the numpy path's central-difference step along geometric shifts


# ----------------------------------------------------------------------------- the model
@njit(cache=True)
def _two_lobe_point(s, nd, ns, angles, deriv, b, db):
    """Two-lobe basis (2 columns, see model._two_lobe_basis) and its derivative at one
    point; ``s = cos^v_as``, ``nd``, ``ns`` are the point's angle-of-incidence values,
    ``angles`` its (log cos gamma, log cos theta, cos theta > 0, log cos phi, cos phi > 0)."""
    lcg, lct, pt, lcp, pp = angles
    ld, dld = _lobe(lct, pt, nd)
    ls, dls = _lobe(lcp, pp, ns)
    diff = ls - ld
    b[0] = ld
    b[1] = ld + s * diff
    if deriv:
        dd = dld * nd
        ds = dls * ns
        for q in range(db.shape[1]):
            db[0, q] = 0.0
            db[1, q] = 0.0
        db[0, 1] = dd
        db[0, 2] = dd * lcg
        db[1, 0] = s * diff * lcg
        oms = 1.0 - s
        db[1, 1] = oms * dd
        db[1, 2] = oms * dd * lcg
        db[1, 3] = s * ds
        db[1, 4] = s * ds * lcg


@njit(cache=True)
def _group_values(z, glcg, gval):
    """Per angle of incidence: cos^v_as, n_d and n_s of the two-lobe model (3 exps per
    angle instead of per point)."""
    for g in range(glcg.size):
        lc = glcg[g]
        gval[g, 0] = fexp(z[0] * lc)
        gval[g, 1] = fexp(z[1] + z[2] * lc)
        gval[g, 2] = fexp(z[3] + z[4] * lc)


@njit(cache=True)
def _point(codes, z, j, geo, gval, deriv, b, db, bp, dbp):
    """Basis and derivative of the two-lobe model wrapped in ``codes`` (innermost first) at
    point ``j`` of the geometry ``geo``. ``b`` (L,), ``db`` (L, P); ``bp``/``dbp`` are
    scratch of the same shapes for the central differences along geometric shifts."""
    if deriv:
        _chain(codes, z, j, geo, gval, b, db, bp, dbp)
    else:
        _chain_value(codes, codes.size, z, j, geo, gval, geo[1][j], 0.0, b, db)


@njit(cache=True)
def _sizes(codes, level):
    """(nonlinear coordinates, linear columns) of the model wrapped by ``codes[:level]``."""
    p = 5
    ll = 2
    for i in range(level):
        c = codes[i]
        if c == EXT_INCIDENCE or c == EXT_TILT or c == EXT_RETRO or c == EXT_OFFSET \
                or c == EXT_HALO:
            p += 1
        if c == EXT_RETRO or c == EXT_BACKGROUND or c == EXT_HALO:
            ll += 1
    return p, ll


@njit(cache=True)
def _shift(code, z, pb, gamma, theta, tilt, extra):
    """The geometry a shift wrapper (angle_offset, offspecular_peak) passes inward, its
    own coordinate ``z[pb]`` plus ``extra``: (theta, tilt)."""
    if code == EXT_OFFSET:
        return theta + z[pb] + extra, tilt
    s = math.sin(gamma)
    return theta, tilt + (z[pb] + extra) * s * abs(s)


@njit(cache=True)
def _geometry_at(codes, upto, level, z, gamma, theta, tilt):
    """The geometry wrapper ``level`` receives (level 0: the two-lobe model itself) under
    the wrappers ``codes[:upto]`` whose outermost receives (theta, tilt)."""
    for outer in range(upto, level, -1):
        code = codes[outer - 1]
        if code == EXT_OFFSET or code == EXT_TILT:
            pb, lb = _sizes(codes, outer - 1)
            theta, tilt = _shift(code, z, pb, gamma, theta, tilt, 0.0)
    return theta, tilt


@njit(cache=True)
def _base(z, j, geo, gval, theta, tilt, deriv, b, db):
    gamma = geo[0][j]
    g = geo[7][j]
    if theta == geo[1][j] and tilt == 0.0:
        lct, pt, lcp, pp = geo[3][j], geo[4][j], geo[5][j], geo[6][j]
    else:
        lct, pt = _cos_parts(theta)
        lcp, pp = _cos_parts(-gamma - theta - tilt)
    _two_lobe_point(gval[g, 0], gval[g, 1], gval[g, 2], (geo[2][j], lct, pt, lcp, pp), deriv, b,
                    db)


@njit(cache=True)
def _added(code, z, pb, gamma, theta, tilt):
    """The column a wrapper adds (background, retro lobe, halo lobe) and d/d z[pb]."""
    if code == EXT_BACKGROUND:
        return 1.0, 0.0
    n = fexp(z[pb])
    if code == EXT_RETRO:
        lc, pos = _cos_parts(theta - gamma)
    else:  # halo: about the (tilted) mirror direction
        lc, pos = _cos_parts(-gamma - theta - tilt)
    lobe, dlobe = _lobe(lc, pos, n)
    return lobe, dlobe * n


@njit(cache=True)
def _chain_value(codes, upto, z, j, geo, gval, theta_in, tilt_in, b, scratch):
    """The model of ``codes[:upto]`` at point ``j`` for the input geometry (theta_in,
    tilt_in) of its outermost wrapper; no derivatives. Writes b[:L]."""
    gamma = geo[0][j]
    theta, tilt = _geometry_at(codes, upto, 0, z, gamma, theta_in, tilt_in)
    _base(z, j, geo, gval, theta, tilt, False, b, scratch)
    for level in range(1, upto + 1):
        code = codes[level - 1]
        pb, lb = _sizes(codes, level - 1)
        if code == EXT_INCIDENCE:
            f = fexp(z[pb] * geo[2][j])
            for col in range(lb):
                b[col] *= f
        elif code == EXT_BACKGROUND or code == EXT_RETRO or code == EXT_HALO:
            theta, tilt = _geometry_at(codes, upto, level, z, gamma, theta_in, tilt_in)
            b[lb], _ = _added(code, z, pb, gamma, theta, tilt)


@njit(cache=True)
def _chain(codes, z, j, geo, gval, b, db, bp, dbp):
    """The model of all ``codes`` at point ``j`` and its derivative with respect to every
    coordinate (central differences along geometric shifts, as the numpy path)."""
    gamma = geo[0][j]
    theta_j = geo[1][j]
    upto = codes.size
    theta, tilt = _geometry_at(codes, upto, 0, z, gamma, theta_j, 0.0)
    _base(z, j, geo, gval, theta, tilt, True, b, db)
    for level in range(1, upto + 1):
        code = codes[level - 1]
        pb, lb = _sizes(codes, level - 1)
        for col in range(lb):  # the new coordinate, if any, starts at zero
            if pb < db.shape[1]:
                db[col, pb] = 0.0
        if code == EXT_INCIDENCE:
            lcg = geo[2][j]
            f = fexp(z[pb] * lcg)
            for col in range(lb):
                b[col] *= f
                for q in range(pb):
                    db[col, q] *= f
                db[col, pb] = b[col] * lcg
        elif code == EXT_OFFSET or code == EXT_TILT:
            h = GEOMETRY_STEP
            th, tl = _geometry_at(codes, upto, level, z, gamma, theta_j, 0.0)
            t1, l1 = _shift(code, z, pb, gamma, th, tl, h)
            _chain_value(codes, level - 1, z, j, geo, gval, t1, l1, bp, dbp)
            plus = bp.copy()
            t2, l2 = _shift(code, z, pb, gamma, th, tl, -h)
            _chain_value(codes, level - 1, z, j, geo, gval, t2, l2, bp, dbp)
            for col in range(lb):
                db[col, pb] = (plus[col] - bp[col]) / (2.0 * h)
        else:
            th, tl = _geometry_at(codes, upto, level, z, gamma, theta_j, 0.0)
            b[lb], d = _added(code, z, pb, gamma, th, tl)
            for q in range(db.shape[1]):
                db[lb, q] = 0.0
            if code != EXT_BACKGROUND:
                db[lb, pb] = d


@njit(cache=True)
def make_geometry(gamma, theta, group, levels):
    """The per-point arrays every evaluation reads (computed once per table): gamma,
    theta, log cos gamma, log cos theta, cos theta > 0, log cos phi, cos phi > 0, the
    index of the point's angle of incidence in ``levels``."""
    n = gamma.size
    lcg = np.empty(n)
    lct = np.empty(n)
    pt = np.empty(n, np.bool_)
    lcp = np.empty(n)
    pp = np.empty(n, np.bool_)
    for j in range(n):
        lcg[j] = math.log(math.cos(gamma[j]))
        lct[j], pt[j] = _cos_parts(theta[j])
        lcp[j], pp[j] = _cos_parts(-gamma[j] - theta[j])
    return KGeo(gamma, theta, lcg, lct, pt, lcp, pp, group)


@njit(cache=True)
def jacobian_full(codes, z, alpha, geo, glcg, sw):
    """The Jacobian in (z, alpha) of the weighted model, for the covariance: (n, P + L).
    Where the share saturates both share columns are the specular lobe (a point exactly
    at its threshold counts as unsaturated: there the derivative sees ``u_as``)."""
    n = sw.size
    p = z.size
    pp, ll = _sizes(codes, codes.size)
    b = np.empty(ll)
    db = np.empty((ll, p))
    bp = np.empty(ll)
    dbp = np.empty((ll, p))
    gval = np.empty((glcg.size, 3))
    _group_values(z, glcg, gval)
    u = _share_at_normal(alpha)
    out = np.empty((n, p + ll))
    for j in range(n):
        _point(codes, z, j, geo, gval, True, b, db, bp, dbp)
        s = gval[geo[7][j], 0]
        if _saturates(u, s, True):
            _saturate_point(b, db, s, geo[2][j], True)
        for q in range(p):
            acc = 0.0
            for col in range(ll):
                acc += db[col, q] * alpha[col]
            out[j, q] = acc * sw[j]
        for col in range(ll):
            out[j, p + col] = b[col] * sw[j]
    return out


@njit(cache=True)
def _saturate_point(b, db, s, lcg, deriv):
    """One point's basis (and derivative) where the share saturates: both share columns
    ``b0 + (b1 - b0) / s`` (models.base.saturated_column), whose derivative along
    ``v_as`` loses the share's own (``s = cos^v_as gamma``, ``lcg = ln cos gamma``)."""
    t = 1.0 / s
    diff = b[1] - b[0]
    sat = b[0] + diff * t
    b[0] = sat
    b[1] = sat
    if deriv:
        for q in range(db.shape[1]):
            d = db[0, q] + (db[1, q] - db[0, q]) * t
            db[0, q] = d
            db[1, q] = d
        db[0, 0] -= diff * t * lcg
        db[1, 0] = db[0, 0]


@njit(cache=True)
def predict(codes, z, alpha, geo, glcg):
    """The model (unweighted) at every point of ``geo``, the share saturated where
    ``u_as cos^v_as(gamma) >= 1``."""
    n = geo[0].size
    p = z.size
    pp, ll = _sizes(codes, codes.size)
    b = np.empty(ll)
    db = np.empty((ll, p))
    gval = np.empty((glcg.size, 3))
    _group_values(z, glcg, gval)
    u = _share_at_normal(alpha)
    out = np.empty(n)
    for j in range(n):
        _point(codes, z, j, geo, gval, False, b, db, b, db)
        s = gval[geo[7][j], 0]
        if _saturates(u, s, False):
            _saturate_point(b, db, s, 0.0, False)
        acc = 0.0
        for col in range(ll):
            acc += b[col] * alpha[col]
        out[j] = acc
    return out


@njit(cache=True)
def _take(geo, idx):
    """The geometry of the points ``idx``."""
    return KGeo(geo[0][idx], geo[1][idx], geo[2][idx], geo[3][idx], geo[4][idx], geo[5][idx],
                geo[6][idx], geo[7][idx])


# ----------------------------------------------------------------------------- per table, per fit
@njit(cache=True)
def _distinct(values):
    """The distinct values in increasing order and each value's index among them (as
    numpy.unique with return_inverse, from a stable sort)."""
    n = values.size
    order = np.argsort(values, kind="mergesort")
    index = np.empty(n, np.int64)
    out = np.empty(n)
    g = -1
    for k in range(n):
        j = order[k]
        if g < 0 or values[j] != out[g]:
            g += 1
            out[g] = values[j]
        index[j] = g
    return out[:g + 1].copy(), index


@njit(cache=True)
def kernel_geometry(gamma, theta):
    """fitting._kernel_geometry in one call: (geometry, log cos of the exact angles of
    incidence, the rounded ones of the per-angle decomposition (as numpy.round(gamma, 9)),
    each point's index among those, the exact angles of incidence)."""
    n = gamma.size
    exact, group = _distinct(gamma)
    rounded = np.empty(n)
    for j in range(n):
        rounded[j] = np.rint(gamma[j] * 1e9) / 1e9
    levels, pgroup = _distinct(rounded)
    glcg = np.empty(exact.size)
    for i in range(exact.size):
        glcg[i] = math.log(math.cos(exact[i]))
    return KTable(make_geometry(gamma, theta, group, exact), glcg, levels, pgroup, exact)
