"""Shared fixtures: seeded synthetic tables, the bundled datasets and the real data."""

# ruff: noqa: E402 (the library thread counts are set before numpy is imported)

from __future__ import annotations

import os

# One thread per numerical library in each test process, set before numpy loads (and
# inherited by the pytest-xdist workers, which start after this file is read): the suite
# runs 2 workers on 2 cores, and OpenBLAS's own threads on top of that oversubscribe the
# cores and spin. A material build (scipy's nnls) took 1.3-29 s instead of 0.3-1.3 s;
# irreflect's process pools do the same (irreflect.selection.parallel.one_thread_per_worker).
# A user's own setting of these variables is kept.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
             "VECLIB_MAXIMUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np
import pandas as pd
import pytest

from irreflect.data import BUNDLED, Measurements, load_bundled, real_data_dir
from irreflect.models import two_lobe_power
from irreflect.paper import TABLE3 as PAPER_TABLE3

TABLE3 = PAPER_TABLE3


def pytest_sessionstart(session):
    """Build the fitting kernel before the first test when numba's cache is cold (a bare
    ``pytest`` on a fresh clone; ``make test`` warms it first): the build announces itself
    on stderr, and in the first test that fits, those two lines broke a test of a command's
    one-line error (test_hostile). A warm cache costs a look at numba's index."""
    from irreflect._compiled import ensure_compiled
    from irreflect.fitting import warm

    ensure_compiled(warm)


def blurred_glossy(width: float = 4.0) -> Measurements:
    """A glossy two-lobe table (lobe half width about 1.2 deg) read by a receiver ``width``
    deg wide: every degree at gamma -10, -30, -50, -70, nothing within 3 deg of the
    source; the truth is :data:`BLURRED_TRUTH`. The blur is this helper's own integral
    (Gauss-Legendre over the receiver's width), not irreflect's aperture model, so that the
    averaged fits are checked against something independent of them."""
    g, t = np.meshgrid([-10.0, -30.0, -50.0, -70.0], np.arange(-85, 85.01, 1.0),
                       indexing="ij")
    g, t = g.ravel(), t.ravel()
    keep = np.abs(t - g) >= 3
    g, t = g[keep], t[keep]
    x, w = np.polynomial.legendre.leggauss(61)
    power = sum(0.5 * wi * two_lobe_power(np.radians(g), np.radians(t + 0.5 * width * xi),
                                          *BLURRED_TRUTH)
                for xi, wi in zip(x, w, strict=True))
    return Measurements(gamma_deg=g, theta_deg=t, power=power, name=f"blur{width:g}")


#: the coefficients of :func:`blurred_glossy`'s material
BLURRED_TRUTH = np.array([0.05, -1.5, 1.2, 0.5, 3000.0, 0.3, 1.0])


def paper_grid(dense: bool = True):
    """The paper's sampling plan (same as experiments/make_datasets.py)."""
    gammas, thetas = [], []
    for mag in range(10, 70, 10):
        near = [-15, -7, -5, -2, 2, 5, 7] if dense else [-5, 5]
        th = sorted({*range(-70, 71, 10)} | {mag + d for d in near})
        th = [t for t in th if -70 <= t <= 70]
        gammas += [-mag] * len(th)
        thetas += th
    return np.array(gammas, float), np.array(thetas, float)


def synthetic(params=TABLE3["terrazzo"], noise=0.0, seed=0, dense=True, sigma_column=False,
              name="synthetic") -> Measurements:
    """A two-lobe table on the paper's grid with optional seeded Gaussian noise."""
    g, t = paper_grid(dense)
    clean = two_lobe_power(np.radians(g), np.radians(t), *params)
    rng = np.random.default_rng(seed)
    power = clean + (rng.normal(0, noise, clean.size) if noise else 0.0)
    sigma = np.full(clean.size, noise) if (sigma_column and noise) else None
    return Measurements(gamma_deg=g, theta_deg=t, power=power, sigma=sigma, name=name)


@pytest.fixture
def make_synthetic():
    return synthetic


@pytest.fixture(params=BUNDLED)
def bundled(request) -> Measurements:
    return load_bundled(request.param)


@pytest.fixture
def real_dir():
    root = real_data_dir()
    if root is None:
        pytest.skip("real data not found: ../shared/datasets/real is absent "
                    "(set IRREFLECT_REAL_DATA to its path)")
    return root


def as_frame(meas: Measurements) -> pd.DataFrame:
    return meas.to_frame()
