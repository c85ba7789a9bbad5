"""The contract of every registered model and of every extension on every model.

In the spirit of scikit-learn's common checks: the suites loop over the registries
(:func:`irreflect.models.model_names`, :data:`irreflect.models.EXTENSIONS`), so a model or
an extension added with one registry line is checked without editing this file:

* parameters and bounds are consistent, the screening box lies inside the bounds, the
  natural <-> internal mapping round-trips;
* the analytic derivatives of the basis match central differences;
* the data-driven starts are finite and inside the bounds;
* the model pickles as its specification (checkpoints, process pools);
* the fitter reaches the generating curve on the model's own generated tables;
* compare, diagnose and select can use it;
* every extension contains its base model as a special case, and every coordinate it adds
  changes the prediction of every model (the off-specular tilt of a microfacet model
  too: the derivative is not identically zero).
"""

from __future__ import annotations

import pickle
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest

from irreflect.compare import compare_models
from irreflect.diagnose import diagnose
from irreflect.errors import IrreflectError
from irreflect.fitting import fit
from irreflect.models import EXTENSIONS, Geometry, get_model, model_names, parse_spec
from irreflect.models import registry as model_registry
from irreflect.models.extensions import Extension, register_extension
from irreflect.selection import FitSettings, SubsetEvaluator
from irreflect.synthetic import synthetic_for_model

MODELS = model_names()
EXTENDED = [f"{m}+{e}" for m in MODELS for e in EXTENSIONS]


def _geometry(n=60, seed=11):
    rng = np.random.default_rng(seed)
    g = np.radians(rng.uniform(-75.0, -5.0, n))
    t = np.radians(rng.uniform(-85.0, 85.0, n))
    return g, t


def _interior(model, rows=3, seed=5):
    """Points well inside the screening box (where a fit searches)."""
    lo, hi = model.screen_box()
    rng = np.random.default_rng(seed)
    return lo + rng.uniform(0.25, 0.75, (rows, lo.size)) * (hi - lo)


def _check_derivatives(model, z, g, t, tol=2e-5):
    geom = Geometry.of(g[None], t[None])
    basis, dbasis = model.basis(geom, z, True)
    assert dbasis.shape == basis.shape + (z.shape[1],)
    for k in range(z.shape[1]):
        h = 1e-6 * max(1.0, np.abs(z[:, k]).max())
        zp, zm = z.copy(), z.copy()
        zp[:, k] += h
        zm[:, k] -= h
        numeric = (model.basis(geom, zp, False)[0] - model.basis(geom, zm, False)[0]) / (2 * h)
        scale = max(np.abs(numeric).max(), np.abs(dbasis[..., k]).max(), 1e-12)
        err = np.abs(numeric - dbasis[..., k]).max() / scale
        assert err < tol, f"{model.name}: d basis / d {model.nonlinear_names[k]} off by {err:.2e}"


# ----------------------------------------------------------------------------- every model
@pytest.mark.parametrize("name", MODELS)
def test_parameters_and_bounds_are_consistent(name):
    model = get_model(name)
    # free parameters (nonlinear + linear); the reported ones may add derived values (the
    # last share of n-lobe, fixed by the shares summing to 1)
    assert model.n_params <= len(model.params) == len(model.param_names)
    assert len(set(model.param_names)) == len(model.params)
    assert len(model.nonlinear_names) == model.n_nonlinear == model.z_lower.size
    assert model.z_upper.size == model.n_nonlinear and np.all(model.z_lower < model.z_upper)
    assert len(model.alpha_nonneg) == model.n_linear >= 1
    assert all(p.lower < p.upper for p in model.params)
    lo, hi = model.screen_box()
    assert np.all(lo < hi)
    assert np.all(lo >= model.z_lower - 1e-12) and np.all(hi <= model.z_upper + 1e-12)
    assert model.formula and model.describe().startswith(model.name)


@pytest.mark.parametrize("name", MODELS + EXTENDED)
def test_natural_parameters_round_trip(name):
    model = get_model(name)
    z = _interior(model)
    alpha = np.random.default_rng(2).uniform(0.05, 0.4, (z.shape[0], model.n_linear))
    natural = model.to_natural(z, alpha)
    assert natural.shape == (z.shape[0], len(model.params)) and np.all(np.isfinite(natural))
    g, t = _geometry()
    # the same curve whichever way the parameters are given
    back = model.predict(natural, g, t)
    geom = Geometry.of(g[None], t[None])
    basis = model.curve_basis(geom, z, alpha)
    np.testing.assert_allclose(back, np.einsum("bnl,bl->bn", basis, alpha), rtol=1e-9,
                               atol=1e-12 * np.abs(back).max())


