"""The fitter is global on glossy and matte materials, for every model, and honest about it.

Generated materials (``irreflect.synthetic``) carry their generating curve, so a global
fit must reach at least its R^2 on the noisy table; the real sets are held to the best of
50 random-start ``scipy.optimize.least_squares`` runs (``tests/helpers.py``).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from irreflect import fit, fit_subsets
from irreflect.cli import main
from irreflect.data import Measurements, as_measurements, read_measurements
from irreflect.errors import DataError, FitError, FitWarning, IrreflectError
from irreflect.fitting import retry_reasons
from irreflect.models import get_model, model_names, two_lobe_power
from irreflect.synthetic import GRIDS, KINDS, synthetic_material, wild_material
from tests.helpers import least_squares_reference, noisy_oren_nayar

SEEDS_PER_CASE = 30  # 2 kinds x 5 grids x 30 seeds = 300 generated materials


@pytest.mark.parametrize("grid", GRIDS)
@pytest.mark.parametrize("kind", KINDS)
def test_two_lobe_reaches_the_generating_curve_on_300_generated_materials(kind, grid):
    shortfalls = []
    for seed in range(SEEDS_PER_CASE):
        case = synthetic_material(seed, kind, grid)
        result = fit(case.measurements)
        if result.r2 < case.r2_truth - 1e-4:
            shortfalls.append((seed, result.r2, case.r2_truth))
    assert not shortfalls, f"{kind}/{grid}: fit below the generating curve: {shortfalls}"


def test_generated_glossy_materials_are_glossy():
    """The generator's glossy tables have the dynamic range the fitter must cope with."""
    ratios = []
    for seed in range(100):
        p = synthetic_material(seed, "glossy").measurements.power
        ratios.append(np.max(p) / np.median(p))
    assert np.median(ratios) > 50 and np.percentile(ratios, 90) > 1e3


@pytest.mark.parametrize("seed", range(4))
def test_scale_of_power_does_not_change_the_shape(seed):
    case = synthetic_material(seed, "glossy")
    fits = [fit(dataclasses.replace(case.measurements, power=case.measurements.power * s))
            for s in (1e-6, 1.0, 1e6)]
    shape = [np.delete(f.values, 6) for f in fits]  # all but K
    # the same optimum to rounding; along a direction the data do not determine (an
    # ill-determined coefficient) the search may stop a hair apart: within 1e-4 of the
    # coefficient's own standard error there
    tol = np.maximum(1e-6 * np.abs(shape[1]), 1e-4 * np.delete(fits[1].stderr, 6))
    assert np.all(np.abs(shape[0] - shape[1]) <= tol)
    assert np.all(np.abs(shape[2] - shape[1]) <= tol)
    assert max(f.cost / s**2 for f, s in zip(fits, (1e-6, 1.0, 1e6), strict=True)) \
        <= min(f.cost / s**2 for f, s in zip(fits, (1e-6, 1.0, 1e6), strict=True)) * (1 + 1e-9)
    np.testing.assert_allclose([f.values[6] for f in fits], fits[1].values[6] * np.array(
        [1e-6, 1.0, 1e6]), rtol=1e-5)
    assert max(f.r2 for f in fits) - min(f.r2 for f in fits) < 1e-9


def test_a_narrow_lobe_seen_by_one_point_is_not_fitted_as_zero():
    """The K = 0 failure: a specular lobe of index 6000 on a grid with one point at the
    mirror and one 1.5 deg off; the old linear coefficients (K, K u_as) allowed K = 0 with a
    nonzero specular term, which mapped back to a zero model (R^2 < 0)."""
    params = (0.047, -2.243, 0.697, -0.125, 6203.0, -0.808, 10.54)
    g, t = [], []
    for gamma in (-15.0, -35.0, -55.0, -70.0):
        theta = np.unique(np.r_[np.arange(-80.0, 81.0, 10.0), -gamma, -gamma + 1.5])
        g += [gamma] * theta.size
        t += list(theta)
    g, t = np.array(g), np.array(t)
    clean = two_lobe_power(np.radians(g), np.radians(t), *params)
    rng = np.random.default_rng(5)
    meas = Measurements(g, t, clean * (1 + 0.01 * rng.standard_normal(clean.size)))
    result = fit(meas)
    truth_r2 = 1 - np.sum((meas.power - clean) ** 2) / np.sum((meas.power - meas.power.mean()) ** 2)
    assert result.values[6] > 0 and result.values[0] > 0
    assert result.r2 >= truth_r2 - 1e-4


