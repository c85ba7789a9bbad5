"""Which measurements would tell explanations apart that the data cannot.

When explanations are ambiguous (each fits as well as the model that holds both), their
fitted models still predict different power where the table has not measured: a constant
receiver offset and an off-specular tilt agree at grazing angles of incidence and part
near the normal (where the tilt vanishes as ``sin^2 gamma``); a background and a
reflectance that varies with gamma agree on a bright lobe and part far from it.

A difference in prediction is not yet a separation: refitted to a new reading, each
explanation moves its own coefficients to follow it. The settings proposed are chosen
for the discrimination itself (T-optimal design, Atkinson and Fedorov 1975): for every
ordered pair (A true, B its rival), linearised about B's fit, the increase in B's
chi-square that a reading at a setting would cause after B is refitted to A's predictions
on the table plus that reading,

    gain = (d - j beta)^2 / (1 + j M j')

with ``d`` the weighted difference A - B at the setting, ``j`` B's weighted Jacobian
row there, ``beta`` the weighted least-squares refit of B to A on the settings so far and
``M`` the inverse of their normal matrix (the added-point formula). A setting must
separate every pair either way round: its score is the smallest gain over ordered pairs.
The best setting is taken, added to the settings, and the next chosen the same way
(greedy; a setting may come again: a repeated reading), until the readings' gain reaches
what the diagnosis' test needs to tell the explanations apart.

The noise at a new setting is the table's variance function
(:meth:`~irreflect.diagnose.noise.NoiseEstimate.sigma_at`). The settings are those the
instrument reaches as the table shows it: its receiver range, its angles of incidence and
5-deg steps down to 10 deg below the smallest and up to 10 deg above the largest (an
offset and a tilt part toward normal incidence, where the tilt vanishes), no closer to
the source direction than it went. The rows have the columns of a measurement plan (``gamma_deg, theta_deg``, and
``why``, as ``irreflect next`` writes them) plus ``readings`` (how many at that setting)
and ``separation_sigma``: the square root of the chi-square gain of those readings, in
noise units, given the ones before them.
"""

from __future__ import annotations

import numpy as np

from ..fitting import prediction_and_jacobian

#: candidate settings: receiver step (deg) and the usual angles of incidence (magnitudes)
THETA_STEP = 1.0
GAMMA_STEPS = np.arange(5.0, 86.0, 5.0)
#: new angles of incidence at most this far (deg) beyond the measured ones
GAMMA_BEYOND = 10.0


def candidate_settings(gamma_deg, theta_deg):
    """Settings the instrument reaches as the table shows it (degrees): its angles of
    incidence and the 5-deg steps from :data:`GAMMA_BEYOND` below the smallest it measured
    to as far above the largest (the fitted laws in gamma are not asked to extrapolate
    further), its receiver range in 1-deg steps, no closer to the source direction than
    it went."""
    g = np.asarray(gamma_deg, float)
    t = np.asarray(theta_deg, float)
    lo = float(np.min(np.abs(g))) - GAMMA_BEYOND
    hi = float(np.max(np.abs(g))) + GAMMA_BEYOND
    steps = GAMMA_STEPS[(GAMMA_STEPS >= lo - 1e-9) & (GAMMA_STEPS <= hi + 1e-9)]
    mags = np.union1d(np.round(np.abs(g), 6), steps)
    mags = mags[mags > 0]
    thetas = np.arange(np.ceil(t.min()), np.floor(t.max()) + 0.5, THETA_STEP)
    gg, tt = np.meshgrid(-mags, thetas, indexing="ij")
    gg, tt = gg.ravel(), tt.ravel()
    closest = float(np.min(np.abs(t - g)))  # how near the source the detector went
    keep = np.abs(tt - gg) >= min(closest, 5.0) - 1e-9
    return gg[keep], tt[keep]


def _prediction_and_jacobian(result, gamma_deg, theta_deg):
    """Predicted power and its derivative with respect to the model's internal
    coordinates (nonlinear and linear) at the given settings (degrees)."""
    with np.errstate(all="ignore"):
        return prediction_and_jacobian(result.model_object, result.values,
                                       np.radians(np.asarray(gamma_deg, float)),
                                       np.radians(np.asarray(theta_deg, float)))


