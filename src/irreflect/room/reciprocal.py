"""A reciprocal surface model fitted to a material's in-plane curve.

The paper's two-component model, extended to 3D as the paper describes it, is not
reciprocal: its specular share and lobe indices follow the angle of incidence only and its
diffuse lobe the exit angle only, so ``f(i -> o) != f(o -> i)`` (1.4-3.6x on a fitted glossy
paint) and a room's response changes when emitter and receiver swap places. Helmholtz
reciprocity asks ``f(i, o) = f(o, i)``. The room therefore uses, by default, a BRDF that is
reciprocal *by construction* and fitted to the material's fitted curve:

    f(i, o) = sum_k c_k b_k(i, o),     c_k >= 0,

a non-negative combination of terms each symmetric in ``i`` and ``o`` (so the sum is too):

* diffuse terms ``(p+2)/(2 pi) cos^p(theta_i) cos^p(theta_o)``, p in 0, 0.5, 1, 2, 4, 8, 16
  (a Lambertian surface is ``p = 0``; larger ``p`` darkens grazing incidence and exit);
* mirror lobes ``(n+1)/(2 pi) cos^n(psi) W(theta_d)``: ``psi`` is the angle between ``o`` and
  the mirror direction of ``i`` (the same as between ``i`` and the mirror direction of
  ``o``), the paper's specular lobe of revolution about the mirror direction (section 3.4);
  ``theta_d`` is the angle between ``i`` and the half vector (Rusinkiewicz), which is the
  angle of incidence at the specular peak, and ``W`` is 1, ``1 / cos(theta_d)`` (the
  paper's constant-share lobe written as a BRDF) or ``(1 - cos theta_d)^q / cos theta_d``,
  q = 1, 2, 3, 5, 8 (a share that grows towards grazing incidence, as the fitted
  ``a_s = u_as cos^v_as(gamma)`` with ``v_as < 0`` does; Schlick's Fresnel form is q = 5);
* retro lobes ``(n+1)/(2 pi) cos^n`` of the angle between ``o`` and ``i``.

Lobe indices lie on a ladder of ratio 1.5 from 1 to 85,000. This is the family of
reciprocal Phong lobes (Lewis 1994) and Lafortune's cosine lobes (1997) with Fresnel-like
weights as in Ashikhmin-Shirley (2000), fitted by non-negative least squares (Lawson-Hanson,
:func:`scipy.optimize.nnls`) to the fitted model's curve in the plane of incidence, over the
measured angles of incidence (every 2 deg) and receiver angles (every 1 deg, refined to
0.05 deg around sharp lobes), weighted as an integral over the plane; at most
:data:`~.kernels.TERMS_MAX` terms are kept. Non-negative terms keep ``f >= 0``; the energy
bound (albedo <= 1 at every incidence) is checked when the material is scaled
(:mod:`.materials`).
"""

from __future__ import annotations

import numpy as np

from .kernels import (
    N_COS,
    N_GAMMA,
    N_VALUES,
    P_EXPONENTS,
    TERM_DIFFUSE,
    TERM_MIRROR,
    TERM_RETRO,
    TERMS_MAX,
    W_POWERS,
    term_albedo_table,
)

#: Gauss-Legendre nodes on [0, 1] for the lobes' albedo quadrature
_X, _W = np.polynomial.legendre.leggauss(32)
_X, _W = (_X + 1) / 2, _W / 2


def dictionary() -> np.ndarray:
    """Every candidate term as rows ``[kind, index, q]`` (q: index into W_POWERS)."""
    rows = [[TERM_DIFFUSE, j, 0] for j in range(P_EXPONENTS.size)]
    for k in range(N_VALUES.size):
        rows += [[TERM_MIRROR, k, q] for q in range(W_POWERS.size)]
        rows.append([TERM_RETRO, k, 0])
    return np.array(rows, np.int64)


