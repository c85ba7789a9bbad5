"""Surface materials in 3D: the plane-of-incidence reflection models extended to every direction.

The fitted models describe the reflected radiant intensity in the plane of incidence. In a
room, light leaves a surface point in every direction, so each model is extended to 3D the
way the paper describes its components (section 3.4: "the 3D diagrams for each component
are a revolution volume along their orientation axes"):

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

Above the surface only: directions below it receive nothing, which cuts lobes whose axis
is tilted (the specular lobe near grazing incidence).

**Scale and energy.** The 3D shape ``s(gamma, omega)`` (radiant intensity per unit power,
1/sr) is scaled per angle of incidence so that the reflected power is the material's total
reflectance times the incident power:

    f(gamma, omega) = rho(gamma) s(gamma, omega) / S(gamma),   S(gamma) = integral of s over the hemisphere

``S`` is computed numerically per angle of incidence (for lobes of revolution by a 1-D
quadrature of the part of each lobe above the surface; for tabulated models by a 2-D
quadrature). The shape restricted to the plane of incidence is exactly the fitted curve at
every gamma; only its overall scale changes with gamma (which is the paper's beta(gamma),
Fig. 11). ``rho`` is either a constant total reflectance given by the user or the material
file, or ``"K"``: the table's power was BRDF x cos(theta) in 1/sr (as for the real data in
``../shared``), so ``f = K s`` and ``rho(gamma) = K S(gamma)``. Either way ``rho <= 1`` is
checked: the reflected power never exceeds the incident power.

The fitted share and index laws are used up to the largest measured angle of incidence
(``gamma_range_deg`` of a material file) and held constant beyond it; the specular share is
clipped to [0, 1].
"""

from __future__ import annotations

import json
import math
import numbers
import re
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .. import schema as sc
from .._atomic import atomic_path
from .._inputs import parse_json, read_text
from ..errors import IrreflectError
from ..models import get_model
from ..validation import check_output_path
from .kernels import (  # noqa: F401  (the table constants are re-exported)
    GAMMA_NODES,
    LOBE_MAX,
    N_GAMMA,
    TABLE_GAMMA,
    TABLE_THETA,
    eval_material_directions,
    hemisphere_integral,
    pack_materials,
)

#: format of a material file written by ``irreflect fit --save``
MATERIAL_FORMAT = "irreflect-material"
MATERIAL_FORMAT_VERSION = 1
#: largest angle of incidence at which the share/index laws are evaluated
GAMMA_LAW_MAX = np.radians(89.5)

KIND_LAMBERTIAN, KIND_LOBES, KIND_TABLE = 0, 1, 2


