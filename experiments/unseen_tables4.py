"""Held-out generator no. 4: dense in-plane goniometer tables of materials never tuned on.

Written independently of the other held-out generators and of ``irreflect.synthetic``: every
physics piece below comes from the literature (references in the function docstrings), and
nothing here imports irreflect. Each table is one material measured in the plane of
incidence with irreflect's angle convention:

* ``gamma_deg`` <= 0: the angle of incidence, on the source side;
* ``theta_deg``: the receiver angle, signed, the mirror direction at ``theta = -gamma``;
* ``power = P0 * gain(gamma) * <f(wi, wo) cos(theta_o)>_aperture [* cos|gamma|]`` plus noise,
  where ``f(wi, wo)`` is a full 3-D BRDF (1/sr) of the unit vectors toward the source
  (``wi``) and the receiver (``wo``), z along the normal, x in the plane of incidence,
  averaged over the receiver's circular aperture.

Kinds of material (``KINDS``; table ``seed`` is of kind ``KINDS[seed % len(KINDS)]``, its
parameters drawn from ``numpy.random.default_rng(seed)``):

``satin_paint``           Lambert + energy-normalised Phong lobe weighted by Schlick Fresnel
``car_paint_flake``       clear coat (narrow GGX) over metallic flakes (Beckmann lobe refracted
                          through the coat) and pigment: two specular lobes of different width
``near_lambert_white``    paper / plaster / ceiling tile: Oren-Nayar, weak broad Beckmann gloss
``textile_sheen``         upholstery / curtain: Oren-Nayar + Charlie sheen (grazing brightening)
``coated_matte``          Hanrahan-Krueger / Weidlich-Wilkie: rough dielectric coat over a
                          Lambertian base, Fresnel transmission, refraction, absorption and
                          inter-reflection inside the coat
``hapke_diffuse``         volume scatterer: Hapke (HG phase, H-functions, opposition surge) or
                          Lommel-Seeliger + Lambert, flatter than Lambert at grazing
``glossy_dielectric``     plastic laminate: GGX/Beckmann + dielectric Fresnel + Smith, coupled
                          Ashikhmin-Shirley diffuse
``carpet_backscatter``    carpet: very rough Oren-Nayar + a retro-reflection lobe about the
                          source direction + weak sheen
``dark_grazing_diffuse``  Minnaert (k > 1) or Wolff diffuse (darker than Lambert at grazing)
                          with a weak gloss
``wood_forward``          wood: Lambert + broad off-specular Lafortune lobe, optional varnish
``conductor_microfacet``  metal (Al, steel, Cr, Cu, Ti): GGX or Beckmann with complex-index
                          Fresnel, roughness 0.02-0.5, a little diffuse dirt
``brushed_metal``         anisotropic Beckmann at a random brush orientation, or a lobe that
                          is Gaussian in the angle from the mirror
``glazed_tile``           glass-like glaze / very glossy plastic: a lobe narrower than most
                          receivers, specular share saturating to 1 at grazing
``anodised_blasted``      bead-blasted anodised metal: rough conductor (share falls with
                          incidence, strong masking) over a Lommel-Seeliger-like oxide

Every BRDF's directional-hemispherical reflectance is integrated numerically (a grid centred
on the mirror direction, fine near it) at every angle of incidence of the table and at 1 and
85 deg; a BRDF whose reflectance exceeds 0.97 anywhere is scaled down to 0.97. index.json
gives the reflectance per angle of incidence.

Instruments: circular receiver aperture of 0.5-3 deg full width (96-point sunflower
quadrature), gain drift per angle of incidence (<= 3 %), proportional + additive detector
noise, a residual dark offset per angle of incidence (the dark reading was subtracted, so
near-zero powers can be slightly negative), quantisation, absolute peak power 1e-9..1e3.
A few tables carry a ``sigma`` column (the 1-sigma noise of ``power``).

Grids: 4-9 angles of incidence (5-80 deg), receivers over most of -85..85 deg with a uniform
step 0.25-5 deg, optionally a finer step near the mirror, optionally a gap of 3-8 deg about
the source direction theta = gamma; 60-1500 points.

Run: ``python experiments/unseen_tables4.py OUTDIR [--first SEED] [--count N]`` (default 0
and 40): writes ``g4_SSS_KIND.csv`` per seed and ``index.json``; the same command writes the
same bytes.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

Brdf = Callable[[np.ndarray, np.ndarray], np.ndarray]

EPS = 1e-9
MAX_REFLECTANCE = 0.97

#: complex refractive index n + ik of metals, (visible ~550 nm, near infrared ~850 nm)
METALS = {
    "aluminium": {"vis": (0.96, 6.69), "nir": (2.80, 8.45)},
    "steel": {"vis": (2.90, 2.90), "nir": (3.00, 3.50)},
    "chromium": {"vis": (3.20, 3.30), "nir": (3.70, 4.40)},
    "copper": {"vis": (0.95, 2.55), "nir": (0.26, 5.30)},
    "titanium": {"vis": (2.50, 3.40), "nir": (3.30, 3.30)},
}


# --------------------------------------------------------------------------------------------
# vector helpers (directions are unit vectors pointing away from the surface, z the normal)
# --------------------------------------------------------------------------------------------


def in_plane(angle_deg) -> np.ndarray:
    """Unit vector at a signed angle from the normal in the x-z plane of incidence."""
    a = np.radians(np.asarray(angle_deg, dtype=float))
    return np.stack([np.sin(a), np.zeros_like(a), np.cos(a)], axis=-1)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.sum(a * b, axis=-1)


def _unit(a: np.ndarray) -> np.ndarray:
    return a / np.maximum(np.linalg.norm(a, axis=-1, keepdims=True), EPS)


def _mu(w: np.ndarray) -> np.ndarray:
    """Cosine to the normal, kept positive (callers zero the lower hemisphere)."""
    return np.maximum(w[..., 2], EPS)


def _upper(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    return (wi[..., 2] > 0) & (wo[..., 2] > 0)


def _mirror(w: np.ndarray) -> np.ndarray:
    return w * np.array([-1.0, -1.0, 1.0])


def _half(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    return _unit(wi + wo)


# --------------------------------------------------------------------------------------------
# Fresnel
# --------------------------------------------------------------------------------------------


def fresnel_dielectric(cos_i: np.ndarray, eta: float) -> np.ndarray:
    """Unpolarised Fresnel reflectance of a dielectric interface of relative index eta
    (Cook & Torrance 1982 form; total internal reflection gives 1)."""
    c = np.clip(cos_i, 0.0, 1.0)
    g2 = eta * eta - 1.0 + c * c
    g = np.sqrt(np.maximum(g2, 0.0))
    a = (g - c) / np.maximum(g + c, EPS)
    b = (c * (g + c) - 1.0) / np.maximum(c * (g - c) + 1.0, EPS)
    return np.where(g2 > 0, np.clip(0.5 * a * a * (1.0 + b * b), 0.0, 1.0), 1.0)


def fresnel_conductor(cos_i: np.ndarray, n: float, k: float) -> np.ndarray:
    """Unpolarised Fresnel reflectance of a conductor of complex index n + ik (exact)."""
    c = np.clip(cos_i, EPS, 1.0).astype(complex)
    eta = complex(n, k)
    cos_t = np.sqrt(1.0 - (1.0 - c * c) / (eta * eta))
    rs = (c - eta * cos_t) / (c + eta * cos_t)
    rp = (eta * c - cos_t) / (eta * c + cos_t)
    return np.clip(0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2), 0.0, 1.0)


def fresnel_schlick(cos_i: np.ndarray, f0: float) -> np.ndarray:
    """Schlick's (1994) approximation."""
    return f0 + (1.0 - f0) * (1.0 - np.clip(cos_i, 0.0, 1.0)) ** 5