# ----------------------------------------------------------------------------- honest results
def test_convergence_is_reported_not_assumed():
    case = synthetic_material(3, "glossy")
    good = fit(case.measurements)
    assert good.converged and good.message.startswith("converged")
    with pytest.warns(FitWarning, match="not converged: iteration limit"):
        short = fit(case.measurements, max_iter=1, max_rounds=0, polish=False)
    assert not short.converged and "iteration limit (1)" in short.message
    assert any(w.startswith("not converged") for w in short.warnings)


def test_a_coefficient_at_its_bound_is_listed_and_warned():
    """Phong on a purely diffuse (cos theta) table: no specular lobe to find, so the fit
    spends its specular term on the broadest lobe it is allowed, n at its lower bound."""
    g = np.repeat([-20.0, -40.0, -60.0], 17)
    t = np.tile(np.linspace(-80, 80, 17), 3)
    power = np.cos(np.radians(t)) * (1 + 0.01 * np.random.default_rng(2).standard_normal(t.size))
    with pytest.warns(FitWarning, match="at a bound"):
        result = fit(Measurements(g, t, power), "phong")
    assert result.at_bound == ("n",)
    assert result.params["n"] == pytest.approx(get_model("phong").params[1].lower)


def test_ill_determined_coefficients_are_listed():
    # one angle of incidence: how the lobes change with gamma cannot be seen
    g = np.full(25, -30.0)
    t = np.linspace(-80, 80, 25)
    power = two_lobe_power(np.radians(g), np.radians(t), 0.1, -1.0, 1.2, 0.5, 60.0, 0.3, 2.0)
    power = power * (1 + 0.01 * np.random.default_rng(1).standard_normal(t.size))
    result = fit(Measurements(g, t, power))
    assert {"v_as", "v_nd", "v_ns"} <= set(result.ill_determined)
    assert any("ill-determined" in w for w in result.warnings)


@pytest.mark.parametrize("power, message", [
    (np.zeros(30), "power is constant"),
    (np.full(30, 2.5), "power is constant"),
])
def test_degenerate_power_is_refused(power, message):
    g = np.repeat([-20.0, -40.0, -60.0], 10)
    t = np.tile(np.linspace(-60, 60, 10), 3)
    with pytest.raises(DataError, match=message):
        fit(Measurements(g, t, power))


def test_no_degree_of_freedom_is_refused(make_synthetic):
    meas = make_synthetic().subset(np.arange(7))
    with pytest.raises(DataError, match="found 7 points while at least 8 are needed"):
        fit(meas)


def test_a_fit_worse_than_a_constant_is_an_error():
    g = np.repeat([-20.0, -40.0, -60.0], 15)
    t = np.tile(np.linspace(-70, 70, 15), 3)
    retro = np.exp(-((t - g) / 8.0) ** 2) + 0.01  # a peak back at the source
    with pytest.raises(FitError, match="cannot beat a constant"):
        fit(Measurements(g, t, retro), "single-lobe")


@pytest.mark.parametrize("value, message", [(0.0, "power is 0 in every row"),
                                            (2.5, "power is constant")])
@pytest.mark.parametrize("command", ["fit", "diagnose", "compare"])
def test_degenerate_tables_give_one_line_errors_on_the_cli(tmp_path, capsys, command, value,
                                                           message):
    path = tmp_path / "flat.csv"
    path.write_text("gamma_deg,theta_deg,power\n" + "".join(
        f"{g},{t},{value}\n" for g in (-20, -40) for t in range(-60, 61, 10)))
    out = tmp_path / "out"
    argv = [command, str(path)] + (["--out", str(out)] if command != "fit" else [])
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0] and "Traceback" not in err[0]
    assert not out.exists()


