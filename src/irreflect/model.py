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
    #: Box of plausible ``z`` sampled by the fitter's global screening (default: the
    #: bounds, clipped to [-6, 6] on each coordinate).
    screen_lower: np.ndarray | None = None
    screen_upper: np.ndarray | None = None

    def screen_box(self) -> tuple[np.ndarray, np.ndarray]:
        lo = self.screen_lower if self.screen_lower is not None else np.maximum(self.z_lower, -6.0)
        hi = self.screen_upper if self.screen_upper is not None else np.minimum(self.z_upper, 6.0)
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
def estimate_specular_index(gamma, theta, power) -> float:
    """Data-driven guess of the specular lobe index from the measured peak widths.

    For every angle of incidence, the excess of power over the curve's minimum is looked
    at around the mirror direction; its half width at half maximum ``phi_half`` gives
    ``n = -ln 2 / ln cos(phi_half)`` (Eq. 3). The median over angles of incidence with a
    resolved peak (peak above 1.5 times the curve's mean) is returned; 20 if none.

    gamma, theta : array-like, radians. power : array-like.
    """
    gamma = np.asarray(gamma, float).ravel()
    theta = np.asarray(theta, float).ravel()
    power = np.asarray(power, float).ravel()
    if power.size < 4:
        return 20.0
    order = np.lexsort((theta, gamma))
    gamma, theta, power = gamma[order], theta[order], power[order]
    starts = np.flatnonzero(np.r_[True, gamma[1:] != gamma[:-1]])
    counts = np.diff(np.r_[starts, gamma.size])
    group = np.repeat(np.arange(starts.size), counts)
    phi = np.abs(-gamma - theta)
    near = phi <= np.radians(15)
    base = np.minimum.reduceat(power, starts)
    peak = np.maximum.reduceat(np.where(near, power, -np.inf), starts)
    mean = np.add.reduceat(power, starts) / counts
    half = (peak - base) / 2
    below = np.where(power - base[group] < half[group], phi, np.inf)
    phi_half = np.minimum.reduceat(below, starts)
    ok = (counts >= 4) & np.isfinite(peak) & (peak > base) & (peak > 1.5 * mean) \
        & np.isfinite(phi_half)
    if not ok.any():
        return 20.0
    phi_half = np.clip(phi_half[ok], np.radians(1.0), np.radians(60))
    estimates = -np.log(2) / np.log(np.cos(phi_half))
    return float(np.clip(np.median(estimates), 2.0, 3000.0))


# --------------------------------------------------------------------------- two-lobe
_TWO_LOBE_PARAMS = (
    Parameter("u_as", "1", 0.0, 1.0, "specular share at normal incidence (Eq. 15)"),
    Parameter("v_as", "1", -12.0, 12.0, "exponent of cos(gamma) in the specular share (Eq. 15)"),
    Parameter("u_nd", "1", 0.05, 100.0, "diffuse lobe index at normal incidence (Eq. 17)"),
    Parameter("v_nd", "1", -12.0, 12.0, "exponent of cos(gamma) in the diffuse index (Eq. 17)"),
    Parameter("u_ns", "1", 0.5, 1.0e4, "specular lobe index at normal incidence (Eq. 18)"),
    Parameter("v_ns", "1", -12.0, 12.0, "exponent of cos(gamma) in the specular index (Eq. 18)"),
    Parameter("K", "power", 0.0, np.inf, "grouped constant factor A_eff P_x beta / d_RX^2 (Eq. 22)"),
)