def hemispherical_fresnel(eta: float, n: int = 2000) -> float:
    """Diffuse (cosine-weighted hemispherical) reflectance of a smooth interface."""
    mu = (np.arange(n) + 0.5) / n
    return float(np.sum(fresnel_dielectric(mu, eta) * 2.0 * mu) / n)


# --------------------------------------------------------------------------------------------
# diffuse pieces
# --------------------------------------------------------------------------------------------


def lambert(rho: float) -> Brdf:
    def f(wi, wo):
        return np.where(_upper(wi, wo), rho / np.pi, 0.0)

    return f


def oren_nayar(rho: float, sigma: float) -> Brdf:
    """Oren & Nayar (1994), the qualitative model: rough diffuse with back-scatter."""
    s2 = sigma * sigma
    a = 1.0 - 0.5 * s2 / (s2 + 0.33)
    b = 0.45 * s2 / (s2 + 0.09)

    def f(wi, wo):
        ti = np.arccos(np.clip(wi[..., 2], -1, 1))
        to = np.arccos(np.clip(wo[..., 2], -1, 1))
        alpha = np.maximum(ti, to)
        beta = np.minimum(np.minimum(ti, to), np.radians(89.9))
        nl = np.linalg.norm(wi[..., :2], axis=-1)
        nv = np.linalg.norm(wo[..., :2], axis=-1)
        ok = (nl > 1e-6) & (nv > 1e-6)
        cphi = np.where(ok, _dot(wi[..., :2], wo[..., :2]) / np.maximum(nl * nv, EPS), 0.0)
        val = rho / np.pi * (a + b * np.maximum(cphi, 0.0) * np.sin(alpha) * np.tan(beta))
        return np.where(_upper(wi, wo), val, 0.0)

    return f


def minnaert(rho: float, k: float) -> Brdf:
    """Minnaert (1941) limb darkening, normalised to reflectance rho at normal incidence."""

    def f(wi, wo):
        val = rho * (k + 1.0) / (2.0 * np.pi) * (_mu(wi) * _mu(wo)) ** (k - 1.0)
        return np.where(_upper(wi, wo), val, 0.0)

    return f


def wolff(rho: float, eta: float) -> Brdf:
    """Wolff (1994) subsurface diffuse of a smooth dielectric: Fresnel-transmitted in and out."""

    def f(wi, wo):
        ti = 1.0 - fresnel_dielectric(_mu(wi), eta)
        to = 1.0 - fresnel_dielectric(_mu(wo), eta)
        return np.where(_upper(wi, wo), rho / np.pi * ti * to, 0.0)

    return f


def ashikhmin_shirley_diffuse(rho: float, rs: float) -> Brdf:
    """Ashikhmin & Shirley (2000) diffuse term coupled to a specular layer of reflectance rs."""

    def f(wi, wo):
        val = (
            28.0 * rho / (23.0 * np.pi) * (1.0 - rs)
            * (1.0 - (1.0 - 0.5 * _mu(wi)) ** 5) * (1.0 - (1.0 - 0.5 * _mu(wo)) ** 5)
        )
        return np.where(_upper(wi, wo), val, 0.0)

    return f


