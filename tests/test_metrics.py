"""Metrics: R^2, RMSE, MSE and the polar-area error of section 5.3."""

from __future__ import annotations

import numpy as np
import pytest

from irreflect import metrics
from irreflect.errors import MetricWarning


def test_r2_rmse_mse_by_hand():
    y = np.array([1.0, 2.0, 3.0, 4.0])
    p = np.array([1.1, 1.9, 3.2, 3.8])
    ss_res = 0.01 + 0.01 + 0.04 + 0.04
    assert metrics.r2(y, p) == pytest.approx(1 - ss_res / 5.0)
    assert metrics.mse(y, p) == pytest.approx(ss_res / 4)
    assert metrics.rmse(y, p) == pytest.approx(np.sqrt(ss_res / 4))
    batch = metrics.r2(y, np.vstack([p, y]))
    assert batch.shape == (2,) and batch[1] == 1.0


def test_polar_area_error_zero_for_identical_curves():
    theta = np.linspace(-70, 70, 15)
    meas = np.cos(np.radians(theta))
    assert metrics.polar_area_error(theta, meas, lambda t: np.cos(np.radians(t))) == 0.0
    # drawn continuously, the model differs from the straight segments by a little
    cont = metrics.polar_area_error(theta, meas, lambda t: np.cos(np.radians(t)),
                                    model_sampling="continuous")
    assert 0.0 < cont < 1.0


def test_polar_area_error_hand_computed_circle():
    # measured: a circle arc of radius 1 over [-60, 60]; model: radius 1.1.
    # area between = 1/2 (1.21 - 1) * span, area under = 1/2 * span -> 21 %
    theta = np.linspace(-60, 60, 7)
    err = metrics.polar_area_error(theta, np.ones(7), lambda t: np.full_like(t, 1.1))
    assert err == pytest.approx(21.0, rel=1e-9)
    # half the range too big by 10 %, half right: 10.5 %
    err_half = metrics.polar_area_error(
        theta, np.ones(7), lambda t: np.where(t > 0, 1.1, 1.0), step_deg=0.001,
        model_sampling="continuous")
    assert err_half == pytest.approx(10.5, rel=1e-3)


def test_polar_area_errors_per_gamma():
    g = np.repeat([-10.0, -20.0], 5)
    t = np.tile(np.linspace(-40, 40, 5), 2)
    y = np.ones(10)
    errs = metrics.polar_area_errors(g, t, y, lambda gg, tt: np.where(gg == -20, 1.1, 1.0))
    assert list(errs) == [10.0, 20.0]
    assert errs[10.0] == pytest.approx(0.0) and errs[20.0] == pytest.approx(21.0)


def test_normalized_residuals_and_information_criteria():
    r = metrics.normalized_residuals([2.0, 4.0], [1.0, 5.0])
    np.testing.assert_allclose(r, [0.5, -0.25])
    r = metrics.normalized_residuals([2.0, 4.0], [1.0, 5.0], sigma=[0.5, 0.5])
    np.testing.assert_allclose(r, [2.0, -2.0])
    assert metrics.bic(1.0, 100, 7) - metrics.bic(1.0, 100, 6) == pytest.approx(np.log(100))
    assert metrics.aic(1.0, 100, 7) - metrics.aic(1.0, 100, 6) == pytest.approx(2.0)


def test_arrays_of_other_lengths_are_refused_not_broadcast():
    from irreflect.errors import IrreflectError

    # a length-1 argument used to broadcast silently (rmse 1.29, r2 0.0)
    with pytest.raises(IrreflectError, match=r"^rmse: measured has 1 point\(s\) and predicted 3 "
                       r"\(along the last axis\): give one predicted value per measured point$"):
        metrics.rmse([1.0], [1.0, 2.0, 3.0])
    with pytest.raises(IrreflectError, match=r"^r2: measured has 3 point\(s\) and predicted 1 "):
        metrics.r2([1.0, 2.0, 3.0], [2.0])
    with pytest.raises(IrreflectError, match=r"^mse: measured has 3 point\(s\) and predicted 2 "):
        metrics.mse([1, 2, 3], [1, 2])  # a bare numpy ValueError before
    with pytest.raises(IrreflectError, match=r"of shape \(2, 3\) and predicted of shape \(4, 3\) "
                       "do not pair up"):
        metrics.r2(np.ones((2, 3)), np.ones((4, 3)))
    with pytest.raises(IrreflectError, match=r"measured has 2 point\(s\) and sigma 3"):
        metrics.normalized_residuals([1.0, 2.0], [1.0, 2.0], sigma=[1.0, 1.0, 1.0])
    with pytest.raises(IrreflectError, match=r"theta_deg has 3 point\(s\) and measured 2"):
        metrics.polar_area_error([0.0, 10.0, 20.0], [1.0, 2.0], lambda t: t)
    with pytest.raises(IrreflectError, match=r"gamma_deg has 3 point\(s\) and theta_deg 2"):
        metrics.polar_area_errors([-10.0] * 3, [0.0, 10.0], [1.0] * 3, lambda g, t: t)
    with pytest.raises(IrreflectError, match="model_sampling must be 'measured' or "
                       "'continuous'; found 'x'"):
        metrics.polar_area_error([0.0, 10.0], [1.0, 1.0], lambda t: t, model_sampling="x")
    # what pairs up still works: a batch of rows, one sigma for all, a constant target
    np.testing.assert_allclose(metrics.r2([1.0, 2.0, 3.0], np.ones((2, 3))), [-1.5, -1.5])
    np.testing.assert_allclose(metrics.normalized_residuals([2.0, 4.0], [1.0, 5.0], sigma=0.5),
                               [2.0, -2.0])
    with pytest.warns(MetricWarning):
        assert metrics.r2([1.0, 1.0, 1.0], [1.0, 2.0, 3.0]) == -np.inf


def test_r2_of_a_constant_target_warns_that_it_is_undefined():
    """r2 of a constant target returned -inf (or NaN) without a word: SS_tot = 0."""
    import warnings

    with pytest.warns(MetricWarning, match=r"^r2: R\^2 is undefined for a constant target "
                      r"\(measured is 2 at all 4 point\(s\), so SS_tot = 0\); returned -inf "
                      r"\(NaN where predicted matches it exactly\): score such a target with "
                      r"rmse or mse instead$") as said:
        assert metrics.r2([2.0] * 4, [1.0, 2.0, 3.0, 4.0]) == -np.inf
    assert len(said) == 1 and said[0].filename == __file__  # the caller's line
    with pytest.warns(MetricWarning, match=r"measured is 4 at all 3 point\(s\) in 1 of 2 rows"):
        out = metrics.r2([[1.0, 2.0, 3.0], [4.0, 4.0, 4.0]], [1.0, 2.0, 4.0])
    assert out[0] == pytest.approx(0.5) and out[1] == -np.inf  # one warning for the batch
    with pytest.warns(MetricWarning):
        assert np.isnan(metrics.r2([3.0, 3.0], [3.0, 3.0]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a varying target: nothing to say
        assert metrics.r2([1.0, 2.0, 3.0], np.ones((2, 3))).tolist() == [-1.5, -1.5]
