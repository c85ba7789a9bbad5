"""Reflection models from the literature, in the plane of incidence (the paper's refs. 18-26).

Each model is written as *received power* in the units of the measurements::

    P(gamma, theta) = K * f_r(gamma, theta) * cos(theta)

with ``f_r`` the model's BRDF (1/sr) and ``K`` a scale in power units (the incident flux
times the receiver's solid angle and any calibration factor; as in the paper's Eq. 22,
``K`` does not depend on the angles). So one fitter serves all models, and their errors
can be compared on the same data with the same measure (section 5.3).

Angles follow the paper: the angle of incidence ``gamma`` is negative on the source side,
the receiver angle ``theta`` is signed, the mirror direction is ``theta = -gamma`` and the
angle from it is ``phi = -gamma - theta``. In the plane of incidence the half vector
``H = (L + V) / |L + V|`` makes the angle ``theta_h = (gamma + theta) / 2`` with the surface
normal, and the angle ``beta = (theta - gamma) / 2`` with the source (and receiver)
direction. Everything here takes **radians**.

Every model splits its reflected power between a diffuse and a specular (glossy) part
whose shares add up to 1, ``K [(1 - k_s) f_d cos(theta) + k_s f_s cos(theta)]``; ``K``
and ``k_s`` are the linear coefficients of the separable form (see :mod:`irreflect.model`)
and the shape parameters (exponents, roughness, refractive index) are the nonlinear
coordinates ``z``. Leaving both shares free beside ``K`` would make the three degenerate.
The glossy lobes are normalised so that ``k_s`` is close to the specular fraction of the
reflected power at normal incidence.

Registered names: ``blinn-phong``, ``lafortune`` (``lafortune:N`` for N lobes, default 2),
``ward``, ``torrance-sparrow`` (Beckmann slope distribution),
``torrance-sparrow-gaussian`` (Gaussian slope-angle distribution, as Torrance and Sparrow
1967) and ``oren-nayar``, in :data:`irreflect.models.registry.MODELS`.

The specular parts see the geometry's ``theta_spec`` (so that an extension that tilts the
specular axis tilts them too); the diffuse parts and the receiver's ``cos(theta)`` see
``theta``.
"""

from __future__ import annotations

import functools

import numpy as np

from ..errors import IrreflectError, unknown_name
from .base import FitHints, Parameter, ReflectionModel, _col, _lobes_to_natural
from .guesses import MAX_LOBE_INDEX, estimate_specular_index, peak_directions

INV_PI = 1.0 / np.pi
#: The narrowest Gaussian-type lobe: RMS slope 1 / sqrt(2 n) at the cosine-lobe mirror
#: limit ``n = MAX_LOBE_INDEX`` (10^6, a half width of 0.07 deg).
MIN_SLOPE = 7.0e-4
TS_DISTRIBUTIONS = ("beckmann", "gaussian")


def _screen(lower, upper) -> dict:
    """Plausible box of ``z`` for the fitter's global screening."""
    return {"screen_lower": np.asarray(lower, float), "screen_upper": np.asarray(upper, float)}


# --------------------------------------------------------------------------- geometry
def half_angle(gamma, theta):
    """Angle ``theta_h = (gamma + theta) / 2`` (radians) between the half vector and the normal."""
    return 0.5 * (np.asarray(gamma, float) + np.asarray(theta, float))


def source_half_angle(gamma, theta):
    """Angle ``beta = (theta - gamma) / 2`` (radians) between the half vector and the source."""
    return 0.5 * (np.asarray(theta, float) - np.asarray(gamma, float))


def _vgroove(geom):
    """:func:`vgroove_attenuation` of a geometry's specular receiver angle."""
    cos_t = np.clip(np.cos(geom.theta_spec), 0.0, None)
    cos_g = np.clip(geom.cos_gamma, 0.0, None)
    with np.errstate(divide="ignore", invalid="ignore"):
        g = np.minimum(2.0 * geom.cos_half * np.minimum(cos_t, cos_g) / geom.cos_source_half,
                       1.0)
    return np.where(np.isfinite(g), np.clip(g, 0.0, 1.0), 0.0)


def _oren_nayar_term(geom):
    """``max(0, cos dphi) sin(a) tan(b)`` of the Oren-Nayar diffuse part (receiver angle)."""
    gamma, theta = geom.gamma, geom.theta
    abs_g, abs_t = np.abs(gamma), np.abs(theta)
    # alpha = max(theta_i, theta_r), beta = min(...); the azimuth term max(0, cos(phi_r -
    # phi_i)) is 1 with the receiver on the source side, else 0
    return np.where((gamma * theta) > 0, np.sin(np.maximum(abs_g, abs_t))
                    * np.tan(np.minimum(abs_g, abs_t)), 0.0)