def hapke(w: float, xi: float, b0: float, h: float, multiple: bool = True) -> Brdf:
    """Hapke (1981, 1993) bidirectional reflectance of a particulate medium: single-scattering
    albedo w, Henyey-Greenstein phase function of asymmetry xi (> 0 forward), shadow-hiding
    opposition surge of amplitude b0 and width h, Chandrasekhar H-functions (Hapke's
    approximation) for multiple scattering. ``multiple=False`` and p = 1 reduce it to
    Lommel-Seeliger."""
    gam = np.sqrt(1.0 - w)

    def hfun(x):
        return (1.0 + 2.0 * x) / (1.0 + 2.0 * x * gam)

    def f(wi, wo):
        mu0, mu = _mu(wi), _mu(wo)
        cos_g = np.clip(_dot(wi, wo), -1.0, 1.0)  # phase angle g: 0 = back to the source
        p = (1.0 - xi * xi) / (1.0 + xi * xi + 2.0 * xi * cos_g) ** 1.5
        tan_half = np.sqrt((1.0 - cos_g) / np.maximum(1.0 + cos_g, EPS))
        surge = b0 / (1.0 + tan_half / h)
        ms = hfun(mu0) * hfun(mu) - 1.0 if multiple else 0.0
        val = w / (4.0 * np.pi) / (mu0 + mu) * (p * (1.0 + surge) + ms)
        return np.where(_upper(wi, wo), val, 0.0)

    return f


# --------------------------------------------------------------------------------------------
# glossy pieces
# --------------------------------------------------------------------------------------------


def _lambda_smith(w: np.ndarray, ax: float, ay: float, dist: str, rot) -> np.ndarray:
    """Smith's Lambda of a direction for anisotropic GGX or Beckmann (Heitz 2014)."""
    x, y, z = rot(w)
    z = np.maximum(z, EPS)
    r2 = x * x + y * y
    a2 = (x * x * ax * ax + y * y * ay * ay) / np.maximum(r2, 1e-30)
    t2 = r2 / (z * z)
    if dist == "ggx":
        return 0.5 * (-1.0 + np.sqrt(1.0 + a2 * t2))
    a = 1.0 / np.sqrt(np.maximum(a2 * t2, 1e-30))
    lam = (1.0 - 1.259 * a + 0.396 * a * a) / (3.535 * a + 2.181 * a * a)
    return np.where(a < 1.6, lam, 0.0)  # Walter et al. (2007) rational fit


def microfacet(
    ax: float,
    fresnel: Callable[[np.ndarray], np.ndarray],
    dist: str = "ggx",
    ay: float | None = None,
    psi: float = 0.0,
    correlated: bool = True,
) -> Brdf:
    """Cook-Torrance microfacet reflection D G F / (4 mu0 mu) with Trowbridge-Reitz (GGX) or
    Beckmann normals of roughness ax (along the brush, at angle psi to the plane of
    incidence) and ay, height-correlated (or separable) Smith masking-shadowing."""
    ay = ax if ay is None else ay
    c, s = np.cos(psi), np.sin(psi)

    def rot(w):
        return c * w[..., 0] + s * w[..., 1], -s * w[..., 0] + c * w[..., 1], w[..., 2]

    def f(wi, wo):
        h = _half(wi, wo)
        hx, hy, hz = rot(h)
        hz = np.maximum(hz, EPS)
        e = (hx * hx / (ax * ax) + hy * hy / (ay * ay)) / (hz * hz)
        if dist == "ggx":
            d = 1.0 / (np.pi * ax * ay * hz**4 * (1.0 + e) ** 2)
        else:
            d = np.exp(-e) / (np.pi * ax * ay * hz**4)
        ll = _lambda_smith(wi, ax, ay, dist, rot)
        lv = _lambda_smith(wo, ax, ay, dist, rot)
        g = 1.0 / (1.0 + ll + lv) if correlated else 1.0 / ((1.0 + ll) * (1.0 + lv))
        val = d * g * fresnel(_dot(wi, h)) / (4.0 * _mu(wi) * _mu(wo))
        return np.where(_upper(wi, wo), val, 0.0)

    return f


def phong_normalised(n: float, f0: float) -> Brdf:
    """Lafortune & Willems (1994) energy-normalised Phong lobe about the mirror direction,
    weighted by Schlick Fresnel of the half angle."""

    def f(wi, wo):
        cos_r = np.maximum(_dot(wo, _mirror(wi)), 0.0)
        val = fresnel_schlick(_dot(wi, _half(wi, wo)), f0) * (n + 2.0) / (2.0 * np.pi) * cos_r**n
        return np.where(_upper(wi, wo), val, 0.0)

    return f


def gaussian_angle_lobe(s: float, fresnel: Callable[[np.ndarray], np.ndarray]) -> Brdf:
    """A lobe Gaussian in the angle from the mirror direction (width s rad), reciprocal
    (1/sqrt(mu0 mu)) and normalised for narrow s."""

    def f(wi, wo):
        phi = np.arccos(np.clip(_dot(wo, _mirror(wi)), -1.0, 1.0))
        lobe = np.exp(-0.5 * (phi / s) ** 2) / (2.0 * np.pi * s * s * np.sqrt(_mu(wi) * _mu(wo)))
        return np.where(_upper(wi, wo), fresnel(_dot(wi, _half(wi, wo))) * lobe, 0.0)

    return f


def lafortune_lobe(ks: float, n: float, cx: float, cz: float = 1.0) -> Brdf:
    """Lafortune et al. (1997) generalised cosine lobe (-cx, -cx, cz): off-specular toward
    grazing when cx > cz; scaled to reflectance ks at normal incidence."""
    k = ks * (n + 2.0) / (2.0 * np.pi * cz**n)

    def f(wi, wo):
        s = -cx * (wi[..., 0] * wo[..., 0] + wi[..., 1] * wo[..., 1]) + cz * wi[..., 2] * wo[..., 2]
        return np.where(_upper(wi, wo), k * np.maximum(s, 0.0) ** n, 0.0)

    return f


