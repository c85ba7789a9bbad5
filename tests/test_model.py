"""Models: the separable form equals the paper's formulas; derivatives; edge cases."""

from __future__ import annotations

import numpy as np
import pytest

from irreflect.errors import IrreflectError, UnknownNameError
from irreflect.models import (
    Geometry,
    get_model,
    model_names,
    n_lobe_power,
    phong_power,
    single_lobe_power,
    two_lobe_power,
)
from tests.conftest import TABLE3, paper_grid

CORE_MODELS = ["two-lobe", "single-lobe", "n-lobe", "n-lobe:2", "phong"]


@pytest.mark.parametrize("material", sorted(TABLE3))
def test_separable_two_lobe_equals_eq19(material):
    g, t = np.radians(paper_grid()[0]), np.radians(paper_grid()[1])
    params = np.array(TABLE3[material])
    direct = two_lobe_power(g, t, *params)
    # Eq. 19 written out by hand for one point, independent of the library's helpers
    gamma, theta = np.radians(-40.0), np.radians(25.0)
    u_as, v_as, u_nd, v_nd, u_ns, v_ns, K = params
    c = np.cos(gamma)
    a_s, n_d, n_s = u_as * c**v_as, u_nd * c**v_nd, u_ns * c**v_ns
    hand = K * ((1 - a_s) * (n_d + 1) / (2 * np.pi) * np.cos(theta) ** n_d
                + a_s * (n_s + 1) / (2 * np.pi) * np.cos(-gamma - theta) ** n_s)
    assert two_lobe_power(gamma, theta, *params) == pytest.approx(hand, rel=1e-12)
    sep = get_model("two-lobe").predict(params, g, t)
    np.testing.assert_allclose(sep, direct, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("name", CORE_MODELS)
def test_basis_derivatives_match_finite_differences(name):
    model = get_model(name)
    rng = np.random.default_rng(1)
    geom = Geometry.of(np.radians(-rng.uniform(5, 65, (1, 60))),
                          np.radians(rng.uniform(-75, 75, (1, 60))))
    frac = rng.uniform(0.3, 0.6, (4, model.n_nonlinear))
    z = model.z_lower + frac * (np.minimum(model.z_upper, 8) - np.maximum(model.z_lower, -8))
    z = np.clip(z, model.z_lower, model.z_upper)
    _, deriv = model.basis(geom, z, True)
    for k in range(z.shape[1]):
        h = 1e-6
        zp, zm = z.copy(), z.copy()
        zp[:, k] += h
        zm[:, k] -= h
        num = (model.basis(geom, zp, False)[0] - model.basis(geom, zm, False)[0]) / (2 * h)
        np.testing.assert_allclose(deriv[..., k], num, rtol=1e-5, atol=1e-7 * np.abs(num).max())


@pytest.mark.parametrize("name", CORE_MODELS)
def test_natural_round_trip(name):
    model = get_model(name)
    rng = np.random.default_rng(2)
    z = model.z_lower + rng.uniform(0.2, 0.8, (3, model.n_nonlinear)) * (
        np.minimum(model.z_upper, 8) - np.maximum(model.z_lower, -8))
    z = np.clip(z, model.z_lower, model.z_upper)
    alpha = rng.uniform(0.1, 1.0, (3, model.n_linear))
    p = model.to_natural(z, alpha)
    z2, a2 = model.from_natural(p)
    np.testing.assert_allclose(z2, z, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(a2, alpha, rtol=1e-10)
    assert p.shape[1] == len(model.param_names)


def test_directions_beyond_90_deg_receive_zero_not_nan():
    params = TABLE3["terrazzo"]
    # gamma -60, theta -80: phi = 140 deg, the specular lobe's cosine is negative
    p = two_lobe_power(np.radians(-60.0), np.radians(-80.0), *params)
    assert np.isfinite(p) and p >= 0
    spec_only = two_lobe_power(np.radians(-60.0), np.radians(-80.0), 1.0, 0.0, 1.0, 0.0, 5.0, 0.0, 1.0)
    assert spec_only == 0.0
    # a fractional index must not turn a negative cosine into NaN
    assert single_lobe_power(np.radians(-30.0), np.radians(-75.0), 2.5, 1.0) == 0.0
    assert phong_power(np.radians(-30.0), np.radians(-75.0), 1.0, 2.5, 1.0) == 0.0


def test_nan_in_nan_out():
    out = two_lobe_power(np.array([np.nan, -0.3]), np.array([0.1, 0.2]), *TABLE3["terrazzo"])
    assert np.isnan(out[0]) and np.isfinite(out[1])


def test_n_lobe_with_normal_and_mirror_lobes_is_two_lobe_with_constant_shares():
    g, t = (np.radians(a) for a in paper_grid())
    u_as, n_d, n_s, K = 0.2, 1.3, 40.0, 0.7
    two = two_lobe_power(g, t, u_as, 0.0, n_d, 0.0, n_s, 0.0, K)
    n2 = n_lobe_power(g, t, [0.0, 1.0], [n_d, n_s], [1 - u_as, u_as], K)
    np.testing.assert_allclose(n2, two, rtol=1e-12)
    model = get_model("n-lobe:2")
    np.testing.assert_allclose(model.predict([0.0, n_d, 1 - u_as, 1.0, n_s, u_as, K], g, t), two,
                               rtol=1e-12)


def test_phong_without_specular_is_lambertian_and_single_lobe_peaks_at_mirror():
    theta = np.radians(np.linspace(-80, 80, 33))
    np.testing.assert_allclose(phong_power(np.radians(-30), theta, 0.0, 20.0, 2.0),
                               2.0 * np.cos(theta), rtol=1e-12)
    grid = np.linspace(-89, 89, 1781)
    peak = grid[np.argmax(single_lobe_power(np.radians(-35.0), np.radians(grid), 15.0, 1.0))]
    assert peak == pytest.approx(35.0, abs=0.05)


def test_registry_names_and_errors():
    assert {"two-lobe", "single-lobe", "n-lobe", "phong"} <= set(model_names())
    assert get_model("two-lobe").n_params == 7
    assert get_model("n-lobe:4").n_params == 12
    with pytest.raises(UnknownNameError, match="did you mean 'two-lobe'|Did you mean 'two-lobe'"):
        get_model("two_lobe")
    with pytest.raises(UnknownNameError, match="Did you mean 'two-lobe'"):
        get_model("TWO-LOBE")  # no suggestion before: matched case-sensitively
    with pytest.raises(IrreflectError, match="n-lobe:<integer>"):
        get_model("n-lobe:x")
    with pytest.raises(IrreflectError, match="between 1 and 6"):
        get_model("n-lobe:9")
