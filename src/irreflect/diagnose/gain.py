"""The gain drift between angles of incidence, as the diagnosis tries it.

A detector or source whose gain changes between the runs at different angles of incidence
multiplies every reading at one angle of incidence by its own factor: not a law in gamma
(the factors jump by a few to 15 % from one run to the next) and not a property of the
material. :func:`irreflect.models.extensions.gain_drift` builds that extension for one
table's angles of incidence (it cannot be registered by name: its parameters are the
table's); here: when the diagnosis tries it (:func:`gain_candidate`), where its fits start
(:func:`gain_starts`), the factors it reports (:func:`gain_params`) and what the verdict
says of it (:data:`GAIN_ADVICE`, :func:`artefact_note`).
"""

from __future__ import annotations

import numpy as np

from ..fitting import FitResult
from ..models.extensions import (
    GAIN_BOUND,
    GAIN_DRIFT,
    GAIN_MIN_READINGS,
    GainDrift,
    gain_drift,
    gain_levels,
)
from .search import ModelSets, canonical_order, set_name


def gain_candidate(names, default: bool, used, meas):
    """The candidate names with the table's gain drift (:data:`GAIN_DRIFT`) among them,
    and the extensions of this table only (``{GAIN_DRIFT: extension}`` or ``{}``). It is
    tried by default (``default``) or when asked for, on a table of at least 3 angles of
    incidence with at least :data:`GAIN_MIN_READINGS` readings each (with fewer, a
    factor per angle leaves too little to compare the curves by)."""
    wanted = GAIN_DRIFT not in used and (default or GAIN_DRIFT in names)
    names = [n for n in names if n != GAIN_DRIFT]
    levels = gain_levels(meas.gamma_deg, GAIN_MIN_READINGS)
    if not wanted or levels.size < 3:
        return names, {}
    return names + [GAIN_DRIFT], {GAIN_DRIFT: gain_drift(levels)}


#: why an explanation with a gain drift is dropped for one without it (see _select)
GAIN_PARSIMONY = ("not needed: an explanation without the gain drift, with fewer "
                   "parameters, explains the data as well")
#: why an explanation with a gain drift whose factors follow a smooth law is not grown
GAIN_SMOOTH = ("not named: its factors follow a smooth law of the angle of incidence "
               "(see the summary)")
#: what to do about a gain drift (the Effect's advice)
GAIN_ADVICE = ("a measurement artefact, not a property of the material: the detector or "
               "source gain changed between the runs at different angles of incidence; "
               "re-measure a reference (the source directly, or a diffuse standard) at "
               "each angle of incidence and normalise each run by its reference reading, "
               "then fit again (the coefficients fitted here with the factors divided out "
               "are the best estimate meanwhile)")


def artefact_note(effects) -> str:
    """What the summary adds for named effects that are measurement artefacts."""
    notes = [f"; {e.name} is {e.advice}" for e in effects if e.artefact]
    return "".join(notes)


def gain_params(result: FitResult, levels) -> tuple[dict, dict]:
    """Every angle of incidence's gain factor of a fit with the gain drift (the last one
    implied: ``1 / prod`` of the others), with standard errors (delta method)."""
    names, v, cov = _free_gains(result, levels)
    last = float(np.exp(-np.sum(np.log(v))))
    var = float(np.sum(cov / np.outer(v, v)))
    params = dict(zip(names, [*map(float, v), last], strict=True))
    stderr = dict(zip(names, [*(float(result.stderrs[n]) for n in names[:-1]),
                              last * float(np.sqrt(max(var, 0.0)))], strict=True))
    return params, stderr


def _free_gains(result: FitResult, levels) -> tuple[list, np.ndarray, np.ndarray]:
    """Every level's parameter name, and the values and covariance of the free factors
    (all but the last, which the others imply)."""
    names = [f"gain_{g:g}" for g in levels]
    idx = [result.param_names.index(n) for n in names[:-1]]
    v = np.asarray(result.values, float)[idx]
    return names, v, np.asarray(result.covariance, float)[np.ix_(idx, idx)]


