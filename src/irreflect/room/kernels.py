"""Compiled kernels of the room simulation (numba).

Why numba: the recursive method visits every pair of surface cells (49.6 million pairs for a
5 x 5 x 3 m room in 0.125 m cells) and the Monte Carlo tracer follows rays one bounce at a
time with a branchy loop (intersections, occlusion, lobe sampling); in numpy both need
pair-sized or ray-sized temporaries (the memory the issue forbids) and run 10-50 times
slower. The kernels are plain loops over scalars, compiled once and cached on disk
(``cache=True``), and release the GIL so that chunks of cells run on several threads.

Units: metres, seconds, radians; powers in watts. Directions are unit 3-vectors passed as
scalars. A material is an index into the packed tables of :func:`pack_materials`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: nodes of the per-gamma normalisation tables over [0, 90] deg
N_GAMMA = 257
GAMMA_NODES = np.linspace(0.0, np.pi / 2, N_GAMMA)
#: lobes per material at most
LOBE_MAX = 8
#: tabulation of plane-of-incidence-equivalent models (0.25 deg)
TABLE_GAMMA = np.radians(np.linspace(0.0, 90.0, 361))
TABLE_THETA = np.radians(np.linspace(-90.0, 90.0, 721))

C_LIGHT = 299_792_458.0
PI = math.pi
TWO_PI = 2.0 * math.pi
_G_STEP = float(GAMMA_NODES[1] - GAMMA_NODES[0])
_TG_STEP = float(TABLE_GAMMA[1] - TABLE_GAMMA[0])
_TT_STEP = float(TABLE_THETA[1] - TABLE_THETA[0])
_TT0 = float(TABLE_THETA[0])


def pack_materials(materials) -> tuple:
    """The arrays the kernels read, for a list of :class:`~irreflect.room.materials.Material`."""
    M = len(materials)
    kind = np.array([m.kind for m in materials], np.int64)
    rho = np.array([m.reflectance if m.reflectance is not None else 0.0 for m in materials])
    gmax = np.array([m.gamma_max_rad for m in materials])
    share = np.array([m.share for m in materials], float).reshape(M, 2)
    lobes = np.zeros((M, LOBE_MAX, 5))
    nlobes = np.zeros(M, np.int64)
    for i, m in enumerate(materials):
        nlobes[i] = len(m.lobes)
        lobes[i, : len(m.lobes)] = m.lobes
    norm = np.array([m.norm_table for m in materials], float).reshape(M, N_GAMMA)
    rhotab = np.array([m.rho_table for m in materials], float).reshape(M, N_GAMMA)
    if any(m.table is not None for m in materials):
        table = np.zeros((M, TABLE_GAMMA.size, TABLE_THETA.size))
        for i, m in enumerate(materials):
            if m.table is not None:
                table[i] = m.table
    else:
        table = np.zeros((M, 1, 1))
    return (kind, rho, gmax, share, lobes, nlobes, norm, rhotab, table)


# ----------------------------------------------------------------------------- helpers
@njit(cache=True)
def _interp_gamma(tab, m, g):
    x = g / _G_STEP
    if x <= 0.0:
        return tab[m, 0]
    last = tab.shape[1] - 1
    if x >= last:
        return tab[m, last]
    i = int(x)
    f = x - i
    return tab[m, i] * (1.0 - f) + tab[m, i + 1] * f


@njit(cache=True)
def _table_lookup(table, m, g, theta):
    if theta <= -0.5 * PI or theta >= 0.5 * PI:
        return 0.0
    x = g / _TG_STEP
    y = (theta - _TT0) / _TT_STEP
    nx = table.shape[1] - 1
    ny = table.shape[2] - 1
    if x >= nx:
        x = nx - 1e-9
    if y >= ny:
        y = ny - 1e-9
    if x < 0.0:
        x = 0.0
    if y < 0.0:
        y = 0.0
    i = int(x)
    j = int(y)
    fx = x - i
    fy = y - j
    return ((table[m, i, j] * (1 - fy) + table[m, i, j + 1] * fy) * (1 - fx)
            + (table[m, i + 1, j] * (1 - fy) + table[m, i + 1, j + 1] * fy) * fx)


@njit(cache=True)
def _tangent(dx, dy, dz, nx, ny, nz, cos_g):
    """Unit tangent of the plane of incidence pointing to the mirror side (0 at normal incidence)."""
    hx = dx + cos_g * nx
    hy = dy + cos_g * ny
    hz = dz + cos_g * nz
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    if hn > 1e-12:
        return hx / hn, hy / hn, hz / hn
    return 0.0, 0.0, 0.0


@njit(cache=True)
def material_value(mats, m, dx, dy, dz, nx, ny, nz, ox, oy, oz):
    """Reflected radiant intensity per unit incident power (1/sr).

    ``d``: propagation direction of the incident light (towards the surface); ``n``: surface
    normal on the side the light comes from; ``o``: outgoing direction.
    """
    kind, rho, gmax, share, lobes, nlobes, norm, rhotab, table = mats
    cos_o = ox * nx + oy * ny + oz * nz
    if cos_o <= 0.0:
        return 0.0
    k = kind[m]
    if k == 0:
        return rho[m] * cos_o / PI
    cos_g = -(dx * nx + dy * ny + dz * nz)
    if cos_g <= 0.0:
        return 0.0
    if cos_g > 1.0:
        cos_g = 1.0
    g = math.acos(cos_g)
    nrm = _interp_gamma(norm, m, g)
    hx, hy, hz = _tangent(dx, dy, dz, nx, ny, nz, cos_g)
    if k == 1:
        gl = min(g, gmax[m])
        lcg = math.log(math.cos(gl))
        a = share[m, 0] * math.exp(share[m, 1] * lcg)
        a = min(max(a, 0.0), 1.0)
        s = 0.0
        for i in range(nlobes[m]):
            w = lobes[m, i, 1] + lobes[m, i, 2] * a
            if w <= 0.0:
                continue
            nn = lobes[m, i, 3] * math.exp(lobes[m, i, 4] * lcg)
            ang = lobes[m, i, 0] * g
            ca = math.cos(ang)
            sa = math.sin(ang)
            c = ox * (ca * nx + sa * hx) + oy * (ca * ny + sa * hy) + oz * (ca * nz + sa * hz)
            if c <= 0.0:
                continue
            s += w * (nn + 1.0) / TWO_PI * math.exp(nn * math.log(c))
        return nrm * s
    # plane-of-incidence equivalent of a tabulated model
    rx = dx + 2.0 * cos_g * nx
    ry = dy + 2.0 * cos_g * ny
    rz = dz + 2.0 * cos_g * nz
    cphi = ox * rx + oy * ry + oz * rz
    cphi = min(max(cphi, -1.0), 1.0)
    phi = math.acos(cphi)
    ex = ox - cphi * rx
    ey = oy - cphi * ry
    ez = oz - cphi * rz
    qx = nx - cos_g * rx
    qy = ny - cos_g * ry
    qz = nz - cos_g * rz
    en = math.sqrt(ex * ex + ey * ey + ez * ez)
    qn = math.sqrt(qx * qx + qy * qy + qz * qz)
    cpsi = 1.0
    if en > 1e-12 and qn > 1e-12:
        cpsi = (ex * qx + ey * qy + ez * qz) / (en * qn)
    wa = 0.5 * (1.0 + cpsi)
    gl = min(g, gmax[m])
    v = wa * _table_lookup(table, m, gl, g - phi) + (1.0 - wa) * _table_lookup(table, m, gl, g + phi)
    return nrm * max(v, 0.0)


@njit(cache=True)
def prepare_cells(mats, cmat, cnorm, din):
    """Per cell, the lobes for one fixed incidence ``din[i]``: ``coef`` (N, L) = norm x weight
    x (n+1)/2pi, ``expo`` (N, L) = n, ``axes`` (N, L, 3); ``mode`` (N,): 0 Lambertian
    (``coef[:, 0]`` = rho/pi), 1 prepared lobes, 2 use :func:`material_value` (tabulated)."""
    kind, rho, gmax, share, lobes, nlobes, norm, rhotab, table = mats
    N = cmat.shape[0]
    L = lobes.shape[1]
    mode = np.zeros(N, np.int64)
    coef = np.zeros((N, L))
    expo = np.zeros((N, L))
    axes = np.zeros((N, L, 3))
    for i in range(N):
        m = cmat[i]
        k = kind[m]
        if k == 0:
            coef[i, 0] = rho[m] / PI
            continue
        if k == 2:
            mode[i] = 2
            continue
        mode[i] = 1
        nx, ny, nz = cnorm[i, 0], cnorm[i, 1], cnorm[i, 2]
        dx, dy, dz = din[i, 0], din[i, 1], din[i, 2]
        cos_g = -(dx * nx + dy * ny + dz * nz)
        if cos_g <= 0.0:
            continue
        cos_g = min(cos_g, 1.0)
        g = math.acos(cos_g)
        nrm = _interp_gamma(norm, m, g)
        hx, hy, hz = _tangent(dx, dy, dz, nx, ny, nz, cos_g)
        gl = min(g, gmax[m])
        lcg = math.log(math.cos(gl))
        a = min(max(share[m, 0] * math.exp(share[m, 1] * lcg), 0.0), 1.0)
        for q in range(nlobes[m]):
            w = lobes[m, q, 1] + lobes[m, q, 2] * a
            if w <= 0.0:
                continue
            nn = lobes[m, q, 3] * math.exp(lobes[m, q, 4] * lcg)
            ang = lobes[m, q, 0] * g
            ca = math.cos(ang)
            sa = math.sin(ang)
            coef[i, q] = nrm * w * (nn + 1.0) / TWO_PI
            expo[i, q] = nn
            axes[i, q, 0] = ca * nx + sa * hx
            axes[i, q, 1] = ca * ny + sa * hy
            axes[i, q, 2] = ca * nz + sa * hz
    return mode, coef, expo, axes


@njit(cache=True)
def prepared_value(mats, prep, cmat, cnorm, din, i, ox, oy, oz, cos_o):
    """:func:`material_value` of cell ``i`` for its prepared incidence ``din[i]``."""
    mode, coef, expo, axes = prep
    md = mode[i]
    if md == 0:
        return coef[i, 0] * cos_o
    if md == 2:
        return material_value(mats, cmat[i], din[i, 0], din[i, 1], din[i, 2], cnorm[i, 0],
                              cnorm[i, 1], cnorm[i, 2], ox, oy, oz)
    s = 0.0
    for q in range(coef.shape[1]):
        c0 = coef[i, q]
        if c0 <= 0.0:
            continue
        c = ox * axes[i, q, 0] + oy * axes[i, q, 1] + oz * axes[i, q, 2]
        if c <= 0.0:
            continue
        s += c0 * math.exp(expo[i, q] * math.log(c))
    return s


@njit(cache=True)
def _basis(ax, ay, az):
    if abs(az) < 0.9:
        tx, ty, tz = -ay, ax, 0.0
    else:
        tx, ty, tz = 0.0, -az, ay
    tn = math.sqrt(tx * tx + ty * ty + tz * tz)
    tx /= tn
    ty /= tn
    tz /= tn
    bx = ay * tz - az * ty
    by = az * tx - ax * tz
    bz = ax * ty - ay * tx
    return tx, ty, tz, bx, by, bz


@njit(cache=True)
def _sample_lobe(ax, ay, az, n):
    """A direction from ``(n+1)/2pi cos^n`` about the unit axis ``a``."""
    c = np.random.random() ** (1.0 / (n + 1.0))
    s = math.sqrt(max(0.0, 1.0 - c * c))
    p = TWO_PI * np.random.random()
    tx, ty, tz, bx, by, bz = _basis(ax, ay, az)
    cp = math.cos(p) * s
    sp = math.sin(p) * s
    return (c * ax + cp * tx + sp * bx, c * ay + cp * ty + sp * by, c * az + cp * tz + sp * bz)


@njit(cache=True)
def sample_material(mats, m, dx, dy, dz, nx, ny, nz):
    """A new direction after reflection and the factor the ray's power is multiplied by.

    Lobes of revolution are sampled from their own mixture, restricted to the hemisphere by
    rejection, so the factor is exactly ``rho(gamma)``. Lambertian: cosine sampling, factor
    ``rho``. Tabulated models: cosine sampling, factor ``f pi / cos(theta)``.
    Returns ``(ox, oy, oz, factor)``; factor 0 ends the ray.
    """
    kind, rho, gmax, share, lobes, nlobes, norm, rhotab, table = mats
    k = kind[m]
    if k == 1:
        cos_g = -(dx * nx + dy * ny + dz * nz)
        cos_g = min(max(cos_g, 0.0), 1.0)
        g = math.acos(cos_g)
        hx, hy, hz = _tangent(dx, dy, dz, nx, ny, nz, cos_g)
        gl = min(g, gmax[m])
        lcg = math.log(math.cos(gl))
        a = share[m, 0] * math.exp(share[m, 1] * lcg)
        a = min(max(a, 0.0), 1.0)
        W = 0.0
        for i in range(nlobes[m]):
            W += max(lobes[m, i, 1] + lobes[m, i, 2] * a, 0.0)
        if W <= 0.0:
            return 0.0, 0.0, 0.0, 0.0
        factor = _interp_gamma(rhotab, m, g)
        for _ in range(200):
            u = np.random.random() * W
            pick = nlobes[m] - 1
            acc = 0.0
            for i in range(nlobes[m]):
                acc += max(lobes[m, i, 1] + lobes[m, i, 2] * a, 0.0)
                if u < acc:
                    pick = i
                    break
            nn = lobes[m, pick, 3] * math.exp(lobes[m, pick, 4] * lcg)
            ang = lobes[m, pick, 0] * g
            ca = math.cos(ang)
            sa = math.sin(ang)
            ox, oy, oz = _sample_lobe(ca * nx + sa * hx, ca * ny + sa * hy, ca * nz + sa * hz, nn)
            if ox * nx + oy * ny + oz * nz > 1e-12:
                return ox, oy, oz, factor
        return 0.0, 0.0, 0.0, 0.0
    ox, oy, oz = _sample_lobe(nx, ny, nz, 1.0)
    cos_o = ox * nx + oy * ny + oz * nz
    if cos_o <= 1e-12:
        return 0.0, 0.0, 0.0, 0.0
    if k == 0:
        return ox, oy, oz, rho[m]
    f = material_value(mats, m, dx, dy, dz, nx, ny, nz, ox, oy, oz)
    return ox, oy, oz, f * PI / cos_o


@njit(cache=True)
def occluded(px, py, pz, qx, qy, qz, boxes):
    """Whether the open segment p-q crosses the interior of any box ``(B, 2, 3)``."""
    for b in range(boxes.shape[0]):
        t0 = 1e-9
        t1 = 1.0 - 1e-9
        hit = True
        for a in range(3):
            if a == 0:
                p, d = px, qx - px
            elif a == 1:
                p, d = py, qy - py
            else:
                p, d = pz, qz - pz
            lo = boxes[b, 0, a]
            hi = boxes[b, 1, a]
            if abs(d) < 1e-15:
                if p <= lo or p >= hi:
                    hit = False
                    break
            else:
                ta = (lo - p) / d
                tb = (hi - p) / d
                if ta > tb:
                    ta, tb = tb, ta
                if ta > t0:
                    t0 = ta
                if tb < t1:
                    t1 = tb
                if t0 >= t1:
                    hit = False
                    break
        if hit:
            return True
    return False


# ----------------------------------------------------------------------------- recursive method
@njit(cache=True, nogil=True)
def forward_cells(j0, j1, cpos, cnorm, carea, cmat, epow, etau, edir, boxes, mats, prep, dt,
                  omega, hist, mom, ph, ubar):
    """Power arriving at cells ``j0..j1`` after one reflection (bounce-1 light), per cell.

    ``epow[i]``, ``etau[i]``, ``edir[i]``: power, delay and propagation direction of the light
    arriving at cell ``i`` straight from the emitter. Writes rows ``j`` of ``hist`` (delay
    histogram, floor binning), ``mom`` (exact sum of power, power x delay, power x delay^2),
    ``ph`` (exact phasor at angular frequency ``omega``) and ``ubar`` (power-weighted mean
    propagation direction of that light).
    """
    N = cpos.shape[0]
    nb = hist.shape[1]
    has_boxes = boxes.shape[0] > 0
    for j in range(j0, j1):
        pjx, pjy, pjz = cpos[j, 0], cpos[j, 1], cpos[j, 2]
        njx, njy, njz = cnorm[j, 0], cnorm[j, 1], cnorm[j, 2]
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        pr = 0.0
        pim = 0.0
        ux = 0.0
        uy = 0.0
        uz = 0.0
        for i in range(N):
            w = epow[i]
            if w <= 0.0 or i == j:
                continue
            vx = pjx - cpos[i, 0]
            vy = pjy - cpos[i, 1]
            vz = pjz - cpos[i, 2]
            d2 = vx * vx + vy * vy + vz * vz
            if d2 <= 0.0:
                continue
            d = math.sqrt(d2)
            vx /= d
            vy /= d
            vz /= d
            cos_out = cnorm[i, 0] * vx + cnorm[i, 1] * vy + cnorm[i, 2] * vz
            if cos_out <= 0.0:
                continue
            cos_in = -(njx * vx + njy * vy + njz * vz)
            if cos_in <= 0.0:
                continue
            if has_boxes and occluded(cpos[i, 0], cpos[i, 1], cpos[i, 2], pjx, pjy, pjz, boxes):
                continue
            f = prepared_value(mats, prep, cmat, cnorm, edir, i, vx, vy, vz, cos_out)
            c = w * f * carea[j] * cos_in / d2
            if c <= 0.0:
                continue
            tau = etau[i] + d / C_LIGHT
            b = int(tau / dt)
            if b < nb:
                hist[j, b] += c
            s0 += c
            s1 += c * tau
            s2 += c * tau * tau
            if omega > 0.0:
                pr += c * math.cos(omega * tau)
                pim -= c * math.sin(omega * tau)
            ux += c * vx
            uy += c * vy
            uz += c * vz
        mom[j, 0] = s0
        mom[j, 1] = s1
        mom[j, 2] = s2
        ph[j, 0] = pr
        ph[j, 1] = pim
        un = math.sqrt(ux * ux + uy * uy + uz * uz)
        if un > 0.0:
            ubar[j, 0] = ux / un
            ubar[j, 1] = uy / un
            ubar[j, 2] = uz / un
        else:
            ubar[j, 0] = -njx
            ubar[j, 1] = -njy
            ubar[j, 2] = -njz


@njit(cache=True, nogil=True)
def backward_cells(c0, c1, chunk, cpos, cnorm, carea, cmat, rgain, rtau, rdir, ubar,
                   epow, etau, edir, boxes, mats, prep_u, prep_e, dt, omega, general,
                   histB, momB, phB, h2, h2mom, h2ph):
    """Per receiver: what a unit power arriving at cell ``j`` delivers to the receiver after
    two more reflections (at ``j`` and at a cell ``q``), for the cells of chunks ``c0..c1``.

    ``rgain[q]``: ``A_R T_s g cos(psi) / d^2`` from cell ``q`` to the receiver (0 if outside
    the field of view or hidden); ``rtau[q]``, ``rdir[q]``: its delay and direction. The
    reflection at ``j`` uses the incidence ``ubar[j]`` (exact for Lambertian ``j``); the
    reflection at ``q`` uses the exact incidence from ``j``. ``histB`` is binned by rounding
    (so that the convolution with floor-binned bounce-1 histograms is unbiased).

    The second-order response (emitter -> j -> q -> receiver) is accumulated exactly per
    chunk in ``h2``, ``h2mom``, ``h2ph`` (with the exact incidence from the emitter at ``j``
    when ``general``).
    """
    N = cpos.shape[0]
    nbB = histB.shape[1]
    nb2 = h2.shape[1]
    has_boxes = boxes.shape[0] > 0
    kind = mats[0]
    rho = mats[1]
    # Lambertian cells: what they send to the receiver does not depend on the incidence
    rlam = np.zeros(N)
    for q in range(N):
        if kind[cmat[q]] == 0 and rgain[q] > 0.0:
            c = cnorm[q, 0] * rdir[q, 0] + cnorm[q, 1] * rdir[q, 1] + cnorm[q, 2] * rdir[q, 2]
            rlam[q] = rgain[q] * rho[cmat[q]] * max(c, 0.0) / PI
    for ch in range(c0, c1):
        for j in range(ch * chunk, min((ch + 1) * chunk, N)):
            pjx, pjy, pjz = cpos[j, 0], cpos[j, 1], cpos[j, 2]
            njx, njy, njz = cnorm[j, 0], cnorm[j, 1], cnorm[j, 2]
            ej = epow[j]
            mj = cmat[j]
            lam_j = kind[mj] == 0
            s0 = 0.0
            s1 = 0.0
            s2 = 0.0
            pr = 0.0
            pim = 0.0
            for q in range(N):
                if rgain[q] <= 0.0 or q == j:
                    continue
                vx = cpos[q, 0] - pjx
                vy = cpos[q, 1] - pjy
                vz = cpos[q, 2] - pjz
                d2 = vx * vx + vy * vy + vz * vz
                if d2 <= 0.0:
                    continue
                d = math.sqrt(d2)
                vx /= d
                vy /= d
                vz /= d
                cos_out = njx * vx + njy * vy + njz * vz
                if cos_out <= 0.0:
                    continue
                cos_in = -(cnorm[q, 0] * vx + cnorm[q, 1] * vy + cnorm[q, 2] * vz)
                if cos_in <= 0.0:
                    continue
                if has_boxes and occluded(pjx, pjy, pjz, cpos[q, 0], cpos[q, 1], cpos[q, 2], boxes):
                    continue
                geo = carea[q] * cos_in / d2
                ml = cmat[q]
                if kind[ml] == 0:
                    r = rlam[q]
                else:
                    r = rgain[q] * material_value(mats, ml, vx, vy, vz, cnorm[q, 0], cnorm[q, 1],
                                                  cnorm[q, 2], rdir[q, 0], rdir[q, 1], rdir[q, 2])
                if r <= 0.0:
                    continue
                if lam_j:
                    fj = rho[mj] * cos_out / PI
                else:
                    fj = prepared_value(mats, prep_u, cmat, cnorm, ubar, j, vx, vy, vz, cos_out)
                tau = d / C_LIGHT + rtau[q]
                c = fj * geo * r
                if c > 0.0:
                    b = int(tau / dt + 0.5)
                    if b < nbB:
                        histB[j, b] += c
                    s0 += c
                    s1 += c * tau
                    s2 += c * tau * tau
                    if omega > 0.0:
                        pr += c * math.cos(omega * tau)
                        pim -= c * math.sin(omega * tau)
                if ej > 0.0:
                    if general and not lam_j:
                        fs = prepared_value(mats, prep_e, cmat, cnorm, edir, j, vx, vy, vz,
                                            cos_out)
                        c2 = ej * fs * geo * r
                    else:
                        c2 = ej * c
                    if c2 > 0.0:
                        t2 = etau[j] + tau
                        b2 = int(t2 / dt)
                        if b2 < nb2:
                            h2[ch, b2] += c2
                        h2mom[ch, 0] += c2
                        h2mom[ch, 1] += c2 * t2
                        h2mom[ch, 2] += c2 * t2 * t2
                        if omega > 0.0:
                            h2ph[ch, 0] += c2 * math.cos(omega * t2)
                            h2ph[ch, 1] -= c2 * math.sin(omega * t2)
            momB[j, 0] = s0
            momB[j, 1] = s1
            momB[j, 2] = s2
            phB[j, 0] = pr
            phB[j, 1] = pim


@njit(cache=True, nogil=True)
def forward_cells_lambertian(j0, j1, cpos, cnorm, carea, crho, epow, etau, boxes, dt, omega,
                             hist, mom, ph):
    """:func:`forward_cells` for rooms whose surfaces are all Lambertian (``crho``: reflectance
    per cell): the same sums with the cosines taken from unnormalised vectors, so that pairs
    that cannot see each other are dropped before the square root."""
    N = cpos.shape[0]
    nb = hist.shape[1]
    has_boxes = boxes.shape[0] > 0
    inv_dt = 1.0 / dt
    inv_c = 1.0 / C_LIGHT
    for j in range(j0, j1):
        pjx, pjy, pjz = cpos[j, 0], cpos[j, 1], cpos[j, 2]
        njx, njy, njz = cnorm[j, 0], cnorm[j, 1], cnorm[j, 2]
        aj = carea[j] / PI
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        pr = 0.0
        pim = 0.0
        for i in range(N):
            w = epow[i] * crho[i]
            if w <= 0.0 or i == j:
                continue
            vx = pjx - cpos[i, 0]
            vy = pjy - cpos[i, 1]
            vz = pjz - cpos[i, 2]
            co = cnorm[i, 0] * vx + cnorm[i, 1] * vy + cnorm[i, 2] * vz
            if co <= 0.0:
                continue
            ci = -(njx * vx + njy * vy + njz * vz)
            if ci <= 0.0:
                continue
            if has_boxes and occluded(cpos[i, 0], cpos[i, 1], cpos[i, 2], pjx, pjy, pjz, boxes):
                continue
            d2 = vx * vx + vy * vy + vz * vz
            inv = 1.0 / d2
            c = w * aj * co * ci * inv * inv
            tau = etau[i] + math.sqrt(d2) * inv_c
            b = int(tau * inv_dt)
            if b < nb:
                hist[j, b] += c
            s0 += c
            s1 += c * tau
            s2 += c * tau * tau
            if omega > 0.0:
                pr += c * math.cos(omega * tau)
                pim -= c * math.sin(omega * tau)
        mom[j, 0] = s0
        mom[j, 1] = s1
        mom[j, 2] = s2
        ph[j, 0] = pr
        ph[j, 1] = pim


@njit(cache=True, nogil=True)
def backward_cells_lambertian(j0, j1, cpos, cnorm, carea, crho, rlam, rtau, boxes, dt, omega,
                              histB, momB, phB):
    """:func:`backward_cells` for all-Lambertian rooms (rows ``j0..j1``); ``rlam[q]``: power
    the receiver gets per unit power arriving at cell ``q``. The second order is then the
    emitter's light shifted through ``histB`` (see the engine)."""
    N = cpos.shape[0]
    nbB = histB.shape[1]
    has_boxes = boxes.shape[0] > 0
    inv_dt = 1.0 / dt
    inv_c = 1.0 / C_LIGHT
    for j in range(j0, j1):
        pjx, pjy, pjz = cpos[j, 0], cpos[j, 1], cpos[j, 2]
        njx, njy, njz = cnorm[j, 0], cnorm[j, 1], cnorm[j, 2]
        rj = crho[j] / PI
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        pr = 0.0
        pim = 0.0
        if rj > 0.0:
            for q in range(N):
                r = rlam[q]
                if r <= 0.0 or q == j:
                    continue
                vx = cpos[q, 0] - pjx
                vy = cpos[q, 1] - pjy
                vz = cpos[q, 2] - pjz
                co = njx * vx + njy * vy + njz * vz
                if co <= 0.0:
                    continue
                ci = -(cnorm[q, 0] * vx + cnorm[q, 1] * vy + cnorm[q, 2] * vz)
                if ci <= 0.0:
                    continue
                if has_boxes and occluded(pjx, pjy, pjz, cpos[q, 0], cpos[q, 1], cpos[q, 2], boxes):
                    continue
                d2 = vx * vx + vy * vy + vz * vz
                inv = 1.0 / d2
                c = rj * carea[q] * co * ci * inv * inv * r
                tau = math.sqrt(d2) * inv_c + rtau[q]
                b = int(tau * inv_dt + 0.5)
                if b < nbB:
                    histB[j, b] += c
                s0 += c
                s1 += c * tau
                s2 += c * tau * tau
                if omega > 0.0:
                    pr += c * math.cos(omega * tau)
                    pim -= c * math.sin(omega * tau)
        momB[j, 0] = s0
        momB[j, 1] = s1
        momB[j, 2] = s2
        phB[j, 0] = pr
        phB[j, 1] = pim