# --------------------------------------------------------------------------- building blocks
def fresnel_dielectric(cos_beta, eta):
    """Unpolarised Fresnel reflectance of a dielectric (Cook and Torrance 1981, ref. 25).

    ``F = 1/2 (g - c)^2 / (g + c)^2 [1 + (c (g + c) - 1)^2 / (c (g - c) + 1)^2]`` with
    ``c = cos(beta)``, ``g = sqrt(eta^2 - 1 + c^2)``.

    cos_beta : cosine of the angle of incidence on the facet (dimensionless, 0..1).
    eta : refractive index (dimensionless, > 1). Returns F (dimensionless, 0..1):
    ``((eta - 1) / (eta + 1))^2`` at normal incidence, 1 at grazing incidence.
    """
    f, _ = _fresnel_and_derivative(np.asarray(cos_beta, float), np.asarray(eta, float))
    return f


def _fresnel_and_derivative(c, eta):
    """Fresnel reflectance and its derivative with respect to ``eta``."""
    g = np.sqrt(eta * eta - 1.0 + c * c)
    gm, gp = g - c, g + c
    a = (gm / gp) ** 2
    u = c * gp - 1.0
    w = c * gm + 1.0
    b = 1.0 + (u / w) ** 2
    f = 0.5 * a * b
    da_dg = 4.0 * c * gm / gp**3
    db_dg = 4.0 * c * u * (1.0 - c * c) / w**3
    df_dg = 0.5 * (da_dg * b + a * db_dg)
    return f, df_dg * eta / g


def beckmann_distribution(theta_h, m):
    """Beckmann facet distribution ``exp(-tan^2(theta_h) / m^2) / (pi m^2 cos^4(theta_h))``.

    theta_h : angle of the facet normal from the surface normal (radians).
    m : RMS facet slope (dimensionless). Normalised over projected area:
    ``integral D cos(theta_h) d omega_h = 1``. Units 1/sr.
    """
    theta_h = np.asarray(theta_h, float)
    c = np.cos(theta_h)
    with np.errstate(under="ignore"):
        return np.exp(-np.tan(theta_h) ** 2 / m**2) / (np.pi * m**2 * c**4)


def gaussian_distribution(theta_h, m):
    """Gaussian facet-angle distribution of Torrance and Sparrow (1967, ref. 26):
    ``exp(-theta_h^2 / m^2) / (pi m^2)``.

    theta_h : radians. m : width of the slope-angle distribution (radians). The factor
    ``1 / (pi m^2)`` normalises it for small ``m`` (as the Beckmann one). Units 1/sr.
    """
    theta_h = np.asarray(theta_h, float)
    with np.errstate(under="ignore"):
        return np.exp(-(theta_h**2) / m**2) / (np.pi * m**2)


def vgroove_attenuation(gamma, theta):
    """Geometric attenuation of symmetric V-grooves (Torrance and Sparrow 1967; Blinn 1977).

    ``G = min(1, 2 cos(theta_h) cos(theta) / cos(beta), 2 cos(theta_h) cos(gamma) / cos(beta))``
    in the plane of incidence (masking and shadowing). gamma, theta: radians. Dimensionless.
    """
    gamma = np.asarray(gamma, float)
    theta = np.asarray(theta, float)
    cos_h = np.cos(half_angle(gamma, theta))
    cos_b = np.cos(source_half_angle(gamma, theta))
    cos_t = np.clip(np.cos(theta), 0.0, None)
    cos_g = np.clip(np.cos(gamma), 0.0, None)
    with np.errstate(divide="ignore", invalid="ignore"):
        g = np.minimum(2.0 * cos_h * np.minimum(cos_t, cos_g) / cos_b, 1.0)
    return np.where(np.isfinite(g), np.clip(g, 0.0, 1.0), 0.0)


def oren_nayar_ab(sigma):
    """Coefficients of the qualitative Oren-Nayar model (Oren and Nayar 1994, ref. 23):
    ``A = 1 - 0.5 s^2 / (s^2 + 0.33)``, ``B = 0.45 s^2 / (s^2 + 0.09)``.

    sigma : standard deviation of the facet slope angle (radians). Returns (A, B),
    dimensionless; ``sigma = 0`` gives Lambert (A = 1, B = 0)."""
    s2 = np.asarray(sigma, float) ** 2
    return 1.0 - 0.5 * s2 / (s2 + 0.33), 0.45 * s2 / (s2 + 0.09)