@pytest.mark.parametrize("name", MODELS)
def test_analytic_derivatives_match_central_differences(name):
    model = get_model(name)
    g, t = _geometry()
    _check_derivatives(model, _interior(model), g, t)


@pytest.mark.parametrize("name", MODELS)
def test_data_driven_starts_are_finite_and_inside_the_bounds(name):
    model = get_model(name)
    case = synthetic_for_model(name, seed=3)
    m = case.measurements
    starts = np.atleast_2d(model.starts(np.radians(m.gamma_deg), np.radians(m.theta_deg),
                                        m.power))
    assert starts.ndim == 2 and starts.shape[1] == model.n_nonlinear and len(starts) >= 1
    assert np.all(np.isfinite(starts))
    assert np.all(starts >= model.z_lower - 1e-9) and np.all(starts <= model.z_upper + 1e-9)


@pytest.mark.parametrize("name", MODELS + [f"{m}+{e}" for m in MODELS[:2] for e in EXTENSIONS])
def test_a_model_pickles_as_its_specification(name):
    model = get_model(name)
    back = pickle.loads(pickle.dumps(model))
    assert back.name == model.name and back.param_names == model.param_names
    g, t = _geometry()
    z = _interior(model, rows=1)
    params = model.to_natural(z, np.full((1, model.n_linear), 0.2))[0]
    np.testing.assert_array_equal(back.predict(params, g, t), model.predict(params, g, t))
    assert parse_spec(model.name).model_text == model.name


@pytest.mark.parametrize("name", MODELS)
def test_the_fitter_reaches_the_generating_curve(name):
    """On the model's own generated tables (random shape in its screening box, random
    grid, 1 % noise), the global fit is at least as good as the curve that made them."""
    seeds = range(8) if name.startswith("n-lobe") else range(20)
    shortfalls = []
    for seed in seeds:
        case = synthetic_for_model(name, seed)
        result = fit(case.measurements, name)
        if result.r2 < case.r2_truth - 1e-4:
            shortfalls.append((seed, round(result.r2, 6), round(case.r2_truth, 6)))
    assert not shortfalls, f"{name}: fit below the generating curve: {shortfalls}"


