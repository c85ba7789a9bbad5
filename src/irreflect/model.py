"""Reflection models in the plane of incidence, as pure vectorised functions.

Angles follow the paper (Section 4.2): the angle of incidence ``gamma`` is negative on the
source side, the receiver angle ``theta`` is signed, the mirror (specular) direction is
``theta = -gamma`` and the angle from it is ``phi = -gamma - theta``. Every function here
takes **radians**; degrees live only at the edges (files, CLI, plots).

Each model is a :class:`ReflectionModel`: a parameter spec (names, units, physical bounds),
a pure ``predict`` and the *separable* form the fitter uses. Every model in irreflect is a
sum of basis functions weighted by linear coefficients::

    P(gamma, theta) = sum_l alpha_l * B_l(gamma, theta; z)

with nonlinear parameters ``z`` (lobe indices, exponents, orientations) and linear
coefficients ``alpha`` (power scales). The fitter eliminates ``alpha`` by linear least
squares for every ``z`` (variable projection, Golub and Pereyra 1973), which makes the
search over ``z`` both smaller and far less prone to local optima. A model declares how
``(z, alpha)`` maps to its natural parameters, so results are always reported in the
paper's terms.

The model registry (:data:`MODELS`, :func:`get_model`, :func:`register_model`) is the one
list of model names in irreflect.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .errors import IrreflectError, unknown_name

TWO_PI = 2.0 * np.pi


# --------------------------------------------------------------------------- building blocks
def generalized_lambertian(cos_angle, n):
    """Normalised generalised-Lambertian lobe ``(n + 1) / (2 pi) * cos^n(angle)`` (Eq. 2).

    Parameters
    ----------
    cos_angle : array-like
        Cosine of the angle from the lobe axis. Directions beyond 90 deg (cosine <= 0)
        receive nothing: the lobe is 0 there, never negative or NaN.
    n : array-like
        Lobe index (dimensionless, >= 0). ``n = 1`` is Lambertian.

    Returns
    -------
    lobe : ndarray
        Lobe value in 1/sr per unit emitted power. NaN in gives NaN out.
    """
    lobe, _ = _lobe_and_derivative(np.asarray(cos_angle, float), np.asarray(n, float))
    return lobe


def _lobe_and_derivative(cos_angle, n):
    """Lobe ``(n+1)/(2 pi) cos^n`` and its derivative with respect to ``n``."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore", under="ignore"):
        positive = cos_angle > 0
        log_cos = np.log(np.where(positive, cos_angle, 1.0))
        power = np.exp(n * log_cos) * positive
        if np.isnan(cos_angle).any():  # keep NaN inputs as NaN outputs
            power = np.where(np.isnan(cos_angle), np.nan, power)
        lobe = (n + 1.0) * (1.0 / TWO_PI) * power
        d_lobe_dn = power * (1.0 / TWO_PI) + lobe * log_cos
    return lobe, d_lobe_dn


def mirror_angle(gamma, theta):
    """Angle phi between the receiver direction and the mirror direction: ``-gamma - theta``."""
    return -np.asarray(gamma, float) - np.asarray(theta, float)


def plane_geometry(gamma, theta) -> dict:
    """Quantities of the measurement geometry that every basis evaluation reuses.

    gamma, theta : arrays of shape ``(Bg, n)``, radians. Computed once per fit (the
    geometry does not change while the parameters do), which keeps trigonometry out of
    the fitter's inner loop. Returns a dict of ``(Bg, n)`` arrays.
    """
    gamma = _as2d(gamma)
    theta = _as2d(theta)
    cos_theta = np.cos(theta)
    cos_phi = np.cos(-gamma - theta)
    pos_theta = cos_theta > 0
    pos_phi = cos_phi > 0
    return {
        "gamma": gamma,
        "theta": theta,
        "phi": -gamma - theta,
        "log_cos_gamma": np.log(np.cos(gamma)),
        "cos_theta": cos_theta,
        "cos_phi": cos_phi,
        "pos_theta": pos_theta,
        "pos_phi": pos_phi,
        "log_cos_theta": np.log(np.where(pos_theta, cos_theta, 1.0)),
        "log_cos_phi": np.log(np.where(pos_phi, cos_phi, 1.0)),
    }


def take_geometry(geom: dict, idx) -> dict:
    """Rows ``idx`` of every array of a geometry (for batches with per-problem geometry)."""
    return {k: v[idx] for k, v in geom.items()}


def _lobe_from_log(log_cos, positive, n, derivative=True):
    """Lobe ``(n+1)/(2 pi) cos^n`` and ``d lobe / d n`` (None unless ``derivative``) from a
    precomputed ``log cos``."""
    # callers run under np.errstate(under="ignore"): cos^n underflows to 0 for sharp lobes
    power = np.exp(n * log_cos) * positive
    lobe = (n + 1.0) * (1.0 / TWO_PI) * power
    if not derivative:
        return lobe, None
    return lobe, power * (1.0 / TWO_PI) + lobe * log_cos


