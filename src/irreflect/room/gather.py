"""Compiled kernels of the recursive method's last leg: what one receiver gathers from the
light leaving every surface cell (:func:`gather`), and the normalised delay histogram of
each cell's light that the gather spreads (:class:`~.transport.Shapes`, filled from exact
arrival histograms by :func:`hist_fill` or from the delay moments as a shifted gamma by
:func:`gamma_fill`). The light's state and the per-pair helpers are in :mod:`.transport`.
"""

from __future__ import annotations

import math

from .kernels import C_LIGHT, dot, hot, occluded
from .transport import SUB_MAX, _offset, _shift, _sub_point, _tstat, emit, lobe_split, pair


@hot
def _fov_split(d, size, cos_r, cos_fov):
    """Midpoints per side for a cell that straddles the receiver's field-of-view edge."""
    ang = math.acos(min(max(cos_r, -1.0), 1.0))
    edge = math.acos(min(max(cos_fov, -1.0), 1.0))
    rad = 0.75 * size / max(d, 1e-12)
    if abs(ang - edge) >= rad:
        return 1
    return min(max(int(math.ceil(rad / 0.002)), 4), 32)


@hot
def gather(cells, mats, ext, src, rx, shapes, knobs, out):
    """What one receiver gets from the light leaving every cell (one more leg).

    ``rx = (position, facing, (gain x area, cos of the half field of view))``; ``shapes``
    the normalised delay histogram of each cell's light (:class:`Shapes`; count 0: deposit at
    the mean delay, for light straight from the emitter); ``out =
    (hist (T,), sums (5,))`` with sums = power, power x delay, power x delay^2, phasor re, im.
    Cells closer than 6 sizes are split into Gauss points, cells across the field-of-view
    edge into up to 32 x 32 midpoints.
    """
    rpos, rdir, rpar = rx
    gain_area, cos_fov = rpar
    hist, sums = out
    data, offset, start, count = shapes
    N = cells.pos.shape[0]
    T = hist.shape[0]
    boxes = cells.boxes
    has_boxes = boxes.shape[0] > 0
    r0 = (rpos[0], rpos[1], rpos[2])
    rd = (rdir[0], rdir[1], rdir[2])
    for j in range(N):
        if src.power[j] <= 0.0:
            continue
        x = (cells.pos[j, 0], cells.pos[j, 1], cells.pos[j, 2])
        nx = (cells.nrm[j, 0], cells.nrm[j, 1], cells.nrm[j, 2])
        v = (r0[0] - x[0], r0[1] - x[1], r0[2] - x[2])
        if dot(v, nx) <= 0.0:
            continue
        dc = math.sqrt(dot(v, v))
        size = 2.0 * max(cells.half[j, 0], cells.half[j, 1])
        cos_rc = -dot(rd, v) / dc
        s = 1
        midpoint = False
        if dc < 6.0 * size:
            s = min(max(int(math.ceil(6.0 * size / dc)), 2), SUB_MAX)
        f = _fov_split(dc, size, cos_rc, cos_fov)
        if f > 1:
            s = f
            midpoint = True
        if not midpoint:
            uc = (v[0] / dc, v[1] / dc, v[2] / dc)
            lam_c, rest_c = emit(src, ext, mats, cells, j, x, uc, dot(uc, nx), knobs)
            if rest_c > 0.02 * lam_c:
                s = max(s, lobe_split(ext, mats, cells, src, knobs, j, size, dc))
        total = 0.0
        for k in range(s * s):
            if midpoint:
                xk = _mid_point(cells, j, s, k)
                wk = 1.0 / (s * s)
            else:
                xk, wk = _sub_point(cells, j, s, k)
            d, u, co, cr = pair(xk, r0, nx, rd)
            if co <= 0.0 or cr < cos_fov or cr <= 0.0:
                continue
            if has_boxes and occluded(xk, r0, boxes):
                continue
            lam, rest = emit(src, ext, mats, cells, j, xk, u, co, knobs)
            total += (lam + rest) * wk * gain_area * cr / (d * d)
        if total <= 0.0:
            continue
        tau = dc / C_LIGHT
        mean, sq, pre, pim, first = _shift(_tstat(src, j), tau, knobs.omega)
        sums[0] += total
        sums[1] += total * mean
        sums[2] += total * sq
        sums[3] += total * pre
        sums[4] += total * pim
        if count[j] == 0:
            b = int(mean / knobs.dt)
            if b < T:
                hist[b] += total
            continue
        shift = tau / knobs.dt
        base = int(math.floor(shift))
        frac = shift - base
        o = offset[j] - start[j]
        for b in range(start[j], start[j] + count[j]):
            w = total * data[o + b]
            t = b + base
            if t < T:
                hist[t] += w * (1.0 - frac)
            if t + 1 < T:
                hist[t + 1] += w * frac