@njit(cache=True)
def shift_add(out, rows, weights, offsets):
    """``out[offsets[j] + b] += weights[j] * rows[j, b]`` (a sum of shifted histograms)."""
    nb = rows.shape[1]
    T = out.shape[0]
    for j in range(rows.shape[0]):
        w = weights[j]
        if w <= 0.0:
            continue
        o = offsets[j]
        top = min(nb, T - o)
        for b in range(top):
            out[o + b] += w * rows[j, b]


@njit(cache=True, nogil=True)
def propagate_cells(l0, l1, cpos, cnorm, carea, cmat, ubar, boxes, mats, prep_u, dt, omega,
                    hin, momin, phin, hout, momout, phout):
    """One more cell-to-cell leg: light arriving at cells (``hin``, after m reflections) is
    reflected (with the incidence ``ubar``) and arrives at cells ``l0..l1`` (``hout``)."""
    N = cpos.shape[0]
    nin = hin.shape[1]
    nout = hout.shape[1]
    has_boxes = boxes.shape[0] > 0
    for q in range(l0, l1):
        plx, ply, plz = cpos[q, 0], cpos[q, 1], cpos[q, 2]
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        pr = 0.0
        pim = 0.0
        for j in range(N):
            if momin[j, 0] <= 0.0 or j == q:
                continue
            vx = plx - cpos[j, 0]
            vy = ply - cpos[j, 1]
            vz = plz - cpos[j, 2]
            d2 = vx * vx + vy * vy + vz * vz
            if d2 <= 0.0:
                continue
            d = math.sqrt(d2)
            vx /= d
            vy /= d
            vz /= d
            cos_out = cnorm[j, 0] * vx + cnorm[j, 1] * vy + cnorm[j, 2] * vz
            if cos_out <= 0.0:
                continue
            cos_in = -(cnorm[q, 0] * vx + cnorm[q, 1] * vy + cnorm[q, 2] * vz)
            if cos_in <= 0.0:
                continue
            if has_boxes and occluded(cpos[j, 0], cpos[j, 1], cpos[j, 2], plx, ply, plz, boxes):
                continue
            f = prepared_value(mats, prep_u, cmat, cnorm, ubar, j, vx, vy, vz, cos_out)
            G = f * carea[q] * cos_in / d2
            if G <= 0.0:
                continue
            tau = d / C_LIGHT
            shift = int(tau / dt + 0.5)
            top = min(nin, nout - shift)
            for b in range(top):
                hout[q, b + shift] += G * hin[j, b]
            a0 = momin[j, 0]
            a1 = momin[j, 1]
            a2 = momin[j, 2]
            s0 += G * a0
            s1 += G * (a1 + tau * a0)
            s2 += G * (a2 + 2.0 * tau * a1 + tau * tau * a0)
            if omega > 0.0:
                cr = math.cos(omega * tau)
                ci = -math.sin(omega * tau)
                pr += G * (phin[j, 0] * cr - phin[j, 1] * ci)
                pim += G * (phin[j, 0] * ci + phin[j, 1] * cr)
        momout[q, 0] = s0
        momout[q, 1] = s1
        momout[q, 2] = s2
        phout[q, 0] = pr
        phout[q, 1] = pim