def _oren_nayar_ab_derivative(sigma):
    return (-0.33 * sigma / (sigma**2 + 0.33) ** 2, 0.081 * sigma / (sigma**2 + 0.09) ** 2)


# --------------------------------------------------------------------------- pure functions
def blinn_phong_power(gamma, theta, k_s, n, K):
    """Blinn-Phong model (Blinn 1977, the paper's ref. 19) as received power.

    ``P = K cos(theta) [(1 - k_s) / pi + k_s (n + 8) / (8 pi) cos^n(theta_h)]``: a Lambertian
    part and a lobe about the half vector, ``theta_h = (gamma + theta) / 2``. The factor
    ``(n + 8) / (8 pi)`` is the usual energy normalisation of the half-vector lobe.

    gamma, theta : radians. k_s : specular share (dimensionless, 0..1). n : half-vector
    exponent (dimensionless; about 4x a Phong exponent for the same peak width).
    K : power units. Returns power in the units of K.
    """
    gamma = np.asarray(gamma, float)
    theta = np.asarray(theta, float)
    cos_t = np.clip(np.cos(theta), 0.0, None)
    spec = (n + 8.0) / (8.0 * np.pi) * np.cos(half_angle(gamma, theta)) ** n
    return K * cos_t * ((1.0 - k_s) * INV_PI + k_s * spec)


def lafortune_power(gamma, theta, cx, n, shares, K):
    """Lafortune generalised cosine lobes (Lafortune et al. 1997, the paper's ref. 20).

    ``P = K cos(theta) [(1 - sum a_i) / pi + sum_i a_i (n_i + 2) / (2 pi) s_i^n_i]`` with
    ``s_i = max(0, Cx_i L_x V_x + L_z V_z) = max(0, Cx_i sin(gamma) sin(theta) +
    cos(gamma) cos(theta))``: the source and receiver directions ``L``, ``V`` in the plane
    of incidence, ``C_z`` fixed to 1 (its magnitude is degenerate with ``a_i``).
    ``Cx = -1`` is a Phong lobe about the mirror direction, ``Cx = 0`` the lobe
    ``(cos gamma cos theta)^n`` that narrows toward the normal, ``Cx > 0`` retro-reflection.

    gamma, theta : radians. cx, n, shares : sequences, one value per lobe
    (dimensionless). K : power units.
    """
    gamma = np.asarray(gamma, float)
    theta = np.asarray(theta, float)
    cos_t = np.clip(np.cos(theta), 0.0, None)
    total = (1.0 - float(np.sum(shares))) * INV_PI * np.ones(np.broadcast(gamma, theta).shape)
    for c_i, n_i, a_i in zip(cx, n, shares, strict=True):
        s = c_i * np.sin(gamma) * np.sin(theta) + np.cos(gamma) * np.cos(theta)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore", under="ignore"):
            lobe = np.where(s > 0, np.abs(s) ** n_i, 0.0)
        total = total + a_i * (n_i + 2.0) / (2.0 * np.pi) * lobe
    return K * cos_t * total


def ward_power(gamma, theta, k_s, alpha, K):
    """Isotropic Ward model (Ward 1992; the Gaussian-lobe family of refs. 21 and 26).

    ``P = K cos(theta) [(1 - k_s) / pi + k_s exp(-tan^2(theta_h) / alpha^2) /
    (4 pi alpha^2 sqrt(cos(gamma) cos(theta)))]``, ``theta_h = (gamma + theta) / 2``.

    gamma, theta : radians. k_s : specular share (0..1). alpha : RMS surface slope
    (dimensionless). K : power units.
    """
    gamma = np.asarray(gamma, float)
    theta = np.asarray(theta, float)
    cos_t = np.clip(np.cos(theta), 0.0, None)
    with np.errstate(under="ignore"):
        spec = np.exp(-np.tan(half_angle(gamma, theta)) ** 2 / alpha**2) / (
            4.0 * np.pi * alpha**2 * np.sqrt(np.cos(gamma) * cos_t))
    return K * cos_t * ((1.0 - k_s) * INV_PI + k_s * spec)