def gain_factors(levels_deg, gamma_deg, power, fitted, weights) -> np.ndarray:
    """The factor per level that best rescales a fitted curve onto the readings at that
    angle of incidence (weighted least squares, ``weights`` = 1 / sigma), normalised to a
    geometric mean of 1; 1 where the curve is zero there."""
    g = np.round(np.asarray(gamma_deg, float), 6)
    y, f = np.asarray(power, float), np.asarray(fitted, float)
    w2 = np.broadcast_to(np.asarray(weights, float) ** 2, y.shape)
    out = np.ones(len(levels_deg))
    for k, level in enumerate(levels_deg):
        at = np.abs(g - level) < 1e-6
        den = float(np.sum(w2[at] * f[at] ** 2))
        num = float(np.sum(w2[at] * f[at] * y[at]))
        if den > 0 and num > 0:
            out[k] = num / den
    log = np.clip(np.log(out), -GAIN_BOUND, GAIN_BOUND)
    return np.exp(log - np.mean(log))


def gain_starts(sets: ModelSets, names, fitted: dict, curves: dict, gamma_deg, power,
                weights) -> np.ndarray:
    """Starts of a set holding the gain drift: the fitted subset without it embedded, its
    gain block set to :func:`gain_factors` of that subset's curve (``fitted``: set name
    -> z; ``curves``: set name -> fitted power). None when that subset is not fitted."""
    target = canonical_order(names)
    ext = sets.local.get(GAIN_DRIFT)
    sub = tuple(n for n in target if n != GAIN_DRIFT)
    key = set_name(sub)
    if GAIN_DRIFT not in target or not isinstance(ext, GainDrift) or key not in fitted \
            or key not in curves:
        return np.zeros((0, sets.model(target).n_nonlinear))
    row = sets.embed(fitted[key], sub, target)
    factors = gain_factors(ext.levels_deg, gamma_deg, power, curves[key], weights)
    row[sets.block_slice(GAIN_DRIFT, target)] = np.log(factors[:-1])
    model = sets.model(target)
    return np.clip(row, model.z_lower, model.z_upper)[None]


#: terms of the smooth laws of the angle of incidence a gain drift must depart from:
#: ``ln K(gamma) = a + b s + c s^2``, ``s = sin^2 gamma`` (``cos^w``, ``1 + c sin^2`` and
#: Fresnel-like rises toward grazing are all close to one of them over 0-70 deg)
SMOOTH_TERMS = 3
#: from this many angles of incidence a gain drift whose factors form one valley or one
#: peak in gamma is not named (a random sequence of 7 is such by chance 2.5 % of the time,
#: of 5 25 %)
UNIMODAL_MIN_ANGLES = 7