@dataclass(frozen=True)
class Material:
    """A surface material ready for 3D evaluation.

    Attributes
    ----------
    name : str
    kind : int
        0 Lambertian, 1 lobes of revolution, 2 tabulated plane-of-incidence equivalent.
    source : str
        Where it came from (``lambertian(0.8)``, ``terrazzo.json (two-lobe)``, ...).
    reflectance : float or None
        Constant total reflectance (None when ``scale == "K"``).
    scale : str
        ``"reflectance"`` or ``"K"`` (see the module docstring).
    model, params, stderr : the fitted model spec and natural parameters (None for Lambertian)
    lobes : ndarray (L, 5)
        ``[tilt t, c0, c1, u_n, v_n]``: axis at ``t gamma`` from the normal, weight
        ``c0 + c1 a(gamma)``, index ``u_n cos^v_n(gamma)``.
    share : (u_a, v_a)
        ``a(gamma) = clip(u_a cos^v_a(gamma), 0, 1)`` (the two-lobe specular share).
    gamma_max_rad : float
        The laws are evaluated at ``min(gamma, gamma_max_rad)``.
    rho_table, norm_table : ndarray (N_GAMMA,)
        ``rho(gamma)`` and ``rho(gamma) / S(gamma)`` at :data:`GAMMA_NODES`.
    table : ndarray (361, 721) or None
        Plane-of-incidence shape for kind 2, at :data:`TABLE_GAMMA` x :data:`TABLE_THETA`.
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

    @property
    def is_lambertian(self) -> bool:
        return self.kind == KIND_LAMBERTIAN

    def rho(self, gamma_rad) -> np.ndarray:
        """Total reflectance at the angle of incidence ``gamma_rad`` (radians, magnitude)."""
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
        rho = (f"reflectance {self.reflectance:g}" if self.scale == "reflectance"
               else f"reflectance K x lobes = {self.rho_table.min():.3g}-{self.rho_table.max():.3g}")
        return f"{self.model} ({rho})"

    def intensity(self, gamma_deg, theta_deg, azimuth_deg=0.0) -> np.ndarray:
        """Reflected radiant intensity per unit incident power (1/sr) in 3D.

        ``gamma_deg``: angle of incidence (its sign is ignored); the outgoing direction is
        at ``theta_deg`` from the normal (positive towards the mirror side) and rotated by
        ``azimuth_deg`` about the normal out of the plane of incidence (0 = in the plane).
        Evaluated by the same compiled code as the simulation.
        """

        g = np.radians(np.abs(np.asarray(gamma_deg, float)))
        t = np.radians(np.asarray(theta_deg, float))
        a = np.radians(np.asarray(azimuth_deg, float))
        g, t, a = np.broadcast_arrays(g, t, a)
        din = np.stack([np.sin(g), np.zeros_like(g), -np.cos(g)], axis=-1)
        dout = np.stack([np.sin(t) * np.cos(a), np.sin(t) * np.sin(a), np.cos(t)], axis=-1)
        out = eval_material_directions(pack_materials([self]), 0, din.reshape(-1, 3),
                                       dout.reshape(-1, 3))
        return out.reshape(g.shape)


# ----------------------------------------------------------------------------- construction
def lambertian(rho: float, name: str | None = None) -> Material:
    """An ideal diffuse (Lambertian) surface of total reflectance ``rho``."""
    rho = _check_rho(rho, name or "lambertian")
    return Material(name=name or f"lambertian({rho:g})", kind=KIND_LAMBERTIAN,
                    source=f"lambertian({rho:g})", reflectance=rho,
                    lobes=np.array([[0.0, 1.0, 0.0, 1.0, 0.0]]),
                    rho_table=np.full(N_GAMMA, rho), norm_table=np.full(N_GAMMA, rho))


def parse_reflectance(value, name: str = "--reflectance"):
    """A material file's reflectance: a number in [0, 1], ``"K"``, or None."""
    if value is None:
        return None
    if isinstance(value, str) and value.strip().upper() == "K":
        return "K"
    return _check_rho(value, name)


def _check_rho(rho, name) -> float:
    try:
        rho = float(rho)
    except (TypeError, ValueError) as exc:
        raise IrreflectError(f"material '{name}': reflectance must be a number in [0, 1] or "
                             f"\"K\"; found {rho!r}") from exc
    if not (0.0 <= rho <= 1.0) or not math.isfinite(rho):
        raise IrreflectError(f"material '{name}': reflectance must be in [0, 1] (reflected power "
                             f"cannot exceed the incident power); found {rho:g}")
    return rho


