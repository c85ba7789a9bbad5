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
