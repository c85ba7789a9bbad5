"""A harder blind set for the diagnosis: glossy, medium-gloss and matte bases, one or two
effects at once in forms that are *not* the catalogue's own, noise proportional to the
signal, weak effects near the detection limit, varied grids.

:mod:`irreflect.diagnose.hidden` makes its tables with the catalogue's extension models on
the paper's Table 3 materials; the diagnosis then fits the very function that made the
data. This generator does not:

* **Bases** (:data:`BASES`): the two-lobe model with a specular share that saturates,
  ``a_s = min(1, u_as cos^v_as(gamma))`` (a share cannot exceed 1): ``glossy`` (lobe
  index ``u_ns`` 150-6000, share 0.02-0.6 at normal incidence, growing toward grazing
  until it saturates), ``semigloss`` (index 15-150) and ``matte`` (share below 0.06, index
  2-20: a matte white is nearly Lambertian).
* **Effects** (:data:`EFFECT_FORMS`), each in one of two forms drawn at random, of which
  at most one is the catalogue's: an off-specular tilt ``t |sin gamma|^p`` with ``p`` in
  1.5-2.5 (the catalogue has ``p = 2``); a retro lobe of cos^n or Gaussian shape; a halo
  of cos^n or Gaussian shape; a reflectance ``cos^w(gamma)`` or ``1 + c sin^2(gamma)``; a
  constant background; a constant receiver-angle offset (applied to everything, last).
* **Cases**: by the seed (:func:`plan`): seeds ``10 k + 0, 1`` carry no effect, ``+ 2 ..
  7`` one effect (in catalogue order), ``+ 8, 9`` a pair (random); the base cycles with
  ``k`` (glossy, semigloss, matte). Every 30 consecutive seeds cover every (base, kind).
* **Size of an effect**: drawn as its visibility, ``lambda`` = the chi-square of the
  base model's best fit to the noise-free table in noise units, log-uniform in
  [8, 2000] (the part of it the base alone leaves on the noise-free table without the
  effect is subtracted): weak effects near the detection limit are as common per decade
  as strong ones. The magnitude is scaled until ``lambda`` is within 25 % of the draw
  (at most 5 fits) and capped at a physical range; ``truth["lambda"]`` is what it came to.
* **Noise**: ``sigma^2 = a^2 + (b P)^2`` with ``P`` the noise-free power: additive
  (``a`` 0.5-3 % of the median power), proportional (``b`` 1-5 %, a tiny ``a``) or both;
  a ``sigma`` column with the true sigma on 40 % of the tables.
* **Grids** (:data:`GRIDS`): the paper's (4-7 angles of incidence, receivers every 5 or
  10 deg), Cornell's (7 incidences, 18 receivers that never land on the mirror angle, none
  within 6 deg of the source), dense (1-2 deg steps, 0.5 deg near the mirror), a coarse
  grid with extra receivers 1-7 deg off the mirror, and three incidences only.

Everything is seeded; the same seed gives the same table. :func:`rivals` measures, on the
noise-free table, how well every catalogue explanation does: what "detectable" and
"identifiable" mean in ``experiments/diagnose_rates.py``.
"""

from __future__ import annotations

import itertools
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..data import Measurements
from ..errors import FitError, FitWarning, IrreflectError
from ..fitting import fit
from ..models.base import generalized_lambertian
from ..models.extensions import CATALOGUE

#: the bases, in the order the seeds cycle through them
BASES = ("glossy", "semigloss", "matte")
#: the grids
GRIDS = ("paper", "cornell", "dense", "near-mirror", "three-gammas")
#: every pair of catalogue effects a case may carry (a halo needs a lobe it can be broader than)
PAIRS = tuple(itertools.combinations(CATALOGUE, 2))
#: the forms each effect is drawn in (the first of each is the catalogue's own, or close)
EFFECT_FORMS = {
    "incidence_reflectance": ("K cos^w(gamma)", "K (1 + c sin^2(gamma))"),
    "offspecular_peak": ("specular axis tilted by t |sin gamma|^p, p in 1.5-2.5",),
    "retroreflection": ("(n+1)/2pi cos^n(theta - gamma)", "(n+1)/2pi exp(-n (theta-gamma)^2/2)"),
    "angle_offset": ("theta -> theta + delta, applied to everything",),
    "background": ("+ b",),
    "specular_halo": ("(n+1)/2pi cos^n(phi)", "(n+1)/2pi exp(-n phi^2/2)"),
}
LAMBDA_RANGE = (8.0, 2000.0)