# --------------------------------------------------------------------------- the paper's models
def two_lobe_power(gamma, theta, u_as, v_as, u_nd, v_nd, u_ns, v_ns, K):
    """Received power of the paper's two-component model (Eqs. 19-22).

    ``P = K [p_d(gamma, theta) + p_s(gamma, phi)]`` with ``phi = -gamma - theta`` and

    * specular share ``a_s = u_as cos^v_as(gamma)`` (Eq. 15), diffuse share ``1 - a_s`` (Eq. 16);
    * diffuse index ``n_d = u_nd cos^v_nd(gamma)`` (Eq. 17), lobe about the surface normal (Eq. 20);
    * specular index ``n_s = u_ns cos^v_ns(gamma)`` (Eq. 18), lobe about the mirror direction (Eq. 21).

    Parameters
    ----------
    gamma : array-like, radians
        Angle of incidence (negative on the source side).
    theta : array-like, radians
        Receiver angle, signed; the mirror direction is ``theta = -gamma``.
    u_as, v_as, u_nd, v_nd, u_ns, v_ns : float
        The six shape coefficients (dimensionless).
    K : float
        Grouped constant factor (Eq. 22), in the units of the measured power.

    Returns
    -------
    power : ndarray
        Same units as ``K``. NaN in gives NaN out.
    """
    gamma = np.asarray(gamma, float)
    theta = np.asarray(theta, float)
    cos_gamma = np.cos(gamma)
    a_s = u_as * cos_gamma**v_as
    n_d = u_nd * cos_gamma**v_nd
    n_s = u_ns * cos_gamma**v_ns
    p_d = (1.0 - a_s) * generalized_lambertian(np.cos(theta), n_d)
    p_s = a_s * generalized_lambertian(np.cos(mirror_angle(gamma, theta)), n_s)
    return K * (p_d + p_s)


def single_lobe_power(gamma, theta, n, K):
    """First approximation (Eq. 6): one lobe about the mirror direction.

    ``P = K (n + 1) / (2 pi) cos^n(phi)``, ``phi = -gamma - theta``; ``K`` groups
    ``A_RX P_x beta / d_RX^2`` as in Eq. 22.

    gamma, theta : array-like, radians. n : lobe index (dimensionless). K : power units.
    """
    return K * generalized_lambertian(np.cos(mirror_angle(gamma, theta)), n)


def n_lobe_power(gamma, theta, orientations, indices, shares, K):
    """Second approximation (Eq. 7): N lobes, each with its own axis, index and power share.

    Lobe ``i`` points at ``theta = -t_i * gamma``: ``t_i = 0`` is the surface normal,
    ``t_i = 1`` the mirror direction, ``t_i = -1`` back to the source. Shares ``a_i`` sum
    to 1 (Eq. 8); the caller's shares are used as given.

    gamma, theta : array-like, radians. orientations : t_i (dimensionless). indices : n_i.
    shares : a_i. K : power units.
    """
    gamma = np.asarray(gamma, float)
    theta = np.asarray(theta, float)
    total = np.zeros(np.broadcast(gamma, theta).shape)
    for t_i, n_i, a_i in zip(orientations, indices, shares, strict=True):
        total = total + a_i * generalized_lambertian(np.cos(theta + t_i * gamma), n_i)
    return K * total


def phong_power(gamma, theta, k_s, n, K):
    """Phong model with constant coefficients (the paper's comparison, ref. 18).

    ``P = K (k_d cos(theta) + k_s cos^n(phi))`` with ``k_d = 1 - k_s`` (the overall scale
    lives in ``K``; leaving both ``k_d`` and ``k_s`` free with ``K`` would make the three
    degenerate). Directions beyond 90 deg contribute zero.

    gamma, theta : array-like, radians. k_s : specular share. n : specular exponent. K : power units.
    """
    gamma = np.asarray(gamma, float)
    theta = np.asarray(theta, float)
    cos_theta = np.clip(np.cos(theta), 0.0, None)
    cos_phi = np.cos(mirror_angle(gamma, theta))
    with np.errstate(divide="ignore", invalid="ignore"):
        spec = np.where(cos_phi > 0, np.abs(cos_phi) ** n, 0.0)
    return K * ((1.0 - k_s) * cos_theta + k_s * spec)


# --------------------------------------------------------------------------- the model object
@dataclass(frozen=True)
class Parameter:
    """One natural parameter of a model: name, unit, physical bounds and meaning."""

    name: str
    unit: str
    lower: float
    upper: float
    description: str


BasisFn = Callable[[np.ndarray, np.ndarray, np.ndarray, bool], tuple]


