"""Material-specific protocols: the few points of a pilot dense scan that pin the model down
(here, beside the optimiser it runs; the protocol itself is a :mod:`irreflect.protocol`
object).

The points are chosen by the subset optimiser of :mod:`irreflect.selection` (NSGA-II on
number of points vs 1 - R^2 against all points, the paper's section 4.3), restricted to
the angles the tool can set and, if asked, to a few angle-of-incidence settings.

Choosing the gamma settings (``n_gamma_settings=K``): changing gamma is the slow step on
a goniometer, so a protocol may be limited to K of the scan's angles of incidence. Which
K is decided by a cheap, documented rule before the optimiser runs: every combination of
K gammas (all of them when there are at most :data:`MAX_COMBINATIONS`, else a greedy
forward choice) is scored by the R^2, against the whole scan, of the model fitted to all
the allowed points of those gammas; the best combination wins. The optimiser then picks
the points among that combination only.
"""

from __future__ import annotations

import itertools
from math import comb

import numpy as np
import pandas as pd

from ..data import as_measurements
from ..errors import IrreflectError
from ..fitting import fit_subsets
from ..models import get_model
from ..protocol.core import Protocol, measurement_permutation, normalise_gammas
from .run import run_selection

#: Above this many gamma combinations, gamma settings are chosen greedily.
MAX_COMBINATIONS = 200

DESIGN_RULE = (
    "optimised on a pilot dense scan: the subset optimiser (irreflect.selection, {selector}, "
    "population {pop_size}, {generations} generations, seed {seed}) minimises the number of "
    "points and 1 - R^2 of the {model} model fitted on them against all {n_dense} points of "
    "{dataset}; {n} points taken from its front ({how}); allowed points: {allowed}"
)


def tool_mask(dense, theta_min=None, theta_max=None, allowed_gammas=None) -> np.ndarray:
    """Points of ``dense`` the tool can set: theta within the limits (degrees, inclusive)
    and gamma among ``allowed_gammas`` (any sign convention, see
    :func:`~.core.normalise_gammas`)."""
    dense = as_measurements(dense)
    mask = np.ones(dense.n_points, bool)
    if theta_min is not None:
        mask &= dense.theta_deg >= float(theta_min) - 1e-9
    if theta_max is not None:
        mask &= dense.theta_deg <= float(theta_max) + 1e-9
    if allowed_gammas is not None:
        wanted = normalise_gammas(allowed_gammas)
        missing = [g for g in wanted if not np.any(np.isclose(dense.gamma_deg, g))]
        if missing:
            raise IrreflectError(
                f"allowed angle(s) of incidence {', '.join(f'{g:g}' for g in missing)} are not in "
                f"{dense.name} (it has {', '.join(f'{g:g}' for g in dense.gammas)})"
            )
        mask &= np.isin(np.round(dense.gamma_deg, 9), np.round(wanted, 9))
    return mask


def choose_gamma_settings(dense, k: int, model="two-lobe", mask=None, *, max_iter: int = 100):
    """The ``k`` angles of incidence whose allowed points, fitted alone, best predict the
    whole scan (see the module docstring).

    Returns ``(gammas (k,), scores DataFrame)`` with one row per combination tried:
    ``gammas`` (text), ``n_points``, ``r2_all``, sorted best first.
    """
    dense = as_measurements(dense)
    model_obj = get_model(model)
    mask = np.ones(dense.n_points, bool) if mask is None else np.asarray(mask, bool)
    levels = [g for g in dense.gammas if np.any(mask & (dense.gamma_deg == g))]
    k = int(k)
    if not 1 <= k <= len(levels):
        raise IrreflectError(
            f"gamma settings must be between 1 and the {len(levels)} angles of incidence the tool "
            f"can use in {dense.name}; found {k}"
        )

    def score(combos):
        masks = np.array([mask & np.isin(dense.gamma_deg, c) for c in combos])
        res = fit_subsets(dense.gamma_deg, dense.theta_deg, dense.power, masks, model_obj,
                          sigma=dense.sigma, max_iter=max_iter)
        return masks.sum(axis=1), res.r2_all

    rows = []
    if comb(len(levels), k) <= MAX_COMBINATIONS:
        combos = list(itertools.combinations(levels, k))
        counts, r2 = score(combos)
        rows = list(zip(combos, counts, r2, strict=True))
    else:  # greedy forward: add the gamma that helps most, k times
        chosen: tuple = ()
        for _ in range(k):
            combos = [tuple(sorted(chosen + (g,), key=abs)) for g in levels if g not in chosen]
            counts, r2 = score(combos)
            rows += list(zip(combos, counts, r2, strict=True))
            chosen = combos[int(np.argmax(r2))]
        rows = [r for r in rows if len(r[0]) == k]
    table = pd.DataFrame({
        "gammas": [", ".join(f"{g:g}" for g in sorted(c, key=abs)) for c, _, _ in rows],
        "n_points": [int(n) for _, n, _ in rows],
        "r2_all": [float(r) for _, _, r in rows],
    }).sort_values("r2_all", ascending=False, kind="stable").reset_index(drop=True)
    best = max(rows, key=lambda r: r[2])[0]
    return np.array(sorted(best, key=abs), float), table


