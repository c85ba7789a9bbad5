"""Surface materials in 3D: the plane-of-incidence reflection models extended to every direction.

The fitted models describe the reflected radiant intensity in the plane of incidence. In a
room light leaves a surface point in every direction, so each model is extended to 3D. Two
surface models are available (``brdf=``):

**"reciprocal" (default).** A BRDF that obeys Helmholtz reciprocity, ``f(i, o) = f(o, i)``, by
construction: a non-negative sum of symmetric diffuse, mirror-lobe and retro-lobe terms
(:mod:`.reciprocal`) fitted to the material's fitted in-plane curve over its measured angles
of incidence. The fit's R^2 against that curve, and on the material's own measurement table
when it can be read, are in :attr:`Material.fidelity`. Its albedo (reflected / incident
power) varies with the angle of incidence as the fitted curve's does (a reciprocal BRDF
cannot be rescaled per angle of incidence without losing reciprocity): ``rho`` scales it so
that the reflectance under diffuse illumination, ``int albedo(g) sin 2g dg``, is ``rho``
(``"K"``: the fitted power was BRDF x cos(theta) in 1/sr and the fit's own scale is kept).
Either way the albedo must stay <= 1 at every incidence: with ``"K"`` a larger one is an
error; with ``rho`` the scale is lowered until it holds and the material carries a warning.

**"paper".** The paper's own components as it describes them (section 3.4: "the 3D diagrams
for each component are a revolution volume along their orientation axes"), not reciprocal:

* **two-lobe** (Eqs. 19-22): the diffuse lobe ``(1-a_s)(n_d+1)/2pi cos^n_d(theta)`` is a
  solid of revolution about the surface normal (``theta`` = angle between the outgoing
  direction and the normal); the specular lobe ``a_s (n_s+1)/2pi cos^n_s(phi)`` is a solid of
  revolution about the mirror direction of the incident ray (``phi`` = angle between the
  outgoing and the mirror direction). ``a_s``, ``n_d`` and ``n_s`` follow the fitted laws
  ``u cos^v(gamma)`` of the angle of incidence ``gamma``.
* **single-lobe** (Eq. 6): one lobe of revolution about the mirror direction.
* **n-lobe** (Eq. 7): lobe ``i`` is a solid of revolution about the axis that lies in the
  plane of incidence at ``t_i gamma`` from the normal towards the mirror side.
* **phong**: ``(1-k_s) cos(theta)`` about the normal plus ``k_s cos^n(phi)`` about the
  mirror direction.
* **any other registered model** (literature models): a *plane-of-incidence-equivalent*
  evaluation. An outgoing direction at angle ``phi`` from the mirror direction and azimuth
  ``psi`` about it (``psi = 0`` towards the normal, ``180 deg`` towards grazing) is given
  ``(1+cos psi)/2 P(gamma, gamma - phi) + (1-cos psi)/2 P(gamma, gamma + phi)``: exact in
  the plane of incidence, a solid of revolution about the mirror direction for lobes about
  it, interpolated in between. The model is tabulated (0.25 deg in gamma and theta).

The shape ``s(gamma, omega)`` is scaled per angle of incidence so that the reflected power is
the total reflectance times the incident power, ``f = rho(gamma) s / S(gamma)`` with ``S`` the
integral of ``s`` over the hemisphere (or ``f = K s``, ``rho(gamma) = K S(gamma)``); in the
plane of incidence it is exactly the fitted curve up to that per-gamma scale. The fitted
share and index laws are used up to the largest measured angle of incidence and held
constant beyond it; the specular share saturates at 1 by irreflect's one rule,
:func:`irreflect.models.base.cap_share` (the kernels compile the same function).

Both forms reflect nothing below the surface, and in both the reciprocal family's fit and
the paper's laws use ``min(1, u_as cos^v_as(gamma))`` for the two-lobe share.
"""

from __future__ import annotations

import functools
import math
import numbers
import re
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .. import schema as sc
from .._atomic import atomic_path
from .._inputs import parse_json, read_text
from .._jsonio import dumps
from ..errors import IrreflectError
from ..models import get_model
from ..models.base import cap_share
from ..validation import check_output_path
from . import reciprocal as _recip
from .kernels import (  # noqa: F401  (the table constants are re-exported)
    GAMMA_NODES,
    KIND_LAMBERTIAN,
    KIND_LOBES,
    KIND_RECIPROCAL,
    KIND_TABLE,
    LOBE_MAX,
    N_COS,
    N_GAMMA,
    TABLE_GAMMA,
    TABLE_THETA,
    eval_directions,
    hemisphere_integral,
    pack_materials,
)

#: format of a material file written by ``irreflect fit --save``
MATERIAL_FORMAT = "irreflect-material"
MATERIAL_FORMAT_VERSION = 1
#: largest angle of incidence at which the share/index laws are evaluated
GAMMA_LAW_MAX = np.radians(89.5)

#: the surface models of a room: reciprocal by construction (default) or the paper's form
BRDFS = ("reciprocal", "paper")
PAPER_WARNING = ("the paper's surface model is not reciprocal (its share and lobe indices "
                 "follow the angle of incidence only): swapping emitter and receiver changes "
                 "the answer on glossy materials; the default 'reciprocal' model does not")


