"""The plain two-lobe model's fast path in the compiled kernel (numba): the table's points by
angle of incidence (:func:`tl_points`), the model's blocks per angle, the Gram sums of the
linear step, its closed form over the share's saturation patterns (:func:`_capped2`), the
normal equations of Levenberg-Marquardt (:func:`_tl_normal`, :func:`_tl_lm`) and the
scoring of screening and scan candidates from their Gram matrices.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .kernel_math import (
    RIDGE,
    STOP_MAXITER,
    STOP_NONFINITE,
    TWO_PI,
    _insert_by_threshold,
    _saturates,
    fexp,
    lexp,
)
from .kernel_types import CapWork, FastWork
from .local_kernel import _lm_step, _lm_verdict

# ----------------------------------------------------------------------------- two-lobe fast path
# The plain two-lobe model (no extension), whose evaluations are most of every fit and of
# every `select` run, on its points stored block by block, one block per exact angle of
# incidence (``gstart[g]:gstart[g + 1]``): within a block cos^v_as, n_d and n_s are
# scalars, so the loops over points read and write plain rows (compiled to vector
# instructions, no gathers). Rows of ``pts`` (9, m):
#   log cos theta, cos theta > 0 (1.0/0.0), log cos phi, cos phi > 0, log cos gamma,
#   sqrt(weight), sqrt(weight) * power, weight, power.
# The arithmetic is the generic path's up to the order of sums over points and the
# lobes' floor (LOBE_FLOOR): the fast path gives the generic path's numbers to rounding.
_TL_ROWS = 9


@njit(cache=True)
def tl_points(geo, n_groups, cols, mask, pts, gstart, lgroup, pgroup):
    """Write the points of ``mask`` into ``pts`` (block order, see above), the blocks'
    starts into ``gstart`` (G + 1) and each point's level of the per-angle decomposition
    (``pgroup``, rounded angles) into ``lgroup``; returns the number of points. ``cols``:
    every point's (sqrt(weight), sqrt(weight) power, weight, power)."""
    sw, yw, weights, power = cols
    group = geo[7]
    n = group.size
    for g in range(n_groups + 1):
        gstart[g] = 0
    for j in range(n):
        if mask[j]:
            gstart[group[j] + 1] += 1
    for g in range(n_groups):
        gstart[g + 1] += gstart[g]
    fill = gstart[:n_groups].copy()
    for j in range(n):
        if mask[j]:
            g = group[j]
            k = fill[g]
            fill[g] += 1
            pts[0, k] = geo[3][j]
            pts[1, k] = 1.0 if geo[4][j] else 0.0
            pts[2, k] = geo[5][j]
            pts[3, k] = 1.0 if geo[6][j] else 0.0
            pts[4, k] = geo[2][j]
            pts[5, k] = sw[j]
            pts[6, k] = yw[j]
            pts[7, k] = weights[j]
            pts[8, k] = power[j]
            lgroup[k] = pgroup[j]
    return gstart[n_groups]


@njit(cache=True, inline="always")
def _tl_values(z, lc):
    """cos^v_as, n_d, n_s at one angle of incidence (``lc``: its log cos)."""
    return fexp(z[0] * lc), fexp(z[1] + z[2] * lc), fexp(z[3] + z[4] * lc)


@njit(cache=True, inline="always")
def _tl_group_values(z, glcg, gval):
    """Per angle of incidence (``glcg``: log cos of each): cos^v_as, n_d, n_s and the
    lobes' normalisations (n_d + 1)/2pi, (n_s + 1)/2pi into the rows of ``gval``."""
    for g in range(glcg.size):
        s, nd, ns = _tl_values(z, glcg[g])
        gval[g, 0] = s
        gval[g, 1] = nd
        gval[g, 2] = ns
        gval[g, 3] = (nd + 1.0) / TWO_PI
        gval[g, 4] = (ns + 1.0) / TWO_PI


# Rows of the fast path's per-point scratch ``vec`` (see tl_work): two slots (the current
# point of a Levenberg-Marquardt run and its trial), slot k at rows _SLOT * k:
#   +0, +1  the lobes' powers cos^n_d theta, cos^n_s phi
#   +2, +3  the weighted effective basis x0, x1 (a fixed column's row is not zeroed: the
#           linear step's ``free`` says which are; where the share saturates both are
#           the specular lobe, at a threshold x0 is (1 - tau) x0 + tau x1)
#   +4      the residuals
#   +5..+9  the block values at every point: n_d, n_s, cos^v_as, (n_d + 1)/2pi, (n_s + 1)/2pi
#   +10     1 where the share saturates, else 0
# then rows _JM.._JM + 4: the Jacobian's columns before projection, dB/dz alpha (weighted).
_SLOT = 11
_JM = 22
_TL_VEC = 27
# Columns of a slot's linear step (``lin[k]``, see _tl_eval): the effective coefficients,
# free columns (1.0/0.0), the free block's inverse (i00, i01, i11), the model's
# coefficients, ln cos of a threshold's angle of incidence (0 unless the solution lies on
# one), the saturation level.
_LIN = 11