@njit(cache=True)
def first_bounce(cnorm, cmat, epow, etau, edir, rgain, rtau, rdir, mats, dt, omega, hist):
    """Emitter -> cell -> receiver; returns (m0, m1, m2, phasor re, phasor im)."""
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    pr = 0.0
    pim = 0.0
    nb = hist.shape[0]
    for q in range(cnorm.shape[0]):
        if epow[q] <= 0.0 or rgain[q] <= 0.0:
            continue
        f = material_value(mats, cmat[q], edir[q, 0], edir[q, 1], edir[q, 2], cnorm[q, 0],
                           cnorm[q, 1], cnorm[q, 2], rdir[q, 0], rdir[q, 1], rdir[q, 2])
        c = epow[q] * f * rgain[q]
        if c <= 0.0:
            continue
        tau = etau[q] + rtau[q]
        b = int(tau / dt)
        if b < nb:
            hist[b] += c
        s0 += c
        s1 += c * tau
        s2 += c * tau * tau
        if omega > 0.0:
            pr += c * math.cos(omega * tau)
            pim -= c * math.sin(omega * tau)
    return s0, s1, s2, pr, pim


# ----------------------------------------------------------------------------- Monte Carlo
@njit(cache=True)
def _intersect(ox, oy, oz, dx, dy, dz, size, boxes):
    """Nearest surface hit from inside the room: (t, nx, ny, nz, box or -1, face 0..5)."""
    best = np.inf
    bnx = 0.0
    bny = 0.0
    bnz = 0.0
    bbox = -1
    bface = -1
    for a in range(3):
        o = ox if a == 0 else (oy if a == 1 else oz)
        d = dx if a == 0 else (dy if a == 1 else dz)
        if d > 1e-15:
            t = (size[a] - o) / d
            face = 2 * a + 1
            sgn = -1.0
        elif d < -1e-15:
            t = -o / d
            face = 2 * a
            sgn = 1.0
        else:
            continue
        if t < best:
            best = t
            bface = face
            bnx = sgn if a == 0 else 0.0
            bny = sgn if a == 1 else 0.0
            bnz = sgn if a == 2 else 0.0
    for b in range(boxes.shape[0]):
        tmin = -np.inf
        tmax = np.inf
        axis = -1
        miss = False
        for a in range(3):
            o = ox if a == 0 else (oy if a == 1 else oz)
            d = dx if a == 0 else (dy if a == 1 else dz)
            lo = boxes[b, 0, a]
            hi = boxes[b, 1, a]
            if abs(d) < 1e-15:
                if o < lo or o > hi:
                    miss = True
                    break
                continue
            t1 = (lo - o) / d
            t2 = (hi - o) / d
            if t1 > t2:
                t1, t2 = t2, t1
            if t1 > tmin:
                tmin = t1
                axis = a
            if t2 < tmax:
                tmax = t2
        if miss or axis < 0 or tmin > tmax or tmin <= 1e-9 or tmin >= best:
            continue
        best = tmin
        bbox = b
        d = dx if axis == 0 else (dy if axis == 1 else dz)
        sgn = -1.0 if d > 0 else 1.0
        bface = 2 * axis if d > 0 else 2 * axis + 1
        bnx = sgn if axis == 0 else 0.0
        bny = sgn if axis == 1 else 0.0
        bnz = sgn if axis == 2 else 0.0
    return best, bnx, bny, bnz, bbox, bface