@dataclass(frozen=True)
class Material:
    """A surface material ready for 3D evaluation.

    Attributes
    ----------
    name : str
    kind : int
        0 Lambertian, 1 the paper's lobes of revolution, 2 the paper's tabulated
        plane-of-incidence equivalent, 3 the reciprocal family.
    source : str
        Where it came from (``lambertian(0.8)``, ``terrazzo.json (two-lobe)``, ...).
    reflectance : float or None
        Total reflectance: the constant albedo of the paper's form, the reflectance under
        diffuse illumination of the reciprocal form (None when ``scale == "K"``).
    scale : str
        ``"reflectance"`` or ``"K"`` (see the module docstring).
    brdf : str
        ``"reciprocal"`` or ``"paper"`` (Lambertian materials are both).
    model, params, stderr : the fitted model spec and natural parameters (None for Lambertian)
    lobes : ndarray (L, 5)
        Paper form: ``[tilt t, c0, c1, u_n, v_n]``: axis at ``t gamma`` from the normal,
        weight ``c0 + c1 a(gamma)``, index ``u_n cos^v_n(gamma)``.
    share : (u_a, v_a)
        Paper form: ``a(gamma) = min(1, u_a cos^v_a(gamma))`` (the two-lobe specular share).
    gamma_max_rad : float
        The laws are evaluated at ``min(gamma, gamma_max_rad)``.
    rho_table, norm_table : ndarray (N_GAMMA,)
        The albedo ``rho(gamma)`` at :data:`GAMMA_NODES`, and the paper form's per-gamma scale.
    table : ndarray (361, 721) or None
        Paper form, kind 2: the plane-of-incidence shape at :data:`TABLE_GAMMA` x :data:`TABLE_THETA`.
    terms : ndarray (T, 4)
        Reciprocal form: ``[kind, index, q, amplitude]`` per term (:mod:`.kernels`).
    term_albedo : ndarray (T, N_GAMMA)
        Reciprocal form: each term's albedo (the sampler's mixture weights).
    fidelity : dict
        Reciprocal form: how far its in-plane curve departs from the fitted one (see
        :func:`from_model`).
    warnings : tuple of str
        What the user should know about this material (printed by ``irreflect room``).
    requested : float, "K" or None
        The reflectance asked for (before an energy cap).
    energy_cap : ndarray (N_COS,) or None
        Reciprocal form: ``g(cos theta)``, the factor ``g(cos theta_i) g(cos theta_o)`` that
        keeps the albedo <= 1 where the scaled fit would exceed it (None: not needed).
    """

    name: str
    kind: int
    source: str
    reflectance: float | None
    scale: str = "reflectance"
    model: str | None = None
    params: dict | None = None
    stderr: dict | None = None
    lobes: np.ndarray = field(default_factory=lambda: np.zeros((0, 5)), repr=False)
    share: tuple[float, float] = (0.0, 0.0)
    gamma_max_rad: float = float(GAMMA_LAW_MAX)
    rho_table: np.ndarray = field(default_factory=lambda: np.zeros(N_GAMMA), repr=False)
    norm_table: np.ndarray = field(default_factory=lambda: np.zeros(N_GAMMA), repr=False)
    table: np.ndarray | None = field(default=None, repr=False)
    metadata: dict = field(default_factory=dict, repr=False)
    brdf: str = "reciprocal"
    terms: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)), repr=False)
    term_albedo: np.ndarray = field(default_factory=lambda: np.zeros((0, N_GAMMA)), repr=False)
    fidelity: dict = field(default_factory=dict, repr=False)
    warnings: tuple[str, ...] = ()
    requested: object = None
    energy_cap: np.ndarray | None = field(default=None, repr=False)

    @property
    def is_lambertian(self) -> bool:
        return self.kind == KIND_LAMBERTIAN

    @property
    def is_reciprocal(self) -> bool:
        return self.kind in (KIND_LAMBERTIAN, KIND_RECIPROCAL)

    def rho(self, gamma_rad) -> np.ndarray:
        """Albedo (reflected / incident power) at the angle of incidence ``gamma_rad``
        (radians, magnitude)."""
        return np.interp(np.abs(gamma_rad), GAMMA_NODES, self.rho_table)

    @property
    def diffuse_reflectance(self) -> float:
        """Reflectance under uniform (diffuse) illumination: ``int rho(g) sin 2g dg``."""
        g = GAMMA_NODES
        return float(np.trapezoid(self.rho_table * np.sin(2 * g), g))

    def renamed(self, name: str) -> Material:
        return replace(self, name=name)

    def describe(self) -> str:
        if self.kind == KIND_LAMBERTIAN:
            return f"Lambertian, reflectance {self.reflectance:g}"
        lo, hi = self.rho_table[:-1].min(), self.rho_table[:-1].max()
        if self.kind == KIND_RECIPROCAL:
            fid = self.fidelity
            text = (f"{self.model}, reciprocal form ({len(self.terms)} terms; diffuse reflectance "
                    f"{self.diffuse_reflectance:.3g}, albedo {lo:.3g}-{hi:.3g} over incidence; "
                    f"in-plane R^2 {fid.get('r2_curve', float('nan')):.4f} against the fitted curve")
            if fid.get("r2_table_reciprocal") is not None:
                text += (f", {fid['r2_table_reciprocal']:.4f} on its table (paper form "
                         f"{fid['r2_table_paper']:.4f})")
            return text + ")"
        rho = (f"reflectance {self.reflectance:g}" if self.scale == "reflectance"
               else f"reflectance K x lobes = {lo:.3g}-{hi:.3g}")
        return f"{self.model}, paper form, not reciprocal ({rho})"

    def intensity(self, gamma_deg, theta_deg, azimuth_deg=0.0) -> np.ndarray:
        """Reflected radiant intensity per unit incident power (1/sr) in 3D.

        ``gamma_deg``: angle of incidence (its sign is ignored); the outgoing direction is
        at ``theta_deg`` from the normal (positive towards the mirror side) and rotated by
        ``azimuth_deg`` about the normal out of the plane of incidence (0 = in the plane).
        Evaluated by the same compiled code as the simulation.
        """
        din, dout, shape = _directions(gamma_deg, theta_deg, azimuth_deg)
        return eval_directions(pack_materials([self]), 0, din, dout, False).reshape(shape)

    def brdf_value(self, incident, outgoing) -> np.ndarray:
        """The BRDF ``f(i, o)`` (1/sr) for rows of unit vectors ``i`` (towards the light) and
        ``o`` (outgoing), with the surface normal +z: for reciprocity checks."""
        i = np.atleast_2d(np.asarray(incident, float))
        o = np.atleast_2d(np.asarray(outgoing, float))
        return eval_directions(pack_materials([self]), 0, np.ascontiguousarray(-i),
                               np.ascontiguousarray(o), True)


def _directions(gamma_deg, theta_deg, azimuth_deg):
    g = np.radians(np.abs(np.asarray(gamma_deg, float)))
    t = np.radians(np.asarray(theta_deg, float))
    a = np.radians(np.asarray(azimuth_deg, float))
    g, t, a = np.broadcast_arrays(g, t, a)
    din = np.stack([np.sin(g), np.zeros_like(g), -np.cos(g)], axis=-1)
    dout = np.stack([np.sin(t) * np.cos(a), np.sin(t) * np.sin(a), np.cos(t)], axis=-1)
    return np.ascontiguousarray(din.reshape(-1, 3)), np.ascontiguousarray(dout.reshape(-1, 3)), g.shape


# ----------------------------------------------------------------------------- construction
def lambertian(rho: float, name: str | None = None) -> Material:
    """An ideal diffuse (Lambertian) surface of total reflectance ``rho``."""
    rho = _check_rho(rho, name or "lambertian")
    return Material(name=name or f"lambertian({rho:g})", kind=KIND_LAMBERTIAN,
                    source=f"lambertian({rho:g})", reflectance=rho,
                    lobes=np.array([[0.0, 1.0, 0.0, 1.0, 0.0]]),
                    rho_table=np.full(N_GAMMA, rho), norm_table=np.full(N_GAMMA, rho),
                    requested=rho)


def parse_reflectance(value, name: str = "--reflectance"):
    """A material file's reflectance: a number in [0, 1], ``"K"``, or None."""
    if value is None:
        return None
    if isinstance(value, str) and value.strip().upper() == "K":
        return "K"
    return _check_rho(value, name)