def test_fit_cli_prints_warnings_on_stderr(tmp_path, capsys):
    g = np.full(25, -30.0)
    t = np.linspace(-80, 80, 25)
    power = two_lobe_power(np.radians(g), np.radians(t), 0.1, -1.0, 1.2, 0.5, 60.0, 0.3, 2.0)
    path = tmp_path / "one_gamma.csv"
    Measurements(g, t, power * (1 + 0.01 * np.random.default_rng(0).standard_normal(25)))\
        .to_frame().to_csv(path, index=False)
    assert main(["fit", str(path)]) == 0
    captured = capsys.readouterr()
    warning_lines = [x for x in captured.err.splitlines() if x.startswith("irreflect: warning:")]
    assert warning_lines and all("ill-determined" in x or "bound" in x for x in warning_lines)
    assert "R^2 =" in captured.out


# ----------------------------------------------------------------------------- subsets
def test_exhaustive_subset_fits_equal_fit_on_the_subset():
    case = synthetic_material(11, "glossy", "uneven")
    meas = case.measurements
    rng = np.random.default_rng(0)
    masks = np.zeros((6, meas.n_points), bool)
    for row in masks:
        row[rng.choice(meas.n_points, 20, replace=False)] = True
    res = fit_subsets(meas.gamma_deg, meas.theta_deg, meas.power, masks, exhaustive=True)
    for i, mask in enumerate(masks):
        alone = fit(meas.subset(mask))
        assert res.cost[i] == pytest.approx(alone.cost, rel=1e-9)
        np.testing.assert_allclose(res.params[i], alone.values, rtol=1e-9)


def test_batched_subset_fits_find_the_lobe_on_glossy_subsets():
    """The search's light subset fits (as ``select`` runs them) on 25-40-point subsets of
    glossy tables: most reach the exhaustive fit's cost; none is more than 10x worse on
    average (the data-driven starts of each subset carry them)."""
    gaps = []
    for seed in range(6):
        meas = synthetic_material(seed, "glossy", "uneven").measurements
        rng = np.random.default_rng(seed)
        masks = np.zeros((10, meas.n_points), bool)
        for row in masks:
            row[rng.choice(meas.n_points, min(meas.n_points, int(rng.integers(25, 41))),
                           replace=False)] = True
        ref = fit_subsets(meas.gamma_deg, meas.theta_deg, meas.power, masks, exhaustive=True)
        fast = fit_subsets(meas.gamma_deg, meas.theta_deg, meas.power, masks, n_screen=32,
                           n_keep=2, max_iter=25, ftol=1e-6)
        gaps += list(fast.cost / ref.cost - 1)
    gaps = np.array(gaps)
    # within 1 % on 86 % of 240 subsets of seeds 6-29 (with the generator of
    # irreflect._draws as with numpy's before it); 75-78 % on these 60 on the AVX-512
    # machines CI ran on before, 68 % (compiled engine) and 72 % (numpy engine) on an AMD
    # EPYC (AVX2): a light search on a rugged 7-parameter fit flips with the rounding
    assert np.mean(gaps < 0.01) >= 0.65
    # the exhaustive fit is the better one (or as good) on nearly every subset: 7-parameter
    # fits of 25-40 points of a glossy table are rugged, and once in a while a search
    # start of the light fit lands in a basin the full search did not try
    assert np.mean(gaps > -1e-9) >= 0.95


# ----------------------------------------------------------------------------- real data
@pytest.mark.real
def test_phong_on_krylon_is_the_global_optimum(real_dir):
    meas = read_measurements(real_dir / "cornell" / "cornell_krylon_blue.csv")
    result = fit(meas, "phong")
    assert result.r2 >= 0.3232  # a 300-start least_squares found 0.3232 (k_s 0.95, n 1190)
    assert result.params["n"] > 1000