def design_protocol(dense, n_points: int | None = None, model="two-lobe", *,
                    theta_min: float | None = None, theta_max: float | None = None,
                    n_gamma_settings: int | None = None, allowed_gammas=None,
                    selector: str = "nsga2", seed: int = 0, pop_size: int = 100,
                    generations: int = 200, progress: bool = False,
                    name: str | None = None) -> Protocol:
    """A protocol for one material from its pilot dense scan.

    Parameters
    ----------
    dense : Measurements, table or path
        The pilot scan (gamma_deg, theta_deg in degrees, power).
    n_points : int, optional
        How many points to recommend; default the knee of the optimiser's front.
    model : str
        Model the protocol must determine.
    theta_min, theta_max : float, degrees, optional
        Receiver range of the tool; points outside are never chosen.
    n_gamma_settings : int, optional
        Number of angle-of-incidence settings allowed (see the module docstring).
    allowed_gammas : numbers, degrees, optional
        Angles of incidence the tool can set.
    selector, seed, pop_size, generations, progress
        Passed to :func:`irreflect.selection.run_selection`.

    Returns
    -------
    Protocol
        ``kind="optimised"``, purpose ``"optimised"``, in measurement order.
    """
    dense = as_measurements(dense)
    model_obj = get_model(model)
    mask = tool_mask(dense, theta_min, theta_max, allowed_gammas)
    gamma_scores = None
    chosen_gammas = None
    if n_gamma_settings is not None:
        chosen_gammas, gamma_scores = choose_gamma_settings(dense, n_gamma_settings, model_obj,
                                                            mask)
        mask &= np.isin(dense.gamma_deg, chosen_gammas)
    n_allowed = int(mask.sum())
    k = model_obj.n_params
    if n_allowed <= k:
        raise IrreflectError(
            f"only {n_allowed} points of {dense.name} are within the tool's limits; fitting "
            f"the {k} parameters of '{model_obj.name}' needs at least {k + 1}: widen the limits"
        )
    if n_points is not None:
        n_points = int(n_points)
        if not k < n_points <= n_allowed:
            raise IrreflectError(
                f"--n must be between {k + 1} (the model's {k} parameters and a degree of "
                f"freedom) and the {n_allowed} allowed points; found {n_points}"
            )
    res = run_selection(dense, model_obj, selector=selector, pop_size=pop_size,
                        generations=generations, seed=seed, candidates=mask, progress=progress)
    n = int(res.knee_n) if n_points is None else n_points
    best = res.best_mask(n)
    if best is None:
        raise IrreflectError(
            f"the optimiser tried no subset of {n} points of {dense.name}: raise the number of "
            "generations or choose another number of points"
        )
    sel = np.asarray(best, bool)
    if sel.sum() != n or np.any(sel & ~mask):
        raise IrreflectError(f"the optimiser returned no valid {n}-point set for {dense.name}")
    idx = np.nonzero(sel)[0]
    idx = idx[measurement_permutation(dense.gamma_deg[idx], dense.theta_deg[idx])]
    allowed = []
    if theta_min is not None or theta_max is not None:
        allowed.append(f"theta in [{theta_min if theta_min is not None else '-'}, "
                       f"{theta_max if theta_max is not None else '-'}] deg")
    if chosen_gammas is not None:
        allowed.append(f"{n_gamma_settings} gamma settings ({', '.join(f'{g:g}' for g in chosen_gammas)}"
                       " deg, the combination whose points fitted alone give the best R^2)")
    elif allowed_gammas is not None:
        allowed.append("gamma in " + ", ".join(f"{g:g}" for g in normalise_gammas(allowed_gammas)))
    rule = DESIGN_RULE.format(
        selector=selector, pop_size=pop_size, generations=generations, seed=seed,
        model=model_obj.name, n_dense=dense.n_points, dataset=dense.name, n=n,
        how="the knee" if n_points is None else "as asked",
        allowed="; ".join(allowed) or "all points of the scan",
    )
    settings = {
        "dataset": dense.name, "model": model_obj.name, "n_points": n,
        "knee_n": int(res.knee_n), "selector": selector, "pop_size": pop_size,
        "generations": generations, "seed": seed,
        "theta_min": theta_min, "theta_max": theta_max, "n_gamma_settings": n_gamma_settings,
        "gamma_settings": None if chosen_gammas is None else [float(g) for g in chosen_gammas],
    }
    if gamma_scores is not None:
        settings["gamma_setting_scores"] = gamma_scores.head(10).to_dict(orient="records")
    lo = float(theta_min) if theta_min is not None else float(np.min(dense.theta_deg[mask]))
    hi = float(theta_max) if theta_max is not None else float(np.max(dense.theta_deg[mask]))
    return Protocol(
        gamma_deg=dense.gamma_deg[idx].astype(float) + 0.0,
        theta_deg=dense.theta_deg[idx].astype(float) + 0.0,
        purpose=("optimised",) * idx.size,
        requested_theta_deg=np.full(idx.size, np.nan),
        adjustment=("",) * idx.size,
        theta_min=lo, theta_max=hi, kind="optimised", rule=rule, settings=settings,
        order="measurement", notes=(), name=name or f"{dense.name}-{n}pt",
    )