def _check_rho(rho, name) -> float:
    """``name``: a material's name, or an option (``--reflectance``), named as such."""
    what = (str(name) if str(name).startswith("--")
            else f"material '{name}': reflectance")
    try:
        rho = float(rho)
    except (TypeError, ValueError) as exc:
        raise IrreflectError(f"{what} must be a number in [0, 1] or \"K\"; found "
                             f"{rho!r}") from exc
    if not (0.0 <= rho <= 1.0) or not math.isfinite(rho):
        raise IrreflectError(f"{what} must be in [0, 1] (reflected power cannot exceed the "
                             f"incident power); found {rho:g}")
    return rho


def check_brdf(brdf: str) -> str:
    if brdf not in BRDFS:
        raise IrreflectError(f"surface model must be one of {', '.join(BRDFS)}; found {brdf!r}")
    return brdf


def from_model(model, params: dict, reflectance, *, name: str = "material",
               source: str | None = None, stderr: dict | None = None,
               gamma_max_deg: float | None = None, metadata: dict | None = None,
               brdf: str = "reciprocal") -> Material:
    """A material from a registered reflection model and its natural parameters.

    Parameters
    ----------
    model : str
        Model spec (``irreflect models``), e.g. ``"two-lobe"``, ``"phong"``, ``"n-lobe:2"``.
    params : dict
        Natural parameters by name (all of ``get_model(model).param_names``).
    reflectance : float in [0, 1] or "K"
        Total reflectance (see the module docstring); or ``"K"``: the power the model was
        fitted to was BRDF x cos(theta) (1/sr), so ``K`` already sets the reflectance.
    gamma_max_deg : float, optional
        Largest measured angle of incidence: the paper form's share and index laws are held
        constant beyond it, and the reciprocal form is fitted up to it (default 89.5 deg;
        a material file's ``gamma_range_deg`` in ``metadata`` gives the lower end too).
    brdf : "reciprocal" or "paper"
        The surface model (module docstring). The reciprocal form's ``fidelity``:
        ``r2_curve`` (weighted R^2 of its in-plane curve against the fitted curve over the
        fitted angles of incidence), ``gamma_range_deg``, ``terms``, and when the
        material's measurement table (``metadata["data_file"]``) can be read,
        ``r2_table_reciprocal`` and ``r2_table_paper`` (both forms' in-plane curves on it,
        in the fit's units) and ``table``.
    """

    check_brdf(brdf)
    model_obj = get_model(model)
    outside = _check_model_arguments(model_obj, params, gamma_max_deg, name)
    spec = model if isinstance(model, str) else model_obj.name
    names = tuple(model_obj.param_names)
    missing = [p for p in names if p not in params]
    extra = [p for p in params if p not in names]
    if missing or extra:
        raise IrreflectError(
            f"material '{name}': model {spec} takes parameters {', '.join(names)}; "
            f"{'missing ' + ', '.join(missing) if missing else ''}"
            f"{'; ' if missing and extra else ''}{'unknown ' + ', '.join(extra) if extra else ''}"
        )
    values = {k: float(params[k]) for k in names}
    bad = [k for k, v in values.items() if not math.isfinite(v)]
    if bad:
        raise IrreflectError(f"material '{name}': parameters {', '.join(bad)} must be finite numbers")
    gmax = GAMMA_LAW_MAX if gamma_max_deg is None else min(np.radians(abs(gamma_max_deg)),
                                                            GAMMA_LAW_MAX)
    if isinstance(reflectance, str):
        if reflectance.strip().upper() != "K":
            raise IrreflectError(f"material '{name}': reflectance must be a number in [0, 1] or "
                                 f"\"K\"; found '{reflectance}'")
        scale, rho, requested = "K", None, "K"
        K = values.get("K", 1.0)
    else:
        scale, rho = "reflectance", _check_rho(reflectance, name)
        requested = rho
        K = 1.0
    lobes, share = _lobes_for(model_obj.name, values)
    metadata = dict(metadata or {})
    unphysical = negative_power(model_obj, values, gmax)
    if outside is not None and unphysical is None:
        raise IrreflectError(outside)
    if unphysical:
        metadata["unphysical"] = unphysical if outside is None else (
            f"{unphysical} ({outside.removeprefix(f'material {name!r}: ')})")
    base = dict(name=name, source=source or f"{spec} {values}", reflectance=rho, scale=scale,
                model=spec, params=values, stderr=stderr, gamma_max_rad=float(gmax),
                metadata=metadata, requested=requested)
    if lobes is not None:
        paper = Material(kind=KIND_LOBES, lobes=lobes, share=share, brdf="paper", **base)
        S = lobe_hemisphere_integral(lobes, share, gmax, GAMMA_NODES)
    else:
        table = _plane_table(model_obj, values, gmax)
        paper = Material(kind=KIND_TABLE, table=table, brdf="paper", **base)
        S = table_hemisphere_integral(paper)
    if outside is not None and not (np.all(np.isfinite(S)) and np.all(S > 0)):
        raise IrreflectError(outside)  # unphysical and not even simulable
    _check_reflects(paper, S)
    if brdf == "paper":
        mat = _with_scale(paper, S, K)
    else:
        mat = _reciprocal(paper, K)
    if outside is not None and not (np.all(np.isfinite(mat.rho_table))
                                    and np.all(np.isfinite(mat.norm_table))):
        raise IrreflectError(outside)  # unphysical and not even simulable
    return mat


def _check_model_arguments(model_obj, params, gamma_max_deg, name) -> str | None:
    """:func:`from_model`'s arguments: params a table of finite numbers, gamma_max_deg None
    or in (0, 90]. Returns the message of a coefficient outside the model's bounds (None
    when all lie within): :func:`from_model` refuses it, unless the model then predicts
    negative power, which makes the material unphysical (refused by ``irreflect room``
    unless ``--allow-unphysical``, :func:`irreflect.room.checks.material_notes`)."""
    if not isinstance(params, dict):
        raise IrreflectError(f"material '{name}': params must be a table NAME: VALUE of the "
                             f"parameters of {model_obj.name}; found {sc.found(params)}")
    outside = None
    try:
        check_params(model_obj, params, f"material '{name}'")
    except IrreflectError as exc:
        if any(not isinstance(v, numbers.Real) or isinstance(v, bool)
               or sc.as_float(v) is None or not math.isfinite(sc.as_float(v))
               for v in params.values()):
            raise
        outside = str(exc)
    if gamma_max_deg is not None:
        x = sc.as_float(gamma_max_deg)
        if x is None or not 0 <= x <= 90:
            raise IrreflectError(f"material '{name}': gamma_max_deg must be a number from 0 to "
                                 f"90 (degrees) or None; found {sc.found(gamma_max_deg)}")
    return outside