def torrance_sparrow_brdf(gamma, theta, m, eta, distribution="beckmann"):
    """Specular BRDF of V-groove microfacets (Torrance and Sparrow 1967, ref. 26, in the
    form of Cook and Torrance 1981, ref. 25), with the Fresnel factor relative to normal
    incidence:

    ``f_s = [F(beta, eta) / F(0, eta)] D(theta_h; m) G / (4 cos(gamma) cos(theta))``.

    gamma, theta : radians. m : roughness (RMS slope for Beckmann, slope-angle width in
    radians for Gaussian). eta : refractive index (> 1). distribution : "beckmann" or
    "gaussian". Returns 1/sr.
    """
    gamma = np.asarray(gamma, float)
    theta = np.asarray(theta, float)
    th = half_angle(gamma, theta)
    d = _ts_distribution(distribution)(th, m)
    c = np.cos(source_half_angle(gamma, theta))
    f = fresnel_dielectric(c, eta) / fresnel_dielectric(1.0, eta)
    g = vgroove_attenuation(gamma, theta)
    with np.errstate(divide="ignore", invalid="ignore"):
        return f * d * g / (4.0 * np.cos(gamma) * np.cos(theta))


def torrance_sparrow_power(gamma, theta, k_s, m, eta, K, distribution="beckmann"):
    """Torrance-Sparrow model with a Lambertian part, as received power:
    ``P = K cos(theta) [(1 - k_s) / pi + k_s f_s]`` with ``f_s`` of
    :func:`torrance_sparrow_brdf`. k_s : specular share (0..1); m, eta, distribution as
    there; gamma, theta in radians; K in power units."""
    theta = np.asarray(theta, float)
    cos_t = np.clip(np.cos(theta), 0.0, None)
    f_s = torrance_sparrow_brdf(gamma, theta, m, eta, distribution)
    return K * cos_t * ((1.0 - k_s) * INV_PI + k_s * np.where(cos_t > 0, f_s, 0.0))


def oren_nayar_power(gamma, theta, k_s, sigma, n, K):
    """Oren-Nayar rough diffuse part (Oren and Nayar 1994, ref. 23, qualitative model) plus a
    normalised Phong lobe about the mirror direction, as received power:

    ``P = K cos(theta) [(1 - k_s) (A + B max(0, cos dphi) sin(a) tan(b)) / pi
    + k_s (n + 2) / (2 pi) cos^n(phi)]`` with ``a = max(|gamma|, |theta|)``,
    ``b = min(|gamma|, |theta|)``, ``cos dphi = 1`` when the receiver is on the source side
    (``gamma theta > 0``) and -1 otherwise, A and B from :func:`oren_nayar_ab`.

    gamma, theta : radians. k_s : specular share (0..1). sigma : facet slope-angle
    standard deviation (radians). n : Phong exponent. K : power units.
    """
    gamma = np.asarray(gamma, float)
    theta = np.asarray(theta, float)
    cos_t = np.clip(np.cos(theta), 0.0, None)
    a, b = oren_nayar_ab(sigma)
    ag, at = np.abs(gamma), np.abs(theta)
    term = np.where(gamma * theta > 0, np.sin(np.maximum(ag, at)) * np.tan(np.minimum(ag, at)), 0.0)
    cos_phi = np.cos(gamma + theta)
    with np.errstate(invalid="ignore", divide="ignore", under="ignore"):
        spec = np.where(cos_phi > 0, np.abs(cos_phi) ** n, 0.0) * (n + 2.0) / (2.0 * np.pi)
    return K * cos_t * ((1.0 - k_s) * (a + b * term) * INV_PI + k_s * spec)


def _ts_distribution(name):
    if name == "beckmann":
        return beckmann_distribution
    if name == "gaussian":
        return gaussian_distribution
    raise unknown_name("facet distribution", str(name), TS_DISTRIBUTIONS)


# --------------------------------------------------------------------------- separable forms
# Every "diffuse + specular" model below has basis columns
#   B_0 = f_d cos(theta)  and  B_1 = f_s(z) cos(theta),  alpha = (K (1 - k_s), K k_s).

def _stack2(b0, b1):
    shape = np.broadcast_shapes(b0.shape, b1.shape)
    out = np.empty(shape + (2,))
    out[..., 0] = b0
    out[..., 1] = b1
    return out


def _dbasis_spec(shape, derivs):
    """dB (M, n, 2, P) with a zero diffuse column and the given specular derivatives."""
    out = np.zeros(shape + (2, len(derivs)))
    for k, d in enumerate(derivs):
        out[..., 1, k] = d
    return out


def _blinn_basis(geom, z, derivatives=True):
    n = np.exp(_col(z, 0))
    cos_t = geom.receiver_cos
    with np.errstate(under="ignore", over="ignore"):
        pw = np.exp(n * geom.log_cos_half) * cos_t
    spec = (n + 8.0) / (8.0 * np.pi) * pw
    basis = _stack2(cos_t * INV_PI, spec)
    if not derivatives:
        return basis, None
    d_ln_n = n * (pw / (8.0 * np.pi) + spec * geom.log_cos_half)
    return basis, _dbasis_spec(basis.shape[:-1], [d_ln_n])


