"""Global least-squares fitting of reflection models.

The fitter is a batched, bounded Levenberg-Marquardt on the *nonlinear* parameters of a
model with the linear coefficients eliminated by (non-negative) linear least squares at
every step (variable projection with Kaufman's Jacobian), started from data-driven
guesses and a screening of the model's shape space, and refined by global scans and
basin hops. The plain two-lobe model and its extensions run in a compiled kernel
(numba); every other model, and the reference the kernel is tested against, in numpy.

Public entry points
-------------------
fit(measurements, model="two-lobe", seed=0)            -> FitResult (frozen)
fit_subsets(gamma, theta, power, masks, model, ...)    -> SubsetFits (one fit per mask)

The package by role (each numpy module beside the compiled kernel of the same step; see
docs/architecture.md):

========================  =========================  ======================================
role                      numpy                      compiled (numba)
========================  =========================  ======================================
the model                 models' ``basis``          :mod:`.model_kernel`
linear step               :mod:`.linear`             :mod:`.linear_kernel`
local solver              :mod:`.local`              :mod:`.local_kernel`, :mod:`.fast_kernel`
starts                    :mod:`.starts`             :mod:`.starts_kernel`
random draws              :mod:`.draws`              :mod:`.draws_kernel`
screening and scans       :mod:`.screening`          :mod:`.fast_kernel`, :mod:`.local_kernel`
global search             :mod:`.search`             :mod:`.search_kernel`
finish                    :mod:`.finish`             :mod:`.finish_kernel`
subsets                   :mod:`.subsets`            :mod:`.subsets_kernel`
result and checks         :mod:`.results`
fit()                     :mod:`.api`
the fit's settings        :mod:`.options`
which engine fits         :mod:`.engine`
========================  =========================  ======================================
"""

from __future__ import annotations

from .api import (
    AVERAGED_OPTIONS,
    GAMMA_TOL_DEG,
    RETRY_CHI2,
    RETRY_GAIN,
    RETRY_R2,
    fit,
    fit_averaged,
    points_at_incidence,
    retry_reasons,
    weights_check,
)
from .engine import ENGINE, ENGINES, uses_kernel
from .finish import prediction_and_jacobian
from .local import STOP_FTOL, STOP_MAXITER, STOP_NONFINITE, STOP_POLISHED, STOP_STUCK, STOP_XTOL
from .options import (
    RETRY_SEARCH,
    RETRY_SMALL_TABLE_SEARCH,
    SMALL_TABLE_POINTS,
    SMALL_TABLE_SEARCH,
    FitOptions,
)
from .results import FitResult, check_fit_data, judge
from .screening import DEFAULT_SCREEN, default_keep, default_screen, screen_samples
from .subsets import SubsetFits, fit_subsets
from .warm import warm

__all__ = [
    "AVERAGED_OPTIONS", "DEFAULT_SCREEN", "ENGINE", "ENGINES", "GAMMA_TOL_DEG", "RETRY_CHI2", "RETRY_GAIN",
    "RETRY_R2", "RETRY_SEARCH", "RETRY_SMALL_TABLE_SEARCH", "SMALL_TABLE_POINTS",
    "SMALL_TABLE_SEARCH", "STOP_FTOL", "STOP_MAXITER", "STOP_NONFINITE", "STOP_POLISHED",
    "STOP_STUCK", "STOP_XTOL", "FitOptions", "FitResult", "SubsetFits", "check_fit_data", "default_keep",
    "default_screen", "fit", "fit_averaged", "fit_subsets", "judge", "points_at_incidence",
    "prediction_and_jacobian", "retry_reasons", "weights_check",
    "screen_samples", "uses_kernel", "warm",
]