def negative_power(model_obj, values: dict, gamma_max: float) -> str | None:
    """Where a model predicts negative power in the range a room uses it (in the plane of
    incidence, ``|gamma| <= gamma_max`` radians, ``|theta| < 90`` deg): one line, or None.
    A negative reflection is unphysical; the room would clip it to 0 and so simulate
    another curve than the one fitted."""
    params = np.array([values[k] for k in model_obj.param_names], float)
    g = np.linspace(0.0, gamma_max, 60)
    t = np.radians(np.linspace(-89.5, 89.5, 359))
    G, T = np.meshgrid(g, t, indexing="ij")
    with np.errstate(all="ignore"):
        p = np.asarray(model_obj.predict(params, -G, T), float)
    finite = np.isfinite(p)
    if not finite.any():
        return "it predicts no finite power in the room's range"
    peak = np.max(np.abs(p[finite]))
    low = np.where(finite, p, np.inf)
    i = np.unravel_index(int(np.argmin(low)), low.shape)
    if low[i] >= -1e-9 * peak:
        return None
    return (f"its model predicts negative power ({low[i]:.3g}, {abs(low[i]) / peak:.2%} of the "
            f"peak) at gamma = {np.degrees(G[i]):.3g} deg, theta = {np.degrees(T[i]):.3g} deg; "
            f"{int(np.sum(low < -1e-9 * peak))} of {low.size} in-plane directions are negative")


def fit_notes(mat: Material) -> list[str]:
    """What the fit behind a material said of itself (its material file's verdict and
    warnings, see ``irreflect fit --save``) and whether its model predicts negative power
    in the room: the lines ``irreflect room`` prints for every material it uses."""
    meta = mat.metadata or {}
    lines = []
    verdict = meta.get("verdict")
    if isinstance(verdict, dict) and verdict.get("summary"):
        lines.append(str(verdict["summary"]))
    lines += [f"warning: {w}" for w in (meta.get("warnings") or [])]
    if meta.get("unphysical"):
        lines.append(f"UNPHYSICAL: {meta['unphysical']}")
    return lines


def _check_reflects(mat: Material, S: np.ndarray) -> None:
    if np.any(~np.isfinite(S)) or np.any(S <= 0):
        raise IrreflectError(f"material '{mat.name}': its lobes reflect nothing above the surface "
                             "at some angle of incidence; check the coefficients")


def _with_scale(mat: Material, S: np.ndarray, K: float) -> Material:
    if mat.scale == "K":
        rho = K * S
        _check_energy_K(mat, rho)
        norm = np.full(N_GAMMA, K)
    else:
        rho = np.full(N_GAMMA, mat.reflectance)
        norm = mat.reflectance / S
    return replace(mat, rho_table=rho, norm_table=norm,
                   warnings=mat.warnings + (f"material '{mat.name}': {PAPER_WARNING}",))


def _check_energy_K(mat: Material, rho: np.ndarray) -> None:
    worst = int(np.argmax(rho))
    if rho[worst] > 1.0 + 1e-9:
        raise IrreflectError(
            f"material '{mat.name}': with reflectance \"K\" the total reflectance K x "
            f"(integral of the lobes) reaches {rho[worst]:.4g} at gamma = "
            f"{np.degrees(GAMMA_NODES[worst]):.1f} deg, more than the incident power; give "
            "reflectance = RHO <= 1 instead (the power was not BRDF x cos(theta) in 1/sr?)")


def _gamma_range(mat: Material) -> tuple[float, float]:
    grange = mat.metadata.get("gamma_range_deg")
    hi = float(mat.gamma_max_rad)
    lo = 0.0
    if isinstance(grange, list | tuple) and len(grange) == 2:
        try:
            lo = min(np.radians(abs(float(grange[0]))), hi)
        except (TypeError, ValueError):
            lo = 0.0
    return lo, hi


def _peaks(mat: Material):
    """Receiver angles of the paper form's lobe axes at incidence g (the mirror at least)."""
    if mat.kind != KIND_LOBES:
        return lambda g: [g]
    tilts = sorted({float(t) for t in mat.lobes[:, 0]} | {1.0})
    return lambda g: [t * g for t in tilts]


#: A reciprocal form whose in-plane curve explains the fitted curve (or the material's
#: table) below this R^2 carries a warning: the room simulates a different surface.
MIN_RECIPROCAL_R2 = 0.9