class _Pair:
    """A (true, rival) pair: the rival's linearised refit to the true model's predictions
    on the settings so far, updated one reading at a time."""

    def __init__(self, true_fit, rival_fit, design_g, design_t, design_w, cand_g, cand_t,
                 cand_w):
        pa, _ = _prediction_and_jacobian(true_fit, design_g, design_t)
        pb, jb = _prediction_and_jacobian(rival_fit, design_g, design_t)
        self.r = (pa - pb) * design_w
        self.j = jb * design_w[:, None]
        ca, _ = _prediction_and_jacobian(true_fit, cand_g, cand_t)
        cb, cj = _prediction_and_jacobian(rival_fit, cand_g, cand_t)
        self.cd = (ca - cb) * cand_w
        self.cj = cj * cand_w[:, None]
        self._solve()

    def _solve(self):
        gram = self.j.T @ self.j
        ridge = 1e-10 * max(float(np.trace(gram)), 1e-300) * np.eye(gram.shape[0])
        self.m = np.linalg.pinv(gram + ridge)
        self.beta = self.m @ (self.j.T @ self.r)

    def gains(self) -> np.ndarray:
        d = self.cd - self.cj @ self.beta
        lev = np.einsum("np,pq,nq->n", self.cj, self.m, self.cj)
        return d * d / (1.0 + np.maximum(lev, 0.0))

    def add(self, i: int) -> None:
        self.r = np.append(self.r, self.cd[i])
        self.j = np.vstack([self.j, self.cj[i][None]])
        self._solve()


def separating_settings(alternatives: dict, noise, gamma_deg, theta_deg, *,
                        target: float, max_readings: int = 12) -> list[dict]:
    """The readings that best separate fitted alternatives (see the module docstring),
    chosen one at a time until their chi-square gain reaches ``target`` (what the
    diagnosis' test needs to tell them apart) or ``max_readings`` have been chosen; a
    setting may be chosen again (a repeated reading).

    Parameters
    ----------
    alternatives : dict
        Name -> FitResult (at least two).
    noise : NoiseEstimate
        The table's noise (per point) and its variance function (for new settings).
    gamma_deg, theta_deg : arrays
        The table's settings (the instrument's reach).
    target : float
        The chi-square gain to reach.

    Returns
    -------
    list of dict
        One per setting, in the order first chosen: ``gamma_deg, theta_deg, readings``,
        ``separation_sigma`` (square root of the gain of its readings), ``measured``
        (whether the table has that setting already), ``total_chi2`` (the gain of all the
        readings proposed) and ``why``.
    """
    names = list(alternatives)
    if len(names) < 2 or max_readings <= 0:
        return []
    gg, tt = candidate_settings(gamma_deg, theta_deg)
    preds = {n: np.asarray(alternatives[n].predict(gg, tt), float) for n in names}
    mean = np.mean([preds[n] for n in names], axis=0)
    cand_w = 1.0 / np.maximum(noise.sigma_at(mean), 1e-300)
    design_w = 1.0 / np.asarray(noise.sigma, float)
    pairs = [_Pair(alternatives[a], alternatives[b], gamma_deg, theta_deg, design_w, gg, tt,
                   cand_w) for a in names for b in names if a != b]
    gain_at: dict[int, float] = {}  # setting -> chi-square gain of its readings
    readings: dict[int, int] = {}
    total = 0.0
    for _ in range(int(max_readings)):
        score = np.min([p.gains() for p in pairs], axis=0)
        score = np.where(np.isfinite(score), score, -np.inf)
        i = int(np.argmax(score))
        if not score[i] > 0:
            break
        for p in pairs:
            p.add(i)
        gain_at[i] = gain_at.get(i, 0.0) + float(score[i])
        readings[i] = readings.get(i, 0) + 1
        total += float(score[i])
        if total >= target:
            break
    measured = {(round(float(x), 6), round(float(y), 6))
                for x, y in zip(gamma_deg, theta_deg, strict=True)}
    out = []
    for i, gain in gain_at.items():  # in the order first chosen
        parts = ", ".join(f"{n} {preds[n][i]:.4g}" for n in names)
        out.append({
            "gamma_deg": float(gg[i]), "theta_deg": float(tt[i]), "readings": readings[i],
            "separation_sigma": float(np.sqrt(gain)),
            "measured": (round(float(gg[i]), 6), round(float(tt[i]), 6)) in measured,
            "total_chi2": total,
            "why": f"separates {' from '.join(names)}: predicted power {parts}",
        })
    return out
