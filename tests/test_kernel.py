"""The compiled kernel against the numpy reference implementation of the same search."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from irreflect import fit, fit_subsets
from irreflect.data import load_bundled
from irreflect.errors import UnknownNameError
from irreflect.fitting import _extension_start_rows, _kernel_codes
from irreflect.models import get_model
from irreflect.models.extensions import CATALOGUE, extend
from irreflect.synthetic import synthetic_material

pytest.importorskip("numba")


def _same_fit(a, b):
    assert a.r2 == pytest.approx(b.r2, abs=1e-9)
    assert a.cost == pytest.approx(b.cost, rel=1e-7)
    np.testing.assert_allclose(a.predict(a.gamma_deg, a.theta_deg),
                               b.predict(b.gamma_deg, b.theta_deg), rtol=1e-5,
                               atol=1e-7 * np.max(np.abs(a.power)))


@pytest.mark.parametrize("name", ["terrazzo", "plasterboard", "foam_board"])
def test_compiled_fit_equals_numpy_on_the_bundled_sets(name):
    meas = load_bundled(name)
    _same_fit(fit(meas, engine="compiled"), fit(meas, engine="numpy"))


@pytest.mark.parametrize("kind", ["glossy", "matte"])
def test_compiled_fit_equals_numpy_on_generated_materials(kind):
    for seed in range(8):
        meas = synthetic_material(seed, kind).measurements
        _same_fit(fit(meas, engine="compiled"), fit(meas, engine="numpy"))


@pytest.mark.parametrize("chain", [[e] for e in CATALOGUE] + [["background", "angle_offset"],
                                                              ["offspecular_peak",
                                                               "incidence_reflectance"]])
def test_compiled_fit_equals_numpy_on_extended_models(chain):
    meas = synthetic_material(2, "glossy", "paper").measurements
    model = extend("two-lobe", chain)
    assert _kernel_codes(model) is not None
    _same_fit(fit(meas, model, engine="compiled"), fit(meas, model, engine="numpy"))


def test_kernel_extension_starts_are_the_models_own():
    """The kernel rebuilds the extended models' starts from the extensions' values: they must
    be the rows the models' own ``starts`` give (after the two-lobe part)."""
    meas = synthetic_material(4, "glossy").measurements
    g, t = np.radians(meas.gamma_deg), np.radians(meas.theta_deg)
    for chain in (["retroreflection"], ["specular_halo", "angle_offset"],
                  ["background", "offspecular_peak", "retroreflection"]):
        model = extend("two-lobe", chain)
        own = np.asarray(model.starts(g, t, meas.power))
        base = np.asarray(get_model("two-lobe").starts(g, t, meas.power))
        tails = _extension_start_rows(model)
        expected = np.vstack([np.column_stack([base, np.tile(tails[0], (len(base), 1))]),
                              np.column_stack([np.tile(base[0], (len(tails) - 1, 1)),
                                               tails[1:]])])
        np.testing.assert_array_equal(own, expected)


def test_subset_fits_agree_between_the_engines():
    rel_batched, rel_exhaustive = [], []
    for seed in range(3):
        meas = synthetic_material(seed, "glossy", "uneven").measurements
        rng = np.random.default_rng(seed)
        masks = np.zeros((20, meas.n_points), bool)
        for row in masks:
            row[rng.choice(meas.n_points, min(meas.n_points, int(rng.integers(12, 40))),
                           replace=False)] = True
        args = (meas.gamma_deg, meas.theta_deg, meas.power)
        light = dict(n_screen=16, n_keep=1, max_iter=15, ftol=1e-6)
        a = fit_subsets(*args, masks, engine="compiled", **light)
        b = fit_subsets(*args, masks, engine="numpy", **light)
        rel_batched += list(np.abs(a.cost / b.cost - 1))
        a = fit_subsets(*args, masks[:6], engine="compiled", exhaustive=True)
        b = fit_subsets(*args, masks[:6], engine="numpy", exhaustive=True)
        rel_exhaustive += list(np.abs(a.cost / b.cost - 1))
    # the same search: the same optimum but where rounding sends a light (15-iteration)
    # search down another path
    assert np.mean(np.array(rel_batched) < 1e-6) >= 0.9
    assert np.mean(np.array(rel_exhaustive) < 1e-6) >= 0.9


