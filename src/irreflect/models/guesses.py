"""Data-driven starting values: what the measurements say about the lobes.

The fitter's global search starts where the data point: the per-angle-of-incidence
decomposition (:func:`lobe_profile`: at every measured angle of incidence, the best
diffuse lobe about the normal plus specular lobe about the mirror direction on a grid
of indices), the peak directions (:func:`peak_directions`) and the specular index they
imply (:func:`estimate_specular_index`). Angles in radians.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import TWO_PI

#: The narrowest lobe irreflect fits: index 10^6 is a half width at half maximum of
#: 0.07 deg, below any goniometer's angular resolution ("the mirror limit"). Gloss paint
#: and glass reach 10^4-10^5.
MAX_LOBE_INDEX = 1.0e6
#: Index grids of the per-angle decomposition (:func:`lobe_profile`).
PROFILE_DIFFUSE_INDICES = np.geomspace(0.05, 100.0, 10)
PROFILE_SPECULAR_INDICES = np.geomspace(0.5, MAX_LOBE_INDEX, 25)


@dataclass(frozen=True)
class LobeProfile:
    """What the data say at every angle of incidence, with nothing tied across angles.

    For each measured angle of incidence the curve is fitted by a diffuse lobe about the
    normal plus a specular lobe about the mirror direction, ``A (n_d+1)/2pi cos^n_d(theta)
    + B (n_s+1)/2pi cos^n_s(phi)``, globally over a grid of indices (``A, B >= 0`` solved
    exactly at every grid node). Arrays are ``(batch, n_gamma)``.

    Attributes
    ----------
    gamma : ndarray (G,)
        Distinct angles of incidence, radians.
    diffuse_index, specular_index : ndarray (B, G)
        Best ``n_d`` and ``n_s`` on the grids.
    diffuse, specular : ndarray (B, G)
        ``A = K (1 - a_s)`` and ``B = K a_s`` in power units.
    ok : ndarray (B, G) of bool
        The angle has at least 3 points with weight (else the other arrays are NaN).
    """

    gamma: np.ndarray
    diffuse_index: np.ndarray
    specular_index: np.ndarray
    diffuse: np.ndarray
    specular: np.ndarray
    ok: np.ndarray

    @property
    def specular_share(self) -> np.ndarray:
        total = self.diffuse + self.specular
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(total > 0, self.specular / total, np.nan)


def lobe_profile(gamma, theta, power, weights=None) -> LobeProfile:
    """Per-angle-of-incidence diffuse + specular decomposition (see :class:`LobeProfile`).

    gamma, theta : array-like (n,), radians. power : array-like (n,). weights : None, (n,)
    or (B, n) non-negative weights (zero drops a point: one row per subset of the table).
    The scale of ``power`` does not matter (the linear step absorbs it). Cost: a few
    matrix products per angle of incidence, so it runs on every fit.
    """
    gamma = np.asarray(gamma, float).ravel()
    theta = np.asarray(theta, float).ravel()
    power = np.asarray(power, float).ravel()
    w = np.ones((1, power.size)) if weights is None else np.atleast_2d(np.asarray(weights, float))
    b = w.shape[0]
    levels, group = np.unique(np.round(gamma, 9), return_inverse=True)
    nd, ns = PROFILE_DIFFUSE_INDICES, PROFILE_SPECULAR_INDICES
    with np.errstate(divide="ignore", invalid="ignore", under="ignore", over="ignore"):
        cos_t, cos_p = np.cos(theta), np.cos(-gamma - theta)
        pos_t, pos_p = cos_t > 0, cos_p > 0
        log_t = np.log(np.where(pos_t, cos_t, 1.0))
        log_p = np.log(np.where(pos_p, cos_p, 1.0))
        lobe_d = (nd[:, None] + 1) / TWO_PI * np.exp(nd[:, None] * log_t) * pos_t  # (D, n)
        lobe_s = (ns[:, None] + 1) / TWO_PI * np.exp(ns[:, None] * log_p) * pos_p  # (S, n)
    shape = (b, levels.size)
    out = {k: np.full(shape, np.nan) for k in ("nd", "ns", "a", "s")}
    ok = np.zeros(shape, bool)
    for g in range(levels.size):
        idx = np.flatnonzero(group == g)
        wg = w[:, idx]
        has = (wg > 0).sum(axis=1) >= 3
        if not has.any():
            continue
        ld, ls, y = lobe_d[:, idx], lobe_s[:, idx], power[idx]
        wy = wg * y
        gdd = wg @ (ld * ld).T  # (B, D)
        gss = wg @ (ls * ls).T  # (B, S)
        gds = ((wg[:, None, :] * ld[None]) @ ls.T)  # (B, D, S)
        rd, rs = wy @ ld.T, wy @ ls.T
        yy = (wy * y).sum(axis=1)
        cost, cd, cs = _two_column_nnls(gdd[:, :, None], gss[:, None, :], gds,
                                        rd[:, :, None], rs[:, None, :], yy[:, None, None])
        flat = np.argmin(cost.reshape(b, -1), axis=1)
        i, k = np.unravel_index(flat, cost.shape[1:])
        rows = np.arange(b)
        ok[:, g] = has
        out["nd"][:, g] = np.where(has, nd[i], np.nan)
        out["ns"][:, g] = np.where(has, ns[k], np.nan)
        out["a"][:, g] = np.where(has, cd[rows, i, k], np.nan)
        out["s"][:, g] = np.where(has, cs[rows, i, k], np.nan)
    return LobeProfile(gamma=levels, diffuse_index=out["nd"], specular_index=out["ns"],
                       diffuse=out["a"], specular=out["s"], ok=ok)


def _two_column_nnls(gdd, gss, gds, rd, rs, yy):
    """Least squares with two non-negative columns from their Gram entries (broadcast).

    Returns cost (up to the constant ``yy``), and the two coefficients. The constrained
    optimum is the unconstrained one if feasible, else the better one-column fit."""
    with np.errstate(divide="ignore", invalid="ignore"):
        det = gdd * gss - gds * gds
        good = det > 1e-12 * gdd * gss
        cd = np.where(good, (gss * rd - gds * rs) / det, -1.0)
        cs = np.where(good, (gdd * rs - gds * rd) / det, -1.0)
        both = (cd >= 0) & (cs >= 0)
        cost_both = np.where(both, yy - cd * rd - cs * rs, np.inf)
        d_only = np.where(gdd > 0, np.maximum(rd, 0) / gdd, 0.0)
        s_only = np.where(gss > 0, np.maximum(rs, 0) / gss, 0.0)
        cost_d = yy - d_only * rd
        cost_s = yy - s_only * rs
    best_single_d = cost_d <= cost_s
    cost_single = np.where(best_single_d, cost_d, cost_s)
    use_both = cost_both < cost_single
    cost = np.where(use_both, cost_both, cost_single)
    coef_d = np.where(use_both, cd, np.where(best_single_d, d_only, 0.0))
    coef_s = np.where(use_both, cs, np.where(best_single_d, 0.0, s_only))
    cost = np.where(np.isfinite(cost), cost, np.inf)
    return cost, np.broadcast_to(coef_d, cost.shape), np.broadcast_to(coef_s, cost.shape)


def _trend(x, y, valid):
    """Weighted straight line ``y = a + b x`` per row over the valid entries: (a, b).

    x : (G,); y, valid : (B, G). Rows with fewer than two distinct x give slope 0 and the
    mean; rows with no valid entry give NaN."""
    v = valid.astype(float)
    count = v.sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        yv = np.where(valid, y, 0.0)
        xm = (v * x).sum(axis=1) / count
        ym = yv.sum(axis=1) / count
        dx = np.where(valid, x[None, :] - xm[:, None], 0.0)
        sxx = (dx * dx).sum(axis=1)
        slope = np.where(sxx > 1e-12, (dx * (yv - ym[:, None])).sum(axis=1) / sxx, 0.0)
    return ym - slope * xm, slope


def estimate_specular_index(gamma, theta, power) -> float:
    """Data-driven guess of the specular lobe index: the median over angles of incidence
    of the per-angle optimum of :func:`lobe_profile` where a specular lobe is found
    (``B > 0``); 20 when none is.

    gamma, theta : array-like, radians. power : array-like.
    """
    return _median_specular_index(lobe_profile(gamma, theta, power))


def _median_specular_index(prof: LobeProfile) -> float:
    found = prof.ok[0] & (prof.specular[0] > 0)
    if not found.any():
        return 20.0
    return float(np.median(prof.specular_index[0][found]))


def peak_directions(gamma, theta, power, k: int = 4) -> list[tuple[float, float]]:
    """``(gamma, theta)`` in radians of the brightest point of each angle of incidence,
    for the ``k`` angles with the highest peaks: where a narrow lobe must point (lobes
    whose axis is free, as in Eq. 7, aim at a measured receiver, not at the mirror)."""
    gamma = np.asarray(gamma, float).ravel()
    theta = np.asarray(theta, float).ravel()
    power = np.asarray(power, float).ravel()
    out = []
    for g in np.unique(np.round(gamma, 9)):
        idx = np.flatnonzero(np.abs(gamma - g) < 1e-9)
        j = idx[np.argmax(power[idx])]
        out.append((power[j], float(gamma[j]), float(theta[j])))
    out.sort(key=lambda r: -r[0])
    return [(g, t) for _, g, t in out[:k]]


def two_lobe_profile_starts(profile: LobeProfile) -> np.ndarray:
    """Two-lobe starts ``z (B, S, 5)`` from a :class:`LobeProfile`: the straight lines
    ``ln n(gamma) = ln u + v ln cos(gamma)`` through the per-angle indices and specular
    shares (Eqs. 15, 17, 18), the same with constant indices (v = 0), and the specular
    index a factor 4 either side. Rows without any usable angle get the neutral start."""
    x = np.log(np.cos(profile.gamma))
    ok = profile.ok
    spec = ok & (profile.specular > 0)
    share = profile.specular_share
    with np.errstate(divide="ignore", invalid="ignore"):
        ln_nd, ln_ns, ln_as = (np.log(profile.diffuse_index), np.log(profile.specular_index),
                               np.log(share))
    a_nd, b_nd = _trend(x, ln_nd, ok)
    a_ns, b_ns = _trend(x, ln_ns, spec)
    _, b_as = _trend(x, ln_as, spec & (share > 0))
    const_nd, _ = _trend(np.zeros_like(x), ln_nd, ok)
    const_ns, _ = _trend(np.zeros_like(x), ln_ns, spec)
    fallback = np.array([0.0, 0.0, 0.3, np.log(30.0), 0.0])

    def row(*cols):
        z = np.column_stack(cols)
        return np.where(np.isfinite(z), z, fallback)

    zeros = np.zeros_like(a_nd)
    starts = [
        row(b_as, a_nd, b_nd, a_ns, b_ns),
        row(zeros, const_nd, zeros, const_ns, zeros),
        row(b_as, a_nd, b_nd, a_ns + np.log(4.0), b_ns),
        row(b_as, a_nd, b_nd, a_ns - np.log(4.0), b_ns),
        row(b_as, a_nd, b_nd, const_ns, zeros),
    ]
    return np.stack(starts, axis=1)