def charlie_sheen(ks: float, r: float) -> Brdf:
    """Estevez & Kulla (2017) 'Charlie' sheen distribution with Ashikhmin's velvet
    denominator: cloth fibres lighting up toward grazing."""

    def f(wi, wo):
        hz = np.clip(_half(wi, wo)[..., 2], 0.0, 1.0)
        sin_h = np.sqrt(np.maximum(1.0 - hz * hz, 0.0))
        d = (2.0 + 1.0 / r) * sin_h ** (1.0 / r) / (2.0 * np.pi)
        mu0, mu = _mu(wi), _mu(wo)
        return np.where(_upper(wi, wo), ks * d / (4.0 * (mu0 + mu - mu0 * mu)), 0.0)

    return f


def retro_lobe(kb: float, sigma: float) -> Brdf:
    """Back-scatter toward the source (carpet pile, fibres): Gaussian in the angle between
    the source and the receiver, reciprocal, reflectance about kb."""

    def f(wi, wo):
        d = np.arccos(np.clip(_dot(wi, wo), -1.0, 1.0))
        val = kb * np.exp(-0.5 * (d / sigma) ** 2) / (
            2.0 * np.pi * sigma * sigma * np.sqrt(_mu(wi) * _mu(wo))
        )
        return np.where(_upper(wi, wo), val, 0.0)

    return f


# --------------------------------------------------------------------------------------------
# layers
# --------------------------------------------------------------------------------------------


def _refract_up(w: np.ndarray, eta: float) -> np.ndarray:
    """The direction inside a layer of index eta that leaves the layer as w (both upward)."""
    xy = w[..., :2] / eta
    z = np.sqrt(np.maximum(1.0 - np.sum(xy * xy, axis=-1), 0.0))
    return np.concatenate([xy, z[..., None]], axis=-1)


def under_coat(inner: Brdf, eta: float, tau: float) -> Brdf:
    """A BRDF seen through a smooth clear coat of index eta and absorption optical depth tau
    (Hanrahan & Krueger 1993, single pass): f = T_in T_out exp(-tau (1/mu0' + 1/mu')) f_in /
    eta^2, with the directions refracted into the coat."""

    def f(wi, wo):
        lp, vp = _refract_up(wi, eta), _refract_up(wo, eta)
        t = (1.0 - fresnel_dielectric(_mu(wi), eta)) * (1.0 - fresnel_dielectric(_mu(wo), eta))
        att = np.exp(-tau * (1.0 / _mu(lp) + 1.0 / _mu(vp)))
        return np.where(_upper(wi, wo), t * att * inner(lp, vp) / (eta * eta), 0.0)

    return f


def coated_lambert(rho: float, eta: float, tau: float) -> tuple[Brdf, float]:
    """Lambertian base under a clear coat with the inter-reflections between base and coat
    summed (Kelly-Meeten / Williams; Weidlich & Wilkie 2007): rho / (1 - rho t^2 r_int).
    Returns the BRDF and the internal diffuse reflectance of the interface."""
    r_int = 1.0 - (1.0 - hemispherical_fresnel(eta)) / (eta * eta)
    t_d = np.exp(-2.0 * tau)
    loop = 1.0 / (1.0 - rho * t_d * t_d * r_int)
    return under_coat(lambert(rho * loop), eta, tau), r_int


def mix(*parts: Brdf) -> Brdf:
    def f(wi, wo):
        return sum(p(wi, wo) for p in parts)

    return f


def scaled(brdf: Brdf, k: float) -> Brdf:
    def f(wi, wo):
        return k * brdf(wi, wo)

    return f


# --------------------------------------------------------------------------------------------
# energy check
# --------------------------------------------------------------------------------------------


def reflectance(brdf: Brdf, gamma_deg: float, nr: int = 192, nphi: int = 96) -> float:
    """Directional-hemispherical reflectance at incidence gamma: integral of f cos over the
    hemisphere on a grid centred on the mirror direction (angle rho = pi u^3, fine near it)."""
    wi = in_plane(gamma_deg)
    th_r = -np.radians(gamma_deg)
    r = in_plane(-gamma_deg)
    e1 = np.array([np.cos(th_r), 0.0, -np.sin(th_r)])
    e2 = np.array([0.0, 1.0, 0.0])
    u = (np.arange(nr) + 0.5) / nr
    rho = np.pi * u**3
    drho = 3.0 * np.pi * u**2 / nr
    psi = (np.arange(nphi) + 0.5) / nphi * 2.0 * np.pi
    cr, sr = np.cos(rho)[:, None, None], np.sin(rho)[:, None, None]
    wo = cr * r + sr * (np.cos(psi)[None, :, None] * e1 + np.sin(psi)[None, :, None] * e2)
    vz = wo[..., 2]
    val = brdf(np.broadcast_to(wi, wo.shape), wo) * np.maximum(vz, 0.0)
    w = (np.sin(rho) * drho)[:, None] * (2.0 * np.pi / nphi)
    return float(np.sum(val * w))


# --------------------------------------------------------------------------------------------
# materials
# --------------------------------------------------------------------------------------------


@dataclass
class Material:
    kind: str
    brdf: Brdf
    params: dict
    description: str
    expected: str  # "two-lobe-likely" or "hard"
    notes: list[str] = field(default_factory=list)


def _logu(rng, lo, hi):
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def _metal(rng):
    name = str(rng.choice(sorted(METALS)))
    band = str(rng.choice(["vis", "nir"]))
    n, k = METALS[name][band]
    return name, band, n, k


