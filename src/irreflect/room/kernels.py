"""Compiled kernels of the room simulation shared by both methods (numba): surface
reflection (evaluation, sampling, albedo), line-of-sight tests and the Monte Carlo tracer.
The recursive method's transfer kernels are in :mod:`.transport`.

Why numba: the Monte Carlo tracer follows rays one bounce at a time with a branchy loop
(intersections, occlusion, lobe sampling) and the recursive method visits millions of cell
pairs; in numpy both need ray- or pair-sized temporaries and run 10-50 times slower. The
kernels are plain loops over scalars, compiled once and cached on disk (``cache=True``), and
release the GIL so that chunks of work run on several threads.

Conventions. Metres, seconds, radians, watts. Vectors are 3-tuples of floats. ``d`` is the
propagation direction of the incident light (towards the surface), ``i = -d`` the direction
towards the light, ``n`` the unit surface normal on the side the light comes from and ``o``
the outgoing direction. A material is an index into the packed tables of
:func:`pack_materials` (one :class:`MatPack`, so that no kernel needs a dozen positional
arrays). ``brdf`` is the BRDF ``f(i, o)`` (1/sr); ``material_value`` the reflected radiant
intensity per unit incident power, ``f(i, o) cos(theta_o)`` (1/sr).

Material kinds: 0 Lambertian, 1 and 2 the paper's plane-of-incidence models extended to 3D
(lobes of revolution, or a tabulated model; normalised per angle of incidence, not
reciprocal), 3 the reciprocal lobe family of :mod:`.materials` (a non-negative sum of
terms, each symmetric in ``i`` and ``o``):

* diffuse term ``p``: ``(p+2)/(2 pi) cos^p(theta_i) cos^p(theta_o)``, ``p`` in :data:`P_EXPONENTS`;
* mirror term ``(n, q)``: ``(n+1)/(2 pi) cos^n(psi) W_q(cos theta_d)``, ``psi`` the angle between
  ``o`` and the mirror direction of ``i`` (``o . M i = i . M o``), ``theta_d`` the angle
  between ``i`` and the half vector, ``W_q = (1 - cos theta_d)^q / cos theta_d`` or 1;
* retro term ``n``: ``(n+1)/(2 pi) cos^n`` of the angle between ``o`` and ``i``.

The indices ``n`` lie on the geometric ladder :data:`N_VALUES` (ratio 1.5), so that every
power is reached from the one below by ``x sqrt(x)``: a term costs a square root and a
product, not an exponential.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba import njit

from ..models.base import cap_share

#: nodes of the per-gamma tables (albedo, normalisation) over [0, 90] deg
N_GAMMA = 257
GAMMA_NODES = np.linspace(0.0, np.pi / 2, N_GAMMA)
#: lobes per material of the paper's form at most
LOBE_MAX = 8
#: tabulation of plane-of-incidence-equivalent models (0.25 deg)
TABLE_GAMMA = np.radians(np.linspace(0.0, 90.0, 361))
TABLE_THETA = np.radians(np.linspace(-90.0, 90.0, 721))

#: reciprocal family: exponents of the diffuse terms (reached by sqrt and squaring)
P_EXPONENTS = np.array([0.0, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0])
#: ratio of the lobe-index ladder and its rungs n_k = 1.5^k, k = 0..28 (1 to 85,000)
N_RATIO = 1.5
N_VALUES = N_RATIO ** np.arange(29)
#: powers q of (1 - cos theta_d)^q / cos theta_d in the mirror terms; -1: the factor 1
W_POWERS = np.array([-1, 0, 1, 2, 3, 5, 8], np.int64)
#: terms per reciprocal material at most
TERMS_MAX = 16
#: nodes of the energy cap g over cos(theta) in [0, 1]
N_COS = 257
TERM_DIFFUSE, TERM_MIRROR, TERM_RETRO = 0, 1, 2
KIND_LAMBERTIAN, KIND_LOBES, KIND_TABLE, KIND_RECIPROCAL = 0, 1, 2, 3

#: the compiled kernels that allocate nothing: no reference counting (with it, unpacking the
#: packed tables into a per-pair helper cost 20x the helper's arithmetic) and numpy's error
#: model (no ZeroDivisionError branches; every division is guarded where it matters)
hot = njit(cache=True, nogil=True, _nrt=False, error_model="numpy")

C_LIGHT = 299_792_458.0
PI = math.pi
TWO_PI = 2.0 * math.pi
_G_STEP = float(GAMMA_NODES[1] - GAMMA_NODES[0])
_TG_STEP = float(TABLE_GAMMA[1] - TABLE_GAMMA[0])
_TT_STEP = float(TABLE_THETA[1] - TABLE_THETA[0])
_TT0 = float(TABLE_THETA[0])
_TINY = 1e-150

#: every material of a scene, packed for the kernels. Paper form: ``share`` (M, 2),
#: ``lobes`` (M, LOBE_MAX, 5), ``nlobes``, ``norm`` (M, N_GAMMA), ``table``; reciprocal
#: family: ``nterms``, ``tkind``, ``tidx``, ``tq``, ``tamp`` (M, TERMS_MAX) and ``talb``
#: (M, TERMS_MAX, N_GAMMA), each term's albedo with its amplitude (the sampler's mixture); all kinds:
#: ``kind``, ``rho`` (Lambertian reflectance), ``gmax``, ``rhotab`` (albedo, M x N_GAMMA).
#: ``gcos`` (M, N_COS): the energy cap ``g(cos theta)`` of the reciprocal form (all ones when
#: its albedo stays <= 1 uncapped), ``f = g(cos theta_i) g(cos theta_o) sum of terms``.
MatPack = namedtuple("MatPack", ["kind", "rho", "gmax", "share", "lobes", "nlobes", "norm",
                                 "rhotab", "table", "nterms", "tkind", "tidx", "tq", "tamp",
                                 "talb", "gcos"])


def pack_materials(materials) -> MatPack:
    """The arrays the kernels read, for a list of :class:`~irreflect.room.materials.Material`."""
    M = len(materials)
    kind = np.array([m.kind for m in materials], np.int64)
    rho = np.array([m.reflectance if (m.kind == KIND_LAMBERTIAN) else 0.0 for m in materials])
    gmax = np.array([m.gamma_max_rad for m in materials])
    share = np.array([m.share for m in materials], float).reshape(M, 2)
    lobes = np.zeros((M, LOBE_MAX, 5))
    nlobes = np.zeros(M, np.int64)
    nterms = np.zeros(M, np.int64)
    tkind = np.full((M, TERMS_MAX), -1, np.int64)
    tidx = np.zeros((M, TERMS_MAX), np.int64)
    tq = np.zeros((M, TERMS_MAX), np.int64)
    tamp = np.zeros((M, TERMS_MAX))
    talb = np.zeros((M, TERMS_MAX, N_GAMMA))
    gcos = np.ones((M, N_COS))
    for i, m in enumerate(materials):
        if m.kind in (KIND_LOBES, KIND_LAMBERTIAN):
            nlobes[i] = len(m.lobes)
            lobes[i, : len(m.lobes)] = m.lobes
        if m.kind == KIND_RECIPROCAL:
            t = len(m.terms)
            nterms[i] = t
            tkind[i, :t] = m.terms[:, 0].astype(np.int64)
            tidx[i, :t] = m.terms[:, 1].astype(np.int64)
            tq[i, :t] = m.terms[:, 2].astype(np.int64)
            tamp[i, :t] = m.terms[:, 3]
            talb[i, :t] = m.term_albedo
            if m.energy_cap is not None:
                gcos[i] = m.energy_cap
    norm = np.array([m.norm_table for m in materials], float).reshape(M, N_GAMMA)
    rhotab = np.array([m.rho_table for m in materials], float).reshape(M, N_GAMMA)
    if any(m.table is not None for m in materials):
        table = np.zeros((M, TABLE_GAMMA.size, TABLE_THETA.size))
        for i, m in enumerate(materials):
            if m.table is not None:
                table[i] = m.table
    else:
        table = np.zeros((M, 1, 1))
    return MatPack(kind, rho, gmax, share, lobes, nlobes, norm, rhotab, table, nterms, tkind,
                   tidx, tq, tamp, talb, gcos)


# ----------------------------------------------------------------------------- vectors
@hot
def comp(v, a):
    """Component ``a`` of the 3-tuple ``v`` (a runtime index into a tuple is slow in numba)."""
    if a == 0:
        return v[0]
    if a == 1:
        return v[1]
    return v[2]


@hot
def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@hot
def scaled(a, s):
    return (a[0] * s, a[1] * s, a[2] * s)


@hot
def neg(a):
    return (-a[0], -a[1], -a[2])


@hot
def mirror(a, n):
    """``a`` reflected about the plane of normal ``n`` with its normal part kept:
    ``2 (a . n) n - a`` (the mirror direction of ``i`` is ``mirror(i, n)``)."""
    c = 2.0 * dot(a, n)
    return (c * n[0] - a[0], c * n[1] - a[1], c * n[2] - a[2])


@hot
def basis(a):
    """Two unit vectors completing the unit vector ``a`` to an orthonormal frame."""
    ax, ay, az = a
    if abs(az) < 0.9:
        tx, ty, tz = -ay, ax, 0.0
    else:
        tx, ty, tz = 0.0, -az, ay
    tn = math.sqrt(tx * tx + ty * ty + tz * tz)
    tx /= tn
    ty /= tn
    tz /= tn
    return (tx, ty, tz), (ay * tz - az * ty, az * tx - ax * tz, ax * ty - ay * tx)


@hot
def cone_direction(a, cos_psi, azimuth):
    """The unit vector at angle ``acos(cos_psi)`` from the unit axis ``a``, at ``azimuth``."""
    t, b = basis(a)
    s = math.sqrt(max(0.0, 1.0 - cos_psi * cos_psi))
    cp = math.cos(azimuth) * s
    sp = math.sin(azimuth) * s
    return (cos_psi * a[0] + cp * t[0] + sp * b[0], cos_psi * a[1] + cp * t[1] + sp * b[1],
            cos_psi * a[2] + cp * t[2] + sp * b[2])


# ----------------------------------------------------------------------------- reciprocal family
@hot
def pow_p(x, idx):
    """``x ** P_EXPONENTS[idx]`` for x >= 0 by a square root and squarings."""
    if idx == 0:
        return 1.0
    if idx == 1:
        return math.sqrt(x)
    v = x
    for _ in range(idx - 2):
        v *= v
    return v


@hot
def w_factor(q, cd):
    """``W_q(cos theta_d)``: 1 for q = 0, else ``(1 - cd)^W_POWERS[q] / cd``."""
    if q == 0:
        return 1.0
    e = W_POWERS[q]
    x = 1.0 - cd
    v = 1.0
    for _ in range(e):
        v *= x
    return v / cd


@hot
def _ladder(x, k, target):
    """Advance ``x = c^(1.5^k)`` to rung ``target``."""
    while k < target:
        if x < _TINY:
            return 0.0, target
        x = x * math.sqrt(x)
        k += 1
    return x, k


@hot
def half_cos(i, o):
    """cos(theta_d): the cosine between ``i`` and the half vector of ``i`` and ``o``."""
    return max(math.sqrt(max(0.5 * (1.0 + dot(i, o)), 0.0)), 1e-6)


@hot
def cap_at(gtab, c):
    """The energy cap ``g`` at cos(theta) = ``c`` (linear in ``c`` between nodes)."""
    x = min(max(c, 0.0), 1.0) * (gtab.size - 1)
    i = min(int(x), gtab.size - 2)
    f = x - i
    return gtab[i] * (1.0 - f) + gtab[i + 1] * f


@hot
def reciprocal_brdf(mats, m, ci, co, cm, cr, cd):
    """BRDF of reciprocal material ``m`` from the cosines of theta_i, theta_o, the mirror
    angle, the retro angle and theta_d (every one symmetric in i and o)."""
    return (cap_at(mats.gcos[m], ci) * cap_at(mats.gcos[m], co)
            * reciprocal_sum(mats, m, ci, co, cm, cr, cd))


@hot
def reciprocal_sum(mats, m, ci, co, cm, cr, cd):
    """The sum of the terms of :func:`reciprocal_brdf`, without the energy cap."""
    s = 0.0
    xm, km = cm, 0
    xr, kr = cr, 0
    for t in range(mats.nterms[m]):
        kind = mats.tkind[m, t]
        if kind == TERM_DIFFUSE:
            s += mats.tamp[m, t] * pow_p(ci * co, mats.tidx[m, t])
        elif kind == TERM_MIRROR:
            if cm > 0.0:
                xm, km = _ladder(xm, km, mats.tidx[m, t])
                s += mats.tamp[m, t] * xm * w_factor(mats.tq[m, t], cd)
        elif cr > 0.0:
            xr, kr = _ladder(xr, kr, mats.tidx[m, t])
            s += mats.tamp[m, t] * xr
    return s


@hot
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


@hot
def _mixture(mats, m, g, out):
    """The sampler's mixture probabilities at incidence ``g`` (term albedos, normalised)
    into ``out``; returns their sum before normalisation."""
    x = g / _G_STEP
    i = min(int(x), N_GAMMA - 2)
    f = min(max(x - i, 0.0), 1.0)
    total = 0.0
    for t in range(mats.nterms[m]):
        v = max(mats.talb[m, t, i] * (1.0 - f) + mats.talb[m, t, i + 1] * f, 0.0)
        out[t] = v
        total += v
    if total > 0.0:
        for t in range(mats.nterms[m]):
            out[t] /= total
    return total


@hot
def reciprocal_pdf(mats, m, probs, co, cm, cr):
    """Density (1/sr) of the sampler's mixture at the outgoing direction."""
    pdf = 0.0
    xm, km = cm, 0
    xr, kr = cr, 0
    for t in range(mats.nterms[m]):
        w = probs[t]
        if w <= 0.0:
            continue
        kind = mats.tkind[m, t]
        idx = mats.tidx[m, t]
        if kind == TERM_DIFFUSE:
            if co > 0.0:
                p = P_EXPONENTS[idx]
                pdf += w * (p + 2.0) / TWO_PI * pow_p(co, idx) * co
        elif kind == TERM_MIRROR:
            if cm > 0.0:
                xm, km = _ladder(xm, km, idx)
                pdf += w * (N_VALUES[idx] + 1.0) / TWO_PI * xm
        elif cr > 0.0:
            xr, kr = _ladder(xr, kr, idx)
            pdf += w * (N_VALUES[idx] + 1.0) / TWO_PI * xr
    return pdf