def smooth_gains(result: FitResult, levels, level: float) -> tuple[bool, str]:
    """Whether the gain factors of a fit with the gain drift follow a smooth law of the
    angle of incidence (:data:`SMOOTH_TERMS`): then they may as well be a reflectance
    that varies with gamma by a law the catalogue follows only nearly, and the drift is
    not named. The test: the factors' departure from the best such law, ``chi2 = r^T
    C^+ r`` in the logarithm (``C`` the covariance of the log-factors, from the fit's),
    on ``G - 3`` degrees of freedom at ``level``; with 3 angles of incidence or fewer
    nothing is left to tell them apart. Nor is a drift named whose factors rise or fall
    steadily with ``|gamma|`` within their errors (departure from the closest monotone
    sequence; on a real glossy paint, Cornell's krylon blue, the factors grew from 0.74
    at 10 deg to 2.4 at 70 deg: a reflectance rising toward grazing and a base model
    that misfits more and more there, not a drift). Returns (smooth, a sentence for the
    summary)."""
    from scipy import special

    _, v, cov = _free_gains(result, levels)
    log = np.log(np.append(v, np.exp(-np.sum(np.log(v)))))  # the last factor implied
    g = len(levels)
    df = g - SMOOTH_TERMS
    head = ("a gain drift between angles of incidence (a factor per angle) fits the data "
            "too, but ")
    tell = ("; measure a reference at each angle of incidence to tell a drifting gain from "
            "a reflectance that varies with gamma")
    if df < 1:
        return True, (f"; {head}on {g} angles of incidence its factors cannot be told from a "
                      f"smooth law of the angle of incidence: it is not named{tell}")
    cov_log = cov / np.outer(v, v)
    a = np.vstack([np.eye(g - 1), -np.ones((1, g - 1))])  # the last log-factor is implied
    precision = np.linalg.pinv(a @ cov_log @ a.T)
    s = np.sin(np.radians(np.asarray(levels, float))) ** 2
    x = np.column_stack([s ** k for k in range(SMOOTH_TERMS)])
    beta = np.linalg.pinv(x.T @ precision @ x) @ x.T @ precision @ log
    r = log - x @ beta
    chi2 = float(r @ precision @ r)
    p = float(special.chdtrc(df, chi2))
    if p >= level:
        return True, (f"; {head}its factors follow a smooth law of the angle of incidence "
                      f"(departure chi2 {chi2:.3g} on {df} dof, p = {p:.3g}): it is not "
                      f"named{tell}")
    # a law that rises or falls steadily toward grazing (a Fresnel-like rise, a base model
    # that misfits more and more toward grazing) is no drift either: the departure from
    # the best monotone sequence in |gamma| (weighted isotonic regression; its tail is
    # bounded by that of chi-square on G - 1 dof, which is used: conservative)
    w = 1.0 / np.clip(np.diag(a @ cov_log @ a.T), 1e-300, None)
    mono = min(float(np.sum(w * (log - _isotonic(log, w)) ** 2)),
               float(np.sum(w * (log + _isotonic(-log, w)) ** 2)))
    p_mono = float(special.chdtrc(g - 1, mono))
    if p_mono >= level:
        return True, (f"; {head}its factors rise or fall steadily with the angle of "
                      f"incidence (departure from monotone chi2 {mono:.3g}, p <= "
                      f"{p_mono:.3g}), as a reflectance that varies with gamma would: it is "
                      f"not named{tell}")
    # nor, on UNIMODAL_MIN_ANGLES angles or more, one that falls to a single valley and
    # rises again (or the reverse): on a held-out Cook-Torrance table with no drift the
    # factors ran 1.07, 1.05, 1.00, 0.97, 0.90, 0.89, 0.91, 0.93, 1.35 from 5 to 79 deg
    # (the base model's misfit per angle, its errors 0.4 % far below it), and a drift was
    # named. On fewer angles a true drift is often such a sequence by chance (the rule on
    # every table named 12 of 20 drifts, not 18)
    if g < UNIMODAL_MIN_ANGLES:
        return False, ""
    uni = _unimodal_departure(log, w)
    p_uni = float(special.chdtrc(g - 1, uni))
    if p_uni < level:
        return False, ""
    return True, (f"; {head}its factors fall to one valley and rise again with the angle of "
                  f"incidence, or the reverse (departure from such a sequence chi2 "
                  f"{uni:.3g}, p <= {p_uni:.3g}), as a reflectance that varies with gamma "
                  f"and a base model that misfits toward grazing would: it is not "
                  f"named{tell}")


def _unimodal_departure(y, w) -> float:
    """The weighted squared departure of ``y`` from the closest sequence that falls and
    then rises (one valley) or rises and then falls (one peak), monotone ones included."""
    y, w = np.asarray(y, float), np.asarray(w, float)
    best = np.inf
    for sign in (1.0, -1.0):  # a valley, then a peak (the valley of -y)
        v = sign * y
        for k in range(len(v) + 1):
            left = -_isotonic(-v[:k], w[:k]) if k else np.empty(0)  # non-increasing
            right = _isotonic(v[k:], w[k:]) if k < len(v) else np.empty(0)
            fit_ = np.concatenate([left, right])
            best = min(best, float(np.sum(w * (v - fit_) ** 2)))
    return best


def _isotonic(y, w) -> np.ndarray:
    """The non-decreasing sequence closest to ``y`` in the weights ``w`` (pool adjacent
    violators)."""
    blocks: list[list[float]] = []  # [mean, weight, count]
    for yi, wi in zip(np.asarray(y, float), np.asarray(w, float), strict=True):
        blocks.append([yi, wi, 1])
        while len(blocks) > 1 and blocks[-2][0] > blocks[-1][0]:
            m2, w2, n2 = blocks.pop()
            m1, w1, n1 = blocks.pop()
            blocks.append([(m1 * w1 + m2 * w2) / (w1 + w2), w1 + w2, n1 + n2])
    return np.concatenate([np.full(n, m) for m, _, n in blocks])