def _reciprocal(paper: Material, K: float) -> Material:
    """The reciprocal form of ``paper`` (a paper-form material, any scale), see the module
    docstring; ``K`` the fit's scale (used when ``paper.scale == "K"``)."""
    lo, hi = _gamma_range(paper)
    shape = replace(paper, norm_table=np.ones(N_GAMMA), rho_table=np.ones(N_GAMMA))
    terms, coef, albedo0, r2 = _fit_reciprocal(shape, lo, hi)
    fidelity = {"r2_curve": r2, "gamma_range_deg": [float(np.degrees(lo)), float(np.degrees(hi))],
                "terms": int(len(terms))}
    fidelity.update(_table_fidelity(paper, shape, terms, coef))
    A0 = albedo0.sum(axis=0)  # per unit K, uncapped
    if paper.scale == "K":
        s, note = K, "with its fitted scale K"
    else:
        s = _scale_for(terms, coef, A0, paper.reflectance)
        note = f"at diffuse reflectance {paper.reflectance:g}"
    cap = None
    warnings = ()
    if s * A0.max() > 1.0:
        cap = _cap(s, A0, terms, coef)
        albedo = _recip.albedo_tables(terms, coef, GAMMA_NODES, cap)
        cos_nodes = np.linspace(0, 1, N_COS)
        gfac = np.interp(np.cos(GAMMA_NODES), cos_nodes, cap)
        total = s * gfac * albedo.sum(axis=0)
        for _ in range(4):  # the raised cap overshot between its nodes: lower it there
            if total.max() <= 1.0:
                break
            # g(gamma) x min(1, 1 / albedo(gamma)) brings every node to <= 1 (the outgoing
            # side's g only falls elsewhere)
            over = np.minimum(1.0, (1.0 - 1e-9) / np.maximum(total, 1e-300))
            cap = cap * np.interp(np.arccos(cos_nodes), GAMMA_NODES, over)
            albedo = _recip.albedo_tables(terms, coef, GAMMA_NODES, cap)
            gfac = np.interp(np.cos(GAMMA_NODES), cos_nodes, cap)
            total = s * gfac * albedo.sum(axis=0)
        if total.max() > 1.0:
            cap = cap / np.sqrt(total.max())
            albedo = _recip.albedo_tables(terms, coef, GAMMA_NODES, cap)
        above = float(np.degrees(GAMMA_NODES[np.argmax(s * A0 > 1.0)]))
        warnings = (f"material '{paper.name}': its reciprocal form {note} would reflect up to "
                    f"{s * A0.max():.3g} of the incident power (above gamma = {above:.1f} deg; "
                    f"measured to {np.degrees(hi):.0f} deg): capped at 1 there by a reciprocal "
                    "factor g(theta_i) g(theta_o)",)
    else:
        albedo = albedo0
    gfac = 1.0 if cap is None else np.interp(np.cos(GAMMA_NODES), np.linspace(0, 1, N_COS), cap)
    rho_table = s * gfac * albedo.sum(axis=0)
    if rho_table.max() > 1.0 + 1e-6:  # cannot happen: g <= 1 / (s A0); a failed cap is a bug
        raise IrreflectError(f"material '{paper.name}': albedo {rho_table.max():.4g} > 1 after "
                             "the energy cap (internal error)")
    rho_table = np.minimum(rho_table, 1.0)  # the cap leaves 1 + 2e-16 by rounding
    rho = None
    if paper.scale != "K":
        rho = float(np.trapezoid(rho_table * np.sin(2 * GAMMA_NODES), GAMMA_NODES))
        if rho < paper.reflectance * (1 - 2e-3):
            warnings = warnings + (
                f"material '{paper.name}': its reciprocal form reaches a diffuse reflectance of "
                f"{rho:.3g} at most (albedo 1 towards grazing incidence), not "
                f"{paper.reflectance:g}",)
    poor = [f"{value:.3g} against {what}" for key, what in
            (("r2_curve", "the fitted curve"), ("r2_table_reciprocal", "its table"))
            if (value := fidelity.get(key)) is not None
            and not (np.isfinite(value) and value >= MIN_RECIPROCAL_R2)]
    if poor:
        warnings = warnings + (
            f"material '{paper.name}': its reciprocal form, the one the room simulates, explains "
            f"its in-plane curve only to R^2 {' and '.join(poor)} (below {MIN_RECIPROCAL_R2:g}): "
            "the multipath from this surface is not the measured material's; refit it with "
            "the two-lobe model or check the fit",)
    amp = _recip.amplitude(terms, coef) * s
    table = np.column_stack([terms.astype(float), amp])
    return replace(paper, kind=KIND_RECIPROCAL, brdf="reciprocal", reflectance=rho,
                   terms=table, term_albedo=albedo * s, rho_table=rho_table,
                   norm_table=np.ones(N_GAMMA), fidelity=fidelity, warnings=warnings,
                   lobes=np.zeros((0, 5)), share=(0.0, 0.0), table=None, energy_cap=cap)


_CAP_NODES = np.linspace(0.0, np.pi / 2, 17)


def _cap(s: float, A0: np.ndarray, terms, coef, rounds: int = 5) -> np.ndarray:
    """The energy cap ``g(cos theta)`` at N_COS nodes for scale ``s``: it starts from
    ``min(1, 1 / (s A0))``, with which the albedo ``s g(gamma) int f g(o)`` is at most 1 (the
    outgoing side's g only lowers it), then is raised, never above 1, where that leaves the
    albedo below 1 (the outgoing g darkens grazing exits twice), towards albedo 1 where the
    fit exceeds it."""
    cos_nodes = np.linspace(0.0, 1.0, N_COS)
    angle = np.arccos(cos_nodes)
    g = np.minimum(1.0, 1.0 / np.maximum(s * np.interp(angle, GAMMA_NODES, A0), 1e-300))
    if g.min() >= 1.0:
        return g
    for _ in range(rounds):
        gi = np.interp(np.cos(_CAP_NODES), cos_nodes, g)
        A = s * gi * _recip.albedo_tables(terms, coef, _CAP_NODES, g).sum(axis=0)
        factor = np.interp(angle, _CAP_NODES, (np.maximum(A, 1e-12) / 0.995) ** -0.7)
        g = np.minimum(1.0, g * factor)
    return g


def _scale_for(terms, coef, A0: np.ndarray, rho: float) -> float:
    """The scale ``s`` at which the capped reciprocal form's diffuse reflectance is ``rho``
    (fixed-point iteration ``s <- s rho / D(s)``; the largest reachable when ``rho`` is not:
    capping more darkens grazing exits)."""
    w = np.sin(2 * GAMMA_NODES)
    D0 = float(np.trapezoid(A0 * w, GAMMA_NODES))
    if D0 <= 0:
        return 0.0
    s0 = rho / D0
    if s0 * A0.max() <= 1.0:
        return s0
    cos_nodes = np.linspace(0.0, 1.0, N_COS)

    def diffuse(s):
        cap = _cap(s, A0, terms, coef)
        Ag = _recip.albedo_tables(terms, coef, _CAP_NODES, cap).sum(axis=0)
        g = np.interp(np.cos(_CAP_NODES), cos_nodes, cap)
        return float(np.trapezoid(s * g * Ag * np.sin(2 * _CAP_NODES), _CAP_NODES))

    best_s, best_d = s0, diffuse(s0)
    s_ = s0
    d = best_d
    for _ in range(8):
        if abs(d - rho) < 1e-3 * rho:
            break
        s_ = s_ * rho / max(d, 1e-12)
        d = diffuse(s_)
        if d <= best_d and d < rho:  # past the largest reachable
            break
        if d > best_d or abs(d - rho) < abs(best_d - rho):
            best_s, best_d = s_, d
    return best_s


def _plane_shape(shape: Material, g, t) -> np.ndarray:
    """The paper form's in-plane intensity per unit K (its fitted curve) at (g, t) radians."""
    return np.maximum(shape.intensity(np.degrees(g), np.degrees(t)), 0.0)


def _fit_reciprocal(shape: Material, lo: float, hi: float):
    key = (shape.model, tuple(sorted((shape.params or {}).items())), round(lo, 12),
           round(hi, 12), shape.kind)
    if shape.kind == KIND_TABLE:
        key = key + (hash(shape.table.tobytes()),)
    return _fit_cached(key, shape, lo, hi)


_FIT_CACHE: dict = {}


def _fit_cached(key, shape, lo, hi):
    hit = _FIT_CACHE.get(key)
    if hit is None:
        g, t, w = _recip.plane_grid(lo, hi, _peaks(shape))
        target = _plane_shape(shape, g, t)
        if not np.any(target > 0):
            raise IrreflectError(f"material '{shape.name}': its fitted curve is zero over the "
                                 "measured angles of incidence; check the coefficients")
        terms, coef, r2 = _recip.fit_terms(g, t, w, target)
        albedo = _recip.albedo_tables(terms, coef, GAMMA_NODES)
        hit = (terms, coef, albedo, r2)
        if len(_FIT_CACHE) > 64:
            _FIT_CACHE.clear()
        _FIT_CACHE[key] = hit
    return hit


