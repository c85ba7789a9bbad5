"""The verdict's word on a model that may lack an effect of the material, from the
readings alone: its fit explains them poorly, or (when the readings carry their noise as a
sigma column) departs from them by more than that noise."""

from __future__ import annotations

import numpy as np
from scipy import special

from .. import metrics
from .._text import p_text
from ..data import Measurements
from ..fitting import FitResult

#: level of the chi-square test of the readings against their sigma
LACK_OF_FIT_P = 1e-3


def misfit_note(res: FitResult, meas: Measurements, weighted: Measurements,
                n_params: int) -> str:
    """Why the model may lack an effect, or "" when the readings give no sign of it.

    ``res`` is the campaign's weighted fit of ``meas`` and ``weighted`` the table it was
    fitted to (its sigma carries the range's weights): with a sigma column the test is the
    fit's own weighted chi-square on ``n - n_params`` degrees of freedom. A hidden
    retroreflection's campaign fitted its readings above the R^2 rule's 0.9, at chi^2/dof
    68-160 against their noise from reading 12 on; ``irreflect diagnose`` on 15 such
    readings, given that noise, names the retroreflection."""
    if np.isfinite(res.r2) and res.r2 < metrics.MISFIT_R2:
        # scattered readings cannot tell noise from misfit: the diagnosis needs sigma
        given = "" if meas.sigma is not None else (
            ", given a sigma column with the instrument's noise")
        return (f"the model explains the readings only to R^2 {res.r2:.3f}: it may lack an "
                f"effect of this material (irreflect diagnose on the readings{given} "
                "names it)")
    dof = meas.n_points - n_params
    if meas.sigma is None or weighted.sigma is None or dof <= 0:
        return ""
    with np.errstate(all="ignore"):
        chi2 = float(np.sum(((meas.power - res.fitted) / weighted.sigma) ** 2))
    p = float(special.chdtrc(dof, chi2)) if np.isfinite(chi2) else 0.0
    if not p < LACK_OF_FIT_P:
        return ""
    return (f"the readings depart from the fit by chi^2/dof {chi2 / dof:.3g} against their "
            f"sigma ({p_text(p)}): the model may lack an effect of this material, or the "
            "sigma understates the noise (irreflect diagnose on the readings names it)")