# ----------------------------------------------------------------------------- paper's form
@hot
def _table_lookup(table, m, g, theta):
    if theta <= -0.5 * PI or theta >= 0.5 * PI:
        return 0.0
    x = min(max(g / _TG_STEP, 0.0), table.shape[1] - 1 - 1e-9)
    y = min(max((theta - _TT0) / _TT_STEP, 0.0), table.shape[2] - 1 - 1e-9)
    i = int(x)
    j = int(y)
    fx = x - i
    fy = y - j
    return ((table[m, i, j] * (1 - fy) + table[m, i, j + 1] * fy) * (1 - fx)
            + (table[m, i + 1, j] * (1 - fy) + table[m, i + 1, j + 1] * fy) * fx)


@hot
def _tangent(d, n, cos_g):
    """Unit tangent of the plane of incidence pointing to the mirror side (0 at normal incidence)."""
    h = (d[0] + cos_g * n[0], d[1] + cos_g * n[1], d[2] + cos_g * n[2])
    hn = math.sqrt(dot(h, h))
    if hn > 1e-12:
        return scaled(h, 1.0 / hn)
    return (0.0, 0.0, 0.0)


#: the specular share's one rule (:func:`irreflect.models.base.cap_share`: it saturates at 1),
#: compiled from the very function the models and the fitter call
_cap_share = hot(cap_share)