def from_model(model, params: dict, reflectance, *, name: str = "material",
               source: str | None = None, stderr: dict | None = None,
               gamma_max_deg: float | None = None, metadata: dict | None = None) -> Material:
    """A material from a registered reflection model and its natural parameters.

    Parameters
    ----------
    model : str
        Model spec (``irreflect models``), e.g. ``"two-lobe"``, ``"phong"``, ``"n-lobe:2"``.
    params : dict
        Natural parameters by name (all of ``get_model(model).param_names``).
    reflectance : float in [0, 1] or "K"
        Constant total reflectance; or ``"K"``: the power the model was fitted to was
        BRDF x cos(theta) (1/sr), so ``K`` already sets the reflectance.
    gamma_max_deg : float, optional
        Largest measured angle of incidence: the share and index laws are held constant
        beyond it (default: used up to 89.5 deg).
    """

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
        scale, rho = "K", None
        K = values.get("K", 1.0)
    else:
        scale, rho = "reflectance", _check_rho(reflectance, name)
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
                metadata=metadata)
    if lobes is not None:
        S = lobe_hemisphere_integral(lobes, share, gmax, GAMMA_NODES)
        mat = Material(kind=KIND_LOBES, lobes=lobes, share=share, **base)
    else:
        table = _plane_table(model_obj, values, gmax)
        mat = Material(kind=KIND_TABLE, table=table, **base)
        S = table_hemisphere_integral(mat)
    mat = _with_scale(mat, S, K)
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


def _with_scale(mat: Material, S: np.ndarray, K: float) -> Material:
    if np.any(~np.isfinite(S)) or np.any(S <= 0):
        raise IrreflectError(f"material '{mat.name}': its lobes reflect nothing above the surface "
                             "at some angle of incidence; check the coefficients")
    if mat.scale == "K":
        rho = K * S
        worst = int(np.argmax(rho))
        if rho[worst] > 1.0 + 1e-9:
            raise IrreflectError(
                f"material '{mat.name}': with reflectance \"K\" the total reflectance K x "
                f"(integral of the lobes) reaches {rho[worst]:.4g} at gamma = "
                f"{np.degrees(GAMMA_NODES[worst]):.1f} deg, more than the incident power; give "
                "reflectance = RHO <= 1 instead (the power was not BRDF x cos(theta) in 1/sr?)")
        norm = np.full(N_GAMMA, K)
    else:
        rho = np.full(N_GAMMA, mat.reflectance)
        norm = mat.reflectance / S
    return replace(mat, rho_table=rho, norm_table=norm)


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
    a = np.clip(u_a * cg ** v_a, 0.0, 1.0)
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
        "wavelength_nm": None if wavelength_nm is None else float(wavelength_nm),
        "notes": notes or "",
    }
    verdict = result.verdict()
    doc["trustworthy"] = verdict.trustworthy
    doc["verdict"] = verdict.to_dict()
    doc["warnings"] = list(result.warnings)
    if not np.all(np.isfinite(result.values)):
        raise IrreflectError(f"{path}: the fit has non-finite coefficients; nothing written")
    with atomic_path(path, "--save") as tmp:
        tmp.write_text(json.dumps(doc, indent=2) + "\n")
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
    "angles": sc.ListOf(sc.Table({
        "gamma_deg": sc.Number(lo=-90.0, hi=90.0), "n_points": sc.Integer(lo=0),
        "polar_error_pct": _VERDICT_NUMBER, "polar_error_at_points_pct": _VERDICT_NUMBER,
        "specular_share": _VERDICT_NUMBER, "lobe_half_width_deg": _VERDICT_NUMBER,
        "lobe_points_1hw": sc.Integer(lo=0), "lobe_points_2hw": sc.Integer(lo=0),
        "lobe_matters": sc.Boolean(), "lobe_resolved": sc.Boolean(), "ok": sc.Boolean(),
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
    if grange is not None and grange[0] > grange[1]:
        raise IrreflectError(f"material '{label}': {path}: gamma_range_deg must be [min, max] "
                             f"with min <= max; found {list(grange)}")
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


__all__ = ["Material", "lambertian", "from_model", "load_material", "save_material",
           "check_params", "MATERIAL_FILE_SCHEMA", "REFLECTANCE", "fit_notes", "negative_power",
           "lobe_fraction_above", "lobe_hemisphere_integral", "parse_lambertian",
           "MATERIAL_FORMAT", "MATERIAL_FORMAT_VERSION"]