@dataclass(frozen=True)
class BlindCase:
    """A table and what is in it (``truth``: base, effects, their parameters, noise, grid,
    ``lambda`` the effects' visibility)."""

    measurements: Measurements
    truth: dict = field(default_factory=dict)
    clean: np.ndarray | None = None
    sigma: np.ndarray | None = None

    @property
    def effects(self) -> tuple[str, ...]:
        return tuple(self.truth["effects"])


def plan(seed: int) -> tuple[str, tuple[str, ...] | None]:
    """The base and the effects of case ``seed``: ``(base, effects)`` with ``effects``
    None for a pair still to be drawn (see the module docstring)."""
    slot = seed % 10
    base = BASES[(seed // 10) % len(BASES)]
    if slot < 2:
        return base, ()
    if slot < 8:
        return base, (CATALOGUE[slot - 2],)
    return base, None


# ----------------------------------------------------------------------------- bases
def _base_params(kind, rng) -> dict:
    if kind == "glossy":
        p = dict(u_as=rng.uniform(0.02, 0.6), v_as=rng.uniform(-2.5, 0.5),
                 u_ns=np.exp(rng.uniform(np.log(150), np.log(6000))), v_ns=rng.uniform(-1, 1))
    elif kind == "semigloss":
        p = dict(u_as=rng.uniform(0.02, 0.4), v_as=rng.uniform(-2.5, 0.5),
                 u_ns=np.exp(rng.uniform(np.log(15), np.log(150))), v_ns=rng.uniform(-1, 1))
    else:
        p = dict(u_as=rng.uniform(0.0, 0.06), v_as=rng.uniform(-2.0, 0.5),
                 u_ns=np.exp(rng.uniform(np.log(2), np.log(20))), v_ns=rng.uniform(-0.5, 0.5))
    p |= dict(u_nd=rng.uniform(0.6, 2.0), v_nd=rng.uniform(-0.4, 0.8),
              K=float(np.exp(rng.uniform(np.log(0.05), np.log(20)))))
    return {k: float(v) for k, v in p.items()}


def _lobe(x_rad, n, shape):
    """Normalised lobe about an axis, ``x`` the angle from it (radians)."""
    if shape == "gauss":
        return (n + 1.0) / (2.0 * np.pi) * np.exp(-0.5 * n * x_rad * x_rad) * (np.abs(x_rad) < np.pi / 2)
    return generalized_lambertian(np.cos(x_rad), n)


def clean_power(base: dict, effects: dict, gamma_deg, theta_deg) -> np.ndarray:
    """Noise-free power of a base (natural two-lobe coefficients, saturating share) with
    ``effects`` (name -> parameters; see :data:`EFFECT_FORMS`). Degrees in."""
    g = np.radians(np.asarray(gamma_deg, float))
    t = np.radians(np.asarray(theta_deg, float))
    if "angle_offset" in effects:  # the receiver arm's zero error moves everything
        t = t + np.radians(effects["angle_offset"]["delta"])
    cg = np.cos(g)
    a_s = np.minimum(1.0, base["u_as"] * cg ** base["v_as"])
    n_d = base["u_nd"] * cg ** base["v_nd"]
    n_s = base["u_ns"] * cg ** base["v_ns"]
    phi = -g - t
    if "offspecular_peak" in effects:
        e = effects["offspecular_peak"]
        phi = phi + np.radians(e["tilt"]) * np.abs(np.sin(g)) ** e["p"]
    K = base["K"]
    power = K * ((1.0 - a_s) * generalized_lambertian(np.cos(t), n_d)
                 + a_s * generalized_lambertian(np.cos(phi), n_s))
    if "retroreflection" in effects:
        e = effects["retroreflection"]
        power = power + K * e["a_r"] / (1 - e["a_r"]) * _lobe(t - g, e["n_r"], e["shape"])
    if "specular_halo" in effects:
        e = effects["specular_halo"]
        power = power + K * e["a_h"] / (1 - e["a_h"]) * _lobe(-g - t, e["n_h"], e["shape"])
    if "incidence_reflectance" in effects:
        e = effects["incidence_reflectance"]
        factor = cg ** e["w"] if e["form"] == "cos" else 1.0 + e["c"] * np.sin(g) ** 2
        power = power * factor
    if "background" in effects:
        power = power + effects["background"]["b"]
    return power


# ----------------------------------------------------------------------------- grids
def _grid(rng, forced=None):
    kind = str(rng.choice(GRIDS))
    if forced is not None:
        kind = forced
    rows = []
    skip_source = kind == "cornell" or rng.random() < 0.5
    if kind == "paper":
        start = int(rng.choice([10, 15]))
        pool = np.arange(start, 80, 10)
        mags = np.sort(rng.choice(pool, size=int(rng.integers(4, min(7, pool.size) + 1)),
                                  replace=False))
        step = int(rng.choice([5, 10]))
        top = int(rng.choice([70, 80, 85]))
        for m in mags:
            rows += [(-m, th) for th in np.arange(-top, top + 0.1, step)]
    elif kind == "cornell":
        recv = np.array([0, 8.1, 16.3, 24.5, 32.9, 41.4, 50.2, 59.3, 68.9])
        recv = np.unique(np.concatenate([-recv, recv]))
        for m in range(10, 71, 10):
            rows += [(-m, th) for th in recv]
    elif kind == "dense":
        mags = np.sort(rng.choice([10, 20, 28, 40, 50, 60, 69, 75], size=int(rng.integers(4, 7)),
                                  replace=False))
        step = float(rng.choice([1.0, 2.0]))
        for m in mags:
            th = set(np.round(np.arange(-85, 85.01, step), 2))
            th |= set(np.round(m + np.arange(-5, 5.01, 0.5), 2))
            rows += [(-m, x) for x in sorted(th) if -85 <= x <= 85]
    elif kind == "near-mirror":
        mags = np.sort(rng.choice(np.arange(10, 80, 5), size=int(rng.integers(4, 7)),
                                  replace=False))
        step = int(rng.choice([5, 10]))
        for m in mags:
            th = set(np.arange(-80, 80.1, step)) | {m + d for d in (-7, -4, -2, -1, 1, 2, 4, 7)}
            rows += [(-m, float(x)) for x in sorted(th) if -85 <= x <= 85]
    else:  # three-gammas
        mags = np.sort(rng.choice([15, 30, 45, 60, 75], size=3, replace=False))
        for m in mags:
            rows += [(-m, float(x)) for x in np.arange(-85, 85.1, 5)]
    g = np.array([float(r[0]) for r in rows])
    t = np.array([float(r[1]) for r in rows])
    if skip_source:  # the detector cannot stand in the source's beam
        keep = np.abs(t - g) > 6.0
        g, t = g[keep], t[keep]
    info = {"kind": kind, "gammas": sorted(set(g.tolist()), reverse=True),
            "points": int(g.size), "no_receivers_near_source": bool(skip_source)}
    return g, t, info


# ----------------------------------------------------------------------------- effects
def _effect_params(name, rng, base, sigma_med, K) -> dict:
    """Initial parameters of an effect; the first key is the magnitude scaled later."""
    if name == "incidence_reflectance":
        if rng.random() < 0.5:
            return {"w": float(rng.choice([-1, 1]) * 0.5), "form": "cos"}
        return {"c": float(rng.choice([-1, 1]) * 0.3), "form": "sin2"}
    if name == "offspecular_peak":
        return {"tilt": float(rng.uniform(2.0, 8.0)), "p": float(rng.uniform(1.5, 2.5))}
    if name == "retroreflection":
        return {"a_r": 0.03, "n_r": float(np.exp(rng.uniform(np.log(5), np.log(100)))),
                "shape": str(rng.choice(["cos", "gauss"]))}
    if name == "angle_offset":
        return {"delta": float(rng.choice([-1, 1]) * 1.0)}
    if name == "background":  # stray light: positive (a negative offset would push the
        # power below zero where the surface reflects little, which no table reader takes)
        return {"b": float(abs(rng.choice([-1, 1, 1, 1])) * 5.0 * sigma_med)}
    if name == "specular_halo":
        top = max(min(60.0, base["u_ns"] / 4.0), 2.5)
        return {"a_h": 0.05, "n_h": float(np.exp(rng.uniform(np.log(2.0), np.log(top)))),
                "shape": str(rng.choice(["cos", "gauss"]))}
    raise IrreflectError(f"unknown effect {name!r}")


_MAGNITUDE = {  # the scaled key and its cap (absolute value)
    "incidence_reflectance": None, "offspecular_peak": ("tilt", 20.0),
    "retroreflection": ("a_r", 0.5), "angle_offset": ("delta", 6.0),
    "background": ("b", np.inf), "specular_halo": ("a_h", 0.6),
}


def _scaled(name, params, s):
    p = dict(params)
    if name == "incidence_reflectance":
        key, cap = ("w", 4.0) if p["form"] == "cos" else ("c", 0.9)
    else:
        key, cap = _MAGNITUDE[name]
    p[key] = float(np.clip(p[key] * s, -cap, cap))
    return p


def _chi2_base(g, t, power, sigma, seed) -> float:
    """Chi-square of the base model's best fit (inf when no fit beats a constant)."""
    meas = Measurements(gamma_deg=g, theta_deg=t, power=power, sigma=sigma)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        try:
            r = fit(meas, "two-lobe", seed=seed)
        except (FitError, IrreflectError):
            return float("inf")
    return float(np.sum((r.residuals / sigma) ** 2))


NOISES = ("additive", "proportional", "both")


def _noise(rng, clean, forced=None):
    kind = str(rng.choice(NOISES))
    if forced is not None:
        kind = forced
    med = float(np.median(np.abs(clean)))
    a = med * (rng.uniform(0.005, 0.03) if kind != "proportional" else 0.001)
    # a floor: a glossy table whose median power is ~0 next to its peak would get an
    # additive noise below what a table's sigma may be (1e-12 of the largest power)
    a = max(a, 1e-9 * float(np.max(np.abs(clean))))
    b = rng.uniform(0.01, 0.05) if kind != "additive" else 0.0
    return kind, float(a), float(b)


def blind_case(seed: int, *, effects: tuple[str, ...] | None = None, base: str | None = None,
               lam: float | None = None, sigma_column: bool | None = None,
               saturate: bool = True, grid: str | None = None,
               noise: str | None = None) -> BlindCase:
    """Case ``seed`` of the harder blind set (see the module docstring).

    Parameters
    ----------
    seed : int
        Seeds everything; also picks the base and the effects (:func:`plan`) unless given.
    effects : tuple of str, optional
        The effects to hide (``()`` for none), overriding the plan.
    base : str, optional
        One of :data:`BASES`, overriding the plan.
    lam : float, optional
        The visibility to aim at (see ``lambda`` in the module docstring) instead of a draw.
    sigma_column : bool, optional
        Force a ``sigma`` column (True) or none (False); else 40 % of the tables carry one.
    saturate : bool
        False: ``u_as`` is lowered until the share stays below 0.95 at every measured
        angle of incidence (the paper's unbounded law then holds on the table); the rest
        of the case is drawn as with True.
    grid, noise : str, optional
        One of :data:`GRIDS` and one of :data:`NOISES`, overriding the draw.
    """
    if not isinstance(seed, int | np.integer) or seed < 0:
        raise IrreflectError(f"seed must be a non-negative integer, found {seed!r}")
    planned_base, planned = plan(int(seed))
    rng = np.random.default_rng([int(seed), 22])
    base = planned_base if base is None else base
    for what, value, allowed in (("base", base, BASES), ("grid", grid, GRIDS),
                                 ("noise", noise, NOISES)):
        if value is not None and value not in allowed:
            raise IrreflectError(f"unknown {what} {value!r}: expected one of "
                                 f"{', '.join(allowed)}")
    if effects is None:
        effects = planned
    if effects is None:  # a pair: no halo on a lobe too broad to have one
        pairs = [p for p in PAIRS if not (base == "matte" and "specular_halo" in p)]
        effects = pairs[int(rng.integers(len(pairs)))]
    effects = tuple(effects)
    for e in effects:
        if e not in CATALOGUE:
            raise IrreflectError(f"unknown effect {e!r}: expected names of {', '.join(CATALOGUE)}")
    bp = _base_params(base, rng)
    g, t, grid_info = _grid(rng, grid)
    top_share = float(np.max(np.cos(np.radians(g)) ** bp["v_as"]))
    if not saturate:
        bp["u_as"] = min(bp["u_as"], 0.95 / top_share)
    base_clean = clean_power(bp, {}, g, t)
    noise_kind, a, b = _noise(rng, base_clean, noise)
    sigma = np.sqrt(a * a + (b * base_clean) ** 2)
    with_sigma = bool(rng.random() < 0.4) if sigma_column is None else bool(sigma_column)
    sigma_med = float(np.median(sigma))
    params = {e: _effect_params(e, rng, bp, sigma_med, bp["K"]) for e in effects}
    targets = {e: float(np.exp(rng.uniform(*np.log(LAMBDA_RANGE)))) for e in effects}
    if lam is not None:
        targets = {e: float(lam) for e in effects}
    lam0 = _chi2_base(g, t, base_clean, sigma, seed) if effects else 0.0
    lams = {}
    for e in effects:  # each effect's own visibility, alone on the base
        p, tried = params[e], []
        for _ in range(6):
            clean_e = clean_power(bp, {e: p}, g, t)
            sig_e = np.sqrt(a * a + (b * clean_e) ** 2)
            got = _chi2_base(g, t, clean_e, sig_e, seed) - lam0
            if not np.isfinite(got):  # a base fit that cannot beat a constant (inf - inf)
                got = np.inf if np.isfinite(lam0) else 1e-9
            got = max(got, 1e-9)
            tried.append((abs(np.log(got / targets[e])), p, got))
            if tried[-1][0] < np.log(1.25):
                break
            new = _scaled(e, p, float(np.clip(np.sqrt(targets[e] / got), 0.05, 20.0)))
            if new == p:  # capped
                break
            p = new
        _, params[e], lams[e] = min(tried, key=lambda x: x[0])
    clean = clean_power(bp, params, g, t)
    sigma = np.sqrt(a * a + (b * clean) ** 2)
    lam_all = (_chi2_base(g, t, clean, sigma, seed) - lam0) if effects else 0.0
    power = clean + rng.standard_normal(clean.size) * sigma
    floor = -0.9 * (4.0 * sigma if with_sigma else 0.02 * np.max(np.abs(power)))
    power = np.maximum(power, floor)  # within the table reader's noise allowance
    tag = "+".join(effects) or "none"
    meas = Measurements(gamma_deg=g, theta_deg=t, power=power,
                        sigma=sigma if with_sigma else None, material=base,
                        name=f"blind_{seed}_{base}_{tag}")
    truth = {
        "seed": int(seed), "base": base, "base_params": bp, "effects": list(effects),
        "params": params, "lambda_target": targets, "lambda_each": lams,
        "lambda": float(lam_all), "lambda_base_misfit": float(lam0),
        "saturates": bool(bp["u_as"] * top_share > 1.0),
        "noise": {"kind": noise_kind, "a": a, "b": b, "sigma_column": with_sigma},
        "grid": grid_info, "n_points": int(g.size),
    }
    return BlindCase(meas, truth, clean=clean, sigma=sigma)


# ----------------------------------------------------------------------------- rivals
def _chi2_fit(meas, model, sigma, seed, starts=None) -> tuple[float, object]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        try:
            r = fit(meas, model, seed=seed, extra_starts=starts, retry=False)
        except (FitError, IrreflectError):
            return float("inf"), None
    return float(np.sum((r.residuals / sigma) ** 2)), r


def rivals(case: BlindCase, seed: int = 0, sets=None) -> dict:
    """Chi-square (true noise units) of catalogue explanations fitted to the noise-free
    table: ``{"": base, "a": a single effect, "a+b": a pair, ...}``. By default the base,
    every single effect and, for a case with effects, every set of the truth's size and
    every union of such a set with the truth (what "identifiable" needs)."""
    meas = Measurements(gamma_deg=case.measurements.gamma_deg,
                        theta_deg=case.measurements.theta_deg, power=case.clean,
                        sigma=case.sigma)
    truth = tuple(sorted(case.effects, key=CATALOGUE.index))
    if sets is None:
        sets = {()} | {(e,) for e in CATALOGUE}
        if truth:
            same = set(itertools.combinations(CATALOGUE, len(truth)))
            sets |= same
            sets |= {tuple(sorted(set(s) | set(truth), key=CATALOGUE.index)) for s in same}
    out = {}
    for s in sorted(sets, key=lambda s: (len(s), [CATALOGUE.index(x) for x in s])):
        model = "two-lobe" + "".join(f"+{x}" for x in s)
        out["+".join(s)], _ = _chi2_fit(meas, model, case.sigma, seed)
    # nested models: a bigger set is at least as good as any of its subsets
    for key in sorted(out, key=lambda k: len(k.split("+")) if k else 0):
        parts = tuple(key.split("+")) if key else ()
        for sub in itertools.chain.from_iterable(itertools.combinations(parts, r)
                                                 for r in range(len(parts))):
            sk = "+".join(sub)
            if sk in out:
                out[key] = min(out[key], out[sk])
    return out