@hot
def paper_share(mats, m, lcg):
    """The two-lobe specular share ``min(1, u_as cos^v_as(gamma))`` (0 below), by
    :func:`~irreflect.models.base.cap_share`."""
    a = mats.share[m, 0] * math.exp(mats.share[m, 1] * lcg)
    return _cap_share(max(a, 0.0))


@hot
def _paper_value(mats, m, d, n, o, cos_o):
    """Intensity per unit incident power of the paper's form (kinds 1 and 2)."""
    cos_g = min(-dot(d, n), 1.0)
    if cos_g <= 0.0:
        return 0.0
    g = math.acos(cos_g)
    nrm = _interp_gamma(mats.norm, m, g)
    h = _tangent(d, n, cos_g)
    gl = min(g, mats.gmax[m])
    if mats.kind[m] == KIND_LOBES:
        lcg = math.log(math.cos(gl))
        a = paper_share(mats, m, lcg)
        s = 0.0
        for i in range(mats.nlobes[m]):
            w = mats.lobes[m, i, 1] + mats.lobes[m, i, 2] * a
            if w <= 0.0:
                continue
            nn = mats.lobes[m, i, 3] * math.exp(mats.lobes[m, i, 4] * lcg)
            ang = mats.lobes[m, i, 0] * g
            ca = math.cos(ang)
            sa = math.sin(ang)
            c = (o[0] * (ca * n[0] + sa * h[0]) + o[1] * (ca * n[1] + sa * h[1])
                 + o[2] * (ca * n[2] + sa * h[2]))
            if c <= 0.0:
                continue
            s += w * (nn + 1.0) / TWO_PI * math.exp(nn * math.log(c))
        return nrm * s
    # plane-of-incidence equivalent of a tabulated model
    r = (d[0] + 2.0 * cos_g * n[0], d[1] + 2.0 * cos_g * n[1], d[2] + 2.0 * cos_g * n[2])
    cphi = min(max(dot(o, r), -1.0), 1.0)
    phi = math.acos(cphi)
    e = (o[0] - cphi * r[0], o[1] - cphi * r[1], o[2] - cphi * r[2])
    q = (n[0] - cos_g * r[0], n[1] - cos_g * r[1], n[2] - cos_g * r[2])
    en = math.sqrt(dot(e, e))
    qn = math.sqrt(dot(q, q))
    cpsi = 1.0
    if en > 1e-12 and qn > 1e-12:
        cpsi = dot(e, q) / (en * qn)
    wa = 0.5 * (1.0 + cpsi)
    v = (wa * _table_lookup(mats.table, m, gl, g - phi)
         + (1.0 - wa) * _table_lookup(mats.table, m, gl, g + phi))
    return nrm * max(v, 0.0)