def _w(q, cd):
    if q == 0:
        return np.ones_like(cd)
    return (1.0 - cd) ** W_POWERS[q] / cd


def plane_columns(terms, gamma, theta) -> np.ndarray:
    """In-plane intensity ``f(i, o) cos(theta_o)`` of unit-amplitude terms (rows
    ``[kind, index, q]``) at angle of incidence ``gamma`` (>= 0) and receiver angle
    ``theta`` (positive on the mirror side), radians. Returns (len(gamma), len(terms))."""
    g, t = np.broadcast_arrays(np.abs(np.asarray(gamma, float)), np.asarray(theta, float))
    g, t = g.ravel(), t.ravel()
    ct = np.cos(t)
    up = np.abs(t) < np.pi / 2
    cg = np.cos(g)
    cm = np.cos(t - g)              # o . mirror(i)
    cr = np.cos(t + g)              # o . i
    cd = np.maximum(np.abs(np.cos((g + t) / 2)), 1e-6)
    with np.errstate(divide="ignore", invalid="ignore", under="ignore", over="ignore"):
        lcm = np.log(np.where(cm > 0, cm, 1.0))
        lcr = np.log(np.where(cr > 0, cr, 1.0))
        out = np.zeros((g.size, len(terms)))
        for c, (kind, idx, q) in enumerate(terms):
            if kind == TERM_DIFFUSE:
                p = P_EXPONENTS[idx]
                v = (p + 2) / (2 * np.pi) * np.clip(cg * ct, 0, None) ** p
            elif kind == TERM_MIRROR:
                n = N_VALUES[idx]
                v = np.where(cm > 0, (n + 1) / (2 * np.pi) * np.exp(n * lcm), 0.0) * _w(q, cd)
            else:
                n = N_VALUES[idx]
                v = np.where(cr > 0, (n + 1) / (2 * np.pi) * np.exp(n * lcr), 0.0)
            out[:, c] = np.where(up, v * ct, 0.0)
    return out


def amplitude(terms, coef) -> np.ndarray:
    """Amplitudes ``c_k x`` the term's normalising constant, as the kernels store them."""
    out = np.empty(len(terms))
    for c, (kind, idx, _q) in enumerate(terms):
        norm = (P_EXPONENTS[idx] + 2) if kind == TERM_DIFFUSE else (N_VALUES[idx] + 1)
        out[c] = coef[c] * norm / (2 * np.pi)
    return out


def plane_grid(gamma_lo, gamma_hi, peaks=None):
    """Rows of the fit: angles of incidence every <= 2 deg over [gamma_lo, gamma_hi] and
    receiver angles every 1 deg over (-89.5, 89.5), refined around ``peaks(gamma)`` (the
    receiver angles of the material's lobe axes; the mirror direction at least), with
    trapezoid weights along theta. Radians; returns (gamma, theta, weight)."""
    lo, hi = sorted((abs(gamma_lo), abs(gamma_hi)))
    n_g = max(2, int(np.ceil(np.degrees(hi - lo) / 2.0)) + 1) if hi > lo else 1
    base = np.radians(np.arange(-89.5, 89.51, 1.0))
    fine = np.radians(np.concatenate([np.arange(-1.0, 1.001, 0.05), np.arange(-5.0, 5.001, 0.25)]))
    G, T, W = [], [], []
    for g in np.linspace(lo, hi, n_g):
        axes = [g] if peaks is None else list(peaks(g))
        th = np.concatenate([base] + [a + fine for a in axes])
        th = np.unique(np.round(th[np.abs(th) < np.radians(89.9)], 12))
        w = np.gradient(th) if th.size > 1 else np.ones(1)
        G.append(np.full(th.size, g))
        T.append(th)
        W.append(w / np.radians(1.0))
    return np.concatenate(G), np.concatenate(T), np.concatenate(W)


def weighted_r2(y, yhat, w) -> float:
    ybar = np.sum(w * y) / np.sum(w)
    ss_tot = np.sum(w * (y - ybar) ** 2)
    return float(1.0 - np.sum(w * (y - yhat) ** 2) / ss_tot) if ss_tot > 0 else float("nan")