def _ward_basis(geom, z, derivatives=True):
    alpha = np.exp(_col(z, 0))
    cos_t = geom.receiver_cos
    with np.errstate(under="ignore", divide="ignore", invalid="ignore"):
        shape_fn = np.sqrt(cos_t / geom.cos_gamma)
        ratio = geom.tan2_half / alpha**2
        spec = np.exp(-ratio) / (4.0 * np.pi * alpha**2) * shape_fn
    basis = _stack2(cos_t * INV_PI, spec)
    if not derivatives:
        return basis, None
    return basis, _dbasis_spec(basis.shape[:-1], [spec * (2.0 * ratio - 2.0)])


def _make_ts_basis(distribution):
    if distribution not in TS_DISTRIBUTIONS:
        raise unknown_name("facet distribution", str(distribution), TS_DISTRIBUTIONS)

    def basis_fn(geom, z, derivatives=True):
        m = np.exp(_col(z, 0))
        eta = _col(z, 1)
        cos_t = geom.receiver_cos
        with np.errstate(under="ignore", divide="ignore", invalid="ignore", over="ignore"):
            if distribution == "beckmann":
                ratio = geom.tan2_half / m**2
                d = np.exp(-ratio) / (np.pi * m**2 * geom.cos_half ** 4)
            else:
                ratio = geom.half_angle ** 2 / m**2
                d = np.exp(-ratio) / (np.pi * m**2)
            f, df = _fresnel_and_derivative(geom.cos_source_half, eta)
            f0 = ((eta - 1.0) / (eta + 1.0)) ** 2
            df0 = 4.0 * (eta - 1.0) / (eta + 1.0) ** 3
            fr = f / f0
            dfr = (df * f0 - f * df0) / f0**2
            # f_s cos(theta) = F/F0 D G / (4 cos gamma): cos(theta) cancels
            geo = _vgroove(geom) / (4.0 * geom.cos_gamma) * (cos_t > 0)
            spec = fr * d * geo
        basis = _stack2(cos_t * INV_PI, spec)
        if not derivatives:
            return basis, None
        d_ln_m = spec * (2.0 * ratio - 2.0)
        d_eta = dfr * d * geo
        return basis, _dbasis_spec(basis.shape[:-1], [d_ln_m, d_eta])

    return basis_fn


def _oren_nayar_basis(geom, z, derivatives=True):
    sigma = _col(z, 0)
    n = np.exp(_col(z, 1))
    cos_t = geom.receiver_cos
    a, b = oren_nayar_ab(sigma)
    term = _oren_nayar_term(geom)
    diffuse = (a + b * term) * INV_PI * cos_t
    with np.errstate(under="ignore", over="ignore"):
        pw = np.exp(n * geom.log_cos_phi) * geom.pos_phi * cos_t
    spec = (n + 2.0) / (2.0 * np.pi) * pw
    basis = _stack2(diffuse, spec)
    if not derivatives:
        return basis, None
    da, db = _oren_nayar_ab_derivative(sigma)
    out = np.zeros(basis.shape[:-1] + (2, 2))
    out[..., 0, 0] = (da + db * term) * INV_PI * cos_t
    out[..., 1, 1] = n * (pw / (2.0 * np.pi) + spec * geom.log_cos_phi)
    return basis, out


# --------------------------------------------------------------------------- model objects
def _ks_to_natural(z_to_nat):
    def to_natural(z, alpha):
        K = alpha.sum(axis=1)
        k_s = alpha[:, 1] / np.where(K > 0, K, 1.0)
        return np.column_stack([k_s, z_to_nat(z), K])

    return to_natural


def _ks_from_natural(nat_to_z):
    def from_natural(p):
        p = np.atleast_2d(np.asarray(p, float))
        z = nat_to_z(p[:, 1:-1])
        alpha = np.column_stack([p[:, -1] * (1.0 - p[:, 0]), p[:, -1] * p[:, 0]])
        return z, alpha

    return from_natural


_KS = Parameter("k_s", "1", 0.0, 1.0, "specular share of the reflected power (diffuse 1 - k_s)")
_K = Parameter("K", "power", 0.0, np.inf,
               "scale: incident flux x receiver solid angle x calibration (as Eq. 22)")