def _table_fidelity(paper: Material, shape: Material, terms, coef) -> dict:
    """R^2 of both forms' in-plane curves on the material's own measurement table, when
    ``metadata["data_file"]`` names a table that can be read (in the fit's units)."""
    path = _find_table(paper.metadata.get("data_file"))
    if path is None or not paper.params or "K" not in paper.params:
        return {}
    try:
        meas = _read_table(str(path))
    except Exception:  # noqa: BLE001 - an unreadable table only loses this diagnostic
        return {}
    K = paper.params["K"]
    g = np.radians(np.abs(meas.gamma_deg))
    t = np.radians(meas.theta_deg)
    y = meas.power
    paper_curve = K * _plane_shape(shape, g, t)
    recip_curve = K * (_recip.plane_columns(terms, g, t) @ coef)
    from ..metrics import r2 as r2_of

    return {"r2_table_paper": float(r2_of(y, paper_curve)),
            "r2_table_reciprocal": float(r2_of(y, recip_curve)), "table": str(path)}


@functools.lru_cache(maxsize=32)
def _read_table(path: str):
    """The material's own table, read for the fidelity diagnostic only: what the reader
    notes about it (slightly negative powers kept, ...) was said when it was fitted."""
    import warnings

    from ..data import read_measurements

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return read_measurements(path)


def _find_table(data_file) -> Path | None:
    if not isinstance(data_file, str) or not data_file:
        return None
    candidates = [Path(data_file)]
    if not Path(data_file).is_absolute():
        from ..data import bundled_dir

        candidates.append(bundled_dir().parent / data_file)
    for c in candidates:
        if c.is_file():
            return c
    return None


def _lobes_for(name: str, p: dict):
    """Lobes ``[t, c0, c1, u_n, v_n]`` and share law ``(u_a, v_a)`` per unit K, or None."""
    base = name.partition(":")[0]
    if base == "two-lobe":
        lobes = [[0.0, 1.0, -1.0, p["u_nd"], p["v_nd"]],   # diffuse: (1 - a_s), about the normal
                 [1.0, 0.0, 1.0, p["u_ns"], p["v_ns"]]]    # specular: a_s, about the mirror
        return np.array(lobes), (p["u_as"], p["v_as"])
    if base == "single-lobe":
        return np.array([[1.0, 1.0, 0.0, p["n"], 0.0]]), (0.0, 0.0)
    if base == "phong":
        # (1-k_s) cos(theta) = (1-k_s) pi * [cos/pi]; k_s cos^n(phi) = k_s 2pi/(n+1) * lobe_n
        n = p["n"]
        return np.array([[0.0, (1 - p["k_s"]) * np.pi, 0.0, 1.0, 0.0],
                         [1.0, p["k_s"] * 2 * np.pi / (n + 1), 0.0, n, 0.0]]), (0.0, 0.0)
    if base == "n-lobe":
        count = sum(1 for k in p if re.fullmatch(r"t_\d+", k))
        if count > LOBE_MAX:
            return None, None
        lobes = [[p[f"t_{i}"], p[f"a_{i}"], 0.0, p[f"n_{i}"], 0.0] for i in range(1, count + 1)]
        return np.array(lobes), (0.0, 0.0)
    return None, None


def with_brdf(mat: Material, brdf: str) -> Material:
    """The same fitted material in the other surface model (Lambertian ones unchanged)."""
    check_brdf(brdf)
    if mat.kind == KIND_LAMBERTIAN or mat.brdf == brdf or mat.model is None:
        return mat
    gmax = float(np.degrees(mat.gamma_max_rad))
    return from_model(mat.model, mat.params, mat.requested, name=mat.name, source=mat.source,
                      stderr=mat.stderr, gamma_max_deg=gmax, metadata=mat.metadata, brdf=brdf)


# ----------------------------------------------------------------------------- normalisation
def _gauss_legendre(n):
    x, w = np.polynomial.legendre.leggauss(n)
    return (x + 1) / 2, w / 2


def lobe_fraction_above(alpha, n, nodes: int = 48) -> np.ndarray:
    """Fraction of a normalised ``(n+1)/2pi cos^n`` lobe whose axis is at ``alpha`` (radians)
    from the surface normal that lies above the surface.

    With ``t = cos^(n+1)(psi)`` (``psi`` the angle from the axis) the lobe's mass is uniform
    in ``t`` on [0, 1]; at cone angle ``psi`` the share of azimuths above the surface is
    ``arccos(-cot(alpha) cot(psi)) / pi``. Gauss-Legendre on both sides of the kink at
    ``psi = 90 deg - alpha``.
    """
    alpha, n = np.broadcast_arrays(np.abs(np.asarray(alpha, float)), np.asarray(n, float))
    x, w = _gauss_legendre(nodes)
    kink = np.clip(np.cos(np.clip(np.pi / 2 - alpha, 0, np.pi)), 0, 1) ** (n + 1)
    kink = np.where(np.pi / 2 - alpha <= 0, 1.0, kink)
    total = np.zeros(alpha.shape)
    for lo, hi in ((np.zeros_like(kink), kink), (kink, np.ones_like(kink))):
        t = lo[..., None] + (hi - lo)[..., None] * x
        psi = np.arccos(np.clip(t ** (1.0 / (n[..., None] + 1.0)), -1, 1))
        sa, ca = np.sin(alpha)[..., None], np.cos(alpha)[..., None]
        sp, cp = np.sin(psi), np.cos(psi)
        with np.errstate(divide="ignore", invalid="ignore"):
            arg = np.where(sa * sp > 1e-15, -(ca * cp) / (sa * sp), np.where(ca * cp > 0, -2.0, 2.0))
        frac = np.arccos(np.clip(arg, -1, 1)) / np.pi
        total = total + (hi - lo) * (frac * w).sum(axis=-1)
    return total


def lobe_law_values(lobes, share, gamma_max, gamma):
    """Weights ``(G, L)`` and indices ``(G, L)`` of the lobes at angles of incidence ``gamma``."""
    g = np.minimum(np.abs(np.asarray(gamma, float)), gamma_max)
    cg = np.cos(g)[:, None]
    u_a, v_a = share
    a = cap_share(np.maximum(u_a * cg ** v_a, 0.0))  # the one share rule of irreflect
    w = np.maximum(lobes[:, 1] + lobes[:, 2] * a, 0.0)
    n = np.clip(lobes[:, 3] * cg ** lobes[:, 4], 0.0, 1e6)
    return w, n