def satin_paint(rng) -> Material:
    rho = rng.uniform(0.2, 0.85)
    n = _logu(rng, 4.0, 80.0)
    f0 = rng.uniform(0.02, 0.08)
    brdf = mix(lambert(rho * (1.0 - f0)), phong_normalised(n, f0))
    p = {"rho_d": rho, "phong_n": n, "F0": f0}
    return Material("satin_paint", brdf, p, "satin wall paint: Lambert + Fresnel-weighted "
                    "normalised Phong", "two-lobe-likely")


def car_paint_flake(rng) -> Material:
    eta = rng.uniform(1.45, 1.6)
    a_coat = _logu(rng, 0.008, 0.04)
    a_flake = rng.uniform(0.12, 0.35)
    kf = rng.uniform(0.15, 0.5)
    name, band, n, k = _metal(rng)
    rho = rng.uniform(0.02, 0.4) * (1.0 - kf)
    tau = rng.uniform(0.0, 0.2)
    flakes = scaled(microfacet(a_flake, lambda c: fresnel_conductor(c, n, k), "beckmann"), kf)
    base, r_int = coated_lambert(rho, eta, tau)
    coat = microfacet(a_coat, lambda c: fresnel_dielectric(c, eta), "ggx")
    brdf = mix(coat, under_coat(flakes, eta, tau), base)
    p = {"coat_eta": eta, "coat_alpha_ggx": a_coat, "flake_alpha_beckmann": a_flake,
         "flake_cover": kf, "flake_metal": name, "band": band, "pigment_rho": rho,
         "coat_tau": tau, "coat_r_int": r_int}
    return Material("car_paint_flake", brdf, p, "metallic car paint / lacquered metallic "
                    "furniture: narrow coat lobe + broad flake lobe + pigment", "hard")


def near_lambert_white(rng) -> Material:
    rho = rng.uniform(0.7, 0.92)
    sigma = rng.uniform(0.0, 0.25)
    a = rng.uniform(0.2, 0.45)
    kg = rng.uniform(0.2, 1.0)
    brdf = mix(oren_nayar(rho * (1.0 - 0.04 * kg), sigma),
               scaled(microfacet(a, lambda c: fresnel_dielectric(c, 1.5), "beckmann"), kg))
    p = {"rho_d": rho, "oren_nayar_sigma_rad": sigma, "gloss_alpha_beckmann": a,
         "gloss_weight": kg, "gloss_eta": 1.5}
    return Material("near_lambert_white", brdf, p, "paper / plaster / ceiling tile: "
                    "Oren-Nayar + weak broad gloss", "two-lobe-likely")


def textile_sheen(rng) -> Material:
    rho = rng.uniform(0.2, 0.7)
    sigma = rng.uniform(0.3, 0.6)
    ks = rng.uniform(0.1, 0.4)
    r = rng.uniform(0.3, 0.8)
    brdf = mix(oren_nayar(rho, sigma), charlie_sheen(ks, r))
    p = {"rho_d": rho, "oren_nayar_sigma_rad": sigma, "sheen_weight": ks, "sheen_r": r}
    return Material("textile_sheen", brdf, p, "upholstery / curtain fabric: Oren-Nayar + "
                    "Charlie sheen", "hard")


def coated_matte(rng) -> Material:
    eta = rng.uniform(1.3, 1.8)
    a = _logu(rng, 0.03, 0.25)
    dist = str(rng.choice(["ggx", "beckmann"]))
    rho = rng.uniform(0.15, 0.9)
    tau = rng.uniform(0.0, 0.3)
    base, r_int = coated_lambert(rho, eta, tau)
    brdf = mix(microfacet(a, lambda c: fresnel_dielectric(c, eta), dist), base)
    p = {"coat_eta": eta, "coat_alpha": a, "coat_distribution": dist, "base_rho": rho,
         "coat_tau": tau, "coat_r_int": r_int}
    return Material("coated_matte", brdf, p, "varnished / lacquered matte base "
                    "(Hanrahan-Krueger / Weidlich-Wilkie)", "two-lobe-likely")


def hapke_diffuse(rng) -> Material:
    variant = str(rng.choice(["hapke", "lommel_seeliger"], p=[0.65, 0.35]))
    a_gloss = rng.uniform(0.2, 0.5)
    k_gloss = rng.uniform(0.0, 0.5)
    gloss = scaled(microfacet(a_gloss, lambda c: fresnel_dielectric(c, 1.5), "ggx"), k_gloss)
    if variant == "hapke":
        w = rng.uniform(0.6, 0.98)
        xi = rng.uniform(-0.2, 0.2)
        b0 = rng.uniform(0.0, 0.5)
        h = rng.uniform(0.03, 0.15)
        diffuse = hapke(w, xi, b0, h)
        p = {"variant": variant, "w": w, "hg_xi": xi, "surge_b0": b0, "surge_h": h}
    else:
        w = rng.uniform(0.5, 0.95)
        share = rng.uniform(0.5, 1.0)
        diffuse = mix(hapke(w * share, 0.0, 0.0, 1.0, multiple=False),
                      lambert(0.5 * w * (1.0 - share)))
        p = {"variant": variant, "w": w, "ls_share": share}
    p.update({"gloss_alpha_ggx": a_gloss, "gloss_weight": k_gloss})
    return Material("hapke_diffuse", mix(diffuse, gloss), p, "volume-scattering diffuse "
                    "(foam, gypsum, felt, stone): flatter than Lambert at grazing", "hard")


