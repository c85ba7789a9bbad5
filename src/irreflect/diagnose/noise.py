"""The measurement noise of a table, and the likelihood that compares explanations of it.

Noise model: ``sigma_i^2 = a^2 + (b P_i)^2``, an additive part ``a`` (detector noise) and
one proportional to the signal ``P_i`` (source drift, speckle, gain noise), the usual
two-component variance function of photometric instruments (Carroll and Ruppert 1988,
"Transformation and weighting in regression", ch. 3).

* :func:`estimate_noise`: the table's ``sigma`` column when it has one; otherwise
  estimated from differences along theta within each angle of incidence (Gasser, Sroka
  and Jennen-Steinmetz 1986) of a fitted model's residuals: every run of three receiver
  angles gives a pseudo-residual blind to a local quadratic, of variance
  ``sum_j w_j^2 sigma_j^2``. ``a`` alone is the robust (3-MAD clipped) RMS of those; with
  the fitted power given, ``(a, b)`` by maximum likelihood, kept only if the likelihood
  ratio against ``b = 0`` is significant at ``alpha`` (a boundary test: half chi-square(1)).
  Where the power exceeds what the resolved windows cover (the peak of a lobe narrower
  than the receiver step), the table cannot say how large the noise is: there the largest
  proportional part it allows (the one-sided ``1 - alpha`` bound of ``b``) is used, and an
  effect is not named on the strength of those points alone. A ``sigma`` column removes
  the doubt.
* :func:`deviance`: ``chi2 = sum (r / sigma)^2`` with that noise (given or estimated, the
  same for every explanation): ``-2 log L`` up to a constant, the quantity the diagnosis
  compares between explanations. (The variance profiled per model would let a model that
  fits the few highest points exactly drive their variance to zero and win by that.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

from .._text import p_text
from ..data import as_measurements
from ..errors import IrreflectError

_MAD_TO_SIGMA = 1.0 / special.ndtri(0.75)  # normal quantile: 1 / 0.6745
#: ratios ``b^2 max(P^2) / a^2`` scanned by the maximum-likelihood fits (then refined)
_RATIO_GRID = np.concatenate([[0.0], np.logspace(-3.0, 8.0, 45)])
#: a window over which the log of the fitted power bends by more than this (the second
#: difference of ln P across its three receivers, scaled to the steps: 1 = the model
#: leaves a straight line in ln P by a factor e) does not resolve the model: a narrow lobe
#: seen by one or two receivers, where a shift of the lobe by a fraction of a step
#: changes the power by a fraction of itself, which is what noise proportional to the
#: power looks like. A Lambertian fall toward grazing bends by a few tenths.
LOG_BEND = 1.0


@dataclass(frozen=True)
class NoiseEstimate:
    """Measurement noise: per-point 1-sigma ``sigma`` (power units), its typical value
    ``value`` (median), where it came from (``source``: "given" or "estimated"), the
    degrees of freedom of the estimate (``inf`` when given), how (``method``), and the
    variance function ``sigma^2 = additive^2 + (relative * P)^2`` (``relative`` 0 when
    only additive noise was found; for a given sigma, the least-squares fit of that
    function to the column)."""

    sigma: np.ndarray
    value: float
    source: str
    dof: float
    method: str
    additive: float = float("nan")
    relative: float = 0.0

    def sigma_at(self, power) -> np.ndarray:
        """The noise the variance function predicts at ``power`` (for new settings)."""
        p = np.clip(np.asarray(power, float), 0.0, None)
        a = self.additive if np.isfinite(self.additive) else self.value
        return np.sqrt(a * a + (self.relative * p) ** 2)


def difference_weights(gamma_deg, theta_deg, order: int = 2):
    """Weights of the difference-based pseudo-residuals along theta within each gamma.

    Every run of ``order + 1`` consecutive receiver angles (sorted, same angle of incidence)
    gives one pseudo-residual ``e = sum_j w_j y_j`` with ``w`` the divided-difference
    weights of that run normalised to unit length: ``e`` is blind to any polynomial of
    degree < ``order`` in theta and has variance ``sigma^2`` for pure noise (Gasser et al.
    1986 for ``order = 2``). Returns a sparse ``(windows, n)`` matrix (``order + 1`` values
    per row: a dense one would hold 3.2 GB on a 20,000-point table); angles in degrees.
    """
    from scipy import sparse

    gamma_deg = np.asarray(gamma_deg, float)
    theta = np.radians(np.asarray(theta_deg, float))
    n = gamma_deg.size
    k = order + 1
    cols, vals = [], []
    for g in np.unique(gamma_deg):
        idx = np.nonzero(gamma_deg == g)[0]
        idx = idx[np.argsort(theta[idx], kind="stable")]
        if idx.size < k:
            continue
        win = np.lib.stride_tricks.sliding_window_view(idx, k)  # (windows, k)
        x = theta[win]
        diff = x[:, :, None] - x[:, None, :]
        diff[:, np.arange(k), np.arange(k)] = 1.0
        good = ~np.any(diff == 0, axis=(1, 2))
        w = 1.0 / np.prod(diff[good], axis=2)
        cols.append(win[good])
        vals.append(w / np.linalg.norm(w, axis=1, keepdims=True))
    cols = np.concatenate(cols) if cols else np.zeros((0, k), np.int64)
    vals = np.concatenate(vals) if vals else np.zeros((0, k))
    m = cols.shape[0]
    return sparse.csr_array((vals.ravel(), cols.ravel(), np.arange(0, m * k + 1, k)),
                            shape=(m, n))


def clipped_scale(e, clip: float = 3.0) -> np.ndarray:
    """Robust RMS along the last axis: pseudo-residuals beyond ``clip`` times the MAD scale
    are dropped (sharp features the differences do not cancel), the RMS of the rest is
    corrected for the truncation of a normal distribution at ``clip`` sigma. As efficient
    as the plain RMS on pure noise, as robust as the median when a minority is spoiled."""
    e = np.atleast_2d(np.asarray(e, float))
    s0 = _MAD_TO_SIGMA * np.median(np.abs(e), axis=-1, keepdims=True)
    keep = np.abs(e) <= clip * s0
    pdf = np.exp(-0.5 * clip * clip) / np.sqrt(2.0 * np.pi)
    kept_var = 1.0 - 2.0 * clip * pdf / (2.0 * special.ndtr(clip) - 1.0)
    mean_sq = np.sum(np.where(keep, e * e, 0.0), axis=-1) / np.maximum(np.sum(keep, axis=-1), 1)
    return np.sqrt(mean_sq / kept_var)


def _huber(x, c2: float):
    """Huber's loss of squared standardised residuals ``x``: ``x`` up to ``c2``, then
    ``2 c sqrt(x) - c2`` (linear in the residual: a few gross residuals cannot dominate,
    and a variance shrinking to zero still costs more than it gains)."""
    c = np.sqrt(c2)
    return np.where(x <= c2, x, 2.0 * c * np.sqrt(np.maximum(x, 0.0)) - c2)


def _profile(e2: np.ndarray, s2: np.ndarray, scale: float, ratios=_RATIO_GRID,
             robust: bool = False):
    """Maximum likelihood of ``v = A (1 + rho s2)`` for squared residuals ``e2``: the
    ``rho`` (in units of ``1 / scale``) and ``A`` with the least ``-2 log L``.
    ``robust``: Huber's loss at 5 sigma instead of the squares (a few sharp misfits the
    differences did not cancel cannot drive the fit). Returns ``(nll, A, rho)``;
    ``nll = sum ln v + loss(e2 / v)`` (without ``n ln 2 pi``)."""
    rhos = np.asarray(ratios, float) / max(scale, 1e-300)
    c2 = 25.0

    def nll(rho):
        g = 1.0 + rho * s2
        u = e2 / g
        a = max(float(np.mean(u)), 1e-300)
        if robust:  # Huber's scale: reweight the largest, a few fixed-point steps
            for _ in range(4):
                with np.errstate(over="ignore", divide="ignore"):  # u = 0: weight 1
                    w = np.minimum(1.0, np.sqrt(c2 * a / u))
                a = max(float(np.mean(w * u)), 1e-300)
            return float(np.sum(np.log(a * g) + _huber(u / a, c2))), a
        return float(np.sum(np.log(a * g)) + u.size), a

    values = [nll(r) for r in rhos]
    i = int(np.argmin([v[0] for v in values]))
    best = (values[i][0], values[i][1], rhos[i])
    if 0 < i:  # refine between the neighbours on a log scale
        lo = np.log(rhos[max(i - 1, 1)])
        hi = np.log(rhos[min(i + 1, rhos.size - 1)])
        for r in np.exp(np.linspace(lo, hi, 13)):
            v, a = nll(r)
            if v < best[0]:
                best = (v, a, r)
    return best


def _upper_b(e2, s2, big_a, big_b, allowance) -> float:
    """With the additive variance held at ``big_a``, the largest proportional coefficient
    ``b`` (``v = A + b^2 s2``) whose ``-2 log L`` (Huber's, as in :func:`_profile`) is
    within ``allowance`` of that at ``big_b``."""
    c2 = 25.0

    def nll(bb):
        v = np.maximum(big_a + bb * s2, 1e-300)
        return float(np.sum(np.log(v) + _huber(e2 / v, c2)))

    best = nll(big_b)
    scale = max(float(np.max(s2)), 1e-300)
    lo = max(big_b, 1e-12 * big_a / scale)
    hi = lo
    for _ in range(80):  # bracket: grow until the likelihood has fallen by the allowance
        hi *= 4.0
        if nll(hi) - best > allowance:
            break
    else:
        return float(np.sqrt(hi))
    a, b = np.log(max(lo, 1e-300)), np.log(hi)
    for _ in range(40):
        mid = 0.5 * (a + b)
        if nll(np.exp(mid)) - best <= allowance:
            a = mid
        else:
            b = mid
    return float(np.sqrt(np.exp(a)))


def _nll_ab(e2, s2, big_a, big_b) -> float:
    """``-2 log L`` (Huber's, as in :func:`_profile`) of the window variances
    ``v = A + B s2``."""
    v = np.maximum(big_a + big_b * s2, 1e-300)
    with np.errstate(over="ignore"):  # a variance of ~0 where a residual is not: inf
        return float(np.sum(np.log(v) + _huber(e2 / v, 25.0)))


def _upper_a(e2, s2, big_a, big_b, allowance) -> float:
    """With the proportional variance held at ``big_b``, the largest additive scale ``a``
    (``v = a^2 + B s2``) whose ``-2 log L`` is within ``allowance`` of the best over
    ``a`` in ``[0, inf)``."""
    best = min(_nll_ab(e2, s2, big_a, big_b), _nll_ab(e2, s2, 0.0, big_b))
    typical = float(np.median(e2)) if e2.size else 0.0
    lo = max(big_a, 1e-24 * max(typical, 1e-300))
    hi = lo
    for _ in range(80):  # bracket: grow until the likelihood has fallen by the allowance
        hi *= 4.0
        if _nll_ab(e2, s2, hi, big_b) - best > allowance:
            break
    else:
        return float(np.sqrt(hi))
    a, b = np.log(lo), np.log(hi)
    for _ in range(40):
        mid = 0.5 * (a + b)
        if _nll_ab(e2, s2, np.exp(mid), big_b) - best <= allowance:
            a = mid
        else:
            b = mid
    return float(np.sqrt(np.exp(a)))


def deviance(residuals, fitted, noise: NoiseEstimate) -> float:
    """``chi2 = sum (r / sigma)^2`` of a model's residuals under the noise model (-2 log L
    up to a constant, the noise being fixed: given, or estimated once from the base model
    and used for every explanation alike). ``fitted`` is accepted for models of the noise
    that depend on the prediction; the fixed noise does not."""
    r = np.asarray(residuals, float)
    return float(np.sum((r / noise.sigma) ** 2))


def _additive_bound(e2, s2, big_a, rho, alpha, a_hat) -> tuple[float, str]:
    """The additive noise part when a proportional part was found, and a note.

    The additive part is then told only by the windows of the lowest power; when they
    cannot tell it from zero (the likelihood ratio of a = 0 is not significant at alpha) a
    zero would make the faintest points look exact and any small misfit there an effect:
    its one-sided 1 - alpha upper bound is used, as for the proportional part above the
    covered powers."""
    allowance = float(special.chdtri(1, 2 * alpha))
    big_b = big_a * rho
    lr_a = _nll_ab(e2, s2, 0.0, big_b) - _nll_ab(e2, s2, big_a, big_b)
    if lr_a < allowance:
        a_up = _upper_a(e2, s2, big_a, big_b, allowance)
        if a_up > a_hat:
            return a_up, (f"; the additive part is not told from zero (likelihood ratio "
                          f"{max(lr_a, 0.0):.2g}): its upper bound a = {a_up:.3g}")
    return a_hat, ""


def estimate_noise(measurements, residuals=None, *, fitted=None, order: int = 2, seed: int = 0,
                   n_sim: int = 400, alpha: float = 0.01) -> NoiseEstimate:
    """Noise of a measurement table: the ``sigma`` column if present, else estimated.

    Parameters
    ----------
    measurements : Measurements
    residuals : array, optional
        Residuals of a fitted model (power units). The estimator is applied to them instead
        of the raw power: the model takes out the sharp specular peak, the differences take
        out what smooth misfit is left. Without them, the raw power is used.
    fitted : array, optional
        The fitted power of that model. Given, noise proportional to the signal is looked
        for too (``sigma^2 = a^2 + (b P)^2``, kept if significant at ``alpha``); without
        it the noise is taken as constant.
    order : int
        Order of the differences (2: three consecutive receiver angles).
    seed : int
        Seeds the simulation that measures the estimate's degrees of freedom.
    n_sim : int
        Pure-noise replicates of that simulation.
    alpha : float
        Level of the test for a proportional part.

    Returns
    -------
    NoiseEstimate
        Per-point sigma, with the degrees of freedom ``1 / (2 var(ln s))`` of the overall
        scale ``s`` of the estimate, measured on simulated noise of that sigma on this grid.

    Raises
    ------
    IrreflectError
        If no angle of incidence has ``order + 1`` receiver angles and no sigma is given.
    """
    meas = as_measurements(measurements)
    if meas.sigma is not None:
        sigma = np.asarray(meas.sigma, float)
        a, b = _fit_variance_function(sigma, fitted if fitted is not None else meas.power)
        return NoiseEstimate(sigma=sigma, value=float(np.median(sigma)), source="given",
                             dof=float("inf"), method="sigma column of the table",
                             additive=a, relative=b)
    weights = difference_weights(meas.gamma_deg, meas.theta_deg, order)
    if weights.shape[0] < 5:
        raise IrreflectError(
            f"cannot estimate the measurement noise: found {weights.shape[0]} runs of "
            f"{order + 1} receiver angles at one angle of incidence, need at least 5; "
            "add a sigma column to the table or measure more receiver angles per gamma"
        )
    values = meas.power if residuals is None else np.asarray(residuals, float)
    e = weights @ values
    floor = 1e-12 * max(float(np.max(np.abs(meas.power))), 1e-300)
    a_hat = max(float(clipped_scale(e)[0]), floor)
    b_hat = 0.0
    extra = 0.0
    test = ""
    if fitted is not None:
        f = np.clip(np.asarray(fitted, float), 0.0, None)
        s2 = np.asarray((weights * weights) @ (f * f), float)  # sum_j w_j^2 P_j^2 per window
        # windows where the model itself changes fast on the scale of the grid (a narrow
        # lobe, its flanks): there the model's own error does not cancel in the
        # differences, and it would pass for noise proportional to the power
        # (the bend of ln(P + a), with ``a`` the robust scale of all pseudo-residuals:
        # where the model lies below the noise, how sharply it bends cannot matter, and
        # those windows are what tells the additive part; a power of exactly zero, far
        # from a narrow lobe, would otherwise leave them out and the additive part would
        # collapse to nothing)
        smooth = _log_bend(weights, meas.theta_deg, f + a_hat) <= LOG_BEND
        e2, s2 = (e * e)[smooth], s2[smooth]
        scale = float(np.max(s2)) if s2.size else 1.0
        nll0, _, _ = _profile(e2, s2, scale, ratios=[0.0], robust=True)
        nll1, big_a, rho = _profile(e2, s2, scale, robust=True)
        lr = nll0 - nll1
        p = 0.5 * float(special.chdtrc(1, lr)) if lr > 0 else 1.0
        if p < alpha and rho > 0:
            a_hat = max(float(np.sqrt(big_a)), floor)
            b_hat = float(np.sqrt(big_a * rho))
            test = f"; noise proportional to the power found (likelihood ratio {p_text(p)})"
            a_hat, note = _additive_bound(e2, s2, big_a, rho, alpha, a_hat)
            test += note
        else:
            big_a, rho = a_hat * a_hat, 0.0
            test = f"; no noise proportional to the power found (p = {p:.2g})"
        if e2.size:
            # beyond the powers the resolved windows cover (a narrow lobe's peak seen by
            # one receiver) the table cannot tell how large the noise is: there the largest
            # proportional part it allows (one-sided 1 - alpha bound) is used
            b_up = _upper_b(e2, s2, big_a, big_a * rho, float(special.chdtri(1, 2 * alpha)))
            covered = float(np.max(s2))
            f_all = np.clip(np.asarray(fitted, float), 0.0, None)
            beyond = np.maximum(f_all * f_all - covered, 0.0)
            if b_up > b_hat and np.any(beyond > 0):
                extra = (b_up * b_up - b_hat * b_hat) * beyond
                test += (f"; above the power {np.sqrt(covered):.3g} the resolved windows "
                         f"reach ({int(np.sum(beyond > 0))} points), its upper bound "
                         f"b = {b_up:.2g}")
    fit_power = np.clip(np.asarray(fitted, float), 0.0, None) if fitted is not None else 0.0
    sigma = np.sqrt(a_hat * a_hat + (b_hat * fit_power) ** 2 + extra) * np.ones(meas.n_points)
    # degrees of freedom of the overall scale: simulate noise of this sigma on this grid
    rng = np.random.default_rng(seed)
    sim = weights @ (sigma[:, None] * rng.standard_normal((meas.n_points, n_sim)))
    window_sigma = np.sqrt(np.asarray((weights * weights) @ (sigma * sigma), float))
    log_s = np.log(clipped_scale((sim / window_sigma[:, None]).T))
    dof = float(1.0 / (2.0 * max(np.var(log_s), 1e-12)))
    what = "base-model residuals" if residuals is not None else "measured power"
    law = (f"sigma^2 = {a_hat:.3g}^2 + ({b_hat:.3g} P)^2" if b_hat > 0 else "constant")
    return NoiseEstimate(
        sigma=sigma, value=float(np.median(sigma)), source="estimated", dof=dof,
        method=f"order-{order} differences of the {what} along theta within each gamma "
               f"({weights.shape[0]} pseudo-residuals, {dof:.0f} effective dof), {law}{test}",
        additive=a_hat, relative=b_hat,
    )


def _log_bend(weights, theta_deg, values) -> np.ndarray:
    """Per difference window of three receivers, ``|l1 h2 - l2 (h1 + h2) + l3 h1| /
    ((h1 + h2) / 2)`` with ``l = ln P`` and ``h`` the two steps: the second difference of
    ``ln P`` scaled to the steps (``|l1 - 2 l2 + l3|`` on an even grid); ``inf`` where the
    power is not positive."""
    w = weights.tocsr()
    cols = w.indices.reshape(w.shape[0], -1)
    if cols.shape[1] != 3:
        return np.zeros(cols.shape[0])
    t = np.asarray(theta_deg, float)[cols]
    order = np.argsort(t, axis=1)
    t = np.take_along_axis(t, order, axis=1)
    v = np.take_along_axis(np.asarray(values, float)[cols], order, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        lv = np.where(v > 0, np.log(np.where(v > 0, v, 1.0)), -np.inf)
        h1, h2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 1]
        bend = np.abs(lv[:, 0] * h2 - lv[:, 1] * (h1 + h2) + lv[:, 2] * h1) / (0.5 * (h1 + h2))
    return np.where(np.isfinite(bend), bend, np.inf)


def _fit_variance_function(sigma, power) -> tuple[float, float]:
    """Least-squares ``(a, b)`` of ``sigma^2 = a^2 + b^2 P^2`` (non-negative), to carry a
    given sigma column to settings not measured."""
    s2 = np.asarray(sigma, float) ** 2
    p2 = np.clip(np.asarray(power, float), 0.0, None) ** 2
    design = np.column_stack([np.ones_like(p2), p2])
    from scipy.optimize import nnls

    coef, _ = nnls(design / s2[:, None], np.ones_like(s2))  # relative least squares
    return float(np.sqrt(coef[0])), float(np.sqrt(coef[1]))