def _n_guess(gamma, theta, power):
    """Phong-type exponent of the measured specular peak (the core's estimate)."""
    return estimate_specular_index(gamma, theta, power)


def make_blinn_phong() -> ReflectionModel:
    """Blinn-Phong (ref. 19): see :func:`blinn_phong_power`."""
    lo, hi = np.log(0.1), np.log(4.0 * MAX_LOBE_INDEX)

    def starts(gamma, theta, power):
        n = 4.0 * _n_guess(gamma, theta, power)  # cos^4n(phi/2) ~ cos^n(phi) near the peak
        return np.log([[n], [n / 4.0], [n * 4.0], [30.0]])

    return ReflectionModel(
        name="blinn-phong",
        params=(_KS, Parameter("n", "1", 0.1, 4.0 * MAX_LOBE_INDEX, "exponent of the half-vector lobe"), _K),
        nonlinear_names=("ln_n",),
        z_lower=np.array([lo]),
        z_upper=np.array([hi]),
        n_linear=2,
        basis=_blinn_basis,
        to_natural=_ks_to_natural(lambda z: np.exp(z[:, 0])),
        from_natural=_ks_from_natural(lambda q: np.log(q[:, [0]])),
        starts=starts,
        alpha_nonneg=(True, True),
        hints=FitHints(residual_column=0),
        formula="K cos(theta) [(1-k_s)/pi + k_s (n+8)/8pi cos^n(theta_h)], theta_h=(gamma+theta)/2",
        reference="Blinn 1977 (the paper's ref. 19)",
        **_screen([np.log(1.0)], [np.log(4.0 * MAX_LOBE_INDEX)]),
    )


def make_ward() -> ReflectionModel:
    """Isotropic Ward: see :func:`ward_power`."""

    def starts(gamma, theta, power):
        a = 1.0 / np.sqrt(2.0 * _n_guess(gamma, theta, power))  # exp(-phi^2/4a^2) ~ cos^n(phi)
        return np.log([[a], [a / 2.0], [a * 2.0], [0.3]])

    return ReflectionModel(
        name="ward",
        params=(_KS, Parameter("alpha", "1", MIN_SLOPE, 2.0, "RMS surface slope (lobe width)"), _K),
        nonlinear_names=("ln_alpha",),
        z_lower=np.log([MIN_SLOPE]),
        z_upper=np.log([2.0]),
        n_linear=2,
        basis=_ward_basis,
        to_natural=_ks_to_natural(lambda z: np.exp(z[:, 0])),
        from_natural=_ks_from_natural(lambda q: np.log(q[:, [0]])),
        starts=starts,
        alpha_nonneg=(True, True),
        hints=FitHints(residual_column=0),
        formula="K cos(theta) [(1-k_s)/pi + k_s exp(-tan^2(theta_h)/alpha^2) / "
        "(4 pi alpha^2 sqrt(cos(gamma) cos(theta)))]",
        reference="Ward 1992 (Gaussian-lobe family, the paper's refs. 21, 26)",
        **_screen([np.log(MIN_SLOPE)], [np.log(1.0)]),
    )


def make_torrance_sparrow(distribution: str = "beckmann") -> ReflectionModel:
    """Torrance-Sparrow with Lambertian part: see :func:`torrance_sparrow_power`."""
    if distribution not in TS_DISTRIBUTIONS:
        raise unknown_name("facet distribution", str(distribution), TS_DISTRIBUTIONS)
    m_unit = "1" if distribution == "beckmann" else "rad"
    m_desc = ("RMS facet slope (Beckmann)" if distribution == "beckmann"
              else "width of the Gaussian facet-angle distribution")

    def starts(gamma, theta, power):
        m = 1.0 / np.sqrt(2.0 * _n_guess(gamma, theta, power))
        return np.array([[np.log(m), 1.5], [np.log(m / 2), 1.5], [np.log(2 * m), 1.5],
                         [np.log(m), 4.0], [np.log(0.3), 1.5]])

    name = "torrance-sparrow" if distribution == "beckmann" else f"torrance-sparrow-{distribution}"
    return ReflectionModel(
        name=name,
        params=(_KS, Parameter("m", m_unit, MIN_SLOPE, 2.0, m_desc),
                Parameter("eta", "1", 1.05, 10.0, "refractive index in the Fresnel factor"), _K),
        nonlinear_names=("ln_m", "eta"),
        z_lower=np.array([np.log(MIN_SLOPE), 1.05]),
        z_upper=np.array([np.log(2.0), 10.0]),
        n_linear=2,
        basis=_make_ts_basis(distribution),
        to_natural=_ks_to_natural(lambda z: np.column_stack([np.exp(z[:, 0]), z[:, 1]])),
        from_natural=_ks_from_natural(lambda q: np.column_stack([np.log(q[:, 0]), q[:, 1]])),
        starts=starts,
        alpha_nonneg=(True, True),
        formula=f"K cos(theta) [(1-k_s)/pi + k_s F(beta,eta)/F(0,eta) D_{distribution}"
        "(theta_h; m) G / (4 cos(gamma) cos(theta))]",
        reference="Torrance and Sparrow 1967 (ref. 26); Cook and Torrance 1981 (ref. 25)",
        hints=FitHints(residual_column=0),
        **_screen([np.log(MIN_SLOPE), 1.1], [np.log(1.0), 5.0]),
    )