@pytest.mark.parametrize("name", MODELS)
def test_compare_diagnose_and_select_take_every_model(name):
    case = synthetic_for_model(name, seed=1)
    meas = case.measurements
    comparison = compare_models(meas, [name])
    scores = list(comparison.scores.values())
    assert len(scores) == 1 and scores[0].r2 > case.r2_truth - 1e-3
    first = next(iter(EXTENSIONS))
    diagnosis = diagnose(meas, name, extensions=[first], max_effects=1)
    assert diagnosis.steps[0].fit.model_object.name == name
    (tried,) = diagnosis.candidates[0]  # the one extension, fitted on top of this model
    assert tried.name == first and tried.assessment is not None, tried.reason
    evaluator = SubsetEvaluator(meas.gamma_deg, meas.theta_deg, meas.power, model=name)
    rng = np.random.default_rng(0)
    masks = np.zeros((3, meas.n_points), bool)
    for row in masks:
        row[rng.choice(meas.n_points, max(meas.n_points // 2, get_model(name).n_params + 2),
                       replace=False)] = True
    scores, failed = evaluator.fit_masks(masks)
    assert not failed.any() and np.all((scores >= 0) & (scores < 1))


# ----------------------------------------------------------------------------- extensions
@pytest.mark.parametrize("name", EXTENDED)
def test_extension_derivatives_match_central_differences(name):
    model = get_model(name)
    g, t = _geometry(seed=4)
    _check_derivatives(model, _interior(model, seed=9), g, t)


@pytest.mark.parametrize("name", EXTENDED)
def test_extension_contains_its_model_and_every_new_coordinate_acts(name):
    model = get_model(name)
    base = model.wrapped
    ext: Extension = model.extension
    g, t = _geometry(seed=6)
    geom = Geometry.of(g[None], t[None])
    zb = _interior(base, rows=1, seed=3)
    # neutral extension: first start row, new linear coefficients zero -> the base model
    pe = len(ext.nonlinear_names)
    ze = np.asarray(ext.z_starts[0] if pe else (), float).reshape(1, pe)
    alpha_b = np.full((1, base.n_linear), 0.3)
    z = np.column_stack([zb, ze])
    alpha = np.column_stack([alpha_b, np.zeros((1, ext.n_linear))])
    basis_b, _ = base.basis(geom, zb, False)
    basis, dbasis = model.basis(geom, z, True)
    expected = np.einsum("bnl,bl->bn", basis_b, alpha_b)
    np.testing.assert_allclose(np.einsum("bnl,bl->bn", basis, alpha), expected, rtol=1e-10,
                               atol=1e-12 * np.abs(expected).max())
    # away from neutral, every added coordinate and column changes the prediction
    z_off = np.column_stack([zb, _interior(model, rows=1, seed=8)[:, base.n_nonlinear:]])
    alpha_off = np.column_stack([alpha_b, np.full((1, ext.n_linear), 0.1)])
    basis, dbasis = model.basis(geom, z_off, True)
    for k in range(base.n_nonlinear, model.n_nonlinear):
        d_pred = np.einsum("bnl,bl->bn", dbasis[..., k], alpha_off)
        assert np.abs(d_pred).max() > 1e-8 * np.abs(expected).max(), (
            f"{name}: {model.nonlinear_names[k]} has no effect on the prediction")
    for j in range(base.n_linear, model.n_linear):
        assert np.abs(basis[..., j]).max() > 0, f"{name}: linear column {j} is zero"


@pytest.mark.parametrize("base", MODELS)
def test_off_specular_tilt_moves_the_peak_of_every_model(base):
    """The tilt acts on the specular part of every model, microfacet models included."""
    model = get_model(f"{base}+offspecular_peak")
    tilt_index = model.nonlinear_names.index(EXTENSIONS["offspecular_peak"].nonlinear_names[0])
    g, t = _geometry(seed=12)
    z = _interior(model, rows=1, seed=13)
    alpha = np.full((1, model.n_linear), 0.2)
    geom = Geometry.of(g[None], t[None])
    flat = np.einsum("bnl,bl->bn", model.basis(geom, z, False)[0], alpha)
    z2 = z.copy()
    z2[0, tilt_index] += 0.05
    tilted = np.einsum("bnl,bl->bn", model.basis(geom, z2, False)[0], alpha)
    assert np.abs(tilted - flat).max() > 1e-6 * np.abs(flat).max()


# ----------------------------------------------------------------------------- registries
def _toy_factory():
    """A new model in one place: the single-lobe model under another name."""
    import dataclasses

    return dataclasses.replace(get_model("single-lobe"), name="toy-lobe")


def test_a_registered_model_is_seen_everywhere():
    model_registry.register_model("toy-lobe", _toy_factory)
    try:
        assert "toy-lobe" in model_names()
        case = synthetic_for_model("single-lobe", seed=2)
        result = fit(case.measurements, "toy-lobe+background")
        assert result.model == "toy-lobe+background" and result.r2 > case.r2_truth - 1e-3
        assert pickle.loads(pickle.dumps(get_model("toy-lobe"))).name == "toy-lobe"
    finally:
        model_registry.MODELS.pop("toy-lobe")
        model_registry._MODEL_CACHE.clear()
    with pytest.raises(IrreflectError, match="toy-lobe"):
        get_model("toy-lobe")


def test_a_factory_that_returns_no_model_is_a_one_line_error():
    model_registry.register_model("not-a-model", lambda: {"name": "not-a-model"})
    try:
        with pytest.raises(IrreflectError, match="must return a ReflectionModel, found dict"):
            get_model("not-a-model")
    finally:
        model_registry.MODELS.pop("not-a-model")
        model_registry._MODEL_CACHE.clear()


def test_a_registered_extension_reaches_fit_and_diagnose():
    import dataclasses

    renamed = dataclasses.replace(EXTENSIONS["background"], name="floor")
    register_extension("floor", renamed)
    try:
        case = synthetic_for_model("two-lobe", seed=4)
        result = fit(case.measurements, "two-lobe+floor")  # not in the compiled kernel
        assert result.model == "two-lobe+floor" and result.r2 > case.r2_truth - 1e-3
        diagnosis = diagnose(case.measurements, extensions=["floor"], max_effects=1)
        (tried,) = diagnosis.candidates[0]
        assert tried.name == "floor" and tried.assessment is not None, tried.reason
    finally:
        EXTENSIONS.pop("floor")
        model_registry._MODEL_CACHE.clear()


def _fit_r2(spec, meas):
    return fit(meas, spec).r2


def test_an_extended_model_fits_in_a_process_pool():
    case = synthetic_for_model("two-lobe", seed=5)
    here = fit(case.measurements, "two-lobe+background").r2
    with ProcessPoolExecutor(1) as pool:
        there = pool.submit(_fit_r2, get_model("two-lobe+background"), case.measurements)
        assert there.result() == pytest.approx(here, abs=1e-12)


def test_fit_settings_refuse_an_unknown_option():
    assert FitSettings.of(max_iter=5).kwargs() == {"max_iter": 5}
    with pytest.raises(IrreflectError, match="max_iters"):
        FitSettings.of(max_iters=5)