def lobe_hemisphere_integral(lobes, share, gamma_max, gamma) -> np.ndarray:
    """``S(gamma)``: integral over the hemisphere of the lobes' shape (per unit K)."""
    w, n = lobe_law_values(lobes, share, gamma_max, gamma)
    alpha = np.abs(lobes[:, 0])[None, :] * np.abs(np.asarray(gamma, float))[:, None]
    return (w * lobe_fraction_above(alpha, n)).sum(axis=1)


def _plane_table(model_obj, values, gamma_max) -> np.ndarray:
    params = np.array([values[k] for k in model_obj.param_names])
    if "K" in values:  # the shape per unit K
        params = params.copy()
        params[list(model_obj.param_names).index("K")] = 1.0
    g = np.minimum(TABLE_GAMMA, gamma_max)
    G, T = np.meshgrid(g, TABLE_THETA, indexing="ij")
    with np.errstate(all="ignore"):
        table = np.asarray(model_obj.predict(params, -G, T), float)
    table = np.where(np.isfinite(table), np.maximum(table, 0.0), 0.0)
    table[:, np.abs(TABLE_THETA) >= np.pi / 2 - 1e-12] = 0.0
    return table


def table_hemisphere_integral(mat: Material, n_mu: int = 96, n_az: int = 192) -> np.ndarray:
    """``S(gamma)`` of a tabulated material, by a product quadrature over the hemisphere."""

    probe = replace(mat, norm_table=np.ones(N_GAMMA), rho_table=np.ones(N_GAMMA))
    return hemisphere_integral(pack_materials([probe]), 0, GAMMA_NODES, n_mu, n_az)


# ----------------------------------------------------------------------------- material files
def _as_number(value):
    """``value`` as a float when it reads as one, else as given (the schema names it)."""
    if value is None or isinstance(value, bool):
        return value
    try:
        return float(value)
    except (TypeError, ValueError):
        return value


def save_material(result, path, *, data_file=None, wavelength_nm=None, notes=None,
                  reflectance=None) -> dict:
    """Write a fitted model as a material file (JSON), atomically.

    ``result`` is a :class:`irreflect.fitting.FitResult`. ``reflectance``: the material's total
    reflectance if known (a number in [0, 1]), ``"K"`` if the fitted power was
    BRDF x cos(theta) in 1/sr, or None (then a scene must give it).
    """

    if not all(hasattr(result, k) for k in ("model", "param_names", "values", "gamma_deg")):
        raise IrreflectError(f"save_material expects a FitResult (from irreflect.fit); found "
                             f"{type(result).__name__}")
    check_output_path(path, "file", "--save", (".json",))
    reflectance = parse_reflectance(reflectance, Path(path).stem)
    gamma = np.abs(np.asarray(result.gamma_deg, float))
    doc = {
        "format": MATERIAL_FORMAT,
        "format_version": MATERIAL_FORMAT_VERSION,
        "model": result.model,
        "params": {k: float(v) for k, v in zip(result.param_names, result.values, strict=True)},
        "stderr": {k: float(v) for k, v in zip(result.param_names, result.stderr, strict=True)},
        "r2": float(result.r2),
        "rmse": float(result.rmse),
        "n_points": int(result.n_points),
        "gamma_range_deg": [float(gamma.min()), float(gamma.max())],
        "data_file": None if data_file is None else str(data_file),
        "reflectance": reflectance,
        "wavelength_nm": _as_number(wavelength_nm),
        "notes": notes or "",
    }
    verdict = result.verdict()
    doc["trustworthy"] = verdict.trustworthy
    doc["verdict"] = verdict.to_dict()
    doc["warnings"] = list(result.warnings)
    if not np.all(np.isfinite(result.values)):
        raise IrreflectError(f"{path}: the fit has non-finite coefficients; nothing written")
    text = dumps(doc)
    try:  # nothing is written that load_material refuses
        _check_material_document(parse_json(text, str(path), _FROM_FIT), path)
    except IrreflectError as exc:
        text = str(exc)
        if "@" in str(result.model):  # a fit at one angle of incidence ('phong@10')
            text = (f"model '{result.model}' is a fit at one angle of incidence, which a "
                    "material file cannot hold: save a fit of the model alone "
                    f"('{str(result.model).partition('@')[0]}')")
        where = "" if str(path) in text else f"{path}: "
        raise IrreflectError(f"save_material: {where}{text}; nothing written") from None
    with atomic_path(path, "--save") as tmp:
        tmp.write_text(text)
    return doc


#: Material files larger than this are refused (they are about a kilobyte).
MAX_MATERIAL_BYTES = 1 * 2**20
_FROM_FIT = "a material file written by 'irreflect fit DATA --save MATERIAL.json'"
#: A material's total reflectance: a number in [0, 1], or "K" (see the module docstring).
REFLECTANCE = sc.AnyOf(
    shape=lambda v: sc.Choice(options=("K",)) if isinstance(v, str) else sc.Number(lo=0.0,
                                                                                  hi=1.0),
    expected='a number from 0 to 1 or "K"', whole=True)
_PARAM_NAME = sc.Text(max_len=64, what="a parameter name")
_VERDICT_NUMBER = sc.Nullable(sc.Number())
#: A fit's verdict as ``fit --save`` writes it (:meth:`irreflect.verdict.FitVerdict.to_dict`):
#: ``irreflect room`` prints its summary, so it is checked like every other key.
VERDICT_SCHEMA = sc.Table({
    "trustworthy": sc.Boolean(),
    "summary": sc.Text(max_len=10_000, multiline=True),
    "problems": sc.ListOf(sc.Text(max_len=10_000, multiline=True), max_items=1_000),
    "at_bound": sc.ListOf(sc.Text(max_len=100, what="a parameter name"), max_items=64),
    "ill_determined": sc.ListOf(sc.Text(max_len=100, what="a parameter name"), max_items=64),
    "converged": sc.Boolean(),
    "saturated_gammas_deg": sc.ListOf(sc.Number(lo=-90.0, hi=90.0), max_items=10_000),
    "clipped_readings": sc.Integer(lo=0),  # since stop 46; older files lack it
    "angles": sc.ListOf(sc.Table({
        "gamma_deg": sc.Number(lo=-90.0, hi=90.0), "n_points": sc.Integer(lo=0),
        "polar_error_pct": _VERDICT_NUMBER, "polar_error_at_points_pct": _VERDICT_NUMBER,
        "specular_share": _VERDICT_NUMBER, "lobe_half_width_deg": _VERDICT_NUMBER,
        "lobe_points_1hw": sc.Integer(lo=0), "lobe_points_2hw": sc.Integer(lo=0),
        "lobe_matters": sc.Boolean(), "lobe_resolved": sc.Boolean(),
        "lobe_undersampled": sc.Boolean(), "ok": sc.Boolean(),
    }, what="a verdict per angle of incidence"), max_items=10_000),
}, what="a fit's verdict (as 'irreflect fit --save' writes it)")
#: The declared schema of a material file (:func:`save_material` writes it).
MATERIAL_FILE_SCHEMA = sc.Table({
    "format": sc.Choice(options=(MATERIAL_FORMAT,)),
    "format_version": sc.Integer(),
    "model": sc.Text(max_len=100, what="a model name (see 'irreflect models')"),
    "params": sc.MapOf(keys=_PARAM_NAME, values=sc.Number(), max_items=64,
                       what="a table of NAME: VALUE"),
    "stderr": sc.Nullable(sc.MapOf(keys=_PARAM_NAME, max_items=64, what="a table",
                                   values=sc.Nullable(sc.Number(lo=0.0, allow_nan=True)))),
    "r2": sc.Nullable(sc.Number(hi=1.0, allow_nan=True)),
    "rmse": sc.Nullable(sc.Number(lo=0.0, allow_nan=True)),
    "n_points": sc.Nullable(sc.Integer(lo=0)),
    "gamma_range_deg": sc.Nullable(sc.Vector(2, item=sc.Number(lo=0.0, hi=90.0),
                                             what="[min, max] in degrees")),
    "data_file": sc.Nullable(sc.Text(max_len=4096)),
    "reflectance": sc.Nullable(REFLECTANCE),
    "wavelength_nm": sc.Nullable(sc.Number(lo=0.0, hi=1e6, lo_open=True, unit="nm")),
    "notes": sc.Nullable(sc.Text(max_len=100_000, multiline=True)),
    "trustworthy": sc.Nullable(sc.Boolean()),
    "verdict": sc.Nullable(VERDICT_SCHEMA),
    "warnings": sc.Nullable(sc.ListOf(sc.Text(max_len=10_000, multiline=True),
                                      max_items=1_000, what="a list of text")),
}, required=("format", "format_version", "model", "params"))


