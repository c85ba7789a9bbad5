"""Literature reflection models: formulas, textbook special cases, derivatives, self-recovery."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import paper_grid

from irreflect.data import Measurements
from irreflect.errors import IrreflectError
from irreflect.fitting import fit
from irreflect.models import get_model, model_names, phong_power
from irreflect.models import literature as lit

RNG_SEED = 20240605

# natural parameters used to generate data, per model, and the pure function of each
TRUE = {
    "blinn-phong": [0.3, 120.0, 0.8],
    "ward": [0.25, 0.15, 0.8],
    "torrance-sparrow": [0.3, 0.2, 1.8, 0.8],
    "torrance-sparrow-gaussian": [0.3, 0.2, 1.8, 0.8],
    "oren-nayar": [0.2, 0.5, 40.0, 0.8],
    "lafortune": [-1.05, 60.0, 0.15, -0.3, 3.0, 0.3, 0.8],
}


def pure(name, params, g, t):
    p = list(params)
    if name == "blinn-phong":
        return lit.blinn_phong_power(g, t, *p)
    if name == "ward":
        return lit.ward_power(g, t, *p)
    if name == "torrance-sparrow":
        return lit.torrance_sparrow_power(g, t, *p)
    if name == "torrance-sparrow-gaussian":
        return lit.torrance_sparrow_power(g, t, *p, distribution="gaussian")
    if name == "oren-nayar":
        return lit.oren_nayar_power(g, t, *p)
    if name == "lafortune":
        return lit.lafortune_power(g, t, p[0:6:3], p[1:6:3], p[2:6:3], p[6])
    raise AssertionError(name)


def random_geometry(n=80, seed=RNG_SEED):
    rng = np.random.default_rng(seed)
    return np.radians(rng.uniform(-75, 0, n)), np.radians(rng.uniform(-85, 85, n))


def test_models_are_registered_with_their_parameter_counts():
    names = model_names()
    expected = {"blinn-phong": 3, "lafortune": 7, "ward": 3, "torrance-sparrow": 4,
                "torrance-sparrow-gaussian": 4, "oren-nayar": 4}
    for name, k in expected.items():
        assert name in names
        model = get_model(name)
        assert model.n_params == k == len(model.params)
        assert model.reference and model.formula
    assert get_model("lafortune:3").n_params == 10


@pytest.mark.parametrize("name", sorted(TRUE))
def test_separable_form_matches_the_closed_formula(name):
    g, t = random_geometry()
    model = get_model(name)
    np.testing.assert_allclose(model.predict(TRUE[name], g, t), pure(name, TRUE[name], g, t),
                               rtol=1e-12, atol=1e-15)
    z, alpha = model.from_natural(np.array(TRUE[name])[None])
    np.testing.assert_allclose(model.to_natural(z, alpha)[0], TRUE[name], rtol=1e-12)


# ----------------------------------------------------------------------------- special cases
def test_no_specular_share_is_lambertian_for_every_model():
    g, t = random_geometry()
    lambert = 0.7 * np.cos(t) / np.pi
    np.testing.assert_allclose(phong_power(g, t, 0.0, 30.0, 0.7), 0.7 * np.cos(t))
    np.testing.assert_allclose(lit.blinn_phong_power(g, t, 0.0, 50.0, 0.7), lambert)
    np.testing.assert_allclose(lit.ward_power(g, t, 0.0, 0.2, 0.7), lambert)
    np.testing.assert_allclose(lit.torrance_sparrow_power(g, t, 0.0, 0.2, 1.5, 0.7), lambert)
    np.testing.assert_allclose(lit.oren_nayar_power(g, t, 0.0, 0.0, 20.0, 0.7), lambert)
    np.testing.assert_allclose(lit.lafortune_power(g, t, [-1.0], [10.0], [0.0], 0.7), lambert)


def test_lafortune_lobes_reduce_to_phong_and_to_the_normal_lobe():
    g, t = random_geometry()
    n = 25.0
    mirror = lit.lafortune_power(g, t, [-1.0], [n], [1.0], 1.0)
    cos_phi = np.cos(g + t)
    phong_lobe = (n + 2) / (2 * np.pi) * np.where(cos_phi > 0, cos_phi, 0.0) ** n * np.cos(t)
    np.testing.assert_allclose(mirror, phong_lobe, rtol=1e-12, atol=1e-300)
    normal = lit.lafortune_power(g, t, [0.0], [n], [1.0], 1.0)
    np.testing.assert_allclose(normal, (n + 2) / (2 * np.pi) * (np.cos(g) * np.cos(t)) ** n
                               * np.cos(t), rtol=1e-12)


def test_blinn_exponent_four_times_phong_near_the_mirror():
    # cos^(4n)(phi/2) = cos^n(phi) (1 + O(n phi^4 / 16))
    gamma = np.radians(-30.0)
    phi = np.radians(np.linspace(-5, 5, 21))
    theta = -gamma - phi
    n = 50.0
    blinn = np.cos(lit.half_angle(gamma, theta)) ** (4 * n)
    np.testing.assert_allclose(blinn, np.cos(phi) ** n, rtol=5e-4)
    assert np.abs(blinn / np.cos(phi) ** n - 1).max() > 1e-6  # not the same function


def test_fresnel_textbook_values():
    eta = 1.5
    assert lit.fresnel_dielectric(1.0, eta) == pytest.approx(((eta - 1) / (eta + 1)) ** 2)
    assert lit.fresnel_dielectric(0.0, eta) == pytest.approx(1.0)
    # 45 deg on glass: Rs = 0.0920, Rp = 0.00847 (Snell + Fresnel equations), mean 0.0502
    c = np.cos(np.radians(45))
    sin_t = np.sin(np.radians(45)) / eta
    cos_t = np.sqrt(1 - sin_t**2)
    rs = ((c - eta * cos_t) / (c + eta * cos_t)) ** 2
    rp = ((cos_t - eta * c) / (cos_t + eta * c)) ** 2
    assert lit.fresnel_dielectric(c, eta) == pytest.approx(0.5 * (rs + rp), rel=1e-12)
    assert 0.5 * (rs + rp) == pytest.approx(0.0502, abs=2e-4)


@pytest.mark.parametrize("m", [0.1, 0.3, 0.6])
def test_beckmann_distribution_is_normalised_over_projected_area(m):
    th = np.linspace(0, np.pi / 2, 200001)[:-1]
    d = lit.beckmann_distribution(th, m)
    total = np.trapezoid(2 * np.pi * d * np.cos(th) * np.sin(th), th)
    assert total == pytest.approx(1.0, abs=1e-4)


def test_gaussian_distribution_is_normalised_for_small_slopes():
    th = np.linspace(0, np.pi / 2, 200001)
    total = np.trapezoid(2 * np.pi * lit.gaussian_distribution(th, 0.05) * np.cos(th)
                         * np.sin(th), th)
    assert total == pytest.approx(1.0, abs=5e-3)


def test_vgroove_attenuation_is_one_at_the_mirror_and_shadows_at_grazing():
    g = np.radians(-40.0)
    assert lit.vgroove_attenuation(g, -g) == pytest.approx(1.0)
    grazing = lit.vgroove_attenuation(g, np.radians(88.0))
    assert 0 < grazing < 0.2
    # receiver on the source side at 60/60 deg: 2 cos^2(60) = 0.5
    assert lit.vgroove_attenuation(np.radians(-60), np.radians(-60)) == pytest.approx(0.5)


def test_torrance_sparrow_brdf_is_reciprocal():
    g, t = random_geometry()
    for dist in lit.TS_DISTRIBUTIONS:
        np.testing.assert_allclose(lit.torrance_sparrow_brdf(g, t, 0.3, 1.6, dist),
                                   lit.torrance_sparrow_brdf(t, g, 0.3, 1.6, dist), rtol=1e-12)
    np.testing.assert_allclose(lit.ward_power(g, t, 1, 0.2, 1) / np.cos(t),
                               lit.ward_power(t, g, 1, 0.2, 1) / np.cos(g), rtol=1e-12)


@pytest.mark.parametrize("distribution", lit.TS_DISTRIBUTIONS)
def test_torrance_sparrow_peak_moves_off_mirror_toward_grazing_as_roughness_grows(distribution):
    gamma = np.radians(-45.0)
    theta = np.radians(np.linspace(0, 89.5, 17901))
    shifts, power_shifts = [], []
    for m in (0.05, 0.1, 0.2, 0.3):
        brdf = lit.torrance_sparrow_brdf(gamma, theta, m, 1.5, distribution)
        shifts.append(np.degrees(theta[np.argmax(brdf)]) - 45.0)
        power = lit.torrance_sparrow_power(gamma, theta, 1.0, m, 1.5, 1.0, distribution)
        power_shifts.append(np.degrees(theta[np.argmax(power)]) - 45.0)
    assert np.all(np.diff(shifts) > 0) and shifts[0] > 0
    assert shifts[0] < 1.0 < 10.0 < shifts[-1]  # near the mirror when smooth, far when rough
    # the received power (BRDF x cos theta) shows the same trend, less strongly
    assert np.all(np.diff(power_shifts) > 0) and power_shifts[-1] > 5.0
    assert all(p < s for p, s in zip(power_shifts[1:], shifts[1:], strict=True))


def test_ward_peak_value_at_the_mirror():
    g = np.radians(-30.0)
    alpha = 0.1
    value = lit.ward_power(g, -g, 1.0, alpha, 1.0) / np.cos(g)  # BRDF
    assert value == pytest.approx(1.0 / (4 * np.pi * alpha**2 * np.cos(g)), rel=1e-12)


def test_oren_nayar_backscatter_and_normal_incidence():
    a, b = lit.oren_nayar_ab(0.0)
    assert (a, b) == (1.0, 0.0)
    a, b = lit.oren_nayar_ab(0.5)
    assert a == pytest.approx(1 - 0.5 * 0.25 / 0.58) and b == pytest.approx(0.45 * 0.25 / 0.34)
    g = np.radians(-50.0)
    back = lit.oren_nayar_power(g, g, 0.0, 0.5, 10.0, 1.0)  # receiver toward the source
    forward = lit.oren_nayar_power(g, -g, 0.0, 0.5, 10.0, 1.0)
    assert back / forward == pytest.approx((a + b * np.sin(-g) * np.tan(-g)) / a)
    assert back > 1.3 * forward  # rough surfaces look brighter toward the source
    t = np.radians(np.linspace(-80, 80, 33))
    np.testing.assert_allclose(lit.oren_nayar_power(0.0, t, 0.0, 0.5, 10.0, 1.0),
                               a * np.cos(t) / np.pi)


# ----------------------------------------------------------------------------- self-recovery
@pytest.mark.parametrize("name", sorted(TRUE))
def test_fit_recovers_the_parameters_of_noiseless_data(name):
    g, t = paper_grid(dense=True)
    power = pure(name, TRUE[name], np.radians(g), np.radians(t))
    meas = Measurements(gamma_deg=g, theta_deg=t, power=power, name=name)
    result = fit(meas, name, seed=0)
    values = result.values
    if name == "lafortune":  # lobes are interchangeable: order by exponent, sharpest first
        lobes = sorted([values[0:3], values[3:6]], key=lambda v: -v[1])
        values = np.concatenate(lobes + [values[6:]])
    np.testing.assert_allclose(values, TRUE[name], rtol=2e-3, atol=1e-6)
    assert result.r2 > 1 - 1e-9


def test_bad_model_options_are_one_line_errors():
    with pytest.raises(IrreflectError, match="between 1 and 4 lobes"):
        get_model("lafortune:9")
    with pytest.raises(IrreflectError):
        get_model("ward:2")
    with pytest.raises(IrreflectError, match="facet distribution"):
        lit.make_torrance_sparrow("cauchy")