@njit(cache=True, nogil=True)
def trace_rays(seed, n_rays, epos, edir, e_order, e_power, rpos, rdir, rgain_area, cos_fov,
               size, boxes, room_mat, box_mat, mats, bounces, dt, omega,
               hist, mom, ph, sumsq, reflected):
    """Modified Monte Carlo (Lopez-Hernandez et al. 2000) with next-event estimation.

    ``n_rays`` rays leave the emitter (Lambertian order ``e_order``) with power
    ``e_power / n_rays`` each. At every hit the power the hit point sends straight to the
    receiver is added (bounce ``k`` -> row ``k`` of ``hist`` / ``mom`` / ``ph``; exact delay),
    then a new direction is drawn from the material's own lobes. ``sumsq`` collects the
    squared per-ray contributions (for the standard error), ``reflected[k]`` the power left
    after ``k + 1`` reflections. Seeded: the same seed gives the same result.
    """
    np.random.seed(seed)
    w0 = e_power / n_rays
    nb = hist.shape[1]
    contrib = np.zeros(bounces)
    tx, ty, tz, bx, by, bz = _basis(edir[0], edir[1], edir[2])
    has_boxes = boxes.shape[0] > 0
    for _ in range(n_rays):
        c = np.random.random() ** (1.0 / (e_order + 1.0))
        s = math.sqrt(max(0.0, 1.0 - c * c))
        p = TWO_PI * np.random.random()
        cp = math.cos(p) * s
        sp = math.sin(p) * s
        dx = c * edir[0] + cp * tx + sp * bx
        dy = c * edir[1] + cp * ty + sp * by
        dz = c * edir[2] + cp * tz + sp * bz
        ox, oy, oz = epos[0], epos[1], epos[2]
        w = w0
        path = 0.0
        for k in range(bounces):
            contrib[k] = 0.0
        for k in range(bounces):
            t, nx, ny, nz, box, face = _intersect(ox, oy, oz, dx, dy, dz, size, boxes)
            if not np.isfinite(t):
                break
            m = room_mat[face] if box < 0 else box_mat[box, face]
            hx = ox + t * dx
            hy = oy + t * dy
            hz = oz + t * dz
            path += t
            vx = rpos[0] - hx
            vy = rpos[1] - hy
            vz = rpos[2] - hz
            d2 = vx * vx + vy * vy + vz * vz
            if d2 > 0.0:
                dist = math.sqrt(d2)
                vx /= dist
                vy /= dist
                vz /= dist
                cos_r = -(rdir[0] * vx + rdir[1] * vy + rdir[2] * vz)
                if cos_r >= cos_fov and cos_r > 0.0 and (nx * vx + ny * vy + nz * vz) > 0.0:
                    if not (has_boxes and occluded(hx, hy, hz, rpos[0], rpos[1], rpos[2], boxes)):
                        f = material_value(mats, m, dx, dy, dz, nx, ny, nz, vx, vy, vz)
                        val = w * f * rgain_area * cos_r / d2
                        if val > 0.0:
                            tau = (path + dist) / C_LIGHT
                            b = int(tau / dt)
                            if b < nb:
                                hist[k, b] += val
                            mom[k, 0] += val
                            mom[k, 1] += val * tau
                            mom[k, 2] += val * tau * tau
                            if omega > 0.0:
                                ph[k, 0] += val * math.cos(omega * tau)
                                ph[k, 1] -= val * math.sin(omega * tau)
                            contrib[k] += val
            ndx, ndy, ndz, factor = sample_material(mats, m, dx, dy, dz, nx, ny, nz)
            if factor <= 0.0:
                break
            w *= factor
            reflected[k] += w
            dx, dy, dz = ndx, ndy, ndz
            ox = hx + nx * 1e-9
            oy = hy + ny * 1e-9
            oz = hz + nz * 1e-9
        for k in range(bounces):
            sumsq[k] += contrib[k] * contrib[k]