@hot
def _mid_point(cells, j, s, k):
    p = (cells.pos[j, 0], cells.pos[j, 1], cells.pos[j, 2])
    p = _offset(p, cells.axes[j, 0], 2.0 * cells.half[j, 0] * ((k // s + 0.5) / s - 0.5))
    return _offset(p, cells.axes[j, 1], 2.0 * cells.half[j, 1] * ((k % s + 0.5) / s - 0.5))


@hot
def _gamma_cdf(x, k):
    """Wilson-Hilferty approximation of the regularised lower incomplete gamma P(k, x)."""
    if x <= 0.0:
        return 0.0
    c = 1.0 / (9.0 * k)
    z = (math.pow(x / k, 1.0 / 3.0) - (1.0 - c)) / math.sqrt(c)
    return 0.5 * (1.0 + math.erf(z / math.sqrt(2.0)))


@hot
def gamma_window(power, m1, m2, t0, dt, nb, j):
    """First bin, number of bins, shape k and scale theta of cell j's shifted gamma
    (k = 0: a point mass in the first bin)."""
    P = power[j]
    mean = m1[j] / P
    var = max(m2[j] / P - mean * mean, 0.0)
    first = min(t0[j], mean) if t0[j] < 1e300 else mean
    my = mean - first
    sd = math.sqrt(var)
    if sd < 0.05 * dt or my <= 1e-6 * dt:
        return min(max(int(mean / dt), 0), nb - 1), 1, 0.0, 0.0
    lo = min(max(int(first / dt), 0), nb - 1)
    hi = min(int((mean + 8.0 * sd) / dt) + 2, nb)
    return lo, max(hi - lo, 1), min(max(my * my / var, 1e-2), 1e6), var / my


@hot
def gamma_fill(power, m1, m2, t0, dt, nb, shapes):
    """Fill :class:`Shapes` (sized by :func:`gamma_window`) with each cell's ``t0 + Gamma``
    delay histogram (Wilson-Hilferty's approximation of the distribution function,
    evaluated every ``max(dt, sd / 8)`` and interpolated), normalised."""
    data, offset, start, count = shapes
    for j in range(power.shape[0]):
        if power[j] <= 0.0:
            continue
        lo, n, k, th = gamma_window(power, m1, m2, t0, dt, nb, j)
        o = offset[j]
        if k == 0.0:
            data[o] = 1.0
            continue
        P = power[j]
        mean = m1[j] / P
        first = min(t0[j], mean) if t0[j] < 1e300 else mean
        step = max(1, int(math.sqrt(k) * th / 8.0 / dt))
        prev = 0.0
        total = 0.0
        c0 = 0.0
        b0 = 0
        for b in range(0, n + step, step):
            bb = min(b, n)
            c1 = _gamma_cdf(((lo + bb) * dt - first) / th, k) if bb > 0 else 0.0
            if bb > b0:
                for q in range(b0, bb):
                    cq = c0 + (c1 - c0) * (q + 1 - b0) / (bb - b0)
                    data[o + q] = cq - prev
                    total += cq - prev
                    prev = cq
            c0 = c1
            b0 = bb
            if bb == n:
                break
        if total > 0.0:
            for q in range(n):
                data[o + q] /= total


@hot
def hist_fill(power, hist, shapes):
    """Fill :class:`Shapes` from exact arrival histograms (normalised)."""
    data, offset, start, count = shapes
    for j in range(power.shape[0]):
        if power[j] <= 0.0:
            continue
        o = offset[j]
        for q in range(count[j]):
            data[o + q] = hist[j, start[j] + q] / power[j]