def test_engine_names_and_replaced_starts():
    meas = load_bundled("terrazzo")
    with pytest.raises(UnknownNameError, match="unknown fitting engine 'gpu'"):
        fit(meas, engine="gpu")
    model = get_model("two-lobe")
    assert _kernel_codes(model) is not None
    # a caller's own starts: the kernel cannot call them, the numpy path fits it
    custom = dataclasses.replace(model, starts=lambda g, t, p: np.zeros((1, 5)))
    assert _kernel_codes(custom) is None
    assert _kernel_codes(get_model("phong")) is None


def test_the_kernels_exp_is_within_one_ulp_of_the_library():
    from numba import njit

    from irreflect._kernel import fexp

    @njit
    def run(x):
        out = np.empty_like(x)
        for i in range(x.size):
            out[i] = fexp(x[i])
        return out

    rng = np.random.default_rng(0)
    x = np.concatenate([rng.uniform(-745, 709.7, 200_000), rng.uniform(-40, 1, 200_000),
                        [0.0, -0.0, 1e-300, -1e-300, 709.78, -708.4, -745.1]])
    got, want = run(x), np.exp(x)
    normal = want > 2.3e-308
    np.testing.assert_allclose(got[normal], want[normal], rtol=2.5e-16, atol=0)
    assert np.all(np.abs(got[~normal] - want[~normal]) <= 5e-324)
    edge = run(np.array([np.nan, -np.inf, np.inf, 710.0, -746.0, -1e10, 1e10]))
    assert np.isnan(edge[0]) and edge[1] == 0 and edge[2] == np.inf and edge[3] == np.inf
    assert edge[4] == 0 and edge[5] == 0 and edge[6] == np.inf


@pytest.mark.parametrize("kind", ["glossy", "matte"])
def test_compiled_finish_equals_the_numpy_covariance(kind):
    """fit()'s compiled finish of the two-lobe model (natural parameters, fitted curve, R^2,
    covariance, near-singular directions) against the numpy functions it replaces."""
    from irreflect import _kernel, metrics
    from irreflect.fitting import _covariance, _fitted_and_jacobian, _kernel_geometry

    model = get_model("two-lobe")
    tables = [load_bundled("terrazzo")] + [synthetic_material(s, kind).measurements
                                           for s in range(6)]
    for meas in tables:
        res = fit(meas)
        z, alpha = (a[0] for a in model.from_natural(res.values[None]))
        g, t = np.radians(meas.gamma_deg), np.radians(meas.theta_deg)
        w = np.ones(meas.n_points)
        kgeo = _kernel_geometry(g, t)
        values, ok, fitted, r2, rmse, mse, cov, singular = _kernel.tl_finish(
            z, alpha, kgeo[0], kgeo[1], w, meas.power, False, res.cost, model.n_params)
        ref_fitted, jfull = _fitted_and_jacobian(model, z, alpha, g, t, w, "numpy")
        ref_cov, ref_singular = _covariance(model, z, alpha, jfull, False, res.cost,
                                            meas.n_points)
        assert ok
        np.testing.assert_allclose(values, model.to_natural(z[None], alpha[None])[0],
                                   rtol=1e-14)
        np.testing.assert_allclose(fitted, ref_fitted, rtol=1e-12,
                                   atol=1e-14 * np.max(np.abs(meas.power)))
        assert r2 == pytest.approx(metrics.r2(meas.power, ref_fitted), abs=1e-12)
        assert rmse == pytest.approx(metrics.rmse(meas.power, ref_fitted), rel=1e-10)
        np.testing.assert_allclose(np.sqrt(np.diag(cov)), np.sqrt(np.diag(ref_cov)), rtol=1e-6)
        np.testing.assert_array_equal(singular, ref_singular)