def glossy_dielectric(rng) -> Material:
    eta = rng.uniform(1.45, 1.65)
    a = _logu(rng, 0.05, 0.5)
    dist = str(rng.choice(["ggx", "beckmann"]))
    rho = rng.uniform(0.02, 0.7)
    f0 = ((eta - 1.0) / (eta + 1.0)) ** 2
    brdf = mix(microfacet(a, lambda c: fresnel_dielectric(c, eta), dist),
               ashikhmin_shirley_diffuse(rho, f0))
    p = {"eta": eta, "alpha": a, "distribution": dist, "rho_d": rho}
    return Material("glossy_dielectric", brdf, p, "plastic laminate / furniture: microfacet "
                    "+ coupled diffuse", "two-lobe-likely")


def carpet_backscatter(rng) -> Material:
    rho = rng.uniform(0.1, 0.5)
    sigma = rng.uniform(0.35, 0.6)
    kb = rho * rng.uniform(0.03, 0.12)  # retro peak about 0.1-1x the diffuse level
    sb = rng.uniform(0.3, 0.55)
    ks = rng.uniform(0.0, 0.1)
    brdf = mix(oren_nayar(rho, sigma), retro_lobe(kb, sb), charlie_sheen(ks, 0.5))
    p = {"rho_d": rho, "oren_nayar_sigma_rad": sigma, "retro_weight": kb,
         "retro_sigma_rad": sb, "sheen_weight": ks, "sheen_r": 0.5}
    return Material("carpet_backscatter", brdf, p, "carpet: rough diffuse + back-scatter "
                    "toward the source + weak sheen", "hard")


def dark_grazing_diffuse(rng) -> Material:
    variant = str(rng.choice(["minnaert", "wolff"]))
    eta = rng.uniform(1.35, 1.7)
    if variant == "minnaert":
        rho = rng.uniform(0.3, 0.85)
        k = rng.uniform(1.1, 1.6)
        diffuse = minnaert(rho, k)
        p = {"variant": variant, "rho": rho, "minnaert_k": k}
    else:
        rho = rng.uniform(0.4, 0.95)
        diffuse = wolff(rho, eta)
        p = {"variant": variant, "rho": rho}
    a = rng.uniform(0.15, 0.4)
    kg = rng.uniform(0.3, 1.0)
    gloss = scaled(microfacet(a, lambda c: fresnel_dielectric(c, eta), "ggx"), kg)
    p.update({"gloss_eta": eta, "gloss_alpha_ggx": a, "gloss_weight": kg})
    return Material("dark_grazing_diffuse", mix(diffuse, gloss), p, "diffuse darker than "
                    "Lambert at grazing (painted concrete, smooth stone) + weak gloss",
                    "two-lobe-likely")


def wood_forward(rng) -> Material:
    rho = rng.uniform(0.25, 0.6)
    n = _logu(rng, 2.0, 12.0)
    cx = rng.uniform(1.0, 1.35)
    ks = rng.uniform(0.05, 0.25)
    parts = [lambert(rho), lafortune_lobe(ks, n, cx)]
    varnish = bool(rng.uniform() < 0.5)
    p = {"rho_d": rho, "lafortune_n": n, "lafortune_cx": cx, "lafortune_cz": 1.0,
         "lafortune_ks": ks, "varnish": varnish}
    if varnish:
        a = rng.uniform(0.04, 0.12)
        parts.append(microfacet(a, lambda c: fresnel_dielectric(c, 1.5), "ggx"))
        p["varnish_alpha_ggx"] = a
    return Material("wood_forward", mix(*parts), p, "wood floor / furniture: Lambert + broad "
                    "off-specular forward lobe (+ varnish)", "hard")


def conductor_microfacet(rng) -> Material:
    name, band, n, k = _metal(rng)
    a = _logu(rng, 0.02, 0.5)
    dist = str(rng.choice(["ggx", "beckmann"]))
    dirt = rng.uniform(0.0, 0.05)
    brdf = mix(microfacet(a, lambda c: fresnel_conductor(c, n, k), dist), lambert(dirt))
    p = {"metal": name, "band": band, "n": n, "k": k, "alpha": a, "distribution": dist,
         "dirt_rho": dirt}
    expected = "two-lobe-likely" if a >= 0.08 else "hard"
    return Material("conductor_microfacet", brdf, p, "metal (frames, fittings, radiators): "
                    "microfacet with complex-index Fresnel", expected)


def brushed_metal(rng) -> Material:
    name, band, n, k = _metal(rng)
    variant = str(rng.choice(["anisotropic_beckmann", "gaussian_angle"]))
    dirt = rng.uniform(0.01, 0.08)
    p = {"metal": name, "band": band, "n": n, "k": k, "variant": variant, "dirt_rho": dirt}

    def fres(c):
        return fresnel_conductor(c, n, k)

    if variant == "anisotropic_beckmann":
        ax = _logu(rng, 0.02, 0.08)
        ay = rng.uniform(0.15, 0.4)
        psi = rng.uniform(0.0, np.pi / 2)
        lobe = microfacet(ax, fres, "beckmann", ay=ay, psi=psi)
        p.update({"alpha_along": ax, "alpha_across": ay, "brush_to_plane_rad": psi})
    else:
        s = np.radians(rng.uniform(2.0, 12.0))
        lobe = gaussian_angle_lobe(s, fres)
        p["gauss_sigma_rad"] = s
    return Material("brushed_metal", mix(lobe, lambert(dirt)), p, "brushed aluminium / "
                    "steel: lobe Gaussian in angle", "two-lobe-likely")


