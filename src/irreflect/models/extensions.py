"""Model extensions: the catalogue of effects a reflection model may be missing.

An *extension* turns a :class:`~irreflect.model.ReflectionModel` into a bigger one that
contains it as a special case (nested: the extension's neutral values give back the wrapped
model exactly). Extensions compose: ``extend(get_model("two-lobe"), ["background",
"angle_offset"])`` wraps the two-lobe model in a background term, then the result in a
receiver-angle offset. The new model stays in the separable form the fitter uses,
``P = sum_l alpha_l B_l(gamma, theta; z)``: an extension adds nonlinear coordinates ``z``,
linear coefficients ``alpha`` (new basis columns) or both, and supplies their derivatives.

The catalogue (the names are part of irreflect's interface):

``incidence_reflectance``
    The reflection factor depends on the angle of incidence, ``K(gamma) = K cos^w(gamma)``
    (the paper's Fig. 11 shows K is not constant): every basis column times
    ``cos^w(gamma)``. New parameter ``w`` (dimensionless); neutral ``w = 0``.
``offspecular_peak``
    The specular lobe's axis is tilted from the mirror direction toward grazing by
    ``tilt * sin^2(gamma)`` (the off-specular peaks of rough surfaces, Torrance and Sparrow
    1967, the paper's ref. 26): the angle from the mirror direction ``phi`` the wrapped
    model sees becomes ``phi + tilt sin^2(gamma)`` (for gamma < 0), so the lobe peaks at
    ``theta = -gamma + tilt sin^2(gamma)``. New parameter ``tilt`` (deg, the tilt at grazing
    incidence; negative = toward the surface normal); neutral 0.
``retroreflection``
    An extra lobe about the direction back to the source, ``theta = gamma``:
    ``K_r (n_r + 1)/2pi cos^n_r(theta - gamma)`` (Eq. 2 about a new axis, as one more
    component of the paper's Eq. 7). New parameters ``a_r = K_r / (K + K_r)``, the lobe's
    share of all the reflected power (the shares of Eq. 8 then sum to 1 again; K is the
    wrapped model's scale), and ``n_r`` (index); neutral ``a_r = 0``.
``angle_offset``
    A constant zero error of the receiver arm: the wrapped model is evaluated at the true
    receiver angle ``theta + delta``. New parameter ``delta`` (deg); neutral 0.
``background``
    An additive constant ``b`` (stray light, detector offset), in power units; neutral 0.
``specular_halo``
    A second, broader lobe about the mirror direction (the paper's three-component model,
    section 3.3): ``K_h (n_h + 1)/2pi cos^n_h(phi)``. New parameters ``a_h = K_h / (K +
    K_h)`` (share of all the reflected power) and ``n_h`` (index); neutral ``a_h = 0``.

Derivatives are analytic, except that the derivative of the wrapped model with respect to
a *geometric* shift (``angle_offset``, ``offspecular_peak``) is a central difference of its
basis along the shift (step 1e-7 rad): a wrapped model only gives derivatives with respect
to its own parameters, and this keeps every extension usable on every model.

Beyond the catalogue, :func:`gain_drift` builds the gain drift between the angles of
incidence of one table (``gain_drift``: every reading at one angle of incidence times its
own factor, the factors' geometric mean 1): not registered, its parameters are that
table's angles of incidence; the diagnosis builds it per table.

Registry: :data:`EXTENSIONS` (name -> callable ``extend(base) -> ReflectionModel``),
:func:`register_extension`, :func:`get_extension`, :func:`extension_names`,
:func:`extend`. A user extension is any such callable; :class:`Extension` is a helper that
builds one from the pieces (new parameters, bounds, starts and the basis function).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..errors import IrreflectError, unknown_name
from .base import FitHints, Parameter, ReflectionModel, _lobe_from_log

GEOMETRY_STEP = 1e-7  # rad, central-difference step along geometric shifts

# (M, n) basis of the extension and its derivative; see Extension.evaluate
EvaluateFn = Callable[..., tuple]


@dataclass(frozen=True)
class Extension:
    """A reusable model extension, applied to a model by calling it: ``ext(base)``.

    Attributes
    ----------
    name : str
        Registry name (appended to the model name: ``two-lobe+background``).
    summary : str
        One line of physics, for reports.
    params : tuple of Parameter
        The natural parameters it adds, in reporting order.
    nonlinear_names : tuple of str
        Its internal nonlinear coordinates (appended to the wrapped model's ``z``).
    z_lower, z_upper : tuple of float
        Box bounds of those coordinates.
    z_starts : tuple of tuples
        Starting values of those coordinates; the first is the neutral one (or a good
        guess), so that a start at the wrapped model's optimum exists.
    n_linear : int
        Number of basis columns (linear coefficients) it adds.
    alpha_nonneg : tuple of bool
        Which of its linear coefficients must be >= 0.
    evaluate : callable
        ``evaluate(base, geom, z_base (M, Pb), z_ext (M, Pe), derivatives) -> (B, dB)``:
        the full basis ``(M, n, Lb + Le)`` and its derivative with respect to all of
        ``z = [z_base, z_ext]``, ``(M, n, Lb + Le, Pb + Pe)`` (None when not asked).
    natural : callable
        ``natural(z_ext, alpha_ext, base_natural, k_scale) -> (M, k_e)`` natural values of
        the new parameters (``k_scale`` is the wrapped model's K, or 1 if it has none).
    internal : callable
        ``internal(natural_ext, base_natural, k_scale) -> (z_ext, alpha_ext)``.
    formula : str
    reference : str
    """

    name: str
    summary: str
    params: tuple[Parameter, ...]
    nonlinear_names: tuple[str, ...]
    z_lower: tuple[float, ...]
    z_upper: tuple[float, ...]
    z_starts: tuple[tuple[float, ...], ...]
    n_linear: int
    alpha_nonneg: tuple[bool, ...]
    evaluate: EvaluateFn
    natural: Callable
    internal: Callable
    formula: str = ""
    reference: str = ""

    def start_rows(self) -> np.ndarray:
        """The starting values of the new coordinates, one row per start ``(S, P_new)``."""
        return _start_rows(self.z_starts, len(self.nonlinear_names))

    def __call__(self, base: ReflectionModel) -> ReflectionModel:
        """The extended model ``self(base)`` (by name: :func:`irreflect.models.extend`)."""
        if not isinstance(base, ReflectionModel):
            raise IrreflectError(
                f"extension '{self.name}' extends a ReflectionModel, found "
                f"{type(base).__name__} {base!r}: pass get_model({base!r}), or use "
                f"extend({base!r}, ['{self.name}'])")
        return apply_extension(base, self)


def _k_scale(base: ReflectionModel, base_natural: np.ndarray) -> np.ndarray:
    """The wrapped model's K (power scale) per row, or ones when it has no K."""
    if "K" in base.param_names:
        k = base_natural[:, base.param_names.index("K")]
        return np.where(k > 0, k, 1.0)
    return np.ones(base_natural.shape[0])


def applied_extensions(model: ReflectionModel) -> tuple[str, ...]:
    """Names of the extensions a model was built with, innermost first."""
    return tuple(model.extensions)


def base_of(model: ReflectionModel) -> ReflectionModel:
    """The innermost model an extended model wraps (the model itself if not extended)."""
    while model.wrapped is not None:
        model = model.wrapped
    return model


def apply_extension(base: ReflectionModel, ext: Extension) -> ReflectionModel:
    """Build the extended model ``ext(base)`` in separable form."""
    if ext.name in applied_extensions(base):
        raise IrreflectError(
            f"extension '{ext.name}' is already part of model '{base.name}': "
            "apply each extension at most once"
        )
    clash = set(base.param_names) & {p.name for p in ext.params}
    if clash:
        raise IrreflectError(
            f"extension '{ext.name}' adds parameter(s) {', '.join(sorted(clash))} that model "
            f"'{base.name}' already has: rename the extension's parameters"
        )
    pb, lb, kb = base.n_nonlinear, base.n_linear, len(base.params)
    pe, le = len(ext.nonlinear_names), ext.n_linear

    def basis(geom, z, derivatives=True):
        z = np.atleast_2d(np.asarray(z, float))
        return ext.evaluate(base, geom, z[:, :pb], z[:, pb:], derivatives)

    def to_natural(z, alpha):
        z, alpha = np.atleast_2d(z), np.atleast_2d(alpha)
        nat_b = base.to_natural(z[:, :pb], alpha[:, :lb])
        nat_e = ext.natural(z[:, pb:], alpha[:, lb:], nat_b, _k_scale(base, nat_b))
        return np.column_stack([nat_b, np.reshape(nat_e, (nat_b.shape[0], -1))])

    def from_natural(params):
        params = np.atleast_2d(np.asarray(params, float))
        nat_b = params[:, :kb]
        zb, ab = base.from_natural(nat_b)
        ze, ae = ext.internal(params[:, kb:], nat_b, _k_scale(base, nat_b))
        m = params.shape[0]
        return (np.column_stack([zb, np.reshape(ze, (m, pe))]),
                np.column_stack([ab, np.reshape(ae, (m, le))]))

    ext_starts = _start_rows(ext.z_starts, pe)

    def starts(gamma, theta, power):
        sb = np.atleast_2d(np.asarray(base.starts(gamma, theta, power), float))
        rows = [np.concatenate([s, ext_starts[0]]) for s in sb]
        rows += [np.concatenate([sb[0], e]) for e in ext_starts[1:]]
        return np.array(rows).reshape(len(rows), pb + pe)

    return ReflectionModel(
        name=f"{base.name}+{ext.name}",
        params=tuple(base.params) + tuple(ext.params),
        nonlinear_names=tuple(base.nonlinear_names) + tuple(ext.nonlinear_names),
        z_lower=np.concatenate([base.z_lower, np.asarray(ext.z_lower, float)]),
        z_upper=np.concatenate([base.z_upper, np.asarray(ext.z_upper, float)]),
        n_linear=lb + le,
        basis=basis,
        to_natural=to_natural,
        from_natural=from_natural,
        starts=starts,
        alpha_nonneg=tuple(base.alpha_nonneg) + tuple(ext.alpha_nonneg),
        formula=f"{base.formula}; {ext.name}: {ext.formula}",
        reference=ext.reference or base.reference,
        hints=_extended_hints(base, ext_starts[0], starts),
        validity=base.validity,  # about the wrapped model's leading part
        wrapped=base,
        extension=ext,
        extensions=applied_extensions(base) + (ext.name,),
        # the wrapped model's screening box (chosen for its physics), and the new
        # coordinates' bounds
        screen_lower=np.concatenate([base.screen_box()[0],
                                     np.maximum(np.asarray(ext.z_lower, float), -15.0)]),
        screen_upper=np.concatenate([base.screen_box()[1],
                                     np.minimum(np.asarray(ext.z_upper, float), 15.0)]),
        share_cap=base.share_cap,
    )


def _extended_hints(base: ReflectionModel, tail, starts) -> FitHints:
    """The fitter's hints of ``base`` extended by new coordinates starting at ``tail``:
    the residual column and the compiled kernel's (about the wrapped model's leading
    part; the kernel reproduces ``starts`` when it reproduced the base's), the base's
    batched starts with the new coordinates neutral; the search sizes are the defaults."""
    kernel_starts = starts if base.hints.kernel_starts is base.starts else None
    batch_starts = None
    if base.hints.batch_starts is not None:
        base_batch = base.hints.batch_starts

        def batch_starts(gamma, theta, power, weights):
            sb = np.asarray(base_batch(gamma, theta, power, weights), float)
            return np.concatenate([sb, np.broadcast_to(tail, sb.shape[:2] + tail.shape)],
                                  axis=2)

    return FitHints(residual_column=base.hints.residual_column, batch_starts=batch_starts,
                    kernel=base.hints.kernel if kernel_starts is not None else None,
                    kernel_starts=kernel_starts)


def _start_rows(z_starts, pe: int) -> np.ndarray:
    """Starting values of ``pe`` new coordinates as rows (one empty row when ``pe == 0``)."""
    if pe == 0 or len(z_starts) == 0:
        return np.zeros((1, pe))
    return np.asarray(z_starts, float).reshape(-1, pe)


# ----------------------------------------------------------------------------- patterns
def _extra_columns(base, geom, zb, derivatives, cols, dcols):
    """Wrapped basis plus new columns ``cols`` (list of (Bg|M, n)) whose derivatives with
    respect to the new coordinates are ``dcols`` (list of (column index, coord index, array))."""
    bb, dbb = base.basis(geom, zb, derivatives)
    m, n, lb = bb.shape
    basis = np.concatenate([bb] + [np.broadcast_to(c, (m, n))[..., None] for c in cols], axis=-1)
    if not derivatives:
        return basis, None
    pb = dbb.shape[-1]
    pe = 1 + max((p for _, p, _ in dcols), default=-1)
    dbasis = np.zeros((m, n, lb + len(cols), pb + pe))
    dbasis[..., :lb, :pb] = dbb
    for col, coord, arr in dcols:
        dbasis[..., lb + col, pb + coord] = arr
    return basis, dbasis


def _shifted(base, geom, zb, ze, derivatives, transform):
    """Wrapped basis on a geometry moved by one scalar shift per row (``transform(geom,
    shift (M, 1)) -> geom``); derivative along the shift by a central difference."""
    shift = ze[:, :1]
    bb, dbb = base.basis(transform(geom, shift), zb, derivatives)
    if not derivatives:
        return bb, None
    h = GEOMETRY_STEP
    plus, _ = base.basis(transform(geom, shift + h), zb, False)
    minus, _ = base.basis(transform(geom, shift - h), zb, False)
    dshift = (plus - minus) / (2.0 * h)
    m, n, lb = bb.shape
    dbasis = np.concatenate([np.broadcast_to(dbb, (m, n, lb, dbb.shape[-1])),
                             dshift[..., None]], axis=-1)
    return bb, dbasis


def _lobe_about(cos_angle, n):
    """Lobe ``(n+1)/2pi cos^n`` and ``d lobe / d ln n`` (zero beyond 90 deg)."""
    positive = cos_angle > 0
    log_cos = np.log(np.where(positive, cos_angle, 1.0))
    with np.errstate(under="ignore", over="ignore"):
        lobe, dlobe = _lobe_from_log(log_cos, positive, n)
    return lobe, dlobe * n


# ----------------------------------------------------------------------------- the catalogue
def _incidence_evaluate(base, geom, zb, ze, derivatives):
    log_cg = geom.log_cos_gamma
    w = ze[:, :1]
    factor = np.exp(w * log_cg)  # cos^w(gamma)
    bb, dbb = base.basis(geom, zb, derivatives)
    basis = bb * factor[..., None]
    if not derivatives:
        return basis, None
    dw = basis * log_cg[..., None]
    dbasis = np.concatenate([dbb * factor[..., None, None], dw[..., None]], axis=-1)
    return basis, dbasis


INCIDENCE_REFLECTANCE = Extension(
    name="incidence_reflectance",
    summary="the reflection factor depends on the angle of incidence: K(gamma) = K cos^w(gamma)",
    params=(Parameter("w", "1", -8.0, 8.0,
                      "exponent of cos(gamma) in the reflection factor K(gamma) = K cos^w(gamma)"),),
    nonlinear_names=("w",),
    z_lower=(-8.0,), z_upper=(8.0,),
    z_starts=((0.0,), (1.0,), (-1.0,)),
    n_linear=0, alpha_nonneg=(),
    evaluate=_incidence_evaluate,
    natural=lambda ze, ae, nat, k: ze[:, :1],
    internal=lambda p, nat, k: (p[:, :1], np.zeros((p.shape[0], 0))),
    formula="every term times cos^w(gamma)",
    reference="the paper's Fig. 11 (K varies with the angle of incidence)",
)


def _tilt_geometry(geom, tilt):
    s = np.sin(geom.gamma)
    return geom.tilted(tilt * s * np.abs(s))


OFFSPECULAR_PEAK = Extension(
    name="offspecular_peak",
    summary="the specular lobe's axis is tilted from the mirror direction toward grazing by "
            "tilt sin^2(gamma)",
    params=(Parameter("tilt", "deg", -20.0, 30.0,
                      "tilt of the specular axis from the mirror direction toward grazing, at "
                      "grazing incidence (at gamma: tilt sin^2(gamma)); < 0 = toward the normal"),),
    nonlinear_names=("tilt_rad",),
    z_lower=(np.radians(-20.0),), z_upper=(np.radians(30.0),),
    z_starts=((0.0,), (np.radians(8.0),), (np.radians(-5.0),)),
    n_linear=0, alpha_nonneg=(),
    evaluate=lambda base, geom, zb, ze, d: _shifted(base, geom, zb, ze, d, _tilt_geometry),
    natural=lambda ze, ae, nat, k: np.degrees(ze[:, :1]),
    internal=lambda p, nat, k: (np.radians(p[:, :1]), np.zeros((p.shape[0], 0))),
    formula="phi -> phi + tilt sin^2(gamma) in the specular lobe",
    reference="Torrance and Sparrow 1967 (the paper's ref. 26): off-specular peaks",
)


def _offset_geometry(geom, delta):
    return geom.shifted(delta)


ANGLE_OFFSET = Extension(
    name="angle_offset",
    summary="a constant zero error of the receiver arm: the true receiver angle is theta + delta",
    params=(Parameter("delta", "deg", -15.0, 15.0,
                      "receiver-arm zero error: the true receiver angle is theta + delta"),),
    nonlinear_names=("delta_rad",),
    z_lower=(np.radians(-15.0),), z_upper=(np.radians(15.0),),
    z_starts=((0.0,), (np.radians(2.0),), (np.radians(-2.0),)),
    n_linear=0, alpha_nonneg=(),
    evaluate=lambda base, geom, zb, ze, d: _shifted(base, geom, zb, ze, d, _offset_geometry),
    natural=lambda ze, ae, nat, k: np.degrees(ze[:, :1]),
    internal=lambda p, nat, k: (np.radians(p[:, :1]), np.zeros((p.shape[0], 0))),
    formula="theta -> theta + delta",
    reference="goniometer zero error",
)


def _background_evaluate(base, geom, zb, ze, derivatives):
    ones = np.ones(np.broadcast_shapes(geom.gamma.shape, geom.theta.shape))
    return _extra_columns(base, geom, zb, derivatives, [ones], [])


BACKGROUND = Extension(
    name="background",
    summary="an additive constant (stray light, detector offset)",
    params=(Parameter("b", "power", -np.inf, np.inf,
                      "additive constant: stray light (> 0) or detector offset"),),
    nonlinear_names=(), z_lower=(), z_upper=(), z_starts=(),
    n_linear=1, alpha_nonneg=(False,),
    evaluate=_background_evaluate,
    natural=lambda ze, ae, nat, k: ae[:, :1],
    internal=lambda p, nat, k: (np.zeros((p.shape[0], 0)), p[:, :1]),
    formula="+ b",
    reference="",
)


def _retro_evaluate(base, geom, zb, ze, derivatives):
    n = np.exp(ze[:, :1])
    lobe, dlobe = _lobe_about(np.cos(geom.theta - geom.gamma), n)
    return _extra_columns(base, geom, zb, derivatives, [lobe], [(0, 0, dlobe)])


def _share_natural(ze, ae, nat, k):
    """New lobe's share of all the reflected power, ``alpha / (K + alpha)``, and its index."""
    return np.column_stack([ae[:, 0] / (k + ae[:, 0]), np.exp(ze[:, 0])])


def _share_internal(p, nat, k):
    share = np.clip(p[:, 0], 0.0, 1.0 - 1e-12)
    return np.log(p[:, 1:2]), (k * share / (1.0 - share))[:, None]


RETROREFLECTION = Extension(
    name="retroreflection",
    summary="an extra lobe about the direction back to the source (theta = gamma)",
    params=(Parameter("a_r", "1", 0.0, 1.0,
                      "share of the reflected power in the retro lobe (K a_r / (1 - a_r))"),
            Parameter("n_r", "1", 1.0, 1.0e4, "index of the retro lobe about theta = gamma")),
    nonlinear_names=("ln_n_r",),
    z_lower=(0.0,), z_upper=(np.log(1.0e4),),
    z_starts=((np.log(20.0),), (np.log(3.0),), (np.log(150.0),)),
    n_linear=1, alpha_nonneg=(True,),
    evaluate=_retro_evaluate,
    natural=_share_natural,
    internal=_share_internal,
    formula="+ K a_r/(1-a_r) (n_r+1)/2pi cos^n_r(theta - gamma)",
    reference="the paper's Eq. 7 with a lobe pointing back to the source",
)


def _halo_evaluate(base, geom, zb, ze, derivatives):
    n = np.exp(ze[:, :1])
    with np.errstate(under="ignore", over="ignore"):
        lobe, dlobe = _lobe_from_log(geom.log_cos_phi, geom.pos_phi, n)
    return _extra_columns(base, geom, zb, derivatives, [lobe], [(0, 0, dlobe * n)])


SPECULAR_HALO = Extension(
    name="specular_halo",
    summary="a second, broader lobe about the mirror direction (three-component model)",
    params=(Parameter("a_h", "1", 0.0, 1.0,
                      "share of the reflected power in the halo lobe (K a_h / (1 - a_h))"),
            Parameter("n_h", "1", 0.5, 1.0e4, "index of the halo lobe about the mirror direction")),
    nonlinear_names=("ln_n_h",),
    z_lower=(np.log(0.5),), z_upper=(np.log(1.0e4),),
    z_starts=((np.log(6.0),), (np.log(2.0),), (np.log(20.0),)),
    n_linear=1, alpha_nonneg=(True,),
    evaluate=_halo_evaluate,
    natural=_share_natural,
    internal=_share_internal,
    formula="+ K a_h/(1-a_h) (n_h+1)/2pi cos^n_h(phi)",
    reference="the paper, section 3.3 (Eq. 7 with three components)",
)


# ----------------------------------------------------------------------------- per table
#: the name of the gain drift between angles of incidence (:func:`gain_drift`); not in
#: :data:`EXTENSIONS`: its parameters are the table's own angles of incidence
GAIN_DRIFT = "gain_drift"
#: the largest change of gain the extension allows at one angle of incidence: a factor 2
GAIN_BOUND = float(np.log(2.0))
#: readings an angle of incidence needs for its own gain factor (fewer: factor 1)
GAIN_MIN_READINGS = 3
#: angles of incidence (deg) within this of a level share its factor
_GAIN_TOL_DEG = 1e-6


@dataclass(frozen=True)
class GainDrift(Extension):
    """The :func:`gain_drift` extension of one table; ``levels_deg``: the angles of
    incidence that carry a factor (the last one's is implied)."""

    levels_deg: tuple[float, ...] = ()


def gain_levels(gamma_deg, min_readings: int = GAIN_MIN_READINGS) -> np.ndarray:
    """The angles of incidence of a table (degrees, sorted) with at least ``min_readings``
    readings each: those a gain drift gives a factor of its own."""
    levels, counts = np.unique(np.round(np.asarray(gamma_deg, float), 6), return_counts=True)
    return levels[counts >= int(min_readings)]


def _gain_contrast(geom, levels_rad) -> np.ndarray:
    """``(rows, n, G - 1)``: +1 where a point is at level k, -1 at the last level (whose
    log-factor is minus the sum of the others), 0 elsewhere (factor 1)."""
    tol = np.radians(_GAIN_TOL_DEG)
    onehot = (np.abs(geom.gamma[..., None] - levels_rad) < tol).astype(float)
    return onehot[..., :-1] - onehot[..., -1:]


def _gain_evaluate(levels_rad):
    def evaluate(base, geom, zb, ze, derivatives):
        contrast = _gain_contrast(geom, levels_rad)
        factor = np.exp(np.sum(contrast * ze[:, None, :], axis=-1))  # (M, n)
        bb, dbb = base.basis(geom, zb, derivatives)
        basis = bb * factor[..., None]
        if not derivatives:
            return basis, None
        dgain = basis[..., None] * contrast[:, :, None, :]
        dbasis = np.concatenate([dbb * factor[..., None, None],
                                 np.broadcast_to(dgain, basis.shape + (ze.shape[1],))],
                                axis=-1)
        return basis, dbasis
    return evaluate


def gain_drift(levels_deg) -> GainDrift:
    """A gain drift between the angles of incidence ``levels_deg`` (degrees, at least 2):
    every reading at the angle of incidence ``gamma_k`` times its own factor ``g_k``
    (the detector's or the source's gain changed between the runs), the factors'
    geometric mean 1 (the model's ``K`` keeps the mean scale, so the extension nests
    the wrapped model at ``g = 1`` and every smooth law that only scales each angle's
    curve, such as ``incidence_reflectance``). Readings at other angles: factor 1.
    New parameters ``gain_<gamma>``, the factors of every level but the last by
    ``|gamma|`` (that one is ``1 / prod`` of the others); internal coordinates their logarithms, within +-ln 2.

    Not a registered extension: its parameters are one table's angles of incidence, so
    the diagnosis builds it for the table it diagnoses
    (:func:`irreflect.diagnose.diagnose`); a model built with it does not round-trip
    through :func:`~irreflect.models.get_model` by name."""
    levels = np.unique(np.round(np.asarray(levels_deg, float), 6))
    levels = levels[np.lexsort((levels, np.abs(levels)))]  # by |gamma|
    if levels.size < 2:
        raise IrreflectError(f"gain_drift needs at least 2 angles of incidence, found "
                             f"{levels.size}")
    k = levels.size - 1
    return GainDrift(
        name=GAIN_DRIFT,
        summary="a gain drift between angles of incidence: every reading at one angle of "
                "incidence times its own factor (a measurement artefact)",
        params=tuple(Parameter(f"gain_{g:g}", "1", 0.5, 2.0,
                               f"gain factor of the readings at gamma = {g:g} deg (the "
                               "factors' geometric mean is 1)") for g in levels[:-1]),
        nonlinear_names=tuple(f"ln_gain_{g:g}" for g in levels[:-1]),
        z_lower=(-GAIN_BOUND,) * k, z_upper=(GAIN_BOUND,) * k,
        z_starts=((0.0,) * k,),
        n_linear=0, alpha_nonneg=(),
        evaluate=_gain_evaluate(np.radians(levels)),
        natural=lambda ze, ae, nat, kk: np.exp(ze[:, :k]),
        internal=lambda p, nat, kk: (np.log(np.clip(p[:, :k], 1e-300, None)),
                                     np.zeros((p.shape[0], 0))),
        formula="every term at gamma_k times g_k, prod g_k = 1",
        reference="a detector or source gain that changed between the runs",
        levels_deg=tuple(float(g) for g in levels),
    )


# ----------------------------------------------------------------------------- registry
#: name -> callable ``extend(base: ReflectionModel) -> ReflectionModel``
EXTENSIONS: dict[str, Callable[[ReflectionModel], ReflectionModel]] = {
    e.name: e for e in (INCIDENCE_REFLECTANCE, OFFSPECULAR_PEAK, RETROREFLECTION, ANGLE_OFFSET,
                        BACKGROUND, SPECULAR_HALO)
}
#: the catalogue of the issue, in a fixed order
CATALOGUE = tuple(EXTENSIONS)


def register_extension(name: str, extension: Callable[[ReflectionModel], ReflectionModel]) -> None:
    """Add an extension to the registry; the diagnosis then tries it like the built-in ones.

    ``extension(base)`` must return a :class:`ReflectionModel` that contains ``base`` as a
    special case, whose ``nonlinear_names``, ``params`` and linear columns start with those
    of ``base`` (then the diagnosis can start it from the base optimum), and whose
    ``extensions`` lists ``name`` (an :class:`Extension` does all of this).
    """
    if not isinstance(name, str) or not name or "+" in name:
        raise IrreflectError(f"extension name must be a non-empty string without '+', got {name!r}")
    if not callable(extension):
        raise IrreflectError(
            f"extension '{name}' must be callable as extension(base) -> ReflectionModel, "
            f"got {type(extension).__name__}"
        )
    EXTENSIONS[name] = extension


def extension_names() -> list[str]:
    return list(EXTENSIONS)


def get_extension(name: str) -> Callable[[ReflectionModel], ReflectionModel]:
    """The extension registered under ``name`` (one-line error listing the valid names)."""
    if name not in EXTENSIONS:
        raise unknown_name("extension", str(name), EXTENSIONS)
    return EXTENSIONS[name]


def warm_starts(model: ReflectionModel, base_z, gamma=None, theta=None, power=None):
    """Starts of ``model`` (an extension of a model whose optimum is ``base_z``) that begin at
    that optimum, one per starting value of the new coordinates; None if ``model`` does not
    extend ``base_z``'s model by appending coordinates. For extensions that are not an
    :class:`Extension`, the new coordinates' starting values are taken from
    ``model.starts(gamma, theta, power)`` (radians) when the data are given."""
    base_z = np.asarray(base_z, float).ravel()
    pb = base_z.size
    ext = model.extension
    wrapped = model.wrapped
    if wrapped is None or wrapped.n_nonlinear != pb or model.n_nonlinear < pb:
        return None
    pe = model.n_nonlinear - pb
    if isinstance(ext, Extension):
        tails = _start_rows(ext.z_starts, pe)
    elif gamma is not None and pe:
        tails = np.unique(np.atleast_2d(model.starts(gamma, theta, power))[:, pb:], axis=0)
    else:
        tails = np.zeros((0, pe))
    if tails.shape[0] == 0:
        tails = np.zeros((1, pe))
    rows = [np.concatenate([base_z, t]) for t in tails]
    return np.clip(np.array(rows), model.z_lower, model.z_upper)


__all__ = [
    "CATALOGUE", "EXTENSIONS", "Extension", "GAIN_DRIFT", "GainDrift", "applied_extensions",
    "apply_extension", "base_of", "extension_names", "gain_drift", "gain_levels",
    "get_extension", "register_extension",
    "warm_starts",
]