@pytest.mark.real
def test_cayman_fit_says_what_is_doubtful(real_dir):
    meas = read_measurements(real_dir / "cornell" / "cornell_cayman.csv")
    with pytest.warns(FitWarning):
        result = fit(meas)
    assert result.r2 > 0.99
    assert result.at_bound or result.ill_determined
    assert "u_ns" in result.ill_determined + result.at_bound


@pytest.mark.real
def test_paper_protocol_failure_on_cayman_is_named_and_the_glossy_protocol_does_better(real_dir):
    from irreflect.protocol.evaluate import (
        evaluate_protocol,
        glossy_protocol_for,
        paper_protocol_for,
    )

    meas = read_measurements(real_dir / "cornell" / "cornell_cayman.csv")
    reference = fit(meas)
    paper = evaluate_protocol(paper_protocol_for(meas), meas, reference=reference)
    assert paper.failed and "specular lobe" in paper.failure
    glossy = evaluate_protocol(glossy_protocol_for(meas, reference), meas, reference=reference)
    assert glossy.r2 > paper.r2 + 0.3


def _real_cases(max_points: int = 200):
    """The suite's share of the matrix: the first real set of at most ``max_points``
    points, Cornell Cayman (its sub-degree specular lobe is the hardest global fit of the
    small sets). Cornell Krylon (23 s) and PTFE at 351 nm (16 s) left the suite at stop 33,
    PTFE at 1064 nm (17 s) at stop 34, to keep it under 5 min on 2 cores;
    experiments/check_global_fits.py runs them with the rest."""
    from irreflect.data import real_datasets

    for name, path in sorted(real_datasets().items()):
        with open(path) as fh:
            if sum(1 for _ in fh) - 1 <= max_points:
                return [name]
    return []


@pytest.mark.slow
@pytest.mark.real
@pytest.mark.parametrize("dataset", _real_cases() or ["(no real data)"])
def test_every_model_beats_50_least_squares_starts_on_real_data(real_dir, dataset):
    """Every model on every real set of at most 200 points (the Cornell and NIST tables):
    irreflect's cost is at most the best of 50 random-start bounded least_squares runs.
    The 1261-point RGL sets took 12-33 s each here (the suite ran 8 min on 2 cores, above
    its 5-min budget); experiments/check_global_fits.py runs the whole matrix. A model
    that cannot beat a constant must also fail to for the reference."""
    from irreflect.data import real_datasets

    meas = read_measurements(real_datasets()[dataset])
    worse = []
    for name in model_names():
        reference = least_squares_reference(name, meas, n_starts=50, seed=1)
        try:
            ours = fit(meas, name, use_sigma=False).cost
        except FitError as exc:
            assert "cannot beat a constant" in str(exc)
            ss_tot = 0.5 * np.sum((meas.power - meas.power.mean()) ** 2)
            assert reference >= ss_tot * (1 - 1e-9), f"{name}: reference beats a constant"
            continue
        if ours > reference * (1 + 1e-6):
            worse.append((name, ours, reference))
    assert not worse, f"{dataset}: irreflect worse than least_squares: {worse}"


@pytest.mark.real
@pytest.mark.parametrize("path,missed", [("cornell/cornell_krylon_blue.csv", True),
                                         ("rgl_epfl/rgl_cc_ibiza_sunset.csv", False)])
def test_small_table_search_finds_one_optimum_of_a_12_point_protocol(real_dir, path, missed):
    """The paper's 12 points of a real set: 7 coefficients on 12 points leave many basins.
    fit() searches small tables harder (SMALL_TABLE_SEARCH): every seed reaches the same
    cost, never above what the large-table search reaches with that seed (which stops up
    to 21 % (Krylon) and 5 % (Ibiza) above it on some seeds, experiments/check_small_fits.py)."""
    import warnings

    from irreflect.protocol.points import paper_protocol_points
    from irreflect.selection.run import snap_points

    meas = read_measurements(real_dir / path)
    mask = np.zeros(meas.n_points, bool)
    mask[snap_points(meas, paper_protocol_points(meas))["index"].to_numpy()] = True
    sub = meas.subset(mask)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        # the first searches alone (retry=False: fit() would search a large-table
        # result again, as it looks like a local optimum)
        small = np.array([fit(sub, seed=s, retry=False).cost for s in range(4)])
        large = np.array([fit(sub, seed=s, n_screen=96, n_keep=3, n_hops=0, max_rounds=3,
                              retry=False).cost for s in range(4)])
    assert np.ptp(small) <= 1e-6 * small.min()
    assert np.all(small <= large * (1 + 1e-9))
    # on Krylon the large-table search misses it (on Ibiza it no longer does since the
    # specular share saturates: the unbounded share's extra basins are gone)
    assert np.any(small < large * (1 - 1e-3)) == missed