def make_oren_nayar() -> ReflectionModel:
    """Oren-Nayar rough diffuse + Phong lobe: see :func:`oren_nayar_power`."""

    def starts(gamma, theta, power):
        n = _n_guess(gamma, theta, power)
        return np.array([[s, np.log(v)] for s in (0.05, 0.5) for v in (n, n * 4.0, 30.0)])

    return ReflectionModel(
        name="oren-nayar",
        params=(_KS, Parameter("sigma", "rad", 0.0, 1.5, "facet slope-angle standard deviation"),
                Parameter("n", "1", 0.1, MAX_LOBE_INDEX, "exponent of the Phong lobe about the mirror"),
                _K),
        nonlinear_names=("sigma", "ln_n"),
        z_lower=np.array([0.0, np.log(0.1)]),
        z_upper=np.array([1.5, np.log(MAX_LOBE_INDEX)]),
        n_linear=2,
        basis=_oren_nayar_basis,
        to_natural=_ks_to_natural(lambda z: np.column_stack([z[:, 0], np.exp(z[:, 1])])),
        from_natural=_ks_from_natural(lambda q: np.column_stack([q[:, 0], np.log(q[:, 1])])),
        starts=starts,
        alpha_nonneg=(True, True),
        hints=FitHints(residual_column=0),
        formula="K cos(theta) [(1-k_s)(A + B max(0,cos dphi) sin a tan b)/pi "
        "+ k_s (n+2)/2pi cos^n(phi)]",
        reference="Oren and Nayar 1994 (the paper's ref. 23) + Phong 1975 (ref. 18)",
        **_screen([0.0, np.log(1.0)], [1.0, np.log(MAX_LOBE_INDEX)]),
    )


#: Lafortune's bounds: C_x / C_z of a lobe, a lobe's exponent.
_LAFORTUNE_CX = (-1.3, 1.3)
_LAFORTUNE_N = (0.1, MAX_LOBE_INDEX)


def _lafortune_basis_fn(n_lobes, geom, z, derivatives=True):
    cos_t = geom.receiver_cos
    cols, dcols = [cos_t * INV_PI], []
    for i in range(n_lobes):
        c = _col(z, 2 * i)
        n = np.exp(_col(z, 2 * i + 1))
        s = c * geom.sin_sin + geom.cos_cos
        pos = s > 0
        with np.errstate(under="ignore", over="ignore", divide="ignore", invalid="ignore"):
            log_s = np.log(np.where(pos, s, 1.0))
            pw = np.exp(n * log_s) * pos * cos_t
            norm = (n + 2.0) / (2.0 * np.pi)
            lobe = norm * pw
            cols.append(lobe)
            if derivatives:
                d_c = np.where(pos, lobe * n / np.where(pos, s, 1.0), 0.0) * geom.sin_sin
                d_ln_n = n * (pw / (2.0 * np.pi) + lobe * log_s)
                dcols.append((d_c, d_ln_n))
    basis = np.stack(np.broadcast_arrays(*cols), axis=-1)
    if not derivatives:
        return basis, None
    dbasis = np.zeros(basis.shape + (2 * n_lobes,))
    for i, (d_c, d_n) in enumerate(dcols):
        dbasis[..., i + 1, 2 * i] = d_c
        dbasis[..., i + 1, 2 * i + 1] = d_n
    return basis, dbasis


def _lafortune_to_natural(n_lobes, z, alpha):
    return _lobes_to_natural(z, alpha, n_lobes, first=1)


def _lafortune_from_natural(n_lobes, p):
    p = np.atleast_2d(np.asarray(p, float))
    z = np.column_stack([p[:, 3 * i] if k == 0 else np.log(p[:, 3 * i + 1])
                         for i in range(n_lobes) for k in (0, 1)])
    K = p[:, -1]
    shares = np.column_stack([p[:, 3 * i + 2] for i in range(n_lobes)])
    alpha = np.column_stack([K * (1.0 - shares.sum(axis=1)), K[:, None] * shares])
    return z, alpha