def fit_terms(gamma, theta, weight, target, max_terms: int = TERMS_MAX):
    """Non-negative least-squares fit of the family to ``target`` (in-plane intensity).

    Returns ``terms`` (T, 3) ``[kind, index, q]``, their coefficients (T,) (unit-amplitude
    columns, same units as ``target``) and the weighted R^2 against the target. Every
    column is scaled to unit weighted norm first; when more than ``max_terms`` terms come
    out, the largest contributions are kept and refitted.
    """
    from scipy.optimize import nnls  # deferred: only a material build needs it

    cand = dictionary()
    A = plane_columns(cand, gamma, theta)
    sw = np.sqrt(weight)
    Aw = A * sw[:, None]
    norms = np.linalg.norm(Aw, axis=0)
    keep = norms > 0
    cand, A, Aw, norms = cand[keep], A[:, keep], Aw[:, keep], norms[keep]
    yw = target * sw
    coef, _ = nnls(Aw / norms, yw, maxiter=50 * A.shape[1])
    coef = coef / norms
    on = np.nonzero(coef > 0)[0]
    if on.size > max_terms:
        contrib = coef[on] * norms[on]
        on = on[np.argsort(contrib)[::-1][:max_terms]]
        sub, _ = nnls(Aw[:, on] / norms[on], yw, maxiter=50 * on.size)
        coef = np.zeros_like(coef)
        coef[on] = sub / norms[on]
        on = on[coef[on] > 0]
    order = np.lexsort((cand[on, 2], cand[on, 1], cand[on, 0]))  # kind, then index: the kernels' order
    on = on[order]
    fitted = A[:, on] @ coef[on]
    return cand[on], coef[on], weighted_r2(target, fitted, weight)


def albedo_tables(terms, coef, gammas, cap=None) -> np.ndarray:
    """Albedo of each term with its coefficient over ``gammas`` (T, len(gammas)), with the
    energy cap ``cap`` (values over cos theta at N_COS nodes) on the outgoing side."""
    gtab = np.ones(N_COS) if cap is None else np.asarray(cap, float)
    gammas = np.asarray(gammas, float)
    # the albedo is smooth in gamma: quadrature at every 4th of many nodes, interpolated
    nodes = gammas if gammas.size <= 40 else np.unique(np.append(gammas[::4], gammas[-1]))
    out = np.empty((len(terms), len(gammas)))
    where = (np.ascontiguousarray(nodes).tobytes(), np.ascontiguousarray(gtab).tobytes())
    for c, (kind, idx, q) in enumerate(terms):
        vals = coef[c] * _term_albedo(int(kind), int(idx), int(q), nodes, gtab, where)
        out[c] = vals if nodes is gammas else np.interp(gammas, nodes, vals)
    return out


#: Unit-amplitude term albedos already computed, by (kind, index, q, nodes, cap): a material
#: asks for the same ones again (the energy cap's search, its final tables; the same
#: material in every scene that names it, e.g. a scene read again) and each costs a
#: quadrature of 2 x 32 x 32 directions per node.
_TERM_ALBEDO: dict = {}


def _term_albedo(kind: int, idx: int, q: int, nodes, gtab, where: tuple) -> np.ndarray:
    key = (kind, idx, q, *where)
    hit = _TERM_ALBEDO.get(key)
    if hit is None:
        hit = term_albedo_table(kind, idx, q, nodes, gtab, _X, _W)
        hit.flags.writeable = False
        if len(_TERM_ALBEDO) >= 4096:
            _TERM_ALBEDO.clear()
        _TERM_ALBEDO[key] = hit
    return hit


__all__ = ["dictionary", "plane_columns", "plane_grid", "fit_terms", "albedo_tables",
           "amplitude", "weighted_r2", "N_GAMMA"]