# ----------------------------------------------------------------------------- second search
def test_tables_unlike_the_tuning_set_are_fitted_globally():
    """wild_material: another generator (mirror-like lobes, 1 to 8 incidences, steps up to
    20 deg, additive noise, sigma over 10 decades). No fit may end above the generating
    coefficients' cost (experiments/check_retry.py runs 2,000 seeds: 15 failures of the
    first search alone, 1 with fit()'s second search)."""
    import warnings

    above = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        for seed in range(80):
            case = wild_material(seed)
            result = fit(case.measurements, seed=seed)
            if result.cost > case.cost_truth * (1 + 1e-6):
                above.append((seed, case.kind, result.cost / case.cost_truth))
    assert not above, f"fits above the generating coefficients' cost: {above}"


@pytest.mark.parametrize("seed", [36, 41, 212, 636])
def test_a_result_that_looks_local_is_searched_again_and_reaches_the_optimum(seed):
    """Glossy and mirror-like tables, weighted and not, where the first search stops in a
    local optimum (up to 5e4 times the generating coefficients' cost), flagged by a
    coefficient at a bound, an ill-determined one, a low R^2, a large reduced chi^2 or a
    specular share saturated where the truth's is not (212: at 78 deg, 1.44x):
    fit() searches again and reaches the optimum, and says that it did."""
    import warnings

    case = wild_material(seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        first = fit(case.measurements, seed=seed, retry=False)
        result = fit(case.measurements, seed=seed)
    assert first.cost > case.cost_truth * 1.4  # the hard case it is meant to be
    assert retry_reasons(first)
    assert result.retried == ("; ".join(retry_reasons(first))
                              + ": the second search found a lower cost")
    assert result.cost <= case.cost_truth * (1 + 1e-6)
    assert result.nfev > first.nfev and result.n_starts > first.n_starts
    assert "searched a second time" in result.report()
    assert result.to_dict()["retried"] == result.retried


@pytest.mark.parametrize("seed", [17, 44])
def test_the_second_search_looks_beyond_the_models_screening_box(seed):
    """On 6 of 62 noise draws of a rough matte table both searches ended at R^2 0.83
    (cost 823-839); the optimum (R^2 0.906) has v_as = -12, u_ns = 0.5 and v_ns about
    -10: a share and a specular index rising steeply toward grazing, outside the
    two-lobe model's screening box, and not found by 50 random starts of scipy's
    least_squares in the bounds either. A dense table the model still misfits after the
    second search is searched a third time, screening the whole of the bounds."""
    import warnings

    from irreflect.fitting.api import _widened_model

    table = noisy_oren_nayar(seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        first = fit(table, retry=False)
        result = fit(table)
    assert first.r2 < 0.85 and retry_reasons(first)  # the first search's basin
    assert result.r2 > 0.9 and result.cost < 0.6 * first.cost
    # independent of irreflect's search: 50 random-start bounded scipy least_squares runs
    # in the same +-15 box end in the first search's basin (seed 17: 823.4 vs 466.6)
    reference = least_squares_reference(get_model("two-lobe"), as_measurements(table),
                                        n_starts=50, seed=0)
    assert result.cost < 0.6 * reference
    assert "a search beyond the model's screening box found a lower cost" in result.retried
    assert result.model_object is get_model("two-lobe")  # not the widened copy
    model = get_model("two-lobe")
    lo, hi = _widened_model(model).screen_box()
    np.testing.assert_array_equal(lo, np.maximum(model.z_lower, -15.0))
    np.testing.assert_array_equal(hi, np.minimum(model.z_upper, 15.0))
    assert _widened_model(model) is _widened_model(model)  # built once


def test_only_a_table_the_model_still_misfits_is_searched_beyond_the_box(monkeypatch):
    """A table the model fits costs no third search, even when it looks local (wild_material
    seed 1374: mirror-like, 64 points, R^2 0.9995, five coefficients ill-determined);
    neither does a small table (a campaign's readings: on a few readings the wider box
    finds needles that fit them and miss the rest, Cornell Krylon's 8 opening readings
    R^2 -4466 against all points where the box gave 0.967). Only a table of more than
    SMALL_TABLE_POINTS points the model still misfits after the second search (R^2 <
    RETRY_R2) is searched beyond the box, as the dense table above is."""
    import warnings

    from irreflect.fitting import RETRY_R2, SMALL_TABLE_POINTS, api
    from irreflect.synthetic import wild_material

    widened = []
    real = api._widened_model
    monkeypatch.setattr(api, "_widened_model", lambda m: widened.append(m) or real(m))
    glossy = wild_material(1374).measurements
    table = noisy_oren_nayar(17)
    small = table.iloc[:: len(table) // 20].head(20)  # 20 readings over the five gammas
    assert len(small) <= SMALL_TABLE_POINTS < min(glossy.n_points, len(table))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        fitted = fit(glossy, seed=1374)
        assert fitted.retried and fitted.r2 >= RETRY_R2  # searched twice, within the box
        result = fit(small)
        assert result.retried and result.r2 < RETRY_R2  # a misfit, but a few readings
        assert widened == []
        fit(table)
    assert widened == [get_model("two-lobe")]


def test_a_fit_that_looks_global_is_not_searched_again():
    """terrazzo: no coefficient at a bound or ill-determined, R^2 0.99: one search (the
    fast path of the benchmarks)."""
    from irreflect.data import load_bundled

    result = fit(load_bundled("terrazzo"))
    assert retry_reasons(result) == ()
    assert result.retried == ""
    assert "searched a second time" not in result.report()


def test_retry_reasons_name_each_sign_of_a_local_optimum():
    case = synthetic_material(3, "glossy")
    result = fit(case.measurements)
    bad = dataclasses.replace(result, at_bound=("v_as",), ill_determined=("u_ns",),
                              converged=False, r2=0.5, sigma=np.ones(result.n_points),
                              chi2_reduced=9.0)
    reasons = retry_reasons(bad)
    assert reasons == ("at a bound: v_as", "ill-determined: u_ns", "not converged",
                       "R^2 0.5 < 0.95", "reduced chi^2 9 > 2")
    assert retry_reasons(None) == ("no fit beat a constant",)


def test_wild_material_is_seeded_and_refuses_a_negative_seed():
    a, b = wild_material(5), wild_material(5)
    np.testing.assert_array_equal(a.measurements.power, b.measurements.power)
    assert not np.array_equal(a.measurements.power[:3], wild_material(6).measurements.power[:3])
    with pytest.raises(IrreflectError, match="seed must be an integer >= 0; found -1"):
        wild_material(-1)


def test_a_model_whose_screening_box_is_its_bounds_is_not_searched_a_third_time(monkeypatch):
    """phong screens its whole bounds already: a third search would repeat the second."""
    import warnings

    from irreflect.fitting import RETRY_R2, api

    calls = []
    search = api._fit_search
    monkeypatch.setattr(api, "_fit_search",
                        lambda *a: calls.append(a[1]) or search(*a))
    table = noisy_oren_nayar(17)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        phong = fit(table, "phong")
        assert phong.retried and phong.r2 < RETRY_R2 and len(calls) == 2
        calls.clear()
        fit(table, "two-lobe")  # its box is narrower than its bounds: searched beyond it
    assert len(calls) == 3