@dataclass(frozen=True)
class ReflectionModel:
    """A reflection model in separable form, with its parameter spec.

    Attributes
    ----------
    name : str
        Registry name.
    params : tuple of Parameter
        Natural parameters, in reporting order.
    nonlinear_names : tuple of str
        Names of the internal nonlinear coordinates ``z`` (e.g. ``ln_u_ns``).
    z_lower, z_upper : ndarray
        Box bounds on ``z``.
    n_linear : int
        Number of linear coefficients ``alpha``.
    basis : callable
        ``basis(geom, z, derivatives)`` with ``geom = plane_geometry(gamma, theta)`` of
        arrays of shape ``(Bg, n)`` (``Bg`` 1 or ``B``; radians) and ``z`` of shape
        ``(B, P)``; returns the basis
        ``(B, n, L)`` and, if asked, its derivative with respect to ``z``, ``(B, n, L, P)``.
    to_natural : callable
        ``(z (B, P), alpha (B, L)) -> params (B, k)``.
    from_natural : callable
        ``params (B, k) -> (z (B, P), alpha (B, L))``.
    starts : callable
        ``starts(gamma, theta, power) -> z (S, P)``: data-driven initial guesses.
    alpha_nonneg : tuple of bool
        Which linear coefficients must be >= 0 (power scales).
    formula : str
        One-line formula, for reports.
    """

    name: str
    params: tuple[Parameter, ...]
    nonlinear_names: tuple[str, ...]
    z_lower: np.ndarray
    z_upper: np.ndarray
    n_linear: int
    basis: BasisFn
    to_natural: Callable
    from_natural: Callable
    starts: Callable
    alpha_nonneg: tuple[bool, ...]
    formula: str = ""
    reference: str = ""
    options: dict = field(default_factory=dict)
    #: ``options`` the fitter reads: ``residual_column`` (the linear coefficient that is
    #: ``K (1 - shares)`` in natural terms), ``batch_starts``, ``validity``, ``groups``,
    #: ``n_screen``, ``n_keep``, ``n_data_starts`` (see :mod:`irreflect.fitting`).
    #: Box of plausible ``z`` sampled by the fitter's global screening (default: the
    #: bounds, clipped to [-15, 15] on each coordinate).
    screen_lower: np.ndarray | None = None
    screen_upper: np.ndarray | None = None

    def screen_box(self) -> tuple[np.ndarray, np.ndarray]:
        lo = self.screen_lower if self.screen_lower is not None else np.maximum(self.z_lower, -15.0)
        hi = self.screen_upper if self.screen_upper is not None else np.minimum(self.z_upper, 15.0)
        return np.asarray(lo, float), np.asarray(hi, float)

    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)

    @property
    def n_params(self) -> int:
        """Number of free parameters (nonlinear + linear)."""
        return len(self.nonlinear_names) + self.n_linear

    @property
    def n_nonlinear(self) -> int:
        return len(self.nonlinear_names)

    def predict(self, params, gamma, theta) -> np.ndarray:
        """Power at (gamma, theta) in radians for natural ``params``.

        ``params`` of shape ``(k,)`` gives the shape of ``gamma``/``theta``; ``(B, k)``
        gives ``(B, n)`` for 1-D angle arrays of length ``n``.
        """
        params = np.asarray(params, float)
        single = params.ndim == 1
        gamma = np.asarray(gamma, float)
        theta = np.asarray(theta, float)
        shape = np.broadcast(gamma, theta).shape
        g = np.broadcast_to(gamma, shape).reshape(1, -1)
        t = np.broadcast_to(theta, shape).reshape(1, -1)
        z, alpha = self.from_natural(np.atleast_2d(params))
        basis, _ = self.basis(plane_geometry(g, t), z, False)
        out = np.einsum("bnl,bl->bn", basis, alpha)
        return out[0].reshape(shape) if single else out

    def predict_deg(self, params, gamma_deg, theta_deg) -> np.ndarray:
        """Same as :meth:`predict` with angles in degrees."""
        return self.predict(params, np.radians(gamma_deg), np.radians(theta_deg))

    def describe(self) -> str:
        rows = [f"{self.name}: {self.formula}"]
        rows += [f"  {p.name:<8} [{p.unit}] {p.description}" for p in self.params]
        return "\n".join(rows)


def _col(z, k):
    """Column ``k`` of ``z`` shaped to broadcast against ``(B, n)`` arrays."""
    return z[:, k][:, None]


def _as2d(a):
    a = np.asarray(a, float)
    return a.reshape(1, -1) if a.ndim == 1 else a


# --------------------------------------------------------------------------- data-driven guesses
#: The narrowest lobe irreflect fits: index 10^6 is a half width at half maximum of
#: 0.07 deg, below any goniometer's angular resolution ("the mirror limit"). Gloss paint
#: and glass reach 10^4-10^5.
MAX_LOBE_INDEX = 1.0e6
#: Index grids of the per-angle decomposition (:func:`lobe_profile`).
PROFILE_DIFFUSE_INDICES = np.geomspace(0.05, 100.0, 10)
PROFILE_SPECULAR_INDICES = np.geomspace(0.5, MAX_LOBE_INDEX, 25)


@dataclass(frozen=True)
class LobeProfile:
    """What the data say at every angle of incidence, with nothing tied across angles.

    For each measured angle of incidence the curve is fitted by a diffuse lobe about the
    normal plus a specular lobe about the mirror direction, ``A (n_d+1)/2pi cos^n_d(theta)
    + B (n_s+1)/2pi cos^n_s(phi)``, globally over a grid of indices (``A, B >= 0`` solved
    exactly at every grid node). Arrays are ``(batch, n_gamma)``.

    Attributes
    ----------
    gamma : ndarray (G,)
        Distinct angles of incidence, radians.
    diffuse_index, specular_index : ndarray (B, G)
        Best ``n_d`` and ``n_s`` on the grids.
    diffuse, specular : ndarray (B, G)
        ``A = K (1 - a_s)`` and ``B = K a_s`` in power units.
    ok : ndarray (B, G) of bool
        The angle has at least 3 points with weight (else the other arrays are NaN).
    """

    gamma: np.ndarray
    diffuse_index: np.ndarray
    specular_index: np.ndarray
    diffuse: np.ndarray
    specular: np.ndarray
    ok: np.ndarray

    @property
    def specular_share(self) -> np.ndarray:
        total = self.diffuse + self.specular
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(total > 0, self.specular / total, np.nan)


