"""The contract every reflection model meets, and the geometry it is evaluated on.

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
paper's terms. The basis is evaluated on a :class:`Geometry`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np

TWO_PI = 2.0 * np.pi


# --------------------------------------------------------------------------- the model object
@dataclass(frozen=True)
class Parameter:
    """One natural parameter of a model: name, unit, physical bounds and meaning."""

    name: str
    unit: str
    lower: float
    upper: float
    description: str

    @property
    def zero_scale(self) -> float:
        """The scale an uncertainty is judged against when the value is near 0 (0: none).

        A coefficient whose range spans 0 on both sides (the exponents ``v_*`` and ``w`` of
        ``cos^v(gamma)``, the axes ``t_*`` and ``cx_*``: unit ``"1"``; the angles ``tilt``
        and ``delta``: unit ``"deg"``) is naturally 0, so ``|value|`` is no scale for it:
        it is judged against 1 (a change of 1 in ``v`` changes ``cos^v(gamma)`` by a factor
        of 2 at 60 deg; 1 deg of angle is below a goniometer's step). A share or a
        roughness that is 0 leaves the lobe it scales unseen, and ``b`` (power) has no
        scale of its own: those are judged against ``|value|``.
        """
        if not (self.lower < 0.0 < self.upper):
            return 0.0
        return 1.0 if self.unit in ("1", "deg") else 0.0


BasisFn = Callable[[np.ndarray, np.ndarray, np.ndarray, bool], tuple]


@dataclass(frozen=True)
class FitHints:
    """What a model tells the fitter besides its basis (every field optional).

    Attributes
    ----------
    residual_column : int or None
        The linear coefficient that is ``K (1 - sum of shares)`` in natural terms: the
        linear step drops it when it would be all but invisible in the data.
    n_screen, n_keep, n_hops : int or None
        The model's own screening size, screened starts kept and basin hops per round
        (None: the fitter's defaults by number of nonlinear coordinates).
    n_data_starts : int
        How many of the best data-driven starts start Levenberg-Marquardt.
    groups : tuple of tuples of int
        Nonlinear coordinates scanned together in the refinement rounds (a lobe's axis
        and index); empty: every coordinate alone.
    batch_starts : callable or None
        ``batch_starts(gamma, theta, power, weights (B, n)) -> (B, S, P)``: the data-driven
        starts of a batch of subsets in one call.
    kernel : str or None
        The compiled kernel that implements this model (``"two-lobe"``), None: numpy.
    kernel_starts : callable or None
        The ``starts`` function the kernel reproduces: a model whose ``starts`` a caller
        replaced is fitted in numpy.
    """

    residual_column: int | None = None
    n_screen: int | None = None
    n_keep: int | None = None
    n_hops: int | None = None
    n_data_starts: int = 2
    groups: tuple[tuple[int, ...], ...] = ()
    batch_starts: Callable | None = None
    kernel: str | None = None
    kernel_starts: Callable | None = None


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
        ``basis(geom, z, derivatives)`` with ``geom`` a :class:`Geometry` of arrays of
        shape ``(Bg, n)`` (``Bg`` 1 or ``B``; radians) and ``z`` of shape ``(B, P)``;
        returns the basis
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
    #: What the fitter should know besides the basis (:class:`FitHints`).
    hints: FitHints = FitHints()
    #: The model's own check of fitted values: ``validity(values, gamma_rad)`` -> warnings
    #: (one line each), run by :meth:`validity_warnings`; None: no check.
    validity: Callable | None = None
    #: An extended model (:mod:`irreflect.models.extensions`): the model it wraps, the
    #: extension that wrapped it and the names of every extension applied, innermost first.
    wrapped: ReflectionModel | None = None
    extension: object = None
    extensions: tuple[str, ...] = ()
    #: Box of plausible ``z`` sampled by the fitter's global screening (default: the
    #: bounds, clipped to [-15, 15] on each coordinate).
    screen_lower: np.ndarray | None = None
    screen_upper: np.ndarray | None = None
    #: The paper's specular share saturates (:func:`irreflect.models.paper.specular_share`):
    #: the first two linear coefficients are ``K (1 - u)`` and ``K u`` of a share
    #: ``a = min(1, u s)`` with ``s = cos^z[0](gamma)``, and where ``u s >= 1`` both
    #: columns of the basis become the specular lobe alone (:func:`saturate_rows`). The
    #: fitter then solves the linear step over the share's saturation patterns.
    share_cap: bool = False

    def validity_warnings(self, values, gamma_rad) -> tuple[str, ...]:
        """The model's own check of fitted natural ``values`` on the measured angles of
        incidence ``gamma_rad``: one line per problem (empty: none, or no check)."""
        if self.validity is None:
            return ()
        return tuple(self.validity(values, gamma_rad))

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
        basis = self.curve_basis(Geometry.of(g, t), z, alpha)
        out = np.einsum("bnl,bl->bn", basis, alpha)
        return out[0].reshape(shape) if single else out

    def curve_basis(self, geom, z, alpha) -> np.ndarray:
        """The basis ``(B, n, L)`` whose product with ``alpha`` is the model's curve: the
        separable basis, with the saturated rows of a saturating share
        (:func:`saturate_rows`) where the model has one."""
        basis, _ = self.basis(geom, z, False)
        if self.share_cap:
            basis = saturate_rows(basis, share_factor(z, geom), alpha)
        return basis

    def predict_deg(self, params, gamma_deg, theta_deg) -> np.ndarray:
        """Same as :meth:`predict` with angles in degrees."""
        return self.predict(params, np.radians(gamma_deg), np.radians(theta_deg))

    def describe(self) -> str:
        rows = [f"{self.name}: {self.formula}"]
        rows += [f"  {p.name:<8} [{p.unit}] {p.description}" for p in self.params]
        return "\n".join(rows)


def cap_share(share):
    """The rule of the specular share everywhere in irreflect: it saturates at 1,
    ``min(share, 1)`` (a share of the reflected power cannot exceed it; below 1 the
    paper's law, Eq. 15, unchanged). The fitter's linear step, its compiled kernel, the
    models' predictions, the protocol designs, the diagnosis and the room all go through
    it (the kernel compiles this very function)."""
    return np.minimum(share, 1.0)


def share_factor(z, geom) -> np.ndarray:
    """``s = cos^v_as(gamma)`` at every point of ``geom`` for every row of ``z`` (its first
    coordinate is ``v_as``): the factor of the specular share ``a_s = min(1, u_as s)``,
    ``(B, n)``."""
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        return np.exp(np.asarray(z, float)[:, :1] * geom.log_cos_gamma)


def saturated_column(basis, s):
    """The value both share columns take where the share saturates: from the unsaturated
    columns ``b0 = L_d`` and ``b1 = L_d + s (L_s - L_d)`` (times whatever factor an
    extension applies to both), ``b0 + (b1 - b0) / s = L_s``. ``basis`` (..., n, L), ``s``
    (..., n) with ``s > 0`` wherever the share can saturate (``s > 1``)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return basis[..., 0] + (basis[..., 1] - basis[..., 0]) / np.where(s > 0, s, 1.0)


def saturate_rows(basis, s, alpha, strict: bool = False):
    """The basis of a model with a saturating share (:attr:`ReflectionModel.share_cap`)
    at the linear coefficients ``alpha`` (B, L): where ``u s >= 1`` (``u = alpha_1 /
    (alpha_0 + alpha_1)``, the share at normal incidence), both share columns are the
    specular lobe, so the curve is ``K L_s`` there (Eq. 19 with ``a_s = 1``). With
    ``strict``, a row exactly at its threshold (``u s = 1``, the same curve either way)
    keeps the unsaturated columns: the side whose derivative sees ``u``."""
    alpha = np.asarray(alpha, float)
    k = alpha[:, 0] + alpha[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.where(k > 0, alpha[:, 1] / np.where(k > 0, k, 1.0), 0.0)
    sat = cap_share(u[:, None] * s) >= 1.0
    if strict:
        sat &= u[:, None] * s > 1.0 + 1e-9
    if not sat.any():
        return basis
    basis = np.array(basis, float, copy=True)
    col = saturated_column(basis, s)
    basis[..., 0] = np.where(sat, col, basis[..., 0])
    basis[..., 1] = np.where(sat, col, basis[..., 1])
    return basis


def _lobes_to_natural(z, alpha, n_lobes: int, first: int):
    """Natural parameters of ``n_lobes`` lobes of coordinates ``(axis, ln index)`` each and
    shares ``alpha[:, first + i] / K`` (``K`` the sum of all linear coefficients):
    ``(axis_1, index_1, share_1, ..., K)``."""
    K = alpha.sum(axis=1)
    safe = np.where(K > 0, K, 1.0)
    out = []
    for i in range(n_lobes):
        out += [z[:, 2 * i], np.exp(z[:, 2 * i + 1]), alpha[:, first + i] / safe]
    return np.column_stack(out + [K])


def _col(z, k):
    """Column ``k`` of ``z`` shaped to broadcast against ``(B, n)`` arrays."""
    return z[:, k][:, None]


def _as2d(a):
    a = np.asarray(a, float)
    return a.reshape(1, -1) if a.ndim == 1 else a


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


@dataclass(frozen=True, eq=False)
class Geometry:
    """The measurement geometry a model is evaluated on: arrays of shape ``(Bg, n)`` in
    radians (``Bg`` 1, shared by a batch, or one row per problem).

    ``theta`` is the receiver angle the diffuse terms see; ``theta_spec`` the one the
    specular terms see: equal, unless an extension tilts the specular axis
    (:meth:`tilted`, the off-specular peak) or shifts the receiver arm (:meth:`shifted`,
    both). Every derived quantity (cosines, their logs, the half vector of the
    microfacet models) is computed once, on first use, and kept: the geometry does not
    change while a fit runs, and a transformed geometry is a new object, so nothing
    derived can go stale.
    """

    gamma: np.ndarray
    theta: np.ndarray
    theta_spec: np.ndarray

    @classmethod
    def of(cls, gamma, theta) -> Geometry:
        """The plane-of-incidence geometry of angles ``gamma``, ``theta`` (radians)."""
        gamma, theta = _as2d(gamma), _as2d(theta)
        return cls(gamma, theta, theta)

    @property
    def rows(self) -> int:
        return max(self.gamma.shape[0], self.theta.shape[0], self.theta_spec.shape[0])

    def take(self, idx) -> Geometry:
        """Rows ``idx`` (for batches with one geometry per problem)."""
        pick = lambda a: a[idx] if a.shape[0] > 1 else a  # noqa: E731
        return Geometry(pick(self.gamma), pick(self.theta), pick(self.theta_spec))

    def repeat(self, k: int) -> Geometry:
        """Every row ``k`` times (one row per candidate of each problem)."""
        return Geometry(*(np.repeat(a, k, axis=0) for a in (self.gamma, self.theta,
                                                               self.theta_spec)))

    def shifted(self, delta) -> Geometry:
        """The receiver arm turned by ``delta`` (radians, broadcast to the rows)."""
        return Geometry(self.gamma, self.theta + delta, self.theta_spec + delta)

    def tilted(self, tilt) -> Geometry:
        """The specular axis tilted by ``tilt`` (radians of phi, broadcast to the rows):
        the specular terms see the receiver at ``theta_spec + tilt``."""
        return Geometry(self.gamma, self.theta, self.theta_spec + tilt)

    # -- the angles and their cosines
    @cached_property
    def phi(self) -> np.ndarray:
        """Angle from the (tilted) mirror direction, ``-gamma - theta_spec``."""
        return -self.gamma - self.theta_spec

    @cached_property
    def cos_gamma(self) -> np.ndarray:
        return np.cos(self.gamma)

    @cached_property
    def log_cos_gamma(self) -> np.ndarray:
        return np.log(self.cos_gamma)

    @cached_property
    def cos_theta(self) -> np.ndarray:
        return np.cos(self.theta)

    @cached_property
    def pos_theta(self) -> np.ndarray:
        return self.cos_theta > 0

    @cached_property
    def log_cos_theta(self) -> np.ndarray:
        return np.log(np.where(self.pos_theta, self.cos_theta, 1.0))

    @cached_property
    def receiver_cos(self) -> np.ndarray:
        """``max(cos theta, 0)``: the receiver's projection (Eq. 5's cos factor)."""
        return np.clip(self.cos_theta, 0.0, None)

    @cached_property
    def cos_phi(self) -> np.ndarray:
        return np.cos(self.phi)

    @cached_property
    def pos_phi(self) -> np.ndarray:
        return self.cos_phi > 0

    @cached_property
    def log_cos_phi(self) -> np.ndarray:
        return np.log(np.where(self.pos_phi, self.cos_phi, 1.0))

    # -- the half vector (microfacet and Blinn models), from the specular receiver angle
    @cached_property
    def half_angle(self) -> np.ndarray:
        """``theta_h = (gamma + theta_spec) / 2``: the half vector from the normal."""
        return 0.5 * (self.gamma + self.theta_spec)

    @cached_property
    def cos_half(self) -> np.ndarray:
        return np.cos(self.half_angle)

    @cached_property
    def log_cos_half(self) -> np.ndarray:
        with np.errstate(divide="ignore"):
            return np.log(self.cos_half)

    @cached_property
    def tan2_half(self) -> np.ndarray:
        return np.tan(self.half_angle) ** 2

    @cached_property
    def source_half_angle(self) -> np.ndarray:
        """``beta = (theta_spec - gamma) / 2``: the half vector from the source."""
        return 0.5 * (self.theta_spec - self.gamma)

    @cached_property
    def cos_source_half(self) -> np.ndarray:
        return np.cos(self.source_half_angle)

    @cached_property
    def sin_sin(self) -> np.ndarray:
        """``sin(gamma) sin(theta_spec)`` (Lafortune's lobes)."""
        return np.sin(self.gamma) * np.sin(self.theta_spec)

    @cached_property
    def cos_cos(self) -> np.ndarray:
        """``cos(gamma) cos(theta_spec)`` (Lafortune's lobes)."""
        return self.cos_gamma * np.cos(self.theta_spec)


def _lobe_from_log(log_cos, positive, n, derivative=True):
    """Lobe ``(n+1)/(2 pi) cos^n`` and ``d lobe / d n`` (None unless ``derivative``) from a
    precomputed ``log cos``."""
    # callers run under np.errstate(under="ignore"): cos^n underflows to 0 for sharp lobes
    power = np.exp(n * log_cos) * positive
    lobe = (n + 1.0) * (1.0 / TWO_PI) * power
    if not derivative:
        return lobe, None
    return lobe, power * (1.0 / TWO_PI) + lobe * log_cos