# ----------------------------------------------------------------------------- any material
@hot
def material_value(mats, m, d, n, o):
    """Reflected radiant intensity per unit incident power, ``f(i, o) cos(theta_o)`` (1/sr);
    0 when ``o`` or ``d`` is on the wrong side of the surface."""
    cos_o = dot(o, n)
    if cos_o <= 0.0:
        return 0.0
    k = mats.kind[m]
    if k == KIND_LAMBERTIAN:
        return mats.rho[m] * cos_o / PI
    ci = -dot(d, n)
    if ci <= 0.0:
        return 0.0
    if k == KIND_RECIPROCAL:
        i = neg(d)
        return reciprocal_brdf(mats, m, min(ci, 1.0), cos_o, dot(o, mirror(i, n)), dot(o, i),
                               half_cos(i, o)) * cos_o
    return _paper_value(mats, m, d, n, o, cos_o)


@hot
def brdf(mats, m, i, n, o):
    """The BRDF ``f(i, o)`` (1/sr), ``i`` towards the light (for reciprocity checks)."""
    cos_o = dot(o, n)
    if cos_o <= 0.0 or dot(i, n) <= 0.0:
        return 0.0
    return material_value(mats, m, neg(i), n, o) / cos_o


@hot
def _sample_lobe(a, n):
    """A direction from ``(n+1)/2pi cos^n`` about the unit axis ``a``."""
    return cone_direction(a, np.random.random() ** (1.0 / (n + 1.0)), TWO_PI * np.random.random())


