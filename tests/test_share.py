"""The specular share saturates at 1 (issue 22): one rule in the model, the fitter (numpy
and compiled, single fits and subsets), the predictions and the room."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from irreflect import fit, fit_subsets
from irreflect.errors import FitWarning
from irreflect.fitting import retry_reasons
from irreflect.fitting.linear import _evaluate, _kaufman_jacobian
from irreflect.models import Geometry, extend, get_model, two_lobe_power
from irreflect.models.base import generalized_lambertian
from irreflect.models.paper import specular_share
from irreflect.synthetic import saturating_material


def _paper_law(g, t, u_as, v_as, u_nd, v_nd, u_ns, v_ns, k):
    """Eqs. 19-22 written out with the unbounded share ``u_as cos^v_as(gamma)``."""
    cg = np.cos(g)
    a_s = u_as * cg**v_as
    n_d, n_s = u_nd * cg**v_nd, u_ns * cg**v_ns
    return k * ((1 - a_s) * generalized_lambertian(np.cos(t), n_d)
                + a_s * generalized_lambertian(np.cos(-g - t), n_s))


def test_the_share_is_the_papers_law_below_one_and_one_beyond():
    cg = np.cos(np.radians([0.0, 30.0, 60.0, 70.0, 80.0]))
    share = specular_share(0.3, -2.0, cg)
    law = 0.3 * cg**-2.0
    np.testing.assert_array_equal(share[law < 1], law[law < 1])
    np.testing.assert_array_equal(share[law >= 1], 1.0)
    assert np.isnan(specular_share(np.nan, -2.0, 0.5))
    # where it saturates the model is the specular lobe alone: K (n_s + 1)/2pi cos^n_s(phi)
    g, t = np.radians(-70.0), np.radians(np.linspace(-80, 85, 34))
    p = (0.3, -2.0, 1.2, 0.5, 400.0, 0.2, 2.5)
    n_s = 400.0 * np.cos(g) ** 0.2
    np.testing.assert_allclose(two_lobe_power(g, t, *p),
                               2.5 * generalized_lambertian(np.cos(-g - t), n_s), rtol=1e-13)


def test_the_papers_table_3_materials_are_unchanged():
    """Table 3's shares stay below 1 over the paper's range (10-60 deg) and to 70 deg: the
    model is the paper's law there, to the bit (the foam board's reaches 1 at 73 deg)."""
    table3 = {"terrazzo": (0.01713, -2.379, 1.021, 0.4283, 34.55, -0.3772, 0.4142),
              "plasterboard": (0.001284, -4.911, 1.083, 0.4636, 33.41, 1.382, 0.5215),
              "foam board": (0.01742, -3.103, 1.457, 1.005, 102.0, 0.731, 0.3879)}
    g = np.radians(np.repeat(-np.arange(0.0, 71.0, 5.0), 33))
    t = np.radians(np.tile(np.linspace(-80, 80, 33), 15))
    for p in table3.values():
        assert specular_share(p[0], p[1], np.cos(g)).max() < 1
        np.testing.assert_array_equal(two_lobe_power(g, t, *p), _paper_law(g, t, *p))


def test_fits_reach_the_generating_curve_on_materials_whose_share_saturates():
    """Issue 22's property: u_as 0.02-0.6, v_as -2.5..0.5, gammas to 70 deg, lobe index
    150-6000, sparse grids, 1 % noise, the share saturating at a measured angle: the fit
    reaches the generating curve's R^2 - 1e-4 on every one (before the share saturated in
    the model: 4 of 32)."""
    short = []
    saturating = 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        for seed in range(40):
            case = saturating_material(seed)
            p = case.params
            g = np.unique(np.abs(case.measurements.gamma_deg))
            saturating += specular_share(p[0], p[1], np.cos(np.radians(g))).max() >= 1
            result = fit(case.measurements)
            if result.r2 < case.r2_truth - 1e-4:
                short.append((seed, result.r2, case.r2_truth))
    assert saturating == 40
    assert not short, short


def test_the_unbounded_share_could_not_fit_them():
    """The same tables under the paper's unbounded law (a share above 1 allowed, the
    diffuse lobe negative there) miss the generating curve: what the cap fixes."""
    from scipy.optimize import least_squares

    case = saturating_material(3)
    m = case.measurements
    g, t = np.radians(m.gamma_deg), np.radians(m.theta_deg)
    capped = fit(m)

    def resid(x):
        with np.errstate(all="ignore"):
            return np.nan_to_num(_paper_law(g, t, *x) - m.power, nan=1e10)

    unbounded = least_squares(resid, capped.values, x_scale="jac", max_nfev=3000).x
    r2_unbounded = 1 - np.sum(resid(unbounded) ** 2) / np.sum((m.power - m.power.mean()) ** 2)
    assert capped.r2 >= case.r2_truth - 1e-4
    # the unbounded law, started at the capped optimum, fits by a share above 1: the
    # curve it reaches is not the capped model's
    share = unbounded[0] * np.cos(np.radians(np.unique(np.abs(m.gamma_deg)))) ** unbounded[1]
    assert share.max() > 1.0 or r2_unbounded < capped.r2


@pytest.mark.parametrize("seed", [0, 5, 11])
def test_the_compiled_fit_equals_numpy_where_the_share_saturates(seed):
    m = saturating_material(seed).measurements
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        a, b = fit(m, engine="compiled"), fit(m, engine="numpy")
    assert a.cost == pytest.approx(b.cost, rel=1e-7)
    assert a.r2 == pytest.approx(b.r2, abs=1e-9)
    np.testing.assert_allclose(a.fitted, b.fitted, rtol=1e-5, atol=1e-7 * np.abs(m.power).max())
    assert a.saturated_gammas_deg.size and np.array_equal(a.saturated_gammas_deg,
                                                          b.saturated_gammas_deg)
    # standard errors where the data determine the coefficient (along an ill-determined
    # direction the two engines may stop a hair apart, and the error there is huge anyway)
    sure = [i for i, n in enumerate(a.param_names)
            if n not in a.ill_determined and n not in b.ill_determined]
    assert sure
    np.testing.assert_allclose(a.stderr[sure], b.stderr[sure], rtol=1e-3)


def test_subset_fits_agree_between_the_engines_where_the_share_saturates():
    m = saturating_material(2).measurements
    rng = np.random.default_rng(0)
    masks = np.zeros((12, m.n_points), bool)
    for row in masks:
        row[rng.choice(m.n_points, min(m.n_points, 20), replace=False)] = True
    args = (m.gamma_deg, m.theta_deg, m.power, masks)
    a = fit_subsets(*args, engine="compiled", exhaustive=True)
    b = fit_subsets(*args, engine="numpy", exhaustive=True)
    assert np.mean(np.abs(a.cost / b.cost - 1) < 1e-6) >= 0.9
    a = fit_subsets(*args, engine="compiled")
    b = fit_subsets(*args, engine="numpy")
    assert np.mean(np.abs(a.cost / b.cost - 1) < 1e-6) >= 0.75
    # a subset fit's R^2 on all points is that of its coefficients' curve (saturated)
    model = get_model("two-lobe")
    i = int(np.argmax(a.r2_all))
    pred = model.predict_deg(a.params[i], m.gamma_deg, m.theta_deg)
    r2 = 1 - np.sum((m.power - pred) ** 2) / np.sum((m.power - m.power.mean()) ** 2)
    assert a.r2_all[i] == pytest.approx(r2, abs=1e-9)


@pytest.mark.parametrize("model", ["two-lobe", "two-lobe+background",
                                   "two-lobe+offspecular_peak"])
def test_the_projected_gradient_is_the_cost_gradient_on_and_between_thresholds(model):
    """Kaufman's Jacobian of the capped linear step gives the exact gradient of the projected
    cost (the term it drops is orthogonal to the residual), on an interval of the share and
    on a threshold (the share exactly 1 at a measured angle), as central differences say."""
    m = get_model(model) if "+" not in model else extend("two-lobe", model.split("+")[1:])
    rng = np.random.default_rng(1)
    gam = np.repeat([10.0, 25.0, 40.0, 55.0, 70.0], 15)
    th = np.tile(np.linspace(-70, 80, 15), 5)
    g, t = np.radians(-gam), np.radians(th)
    y = two_lobe_power(g, t, 0.3, -2.0, 1.2, 0.5, 80.0, 0.3, 1.0)
    y = y * (1 + 0.05 * rng.standard_normal(y.size)) + 0.01
    geom = Geometry.of(g[None], t[None])
    sw, yw = np.ones((1, g.size)), y[None]
    kinds = set()
    for _ in range(60):
        z = np.concatenate([[rng.uniform(-4, 0.5), np.log(rng.uniform(0.5, 3)),
                             rng.uniform(-1, 2), np.log(rng.uniform(5, 500)),
                             rng.uniform(-1, 1)], 0.01 * rng.standard_normal(m.n_nonlinear - 5)
                            + np.clip(0.0, m.z_lower[5:], m.z_upper[5:])])[None]
        st = _evaluate(m, geom, z, sw, yw)
        kinds.add("threshold" if np.isfinite(st["tau"][0]) else
                  "saturated" if st["lower"][0] > 0 else "plain")
        grad = _kaufman_jacobian(st, sw)[0].T @ st["resid"][0]
        fd = np.empty(z.shape[1])
        for q in range(z.shape[1]):
            h = np.zeros_like(z)
            h[0, q] = 1e-6
            fd[q] = (_evaluate(m, geom, z + h, sw, yw)["cost"][0]
                     - _evaluate(m, geom, z - h, sw, yw)["cost"][0]) / 2e-6
        np.testing.assert_allclose(grad, fd, rtol=1e-4, atol=1e-6 * np.abs(fd).max())
    assert kinds == {"threshold", "saturated", "plain"}


def test_a_saturated_fit_says_where_and_is_searched_again():
    case = saturating_material(1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        result = fit(case.measurements)
    sat = result.saturated_gammas_deg
    g = np.unique(np.abs(case.measurements.gamma_deg))
    share = specular_share(result.values[0], result.values[1], np.cos(np.radians(g)))
    np.testing.assert_array_equal(sat, g[share >= 1])
    assert sat.size
    assert any("saturates" in r for r in retry_reasons(result))
    assert "saturates" in result.retried


@pytest.mark.parametrize("engine", ["numpy", "compiled"])
def test_the_designs_linearise_the_saturating_model(engine):
    # the campaign's prior, the D-optimal selector and the diagnosis's discriminating
    # readings linearise the model with prediction_and_jacobian: the curve predict gives
    # (before stop 33 they took the separable basis, whose diffuse term turns negative
    # where the share passes 1: -5e4 at 70 deg on a campaign's fit)
    from irreflect.fitting import prediction_and_jacobian

    model = get_model("two-lobe")
    p = np.array([6.12e-3, -7.03, 0.05, -12.0, 1575.3, 2.52, 1.52])  # share 11 at 70 deg
    g = np.radians(np.repeat([-10.0, -61.0, -70.0], 5))
    t = np.radians(np.tile([-2.0, 0.0, 2.0, 61.0, 70.0], 3))
    f, jac = prediction_and_jacobian(model, p, g, t, engine=engine)
    np.testing.assert_allclose(f, model.predict(p, g, t), rtol=1e-9, atol=1e-12)
    z, alpha = model.from_natural(p[None])
    raw, _ = model.basis(Geometry.of(g[None], t[None]), z, False)
    assert (raw[0] @ alpha[0]).min() < -1e3  # what the separable basis said
    # its Jacobian is the derivative of that curve (central differences in z and alpha)
    x = np.concatenate([z[0], alpha[0]])
    n_z = model.n_nonlinear

    def curve(x):
        return model.predict(model.to_natural(x[None, :n_z], x[None, n_z:])[0], g, t)

    for k in range(x.size):
        h = 1e-6 * max(abs(x[k]), 1e-3)
        step = np.zeros_like(x)
        step[k] = h
        numeric = (curve(x + step) - curve(x - step)) / (2 * h)
        np.testing.assert_allclose(jac[:, k], numeric, rtol=1e-4,
                                   atol=1e-6 * np.max(np.abs(f)))
