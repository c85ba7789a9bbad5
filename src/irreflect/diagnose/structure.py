"""The residual's statistics the discrepancy workflow judges a fit by
(:mod:`irreflect.diagnose.workflow`, step 2): the lack of fit against the noise, and the
structure tests (runs of signs along theta; the mean residual per angle of incidence, per
receiver angle, per distance from the mirror and from the source direction)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

from .noise import NoiseEstimate


@dataclass(frozen=True)
class LackOfFit:
    """Lack-of-fit of a model against the noise: ``chi2 = sum (r / sigma)^2`` on ``dof``
    degrees of freedom, ``ratio = chi2 / dof`` (1 when only noise is left) and the p-value of
    a ratio at least that large (chi-square test with a given sigma, F test with an
    estimated one)."""

    chi2: float
    dof: int
    ratio: float
    p_value: float
    test: str


def lack_of_fit(normalized_residuals, n_params: int, noise: NoiseEstimate) -> LackOfFit:
    z = np.asarray(normalized_residuals, float)
    chi2 = float(np.sum(z * z))
    dof = max(z.size - int(n_params), 1)
    ratio = chi2 / dof
    if np.isinf(noise.dof):
        p, test = float(special.chdtrc(dof, chi2)), "chi-square"
    else:
        p, test = float(special.fdtrc(dof, noise.dof, ratio)), "F"
    return LackOfFit(chi2=chi2, dof=dof, ratio=ratio, p_value=p, test=test)


@dataclass(frozen=True)
class StructureTest:
    """One test for non-random residuals: statistic, degrees of freedom, p-value and where
    the strongest deviation lies (``where``, ``z_worst`` its z-score)."""

    name: str
    statistic: float
    dof: float
    p_value: float
    where: str
    z_worst: float


def _deg(x) -> str:
    """An angle for a sentence: degrees to 0.1, no trailing zeros."""
    return f"{round(float(x), 1):g}"


def _runs_test(gamma_deg, theta_deg, z) -> StructureTest:
    """Wald-Wolfowitz runs of residual signs along theta within each gamma (too few runs
    = neighbouring residuals share their sign = structure)."""
    runs = expected = variance = 0.0
    longest = (0, None, None, None, 0)
    for g in np.unique(gamma_deg):
        sel = np.nonzero(gamma_deg == g)[0]
        sel = sel[np.argsort(theta_deg[sel], kind="stable")]
        signs = np.sign(z[sel])
        keep = signs != 0
        s, th = signs[keep], theta_deg[sel][keep]
        n1, n2 = int(np.sum(s > 0)), int(np.sum(s < 0))
        n = n1 + n2
        if n < 2:
            continue
        change = np.nonzero(s[1:] != s[:-1])[0]
        runs += change.size + 1
        expected += 1.0 + 2.0 * n1 * n2 / n
        variance += 2.0 * n1 * n2 * (2.0 * n1 * n2 - n) / (n * n * (n - 1.0))
        bounds = np.concatenate([[0], change + 1, [n]])
        lengths = np.diff(bounds)
        i = int(np.argmax(lengths))
        if lengths[i] > longest[0]:
            longest = (int(lengths[i]), g, th[bounds[i]], th[bounds[i + 1] - 1], s[bounds[i]])
    zscore = (runs - expected) / np.sqrt(variance) if variance > 0 else 0.0
    p = float(special.ndtr(zscore))
    length, g, t0, t1, sign = longest
    where = (f"{length} residuals in a row {'above' if sign > 0 else 'below'} the model at "
             f"gamma {_deg(g)} deg, theta {_deg(t0)}..{_deg(t1)} deg") if length else "no residuals"
    return StructureTest("runs of signs along theta", float(runs), float(expected), p, where,
                         float(zscore))


def _group_test(name, z, labels, describe, noise_dof=np.inf) -> StructureTest:
    """Mean normalised residual per group: ``sum n_b mean_b^2 ~ chi2(groups)`` for noise
    of a known sigma; ``(that / groups) ~ F(groups, noise_dof)`` for an estimated one."""
    keys, inverse, counts = np.unique(labels, return_inverse=True, return_counts=True)
    sums = np.bincount(inverse, weights=z, minlength=keys.size)
    means = sums / counts
    zb = means * np.sqrt(counts)
    stat = float(np.sum(zb * zb))
    dof = int(keys.size)
    if np.isfinite(noise_dof):
        p = float(special.fdtrc(dof, noise_dof, stat / dof))
    else:
        p = float(special.chdtrc(dof, stat))
    i = int(np.argmax(np.abs(zb)))
    where = (f"{describe(keys[i])}: mean residual {means[i]:+.2f} sigma over {counts[i]} "
             f"points (z = {zb[i]:+.1f})")
    return StructureTest(name, stat, float(dof), p, where, float(zb[i]))


_OFFSET_EDGES = np.array([-30.0, -12.0, -4.0, 4.0, 12.0, 30.0])
_OFFSET_NAMES = (">30", "12-30", "4-12", "within 4", "4-12", "12-30", ">30")


def _offset_label(direction: str, negative: str, positive: str):
    def describe(k):
        k = int(k)
        if k == 3:
            return f"within 4 deg of the {direction} direction"
        side = negative if k < 3 else positive
        return f"{_OFFSET_NAMES[k]} deg from the {direction} direction toward {side}"
    return describe


def structure_tests(gamma_deg, theta_deg, normalized_residuals,
                    noise_dof: float = np.inf) -> list[StructureTest]:
    """The five structure tests of the workflow (angles in degrees, residuals / sigma;
    ``noise_dof``: degrees of freedom of an estimated sigma, ``inf`` when it is known)."""
    g = np.asarray(gamma_deg, float)
    t = np.asarray(theta_deg, float)
    z = np.asarray(normalized_residuals, float)
    mirror = t + g  # > 0: beyond the mirror direction, toward grazing
    source = t - g  # > 0: from the source toward the normal
    return [
        _runs_test(g, t, z),
        _group_test("mean by angle of incidence", z, g, lambda k: f"gamma {_deg(k)} deg",
                    noise_dof),
        _group_test("mean by receiver angle", z, np.round(t / 10.0) * 10.0,
                    lambda k: f"theta {_deg(k - 5)}..{_deg(k + 5)} deg", noise_dof),
        _group_test("mean by distance from the mirror direction", z,
                    np.searchsorted(_OFFSET_EDGES, mirror),
                    _offset_label("mirror", "the normal", "grazing"), noise_dof),
        _group_test("mean by distance from the source direction", z,
                    np.searchsorted(_OFFSET_EDGES, source),
                    _offset_label("source", "grazing", "the normal"), noise_dof),
    ]


def per_gamma_chi2(gamma_deg, normalized_residuals) -> dict[float, float]:
    """``chi2 / points`` of the normalised residuals per angle of incidence (1 = noise)."""
    g = np.asarray(gamma_deg, float)
    z = np.asarray(normalized_residuals, float)
    return {float(k): float(np.mean(z[g == k] ** 2)) for k in np.unique(g)}