def lobe_profile(gamma, theta, power, weights=None) -> LobeProfile:
    """Per-angle-of-incidence diffuse + specular decomposition (see :class:`LobeProfile`).

    gamma, theta : array-like (n,), radians. power : array-like (n,). weights : None, (n,)
    or (B, n) non-negative weights (zero drops a point: one row per subset of the table).
    The scale of ``power`` does not matter (the linear step absorbs it). Cost: a few
    matrix products per angle of incidence, so it runs on every fit.
    """
    gamma = np.asarray(gamma, float).ravel()
    theta = np.asarray(theta, float).ravel()
    power = np.asarray(power, float).ravel()
    w = np.ones((1, power.size)) if weights is None else np.atleast_2d(np.asarray(weights, float))
    b = w.shape[0]
    levels, group = np.unique(np.round(gamma, 9), return_inverse=True)
    nd, ns = PROFILE_DIFFUSE_INDICES, PROFILE_SPECULAR_INDICES
    with np.errstate(divide="ignore", invalid="ignore", under="ignore", over="ignore"):
        cos_t, cos_p = np.cos(theta), np.cos(-gamma - theta)
        pos_t, pos_p = cos_t > 0, cos_p > 0
        log_t = np.log(np.where(pos_t, cos_t, 1.0))
        log_p = np.log(np.where(pos_p, cos_p, 1.0))
        lobe_d = (nd[:, None] + 1) / TWO_PI * np.exp(nd[:, None] * log_t) * pos_t  # (D, n)
        lobe_s = (ns[:, None] + 1) / TWO_PI * np.exp(ns[:, None] * log_p) * pos_p  # (S, n)
    shape = (b, levels.size)
    out = {k: np.full(shape, np.nan) for k in ("nd", "ns", "a", "s")}
    ok = np.zeros(shape, bool)
    for g in range(levels.size):
        idx = np.flatnonzero(group == g)
        wg = w[:, idx]
        has = (wg > 0).sum(axis=1) >= 3
        if not has.any():
            continue
        ld, ls, y = lobe_d[:, idx], lobe_s[:, idx], power[idx]
        wy = wg * y
        gdd = wg @ (ld * ld).T  # (B, D)
        gss = wg @ (ls * ls).T  # (B, S)
        gds = ((wg[:, None, :] * ld[None]) @ ls.T)  # (B, D, S)
        rd, rs = wy @ ld.T, wy @ ls.T
        yy = (wy * y).sum(axis=1)
        cost, cd, cs = _two_column_nnls(gdd[:, :, None], gss[:, None, :], gds,
                                        rd[:, :, None], rs[:, None, :], yy[:, None, None])
        flat = np.argmin(cost.reshape(b, -1), axis=1)
        i, k = np.unravel_index(flat, cost.shape[1:])
        rows = np.arange(b)
        ok[:, g] = has
        out["nd"][:, g] = np.where(has, nd[i], np.nan)
        out["ns"][:, g] = np.where(has, ns[k], np.nan)
        out["a"][:, g] = np.where(has, cd[rows, i, k], np.nan)
        out["s"][:, g] = np.where(has, cs[rows, i, k], np.nan)
    return LobeProfile(gamma=levels, diffuse_index=out["nd"], specular_index=out["ns"],
                       diffuse=out["a"], specular=out["s"], ok=ok)


def _two_column_nnls(gdd, gss, gds, rd, rs, yy):
    """Least squares with two non-negative columns from their Gram entries (broadcast).

    Returns cost (up to the constant ``yy``), and the two coefficients. The constrained
    optimum is the unconstrained one if feasible, else the better one-column fit."""
    with np.errstate(divide="ignore", invalid="ignore"):
        det = gdd * gss - gds * gds
        good = det > 1e-12 * gdd * gss
        cd = np.where(good, (gss * rd - gds * rs) / det, -1.0)
        cs = np.where(good, (gdd * rs - gds * rd) / det, -1.0)
        both = (cd >= 0) & (cs >= 0)
        cost_both = np.where(both, yy - cd * rd - cs * rs, np.inf)
        d_only = np.where(gdd > 0, np.maximum(rd, 0) / gdd, 0.0)
        s_only = np.where(gss > 0, np.maximum(rs, 0) / gss, 0.0)
        cost_d = yy - d_only * rd
        cost_s = yy - s_only * rs
    best_single_d = cost_d <= cost_s
    cost_single = np.where(best_single_d, cost_d, cost_s)
    use_both = cost_both < cost_single
    cost = np.where(use_both, cost_both, cost_single)
    coef_d = np.where(use_both, cd, np.where(best_single_d, d_only, 0.0))
    coef_s = np.where(use_both, cs, np.where(best_single_d, 0.0, s_only))
    cost = np.where(np.isfinite(cost), cost, np.inf)
    return cost, np.broadcast_to(coef_d, cost.shape), np.broadcast_to(coef_s, cost.shape)


def _trend(x, y, valid):
    """Weighted straight line ``y = a + b x`` per row over the valid entries: (a, b).

    x : (G,); y, valid : (B, G). Rows with fewer than two distinct x give slope 0 and the
    mean; rows with no valid entry give NaN."""
    v = valid.astype(float)
    count = v.sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        yv = np.where(valid, y, 0.0)
        xm = (v * x).sum(axis=1) / count
        ym = yv.sum(axis=1) / count
        dx = np.where(valid, x[None, :] - xm[:, None], 0.0)
        sxx = (dx * dx).sum(axis=1)
        slope = np.where(sxx > 1e-12, (dx * (yv - ym[:, None])).sum(axis=1) / sxx, 0.0)
    return ym - slope * xm, slope


def estimate_specular_index(gamma, theta, power) -> float:
    """Data-driven guess of the specular lobe index: the median over angles of incidence
    of the per-angle optimum of :func:`lobe_profile` where a specular lobe is found
    (``B > 0``); 20 when none is.

    gamma, theta : array-like, radians. power : array-like.
    """
    return _median_specular_index(lobe_profile(gamma, theta, power))


