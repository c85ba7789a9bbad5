"""Model comparison (section 5.3): polar-area error, Table 6 trend, AIC/BIC, CLI, report."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import blurred_glossy, paper_grid

from irreflect import fit, metrics
from irreflect.cli import main
from irreflect.compare import compare_models, parse_model_list
from irreflect.data import Measurements, bundled_dir, load_bundled, read_measurements
from irreflect.errors import IrreflectError, UnknownNameError
from irreflect.models import get_model, phong_power


def phong_table(noise=0.0, seed=0, params=(0.4, 40.0, 0.5)) -> Measurements:
    g, t = paper_grid(dense=True)
    clean = phong_power(np.radians(g), np.radians(t), *params)
    rng = np.random.default_rng(seed)
    power = clean + (rng.normal(0, noise, clean.size) if noise else 0.0)
    return Measurements(gamma_deg=g, theta_deg=t, power=power, name="phong-synthetic")


# ----------------------------------------------------------------------------- the error
def test_polar_area_error_is_zero_for_identical_curves():
    # piecewise linear in theta, so identical whether the model is sampled at the measured
    # angles or on the integration grid
    theta = np.linspace(-70, 70, 15)
    assert metrics.polar_area_error(theta, 1 + 0.01 * theta, lambda th: 1 + 0.01 * th) \
        == pytest.approx(0.0, abs=1e-12)
    assert metrics.polar_area_error(theta, 1 + 0.01 * theta, lambda th: 1 + 0.011 * th) > 0.1
    comp = compare_models(phong_table(), ["phong"])
    errors = comp.scores["phong"].per_gamma_error_pct
    assert len(errors) == 6 and max(errors.values()) < 1e-6
    assert comp.scores["phong"].r2 == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("model_radius, expected", [(1.1, 21.0), (np.sqrt(0.5), 50.0),
                                                    (0.0, 100.0)])
def test_polar_area_error_hand_computed(model_radius, expected):
    # measured: circle of radius 1 over -60..60 deg; model: circle of radius r.
    # area between / area measured = |1 - r^2| (the angular span cancels)
    theta = np.linspace(-60, 60, 13)
    got = metrics.polar_area_error(theta, np.ones(13), lambda th: np.full_like(th, model_radius))
    assert got == pytest.approx(expected, rel=1e-9)


def test_half_span_mismatch_counts_only_its_share():
    # model equal to the measurement on theta < 0 and zero on theta > 0: half of the area
    theta = np.linspace(-60, 60, 121)
    got = metrics.polar_area_error(theta, np.ones(121),
                                   lambda th: np.where(th <= 0, 1.0, 0.0), step_deg=0.01)
    assert got == pytest.approx(50.0, abs=0.5)


# ----------------------------------------------------------------------------- Table 6
@pytest.fixture(scope="module")
def bundled_comparisons():
    return {name: compare_models(load_bundled(name), ["two-lobe", "phong@10", "phong"])
            for name in ("terrazzo", "plasterboard", "foam_board")}


@pytest.mark.parametrize("name", ["terrazzo", "plasterboard", "foam_board"])
def test_phong_at_10_degrades_with_gamma_while_two_lobe_stays_flat(bundled_comparisons, name):
    comp = bundled_comparisons[name]
    phong = comp.scores["phong@10"].per_gamma_error_pct
    two = comp.scores["two-lobe"].per_gamma_error_pct
    assert list(phong) == [10.0, 20.0, 30.0, 40.0, 50.0, 60.0]
    # as in the paper's Table 6: good where it was fitted, far worse at 60 deg
    assert phong[10.0] < 1.5 * two[10.0]
    assert phong[60.0] > 5 * phong[10.0]
    assert phong[60.0] > 5 * two[60.0]
    rank = np.corrcoef(np.arange(6), np.argsort(np.argsort(list(phong.values()))))[0, 1]
    assert rank > 0.9  # (almost) monotone growth
    assert max(two.values()) < 3 * min(two.values())  # flat
    assert comp.scores["phong@10"].fitted_on.startswith("|gamma| = 10 deg")
    assert comp.best_by_bic == "two-lobe"


def test_fitting_phong_to_all_angles_beats_phong_at_one_angle_overall(bundled_comparisons):
    for comp in bundled_comparisons.values():
        assert comp.scores["phong"].r2 > comp.scores["phong@10"].r2
        assert comp.scores["phong"].bic < comp.scores["phong@10"].bic


# ----------------------------------------------------------------------------- AIC / BIC
def test_bic_does_not_reward_parameters_that_only_fit_noise():
    # single-lobe data: two-lobe contains single-lobe (u_as = 1, v = 0), so its RSS is lower,
    # but BIC must prefer the 2-parameter model that generated the data
    g, t = paper_grid(dense=True)
    model = get_model("single-lobe")
    rng = np.random.default_rng(11)
    clean = model.predict_deg([20.0, 1.0], g, t)
    meas = Measurements(gamma_deg=g, theta_deg=t,
                        power=clean + rng.normal(0, 0.02 * clean.max(), clean.size))
    comp = compare_models(meas, ["single-lobe", "two-lobe"])
    single, two = comp.scores["single-lobe"], comp.scores["two-lobe"]
    assert two.rss <= single.rss * (1 + 1e-9)
    assert single.bic < two.bic and comp.best_by_bic == "single-lobe"
    n = meas.n_points
    assert single.bic == pytest.approx(n * np.log(single.rss / n) + 2 * np.log(n))
    assert two.aic == pytest.approx(n * np.log(two.rss / n) + 2 * 7)


def test_model_list_parsing():
    assert parse_model_list(None, 20)[:3] == ["two-lobe", "phong@20", "phong"]
    assert parse_model_list("ward, phong@, two-lobe", 30) == ["ward", "phong@30", "two-lobe"]
    assert parse_model_list("phong@-10.0") == ["phong@10"]
    with pytest.raises(UnknownNameError, match="unknown model 'wardd'"):
        parse_model_list("two-lobe,wardd")
    with pytest.raises(IrreflectError, match="listed twice"):
        parse_model_list("ward,ward")
    with pytest.raises(IrreflectError, match="MODEL@G"):
        parse_model_list("phong@x")
    # another case: the registry name is suggested
    with pytest.raises(UnknownNameError, match="unknown model 'TWO-LOBE': .* Did you mean "
                       "'two-lobe'\\?$"):
        parse_model_list("TWO-LOBE")


@pytest.mark.parametrize("models", ["", "  ", [], [""], ("two-lobe", 3)])
def test_compare_models_refuses_an_empty_model_list(models):
    # '' and [] silently compared every default model (the CLI refuses --models "")
    meas = load_bundled("terrazzo")
    with pytest.raises(IrreflectError, match=r"^compare_models: models must be one or more "
                       r"model names, .*; found .*: pass models=None for the default models$"):
        compare_models(meas, models)


# ----------------------------------------------------------------------------- CLI
def test_cli_json_has_the_documented_keys(capsys):
    data = str(bundled_dir() / "plasterboard.csv")
    assert main(["compare", data, "--models", "two-lobe,phong@10,blinn-phong", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert list(out["models"]) == ["two-lobe", "phong@10", "blinn-phong"]
    for entry in out["models"].values():
        assert {"per_gamma_error_pct", "mean_error_pct", "max_error_pct", "r2", "rmse",
                "n_params", "bic"} <= set(entry)
        errs = entry["per_gamma_error_pct"]
        assert list(errs) == ["10", "20", "30", "40", "50", "60"]
        assert entry["mean_error_pct"] == pytest.approx(np.mean(list(errs.values())))
        assert entry["max_error_pct"] == pytest.approx(max(errs.values()))
    assert out["models"]["phong@10"]["n_params"] == 3
    assert out["models"]["two-lobe"]["r2"] > out["models"]["phong@10"]["r2"]


def test_cli_table_and_out_dir(tmp_path, capsys):
    out_dir = tmp_path / "cmp"
    data = str(bundled_dir() / "terrazzo.csv")
    assert main(["compare", data, "--models", "two-lobe,phong@20,ward", "--out", str(out_dir)]) == 0
    text = capsys.readouterr().out
    header = text.splitlines()[1].split()
    assert header[:7] == ["model", "10", "20", "30", "40", "50", "60"]
    assert header[7:] == ["mean", "worst", "R^2", "RMSE", "k", "BIC"]
    row = next(line for line in text.splitlines() if line.startswith("phong@20"))
    assert int(row.split()[11]) == 3
    assert "best by BIC: two-lobe" in text
    for name in ("comparison_polar.png", "comparison_errors.png"):
        assert (out_dir / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    saved = json.loads((out_dir / "comparison.json").read_text())
    assert set(saved["models"]) == {"two-lobe", "phong@20", "ward"}
    files = ["comparison.csv", "comparison.json", "comparison_errors.png", "comparison_polar.png"]
    assert sorted(p.name for p in out_dir.iterdir()) == [".irreflect-manifest.json", *files]
    assert json.loads((out_dir / ".irreflect-manifest.json").read_text())["files"] == files


@pytest.mark.parametrize("args, message", [
    (["--phong-at-deg", "15"], "no measurements at |gamma| = 15 deg"),
    (["--models", "two-lobe,phongg"], "unknown model 'phongg'"),
    (["--phong-at-deg", "95"], "between 0 and 90"),
])
def test_cli_errors_are_one_line_and_write_nothing(tmp_path, capsys, args, message):
    out_dir = tmp_path / "out"
    code = main(["compare", str(bundled_dir() / "terrazzo.csv"), "--out", str(out_dir), *args])
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
    assert not out_dir.exists() or list(out_dir.iterdir()) == []
    assert [p for p in tmp_path.iterdir() if p.name != "out"] == []


# ----------------------------------------------------------------------------- real data
@pytest.mark.real
def test_real_ptfe_comparison(real_dir):
    meas = read_measurements(real_dir / "ptfe_nist" / "ptfe_sintered_1064nm.csv")
    with pytest.raises(IrreflectError, match="found |gamma| = 0, 15, 30, 45, 60, 75"):
        compare_models(meas, ["phong@10"])
    comp = compare_models(meas, None, phong_at_deg=15)
    assert list(comp.scores)[:2] == ["two-lobe", "phong@15"] and comp.notes == ()
    # with the default, phong@ moves to the nearest measured incidence and says so
    default = compare_models(meas, ["two-lobe", "phong@"])
    assert list(default.scores) == ["two-lobe", "phong@15"]
    assert "nearest measured angle of incidence, 15 deg" in default.notes[0]
    assert default.scores["phong@15"].r2 == pytest.approx(comp.scores["phong@15"].r2)
    assert comp.gammas == [0.0, 15.0, 30.0, 45.0, 60.0, 75.0]
    # a near-Lambertian diffuser: every model fits it reasonably, the two-lobe model best
    for s in comp.scores.values():
        assert s.r2 > 0.9 and s.mean_error_pct < 10
    two = comp.scores["two-lobe"]
    assert two.mean_error_pct < min(s.mean_error_pct for n, s in comp.scores.items()
                                    if n != "two-lobe")
    assert comp.best_by_bic == "two-lobe"
    # Phong fitted at 15 deg misses the forward scatter at 75 deg
    at = comp.scores["phong@15"].per_gamma_error_pct
    assert at[75.0] > 3 * at[15.0]


def test_models_with_more_parameters_than_points_are_skipped_when_asked():
    g = np.repeat([-20.0, -40.0], 3)
    t = np.tile([-30.0, 10.0, 40.0], 2)
    meas = Measurements(gamma_deg=g, theta_deg=t,
                        power=phong_power(np.radians(g), np.radians(t), 0.3, 10.0, 1.0))
    with pytest.raises(IrreflectError, match="at least 8 are needed"):
        compare_models(meas, ["phong", "lafortune"])
    comp = compare_models(meas, ["phong", "lafortune"], skip_failures=True)
    assert list(comp.scores) == ["phong"] and "at least 8" in comp.skipped["lafortune"]
    assert comp.scores["phong"].r2 == pytest.approx(1.0, abs=1e-9)
    assert "skipped lafortune" in comp.format()


@pytest.mark.real
def test_compare_with_defaults_works_on_every_real_table(real_dir, capsys):
    tables = sorted(real_dir.glob("*/*.csv"))
    assert len(tables) >= 11
    for path in tables:
        meas = read_measurements(path)
        gammas = np.unique(np.abs(meas.gamma_deg))
        has_10 = bool(np.any(np.isclose(gammas, 10.0)))
        nonzero = gammas[gammas > 0]
        expected = 10.0 if has_10 else float(nonzero[np.argmin(np.abs(nonzero - 10.0))])
        comp = compare_models(meas, ["phong@"])  # phong@ alone: one incidence, a quick fit
        assert list(comp.scores) == [f"phong@{expected:g}"], (path.name, list(comp.scores))
        assert bool(comp.notes) == (not has_10)
    # the command line, with its defaults, on a table without a 10 deg incidence
    rgl = real_dir / "rgl_epfl" / "rgl_paper_white.csv"
    assert main(["compare", str(rgl), "--models", "two-lobe,phong@,phong"]) == 0
    out = capsys.readouterr().out
    assert "note: rgl_paper_white has no measurements at |gamma| = 10 deg" in out
    assert "phong@27.668" in out


@pytest.mark.real
def test_compare_cli_defaults_on_a_matte_paint_where_two_models_cannot_fit(real_dir, capsys):
    """RGL's matte wall paint with every default model: blinn-phong and oren-nayar cannot
    beat a constant there; the command still compares the others (exit 0), lists the two as
    skipped with the reason, and warns on stderr once per model left out."""
    from irreflect.compare import DEFAULT_MODELS

    rgl = real_dir / "rgl_epfl" / "rgl_colodur_napoli_4f.csv"
    assert main(["compare", str(rgl), "--json"]) == 0
    captured = capsys.readouterr()
    out = json.loads(captured.out)
    assert len(out["models"]) + len(out["skipped"]) == len(DEFAULT_MODELS)
    assert "two-lobe" in out["models"] and out["best_by_bic"] == "two-lobe"
    for label, why in out["skipped"].items():
        assert "cannot beat a constant" in why
        assert f"{label} left out of the comparison" in captured.err
    assert captured.err.count("left out of the comparison") == len(out["skipped"]) >= 1


def test_a_fit_at_one_incidence_warns_under_its_own_label():
    # 'phong@10' warned as 'phong', beside the all-points 'phong' fit's own warnings
    import warnings

    th = np.linspace(-70.0, 70.0, 15)
    g = np.repeat([-10.0, -30.0, -50.0], th.size)
    t = np.tile(th, 3)
    meas = Measurements(g, t, np.cos(np.radians(t)) / np.pi, name="lambert")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = fit(meas, "phong@10")
    texts = [str(w.message) for w in caught]
    assert res.model == "phong@10" and texts
    assert all(t.startswith("lambert, phong@10: ") for t in texts), texts


def test_compare_with_the_receivers_resolution_fits_every_model_averaged(tmp_path, capsys):
    # a glossy table read by a receiver 4 deg wide (lobe half width about 1.2 deg): as
    # points the two-lobe model leaves a polar-area error of 4.1 % (R^2 0.9990); averaged
    # over the receiver it is recovered, and MODEL@G is fitted averaged on its incidence
    meas = blurred_glossy(4.0)
    point = compare_models(meas, "two-lobe,phong@10")
    wide = compare_models(meas, "two-lobe,phong@10", resolution=4.0)
    assert point.scores["two-lobe"].r2 < 0.9995 < 0.99999 < wide.scores["two-lobe"].r2
    assert wide.scores["phong@10"].r2 != point.scores["phong@10"].r2
    assert "fitted on |gamma| = 10 deg (166 points)" in wide.format()
    assert any("4 deg resolution" in n for n in wide.notes) and not point.notes
    path = tmp_path / "blur4.csv"
    meas.to_frame().to_csv(path, index=False)
    assert main(["compare", str(path), "--models", "two-lobe", "--resolution", "4"]) == 0
    assert "4 deg resolution" in capsys.readouterr().out
    for bad in (-1, 95):  # checked as fit --resolution checks it
        with pytest.raises(IrreflectError, match=r"receiver's resolution \(--resolution, deg\)"):
            compare_models(meas, "two-lobe", resolution=bad)


def test_a_table_of_one_angle_of_incidence_says_what_its_comparison_cannot_judge():
    # unseen_tables3 one_gamma: 'best by BIC: ward' with no word that one angle of
    # incidence cannot judge how the models vary with it
    terrazzo = load_bundled("terrazzo")
    keep = terrazzo.gamma_deg == terrazzo.gamma_deg[0]
    one = Measurements(terrazzo.gamma_deg[keep], terrazzo.theta_deg[keep],
                       terrazzo.power[keep], name="one")
    notes = compare_models(one, "two-lobe,phong").notes
    assert any("has one angle of incidence" in n for n in notes)
    assert not any("one angle of incidence" in n
                   for n in compare_models(terrazzo, "two-lobe,phong").notes)
    assert not any("one angle of incidence" in n  # a single model is not compared
                   for n in compare_models(one, "phong").notes)
