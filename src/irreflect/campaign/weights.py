"""The weights of the campaign's fit: how much of the instrument's range each reading
stands for (:func:`range_weights`), counted or power-aware (:func:`power_weights`); see
docs/campaign.md, "The campaign's fit". Re-exported by :mod:`irreflect.campaign.core`."""

from __future__ import annotations

import numpy as np

from .instrument import thin_settings

#: The range's settings that weigh the readings (see :func:`range_weights`) are thinned to
#: at most this many.
MAX_RANGE_POINTS = 20_000


def range_weights(range_deg: np.ndarray, gamma_deg, theta_deg) -> np.ndarray:
    """How much of the range each reading stands for: the number of the range's settings
    nearer to it than to any other reading (gamma and theta in degrees alike), at least 1,
    scaled to a mean of 1.

    The campaign fits its readings with these weights, so that its fit approximates the
    least-squares fit over the whole range (a quadrature of the range's squared error)
    rather than over where the readings happen to cluster. Where the model describes the
    material the two agree; where it misfits (films, paints, grazing incidence), a single
    reading in the misfit would otherwise pull the fit as much as a whole row of
    settings. On the 11 real sets of experiments/bench_campaign.py this took the
    campaign within 0.01 of the all-points fit from 12 readings on the satin (never, before:
    its 25th reading, 7 deg off the mirror at 69 deg, cost 0.008 of R^2), 12 on the iris
    film (17) and 13 on the colodur paint (18)."""
    nearest, size = range_cells(range_deg, gamma_deg, theta_deg)
    if size == 0:
        return np.ones(0)
    w = np.maximum(np.bincount(nearest, minlength=size).astype(float), 1.0)
    return w / w.mean()


def range_cells(range_deg: np.ndarray, gamma_deg, theta_deg) -> tuple[np.ndarray, int]:
    """The reading nearest to each of the range's settings (gamma and theta in degrees
    alike; the range thinned to :data:`MAX_RANGE_POINTS`), and the number of readings."""
    g = np.asarray(gamma_deg, float)
    t = np.asarray(theta_deg, float)
    if g.size == 0:
        return np.zeros(0, int), 0
    r = thinned_range(range_deg)
    nearest = np.empty(len(r), int)
    for lo in range(0, len(r), 4096):  # in blocks: memory stays small on a fine range
        block = r[lo:lo + 4096]
        d = (block[:, None, 0] - g[None]) ** 2 + (block[:, None, 1] - t[None]) ** 2
        nearest[lo:lo + 4096] = np.argmin(d, axis=1)
    return nearest, g.size


def thinned_range(range_deg) -> np.ndarray:
    """The range's settings, thinned to at most :data:`MAX_RANGE_POINTS`."""
    r = np.asarray(range_deg, float)
    if len(r) > MAX_RANGE_POINTS:
        r = r[thin_settings(r, MAX_RANGE_POINTS)]
    return r


def power_weights(nearest: np.ndarray, f_range: np.ndarray, f_read: np.ndarray, *,
                  cap: float = 0.0, floor: float = 0.0) -> np.ndarray:
    """The power-aware quadrature of the range's squared error: reading ``i`` stands for
    the sum over its cell (``nearest == i``) of ``(f_r / f_i)^2``, ``f`` a fit's predicted
    power on the range settings (``f_range``) and at the readings (``f_read``), plus
    ``floor`` times its peak over the range; the ratio capped at ``cap`` (0: not capped).
    At least 1, scaled to a mean of 1. A relative misfit at a reading is a misfit in power
    units in proportion to the predicted power over the range it stands for."""
    fr = np.abs(np.nan_to_num(np.asarray(f_range, float), nan=0.0, posinf=0.0, neginf=0.0))
    fi = np.abs(np.nan_to_num(np.asarray(f_read, float), nan=0.0, posinf=0.0, neginf=0.0))
    peak = max(float(np.max(fr)) if fr.size else 0.0, float(np.max(fi)) if fi.size else 0.0,
               1e-300)
    add = max(float(floor), 1e-6) * peak
    ratio = (fr + add) / (fi[nearest] + add)
    if cap and cap > 0:
        ratio = np.minimum(ratio, cap)
    w = np.maximum(np.bincount(nearest, weights=ratio ** 2, minlength=fi.size), 1.0)
    return w / w.mean()