@hot
def _sample_paper(mats, m, d, n):
    cos_g = min(max(-dot(d, n), 0.0), 1.0)
    g = math.acos(cos_g)
    h = _tangent(d, n, cos_g)
    lcg = math.log(math.cos(min(g, mats.gmax[m])))
    a = paper_share(mats, m, lcg)
    W = 0.0
    for i in range(mats.nlobes[m]):
        W += max(mats.lobes[m, i, 1] + mats.lobes[m, i, 2] * a, 0.0)
    if W <= 0.0:
        return (0.0, 0.0, 0.0), 0.0
    factor = _interp_gamma(mats.rhotab, m, g)
    for _ in range(200):
        u = np.random.random() * W
        pick = mats.nlobes[m] - 1
        acc = 0.0
        for i in range(mats.nlobes[m]):
            acc += max(mats.lobes[m, i, 1] + mats.lobes[m, i, 2] * a, 0.0)
            if u < acc:
                pick = i
                break
        nn = mats.lobes[m, pick, 3] * math.exp(mats.lobes[m, pick, 4] * lcg)
        ang = mats.lobes[m, pick, 0] * g
        ca = math.cos(ang)
        sa = math.sin(ang)
        o = _sample_lobe((ca * n[0] + sa * h[0], ca * n[1] + sa * h[1], ca * n[2] + sa * h[2]), nn)
        if dot(o, n) > 1e-12:
            return o, factor
    return (0.0, 0.0, 0.0), 0.0


@hot
def sample_material(mats, m, d, n, probs):
    """A new direction after reflection and the factor the ray's power is multiplied by,
    ``(o, factor)``; factor 0 ends the ray. ``probs``: scratch of TERMS_MAX floats.

    Reciprocal materials: a term is drawn with probability proportional to its albedo at
    this incidence, a direction from that term's own density, and the factor is the
    *evaluated* ``f(i, o) cos(theta_o) / pdf(o)`` with ``pdf`` the mixture's density: its mean
    is the material's albedo whatever the mixture (directions below the surface end the
    ray). Lambertian: cosine sampling, factor ``rho``. The paper's lobes (kind 1): their own
    mixture restricted to the hemisphere, factor ``rho(gamma)`` (exact, they are normalised
    per incidence). Tabulated (kind 2): cosine sampling, factor ``f pi / cos(theta_o)``.
    """
    k = mats.kind[m]
    if k == KIND_RECIPROCAL:
        i = neg(d)
        ci = min(dot(i, n), 1.0)
        if ci <= 0.0:
            return (0.0, 0.0, 0.0), 0.0
        if _mixture(mats, m, math.acos(ci), probs) <= 0.0:
            return (0.0, 0.0, 0.0), 0.0
        u = np.random.random()
        pick = mats.nterms[m] - 1
        acc = 0.0
        for t in range(mats.nterms[m]):
            acc += probs[t]
            if u < acc:
                pick = t
                break
        kind = mats.tkind[m, pick]
        idx = mats.tidx[m, pick]
        if kind == TERM_DIFFUSE:
            o = _sample_lobe(n, P_EXPONENTS[idx] + 1.0)
        elif kind == TERM_MIRROR:
            o = _sample_lobe(mirror(i, n), N_VALUES[idx])
        else:
            o = _sample_lobe(i, N_VALUES[idx])
        co = dot(o, n)
        if co <= 1e-12:
            return (0.0, 0.0, 0.0), 0.0
        cm = dot(o, mirror(i, n))
        cr = dot(o, i)
        pdf = reciprocal_pdf(mats, m, probs, co, cm, cr)
        if pdf <= 0.0:
            return (0.0, 0.0, 0.0), 0.0
        f = reciprocal_brdf(mats, m, ci, co, cm, cr, half_cos(i, o))
        return o, f * co / pdf
    if k == KIND_LOBES:
        return _sample_paper(mats, m, d, n)
    o = _sample_lobe(n, 1.0)
    cos_o = dot(o, n)
    if cos_o <= 1e-12:
        return (0.0, 0.0, 0.0), 0.0
    if k == KIND_LAMBERTIAN:
        return o, mats.rho[m]
    return o, material_value(mats, m, d, n, o) * PI / cos_o