def _two_lobe_basis(geom, z, derivatives=True):
    log_cg = geom["log_cos_gamma"]
    v_as, ln_u_nd, v_nd, ln_u_ns, v_ns = z.T[:, :, None]
    share_shape = np.exp(v_as * log_cg)  # a_s / u_as = cos^v_as(gamma)
    n_d = np.exp(ln_u_nd + v_nd * log_cg)
    n_s = np.exp(ln_u_ns + v_ns * log_cg)
    lobe_d, dlobe_d = _lobe_from_log(geom["log_cos_theta"], geom["pos_theta"], n_d, derivatives)
    lobe_s, dlobe_s = _lobe_from_log(geom["log_cos_phi"], geom["pos_phi"], n_s, derivatives)
    # P = K * lobe_d + (K u_as) * cos^v_as(gamma) * (lobe_s - lobe_d)
    b2 = share_shape * (lobe_s - lobe_d)
    shape = b2.shape
    basis = np.empty(shape + (2,))
    basis[..., 0] = lobe_d
    basis[..., 1] = b2
    if not derivatives:
        return basis, None
    dd = dlobe_d * n_d  # d lobe_d / d ln_u_nd
    ds = dlobe_s * n_s  # d lobe_s / d ln_u_ns
    dbasis = np.zeros(shape + (2, 5))
    dbasis[..., 0, 1] = dd
    dbasis[..., 0, 2] = dd * log_cg
    dbasis[..., 1, 0] = b2 * log_cg
    sdd = share_shape * dd
    dbasis[..., 1, 1] = -sdd
    dbasis[..., 1, 2] = -sdd * log_cg
    sds = share_shape * ds
    dbasis[..., 1, 3] = sds
    dbasis[..., 1, 4] = sds * log_cg
    return basis, dbasis


def _two_lobe_to_natural(z, alpha):
    K = alpha[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        u_as = np.where(K > 0, alpha[:, 1] / np.where(K > 0, K, 1.0), 0.0)
    return np.column_stack([u_as, z[:, 0], np.exp(z[:, 1]), z[:, 2], np.exp(z[:, 3]), z[:, 4], K])


def _two_lobe_from_natural(p):
    p = np.atleast_2d(np.asarray(p, float))
    z = np.column_stack([p[:, 1], np.log(p[:, 2]), p[:, 3], np.log(p[:, 4]), p[:, 5]])
    alpha = np.column_stack([p[:, 6], p[:, 6] * p[:, 0]])
    return z, alpha


def _two_lobe_starts(gamma, theta, power):
    n_est = estimate_specular_index(gamma, theta, power)
    starts = []
    for ln_ns in (np.log(n_est), np.log(max(n_est / 4, 1.0)), np.log(n_est * 4), np.log(30.0)):
        for v_as in (-2.5, 0.5):
            starts.append([v_as, 0.0, 0.3, ln_ns, 0.0])
    return np.array(starts)


def make_two_lobe() -> ReflectionModel:
    lo = np.array([-12.0, np.log(0.05), -12.0, np.log(0.5), -12.0])
    hi = np.array([12.0, np.log(100.0), 12.0, np.log(1.0e4), 12.0])
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
        screen_lower=np.array([-6.0, np.log(0.3), -3.0, np.log(1.0), -3.0]),
        screen_upper=np.array([2.0, np.log(20.0), 6.0, np.log(3000.0), 3.0]),
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
            Parameter("n", "1", 0.05, 1.0e4, "lobe index about the mirror direction (Eq. 6)"),
            Parameter("K", "power", 0.0, np.inf, "grouped factor A_RX P_x beta / d_RX^2 (Eq. 6)"),
        ),
        nonlinear_names=("ln_n",),
        z_lower=np.array([np.log(0.05)]),
        z_upper=np.array([np.log(1.0e4)]),
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
            Parameter(f"n_{i}", "1", 0.05, 1.0e4, f"index of lobe {i}"),
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
        return np.array(out)

    lo = np.tile([-1.5, np.log(0.05)], n_lobes)
    hi = np.tile([1.5, np.log(1.0e4)], n_lobes)
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
        options={"n_lobes": n_lobes},
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
            Parameter("n", "1", 0.05, 1.0e4, "specular exponent"),
            Parameter("K", "power", 0.0, np.inf, "overall scale"),
        ),
        nonlinear_names=("ln_n",),
        z_lower=np.array([np.log(0.05)]),
        z_upper=np.array([np.log(1.0e4)]),
        n_linear=2,
        basis=_phong_basis,
        to_natural=_phong_to_natural,
        from_natural=_phong_from_natural,
        starts=lambda g, t, p: np.log([[3.0], [30.0], [300.0], [estimate_specular_index(g, t, p)]]),
        alpha_nonneg=(True, True),
        formula="K ((1-k_s) cos(theta) + k_s cos^n(phi))",
        reference="Phong 1975 (the paper's ref. 18)",
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