def _lafortune_starts(n_lobes, gamma, theta, power):
    n = _n_guess(gamma, theta, power)
    # first lobe: the specular peak; further lobes broad and tilted toward the normal
    others = [(-0.5, 2.0), (0.0, 5.0), (0.5, 2.0)]
    out = []
    for first in ((-1.0, n), (-1.0, n / 4.0), (-0.8, n * 2.0)):
        for shift in range(2):
            row = [first[0], np.log(first[1])]
            for i in range(n_lobes - 1):
                c, v = others[(i + shift) % len(others)]
                row += [c, np.log(v)]
            out.append(row)
    # ... or narrow lobes aimed at the brightest receivers, one per lobe: s^n peaks
    # where tan(theta) = Cx tan(gamma), so Cx = tan(theta) / tan(gamma)
    (c_lo, c_hi), (n_lo, n_hi) = _LAFORTUNE_CX, _LAFORTUNE_N
    peaks = [float(np.clip(np.tan(tp) / np.tan(g), c_lo, c_hi))
             for g, tp in peak_directions(gamma, theta, power, k=6)
             if abs(np.tan(g)) > 1e-6]
    for width in (n, 1e3, 1e4, 1e5):
        ln_n = np.log(min(max(width, n_lo), n_hi))
        for first in range(len(peaks)):
            aimed = (peaks[first:] + peaks[:first])[:n_lobes]
            row = []
            for cx in aimed:
                row += [cx, ln_n]
            while len(row) < 2 * n_lobes:
                row += [0.0, np.log(5.0)]
            out.append(row)
    return np.array(out)


def make_lafortune(n_lobes: int = 2) -> ReflectionModel:
    """Lafortune with a Lambertian term and ``n_lobes`` cosine lobes: see
    :func:`lafortune_power`."""
    n_lobes = int(n_lobes)
    if not 1 <= n_lobes <= 4:
        raise IrreflectError(
            f"lafortune needs between 1 and 4 lobes, got {n_lobes}: use e.g. 'lafortune:2'"
        )
    (c_lo, c_hi), (n_lo, n_hi) = _LAFORTUNE_CX, _LAFORTUNE_N
    params = []
    for i in range(1, n_lobes + 1):
        params += [
            Parameter(f"cx_{i}", "1", c_lo, c_hi, f"C_x / C_z of lobe {i} (-1: mirror lobe)"),
            Parameter(f"n_{i}", "1", n_lo, n_hi, f"exponent of lobe {i}"),
            Parameter(f"a_{i}", "1", 0.0, 1.0, f"power share of lobe {i} (diffuse 1 - sum a_i)"),
        ]
    params.append(_K)

    return ReflectionModel(
        name="lafortune" if n_lobes == 2 else f"lafortune:{n_lobes}",
        params=tuple(params),
        nonlinear_names=tuple(f"{k}_{i}" for i in range(1, n_lobes + 1) for k in ("cx", "ln_n")),
        z_lower=np.tile([c_lo, np.log(n_lo)], n_lobes),
        z_upper=np.tile([c_hi, np.log(n_hi)], n_lobes),
        n_linear=n_lobes + 1,
        basis=functools.partial(_lafortune_basis_fn, n_lobes),
        to_natural=functools.partial(_lafortune_to_natural, n_lobes),
        from_natural=functools.partial(_lafortune_from_natural, n_lobes),
        starts=functools.partial(_lafortune_starts, n_lobes),
        alpha_nonneg=(True,) * (n_lobes + 1),
        formula="K cos(theta) [(1-sum a_i)/pi + sum_i a_i (n_i+2)/2pi "
        "(Cx_i sin(gamma) sin(theta) + cos(gamma) cos(theta))^n_i]",
        reference="Lafortune, Foo, Torrance and Greenberg 1997 (the paper's ref. 20)",
        hints=FitHints(n_data_starts=6, residual_column=0,
                       groups=tuple((2 * i, 2 * i + 1) for i in range(n_lobes))),
        **_screen(np.tile([-1.2, np.log(1.0)], n_lobes), np.tile([0.5, np.log(1.0e5)], n_lobes)),
    )


def make_torrance_sparrow_gaussian() -> ReflectionModel:
    """Torrance-Sparrow with the Gaussian slope-angle distribution of the 1967 paper."""
    return make_torrance_sparrow("gaussian")