def _median_specular_index(prof: LobeProfile) -> float:
    found = prof.ok[0] & (prof.specular[0] > 0)
    if not found.any():
        return 20.0
    return float(np.median(prof.specular_index[0][found]))


def peak_directions(gamma, theta, power, k: int = 4) -> list[tuple[float, float]]:
    """``(gamma, theta)`` in radians of the brightest point of each angle of incidence,
    for the ``k`` angles with the highest peaks: where a narrow lobe must point (lobes
    whose axis is free, as in Eq. 7, aim at a measured receiver, not at the mirror)."""
    gamma = np.asarray(gamma, float).ravel()
    theta = np.asarray(theta, float).ravel()
    power = np.asarray(power, float).ravel()
    out = []
    for g in np.unique(np.round(gamma, 9)):
        idx = np.flatnonzero(np.abs(gamma - g) < 1e-9)
        j = idx[np.argmax(power[idx])]
        out.append((power[j], float(gamma[j]), float(theta[j])))
    out.sort(key=lambda r: -r[0])
    return [(g, t) for _, g, t in out[:k]]


def two_lobe_profile_starts(profile: LobeProfile) -> np.ndarray:
    """Two-lobe starts ``z (B, S, 5)`` from a :class:`LobeProfile`: the straight lines
    ``ln n(gamma) = ln u + v ln cos(gamma)`` through the per-angle indices and specular
    shares (Eqs. 15, 17, 18), the same with constant indices (v = 0), and the specular
    index a factor 4 either side. Rows without any usable angle get the neutral start."""
    x = np.log(np.cos(profile.gamma))
    ok = profile.ok
    spec = ok & (profile.specular > 0)
    share = profile.specular_share
    with np.errstate(divide="ignore", invalid="ignore"):
        ln_nd, ln_ns, ln_as = (np.log(profile.diffuse_index), np.log(profile.specular_index),
                               np.log(share))
    a_nd, b_nd = _trend(x, ln_nd, ok)
    a_ns, b_ns = _trend(x, ln_ns, spec)
    _, b_as = _trend(x, ln_as, spec & (share > 0))
    const_nd, _ = _trend(np.zeros_like(x), ln_nd, ok)
    const_ns, _ = _trend(np.zeros_like(x), ln_ns, spec)
    fallback = np.array([0.0, 0.0, 0.3, np.log(30.0), 0.0])

    def row(*cols):
        z = np.column_stack(cols)
        return np.where(np.isfinite(z), z, fallback)

    zeros = np.zeros_like(a_nd)
    starts = [
        row(b_as, a_nd, b_nd, a_ns, b_ns),
        row(zeros, const_nd, zeros, const_ns, zeros),
        row(b_as, a_nd, b_nd, a_ns + np.log(4.0), b_ns),
        row(b_as, a_nd, b_nd, a_ns - np.log(4.0), b_ns),
        row(b_as, a_nd, b_nd, const_ns, zeros),
    ]
    return np.stack(starts, axis=1)


# --------------------------------------------------------------------------- two-lobe
_TWO_LOBE_PARAMS = (
    Parameter("u_as", "1", 0.0, 1.0, "specular share at normal incidence (Eq. 15)"),
    Parameter("v_as", "1", -12.0, 12.0, "exponent of cos(gamma) in the specular share (Eq. 15)"),
    Parameter("u_nd", "1", 0.05, 100.0, "diffuse lobe index at normal incidence (Eq. 17)"),
    Parameter("v_nd", "1", -12.0, 12.0, "exponent of cos(gamma) in the diffuse index (Eq. 17)"),
    Parameter("u_ns", "1", 0.5, MAX_LOBE_INDEX, "specular lobe index at normal incidence (Eq. 18)"),
    Parameter("v_ns", "1", -12.0, 12.0, "exponent of cos(gamma) in the specular index (Eq. 18)"),
    Parameter("K", "power", 0.0, np.inf, "grouped constant factor A_eff P_x beta / d_RX^2 (Eq. 22)"),
)


def _two_lobe_basis(geom, z, derivatives=True):
    """Separable two-lobe model with *physical* linear coefficients.

    ``P = K [(1 - a_s) L_d + a_s L_s]`` with ``a_s = u_as s``, ``s = cos^v_as(gamma)`` is
    written ``P = c_1 B_1 + c_2 B_2`` with ``B_1 = L_d``, ``B_2 = (1 - s) L_d + s L_s``,
    ``c_1 = K (1 - u_as)`` and ``c_2 = K u_as``. Non-negative ``c`` is then exactly the
    declared box ``K >= 0, 0 <= u_as <= 1``: every solution of the linear step maps back
    to the paper's coefficients (with ``c = (K, K u_as)`` a solution with ``K = 0`` and
    ``K u_as > 0`` could not, and was reported as a zero model).
    """
    log_cg = geom["log_cos_gamma"]
    v_as, ln_u_nd, v_nd, ln_u_ns, v_ns = z.T[:, :, None]
    s = np.exp(v_as * log_cg)
    n_d = np.exp(ln_u_nd + v_nd * log_cg)
    n_s = np.exp(ln_u_ns + v_ns * log_cg)
    lobe_d, dlobe_d = _lobe_from_log(geom["log_cos_theta"], geom["pos_theta"], n_d, derivatives)
    lobe_s, dlobe_s = _lobe_from_log(geom["log_cos_phi"], geom["pos_phi"], n_s, derivatives)
    diff = lobe_s - lobe_d
    shape = np.broadcast_shapes(lobe_d.shape, diff.shape, s.shape)
    basis = np.empty(shape + (2,))
    basis[..., 0] = lobe_d
    basis[..., 1] = lobe_d + s * diff
    if not derivatives:
        return basis, None
    dd = dlobe_d * n_d  # d L_d / d ln_u_nd
    ds = dlobe_s * n_s  # d L_s / d ln_u_ns
    one_minus_s = 1.0 - s
    dbasis = np.zeros(shape + (2, 5))
    dbasis[..., 0, 1] = dd
    dbasis[..., 0, 2] = dd * log_cg
    dbasis[..., 1, 0] = s * diff * log_cg
    d2 = one_minus_s * dd
    dbasis[..., 1, 1] = d2
    dbasis[..., 1, 2] = d2 * log_cg
    s2 = s * ds
    dbasis[..., 1, 3] = s2
    dbasis[..., 1, 4] = s2 * log_cg
    return basis, dbasis