# ----------------------------------------------------------------------------- helpers for numpy callers
@njit(cache=True)
def eval_material_directions(mats, m, din, dout):
    """``material_value`` for rows of incident / outgoing directions (normal +z)."""
    out = np.empty(din.shape[0])
    for i in range(din.shape[0]):
        out[i] = material_value(mats, m, din[i, 0], din[i, 1], din[i, 2], 0.0, 0.0, 1.0,
                                dout[i, 0], dout[i, 1], dout[i, 2])
    return out


@njit(cache=True)
def _hemisphere(mats, m, gammas, mu, wmu, n_az):
    out = np.zeros(gammas.size)
    daz = TWO_PI / n_az
    for gi in range(gammas.size):
        g = gammas[gi]
        dx = math.sin(g)
        dz = -math.cos(g)
        total = 0.0
        for a in range(mu.size):
            st = math.sqrt(max(0.0, 1.0 - mu[a] * mu[a]))
            for b in range(n_az):
                az = (b + 0.5) * daz
                total += wmu[a] * daz * material_value(mats, m, dx, 0.0, dz, 0.0, 0.0, 1.0,
                                                       st * math.cos(az), st * math.sin(az), mu[a])
        out[gi] = total
    return out


def hemisphere_integral(mats, m, gammas, n_mu: int = 96, n_az: int = 192) -> np.ndarray:
    """Integral over the hemisphere (sr) of material ``m``'s intensity, per angle of incidence
    (radians), by Gauss-Legendre in cos(theta) x midpoints in azimuth."""
    x, w = np.polynomial.legendre.leggauss(n_mu)
    return _hemisphere(mats, m, np.asarray(gammas, float), (x + 1) / 2, w / 2, int(n_az))
