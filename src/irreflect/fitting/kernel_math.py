"""Compiled arithmetic shared by every kernel of the fitter (numba): the exponential
the lobes use (:func:`fexp`, :func:`lexp`), the specular share's cap, numpy's pairwise sum
to the bit, and the constants (ridge, stop codes) the numpy code uses too.
"""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

from ..models.base import cap_share

TWO_PI = 2.0 * math.pi
RIDGE = 1e-12
EXTREME = 1e8
STOP_FTOL, STOP_XTOL, STOP_STUCK, STOP_MAXITER, STOP_NONFINITE = 1, 2, 3, 4, 5


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


@njit(cache=True, inline="always")
def _insert_by_threshold(order, count, tau, g):
    """Insert angle ``g`` into ``order[:count]`` (kept in increasing ``tau``, a later equal
    one after the earlier); returns the new count."""
    i = count
    while i > 0 and tau[order[i - 1]] > tau[g]:
        order[i] = order[i - 1]
        i -= 1
    order[i] = g
    return count + 1


@njit(cache=True)
def _stable_order(values):
    return np.argsort(values, kind="mergesort")


@njit(cache=True)
def _close(a, b, rtol, atol):
    """numpy.allclose(a, b, rtol, atol)."""
    for i in range(a.size):
        if not abs(a[i] - b[i]) <= atol + rtol * abs(b[i]):
            return False
    return True


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