def glazed_tile(rng) -> Material:
    eta = rng.uniform(1.5, 1.7)
    a = _logu(rng, 0.01, 0.04)
    rho = rng.uniform(0.03, 0.6)
    base, r_int = coated_lambert(rho, eta, 0.0)
    brdf = mix(microfacet(a, lambda c: fresnel_dielectric(c, eta), "ggx"), base)
    p = {"glaze_eta": eta, "glaze_alpha_ggx": a, "body_rho": rho, "glaze_r_int": r_int}
    return Material("glazed_tile", brdf, p, "glazed ceramic tile / glass-like plastic: "
                    "very narrow lobe, specular share -> 1 at grazing", "hard")


def anodised_blasted(rng) -> Material:
    name, band, n, k = _metal(rng)
    a = rng.uniform(0.3, 0.55)
    w = rng.uniform(0.2, 0.6)
    oxide = hapke(w, rng.uniform(-0.2, 0.2), 0.0, 1.0, multiple=False)
    lobe = microfacet(a, lambda c: fresnel_conductor(c, n, k), "ggx", correlated=False)
    ks = rng.uniform(0.4, 0.9)
    brdf = mix(scaled(lobe, ks), oxide)
    p = {"metal": name, "band": band, "alpha_ggx": a, "lobe_weight": ks, "oxide_w": w,
         "smith": "separable"}
    return Material("anodised_blasted", brdf, p, "bead-blasted anodised metal: rough lobe "
                    "whose share falls with incidence over a Lommel-Seeliger oxide", "hard")


KINDS: tuple[Callable[[np.random.Generator], Material], ...] = (
    satin_paint, car_paint_flake, near_lambert_white, textile_sheen, coated_matte,
    hapke_diffuse, glossy_dielectric, carpet_backscatter, dark_grazing_diffuse, wood_forward,
    conductor_microfacet, brushed_metal, glazed_tile, anodised_blasted,
)


# --------------------------------------------------------------------------------------------
# grid
# --------------------------------------------------------------------------------------------

STEPS = (0.25, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0)


def make_grid(rng) -> tuple[list[float], dict[float, np.ndarray], dict]:
    style = str(rng.choice(["tens", "fifteens", "random"]))
    if style == "tens":
        ng = int(rng.integers(4, 8))
        start = float(rng.choice([10.0, 5.0]))
        gammas = [-(start + 10.0 * i) for i in range(ng)]
    elif style == "fifteens":
        ng = int(rng.integers(4, 6))
        gammas = [-(7.5 + 15.0 * i) if rng.uniform() < 0.3 else -(15.0 * (i + 1))
                  for i in range(ng)]
        gammas = sorted(set(gammas), reverse=True)
    else:
        ng = int(rng.integers(4, 10))
        choices = np.arange(5.0, 80.01, 2.5)
        gammas = sorted((-float(g) for g in rng.choice(choices, size=ng, replace=False)),
                        reverse=True)
    gammas = [g for g in gammas if -80.0 <= g <= -5.0]
    ng = len(gammas)
    lo = -float(rng.integers(75, 86))
    hi = float(rng.integers(75, 86))
    span = hi - lo
    ok = [s for s in STEPS if 60 <= ng * span / s <= 1350]
    step = float(rng.choice(ok))
    offset = float(rng.choice([0.0, 0.0, step / 2.0])) if step >= 1.0 else 0.0
    gap = float(rng.uniform(3.0, 8.0)) if rng.uniform() < 0.7 else 0.0
    fine = None
    if step >= 1.5 and rng.uniform() < 0.5:
        fine_step = float(rng.choice([0.25, 0.5, 1.0]))
        fine_half = float(rng.uniform(6.0, 20.0))
        if ng * (span / step + 2 * fine_half / fine_step) <= 1450:
            fine = (fine_step, fine_half)
    base = np.arange(lo + offset, hi + 1e-9, step)
    thetas = {}
    for g in gammas:
        t = base
        if fine is not None:
            a = np.floor((-g - fine[1]) / fine[0]) * fine[0]  # on the fine step's lattice
            t = np.concatenate([t, np.arange(a, -g + fine[1] + 1e-9, fine[0])])
        t = np.unique(np.round(t, 2))
        t = t[(t >= lo) & (t <= hi) & (np.abs(t) <= 85.0)]
        if gap > 0:
            t = t[np.abs(t - g) >= gap / 2.0]
        thetas[g] = t
    desc = {"style": style, "gammas_deg": gammas, "theta_range_deg": [lo, hi],
            "theta_step_deg": step, "theta_offset_deg": offset,
            "fine_near_mirror": None if fine is None else
            {"step_deg": fine[0], "half_width_deg": fine[1]},
            "source_gap_deg": round(gap, 2),
            "points": int(sum(len(t) for t in thetas.values()))}
    return gammas, thetas, desc


# --------------------------------------------------------------------------------------------
# instrument
# --------------------------------------------------------------------------------------------


def sunflower(n: int = 96) -> np.ndarray:
    """n points evenly covering the unit disk (Vogel's spiral), shape (n, 2)."""
    k = np.arange(n) + 0.5
    r = np.sqrt(k / n)
    a = k * np.pi * (3.0 - np.sqrt(5.0))
    return np.stack([r * np.cos(a), r * np.sin(a)], axis=-1)


def received(brdf: Brdf, gamma: float, thetas: np.ndarray, aperture_deg: float) -> np.ndarray:
    """<f(wi, wo) cos(theta_o)> over a circular receiver aperture of full width aperture_deg."""
    wi = in_plane(gamma)
    wo0 = in_plane(thetas)[:, None, :]
    th = np.radians(thetas)[:, None, None]
    e1 = np.concatenate([np.cos(th), np.zeros_like(th), -np.sin(th)], axis=-1)
    e2 = np.array([0.0, 1.0, 0.0])
    off = sunflower() * np.radians(aperture_deg) / 2.0
    wo = _unit(wo0 + off[None, :, 0:1] * e1 + off[None, :, 1:2] * e2)
    val = brdf(np.broadcast_to(wi, wo.shape), wo) * np.maximum(wo[..., 2], 0.0)
    return val.mean(axis=1)