def check_params(model, params: dict, source: str) -> None:
    """Natural parameters of ``model`` within the model's physical bounds (one line naming
    the parameter, its range and the value); names are checked by :func:`from_model`."""
    model_obj = get_model(model)
    for p in model_obj.params:
        value = params.get(p.name)
        if value is None:
            continue
        x = sc.as_float(value)
        span = p.upper - p.lower if math.isfinite(p.upper - p.lower) else 1.0
        tol = 1e-9 * max(span, 1.0)
        if x is None or x < p.lower - tol or x > p.upper + tol:
            raise IrreflectError(
                f"{source}: {p.name} of {model_obj.name} must be a number from {p.lower:g} to "
                f"{p.upper:g} ({p.description}); found {sc.found(value)}")


def _check_material_document(doc, path) -> dict:
    """The rules a material file's document must follow (:func:`load_material` reads only
    such files, :func:`save_material` writes only such documents): the checked document."""
    if not isinstance(doc, dict) or doc.get("format") != MATERIAL_FORMAT:
        raise IrreflectError(f"{path} is not an irreflect material file (no \"format\": "
                             f"\"{MATERIAL_FORMAT}\"); write one with 'irreflect fit DATA "
                             "--save MATERIAL.json'")
    version = doc.get("format_version")
    if version != MATERIAL_FORMAT_VERSION:
        raise IrreflectError(f"{path} has format_version {sc.found(version)}; this "
                             f"irreflect reads version {MATERIAL_FORMAT_VERSION}")
    doc = sc.validate(MATERIAL_FILE_SCHEMA, doc, str(path))
    get_model(doc["model"])  # the bounds of its coefficients: from_model
    extra = sorted(set(doc.get("stderr") or {}) - set(doc["params"]))
    if extra:
        raise IrreflectError(f"{path}: stderr has '{extra[0]}', which is not one of the "
                             f"params ({', '.join(doc['params'])})")
    grange = doc.get("gamma_range_deg")
    if grange is not None and grange[0] > grange[1]:
        raise IrreflectError(f"{path}: gamma_range_deg must be [min, max] with min <= max; "
                             f"found {list(grange)}")
    return doc


def load_material(path, *, name: str | None = None, reflectance=None) -> Material:
    """Read a material file written by ``irreflect fit --save``.

    Every key is checked against :data:`MATERIAL_FILE_SCHEMA` and the coefficients against
    the model's physical bounds. ``reflectance`` overrides the file's (a number in [0, 1] or
    ``"K"``); one of the two must give it.
    """
    label = name or (Path(path).stem if isinstance(path, str | Path) else "material")
    try:
        text = read_text(path, f"material '{label}'", _FROM_FIT, MAX_MATERIAL_BYTES)
        doc = parse_json(text, str(path), _FROM_FIT)
        path = Path(path)
        doc = _check_material_document(doc, path)
    except IrreflectError as exc:
        text = str(exc)
        where = "" if str(path) in text else f"{path}: "
        raise IrreflectError(f"material '{label}': {where}{text}") from None
    rho = reflectance if reflectance is not None else doc.get("reflectance")
    if rho is None:
        raise IrreflectError(
            f"material '{label}': {path} gives no total reflectance: add reflectance = RHO "
            "(0..1) to the scene's material, or save the fit with --reflectance RHO")
    grange = doc.get("gamma_range_deg")
    try:
        return from_model(doc["model"], doc["params"], rho, name=label,
                          source=f"{path.name} ({doc['model']})", stderr=doc.get("stderr"),
                          gamma_max_deg=None if grange is None else grange[1],
                          metadata={k: doc.get(k) for k in ("r2", "data_file", "wavelength_nm",
                                                            "notes", "gamma_range_deg",
                                                            "trustworthy", "verdict",
                                                            "warnings")})
    except IrreflectError as exc:  # the file named in the one line
        text = str(exc).removeprefix(f"material '{label}': ")
        raise IrreflectError(f"material '{label}': {path}: {text}") from None


_LAMBERTIAN_RE = re.compile(r"^\s*lambertian\s*\(\s*([^)]*)\)\s*$", re.IGNORECASE)


def parse_lambertian(text: str):
    """``"lambertian(0.8)"`` -> 0.8, or None when ``text`` is not of that form."""
    m = _LAMBERTIAN_RE.match(text)
    if not m:
        return None
    try:
        return float(m.group(1))
    except ValueError as exc:
        raise IrreflectError(f"'{text}': expected lambertian(RHO) with RHO a number in [0, 1]") from exc


__all__ = ["Material", "lambertian", "from_model", "with_brdf", "load_material", "save_material",
           "BRDFS", "PAPER_WARNING", "check_brdf", "check_params", "MATERIAL_FILE_SCHEMA",
           "REFLECTANCE", "fit_notes", "negative_power",
           "lobe_fraction_above", "lobe_hemisphere_integral", "parse_lambertian",
           "MATERIAL_FORMAT", "MATERIAL_FORMAT_VERSION"]