# ----------------------------------------------------------------------------- albedo
@hot
def _gl_nodes(nodes, lo, hi, k):
    return lo + (hi - lo) * nodes[k]


@hot
def lobe_albedo(kind, n, q, g, gtab, xs, ws):
    """Albedo (reflected / incident power) at incidence ``g`` of one unit-amplitude lobe term
    ``(n+1)/2pi cos^n(psi) W_q`` about the mirror (kind 1) or the retro direction (kind 2),
    cut by the surface. Quadrature in the lobe's own coordinates (its mass is uniform in
    ``t = cos^(n+1) psi``), split where the cone starts to cross the surface, over the part of
    each cone above it (Gauss-Legendre nodes ``xs`` / weights ``ws`` on [0, 1]). The outgoing
    side's energy cap ``gtab`` (over cos theta) is included."""
    g = min(g, 0.5 * PI - 1e-3)
    sg, cg = math.sin(g), math.cos(g)
    i = (-sg, 0.0, cg)
    if kind == TERM_MIRROR:
        a = (sg, 0.0, cg)
        e1 = (-cg, 0.0, sg)
    else:
        a = (-sg, 0.0, cg)
        e1 = (cg, 0.0, sg)
    e2 = (0.0, 1.0, 0.0)
    tk = sg ** (n + 1.0)  # t at the cone angle 90 deg - g
    total = 0.0
    for part in range(2):
        lo, hi = (tk, 1.0) if part == 0 else (0.0, tk)
        if hi <= lo:
            continue
        for a_t in range(xs.size):
            t = lo + (hi - lo) * xs[a_t]
            cpsi = t ** (1.0 / (n + 1.0))
            spsi = math.sqrt(max(0.0, 1.0 - cpsi * cpsi))
            if part == 0 or spsi * sg <= 0.0:
                amax = PI
            else:
                c = -(cpsi * cg) / (spsi * sg)
                amax = math.acos(min(max(c, -1.0), 1.0))
            ring = 0.0
            for b in range(xs.size):
                al = amax * xs[b]
                ca, sa = math.cos(al), math.sin(al)
                o = (cpsi * a[0] + spsi * (ca * e1[0] + sa * e2[0]),
                     cpsi * a[1] + spsi * (ca * e1[1] + sa * e2[1]),
                     cpsi * a[2] + spsi * (ca * e1[2] + sa * e2[2]))
                if o[2] <= 0.0:
                    continue
                w = 1.0 if (kind != TERM_MIRROR or q == 0) else w_factor(q, half_cos(i, o))
                ring += ws[b] * w * o[2] * cap_at(gtab, o[2])
            total += (hi - lo) * ws[a_t] * ring * 2.0 * amax / TWO_PI
    return total


@njit(cache=True)
def term_albedo_table(kind, idx, q, gammas, gtab, xs, ws):
    """Albedo of one unit-amplitude term of the reciprocal family over ``gammas``, with the
    energy cap ``gtab`` on the outgoing side only (the incident side's is a common factor)."""
    out = np.empty(gammas.size)
    dif = 0.0
    if kind == TERM_DIFFUSE:
        # (p+2) int_0^1 mu^(p+1) g(mu) dmu, times cos^p(gamma)
        for a in range(xs.size):
            dif += ws[a] * (P_EXPONENTS[idx] + 2.0) * pow_p(xs[a], idx) * xs[a] * cap_at(gtab, xs[a])
    for k in range(gammas.size):
        if kind == TERM_DIFFUSE:
            out[k] = pow_p(math.cos(min(gammas[k], 0.5 * PI)), idx) * dif
        else:
            out[k] = lobe_albedo(kind, N_VALUES[idx], q, gammas[k], gtab, xs, ws)
    return out


@njit(cache=True)
def _hemisphere(mats, m, gammas, mu, wmu, n_az):
    out = np.zeros(gammas.size)
    daz = TWO_PI / n_az
    n = (0.0, 0.0, 1.0)
    for gi in range(gammas.size):
        d = (math.sin(gammas[gi]), 0.0, -math.cos(gammas[gi]))
        total = 0.0
        for a in range(mu.size):
            st = math.sqrt(max(0.0, 1.0 - mu[a] * mu[a]))
            for b in range(n_az):
                az = (b + 0.5) * daz
                total += wmu[a] * daz * material_value(mats, m, d, n, (st * math.cos(az),
                                                                         st * math.sin(az), mu[a]))
        out[gi] = total
    return out


