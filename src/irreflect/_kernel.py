"""Compiled kernel of the fitter (numba): the same global search as :mod:`irreflect.fitting`.

Why numba: a fit is a few hundred evaluations of the model on a few hundred points, each
followed by a tiny linear solve; in numpy three quarters of the time is call overhead on
small arrays. Here every step (the per-angle decomposition that gives the data-driven
starts, the screening, the bounded Levenberg-Marquardt with Kaufman's Jacobian, the
global scans and the basin hops) is a loop over scalars compiled once and cached on disk
(``cache=True``), for one table or for a whole batch of subsets in one call.

The numpy code in :mod:`irreflect.fitting` is the reference implementation: the kernel
follows it step by step (same candidates in the same order, same tie-breaking, same
stopping rules), so the two reach the same optimum; sums are taken in another order, so
the numbers agree to rounding, not to the bit (tests hold R^2 to 1e-9). The plain
two-lobe model's fast path scores screening and scan candidates from their Gram matrices
(the residuals themselves only where that would keep too few digits) and counts lobes
below exp(-340) of their peak as 0; subset batches score the shared candidates and the
per-angle decomposition from per-point products summed over each subset's points.

Models: the paper's two-lobe model (Eqs. 19-22) with any chain of the diagnosis
catalogue's extensions (:mod:`irreflect.models.extensions`), described by
:func:`model_code`; other models use the numpy path. Angles in radians.
"""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

from .models.base import cap_share

TWO_PI = 2.0 * math.pi
RIDGE = 1e-12
EXTREME = 1e8
STOP_FTOL, STOP_XTOL, STOP_STUCK, STOP_MAXITER, STOP_NONFINITE = 1, 2, 3, 4, 5

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


def model_code(model) -> np.ndarray | None:
    """The kernel's description of ``model``: extension codes innermost first, or None when
    the kernel does not cover the model (then the numpy path fits it)."""
    from .models.extensions import applied_extensions, base_of

    if base_of(model).name != "two-lobe":
        return None
    codes = []
    for name in applied_extensions(model):
        if name not in EXT_CODES:
            return None
        codes.append(EXT_CODES[name])
    return np.array(codes, np.int64)


#: The specular share's rule (models.base.cap_share: it saturates at 1), compiled from the
#: very function the numpy code calls.
_cap_share = njit(cache=True)(cap_share)


@njit(cache=True)
def _saturates(u, s, strict):
    """Whether the share ``u s`` saturates (:data:`_cap_share`); ``strict``: a point
    exactly at its threshold (the same curve either way) counts as unsaturated, the side
    whose derivative sees ``u``."""
    if strict:
        return u * s > 1.0 + 1e-9
    return _cap_share(u * s) >= 1.0


@njit(cache=True)
def _share_at_normal(alpha):
    """``u_as = alpha_1 / (alpha_0 + alpha_1)`` (0 without power)."""
    k = alpha[0] + alpha[1]
    return alpha[1] / k if k > 0.0 else 0.0


# ----------------------------------------------------------------------------- exp
@intrinsic
def _bits_as_float(typingctx, bits):
    """The float64 whose IEEE bits are the int64 ``bits`` (a register reinterpretation)."""
    sig = types.float64(types.int64)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.DoubleType())

    return sig, codegen


_LOG2E = 1.4426950408889634
_LN2_HI = 6.93147180369123816490e-01  # ln 2 in two parts (Cody and Waite): k * _LN2_HI is
_LN2_LO = 1.90821492927058770002e-10  # exact for every |k| < 2^11
_E2, _E3, _E4, _E5, _E6, _E7 = 1 / 2, 1 / 6, 1 / 24, 1 / 120, 1 / 720, 1 / 5040
_E8, _E9, _E10, _E11, _E12, _E13 = (1 / 40320, 1 / 362880, 1 / 3628800, 1 / 39916800,
                                    1 / 479001600, 1 / 6227020800)


@njit(cache=True, inline="always")
def fexp(x):
    """``exp(x)`` within one unit in the last place, in plain arithmetic (no library call),
    so that loops over points compile to vector instructions: the exponentials are most of
    a fit's work and the library's ``exp`` is a scalar call (4-7 ns; this: about 1 ns in a
    vectorised loop). ``x = k ln 2 + r``, ``|r| <= ln 2 / 2``, ``exp(r)`` by its Taylor
    polynomial of degree 13 (truncation < 1e-17 relative), ``2^k`` built from its bits in
    two factors (so that subnormal results and overflow come out as IEEE arithmetic gives
    them). NaN in, NaN out; exp(-inf) = 0, exp(inf) = inf."""
    xc = x if x > -746.0 else -746.0
    xc = xc if xc < 710.0 else 710.0
    kf = math.floor(xc * _LOG2E + 0.5)
    r = (xc - kf * _LN2_HI) - kf * _LN2_LO
    p = _E13
    p = p * r + _E12
    p = p * r + _E11
    p = p * r + _E10
    p = p * r + _E9
    p = p * r + _E8
    p = p * r + _E7
    p = p * r + _E6
    p = p * r + _E5
    p = p * r + _E4
    p = p * r + _E3
    p = p * r + _E2
    p = p * r + 1.0
    p = p * r + 1.0
    k = np.int64(kf)
    k1 = k >> 1
    out = p * _bits_as_float((k1 + 1023) << 52) * _bits_as_float((k - k1 + 1023) << 52)
    return out if x == x else x


#: Below exp(LOBE_FLOOR) (about 1e-148) a lobe's power counts as 0 in the search: its
#: products (squares, times weights) then never leave the normal range of floating point,
#: where the processor is fast (a subnormal or underflowing result costs it twice as long
#: or more); the costs change by less than 1e-290 of the lobes' peak values.
LOBE_FLOOR = -340.0


@njit(cache=True, inline="always")
def lexp(x):
    """``exp(x)`` of a lobe's power in the search: :func:`fexp`, 0 below LOBE_FLOOR (the
    input is replaced there, so that no lane of a vector loop computes an underflow)."""
    keep = x > LOBE_FLOOR
    out = fexp(x if keep else 0.0)
    out = out if keep else 0.0
    return out if x == x else x


# ----------------------------------------------------------------------------- geometry
@njit(cache=True)
def _lobe(log_cos, positive, n):
    """Lobe ``(n+1)/2pi cos^n`` and ``d lobe / d n`` from ``log cos``."""
    if positive:
        power = fexp(n * log_cos)
    else:
        power = 0.0
    lobe = (n + 1.0) / TWO_PI * power
    return lobe, power / TWO_PI + lobe * log_cos


@njit(cache=True)
def _cos_parts(angle):
    c = math.cos(angle)
    if c > 0.0:
        return math.log(c), True
    return 0.0, False