def _r6(x):
    if isinstance(x, (bool, str)) or x is None:
        return x
    if isinstance(x, dict):
        return {k: _r6(val) for k, val in x.items()}
    if isinstance(x, (list, tuple)):
        return [_r6(val) for val in x]
    if isinstance(x, (int, np.integer)):
        return int(x)
    return float(f"{float(x):.6g}")


def make_table(seed: int) -> tuple[str, str, dict]:
    """Return (file name, CSV text, index entry) of the table of this seed."""
    rng = np.random.default_rng(seed)
    material = KINDS[seed % len(KINDS)](rng)
    gammas, thetas, grid = make_grid(rng)

    # energy conservation: reflectance at the table's angles and at 1 and 85 deg
    checks = sorted(set([-1.0, -85.0] + gammas), reverse=True)
    alb = np.array([reflectance(material.brdf, g) for g in checks])
    scale = 1.0
    if alb.max() > MAX_REFLECTANCE:
        scale = MAX_REFLECTANCE / alb.max()
        material.notes.append(f"BRDF scaled by {scale:.4g} to keep reflectance <= 0.97")
    brdf = scaled(material.brdf, scale)
    alb = alb * scale

    aperture = float(rng.uniform(0.5, 3.0))
    irradiance = bool(rng.uniform() < 0.5)
    drift = float(rng.uniform(0.0, 0.03))
    gains = {g: 1.0 + float(rng.uniform(-drift, drift)) for g in gammas}
    rel = _logu(rng, 0.002, 0.03)
    add = _logu(rng, 1e-4, 3e-3)
    dark = float(rng.uniform(0.0, 0.6))
    quant = _logu(rng, 1e-5, 5e-4)
    peak_target = float(10.0 ** rng.uniform(-9.0, 3.0))
    with_sigma = bool(rng.uniform() < 0.25)

    unit = {}
    for g in gammas:
        p = received(brdf, g, thetas[g], aperture) * gains[g]
        if irradiance:
            p = p * np.cos(np.radians(g))
        unit[g] = p
    peak_unit = max(float(p.max()) for p in unit.values())
    p0 = peak_target / peak_unit

    rows = []
    for g in gammas:
        true = unit[g] * p0
        sd = np.sqrt((rel * true) ** 2 + (add * peak_target) ** 2)
        offset = rng.normal(0.0, dark * add * peak_target)
        reading = true + rng.normal(0.0, 1.0, size=true.shape) * sd + offset
        q = quant * peak_target
        reading = np.round(reading / q) * q
        sig = np.sqrt(sd**2 + (dark * add * peak_target) ** 2 + q * q / 12.0)
        for t, pw, s in zip(thetas[g], reading, sig, strict=True):
            rows.append((g, float(t), float(pw) + 0.0, float(s)))

    head = "gamma_deg,theta_deg,power" + (",sigma" if with_sigma else "")
    lines = [head]
    for g, t, pw, s in rows:
        line = f"{g:g},{t:g},{pw:.7g}"
        if with_sigma:
            line += f",{s:.3g}"
        lines.append(line)
    text = "\n".join(lines) + "\n"
    name = f"g4_{seed:03d}_{material.kind}.csv"

    entry = {
        "file": name,
        "seed": seed,
        "kind": material.kind,
        "description": material.description,
        "expected": material.expected,
        "params": _r6(material.params),
        "brdf_scale": _r6(scale),
        "reflectance_per_gamma": {f"{g:g}": _r6(a) for g, a in zip(checks, alb, strict=True)},
        "grid": _r6(grid),
        "instrument": _r6({
            "aperture_full_width_deg": aperture,
            "irradiance_cos_gamma_included": irradiance,
            "gain_per_gamma": {f"{g:g}": gains[g] for g in gammas},
            "noise_proportional": rel,
            "noise_additive_of_peak": add,
            "dark_offset_residual_sd_of_additive": dark,
            "quantisation_step_of_peak": quant,
            "peak_power": peak_target,
            "P0": p0,
            "sigma_column": with_sigma,
        }),
        "power": "P0 * gain(gamma) * <BRDF * cos(theta)>_aperture"
                 + (" * cos|gamma|" if irradiance else "") + " + noise",
        "notes": material.notes,
    }
    return name, text, entry


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("outdir", type=Path)
    ap.add_argument("--first", type=int, default=0, help="first seed (default 0)")
    ap.add_argument("--count", type=int, default=40, help="number of tables (default 40)")
    args = ap.parse_args(argv)
    args.outdir.mkdir(parents=True, exist_ok=True)
    entries = []
    for seed in range(args.first, args.first + args.count):
        name, text, entry = make_table(seed)
        (args.outdir / name).write_text(text)
        entries.append(entry)
        print(f"{name}: {entry['grid']['points']} points, "
              f"{len(entry['grid']['gammas_deg'])} angles of incidence")
    index = {"generator": "experiments/unseen_tables4.py", "first": args.first,
             "count": args.count, "angle_convention": "gamma <= 0 source side, mirror at "
             "theta = -gamma, phi = -gamma - theta",
             "kinds": [k.__name__ for k in KINDS], "tables": entries}
    (args.outdir / "index.json").write_text(json.dumps(index, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