def hemisphere_integral(mats, m, gammas, n_mu: int = 96, n_az: int = 192) -> np.ndarray:
    """Integral over the hemisphere (sr) of material ``m``'s intensity per unit incident
    power, per angle of incidence (radians): its albedo, by Gauss-Legendre in cos(theta) x
    midpoints in azimuth (a brute-force check independent of the lobes' own quadrature)."""
    x, w = np.polynomial.legendre.leggauss(n_mu)
    return _hemisphere(mats, m, np.asarray(gammas, float), (x + 1) / 2, w / 2, int(n_az))


@njit(cache=True)
def sampled_albedo(mats, m, gammas, n_samples, seed):
    """Mean sampling factor of :func:`sample_material` per angle of incidence, and its
    standard error: the albedo as the Monte Carlo tracer sees it (white-furnace check)."""
    np.random.seed(seed)
    probs = np.zeros(TERMS_MAX)
    n = (0.0, 0.0, 1.0)
    mean = np.zeros(gammas.size)
    err = np.zeros(gammas.size)
    for k in range(gammas.size):
        d = (math.sin(gammas[k]), 0.0, -math.cos(gammas[k]))
        s = 0.0
        s2 = 0.0
        for _ in range(n_samples):
            _, f = sample_material(mats, m, d, n, probs)
            s += f
            s2 += f * f
        mean[k] = s / n_samples
        err[k] = math.sqrt(max(s2 / n_samples - mean[k] ** 2, 0.0) / n_samples)
    return mean, err


@njit(cache=True)
def eval_directions(mats, m, din, dout, want_brdf):
    """``material_value`` (or ``brdf`` with ``want_brdf``) for rows of incident propagation
    directions / outgoing directions (normal +z)."""
    out = np.empty(din.shape[0])
    n = (0.0, 0.0, 1.0)
    for k in range(din.shape[0]):
        d = (din[k, 0], din[k, 1], din[k, 2])
        o = (dout[k, 0], dout[k, 1], dout[k, 2])
        out[k] = brdf(mats, m, neg(d), n, o) if want_brdf else material_value(mats, m, d, n, o)
    return out


# ----------------------------------------------------------------------------- geometry
@hot
def occluded(p, q, boxes):
    """Whether the open segment p-q crosses the interior of any box ``(B, 2, 3)``."""
    for b in range(boxes.shape[0]):
        t0 = 1e-9
        t1 = 1.0 - 1e-9
        hit = True
        for a in range(3):
            s = comp(p, a)
            dd = comp(q, a) - s
            lo = boxes[b, 0, a]
            hi = boxes[b, 1, a]
            if abs(dd) < 1e-15:
                if s <= lo or s >= hi:
                    hit = False
                    break
            else:
                ta = (lo - s) / dd
                tb = (hi - s) / dd
                if ta > tb:
                    ta, tb = tb, ta
                t0 = max(t0, ta)
                t1 = min(t1, tb)
                if t0 >= t1:
                    hit = False
                    break
        if hit:
            return True
    return False


# ----------------------------------------------------------------------------- Monte Carlo
#: the tracer's scene: room size, boxes (B, 2, 3), material of each room face (6) and of each
#: box face (B, 6)
TraceScene = namedtuple("TraceScene", ["size", "boxes", "room_mat", "box_mat"])
#: one emitter-receiver pair: emitter position, direction, (Lambertian order, power);
#: receiver position, direction, (gain x area, cos of the field of view)
TraceLink = namedtuple("TraceLink", ["epos", "edir", "eparams", "rpos", "rdir", "rparams"])
#: the tracer's outputs per reflection order k (row k - 1): ``hist`` (K, T) power per delay
#: bin, ``mom`` (K, 3) power, power x delay, power x delay^2, ``ph`` (K, 2) phasor,
#: ``sumsq`` (K,) squared per-ray contributions, ``reflected`` (K,) power left after k
#: reflections; ``scratch`` (K + TERMS_MAX,) work space
TraceOut = namedtuple("TraceOut", ["hist", "mom", "ph", "sumsq", "reflected", "scratch"])


