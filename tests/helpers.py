"""Reference optimisers the tests hold irreflect's fitter to (independent of its search),
and a tiny room scene."""

from __future__ import annotations

import warnings

import numpy as np
from scipy.optimize import least_squares

from irreflect.models import Geometry, get_model


def least_squares_reference(model, meas, n_starts: int = 50, seed: int = 0,
                            max_nfev: int = 400) -> float:
    """Best cost ``0.5 * sum(residual^2)`` of plain bounded ``scipy.optimize.least_squares``
    (trust-region reflective) from ``n_starts`` random starts.

    It optimises all coefficients together in the model's internal coordinates (shape
    ``z`` in its bounds, within +-15; power scales ``alpha`` >= 0 where the model says so:
    the same box as irreflect's natural bounds) with the analytic Jacobian, starting from
    shapes drawn uniformly in the model's screening box and scales drawn from a flat
    Dirichlet matched to the data's level: no variable projection, no data-driven starts,
    no screening. Unweighted, as ``fit(..., use_sigma=False)``.
    """
    model = get_model(model)
    g, t, y = np.radians(meas.gamma_deg), np.radians(meas.theta_deg), np.asarray(meas.power)
    geom = Geometry.of(g[None], t[None])
    p, n_lin = model.n_nonlinear, model.n_linear
    zlo, zhi = np.maximum(model.z_lower, -15.0), np.minimum(model.z_upper, 15.0)
    lo = np.concatenate([zlo, np.where(model.alpha_nonneg, 0.0, -np.inf)])
    hi = np.concatenate([zhi, np.full(n_lin, np.inf)])

    def resid(x):
        with np.errstate(all="ignore"):
            b = model.curve_basis(geom, x[None, :p], x[None, p:])
            r = b[0] @ x[p:] - y
        return np.nan_to_num(r, nan=1e10, posinf=1e10, neginf=-1e10)

    def jac(x):
        with np.errstate(all="ignore"):
            b, db = model.basis(geom, x[None, :p], True)
            jz = np.einsum("nlp,l->np", db[0], x[p:])
        return np.nan_to_num(np.concatenate([jz, b[0]], axis=1))

    def resid_rows(_fun, xs):
        """``resid`` of every point of ``xs`` (a map over them, as scipy's ``workers``
        is called): the basis of all points in one call, then the product and the
        clean-up point by point as in ``resid``, so the same numbers."""
        x = np.array(list(xs), float)
        with np.errstate(all="ignore"):
            b = model.curve_basis(geom, x[:, :p], x[:, p:])
            rows = np.array([b[k] @ x[k, p:] - y for k in range(len(x))])
        return list(np.nan_to_num(rows, nan=1e10, posinf=1e10, neginf=-1e10))

    # a saturating share (model.share_cap): the curve is piecewise in the coefficients, so
    # the reference takes finite differences of it rather than sharing the fitter's
    # derivative of the saturated rows; scipy's 3-point scheme evaluates its 2 x (p + L)
    # shifted points through ``workers`` (a map), here all in one call of the basis
    jac_used = "3-point" if model.share_cap else jac
    fd_map = resid_rows if model.share_cap else None
    # least_squares takes ``workers`` from scipy 1.16 on (pyproject allows 1.11): older
    # ones evaluate the same points one call each
    import inspect

    extra = ({"workers": fd_map}
             if "workers" in inspect.signature(least_squares).parameters else {})

    rng = np.random.default_rng(seed)
    slo, shi = model.screen_box()
    best = np.inf
    for _ in range(n_starts):
        z0 = rng.uniform(np.maximum(slo, zlo), np.minimum(shi, zhi))
        with np.errstate(all="ignore"):
            b, _ = model.basis(geom, z0[None], False)
        shares = rng.dirichlet(np.ones(n_lin))
        with np.errstate(all="ignore"):
            total = np.nan_to_num(b[0] @ shares)
        with np.errstate(all="ignore"):
            level = max(float(total @ y) / max(float(total @ total), 1e-300), 1e-12)
        x0 = np.clip(np.concatenate([z0, shares * level]), lo, hi)
        try:
            with warnings.catch_warnings():  # scipy's overflow notes on wild starts
                warnings.simplefilter("ignore", RuntimeWarning)
                res = least_squares(resid, x0, jac=jac_used, bounds=(lo, hi),
                                    max_nfev=max_nfev, **extra)
        except ValueError:  # a start where the model is not finite
            continue
        best = min(best, float(res.cost))
    return best


def noisy_oren_nayar(seed: int):
    """A rough matte surface the model does not describe (qualitative Oren-Nayar, facet
    slope sigma 0.246 rad, times cos(gamma): a held-out table's generator, lambert-6 of
    experiments/unseen_tables.py --random 30 --first-seed 9400) with 2.9 % noise."""
    import pandas as pd

    g = np.repeat([-8.0, -23.0, -41.0, -57.0, -72.0], 86)
    t = np.tile(np.arange(-85.0, 86.0, 2.0), 5)
    keep = np.abs(t - g) > 8  # the receiver kept off the source
    g, t = g[keep], t[keep]
    gi, tr = np.radians(-g), np.radians(t)
    s2 = 0.2457 ** 2
    a, b = 1 - 0.5 * s2 / (s2 + 0.33), 0.45 * s2 / (s2 + 0.09)
    big, small = np.maximum(gi, np.abs(tr)), np.minimum(gi, np.abs(tr))
    y = (a + b * (tr < 0) * np.sin(big) * np.tan(small)) * np.cos(tr) * np.cos(gi)
    y = y / y.max() * 19.33
    rng = np.random.default_rng(seed)
    y = y * (1 + 0.029 * rng.standard_normal(y.size)) + 1e-4 * y.max() * rng.standard_normal(y.size)
    return pd.DataFrame({"gamma_deg": g, "theta_deg": t, "power": y})


def tiny_room(floor: str = "white", materials: str = "") -> str:
    """A 3 x 3 x 2.5 m room scene (TOML): Lambertian white walls and ceiling, the floor
    material ``floor`` (defined in ``materials``, more TOML, unless it is ``white``), one
    lamp at the ceiling and one receiver."""
    return f"""
[scene]
name = "tiny"
[room]
size_m = [3.0, 3.0, 2.5]
[room.materials]
walls = "white"
ceiling = "white"
floor = "{floor}"
[materials.white]
lambertian = 0.7
{materials}
[[emitter]]
name = "lamp"
position_m = [1.5, 1.5, 2.5]
direction = [0, 0, -1]
lambertian_order = 1
power_w = 1.0
[[receiver]]
name = "rx"
position_m = [0.5, 1.0, 0.8]
direction = [0, 0, 1]
area_m2 = 1e-4
fov_deg = 85
"""
