"""The paper's models: two-lobe (Eqs. 19-22), single-lobe (Eq. 6), N-lobe (Eqs. 7-8), and
Phong as the paper compares it; pure vectorised functions and their separable forms.

Angles in radians (see :mod:`irreflect.models.base` for the conventions).
"""

from __future__ import annotations

import functools

import numpy as np

from ..errors import IrreflectError
from .base import (
    FitHints,
    Parameter,
    ReflectionModel,
    _col,
    _lobe_and_derivative,
    _lobe_from_log,
    _lobes_to_natural,
    cap_share,
    generalized_lambertian,
    mirror_angle,
)
from .guesses import (
    MAX_LOBE_INDEX,
    _median_specular_index,
    estimate_specular_index,
    lobe_profile,
    peak_directions,
    two_lobe_profile_starts,
)


# --------------------------------------------------------------------------- the paper's models
def specular_share(u_as, v_as, cos_gamma):
    """The specular share of the two-lobe model, ``a_s = min(1, u_as cos^v_as(gamma))``.

    Eq. 15 (``a_s = u_as cos^v_as(gamma)``) wherever that is below 1, and 1 beyond: a
    share of the reflected power cannot exceed the whole of it (with ``a_s > 1`` the
    diffuse lobe, ``1 - a_s``, would carry negative power). With ``v_as < 0`` the law
    grows toward grazing incidence, so a glossy material's share reaches 1 at some angle
    and the reflection is all specular beyond it. The paper's Table 3 materials stay
    below 1 over their whole range, where this is the paper's law exactly.

    Parameters
    ----------
    u_as, v_as : array-like
        Coefficients of Eq. 15 (dimensionless).
    cos_gamma : array-like
        Cosine of the angle of incidence.

    Returns
    -------
    ndarray
        The share, in [0, 1] for ``u_as >= 0``. NaN in gives NaN out.
    """
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        return cap_share(np.asarray(u_as, float) * np.power(np.asarray(cos_gamma, float),
                                                            v_as))


def two_lobe_power(gamma, theta, u_as, v_as, u_nd, v_nd, u_ns, v_ns, K):
    """Received power of the paper's two-component model (Eqs. 19-22).

    ``P = K [p_d(gamma, theta) + p_s(gamma, phi)]`` with ``phi = -gamma - theta`` and

    * specular share ``a_s = min(1, u_as cos^v_as(gamma))`` (Eq. 15, saturating at 1: see
      :func:`specular_share`), diffuse share ``1 - a_s`` (Eq. 16);
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
    a_s = specular_share(u_as, v_as, cos_gamma)
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

    This is the basis where the share is below 1. Where ``u_as s >= 1`` the share
    saturates (:func:`specular_share`) and both columns are ``L_s``
    (:func:`~irreflect.models.base.saturate_rows`): which rows saturate depends on
    ``u_as = c_2 / (c_1 + c_2)``, so the fitter's linear step solves over the saturation
    patterns (``share_cap``, :func:`irreflect.fitting._linear_step`).
    """
    log_cg = geom.log_cos_gamma
    v_as, ln_u_nd, v_nd, ln_u_ns, v_ns = z.T[:, :, None]
    s = np.exp(v_as * log_cg)
    n_d = np.exp(ln_u_nd + v_nd * log_cg)
    n_s = np.exp(ln_u_ns + v_ns * log_cg)
    lobe_d, dlobe_d = _lobe_from_log(geom.log_cos_theta, geom.pos_theta, n_d, derivatives)
    lobe_s, dlobe_s = _lobe_from_log(geom.log_cos_phi, geom.pos_phi, n_s, derivatives)
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
        hints=FitHints(batch_starts=_two_lobe_batch_starts, residual_column=0,
                       kernel="two-lobe", kernel_starts=_two_lobe_starts,
                       n_screen=96, n_keep=3, n_hops=0),
        screen_lower=np.array([-6.0, np.log(0.3), -3.0, np.log(1.0), -3.0]),
        screen_upper=np.array([2.0, np.log(20.0), 6.0, np.log(1.0e5), 3.0]),
        share_cap=True,
    )


# --------------------------------------------------------------------------- single-lobe
def _single_lobe_basis(geom, z, derivatives=True):
    n = np.exp(_col(z, 0))
    lobe, dlobe = _lobe_from_log(geom.log_cos_phi, geom.pos_phi, n)
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
def _n_lobe_basis_fn(n_lobes, geom, z, derivatives=True):
    gamma, theta = geom.gamma, geom.theta_spec
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


def _n_lobe_to_natural(n_lobes, z, alpha):
    return _lobes_to_natural(z, alpha, n_lobes, first=0)


def _n_lobe_from_natural(n_lobes, p):
    p = np.atleast_2d(np.asarray(p, float))
    z = np.column_stack(
        [p[:, 3 * i + k] if k == 0 else np.log(p[:, 3 * i + 1]) for i in range(n_lobes) for k in (0, 1)]
    )
    K = p[:, -1]
    alpha = np.column_stack([K * p[:, 3 * i + 2] for i in range(n_lobes)])
    return z, alpha


def _n_lobe_starts(n_lobes, gamma, theta, power):
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

    lo = np.tile([-1.5, np.log(0.05)], n_lobes)
    hi = np.tile([1.5, np.log(MAX_LOBE_INDEX)], n_lobes)
    return ReflectionModel(
        name=f"n-lobe:{n_lobes}" if n_lobes != 3 else "n-lobe",
        params=tuple(params),
        nonlinear_names=tuple(f"{k}_{i}" for i in range(1, n_lobes + 1) for k in ("t", "ln_n")),
        z_lower=lo,
        z_upper=hi,
        n_linear=n_lobes,
        basis=functools.partial(_n_lobe_basis_fn, n_lobes),
        to_natural=functools.partial(_n_lobe_to_natural, n_lobes),
        from_natural=functools.partial(_n_lobe_from_natural, n_lobes),
        starts=functools.partial(_n_lobe_starts, n_lobes),
        alpha_nonneg=(True,) * n_lobes,
        formula="K sum_i a_i (n_i+1)/2pi cos^n_i(theta + t_i gamma)",
        reference="the paper, Eqs. 7-8",
        hints=FitHints(n_data_starts=6,
                       groups=tuple((2 * i, 2 * i + 1) for i in range(n_lobes))),
    )


# --------------------------------------------------------------------------- phong
def _phong_basis(geom, z, derivatives=True):
    n = np.exp(_col(z, 0))
    cos_t = np.clip(geom.cos_theta, 0.0, None)
    log_cp = geom.log_cos_phi
    with np.errstate(over="ignore", under="ignore"):
        spec = np.exp(n * log_cp) * geom.pos_phi
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
        hints=FitHints(residual_column=0),
    )