@njit(cache=True, error_model="numpy")
def _tl_broadcast(z, gstart, glcg, vec, r, gbuf):
    """Every point's block values (rows ``r``..``r + 4`` of ``vec``, see above): the loops
    over points then read plain rows (a loop per block leaves most points to the scalar
    remainder of the vector loop). The blocks' exponentials are taken eight at a time in
    ``gbuf`` (a loop of constant length vectorises; one over the few blocks would not),
    the loops over a block's points use unsigned indices (no negative-index wraparound)."""
    n_groups = glcg.size
    for g in range(n_groups):
        lc = glcg[g]
        gbuf[g] = z[0] * lc
        gbuf[n_groups + g] = z[1] + z[2] * lc
        gbuf[2 * n_groups + g] = z[3] + z[4] * lc
    for c in range((3 * n_groups + 7) // 8):
        o = 8 * c
        for i in range(8):
            gbuf[o + i] = fexp(gbuf[o + i])
    for g in range(n_groups):
        s = gbuf[g]
        nd = gbuf[n_groups + g]
        ns = gbuf[2 * n_groups + g]
        cd = (nd + 1.0) / TWO_PI
        cs = (ns + 1.0) / TWO_PI
        for j in range(np.uint64(gstart[g]), np.uint64(gstart[g + 1])):
            vec[r, j] = nd
            vec[r + 1, j] = ns
            vec[r + 2, j] = s
            vec[r + 3, j] = cd
            vec[r + 4, j] = cs


@njit(cache=True, error_model="numpy")
def _tl_broadcast_lobe(z, gstart, glcg, vec, r, specular):
    """One lobe's block values of :func:`_tl_broadcast`: the diffuse (specular) lobe's
    index into row ``r + 0`` (``r + 1``) and its normalisation into row ``r + 3``
    (``r + 4``); the other rows are left (a scan along that lobe's coordinates)."""
    k = 2 if specular else 0
    for g in range(glcg.size):
        n = fexp(z[k + 1] + z[k + 2] * glcg[g])
        c = (n + 1.0) / TWO_PI
        for j in range(np.uint64(gstart[g]), np.uint64(gstart[g + 1])):
            vec[r, j] = n
            vec[r + 3, j] = c


#: The sums over points of the fast path (Gram matrices, residuals, normal equations) may
#: be re-associated, so that they compile to vector instructions too: they then differ from
#: the sequential sums of the generic path in the last bits, as numpy's pairwise sums do.
_SUMS = {"reassoc", "contract"}


@njit(cache=True, error_model="numpy", fastmath=_SUMS)
def _tl_fill(z, pts, gstart, glcg, vec, k, gbuf, gsum):
    """The lobes and the weighted (unsaturated) basis at ``z`` into slot ``k`` of ``vec``
    and per angle of incidence the sums of the linear step (:func:`_capped2`):
    ``gsum[g, :5]`` = (x0'x0, x0'x1, x1'x1, x0'y, x1'y) of the angle's points
    (:func:`_tl_sums`). After it ``gbuf[:G]`` holds the angles' ``cos^v_as``. Rows of 2-D
    arrays are indexed in place, not taken as views: a view costs a reference count, as
    much as a dozen points; the loop over every point (not per angle) vectorises."""
    o = _SLOT * k
    _tl_broadcast(z, gstart, glcg, vec, o + 5, gbuf)
    for j in range(gstart[glcg.size]):
        a = lexp(vec[o + 5, j] * pts[0, j]) * pts[1, j]
        b = lexp(vec[o + 6, j] * pts[2, j]) * pts[3, j]
        vec[o, j] = a
        vec[o + 1, j] = b
        ld = vec[o + 8, j] * a
        ls = vec[o + 9, j] * b
        w = pts[5, j]
        vec[o + 2, j] = ld * w
        vec[o + 3, j] = (ld + vec[o + 7, j] * (ls - ld)) * w
    _tl_sums(pts, gstart, vec, o, gsum)


@njit(cache=True, error_model="numpy", fastmath=_SUMS)
def _tl_sums(pts, gstart, vec, o, gsum):
    """Per angle of incidence the Gram sums of the weighted basis in rows ``o + 2``,
    ``o + 3`` of ``vec`` and the weighted power: ``gsum[g, :5]``."""
    for g in range(gsum.shape[0]):
        g00 = 0.0
        g01 = 0.0
        g11 = 0.0
        r0 = 0.0
        r1 = 0.0
        for j in range(np.uint64(gstart[g]), np.uint64(gstart[g + 1])):
            x0 = vec[o + 2, j]
            x1 = vec[o + 3, j]
            y = pts[6, j]
            g00 += x0 * x0
            g01 += x0 * x1
            g11 += x1 * x1
            r0 += x0 * y
            r1 += x1 * y
        _put_sums(gsum, g, g00, g01, g11, r0, r1)


@njit(cache=True, inline="always")
def _put_sums(gsum, g, g00, g01, g11, r0, r1):
    gsum[g, 0] = g00
    gsum[g, 1] = g01
    gsum[g, 2] = g11
    gsum[g, 3] = r0
    gsum[g, 4] = r1


@njit(cache=True, error_model="numpy")
def _tl_set_yy(pts, gstart, gsum):
    """Column 5 of the per-angle sums: y'y of each angle's points (the table's: set once)."""
    for g in range(gsum.shape[0]):
        yy = 0.0
        for j in range(gstart[g], gstart[g + 1]):
            yy += pts[6, j] * pts[6, j]
        gsum[g, 5] = yy


@njit(cache=True)
def _tl_cap_work(n_groups):
    """The fast path's scratch of its linear step: per-angle sums (G, 6; see _tl_fill and
    _tl_set_yy), the thresholds, the saturable angles in threshold order, a linear-step
    row (_LIN) for the scores that keep no slot, the angles' ``cos^v_as``."""
    return CapWork(np.zeros((n_groups, 6)), np.empty(n_groups), np.empty(n_groups, np.int64),
                   np.zeros(_LIN), np.empty(n_groups))


@njit(cache=True, inline="always")
def _profile_cost(u, a, b, c, d, e, yy):
    """The cost ``0.5 (y'y - (a + b u)^2 / (c + 2 d u + e u^2))`` of the best ``K >= 0`` at
    share ``u`` of one saturation pattern (see :func:`_capped2`), and that ``K``."""
    num = a + b * u
    den = c + (2.0 * d + e * u) * u
    if num > 0.0 and den > 0.0:
        k = num / den
        return 0.5 * (yy - num * k), k
    return 0.5 * yy, 0.0


@njit(cache=True, error_model="numpy")
def _capped2(gsum, s_g, v_as, cap, lin, k):
    """The linear step of the plain two-lobe model (two columns) with its saturating share,
    in closed form: :func:`_capped_solve`'s solution as a profile over the share ``u``.
    With ``c = K (1 - u, u)`` the curve of one saturation pattern is ``K B(u)``, ``B``
    affine in ``u``, so the best ``K >= 0`` leaves ``y'y - (a + b u)^2 / (c + 2 d u + e u^2)``
    (``a``.. ``e`` from the pattern's Gram sums), whose one stationary point is
    ``u* = (a d - b c) / (b d - a e)``. Per interval between thresholds the minimum is at
    ``u*`` or an end: a few flops per pattern, no iteration. The patterns are visited by
    growing saturation, and each saturated angle costs at least what its own best
    ``K L_s`` leaves: once that floor exceeds the best cost no later pattern can win (on a
    matte material one saturated angle ends the search). A saturated angle's sums follow
    from its unsaturated ones: ``x_s = x0 + (x1 - x0) / s``.

    ``gsum``: per-angle sums (see _tl_fill); ``s_g``: each angle's ``cos^v_as``; ``cap``:
    (_, thresholds, order, ...) of :func:`_tl_cap_work`; the solution goes into
    ``lin[k]`` (see _LIN: a threshold's one column ``(1 - tau) x0 + tau x1`` carries
    ``K``; u = 0 and u = 1 are thresholds too). Returns (cost from the sums, y'y, the
    threshold of a solution on one or -1)."""
    tau_g, order = cap[1], cap[2]
    n_groups = s_g.size
    g00 = 0.0
    g01 = 0.0
    g11 = 0.0
    r0 = 0.0
    r1 = 0.0
    yy = 0.0
    count = 0
    for g in range(n_groups):
        g00 += gsum[g, 0]
        g01 += gsum[g, 1]
        g11 += gsum[g, 2]
        r0 += gsum[g, 3]
        r1 += gsum[g, 4]
        yy += gsum[g, 5]
        sg = s_g[g]
        t = 1.0 / sg if sg > 1.0 else math.inf
        tau_g[g] = t
        if t < 1.0:
            count = _insert_by_threshold(order, count, tau_g, g)
    best = math.inf
    bu = 0.0
    bk = 0.0
    blower = 0.0
    bend = True
    b00 = g00
    b01 = g01
    b11 = g11
    lo = 0.0
    i = 0
    floor = 0.0  # a lower bound of the cost of every pattern from here on
    while True:
        hi = tau_g[order[i]] if i < count else 1.0
        c = g00
        d = g01 - g00
        e = g00 - 2.0 * g01 + g11
        a = r0
        b = r1 - r0
        cost, kk = _profile_cost(lo, a, b, c, d, e, yy)
        if cost < best:
            best, bu, bk, blower, bend = cost, lo, kk, lo, True
            b00, b01, b11 = g00, g01, g11
        den = b * d - a * e
        if den != 0.0:
            u = (a * d - b * c) / den
            if u > lo and u < hi:
                cost, kk = _profile_cost(u, a, b, c, d, e, yy)
                if cost < best:
                    best, bu, bk, blower, bend = cost, u, kk, lo, False
                    b00, b01, b11 = g00, g01, g11
        if i >= count:
            cost, kk = _profile_cost(1.0, a, b, c, d, e, yy)
            if cost < best:
                best, bu, bk, blower, bend = cost, 1.0, kk, 1.0, True
                b00, b01, b11 = g00, g01, g11
            break
        while i < count and tau_g[order[i]] == hi:  # past hi these angles saturate
            g = order[i]
            t = tau_g[g]
            x00, x01, x11, y0, y1 = gsum[g, 0], gsum[g, 1], gsum[g, 2], gsum[g, 3], gsum[g, 4]
            gss = x00 + (2.0 * (x01 - x00) + (x00 - 2.0 * x01 + x11) * t) * t
            rs = y0 + (y1 - y0) * t
            g00 += gss - x00
            g01 += gss - x01
            g11 += gss - x11
            r0 += rs - y0
            r1 += rs - y1
            # a saturated angle's curve is K L_s: it costs at least what its own best
            # K >= 0 leaves, whatever the other angles do
            floor += 0.5 * (gsum[g, 5] - (rs * rs / gss if rs > 0.0 and gss > 0.0 else 0.0))
            i += 1
        if floor >= best:  # every later pattern saturates these angles too
            break
        lo = hi
    row = lin[k]
    row[7] = bk * (1.0 - bu)
    row[8] = bk * bu
    row[10] = blower
    if bend:  # the one column (1 - u) x0 + u x1 at a threshold u
        cc = (1.0 - bu) * (1.0 - bu) * b00 + 2.0 * bu * (1.0 - bu) * b01 + bu * bu * b11
        row[0] = bk
        row[1] = 0.0
        row[2] = 1.0 if bk > 0.0 else 0.0
        row[3] = 0.0
        row[4] = 1.0 / (cc * (1.0 + RIDGE)) if bk > 0.0 and cc > 0.0 else 0.0
        row[5] = 0.0
        row[6] = 0.0
        row[9] = -math.log(bu) / v_as if (bu > 0.0 and bu < 1.0) else 0.0
    else:
        a00 = b00 * (1.0 + RIDGE)
        a11 = b11 * (1.0 + RIDGE)
        det = a00 * a11 - b01 * b01
        row[0] = row[7]
        row[1] = row[8]
        row[2] = 1.0
        row[3] = 1.0
        row[4] = a11 / det
        row[5] = -b01 / det
        row[6] = a00 / det
        row[9] = 0.0
    return best, yy, bu if bend else -1.0


@njit(cache=True, error_model="numpy")
def _tl_capped(s_g, v_as, cap):
    """:func:`_capped2` of the sums in ``cap[0]`` into ``cap``'s own row, for a score
    (cost from the sums, y'y)."""
    row = cap[3]
    cost, yy, _ = _capped2(cap[0], s_g, v_as, cap, row.reshape((1, row.size)), 0)
    return cost, yy


@njit(cache=True, error_model="numpy")
def _tl_residual(vec, k, pts, m, a0, a1):
    """Residuals (row ``+4`` of slot ``k``) and cost of the basis in the slot."""
    o = _SLOT * k
    cost = 0.0
    for j in range(m):
        acc = pts[6, j] - vec[o + 2, j] * a0 - vec[o + 3, j] * a1
        vec[o + 4, j] = acc
        cost += acc * acc
    cost *= 0.5
    if not math.isfinite(cost):
        cost = math.inf
    return cost


@njit(cache=True, error_model="numpy")
def _tl_saturate(vec, k, pts, gstart, tau_g, lower, tau):
    """The effective basis of slot ``k`` (see the rows above) for a saturation level
    ``lower`` and a threshold ``tau`` (-1: none) of the linear step, and the slot's
    saturation flags (left alone by _tl_fill: _tl_eval clears them when nothing
    saturates)."""
    o = _SLOT * k
    for g in range(tau_g.size):
        sat = tau_g[g] <= lower
        for j in range(np.uint64(gstart[g]), np.uint64(gstart[g + 1])):
            vec[o + 10, j] = 1.0 if sat else 0.0
            if sat:
                xs = vec[o + 9, j] * vec[o + 1, j] * pts[5, j]
                vec[o + 2, j] = xs
                vec[o + 3, j] = xs
    if tau >= 0.0:
        for j in range(gstart[tau_g.size]):
            vec[o + 2, j] = (1.0 - tau) * vec[o + 2, j] + tau * vec[o + 3, j]


@njit(cache=True, error_model="numpy")
def _tl_eval(z, pts, gstart, glcg, vec, k, lin, gbuf, cap):
    """Lobes, basis, the saturating share's linear step (``lin[k]``, see _LIN) and
    residuals at ``z`` in slot ``k``; returns the cost (as _evaluate)."""
    flagged = lin[k, 10] > 0.0  # the slot's saturation flags are set (see _tl_saturate)
    _tl_fill(z, pts, gstart, glcg, vec, k, gbuf, cap[0])
    _, _, tau = _capped2(cap[0], gbuf[:glcg.size], z[0], cap, lin, k)
    lower = lin[k, 10]
    if lower > 0.0 or tau >= 0.0:
        _tl_saturate(vec, k, pts, gstart, cap[1], lower, tau)
    elif flagged:
        vec[_SLOT * k + 10, :gstart[glcg.size]] = 0.0
    return _tl_residual(vec, k, pts, gstart[glcg.size], lin[k, 0], lin[k, 1])


@njit(cache=True, error_model="numpy", fastmath=_SUMS)
def _tl_normal(pts, m, vec, k, lin, coef, grad, hess):
    """Kaufman's Jacobian of the projected residual at the point in slot ``k`` (its lobes,
    block values, effective basis, saturation flags and residuals; along ``v_as`` a
    solution on a threshold moves with the threshold, ``ln cos gamma - ln cos gamma*``)
    and the normal equations' gradient ``J'r`` and
    matrix ``J'J`` (as _jacobian and _lm): one pass for the Jacobian's columns before
    projection and their products with the basis, one for the projected columns and
    every sum of the normal equations."""
    o = _SLOT * k
    a0 = lin[k, 7]  # the model's coefficients: the unsaturated rows' derivative
    a1 = lin[k, 8]
    f0 = lin[k, 2]
    f1 = lin[k, 3]
    lstar = lin[k, 9]  # ln cos gamma of a threshold the solution lies on (else 0)
    t00 = 0.0
    t01 = 0.0
    t02 = 0.0
    t03 = 0.0
    t04 = 0.0
    t10 = 0.0
    t11 = 0.0
    t12 = 0.0
    t13 = 0.0
    t14 = 0.0
    for j in range(m):
        a = vec[o, j]
        b = vec[o + 1, j]
        nd = vec[o + 5, j]
        ns = vec[o + 6, j]
        s = vec[o + 7, j]
        ld = vec[o + 8, j] * a
        ls = vec[o + 9, j] * b
        lcg = pts[4, j]
        dd = nd * (a / TWO_PI + ld * pts[0, j])
        ds = ns * (b / TWO_PI + ls * pts[2, j])
        oms = 1.0 - s
        w = pts[5, j]
        sat = vec[o + 10, j]  # saturated: K L_s, only the specular lobe moves
        un = 1.0 - sat
        j0 = un * s * (ls - ld) * (lcg - lstar) * a1 * w
        j1 = un * (dd * a0 + oms * dd * a1) * w
        j2 = j1 * lcg
        j3 = (un * s * a1 + sat * (a0 + a1)) * ds * w
        j4 = j3 * lcg
        vec[_JM, j] = j0
        vec[_JM + 1, j] = j1
        vec[_JM + 2, j] = j2
        vec[_JM + 3, j] = j3
        vec[_JM + 4, j] = j4
        x0 = vec[o + 2, j] * f0
        x1 = vec[o + 3, j] * f1
        t00 += x0 * j0
        t01 += x0 * j1
        t02 += x0 * j2
        t03 += x0 * j3
        t04 += x0 * j4
        t10 += x1 * j0
        t11 += x1 * j1
        t12 += x1 * j2
        t13 += x1 * j3
        t14 += x1 * j4
    i00 = lin[k, 4]
    i01 = lin[k, 5]
    i11 = lin[k, 6]
    coef[0, 0] = i00 * t00 + i01 * t10
    coef[0, 1] = i00 * t01 + i01 * t11
    coef[0, 2] = i00 * t02 + i01 * t12
    coef[0, 3] = i00 * t03 + i01 * t13
    coef[0, 4] = i00 * t04 + i01 * t14
    coef[1, 0] = i01 * t00 + i11 * t10
    coef[1, 1] = i01 * t01 + i11 * t11
    coef[1, 2] = i01 * t02 + i11 * t12
    coef[1, 3] = i01 * t03 + i11 * t13
    coef[1, 4] = i01 * t04 + i11 * t14
    c00, c01, c02, c03, c04 = coef[0, 0], coef[0, 1], coef[0, 2], coef[0, 3], coef[0, 4]
    c10, c11, c12, c13, c14 = coef[1, 0], coef[1, 1], coef[1, 2], coef[1, 3], coef[1, 4]
    g0 = 0.0
    g1 = 0.0
    g2 = 0.0
    g3 = 0.0
    g4 = 0.0
    h00 = 0.0
    h01 = 0.0
    h02 = 0.0
    h03 = 0.0
    h04 = 0.0
    h11 = 0.0
    h12 = 0.0
    h13 = 0.0
    h14 = 0.0
    h22 = 0.0
    h23 = 0.0
    h24 = 0.0
    h33 = 0.0
    h34 = 0.0
    h44 = 0.0
    for j in range(m):
        x0 = vec[o + 2, j] * f0
        x1 = vec[o + 3, j] * f1
        r = vec[o + 4, j]
        q0 = x0 * c00 + x1 * c10 - vec[_JM, j]
        q1 = x0 * c01 + x1 * c11 - vec[_JM + 1, j]
        q2 = x0 * c02 + x1 * c12 - vec[_JM + 2, j]
        q3 = x0 * c03 + x1 * c13 - vec[_JM + 3, j]
        q4 = x0 * c04 + x1 * c14 - vec[_JM + 4, j]
        g0 += q0 * r
        g1 += q1 * r
        g2 += q2 * r
        g3 += q3 * r
        g4 += q4 * r
        h00 += q0 * q0
        h01 += q0 * q1
        h02 += q0 * q2
        h03 += q0 * q3
        h04 += q0 * q4
        h11 += q1 * q1
        h12 += q1 * q2
        h13 += q1 * q3
        h14 += q1 * q4
        h22 += q2 * q2
        h23 += q2 * q3
        h24 += q2 * q4
        h33 += q3 * q3
        h34 += q3 * q4
        h44 += q4 * q4
    grad[0] = g0
    grad[1] = g1
    grad[2] = g2
    grad[3] = g3
    grad[4] = g4
    hess[0, 0] = h00
    hess[0, 1] = h01
    hess[0, 2] = h02
    hess[0, 3] = h03
    hess[0, 4] = h04
    hess[1, 1] = h11
    hess[1, 2] = h12
    hess[1, 3] = h13
    hess[1, 4] = h14
    hess[2, 2] = h22
    hess[2, 3] = h23
    hess[2, 4] = h24
    hess[3, 3] = h33
    hess[3, 4] = h34
    hess[4, 4] = h44
    for q in range(5):
        for r in range(q):
            hess[q, r] = hess[r, q]


@njit(cache=True)
def tl_work(n, n_groups):
    """Scratch of the fast path for up to ``n`` points at ``n_groups`` angles of incidence:
    the per-point rows (_TL_VEC, n; see _SLOT), the linear steps of the two slots (2,
    _LIN; see _tl_eval), the projection's coefficients (2, 5), gradient, normal matrix,
    the damped system and its right-hand side, the step, the current and trial
    coordinates, the pinned ones, the blocks' exponentials (_tl_broadcast; at most ``n``
    blocks), the linear step's scratch (:func:`_tl_cap_work`)."""
    return FastWork(np.zeros((_TL_VEC, n)), np.zeros((2, _LIN)), np.empty((2, 5)), np.empty(5),
                    np.empty((5, 5)), np.empty((5, 5)), np.empty(5), np.empty(5), np.empty(5),
                    np.empty(5), np.empty(5, np.bool_), np.zeros(3 * n + 8),
                    _tl_cap_work(n_groups))


@njit(cache=True)
def _tl_costs(cands, pts, gstart, glcg, nonneg, residual, ws):
    """:func:`_costs` of the plain two-lobe model."""
    vec, lin, gbuf, cap = ws[0], ws[1], ws[11], ws[12]
    out = np.empty(cands.shape[0])
    for i in range(cands.shape[0]):
        out[i] = _tl_eval(cands[i], pts, gstart, glcg, vec, 0, lin, gbuf, cap)
    return out


@njit(cache=True)
def _tl_lm(nonneg, residual, z0, bounds, table, stop, z_out, alpha_out, ws):
    """:func:`_lm` of the plain two-lobe model (the same steps and stopping rules): the
    trial points are evaluated without derivatives, the Jacobian is formed only at
    accepted points, from the lobes kept there. ``table``: (points, block starts, log
    cos of the angles of incidence)."""
    p = 5
    lo, hi = bounds
    pts, gstart, glcg = table
    max_iter, ftol, xtol = stop
    vec, lin, coef, grad, hess, a, rhs, step, z, zt, pinned, gbuf, cap = ws
    m = gstart[glcg.size]
    for q in range(p):
        z[q] = min(max(z0[q], lo[q]), hi[q])
    cur = 0
    cost = _tl_eval(z, pts, gstart, glcg, vec, 0, lin, gbuf, cap)
    nfev = 1
    lam = 1e-3
    if not math.isfinite(cost):
        z_out[:] = z
        alpha_out[0] = lin[cur, 7]
        alpha_out[1] = lin[cur, 8]
        return math.inf, STOP_NONFINITE, nfev
    reason = STOP_MAXITER
    for _ in range(max_iter):
        _tl_normal(pts, m, vec, cur, lin, coef, grad, hess)
        _lm_step(z, (lo, hi), lam, grad, hess, pinned, a, rhs, step, zt)
        tri = 1 - cur
        tcost = _tl_eval(zt, pts, gstart, glcg, vec, tri, lin, gbuf, cap)
        better, lam, stop_now = _lm_verdict(z, zt, cost, tcost, lam, xtol, ftol)
        nfev += 1
        if better:
            z[:] = zt
            cost = tcost
            cur = tri
        if stop_now:
            reason = stop_now
            break
    z_out[:] = z
    alpha_out[0] = lin[cur, 7]
    alpha_out[1] = lin[cur, 8]
    return cost, reason, nfev


@njit(cache=True, error_model="numpy", fastmath=_SUMS)
def _tl_gram(pts, gstart, vec, q, gsum):
    """Per angle of incidence the sums of the linear step (``gsum``, see _tl_fill) of the
    basis whose block values are in rows 5..9 of ``vec`` (the basis itself goes to rows
    2, 3: scratch here). ``q``: -1, both lobes from their exponentials; 1 or 2 (3 or 4),
    the diffuse (specular) lobe from its exponential, the other from row 1 (row 0): the
    lobes at the centre of a scan, times their block factors (along the diffuse
    (specular) coordinates only the diffuse (specular) lobe changes). One loop per case:
    a branch inside the loop would keep it from vectorising."""
    m = gstart[gsum.shape[0]]
    if q < 0:
        for j in range(m):
            ld = vec[8, j] * (lexp(vec[5, j] * pts[0, j]) * pts[1, j])
            ls = vec[9, j] * (lexp(vec[6, j] * pts[2, j]) * pts[3, j])
            w = pts[5, j]
            vec[2, j] = ld * w
            vec[3, j] = (ld + vec[7, j] * (ls - ld)) * w
    elif q <= 2:
        for j in range(m):
            ld = vec[8, j] * (lexp(vec[5, j] * pts[0, j]) * pts[1, j])
            ls = vec[1, j]
            w = pts[5, j]
            vec[2, j] = ld * w
            vec[3, j] = (ld + vec[7, j] * (ls - ld)) * w
    else:
        for j in range(m):
            ld = vec[0, j]
            ls = vec[9, j] * (lexp(vec[6, j] * pts[2, j]) * pts[3, j])
            w = pts[5, j]
            vec[2, j] = ld * w
            vec[3, j] = (ld + vec[7, j] * (ls - ld)) * w
    _tl_sums(pts, gstart, vec, 0, gsum)


#: Below this fraction of y'y a cost from the Gram sums keeps too few digits (it is the
#: small difference of numbers of the size of y'y: about 1e-16 y'y of rounding): the
#: residuals are then summed instead.
GRAM_DIGITS = 1e-5


@njit(cache=True, error_model="numpy")
def _tl_gram_cost(z, s_g, pts, gstart, glcg, ws):
    """The projected cost at ``z`` from the per-angle sums now in ``ws``'s linear-step
    scratch (:func:`_tl_capped`; ``s_g``: the angles' ``cos^v_as`` at ``z``), from the
    residuals (:func:`_tl_eval`, which overwrites slot 0 of ``ws``) where the sums keep
    too few digits (GRAM_DIGITS)."""
    cost, yy = _tl_capped(s_g, z[0], ws[12])
    if cost < GRAM_DIGITS * yy:
        cost = _tl_eval(z, pts, gstart, glcg, ws[0], 0, ws[1], ws[11], ws[12])
    return cost


@njit(cache=True, error_model="numpy")
def _tl_cost(z, pts, gstart, glcg, nonneg, residual, ws):
    """The projected cost at ``z`` (as :func:`_tl_eval`) from the per-angle sums, in one
    pass over the points."""
    vec = ws[0]
    _tl_broadcast(z, gstart, glcg, vec, 5, ws[11])
    _tl_gram(pts, gstart, vec, -1, ws[12][0])
    return _tl_gram_cost(z, ws[11][:glcg.size], pts, gstart, glcg, ws)


@njit(cache=True)
def _tl_screen_costs(cands, pts, gstart, glcg, nonneg, residual, ws):
    """:func:`_tl_costs` of many candidates (:func:`_tl_cost`)."""
    out = np.empty(cands.shape[0])
    for i in range(cands.shape[0]):
        out[i] = _tl_cost(cands[i], pts, gstart, glcg, nonneg, residual, ws)
    return out


@njit(cache=True, error_model="numpy")
def _tl_centre(z, pts, gstart, glcg, vec, gbuf):
    """Block values and the lobes at ``z`` into rows 5..9 and 0, 1 of ``vec``."""
    _tl_broadcast(z, gstart, glcg, vec, 5, gbuf)
    for j in range(gstart[glcg.size]):
        vec[0, j] = vec[8, j] * (lexp(vec[5, j] * pts[0, j]) * pts[1, j])
        vec[1, j] = vec[9, j] * (lexp(vec[6, j] * pts[2, j]) * pts[3, j])


@njit(cache=True, error_model="numpy")
def _tl_scan_costs(z, axes, pts, gstart, glcg, nonneg, residual, ws):
    """Projected costs of the one-coordinate scans through ``z`` (the numbers of
    :func:`_tl_costs` of :func:`_scan_candidates`, from the per-angle sums as
    :func:`_tl_cost`). Along v_as only the blocks' shares cos^v_as change: the sums are
    then those of the lobes' products at ``z``, without a pass over the points."""
    p, n_axis = axes.shape
    vec = ws[0]
    gbuf = ws[11]
    gsum = ws[12][0]
    n_groups = glcg.size
    _tl_centre(z, pts, gstart, glcg, vec, gbuf)
    # per block: sums of the weighted lobes' products at z
    blk = np.zeros((n_groups, 5))
    for g in range(n_groups):
        for j in range(np.uint64(gstart[g]), np.uint64(gstart[g + 1])):
            w = pts[5, j]
            xd = vec[0, j] * w
            xs = vec[1, j] * w
            y = pts[6, j]
            blk[g, 0] += xd * xd
            blk[g, 1] += xd * xs
            blk[g, 2] += xs * xs
            blk[g, 3] += xd * y
            blk[g, 4] += xs * y
    s_z = gbuf[:n_groups].copy()  # the angles' cos^v_as at z
    s_g = ws[12][4]
    out = np.empty(p * n_axis)
    zc = z.copy()
    for q in range(p):
        for i in range(n_axis):
            zc[:] = z
            zc[q] = axes[q, i]
            if q == 0:
                for g in range(n_groups):
                    sh = fexp(zc[0] * glcg[g])
                    s_g[g] = sh
                    om = 1.0 - sh
                    a_, b_, c_, d_, e_ = blk[g, 0], blk[g, 1], blk[g, 2], blk[g, 3], blk[g, 4]
                    _put_sums(gsum, g, a_, om * a_ + sh * b_,
                              om * om * a_ + 2.0 * sh * om * b_ + sh * sh * c_, d_,
                              om * d_ + sh * e_)
            else:  # only the scanned lobe's block values change
                s_g[:] = s_z
                _tl_broadcast_lobe(zc, gstart, glcg, vec, 5 if q <= 2 else 6, q >= 3)
                _tl_gram(pts, gstart, vec, q, gsum)
            cost, yy = _tl_capped(s_g, zc[0], ws[12])
            if cost < GRAM_DIGITS * yy:
                cost = _tl_eval(zc, pts, gstart, glcg, vec, 0, ws[1], gbuf, ws[12])
                _tl_centre(z, pts, gstart, glcg, vec, gbuf)
            out[q * n_axis + i] = cost
    return out


@njit(cache=True, error_model="numpy")
def _tl_ss(pts, m, vec, a0, a1):
    """Sum of squared differences between the power (row 8 of ``pts``) and the plain
    two-lobe model whose block values are in rows 5..9 of ``vec`` (the share saturated
    where ``u_as cos^v_as(gamma) >= 1``)."""
    ss = 0.0
    k = a0 + a1
    u = a1 / k if k > 0.0 else 0.0
    for j in range(m):
        ld = vec[8, j] * (lexp(vec[5, j] * pts[0, j]) * pts[1, j])
        ls = vec[9, j] * (lexp(vec[6, j] * pts[2, j]) * pts[3, j])
        s = vec[7, j]
        if _saturates(u, s, False):
            r = pts[8, j] - ls * k
        else:
            r = pts[8, j] - (ld * a0 + (ld + s * (ls - ld)) * a1)
        ss += r * r
    return ss