def _two_lobe_to_natural(z, alpha):
    K = alpha[:, 0] + alpha[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        u_as = np.where(K > 0, alpha[:, 1] / np.where(K > 0, K, 1.0), 0.0)
    return np.column_stack([u_as, z[:, 0], np.exp(z[:, 1]), z[:, 2], np.exp(z[:, 3]), z[:, 4], K])


def _two_lobe_from_natural(p):
    p = np.atleast_2d(np.asarray(p, float))
    z = np.column_stack([p[:, 1], np.log(p[:, 2]), p[:, 3], np.log(p[:, 4]), p[:, 5]])
    alpha = np.column_stack([p[:, 6] * (1.0 - p[:, 0]), p[:, 6] * p[:, 0]])
    return z, alpha


def _two_lobe_starts(gamma, theta, power):
    """Starts from the per-angle decomposition (:func:`two_lobe_profile_starts`) and, as
    a fallback for tables without three points per angle, fixed shapes around the median
    specular index."""
    prof = lobe_profile(gamma, theta, power)
    n_est = _median_specular_index(prof)
    fixed = [[v_as, 0.0, 0.3, ln_ns, 0.0]
             for ln_ns in (np.log(n_est), np.log(30.0)) for v_as in (-2.5, 0.5)]
    return np.vstack([two_lobe_profile_starts(prof)[0], fixed])


def _two_lobe_batch_starts(gamma, theta, power, weights):
    """Starts of many subsets at once (one row of ``weights`` (B, n) per subset): the
    profile starts of each subset's own points, ``(B, 5, 5)``."""
    return two_lobe_profile_starts(lobe_profile(gamma, theta, power, weights))


def _two_lobe_validity(values, gamma) -> list[str]:
    """The specular share ``a_s = u_as cos^v_as(gamma)`` must stay within [0, 1] at the
    measured angles of incidence (else the diffuse lobe carries negative power)."""
    u_as, v_as = values[0], values[1]
    g = np.unique(np.abs(np.asarray(gamma, float)))
    with np.errstate(over="ignore", divide="ignore"):
        share = u_as * np.cos(g) ** v_as
    bad = share > 1.0 + 1e-9
    if not bad.any():
        return []
    worst = int(np.argmax(share))
    return [f"the specular share a_s = u_as cos^v_as(gamma) exceeds 1 at "
            f"{int(bad.sum())} angle(s) of incidence (a_s = {share[worst]:.3g} at gamma = "
            f"{np.degrees(g[worst]):.3g} deg): the diffuse lobe carries negative power there"]


def make_two_lobe() -> ReflectionModel:
    lo = np.array([-12.0, np.log(0.05), -12.0, np.log(0.5), -12.0])
    hi = np.array([12.0, np.log(100.0), 12.0, np.log(MAX_LOBE_INDEX), 12.0])
    return ReflectionModel(
        name="two-lobe",
        params=_TWO_LOBE_PARAMS,
        nonlinear_names=("v_as", "ln_u_nd", "v_nd", "ln_u_ns", "v_ns"),
        z_lower=lo,
        z_upper=hi,
        n_linear=2,
        basis=_two_lobe_basis,
        to_natural=_two_lobe_to_natural,
        from_natural=_two_lobe_from_natural,
        starts=_two_lobe_starts,
        alpha_nonneg=(True, True),
        formula="K [(1-a_s) (n_d+1)/2pi cos^n_d(theta) + a_s (n_s+1)/2pi cos^n_s(phi)], "
        "z = u_z cos^v_z(gamma)",
        reference="the paper, Eqs. 19-22",
        # its data-driven starts carry the search on glossy tables: a lighter screening,
        # no basin hops and one-coordinate scans suffice (300 of 300 generated materials,
        # tests/test_global_fit.py; the same with 64 candidates: 96 keeps a margin)
        options={"validity": _two_lobe_validity, "batch_starts": _two_lobe_batch_starts,
                 "residual_column": 0, "canonical_starts": _two_lobe_starts,
                 "n_screen": 96, "n_keep": 3, "n_hops": 0},
        screen_lower=np.array([-6.0, np.log(0.3), -3.0, np.log(1.0), -3.0]),
        screen_upper=np.array([2.0, np.log(20.0), 6.0, np.log(1.0e5), 3.0]),
    )


# --------------------------------------------------------------------------- single-lobe
def _single_lobe_basis(geom, z, derivatives=True):
    n = np.exp(_col(z, 0))
    lobe, dlobe = _lobe_from_log(geom["log_cos_phi"], geom["pos_phi"], n)
    basis = lobe[..., None]
    if not derivatives:
        return basis, None
    return basis, (dlobe * n)[..., None, None]


def make_single_lobe() -> ReflectionModel:
    return ReflectionModel(
        name="single-lobe",
        params=(
            Parameter("n", "1", 0.05, MAX_LOBE_INDEX, "lobe index about the mirror direction (Eq. 6)"),
            Parameter("K", "power", 0.0, np.inf, "grouped factor A_RX P_x beta / d_RX^2 (Eq. 6)"),
        ),
        nonlinear_names=("ln_n",),
        z_lower=np.array([np.log(0.05)]),
        z_upper=np.array([np.log(MAX_LOBE_INDEX)]),
        n_linear=1,
        basis=_single_lobe_basis,
        to_natural=lambda z, a: np.column_stack([np.exp(z[:, 0]), a[:, 0]]),
        from_natural=lambda p: (
            np.log(np.atleast_2d(p)[:, [0]]),
            np.atleast_2d(p)[:, [1]].astype(float),
        ),
        starts=lambda g, t, p: np.log([[1.0], [5.0], [30.0], [estimate_specular_index(g, t, p)]]),
        alpha_nonneg=(True,),
        formula="K (n+1)/2pi cos^n(phi)",
        reference="the paper, Eq. 6",
    )


# --------------------------------------------------------------------------- n-lobe
def make_n_lobe(n_lobes: int = 3) -> ReflectionModel:
    """Eq. 7 with ``n_lobes`` lobes; lobe ``i`` points at ``theta = -t_i gamma``."""
    n_lobes = int(n_lobes)
    if not 1 <= n_lobes <= 6:
        raise IrreflectError(
            f"n-lobe needs between 1 and 6 lobes, got {n_lobes}: use e.g. 'n-lobe:3'"
        )
    params = []
    for i in range(1, n_lobes + 1):
        params += [
            Parameter(f"t_{i}", "1", -1.5, 1.5, f"axis of lobe {i} as a fraction of the mirror angle"),
            Parameter(f"n_{i}", "1", 0.05, MAX_LOBE_INDEX, f"index of lobe {i}"),
            Parameter(f"a_{i}", "1", 0.0, 1.0, f"power share of lobe {i} (shares sum to 1, Eq. 8)"),
        ]
    params.append(Parameter("K", "power", 0.0, np.inf, "grouped constant factor (Eq. 7)"))

    def basis_fn(geom, z, derivatives=True):
        gamma, theta = geom["gamma"], geom["theta"]
        cols, dcols = [], []
        for i in range(n_lobes):
            t_i = _col(z, 2 * i)
            n_i = np.exp(_col(z, 2 * i + 1))
            angle = theta + t_i * gamma
            cos_a = np.cos(angle)
            lobe, dlobe = _lobe_and_derivative(cos_a, n_i)
            cols.append(lobe)
            if derivatives:
                with np.errstate(divide="ignore", invalid="ignore"):
                    # d/dt of (n+1)/2pi cos^n(theta + t gamma) = -lobe n tan(angle) gamma
                    dt = np.where(cos_a > 1e-12, -lobe * n_i * np.tan(angle) * gamma, 0.0)
                dcols.append((dt, dlobe * n_i))
        basis = np.stack(np.broadcast_arrays(*cols), axis=-1)
        if not derivatives:
            return basis, None
        shape = basis.shape[:-1]
        dbasis = np.zeros(shape + (n_lobes, 2 * n_lobes))
        for i, (dt, dn) in enumerate(dcols):
            dbasis[..., i, 2 * i] = dt
            dbasis[..., i, 2 * i + 1] = dn
        return basis, dbasis

    def to_natural(z, alpha):
        K = alpha.sum(axis=1)
        safe = np.where(K > 0, K, 1.0)
        out = []
        for i in range(n_lobes):
            out += [z[:, 2 * i], np.exp(z[:, 2 * i + 1]), alpha[:, i] / safe]
        return np.column_stack(out + [K])

    def from_natural(p):
        p = np.atleast_2d(np.asarray(p, float))
        z = np.column_stack(
            [p[:, 3 * i + k] if k == 0 else np.log(p[:, 3 * i + 1]) for i in range(n_lobes) for k in (0, 1)]
        )
        K = p[:, -1]
        alpha = np.column_stack([K * p[:, 3 * i + 2] for i in range(n_lobes)])
        return z, alpha

    def starts(gamma, theta, power):
        n_est = estimate_specular_index(gamma, theta, power)
        axes = [0.0, 1.0, -1.0, 0.5, 1.2, -0.5][:n_lobes]
        out = []
        for scale in (1.0, 0.25, 4.0):
            row = []
            for i, t in enumerate(axes):
                n = 1.0 if t == 0.0 else n_est * scale / (1 + i)
                row += [t, np.log(max(n, 0.1))]
            out.append(row)
        # narrow lobes aimed at the brightest receivers (axis theta = -t gamma through the
        # receiver: a goniometer's receivers seldom sit exactly on the mirror), one per lobe
        # but the last, which stays broad about the normal
        peaks = [float(np.clip(-tp / g, -1.5, 1.5))
                 for g, tp in peak_directions(gamma, theta, power, k=6) if abs(g) > 1e-6]
        for n in (n_est, 1e3, 1e4, 1e5):
            ln_n = np.log(min(max(n, 1.0), MAX_LOBE_INDEX))
            for first in range(len(peaks)):
                aimed = (peaks[first:] + peaks[:first])[: max(n_lobes - 1, 1)]
                row = []
                for axis in aimed:
                    row += [axis, ln_n]
                while len(row) < 2 * n_lobes:
                    row += [0.0, np.log(2.0)]
                out.append(row[: 2 * n_lobes])
        return np.array(out)

    lo = np.tile([-1.5, np.log(0.05)], n_lobes)
    hi = np.tile([1.5, np.log(MAX_LOBE_INDEX)], n_lobes)
    return ReflectionModel(
        name=f"n-lobe:{n_lobes}" if n_lobes != 3 else "n-lobe",
        params=tuple(params),
        nonlinear_names=tuple(f"{k}_{i}" for i in range(1, n_lobes + 1) for k in ("t", "ln_n")),
        z_lower=lo,
        z_upper=hi,
        n_linear=n_lobes,
        basis=basis_fn,
        to_natural=to_natural,
        from_natural=from_natural,
        starts=starts,
        alpha_nonneg=(True,) * n_lobes,
        formula="K sum_i a_i (n_i+1)/2pi cos^n_i(theta + t_i gamma)",
        reference="the paper, Eqs. 7-8",
        options={"n_lobes": n_lobes, "n_data_starts": 6,
                 "groups": tuple((2 * i, 2 * i + 1) for i in range(n_lobes))},
    )


# --------------------------------------------------------------------------- phong
def _phong_basis(geom, z, derivatives=True):
    n = np.exp(_col(z, 0))
    cos_t = np.clip(geom["cos_theta"], 0.0, None)
    log_cp = geom["log_cos_phi"]
    with np.errstate(over="ignore", under="ignore"):
        spec = np.exp(n * log_cp) * geom["pos_phi"]
    basis = np.stack(np.broadcast_arrays(cos_t, spec), axis=-1)
    if not derivatives:
        return basis, None
    dspec = spec * log_cp * n
    dbasis = np.stack(np.broadcast_arrays(np.zeros_like(dspec), dspec), axis=-1)[..., None]
    return basis, dbasis


def _phong_to_natural(z, alpha):
    K = alpha.sum(axis=1)
    k_s = alpha[:, 1] / np.where(K > 0, K, 1.0)
    return np.column_stack([k_s, np.exp(z[:, 0]), K])


def _phong_from_natural(p):
    p = np.atleast_2d(np.asarray(p, float))
    return np.log(p[:, [1]]), np.column_stack([p[:, 2] * (1 - p[:, 0]), p[:, 2] * p[:, 0]])


def make_phong() -> ReflectionModel:
    return ReflectionModel(
        name="phong",
        params=(
            Parameter("k_s", "1", 0.0, 1.0, "specular share (k_d = 1 - k_s)"),
            Parameter("n", "1", 0.05, MAX_LOBE_INDEX, "specular exponent"),
            Parameter("K", "power", 0.0, np.inf, "overall scale"),
        ),
        nonlinear_names=("ln_n",),
        z_lower=np.array([np.log(0.05)]),
        z_upper=np.array([np.log(MAX_LOBE_INDEX)]),
        n_linear=2,
        basis=_phong_basis,
        to_natural=_phong_to_natural,
        from_natural=_phong_from_natural,
        starts=lambda g, t, p: np.log([[3.0], [30.0], [300.0], [estimate_specular_index(g, t, p)]]),
        alpha_nonneg=(True, True),
        formula="K ((1-k_s) cos(theta) + k_s cos^n(phi))",
        reference="Phong 1975 (the paper's ref. 18)",
        options={"residual_column": 0},
    )


# --------------------------------------------------------------------------- registry
MODELS: dict[str, Callable[..., ReflectionModel]] = {
    "two-lobe": make_two_lobe,
    "single-lobe": make_single_lobe,
    "n-lobe": make_n_lobe,
    "phong": make_phong,
}


def register_model(name: str, factory: Callable[..., ReflectionModel]) -> None:
    """Add a model factory to the registry (used by the comparison and diagnostics modules)."""
    MODELS[name] = factory
    for key in [k for k in _MODEL_CACHE if k.partition(":")[0] == name]:
        del _MODEL_CACHE[key]


def get_model(model) -> ReflectionModel:
    """Return a model by registry name (``"n-lobe:4"`` passes 4 to the factory) or as given."""
    if isinstance(model, ReflectionModel):
        return model
    cached = _MODEL_CACHE.get(model) if isinstance(model, str) else None
    if cached is not None:
        return cached
    built = _build_model(model)
    _MODEL_CACHE[model] = built
    return built


_MODEL_CACHE: dict[str, ReflectionModel] = {}


def _build_model(model) -> ReflectionModel:
    if not isinstance(model, str):
        raise IrreflectError(f"model must be a name or a ReflectionModel, got {type(model).__name__}")
    _ensure_plugins_loaded()
    base, _, arg = model.partition(":")
    if base not in MODELS:
        raise unknown_name("model", model, MODELS)
    if arg:
        try:
            count = int(arg)
        except ValueError as exc:
            raise IrreflectError(
                f"model '{model}': expected '{base}:<integer>', found '{arg}'"
            ) from exc
        try:
            return MODELS[base](count)
        except TypeError as exc:
            raise IrreflectError(f"model '{base}' takes no ':{arg}' option") from exc
    return MODELS[base]()


def model_names() -> list[str]:
    _ensure_plugins_loaded()
    return sorted(MODELS)


def _ensure_plugins_loaded() -> None:
    """Import the modules that register more models (literature models), if present."""
    import importlib
    import importlib.util

    for module in ("irreflect.literature",):
        if importlib.util.find_spec(module) is not None:
            importlib.import_module(module)