# ----------------------------------------------------------------------------- the model
@njit(cache=True)
def _two_lobe_point(s, nd, ns, lcg, lct, pt, lcp, pp, deriv, b, db):
    """Two-lobe basis (2 columns, see model._two_lobe_basis) and its derivative at one
    point; ``s = cos^v_as``, ``nd``, ``ns`` are the point's angle-of-incidence values."""
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
    _two_lobe_point(gval[g, 0], gval[g, 1], gval[g, 2], geo[2][j], lct, pt, lcp, pp, deriv, b,
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
    return (gamma, theta, lcg, lct, pt, lcp, pp, group)


# ----------------------------------------------------------------------------- projection
@njit(cache=True)
def _inverse(g, free, scale, out):
    """Inverse of the free block of the Gram matrix ``g`` (ridge ``RIDGE * scale`` on the
    diagonal, 1 on fixed columns), zero outside it (as fitting._solve_linear)."""
    ll = g.shape[0]
    if ll == 1:
        out[0, 0] = 1.0 / (g[0, 0] + RIDGE * scale[0]) if free[0] else 0.0
        return
    if ll == 2:
        a00 = g[0, 0] + RIDGE * scale[0] if free[0] else 1.0
        a11 = g[1, 1] + RIDGE * scale[1] if free[1] else 1.0
        a01 = g[0, 1] if (free[0] and free[1]) else 0.0
        det = a00 * a11 - a01 * a01
        out[0, 0] = a11 / det if free[0] else 0.0
        out[1, 1] = a00 / det if free[1] else 0.0
        off = -a01 / det if (free[0] and free[1]) else 0.0
        out[0, 1] = off
        out[1, 0] = off
        return
    a = np.empty((ll, ll))
    for i in range(ll):
        for j in range(ll):
            if free[i] and free[j]:
                a[i, j] = g[i, j]
            else:
                a[i, j] = 0.0
        a[i, i] += RIDGE * scale[i] if free[i] else 1.0
    out[:, :] = np.linalg.inv(a)
    for i in range(ll):
        for j in range(ll):
            if not (free[i] and free[j]):
                out[i, j] = 0.0


@njit(cache=True, error_model="numpy")
def _lm_step(z, lo, hi, lam, grad, hess, pinned, a, rhs, step, zt):
    """One bounded Levenberg-Marquardt trial point ``zt`` from ``z``: coordinates at a bound
    whose gradient points outwards are pinned (their row and column of ``hess`` and their
    gradient cleared), the diagonal damped by ``lam`` (relative to itself, floored), the
    step solved and the trial point clipped into ``[lo, hi]``. ``grad`` and ``hess`` are
    modified; ``pinned``, ``a``, ``rhs``, ``step`` are scratch."""
    p = z.size
    for q in range(p):
        pinned[q] = (z[q] <= lo[q] + 1e-12 and grad[q] > 0.0) or \
            (z[q] >= hi[q] - 1e-12 and grad[q] < 0.0)
    for q in range(p):
        if pinned[q]:
            for r in range(p):
                hess[q, r] = 0.0
                hess[r, q] = 0.0
            hess[q, q] = 1.0
            grad[q] = 0.0
    dmax = 0.0
    for q in range(p):
        dmax = max(dmax, hess[q, q])
    a[:, :] = hess
    for q in range(p):
        d = max(hess[q, q], 1e-12 * dmax + 1e-300)
        a[q, q] += lam * d
        rhs[q] = -grad[q]
    _solve_small(a, rhs, step)
    for q in range(p):
        if not math.isfinite(step[q]):
            step[q] = 0.0
        zt[q] = min(max(z[q] + step[q], lo[q]), hi[q])


@njit(cache=True)
def _lm_verdict(z, zt, cost, tcost, lam, xtol, ftol):
    """Judge the trial point ``zt`` of a Levenberg-Marquardt step from ``z``: returns
    (better, the new damping, stop), ``stop`` 0 to go on, else why to stop, in this order:
    STOP_FTOL (an accepted step gained at most ``ftol`` of the cost), STOP_XTOL (a step of
    at most ``xtol`` relative to |z|), STOP_STUCK (the damping grew past 1e10)."""
    better = tcost < cost
    lam_new = max(lam / 3.0, 1e-12) if better else lam * 4.0
    dz = 0.0
    zn = 0.0
    for q in range(z.size):
        dz += (zt[q] - z[q]) ** 2
        zn += z[q] * z[q]
    if better and cost - tcost <= ftol * max(cost, 1e-300):
        return better, lam_new, STOP_FTOL
    if math.sqrt(dz) <= xtol * (math.sqrt(zn) + xtol):
        return better, lam_new, STOP_XTOL
    if lam_new > 1e10:
        return better, lam_new, STOP_STUCK
    return better, lam_new, 0


@njit(cache=True)
def _solve_small(a, b, x):
    """Solve the small system ``a x = b`` by Gaussian elimination with partial pivoting
    (``a`` and ``b`` are overwritten); a singular pivot leaves that component 0."""
    p = b.size
    for k in range(p):
        piv = k
        big = abs(a[k, k])
        for i in range(k + 1, p):
            if abs(a[i, k]) > big:
                big = abs(a[i, k])
                piv = i
        if piv != k:
            for j in range(p):
                tmp = a[k, j]
                a[k, j] = a[piv, j]
                a[piv, j] = tmp
            tmp = b[k]
            b[k] = b[piv]
            b[piv] = tmp
        if a[k, k] == 0.0:
            continue
        for i in range(k + 1, p):
            f = a[i, k] / a[k, k]
            if f != 0.0:
                for j in range(k, p):
                    a[i, j] -= f * a[k, j]
                b[i] -= f * b[k]
    for k in range(p - 1, -1, -1):
        acc = b[k]
        for j in range(k + 1, p):
            acc -= a[k, j] * x[j]
        x[k] = acc / a[k, k] if a[k, k] != 0.0 else 0.0


@njit(cache=True)
def _solve_gram(g, rhs, nonneg, residual, alpha, free, inv, scale):
    """:func:`_solve_linear` from the Gram matrix ``g`` (symmetric) and ``rhs`` (``scale``:
    scratch of length L)."""
    ll = rhs.size
    for i in range(ll):
        scale[i] = max(g[i, i], 1e-300)
        free[i] = g[i, i] > 0.0
    _inverse(g, free, scale, inv)
    _apply(inv, rhs, free, alpha)
    for _ in range(ll):
        worst = -1
        worst_value = 0.0
        total = 0.0
        largest = -1
        largest_value = -1.0
        for i in range(ll):
            if free[i]:
                a = alpha[i]
                if nonneg[i] and a < 0.0:
                    v = a * math.sqrt(scale[i])
                    if worst < 0 or v < worst_value:
                        worst = i
                        worst_value = v
                m = abs(a)
                total += m
                if m > largest_value:
                    largest = i
                    largest_value = m
        drop = worst
        if drop < 0 and residual >= 0 and free[residual]:
            r = abs(alpha[residual])
            if r > 0.0 and r < total / EXTREME:
                drop = largest
        if drop < 0:
            break
        free[drop] = False
        _inverse(g, free, scale, inv)
        _apply(inv, rhs, free, alpha)
    for i in range(ll):
        if not free[i]:
            alpha[i] = 0.0


@njit(cache=True)
def _apply(inv, rhs, free, alpha):
    ll = rhs.size
    for i in range(ll):
        acc = 0.0
        for k in range(ll):
            if free[k]:
                acc += inv[i, k] * rhs[k]
        alpha[i] = acc


@njit(cache=True)
def _evaluate(codes, nonneg, residual, z, table, deriv, st, sc):
    """Basis (weighted, fixed columns zeroed), linear coefficients, residuals and cost at
    ``z``. ``table``: (geometry, log cos of the angles of incidence, sqrt(weights),
    weighted power); ``st``: the evaluation's state (:func:`_gen_state`), written;
    ``sc``: scratch (:func:`_gen_scratch`). The linear step is the saturating share's
    (:func:`_capped_solve`): the state's ``alpha`` are the effective basis' coefficients
    (for the Jacobian), its ``alpha_true`` the model's."""
    geo, glcg, sw, yw = table
    bw, dbw, alpha, free, inv, resid, alpha_true, share = st
    b, db, bp, dbp, gval, sums, cw = sc
    n, ll = bw.shape
    p = z.size
    _group_values(z, gval[0], gval[1])
    if codes.size == 0:
        _two_lobe_fill(geo, gval[1], sw, deriv, bw, dbw)
    else:
        for j in range(n):
            _point(codes, z, j, geo, gval[1], deriv, b, db, bp, dbp)
            w = sw[j]
            for col in range(ll):
                bw[j, col] = b[col] * w
                if deriv:
                    for q in range(p):
                        dbw[j, col, q] = db[col, q]
    tau_g = cw[9]
    for g in range(glcg.size):
        sg = gval[1][g, 0]
        tau_g[g] = 1.0 / sg if sg > 1.0 else math.inf
    yy = 0.0
    for j in range(n):
        yy += yw[j] * yw[j]
    _group_grams(bw, yw, geo[7], tau_g, sums)
    cost, lower, tau = _capped_solve(sums, tau_g, yy, nonneg, residual, cw,
                                     (alpha, alpha_true, free, inv))
    share[0] = lower
    share[1] = tau
    if lower > 0.0 or tau >= 0.0:
        _saturate_basis(z, geo, glcg, sw, tau_g, lower, tau, deriv, bw, dbw)
    cost = 0.0
    for j in range(n):
        acc = yw[j]
        for col in range(ll):
            acc -= bw[j, col] * alpha[col]
        resid[j] = acc
        cost += acc * acc
    cost *= 0.5
    if not math.isfinite(cost):
        cost = math.inf
    for col in range(ll):
        if not free[col]:
            for j in range(n):
                bw[j, col] = 0.0
    return cost


@njit(cache=True)
def _gen_state(n, ll, p):
    """One evaluation's state of the generic path: weighted basis (n, L), its derivative
    (n, L, P), the effective coefficients, free columns, the free block's inverse,
    residuals, the model's coefficients, and (the saturation level, the threshold or -1)."""
    return (np.empty((n, ll)), np.empty((n, ll, p)), np.empty(ll), np.empty(ll, np.bool_),
            np.empty((ll, ll)), np.empty(n), np.empty(ll), np.zeros(2))


@njit(cache=True)
def _gen_scratch(ll, p, n_groups, glcg):
    """Scratch of the generic path's evaluations: one point's basis and derivative (and
    their copies for the central differences), the per-angle values, the per-angle Gram
    sums (:func:`_group_grams`) and the linear step's workspace (:func:`_capped_work`)."""
    gval = (glcg, np.empty((n_groups, 3)))
    return (np.empty(ll), np.empty((ll, p)), np.empty(ll), np.empty((ll, p)), gval,
            _group_sums(n_groups, ll), _capped_work(n_groups, ll))


@njit(cache=True)
def _group_sums(n_groups, ll):
    """Per angle of incidence: the Gram matrix and right-hand side of the basis as it is,
    and with the share's two columns saturated (see :func:`_group_grams`)."""
    return (np.zeros((n_groups, ll, ll)), np.zeros((n_groups, ll)),
            np.zeros((n_groups, ll, ll)), np.zeros((n_groups, ll)))


@njit(cache=True)
def _capped_work(n_groups, ll):
    """Workspace of :func:`_capped_solve`: a Gram matrix and right-hand side being summed,
    a transformed pair, the candidate's coefficients, free columns, inverse, column
    scales, the saturable angles in threshold order, the thresholds (set by the caller)."""
    return (np.empty((ll, ll)), np.empty(ll), np.empty((ll, ll)), np.empty(ll), np.empty(ll),
            np.empty(ll, np.bool_), np.empty((ll, ll)), np.empty(ll),
            np.empty(n_groups, np.int64), np.empty(n_groups))


@njit(cache=True, error_model="numpy")
def _group_grams(bw, yw, group, tau_g, sums):
    """Per angle of incidence ``g``: ``gu[g] = B'B`` and ``ru[g] = B'y`` of the weighted
    basis rows at that angle, and ``gs``, ``rs`` the same with the share's two columns
    replaced by the saturated column ``b0 + (b1 - b0) / s`` (``s = 1 / tau_g``; the
    curve where the share is 1, see models.base.saturated_column); angles that cannot
    saturate (``tau_g`` infinite) keep ``gs = gu``."""
    gu, ru, gs, rs = sums
    n, ll = bw.shape
    gu[:] = 0.0
    ru[:] = 0.0
    gs[:] = 0.0
    rs[:] = 0.0
    for j in range(n):
        g = group[j]
        y = yw[j]
        t = tau_g[g]
        sat = bw[j, 0] + (bw[j, 1] - bw[j, 0]) * t if t < math.inf else 0.0
        for a in range(ll):
            ba = bw[j, a]
            sa = ba if (a >= 2 or t == math.inf) else sat
            ru[g, a] += ba * y
            rs[g, a] += sa * y
            for c in range(a, ll):
                bc = bw[j, c]
                scv = bc if (c >= 2 or t == math.inf) else sat
                gu[g, a, c] += ba * bc
                gs[g, a, c] += sa * scv
    for g in range(gu.shape[0]):
        for a in range(ll):
            for c in range(a + 1, ll):
                gu[g, c, a] = gu[g, a, c]
                gs[g, c, a] = gs[g, a, c]


@njit(cache=True)
def _gram_candidate(g, r, yy, nonneg, residual, cw):
    """Non-negative least squares from a Gram matrix (:func:`_solve_gram`, into the
    workspace's coefficients, free columns and inverse); returns its cost
    ``0.5 (y'y - 2 a'r + a'G a)``."""
    alpha, free, inv, scale = cw[4], cw[5], cw[6], cw[7]
    _solve_gram(g, r, nonneg, residual, alpha, free, inv, scale)
    ll = r.size
    cost = yy
    for i in range(ll):
        cost -= 2.0 * alpha[i] * r[i]
        for k in range(ll):
            cost += alpha[i] * g[i, k] * alpha[k]
    cost *= 0.5
    return cost if math.isfinite(cost) else math.inf


@njit(cache=True)
def _keep_candidate(cw, out, tau):
    """Copy the workspace's candidate into ``out`` (effective coefficients, the model's
    coefficients, free columns, inverse); at a threshold ``tau`` (>= 0) the one column
    ``(1 - tau) b0 + tau b1`` carries ``K``: the model's are ``(K (1 - tau), K tau)``."""
    alpha, free, inv = cw[4], cw[5], cw[6]
    a_eff, a_true, f_eff, i_eff = out
    a_eff[:] = alpha
    a_true[:] = alpha
    f_eff[:] = free
    i_eff[:, :] = inv
    if tau >= 0.0:
        a_true[0] = alpha[0] * (1.0 - tau)
        a_true[1] = alpha[0] * tau


@njit(cache=True, error_model="numpy")
def _capped_solve(sums, tau_g, yy, nonneg, residual, cw, out):
    """The linear step of a model whose specular share saturates (fitting._linear_step,
    here from per-angle Gram sums): between consecutive thresholds ``tau`` (``1 /
    cos^v_as(gamma)`` of the angles where that exceeds 1) the model is linear in ``(K (1 -
    u), K u)`` with the angles past the interval saturated; each interval's
    non-negative least squares is kept when its ``u`` lies in it, each threshold's
    (``u = tau``, one column) always; the lowest cost wins. ``out``: (effective
    coefficients, the model's, free columns, inverse), written. Returns (cost from the
    Gram sums, the saturation level: angles with ``tau_g <= level`` saturate, the
    threshold of a solution on one or -1)."""
    gu, ru, gs, rs = sums
    gk, rk, gt, rt, alpha, order = cw[0], cw[1], cw[2], cw[3], cw[4], cw[8]
    n_groups, ll = ru.shape
    gk[:, :] = 0.0
    rk[:] = 0.0
    count = 0
    for g in range(n_groups):
        for a in range(ll):
            rk[a] += ru[g, a]
            for c in range(ll):
                gk[a, c] += gu[g, a, c]
        if tau_g[g] < 1.0:  # insertion in threshold order
            i = count
            while i > 0 and tau_g[order[i - 1]] > tau_g[g]:
                order[i] = order[i - 1]
                i -= 1
            order[i] = g
            count += 1
    best = math.inf
    best_lower = 0.0
    best_tau = -1.0
    lower = 0.0
    i = 0
    while True:
        upper = tau_g[order[i]] if i < count else 1.0
        cost = _gram_candidate(gk, rk, yy, nonneg, residual, cw)
        k = alpha[0] + alpha[1]
        u = alpha[1] / k if k > 0.0 else lower
        if cost < best and u >= lower and u <= upper:
            best = cost
            best_lower = lower
            best_tau = -1.0
            _keep_candidate(cw, out, -1.0)
        if i >= count:
            break
        t = upper  # past it, every angle with this threshold saturates
        while i < count and tau_g[order[i]] == t:
            g = order[i]
            for a in range(ll):
                rk[a] += rs[g, a] - ru[g, a]
                for c in range(ll):
                    gk[a, c] += gs[g, a, c] - gu[g, a, c]
            i += 1
        lower = t
        # the threshold itself: u = t, the one column (1 - t) b0 + t b1
        for a in range(ll):
            for c in range(ll):
                gt[a, c] = gk[a, c]
            rt[a] = rk[a]
        gt[0, 0] = ((1.0 - t) * (1.0 - t) * gk[0, 0] + 2.0 * t * (1.0 - t) * gk[0, 1]
                    + t * t * gk[1, 1])
        rt[0] = (1.0 - t) * rk[0] + t * rk[1]
        for c in range(2, ll):
            gt[0, c] = (1.0 - t) * gk[0, c] + t * gk[1, c]
            gt[c, 0] = gt[0, c]
        for c in range(ll):
            gt[1, c] = 0.0
            gt[c, 1] = 0.0
        rt[1] = 0.0
        cost = _gram_candidate(gt, rt, yy, nonneg, residual, cw)
        if cost < best:
            best = cost
            best_lower = t
            best_tau = t
            _keep_candidate(cw, out, t)
    return best, best_lower, best_tau


@njit(cache=True, error_model="numpy")
def _saturate_basis(z, geo, glcg, sw, tau_g, lower, tau, deriv, bw, dbw):
    """The effective basis the linear step chose (:func:`_capped_solve`): rows at angles
    with ``tau_g <= lower`` take the saturated column in both share columns (and its
    derivative); at a threshold ``tau >= 0`` column 0 becomes ``(1 - tau) b0 + tau b1``
    (column 1 is then fixed at 0), whose derivative along ``v_as`` has the threshold's
    own: ``d tau / d v_as = -tau ln cos gamma* = tau ln(tau) / v_as``."""
    n, ll = bw.shape
    p = z.size
    group = geo[7]
    lcg_all = geo[2]
    dtau = tau * math.log(tau) / z[0] if tau > 0.0 else 0.0
    for j in range(n):
        t = tau_g[group[j]]
        w = sw[j]
        b0 = bw[j, 0]
        b1 = bw[j, 1]
        if t <= lower:
            sat = b0 + (b1 - b0) * t
            if deriv:
                inv_w = 1.0 / w if w > 0.0 else 0.0
                for q in range(p):
                    d = dbw[j, 0, q] + (dbw[j, 1, q] - dbw[j, 0, q]) * t
                    dbw[j, 0, q] = d
                    dbw[j, 1, q] = d
                dbw[j, 0, 0] -= (b1 - b0) * inv_w * t * lcg_all[j]
                dbw[j, 1, 0] = dbw[j, 0, 0]
            b0 = sat
            b1 = sat
            bw[j, 0] = sat
            bw[j, 1] = sat
        if tau >= 0.0:
            bw[j, 0] = (1.0 - tau) * b0 + tau * b1
            bw[j, 1] = 0.0
            if deriv:
                inv_w = 1.0 / w if w > 0.0 else 0.0
                for q in range(p):
                    dbw[j, 0, q] = (1.0 - tau) * dbw[j, 0, q] + tau * dbw[j, 1, q]
                    dbw[j, 1, q] = 0.0
                dbw[j, 0, 0] += (b1 - b0) * inv_w * dtau


@njit(cache=True)
def _two_lobe_fill(geo, gval, sw, deriv, bw, dbw):
    """The plain two-lobe model's weighted basis and unweighted derivative at every point
    (the hot loop: two exponentials per point, the angle-of-incidence parts from gval)."""
    lcg_all, lct_all, pt_all, lcp_all, pp_all, group = geo[2], geo[3], geo[4], geo[5], \
        geo[6], geo[7]
    for j in range(sw.size):
        g = group[j]
        s = gval[g, 0]
        nd = gval[g, 1]
        ns = gval[g, 2]
        lct = lct_all[j]
        lcp = lcp_all[j]
        pd = fexp(nd * lct) if pt_all[j] else 0.0
        ps = fexp(ns * lcp) if pp_all[j] else 0.0
        ld = (nd + 1.0) / TWO_PI * pd
        ls = (ns + 1.0) / TWO_PI * ps
        diff = ls - ld
        w = sw[j]
        bw[j, 0] = ld * w
        bw[j, 1] = (ld + s * diff) * w
        if deriv:
            lcg = lcg_all[j]
            dd = nd * (pd / TWO_PI + ld * lct)
            ds = ns * (ps / TWO_PI + ls * lcp)
            oms = 1.0 - s
            dbw[j, 0, 0] = 0.0
            dbw[j, 0, 1] = dd
            dbw[j, 0, 2] = dd * lcg
            dbw[j, 0, 3] = 0.0
            dbw[j, 0, 4] = 0.0
            dbw[j, 1, 0] = s * diff * lcg
            dbw[j, 1, 1] = oms * dd
            dbw[j, 1, 2] = oms * dd * lcg
            dbw[j, 1, 3] = s * ds
            dbw[j, 1, 4] = s * ds * lcg


@njit(cache=True)
def _jacobian(bw, dbw, alpha, inv, sw, jac, jm, t, coef):
    """Kaufman's Jacobian of the projected residual: ``(P_B - I) dB/dz alpha``
    (``jm``, ``t``, ``coef``: scratch of shapes (n, P), (L, P), (L, P))."""
    n, ll = bw.shape
    p = jac.shape[1]
    for j in range(n):
        for q in range(p):
            acc = 0.0
            for col in range(ll):
                acc += dbw[j, col, q] * alpha[col]
            jm[j, q] = acc * sw[j]
    t[:, :] = 0.0
    for j in range(n):
        for col in range(ll):
            bjc = bw[j, col]
            if bjc != 0.0:
                for q in range(p):
                    t[col, q] += bjc * jm[j, q]
    for col in range(ll):
        for q in range(p):
            acc = 0.0
            for k in range(ll):
                acc += inv[col, k] * t[k, q]
            coef[col, q] = acc
    for j in range(n):
        for q in range(p):
            acc = -jm[j, q]
            for col in range(ll):
                acc += bw[j, col] * coef[col, q]
            jac[j, q] = acc


@njit(cache=True)
def _lm(codes, nonneg, residual, z0, bounds, table, stop, z_out, alpha_out):
    """Bounded Levenberg-Marquardt from one start (fitting._lm_loop for one problem).
    ``bounds``: (lower, upper); ``table``: as :func:`_evaluate`; ``stop``: (max_iter,
    ftol, xtol). Returns (cost, reason, nfev); writes z_out and alpha_out (the model's
    coefficients)."""
    lo, hi = bounds
    max_iter, ftol, xtol = stop
    geo, glcg, sw, yw = table
    n = sw.size
    p = z0.size
    pp, ll = _sizes(codes, codes.size)
    cur = _gen_state(n, ll, p)
    trial = _gen_state(n, ll, p)
    sc = _gen_scratch(ll, p, glcg.size, glcg)
    jac = np.empty((n, p))
    z = np.empty(p)
    zt = np.empty(p)
    for q in range(p):
        z[q] = min(max(z0[q], lo[q]), hi[q])
    cost = _evaluate(codes, nonneg, residual, z, table, True, cur, sc)
    nfev = 1
    lam = 1e-3
    if not math.isfinite(cost):
        z_out[:] = z
        alpha_out[:] = cur[6]
        return math.inf, STOP_NONFINITE, nfev
    reason = STOP_MAXITER
    grad = np.empty(p)
    hess = np.empty((p, p))
    pinned = np.empty(p, np.bool_)
    jm = np.empty((n, p))
    tt = np.empty((ll, p))
    coef = np.empty((ll, p))
    a = np.empty((p, p))
    rhs = np.empty(p)
    step = np.empty(p)
    for _ in range(max_iter):
        bw, dbw, alpha, inv, resid = cur[0], cur[1], cur[2], cur[4], cur[5]
        _jacobian(bw, dbw, alpha, inv, sw, jac, jm, tt, coef)
        for q in range(p):
            acc = 0.0
            for j in range(n):
                acc += jac[j, q] * resid[j]
            grad[q] = acc
            for r in range(q, p):
                acc = 0.0
                for j in range(n):
                    acc += jac[j, q] * jac[j, r]
                hess[q, r] = acc
                hess[r, q] = acc
        _lm_step(z, lo, hi, lam, grad, hess, pinned, a, rhs, step, zt)
        tcost = _evaluate(codes, nonneg, residual, zt, table, True, trial, sc)
        better, lam, stop_now = _lm_verdict(z, zt, cost, tcost, lam, xtol, ftol)
        nfev += 1
        if better:
            z[:] = zt
            cost = tcost
            cur, trial = trial, cur
        if stop_now:
            reason = stop_now
            break
    z_out[:] = z
    alpha_out[:] = cur[6]
    return cost, reason, nfev


@njit(cache=True)
def _costs(codes, nonneg, residual, cands, table):
    """Projected cost of every candidate row (no derivatives)."""
    m, p = cands.shape
    glcg, sw = table[1], table[2]
    n = sw.size
    pp, ll = _sizes(codes, codes.size)
    st = _gen_state(n, ll, 1)
    sc = _gen_scratch(ll, p, glcg.size, glcg)
    out = np.empty(m)
    for i in range(m):
        out[i] = _evaluate(codes, nonneg, residual, cands[i], table, False, st, sc)
    return out


# ----------------------------------------------------------------------------- data-driven starts
@njit(cache=True)
def _two_columns(gdd, gss, gds, rd, rs, yy):
    """model._two_column_nnls for one grid node."""
    det = gdd * gss - gds * gds
    good = det > 1e-12 * gdd * gss
    cd = (gss * rd - gds * rs) / det if good else -1.0
    cs = (gdd * rs - gds * rd) / det if good else -1.0
    cost_both = yy - cd * rd - cs * rs if (cd >= 0.0 and cs >= 0.0) else math.inf
    d_only = max(rd, 0.0) / gdd if gdd > 0.0 else 0.0
    s_only = max(rs, 0.0) / gss if gss > 0.0 else 0.0
    cost_d = yy - d_only * rd
    cost_s = yy - s_only * rs
    if cost_d <= cost_s:
        cost_single, c1, c2 = cost_d, d_only, 0.0
    else:
        cost_single, c1, c2 = cost_s, 0.0, s_only
    if cost_both < cost_single:
        cost, c1, c2 = cost_both, cd, cs
    else:
        cost = cost_single
    if not math.isfinite(cost):
        cost = math.inf
    return cost, c1, c2


@njit(cache=True)
def _trend(x, y, valid):
    """model._trend for one row: (intercept, slope); NaN without a valid entry."""
    count = 0.0
    sx = 0.0
    sy = 0.0
    for i in range(x.size):
        if valid[i]:
            count += 1.0
            sx += x[i]
            sy += y[i]
    if count == 0.0:
        return math.nan, math.nan
    xm = sx / count
    ym = sy / count
    sxx = 0.0
    sxy = 0.0
    for i in range(x.size):
        if valid[i]:
            dx = x[i] - xm
            sxx += dx * dx
            sxy += dx * (y[i] - ym)
    slope = sxy / sxx if sxx > 1e-12 else 0.0
    return ym - slope * xm, slope


@njit(cache=True)
def _profile_starts(levels, prof, ok):
    """model.two_lobe_profile_starts for one profile: (5, 5)."""
    g_count = levels.size
    x = np.empty(g_count)
    zero = np.zeros(g_count)
    ln_nd = np.empty(g_count)
    ln_ns = np.empty(g_count)
    ln_as = np.empty(g_count)
    spec = np.empty(g_count, np.bool_)
    spec_share = np.empty(g_count, np.bool_)
    for g in range(g_count):
        x[g] = math.log(math.cos(levels[g]))
        d, s = prof[g, 2], prof[g, 3]
        spec[g] = ok[g] and s > 0.0
        total = d + s
        share = s / total if total > 0.0 else math.nan
        spec_share[g] = spec[g] and share > 0.0
        ln_nd[g] = math.log(prof[g, 0]) if ok[g] else math.nan
        ln_ns[g] = math.log(prof[g, 1]) if ok[g] else math.nan
        ln_as[g] = math.log(share) if share > 0.0 else math.nan
    a_nd, b_nd = _trend(x, ln_nd, ok)
    a_ns, b_ns = _trend(x, ln_ns, spec)
    _, b_as = _trend(x, ln_as, spec_share)
    c_nd, _ = _trend(zero, ln_nd, ok)
    c_ns, _ = _trend(zero, ln_ns, spec)
    fallback = np.array([0.0, 0.0, 0.3, math.log(30.0), 0.0])
    rows = np.empty((5, 5))
    ln4 = math.log(4.0)
    vals = ((b_as, a_nd, b_nd, a_ns, b_ns), (0.0, c_nd, 0.0, c_ns, 0.0),
            (b_as, a_nd, b_nd, a_ns + ln4, b_ns), (b_as, a_nd, b_nd, a_ns - ln4, b_ns),
            (b_as, a_nd, b_nd, c_ns, 0.0))
    for r in range(5):
        row = vals[r]
        for c in range(5):
            v = row[c]
            rows[r, c] = v if math.isfinite(v) else fallback[c]
    return rows


@njit(cache=True)
def _median_specular(prof, ok):
    count = 0
    for g in range(ok.size):
        if ok[g] and prof[g, 3] > 0.0:
            count += 1
    if count == 0:
        return 20.0
    vals = np.empty(count)
    k = 0
    for g in range(ok.size):
        if ok[g] and prof[g, 3] > 0.0:
            vals[k] = prof[g, 1]
            k += 1
    return np.median(vals)


@njit(cache=True)
def _own_starts(prof, ok, levels, jitter, lo, hi, ext_start, extra):
    """The caller's ``extra`` starts, then the model's data-driven starts (profile rows of
    the per-angle decomposition ``prof``/``ok``, fixed rows), random perturbations of the
    first row, clipped and made unique (sorted rows, as numpy.unique(axis=0))."""
    prow = _profile_starts(levels, prof, ok)
    n_est = _median_specular(prof, ok)
    p = lo.size
    n_rows = extra.shape[0] + 9 + ext_start.shape[0] - 1 + jitter.shape[0]
    rows = np.empty((n_rows, p))
    r = 0
    for i in range(extra.shape[0]):
        rows[r] = extra[i]
        r += 1
    for i in range(5):
        rows[r, :5] = prow[i]
        rows[r, 5:] = ext_start[0]
        r += 1
    for ln_ns in (math.log(n_est), math.log(30.0)):
        for v_as in (-2.5, 0.5):
            rows[r, 0] = v_as
            rows[r, 1] = 0.0
            rows[r, 2] = 0.3
            rows[r, 3] = ln_ns
            rows[r, 4] = 0.0
            rows[r, 5:] = ext_start[0]
            r += 1
    for e in range(1, ext_start.shape[0]):  # the first base start with the other new values
        rows[r, :5] = prow[0]
        rows[r, 5:] = ext_start[e]
        r += 1
    first = rows[0].copy()
    for i in range(jitter.shape[0]):
        for q in range(p):
            rows[r, q] = first[q] + jitter[i, q]
        r += 1
    for i in range(n_rows):
        for q in range(p):
            rows[i, q] = min(max(rows[i, q], lo[q]), hi[q])
    return _unique_rows(rows)


@njit(cache=True)
def _row_less(a, b):
    for q in range(a.size):
        if a[q] < b[q]:
            return True
        if a[q] > b[q]:
            return False
    return False


@njit(cache=True)
def _unique_rows(rows):
    m = rows.shape[0]
    order = np.arange(m)
    for i in range(1, m):  # insertion sort: a handful of rows
        k = order[i]
        j = i - 1
        while j >= 0 and _row_less(rows[k], rows[order[j]]):
            order[j + 1] = order[j]
            j -= 1
        order[j + 1] = k
    keep = np.ones(m, np.bool_)
    for i in range(1, m):
        same = True
        for q in range(rows.shape[1]):
            if rows[order[i], q] != rows[order[i - 1], q]:
                same = False
                break
        keep[i] = not same
    out = np.empty((keep.sum(), rows.shape[1]))
    k = 0
    for i in range(m):
        if keep[i]:
            out[k] = rows[order[i]]
            k += 1
    return out


@njit(cache=True)
def _stable_order(values):
    return np.argsort(values, kind="mergesort")


@njit(cache=True)
def _diverse(cands, costs, k, lo, hi, min_distance):
    """fitting._diverse_best: indices of up to k low-cost candidates apart from each other."""
    p = lo.size
    width = np.empty(p)
    for q in range(p):
        width[q] = hi[q] - lo[q] if hi[q] > lo[q] else 1.0
    chosen = np.empty(k, np.int64)
    count = 0
    for i in _stable_order(costs):
        if count == k or not math.isfinite(costs[i]):
            break
        ok = True
        for c in range(count):
            j = chosen[c]
            d = 0.0
            for q in range(p):
                u = (cands[i, q] - lo[q]) / width[q] - (cands[j, q] - lo[q]) / width[q]
                d += u * u
            if math.sqrt(d / p) < min_distance:
                ok = False
                break
        if ok:
            chosen[count] = i
            count += 1
    return chosen[:count]


@njit(cache=True)
def _scan_candidates(z, axes):
    """One row per value of every coordinate's scan axis, the others held at ``z``."""
    p, m = axes.shape
    out = np.empty((p * m, p))
    for q in range(p):
        for i in range(m):
            out[q * m + i] = z
            out[q * m + i, q] = axes[q, i]
    return out


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
def tl_points(geo, n_groups, sw, yw, weights, power, mask, pts, gstart, lgroup, pgroup):
    """Write the points of ``mask`` into ``pts`` (block order, see above), the blocks'
    starts into ``gstart`` (G + 1) and each point's level of the per-angle decomposition
    (``pgroup``, rounded angles) into ``lgroup``; returns the number of points."""
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
    return (np.zeros((n_groups, 6)), np.empty(n_groups), np.empty(n_groups, np.int64),
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
        if t < 1.0:  # insertion in threshold order
            i = count
            while i > 0 and tau_g[order[i - 1]] > t:
                order[i] = order[i - 1]
                i -= 1
            order[i] = g
            count += 1
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
    return (np.zeros((_TL_VEC, n)), np.zeros((2, _LIN)), np.empty((2, 5)), np.empty(5),
            np.empty((5, 5)), np.empty((5, 5)), np.empty(5), np.empty(5), np.empty(5),
            np.empty(5), np.empty(5, np.bool_), np.zeros(3 * n + 8), _tl_cap_work(n_groups))


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
        _lm_step(z, lo, hi, lam, grad, hess, pinned, a, rhs, step, zt)
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
def _tl_profile(pts, m, lgroup, n_levels, nd_grid, ns_grid):
    """:func:`_profile` of the points ``pts[:, :m]`` (weights and power from its rows, the
    level of each in ``lgroup``): per level (diffuse index, specular index, diffuse,
    specular) and ok. The products of every diffuse and specular grid lobe are summed
    level by level, point by point (the sums of :func:`_profile_add`, in its order)."""
    d_count = nd_grid.size
    s_count = ns_grid.size
    ldt, lst = _profile_lobes(pts, m, nd_grid, ns_grid)
    sums = np.zeros((n_levels, _profile_width(d_count, s_count)))
    counts = np.zeros(n_levels, np.int64)
    gdd = np.empty(d_count)
    rd = np.empty(d_count)
    gss = np.empty(s_count)
    rs = np.empty(s_count)
    gds = np.empty((d_count, s_count))
    o_rd = 1 + d_count
    o_ss = 1 + 2 * d_count
    o_rs = o_ss + s_count
    o_ds = o_rs + s_count
    for gi in range(n_levels):
        yy = 0.0
        gdd[:] = 0.0
        rd[:] = 0.0
        gss[:] = 0.0
        rs[:] = 0.0
        gds[:, :] = 0.0
        count = 0
        for k in range(m):
            if lgroup[k] != gi or not pts[7, k] > 0.0:
                continue
            count += 1
            wc = pts[7, k]
            yc = pts[8, k]
            yy += wc * yc * yc
            for a in range(d_count):
                v = wc * ldt[k, a]
                gdd[a] += v * ldt[k, a]
                rd[a] += v * yc
            for a in range(s_count):
                v = wc * lst[k, a]
                gss[a] += v * lst[k, a]
                rs[a] += v * yc
            for a in range(d_count):
                v = wc * ldt[k, a]
                for b in range(s_count):
                    gds[a, b] += v * lst[k, b]
        counts[gi] = count
        sums[gi, 0] = yy
        for a in range(d_count):
            sums[gi, 1 + a] = gdd[a]
            sums[gi, o_rd + a] = rd[a]
            for b in range(s_count):
                sums[gi, o_ds + a * s_count + b] = gds[a, b]
        for a in range(s_count):
            sums[gi, o_ss + a] = gss[a]
            sums[gi, o_rs + a] = rs[a]
    return _profile_pick(sums, counts, nd_grid, ns_grid)


@njit(cache=True)
def _profile_width(d_count, s_count):
    """Products per point of the per-angle decomposition: y'y, then per diffuse grid index
    l_d'l_d and l_d'y, per specular one l_s'l_s and l_s'y, then every l_d'l_s."""
    return 1 + 2 * d_count + 2 * s_count + d_count * s_count


@njit(cache=True, error_model="numpy")
def _profile_lobes(pts, m, nd_grid, ns_grid):
    """The grid lobes of the per-angle decomposition at the points ``pts[:, :m]``: (m, D)
    diffuse and (m, S) specular (the exponentials in loops over points, which vectorise;
    stored point by point for the sums)."""
    d_count = nd_grid.size
    s_count = ns_grid.size
    ld = np.empty((d_count, m))
    ls = np.empty((s_count, m))
    for a in range(d_count):
        n = nd_grid[a]
        c = (n + 1.0) / TWO_PI
        for k in range(m):
            ld[a, k] = c * (lexp(n * pts[0, k]) * pts[1, k])
    for a in range(s_count):
        n = ns_grid[a]
        c = (n + 1.0) / TWO_PI
        for k in range(m):
            ls[a, k] = c * (lexp(n * pts[2, k]) * pts[3, k])
    return ld.T.copy(), ls.T.copy()


@njit(cache=True, error_model="numpy", inline="always")
def _profile_add(ldt, lst, k, wc, yc, sums, gi):
    """Add point ``k``'s products (weight ``wc``, power ``yc``; layout: _profile_width) to
    ``sums[gi]``."""
    d_count = ldt.shape[1]
    s_count = lst.shape[1]
    o_rd = 1 + d_count
    o_ss = 1 + 2 * d_count
    o_rs = o_ss + s_count
    o_ds = o_rs + s_count
    sums[gi, 0] += wc * yc * yc
    for a in range(d_count):
        v = wc * ldt[k, a]
        sums[gi, 1 + a] += v * ldt[k, a]
        sums[gi, o_rd + a] += v * yc
    for a in range(s_count):
        v = wc * lst[k, a]
        sums[gi, o_ss + a] += v * lst[k, a]
        sums[gi, o_rs + a] += v * yc
    for a in range(d_count):
        v = wc * ldt[k, a]
        o = o_ds + a * s_count
        for s in range(s_count):
            sums[gi, o + s] += v * lst[k, s]


@njit(cache=True, error_model="numpy")
def _profile_pick(sums, counts, nd_grid, ns_grid):
    """The per-angle decomposition from each level's summed products (_profile_width):
    per level the grid node of least cost (_two_columns' numbers: the one-column fits
    once per row and column of the grid, the coefficients kept for the best node only),
    levels of fewer than 3 points not ok. Returns (prof (levels, 4), ok)."""
    n_levels = counts.size
    d_count = nd_grid.size
    s_count = ns_grid.size
    o_rd = 1 + d_count
    o_ss = 1 + 2 * d_count
    o_rs = o_ss + s_count
    o_ds = o_rs + s_count
    out = np.full((n_levels, 4), np.nan)
    ok = np.zeros(n_levels, np.bool_)
    cost_s = np.empty(s_count)
    costs = np.empty(s_count)
    for gi in range(n_levels):
        if counts[gi] < 3:
            continue
        yy = sums[gi, 0]
        for s in range(s_count):
            gss = sums[gi, o_ss + s]
            rs = sums[gi, o_rs + s]
            so = max(rs, 0.0) / gss if gss > 0.0 else 0.0
            cost_s[s] = yy - so * rs
        best = math.inf
        bi = 0
        bk = 0
        for a in range(d_count):
            gdd = sums[gi, 1 + a]
            rd = sums[gi, o_rd + a]
            d_only = max(rd, 0.0) / gdd if gdd > 0.0 else 0.0
            cost_d = yy - d_only * rd
            o = o_ds + a * s_count
            for s in range(s_count):
                gss = sums[gi, o_ss + s]
                gds = sums[gi, o + s]
                rs = sums[gi, o_rs + s]
                det = gdd * gss - gds * gds
                good = det > 1e-12 * gdd * gss
                cd = (gss * rd - gds * rs) / det if good else -1.0
                cs = (gdd * rs - gds * rd) / det if good else -1.0
                both = cd >= 0.0 and cs >= 0.0
                cost_both = yy - cd * rd - cs * rs if both else math.inf
                cost_single = min(cost_d, cost_s[s])
                cost = cost_both if cost_both < cost_single else cost_single
                costs[s] = cost if math.isfinite(cost) else math.inf
            for s in range(s_count):
                if costs[s] < best:
                    best = costs[s]
                    bi = a
                    bk = s
        bcd = 0.0
        bcs = 0.0
        if best < math.inf:  # the best node's coefficients (_two_columns)
            cost, bcd, bcs = _two_columns(sums[gi, 1 + bi], sums[gi, o_ss + bk],
                                          sums[gi, o_ds + bi * s_count + bk],
                                          sums[gi, o_rd + bi], sums[gi, o_rs + bk], yy)
        ok[gi] = True
        out[gi, 0] = nd_grid[bi]
        out[gi, 1] = ns_grid[bk]
        out[gi, 2] = bcd
        out[gi, 3] = bcs
    return out, ok


# ----------------------------------------------------------------------------- draws
# The counter-based generator of irreflect._draws, compiled: the same numbers from the
# same (key, stream, index), so that a fit draws its candidates inside its one call.
_U_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_U_M1 = np.uint64(0xBF58476D1CE4E5B9)
_U_M2 = np.uint64(0x94D049BB133111EB)
STREAM_STRATA, STREAM_OFFSETS, STREAM_JITTER, STREAM_HOPS = 0, 1, 2, 3


@njit(cache=True, inline="always")
def _mix64(x):
    x = (x ^ (x >> np.uint64(30))) * _U_M1
    x = (x ^ (x >> np.uint64(27))) * _U_M2
    return x ^ (x >> np.uint64(31))


@njit(cache=True)
def draw_uniforms(key, stream, count):
    """_draws.uniforms: ``count`` uniforms in (0, 1) of ``stream``."""
    base = _mix64(np.uint64(key) + _U_GOLDEN * np.uint64(stream + 1))
    out = np.empty(count)
    for i in range(count):
        h = _mix64(base + np.uint64(i + 1) * _U_GOLDEN)
        out[i] = (np.float64(h >> np.uint64(11)) + 0.5) * 2.0 ** -53
    return out


@njit(cache=True)
def draw_normals(key, stream, count):
    """_draws.normals: ``count`` standard normals of ``stream`` (Box-Muller)."""
    u = draw_uniforms(key, stream, 2 * count)
    out = np.empty(count)
    for i in range(count):
        out[i] = math.sqrt(-2.0 * math.log(u[2 * i])) * math.cos(TWO_PI * u[2 * i + 1])
    return out


@njit(cache=True)
def draw_latin_hypercube(key, n, lo, hi):
    """_draws.latin_hypercube: ``n`` points of a Latin hypercube in the box (lo, hi)."""
    p = lo.size
    keys = draw_uniforms(key, STREAM_STRATA, n * p)
    offsets = draw_uniforms(key, STREAM_OFFSETS, n * p)
    out = np.empty((n, p))
    for q in range(p):
        strata = np.argsort(keys[q * n:(q + 1) * n], kind="mergesort")
        for i in range(n):
            out[i, q] = lo[q] + (strata[i] + offsets[q * n + i]) / n * (hi[q] - lo[q])
    return out


# ----------------------------------------------------------------------------- the search
@njit(cache=True)
def global_search(codes, nonneg, residual, geo, glcg, power, weights, levels, group, nd_grid,
                  ns_grid, jitter, ext_start, extra, screen, lo, hi, zlo, zhi, axes, hops,
                  n_data_starts, n_keep, max_iter, max_rounds):
    """fitting._global_search_unit for one (normalised) table. Returns
    (z, alpha, cost, reason, n_starts, n_evals); cost inf when no start is finite.
    ``geo``: :func:`make_geometry`; ``glcg``: log cos of its exact angles of incidence;
    ``levels``/``group``: the rounded ones of the per-angle decomposition."""
    p = zlo.size
    pp, ll = _sizes(codes, codes.size)
    fast = codes.size == 0
    n = power.size
    sw = np.sqrt(weights)
    yw = sw * power
    pts = np.empty((_TL_ROWS, n))
    gstart = np.empty(glcg.size + 1, np.int64)
    lgroup = np.empty(n, np.int64)
    tl_points(geo, glcg.size, sw, yw, np.ones(n), power, np.ones(n, np.bool_), pts, gstart,
              lgroup, group)
    ws = tl_work(n, glcg.size)
    _tl_set_yy(pts, gstart, ws[12][0])
    prof, ok = _tl_profile(pts, n, lgroup, levels.size, nd_grid, ns_grid)
    own = _own_starts(prof, ok, levels, jitter, zlo, zhi, ext_start, extra)
    n_own = own.shape[0]
    m = n_own + screen.shape[0]
    cands = np.empty((m, p))
    cands[:n_own] = own
    for i in range(screen.shape[0]):
        for q in range(p):
            cands[n_own + i, q] = min(max(screen[i, q], zlo[q]), zhi[q])
    if fast:
        costs = _tl_screen_costs(cands, pts, gstart, glcg, nonneg, residual, ws)
    else:
        costs = _costs(codes, nonneg, residual, cands, (geo, glcg, sw, yw))
    n_evals = m
    first = _diverse(own, costs[:n_own], n_data_starts, lo, hi, 1e-9)
    others = _diverse(cands, costs, n_keep, lo, hi, 0.08)
    picks = np.unique(np.concatenate((first, others)))
    if picks.size == 0:
        picks = np.zeros(1, np.int64)
    zb = np.empty(p)
    ab = np.empty(ll)
    cb = math.inf
    rb = STOP_NONFINITE
    zt = np.empty(p)
    at = np.empty(ll)
    n_starts = picks.size
    for i in picks:
        if fast:
            c, r, nf = _tl_lm(nonneg, residual, cands[i], (zlo, zhi), (pts, gstart, glcg),
                              (max_iter, 1e-10, 1e-9), zt, at, ws)
        else:
            c, r, nf = _lm(codes, nonneg, residual, cands[i], (zlo, zhi),
                           (geo, glcg, sw, yw), (max_iter, 1e-10, 1e-9), zt, at)
        n_evals += nf
        if c < cb:
            cb = c
            rb = r
            zb[:] = zt
            ab[:] = at
    if not math.isfinite(cb):
        return zb, ab, cb, rb, n_starts, n_evals
    n_hops = hops.shape[1]
    width = np.empty(p)
    for q in range(p):
        width[q] = hi[q] - lo[q] if hi[q] > lo[q] else 1.0
    for rnd in range(max_rounds):
        scan = _scan_candidates(zb, axes)
        if fast:
            sc = _tl_scan_costs(zb, axes, pts, gstart, glcg, nonneg, residual, ws)
        else:
            sc = _costs(codes, nonneg, residual, scan, (geo, glcg, sw, yw))
        n_evals += scan.shape[0]
        n_axis = axes.shape[1]
        extra = np.empty((p + n_hops, p))
        k = 0
        for q in range(p):
            j = q * n_axis + np.argmin(sc[q * n_axis:(q + 1) * n_axis])
            if sc[j] < cb * (1.0 - 1e-9):
                extra[k] = scan[j]
                k += 1
        for h in range(n_hops):
            for q in range(p):
                extra[k, q] = min(max(zb[q] + hops[rnd, h, q] * width[q], zlo[q]), zhi[q])
            k += 1
        if k == 0:
            break
        best_c = math.inf
        best_r = 0
        zc = np.empty(p)
        ac = np.empty(ll)
        for i in range(k):
            for q in range(p):
                extra[i, q] = min(max(extra[i, q], zlo[q]), zhi[q])
            if fast:
                c, r, nf = _tl_lm(nonneg, residual, extra[i], (zlo, zhi),
                                  (pts, gstart, glcg), (max_iter, 1e-10, 1e-9), zt, at, ws)
            else:
                c, r, nf = _lm(codes, nonneg, residual, extra[i], (zlo, zhi),
                               (geo, glcg, sw, yw), (max_iter, 1e-10, 1e-9), zt, at)
            n_evals += nf
            n_starts += 1
            if c < best_c:
                best_c = c
                best_r = r
                zc[:] = zt
                ac[:] = at
        if not best_c < cb * (1.0 - 1e-12):
            break
        cb = best_c
        rb = best_r
        zb[:] = zc
        ab[:] = ac
    return zb, ab, cb, rb, n_starts, n_evals


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
    return (geo[0][idx], geo[1][idx], geo[2][idx], geo[3][idx], geo[4][idx], geo[5][idx],
            geo[6][idx], geo[7][idx])


@njit(cache=True, error_model="numpy")
def _profile_table(geo, weights, power, nd_grid, ns_grid):
    """Every point's products of the per-angle decomposition (:func:`_profile_add`; table
    order, weight and power of the table): a subset's per-level sums are then sums of
    its points' rows, without an exponential."""
    n = power.size
    pts = np.empty((9, n))
    for j in range(n):
        pts[0, j] = geo[3][j]
        pts[1, j] = 1.0 if geo[4][j] else 0.0
        pts[2, j] = geo[5][j]
        pts[3, j] = 1.0 if geo[6][j] else 0.0
    ldt, lst = _profile_lobes(pts, n, nd_grid, ns_grid)
    out = np.zeros((n, _profile_width(nd_grid.size, ns_grid.size)))
    for j in range(n):
        _profile_add(ldt, lst, j, weights[j], power[j], out, j)
    return out


#: Products per point and shared candidate (:func:`_shared_products`): x0 x0, x0 x1, x1 x1,
#: x0 y, x1 y (the sums of _tl_fill).
_SHARED = 5


@njit(cache=True, error_model="numpy", fastmath=_SUMS)
def _shared_products(cands, geo, glcg, sw, yw):
    """For every point (table order) and candidate row of the plain two-lobe model, the
    products whose sums over a subset's points at each angle of incidence are that
    angle's sums of the linear step (see _tl_fill; x: the weighted basis, y: the
    weighted power), as (n, _SHARED * candidates). Shared candidates are then scored on
    any subset without an exponential."""
    n = sw.size
    c_count = cands.shape[0]
    out = np.empty((n, _SHARED * c_count))
    gval = np.empty((glcg.size, 5))
    lct_all, pt_all, lcp_all, pp_all, group = geo[3], geo[4], geo[5], geo[6], geo[7]
    for c in range(c_count):
        z = cands[c]
        _tl_group_values(z, glcg, gval)
        o = _SHARED * c
        for j in range(n):
            g = group[j]
            a = lexp(gval[g, 1] * lct_all[j]) * (1.0 if pt_all[j] else 0.0)
            b = lexp(gval[g, 2] * lcp_all[j]) * (1.0 if pp_all[j] else 0.0)
            ld = gval[g, 3] * a
            ls = gval[g, 4] * b
            w = sw[j]
            x0 = ld * w
            x1 = (ld + gval[g, 0] * (ls - ld)) * w
            y = yw[j]
            out[j, o] = x0 * x0
            out[j, o + 1] = x0 * x1
            out[j, o + 2] = x1 * x1
            out[j, o + 3] = x0 * y
            out[j, o + 4] = x1 * y
    return out


@njit(cache=True, error_model="numpy")
def _subset_sums(mask, weights, groups, tables, out):
    """A subset's sums of its points' rows: the per-angle decomposition's products per
    level (points of positive weight, ``out[0]``; ``groups[0]``: each point's level) and
    the shared candidates' per angle of incidence (``out[1]``, (G, _SHARED *
    candidates); ``groups[1]``: each point's angle). ``tables``: the batch's
    (:func:`_profile_table`, :func:`_shared_products`)."""
    pgroup, egroup = groups
    qtab, shared = tables
    sums, gsums = out
    sums[:, :] = 0.0
    gsums[:, :] = 0.0
    width = sums.shape[1]
    n_shared = gsums.shape[1]
    for j in range(mask.size):
        if mask[j]:
            g = egroup[j]
            for i in range(n_shared):
                gsums[g, i] += shared[j, i]
            if weights[j] > 0.0:
                gi = pgroup[j]
                for i in range(width):
                    sums[gi, i] += qtab[j, i]


@njit(cache=True)
def subset_search(codes, nonneg, residual, geo, glcg, power, weights, masks, levels, group,
                  nd_grid, ns_grid, ext_first, screen, zlo, zhi, n_keep, n_data_starts,
                  max_iter, ftol):
    """fitting.fit_subsets' batched search for every mask row: the profile starts of each
    subset's points and the shared screening candidates, scored on the subset's points;
    Levenberg-Marquardt from the best ``n_keep`` candidates and the best
    ``n_data_starts`` data-driven starts. One thread (parallel runs use processes, see
    irreflect.selection.parallel). Returns (z (B, P), alpha (B, L), cost (B,),
    converged (B,), nfev)."""
    b_count, n = masks.shape
    p = zlo.size
    pp, ll = _sizes(codes, codes.size)
    z_out = np.full((b_count, p), np.nan)
    a_out = np.full((b_count, ll), np.nan)
    c_out = np.full(b_count, math.inf)
    conv = np.zeros(b_count, np.bool_)
    nfev_each = np.zeros(b_count, np.int64)
    n_screen = screen.shape[0]
    clipped = np.empty((n_screen, p))
    for i in range(n_screen):
        for q in range(p):
            clipped[i, q] = min(max(screen[i, q], zlo[q]), zhi[q])
    # per call, not per subset: the whole table's sqrt(weights) and weighted power, the
    # scratch of the subsets' points and of the fast path
    sw = np.sqrt(weights)
    yw = sw * power
    pts = np.empty((_TL_ROWS, n))
    gstart = np.empty(glcg.size + 1, np.int64)
    lgroup = np.empty(n, np.int64)
    ws = tl_work(n, glcg.size)
    if codes.size == 0:
        # the plain two-lobe model: every point's products of the per-angle decomposition
        # and of the shared candidates, once for the whole batch
        qtab = _profile_table(geo, weights, power, nd_grid, ns_grid)
        shared = _shared_products(clipped, geo, glcg, sw, yw)
    else:
        qtab = np.zeros((0, 0))
        shared = np.zeros((0, 0))
    sums = (np.empty((levels.size, _profile_width(nd_grid.size, ns_grid.size))),
            np.empty((glcg.size, _SHARED * n_screen)))
    for bi in range(b_count):
        _one_subset(codes, nonneg, residual, geo, glcg, power, weights, sw, yw, masks[bi],
                    levels, group, nd_grid, ns_grid, ext_first, clipped, zlo, zhi, n_keep,
                    n_data_starts, max_iter, ftol, z_out[bi], a_out[bi], c_out, conv,
                    nfev_each, bi, pts, gstart, lgroup, ws, qtab, shared, sums)
    return z_out, a_out, c_out, conv, nfev_each.sum()


@njit(cache=True)
def _one_subset(codes, nonneg, residual, geo, glcg, power, weights, sw_all, yw_all, mask,
                levels, group, nd_grid, ns_grid, ext_first, clipped, zlo, zhi, n_keep,
                n_data_starts, max_iter, ftol, z_row, a_row, c_out, conv, nfev_each, bi, pts,
                gstart, lgroup, ws, qtab, shared, sums):
    p = zlo.size
    pp, ll = _sizes(codes, codes.size)
    fast = codes.size == 0
    count = tl_points(geo, glcg.size, sw_all, yw_all, weights, power, mask, pts, gstart,
                      lgroup, group)
    _tl_set_yy(pts, gstart, ws[12][0])
    if fast:  # sums of the subset's rows of the batch's tables
        _subset_sums(mask, weights, (group, geo[7]), (qtab, shared), sums)
        counts = np.zeros(levels.size, np.int64)
        for j in range(mask.size):
            if mask[j] and weights[j] > 0.0:
                counts[group[j]] += 1
        prof, ok = _profile_pick(sums[0], counts, nd_grid, ns_grid)
    else:
        prof, ok = _tl_profile(pts, count, lgroup, levels.size, nd_grid, ns_grid)
    data = _profile_starts(levels, prof, ok)
    n_data = data.shape[0]
    n_screen = clipped.shape[0]
    cands = np.empty((n_data + n_screen, p))
    for i in range(n_data):
        for q in range(p):
            v = data[i, q] if q < 5 else ext_first[q - 5]
            cands[i, q] = min(max(v, zlo[q]), zhi[q])
    cands[n_data:] = clipped
    if fast:
        costs = np.empty(cands.shape[0])
        costs[:n_data] = _tl_costs(cands[:n_data], pts, gstart, glcg, nonneg, residual, ws)
        gsums = sums[1]
        gsum = ws[12][0]
        s_g = ws[12][4]
        for i in range(n_screen):
            o = _SHARED * i
            for g in range(glcg.size):
                for c in range(_SHARED):
                    gsum[g, c] = gsums[g, o + c]
                s_g[g] = fexp(clipped[i, 0] * glcg[g])
            costs[n_data + i] = _tl_gram_cost(clipped[i], s_g, pts, gstart, glcg, ws)
        sub = geo
        sw = sw_all
        yw = yw_all
    else:
        idx = np.empty(count, np.int64)
        k = 0
        for j in range(mask.size):
            if mask[j]:
                idx[k] = j
                k += 1
        sub = _take(geo, idx)
        sw = sw_all[idx]
        yw = yw_all[idx]
        costs = _costs(codes, nonneg, residual, cands, (sub, glcg, sw, yw))
    nfev = cands.shape[0]
    order = _stable_order(costs)
    data_order = _stable_order(costs[:n_data])
    n1 = min(n_keep, cands.shape[0])
    n2 = min(n_data_starts, n_data)
    best = math.inf
    zt = np.empty(p)
    at = np.empty(ll)
    done = np.empty(n1 + n2, np.int64)
    for k in range(n1 + n2):
        s = order[k] if k < n1 else data_order[k - n1]
        done[k] = s
        again = False
        for i in range(k):  # the same start again would end at the same point
            again = again or done[i] == s
        if again:
            continue
        if fast:
            c, r, nf = _tl_lm(nonneg, residual, cands[s], (zlo, zhi), (pts, gstart, glcg),
                              (max_iter, ftol, 1e-9), zt, at, ws)
        else:
            c, r, nf = _lm(codes, nonneg, residual, cands[s], (zlo, zhi), (sub, glcg, sw, yw),
                           (max_iter, ftol, 1e-9), zt, at)
        nfev += nf
        if c < best:
            best = c
            z_row[:] = zt
            a_row[:] = at
            conv[bi] = r == STOP_FTOL or r == STOP_XTOL or r == STOP_STUCK
    c_out[bi] = best
    nfev_each[bi] = nfev


# ----------------------------------------------------------------------------- per table, per fit
@njit(cache=True)
def kernel_geometry(gamma, theta):
    """fitting._kernel_geometry in one call: (geometry, log cos of the exact angles of
    incidence, the rounded ones of the per-angle decomposition (as numpy.round(gamma, 9)),
    each point's index among those, the exact angles of incidence)."""
    n = gamma.size
    order = np.argsort(gamma, kind="mergesort")
    group = np.empty(n, np.int64)
    exact = np.empty(n)
    g = -1
    for k in range(n):
        j = order[k]
        if g < 0 or gamma[j] != exact[g]:
            g += 1
            exact[g] = gamma[j]
        group[j] = g
    exact = exact[:g + 1].copy()
    rounded = np.empty(n)
    for j in range(n):
        rounded[j] = np.rint(gamma[j] * 1e9) / 1e9
    order = np.argsort(rounded, kind="mergesort")
    pgroup = np.empty(n, np.int64)
    levels = np.empty(n)
    g = -1
    for k in range(n):
        j = order[k]
        if g < 0 or rounded[j] != levels[g]:
            g += 1
            levels[g] = rounded[j]
        pgroup[j] = g
    levels = levels[:g + 1].copy()
    glcg = np.empty(exact.size)
    for i in range(exact.size):
        glcg[i] = math.log(math.cos(exact[i]))
    return make_geometry(gamma, theta, group, exact), glcg, levels, pgroup, exact


@njit(cache=True)
def _close(a, b, rtol, atol):
    """numpy.allclose(a, b, rtol, atol)."""
    for i in range(a.size):
        if not abs(a[i] - b[i]) <= atol + rtol * abs(b[i]):
            return False
    return True


@njit(cache=True)
def tl_natural(z, alpha, out):
    """models.paper._two_lobe_to_natural of one row."""
    k = alpha[0] + alpha[1]
    out[0] = alpha[1] / k if k > 0.0 else 0.0
    out[1] = z[0]
    out[2] = math.exp(z[1])
    out[3] = z[2]
    out[4] = math.exp(z[3])
    out[5] = z[4]
    out[6] = k


@njit(cache=True)
def tl_finish(z, alpha, geo, glcg, weights, power, absolute_sigma, cost, n_params):
    """What fit() computes after the search of the plain two-lobe model, in one call:
    natural parameters, whether they map back to (z, alpha) (fit's round-trip check),
    the fitted curve, R^2, RMSE, MSE, the covariance of the natural parameters and which
    lie along a near-singular direction (fitting._covariance, the same steps). Returns
    (values, round_trip_ok, fitted, r2, rmse, mse, covariance, singular)."""
    n = power.size
    p = 5
    k = p + 2
    values = np.empty(k)
    tl_natural(z, alpha, values)
    zb = np.empty(p)
    zb[0] = values[1]
    zb[1] = math.log(values[2])
    zb[2] = values[3]
    zb[3] = math.log(values[4])
    zb[4] = values[5]
    ab = np.empty(2)
    ab[0] = values[6] * (1.0 - values[0])
    ab[1] = values[6] * values[0]
    amax = max(abs(alpha[0]), abs(alpha[1]))
    ok = _close(zb, z, 1e-9, 1e-12) and _close(ab, alpha, 1e-6, 1e-9 * amax)
    # the fitted curve and the Jacobian in (z, alpha) of the weighted model (jacobian_full)
    fitted = np.empty(n)
    jfull = np.empty((n, k))
    a0 = alpha[0]
    a1 = alpha[1]
    gval = np.empty((glcg.size, 5))
    _tl_group_values(z, glcg, gval)
    lcg_all, lct_all, pt_all, lcp_all, pp_all, group = geo[2], geo[3], geo[4], geo[5], \
        geo[6], geo[7]
    u = _share_at_normal(alpha)
    for j in range(n):
        g = group[j]
        s = gval[g, 0]
        nd = gval[g, 1]
        ns = gval[g, 2]
        a = fexp(nd * lct_all[j]) if pt_all[j] else 0.0
        b = fexp(ns * lcp_all[j]) if pp_all[j] else 0.0
        ld = gval[g, 3] * a
        ls = gval[g, 4] * b
        diff = ls - ld
        lcg = lcg_all[j]
        dd = nd * (a / TWO_PI + ld * lct_all[j])
        ds = ns * (b / TWO_PI + ls * lcp_all[j])
        oms = 1.0 - s
        w = math.sqrt(weights[j])
        if _saturates(u, s, True):  # a_s = 1: K L_s (jacobian_full's saturated rows)
            fitted[j] = ls * (a0 + a1)
            jfull[j, 0] = 0.0
            jfull[j, 1] = 0.0
            jfull[j, 2] = 0.0
            jfull[j, 3] = ds * (a0 + a1) * w
            jfull[j, 4] = ds * lcg * (a0 + a1) * w
            jfull[j, 5] = ls * w
            jfull[j, 6] = ls * w
            continue
        b1 = ld + s * diff
        fitted[j] = ld * a0 + b1 * a1
        jfull[j, 0] = (0.0 * a0 + s * diff * lcg * a1) * w
        jfull[j, 1] = (dd * a0 + oms * dd * a1) * w
        jfull[j, 2] = (dd * lcg * a0 + oms * dd * lcg * a1) * w
        jfull[j, 3] = (0.0 * a0 + s * ds * a1) * w
        jfull[j, 4] = (0.0 * a0 + s * ds * lcg * a1) * w
        jfull[j, 5] = ld * w
        jfull[j, 6] = b1 * w
    mean = 0.0
    for j in range(n):
        mean += power[j]
    mean /= n
    ss_res = 0.0
    ss_tot = 0.0
    for j in range(n):
        ss_res += (power[j] - fitted[j]) ** 2
        ss_tot += (power[j] - mean) ** 2
    r2 = 1.0 - ss_res / ss_tot if ss_tot > 0.0 else (math.nan if ss_res == 0.0 else -math.inf)
    mse = ss_res / n
    # covariance (fitting._covariance)
    col = np.empty(k)
    for q in range(k):
        acc = 0.0
        for j in range(n):
            acc += jfull[j, q] * jfull[j, q]
        col[q] = math.sqrt(acc) if acc > 0.0 else 1.0
    info = np.empty((k, k))
    for q in range(k):
        for r in range(q, k):
            acc = 0.0
            for j in range(n):
                acc += (jfull[j, q] / col[q]) * (jfull[j, r] / col[r])
            info[q, r] = acc
            info[r, q] = acc
    dof = max(n - n_params, 1)
    s2 = 1.0 if absolute_sigma else 2.0 * cost / dof
    evals, evecs = np.linalg.eigh(info)
    floor = 1e-12 * max(evals.max(), 1e-300)
    weak = evals < floor
    cov_internal = np.zeros((k, k))
    for e in range(k):
        ev = max(evals[e], floor)
        for q in range(k):
            for r in range(k):
                cov_internal[q, r] += evecs[q, e] * evecs[r, e] / ev
    for q in range(k):
        for r in range(k):
            cov_internal[q, r] = cov_internal[q, r] * s2 / (col[q] * col[r])
    x0 = np.empty(k)
    x0[:p] = z
    x0[p:] = alpha
    grad = np.empty((k, k))  # d natural / d internal: (natural, internal)
    plus = np.empty(k)
    minus = np.empty(k)
    xp = np.empty(k)
    for i in range(k):
        step = 1e-6 * max(abs(x0[i]), 1e-3)
        xp[:] = x0
        xp[i] = x0[i] + step
        tl_natural(xp[:p], xp[p:], plus)
        xp[i] = x0[i] - step
        tl_natural(xp[:p], xp[p:], minus)
        for q in range(k):
            grad[q, i] = (plus[q] - minus[q]) / (2.0 * step)
    cov = grad @ cov_internal @ grad.T
    singular = np.zeros(k, np.bool_)
    for q in range(k):
        total = 0.0
        along = 0.0
        for i in range(k):
            total += (grad[q, i] / col[i]) ** 2
        for e in range(k):
            if weak[e]:
                acc = 0.0
                for i in range(k):
                    acc += grad[q, i] / col[i] * evecs[i, e]
                along += acc * acc
        singular[q] = math.sqrt(along) > 0.1 * max(math.sqrt(total), 1e-300)
    return values, ok, fitted, r2, math.sqrt(mse), mse, cov, singular


DEG = math.pi / 180.0  # numpy.radians multiplies by this (the same rounding)


@njit(cache=True)
def _pairwise_block(a, lo, n):
    """numpy's pairwise sum of ``a[lo:lo + n]`` for ``n <= 128``: sequential below 8,
    else eight running sums combined as numpy combines them, then the remainder."""
    if n < 8:
        acc = -0.0
        for i in range(n):
            acc += a[lo + i]
        return acc
    r0 = a[lo]
    r1 = a[lo + 1]
    r2 = a[lo + 2]
    r3 = a[lo + 3]
    r4 = a[lo + 4]
    r5 = a[lo + 5]
    r6 = a[lo + 6]
    r7 = a[lo + 7]
    i = 8
    while i < n - n % 8:
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    acc = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        acc += a[lo + i]
        i += 1
    return acc


@njit(cache=True)
def pairwise_sum(a, lo, n):
    """``numpy.sum`` of ``a[lo:lo + n]`` (float64, contiguous) to the bit: numpy's pairwise
    summation (blocks of up to 128, :func:`_pairwise_block`; above, the two halves, the
    first a multiple of 8 long, summed and added), so that a value the numpy path computes
    with ``numpy.mean`` comes out the same here. The halving is walked with an explicit
    stack: numba's on-disk cache does not keep recursive functions reliably."""
    if n <= 128:
        return _pairwise_block(a, lo, n)
    s_lo = np.empty(64, np.int64)
    s_n = np.empty(64, np.int64)
    s_state = np.zeros(64, np.int64)
    vals = np.empty(64)
    nv = 0
    top = 0
    s_lo[0] = lo
    s_n[0] = n
    while top >= 0:
        m = s_n[top]
        if m <= 128:
            vals[nv] = _pairwise_block(a, s_lo[top], m)
            nv += 1
            top -= 1
            continue
        half = m // 2
        half -= half % 8
        state = s_state[top]
        if state == 2:  # both halves summed: combine
            vals[nv - 2] = vals[nv - 2] + vals[nv - 1]
            nv -= 1
            top -= 1
            continue
        s_state[top] = state + 1
        child_lo = s_lo[top] if state == 0 else s_lo[top] + half
        child_n = half if state == 0 else m - half
        top += 1
        s_lo[top] = child_lo
        s_n[top] = child_n
        s_state[top] = 0
    return vals[0]


@njit(cache=True)
def tl_fit(gamma_deg, theta_deg, power, sigma, use_sigma, n_params, nonneg, residual,
           nd_grid, ns_grid, key, n_random, n_screen, n_hops, jitter_width, ext_start, extra,
           lo, hi, zlo, zhi, axes, plo, phi, n_data_starts, n_keep, max_iter, max_rounds):
    """fit() of the plain two-lobe model in one call, from the table as it is stored:
    the checks of the data (a status: 0 fit, 1 non-finite power, 2 constant power,
    3 sigma <= 0; fit() raises its one-line error for any other than 0, and nothing is
    searched), angles to radians, weights ``1 / sigma^2`` (``use_sigma``) or 1, the
    table's geometry (kernel_geometry), the random draws of the search from the
    generator's ``key`` (irreflect._draws: the jitter of ``n_random`` starts, the Latin
    hypercube of ``n_screen`` candidates, ``n_hops`` basin hops per round), the global
    search on the power divided by its weighted root mean square (global_search) and,
    unless the search ended where fit() polishes or checks the gradient (the iteration
    limit, no step lowering the cost: then fit() finishes in Python), the finish in the
    units of power (tl_finish). Returns (status, z, alpha and cost (search units), the
    scale, reason, n_starts, n_evals, the exact angles of incidence, finished, values, round_trip_ok,
    fitted, r2, rmse, mse, covariance, singular, standard errors, residuals, all values
    finite, whether judge() would flag anything: a value at a bound ``plo``/``phi`` or
    ill-determined)."""
    n = power.size
    p = zlo.size
    status = 0
    pmin = math.inf
    pmax = -math.inf
    for j in range(n):
        v = power[j]
        if not math.isfinite(v):
            status = 1
            break
        pmin = min(pmin, v)
        pmax = max(pmax, v)
    if status == 0 and pmax - pmin == 0.0:
        status = 2
    weights = np.ones(n)
    if use_sigma:
        for j in range(n):
            if sigma[j] > 0.0:
                weights[j] = 1.0 / sigma[j] ** 2
            else:
                status = 3 if status == 0 else status
    gamma = gamma_deg * DEG
    theta = theta_deg * DEG
    geo, glcg, levels, pgroup, exact = kernel_geometry(gamma, theta)
    if status == 0:
        # fitting._global_search's scale, to the bit (np.sqrt(np.mean(w * p * p)))
        scale = math.sqrt(pairwise_sum(weights * power * power, 0, n) / n)
        if not (math.isfinite(scale) and scale > 0.0):
            scale = 1.0
        jitter = draw_normals(key, STREAM_JITTER, n_random * p).reshape((n_random, p))
        for i in range(n_random):
            for q in range(p):
                jitter[i, q] = 0.15 * jitter[i, q] * jitter_width[q]
        hops = draw_normals(key, STREAM_HOPS, max_rounds * n_hops * p).reshape(
            (max_rounds, n_hops, p))
        for r in range(max_rounds):
            for i in range(n_hops):
                for q in range(p):
                    hops[r, i, q] = 0.15 * hops[r, i, q]
        screen = draw_latin_hypercube(key, n_screen, lo, hi)
        z, alpha, cost, reason, n_starts, n_evals = global_search(
            np.zeros(0, np.int64), nonneg, residual, geo, glcg, power / scale, weights,
            levels, pgroup, nd_grid, ns_grid, jitter, ext_start, extra, screen, lo, hi, zlo,
            zhi, axes, hops, n_data_starts, n_keep, max_iter, max_rounds)
    else:
        scale = 1.0
        z = np.zeros(p)
        alpha = np.zeros(2)
        cost = math.inf
        reason = STOP_NONFINITE
        n_starts = 0
        n_evals = 0
    finished = math.isfinite(cost) and reason != STOP_STUCK and reason != STOP_MAXITER
    k = z.size + alpha.size
    if finished:
        values, ok, fitted, r2, rmse, mse, cov, singular = tl_finish(
            z, alpha * scale, geo, glcg, weights, power, use_sigma, cost * scale * scale,
            n_params)
    else:
        values = np.full(k, np.nan)
        ok = False
        fitted = np.full(power.size, np.nan)
        r2 = math.nan
        rmse = math.nan
        mse = math.nan
        cov = np.full((k, k), np.nan)
        singular = np.zeros(k, np.bool_)
    # what fit() reports besides: standard errors, residuals, whether every value is
    # finite, and whether judge() has anything to say of the values (its tests, on the
    # same numbers)
    stderr = np.empty(k)
    finite = True
    flagged = False
    for q in range(k):
        v = cov[q, q]
        stderr[q] = math.sqrt(v) if v > 0.0 else (0.0 if v <= 0.0 else v)
        finite = finite and math.isfinite(values[q])
        x = values[q]
        b = plo[q]
        if math.isfinite(b) and x <= b + (1e-6 * abs(b) if b != 0.0 else 1e-12):
            flagged = True
        b = phi[q]
        if math.isfinite(b) and x >= b - (1e-6 * abs(b) if b != 0.0 else 1e-12):
            flagged = True
        e = stderr[q]
        if not math.isfinite(e) or e > abs(x) or singular[q]:
            flagged = True
    resid = power - fitted
    return (status, z, alpha, cost, scale, reason, n_starts, n_evals, exact, finished, values,
            ok, fitted, r2, rmse, mse, cov, singular, stderr, resid, finite, flagged)


def warm() -> None:
    """Compile (or load from the on-disk cache) every entry point once: a fit, a batch of
    subset fits and an extended model's fit of a small generated table. ``make`` runs it
    after installing so that test workers and commands find the cache warm."""
    import warnings

    from .data import Measurements
    from .errors import FitWarning
    from .fitting import fit, fit_subsets
    from .models import two_lobe_power

    g = np.repeat([-20.0, -40.0, -60.0], 9)
    t = np.tile(np.linspace(-60.0, 80.0, 9), 3)
    p = two_lobe_power(np.radians(g), np.radians(t), 0.05, -1.0, 1.0, 0.4, 80.0, 0.2, 1.0)
    meas = Measurements(g, t, p * (1.0 + 0.01 * np.sin(np.arange(p.size))))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        fit(meas, engine="compiled")
        from .models.extensions import extend

        fit(meas, extend("two-lobe", ["background"]), engine="compiled")
        masks = np.ones((2, p.size), bool)
        masks[0, ::2] = False
        fit_subsets(g, t, p, masks, engine="compiled")


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


@njit(cache=True)
def r2_rows(codes, zs, alphas, geo, glcg, power):
    """R^2 against ``power`` of the model at every row of (zs, alphas) (NaN rows: NaN)."""
    b = zs.shape[0]
    n = power.size
    mean = 0.0
    for j in range(n):
        mean += power[j]
    mean /= n
    ss_tot = 0.0
    for j in range(n):
        ss_tot += (power[j] - mean) ** 2
    out = np.full(b, np.nan)
    pred = np.empty(n)
    fast = codes.size == 0
    if fast:  # the points by blocks, as the search stores them
        pts = np.empty((_TL_ROWS, n))
        gstart = np.empty(glcg.size + 1, np.int64)
        lgroup = np.empty(n, np.int64)
        ones = np.ones(n)
        tl_points(geo, glcg.size, ones, ones, ones, power, np.ones(n, np.bool_), pts, gstart,
                  lgroup, geo[7])
        vec = np.empty((10, n))
        gbuf = np.zeros(3 * glcg.size + 8)
    for i in range(b):
        ok = True
        for q in range(zs.shape[1]):
            ok = ok and math.isfinite(zs[i, q])
        for q in range(alphas.shape[1]):
            ok = ok and math.isfinite(alphas[i, q])
        if not ok:
            continue
        if fast:
            _tl_broadcast(zs[i], gstart, glcg, vec, 5, gbuf)
            ss = _tl_ss(pts, n, vec, alphas[i, 0], alphas[i, 1])
        else:
            pred = predict(codes, zs[i], alphas[i], geo, glcg)
            ss = 0.0
            for j in range(n):
                ss += (power[j] - pred[j]) ** 2
        out[i] = 1.0 - ss / ss_tot if ss_tot > 0.0 else math.nan
    return out