@hot
def _intersect(p, d, size, boxes):
    """Nearest surface hit from inside the room: (t, normal, box or -1, face 0..5)."""
    best = np.inf
    bn = (0.0, 0.0, 0.0)
    bbox = -1
    bface = -1
    for a in range(3):
        da = comp(d, a)
        pa = comp(p, a)
        if da > 1e-15:
            t = (size[a] - pa) / da
            face = 2 * a + 1
            sgn = -1.0
        elif da < -1e-15:
            t = -pa / da
            face = 2 * a
            sgn = 1.0
        else:
            continue
        if t < best:
            best = t
            bface = face
            bn = (sgn if a == 0 else 0.0, sgn if a == 1 else 0.0, sgn if a == 2 else 0.0)
    for b in range(boxes.shape[0]):
        tmin = -np.inf
        tmax = np.inf
        axis = -1
        miss = False
        for a in range(3):
            lo = boxes[b, 0, a]
            hi = boxes[b, 1, a]
            da = comp(d, a)
            pa = comp(p, a)
            if abs(da) < 1e-15:
                if pa < lo or pa > hi:
                    miss = True
                    break
                continue
            t1 = (lo - pa) / da
            t2 = (hi - pa) / da
            if t1 > t2:
                t1, t2 = t2, t1
            if t1 > tmin:
                tmin = t1
                axis = a
            tmax = min(tmax, t2)
        if miss or axis < 0 or tmin > tmax or tmin <= 1e-9 or tmin >= best:
            continue
        best = tmin
        bbox = b
        dax = comp(d, axis)
        sgn = -1.0 if dax > 0 else 1.0
        bface = 2 * axis if dax > 0 else 2 * axis + 1
        bn = (sgn if axis == 0 else 0.0, sgn if axis == 1 else 0.0, sgn if axis == 2 else 0.0)
    return best, bn, bbox, bface


@hot
def trace_rays(seed, n_rays, scene, link, mats, dt_omega, out):
    """Modified Monte Carlo (Lopez-Hernandez et al. 2000) with next-event estimation.

    ``n_rays`` rays leave the emitter (Lambertian order ``link.eparams[0]``) with power
    ``eparams[1] / n_rays`` each. At every hit the power the hit point sends straight to the
    receiver is added (reflection ``k`` -> row ``k - 1`` of ``out``; exact delay; the delay
    bin is ``floor(tau / dt)``, ``dt_omega = (dt, 2 pi f_mod)``), then a new direction and
    the ray's weight come from :func:`sample_material`. Seeded: the same seed gives the same
    result.
    """
    np.random.seed(seed)
    dt, omega = dt_omega
    e_order, e_power = link.eparams
    gain_area, cos_fov = link.rparams
    bounces = out.mom.shape[0]
    w0 = e_power / n_rays
    nb = out.hist.shape[1]
    contrib = out.scratch[:bounces]
    probs = out.scratch[bounces:]
    edir = (link.edir[0], link.edir[1], link.edir[2])
    rpos = (link.rpos[0], link.rpos[1], link.rpos[2])
    rdir = (link.rdir[0], link.rdir[1], link.rdir[2])
    has_boxes = scene.boxes.shape[0] > 0
    for _ in range(n_rays):
        d = _sample_lobe(edir, e_order)
        p = (link.epos[0], link.epos[1], link.epos[2])
        w = w0
        path = 0.0
        for k in range(bounces):
            contrib[k] = 0.0
        for k in range(bounces):
            t, nrm, box, face = _intersect(p, d, scene.size, scene.boxes)
            if not np.isfinite(t):
                break
            m = scene.room_mat[face] if box < 0 else scene.box_mat[box, face]
            h = (p[0] + t * d[0], p[1] + t * d[1], p[2] + t * d[2])
            path += t
            v = (rpos[0] - h[0], rpos[1] - h[1], rpos[2] - h[2])
            d2 = dot(v, v)
            if d2 > 0.0:
                dist = math.sqrt(d2)
                v = scaled(v, 1.0 / dist)
                cos_r = -dot(rdir, v)
                if cos_r >= cos_fov and cos_r > 0.0 and dot(nrm, v) > 0.0:
                    if not (has_boxes and occluded(h, rpos, scene.boxes)):
                        val = w * material_value(mats, m, d, nrm, v) * gain_area * cos_r / d2
                        if val > 0.0:
                            tau = (path + dist) / C_LIGHT
                            b = int(tau / dt)
                            if b < nb:
                                out.hist[k, b] += val
                            out.mom[k, 0] += val
                            out.mom[k, 1] += val * tau
                            out.mom[k, 2] += val * tau * tau
                            if omega > 0.0:
                                out.ph[k, 0] += val * math.cos(omega * tau)
                                out.ph[k, 1] -= val * math.sin(omega * tau)
                            contrib[k] += val
            nd, factor = sample_material(mats, m, d, nrm, probs)
            if factor <= 0.0:
                break
            w *= factor
            out.reflected[k] += w
            d = nd
            p = (h[0] + nrm[0] * 1e-9, h[1] + nrm[1] * 1e-9, h[2] + nrm[2] * 1e-9)
        for k in range(bounces):
            out.sumsq[k] += contrib[k] * contrib[k]
