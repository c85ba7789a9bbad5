"""Measurement tables: reading, writing and every validation error."""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from irreflect.data import DataNotice, read_measurements, validate_table, write_measurements
from irreflect.errors import DataError, IrreflectError
from tests.conftest import synthetic


def _csv(tmp_path, text, name="t.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


GOOD = "gamma_deg,theta_deg,power\n-10,0,0.5\n-10,10,0.9\n-20,5,0.4\n"


def test_reads_a_good_table(tmp_path):
    m = read_measurements(_csv(tmp_path, GOOD))
    assert m.n_points == 3 and m.sigma is None
    np.testing.assert_array_equal(m.gamma_deg, [-10, -10, -20])
    assert list(m.gammas) == [-10, -20]


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_write_then_read_is_lossless(tmp_path, suffix):
    meas = synthetic(noise=0.01, seed=3, sigma_column=True)
    meas = type(meas)(meas.gamma_deg, meas.theta_deg, meas.power * np.pi, meas.sigma,
                      material="foam board", name="x")
    path = write_measurements(meas, tmp_path / f"m{suffix}")
    back = read_measurements(path)
    np.testing.assert_array_equal(back.power, meas.power)
    np.testing.assert_array_equal(back.sigma, meas.sigma)
    np.testing.assert_array_equal(back.theta_deg, meas.theta_deg)
    assert back.material == "foam board"


@pytest.mark.parametrize(
    "text, pattern",
    [
        ("gamma,theta_deg,power\n-10,0,1\n", r"missing column 'gamma_deg'.*found 'gamma': rename"),
        ("Gamma_Deg,theta_deg,power\n-10,0,1\n", r"found 'Gamma_Deg': rename it to 'gamma_deg'"),
        ("gamma_deg,theta_deg,pwr\n-10,0,1\n", r"missing column 'power'.*found 'pwr'"),
        ("gamma_deg,theta_deg,power\n-10,0,1\n-10,5,abc\n", r"'power' must be numeric; found 'abc' in data row 2"),
        ("gamma_deg,theta_deg,power\n-10,0,1\n-10,5,\n", r"'power' has 1 empty, NaN or infinite.*data row 2"),
        ("gamma_deg,theta_deg,power\n-10,0,1\n-10,5,inf\n", r"infinite"),
        ("gamma_deg,theta_deg,power\n-10,90,1\n", r"every row has an angle of \+-90 deg"),
        ("gamma_deg,theta_deg,power\n-95,10,1\n", r"gamma_deg must lie within -90 and 90 degrees; found -95"),
        ("gamma_deg,theta_deg,power\n-10,90,1\n-10,91,1\n", r"theta_deg must lie within.*found 91 in data row 2 \(line 3\)"),
        ("gamma_deg,theta_deg,power,sigma\n-10,0,1,-0.1\n", r"sigma must be > 0 \(a 1-sigma uncertainty; .*\); found -0.1"),
        ("gamma_deg,theta_deg,power,sigma\n-10,0,1,0\n", r"sigma must be > 0 \(a 1-sigma uncertainty; .*\); found 0 in"),
        ("gamma_deg,theta_deg,power\n-10,0,1\n-10,0,2\n", r"duplicated \(gamma_deg, theta_deg\).*--average-duplicates"),
        ("gamma_deg,theta_deg,power\n-10,0,1\n10,0,2\n", r"mixes positive and negative.*ambiguous"),
        ("gamma_deg,theta_deg,power\n-10,0,1\n-10,5,-0.5\n", r"power must be >= 0 up to noise; found -0.5.*or give the noise as a sigma column \(negative power down to -4 sigma is kept; without it, down to -2% of the largest power\)"),
        ("gamma_deg,theta_deg,power,sigma\n-10,0,1,0.01\n-10,5,-0.5,0.1\n", r"found -0.5 at data row 2 \(line 3\), below the noise allowance -0.4: check the detector offset or the sign of the column$"),
        ("gamma_deg,theta_deg,power\n", r"no rows"),
        ("gamma_deg,theta_deg,power,material\n-10,0,1,A\n-10,5,2,B\n-10,9,2,A\n",
         r"the material column names 2 materials \(A, B\).*one table per material$"),
    ],
)
def test_validation_errors_are_one_line_and_say_how_to_fix(tmp_path, text, pattern):
    with pytest.raises(DataError, match=pattern) as info:
        read_measurements(_csv(tmp_path, text))
    assert "\n" not in str(info.value)


def test_rows_at_ninety_degrees_are_left_out_with_a_note_and_rows_keep_their_lines(tmp_path):
    # a goniometer sweeping -90..90 writes receivers in the surface plane: the whole file
    # was refused ("strictly between -90 and 90"); those rows are now left out, with a note
    text = "gamma_deg,theta_deg,power\n-10,-90,0.001\n" + "".join(
        f"-10,{t},{1 + np.cos(np.radians(t)):.4f}\n" for t in range(-80, 81, 10)) + \
        "-10,90,0.002\n-30,90,0.0\n"
    with pytest.warns(DataNotice, match=r"left out 3 row\(s\) at gamma or theta = \+-90 deg "
                                        r"\(first data row 1 \(line 2\)\)"):
        meas = read_measurements(_csv(tmp_path, text))
    assert meas.n_points == 17 and np.max(np.abs(meas.theta_deg)) == 80
    # a later error names its row in the file, not its place among the rows kept
    lines = text.splitlines()
    lines[3] = "-10,-70,-0.9"
    with pytest.raises(DataError, match=r"found -0.9 at data row 3 \(line 4\)"):
        read_measurements(_csv(tmp_path, "\n".join(lines) + "\n"))


@pytest.mark.parametrize("clipped, noted", [(2, False), (3, True), (9, True)])
def test_a_clipped_top_is_noted_as_a_saturated_detector(tmp_path, clipped, noted):
    # held-out tables with a clipped peak tied 4-92 settings at the largest power and were
    # read (and fitted "trustworthy") without a word
    t = np.arange(-80.0, 81.0, 2.0)
    power = 0.1 * np.cos(np.radians(t)) + 5 * np.exp(-0.5 * ((t - 30) / 6) ** 2)
    top = np.sort(power)[-clipped]
    power = np.minimum(power, top)
    frame = pd.DataFrame({"gamma_deg": -30.0, "theta_deg": t, "power": power})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        validate_table(frame, "clipped")
    said = [str(w.message) for w in caught if "saturated detector" in str(w.message)]
    assert bool(said) is noted, said
    if noted:
        assert said[0].startswith(f"clipped: {clipped} readings ({clipped / t.size:.0%}) equal "
                                  f"the largest power, {top:g}, exactly, at 1 angle(s)")


def test_series_with_different_indexes_are_refused_not_paired_by_position():
    """Measurements(Series, Series, Series) whose indexes differ paired the values by
    position silently (gamma of label 5 with power of label 0); equal indexes still pass."""
    from irreflect.data import Measurements

    df = synthetic(noise=0.004, seed=1).to_frame()
    shifted = df.set_axis(df.index + 5)
    with pytest.raises(DataError, match=r"^Measurements 'measurements': gamma_deg and power are "
                       r"pandas Series with different indexes \(5, 6, 7, \.\.\. and 0, 1, 2, "
                       r"\.\.\.\), which would pair their values by position, not by label: "
                       r"take them from one DataFrame, call \.reset_index\(drop=True\) on each, "
                       r"or pass arrays \(\.to_numpy\(\)\)$"):
        Measurements(shifted["gamma_deg"], shifted["theta_deg"], df["power"])
    sigma = pd.Series(np.full(len(df), 0.01)).iloc[::-1]  # the same labels, another order
    with pytest.raises(DataError, match="gamma_deg and sigma are pandas Series with different"):
        Measurements(df["gamma_deg"], df["theta_deg"].to_numpy(), df["power"].to_numpy(),
                     sigma=sigma)
    fixed = Measurements(shifted["gamma_deg"].reset_index(drop=True), df["theta_deg"],
                         df["power"])
    np.testing.assert_array_equal(fixed.gamma_deg, df["gamma_deg"].to_numpy())
    same = Measurements(shifted["gamma_deg"], shifted["theta_deg"], shifted["power"])
    np.testing.assert_array_equal(same.power, df["power"].to_numpy())
    one = Measurements(shifted["gamma_deg"], df["theta_deg"].to_numpy(), df["power"].to_numpy())
    assert one.n_points == len(df)  # one Series among arrays: nothing to pair by label


def test_missing_file_and_unknown_type(tmp_path):
    with pytest.raises(DataError, match="no such file"):
        read_measurements(tmp_path / "absent.csv")
    with pytest.raises(DataError, match=r"unknown file type '.xlsx'"):
        read_measurements(_csv(tmp_path, GOOD, "t.xlsx"))


def test_duplicates_averaged_on_request(tmp_path):
    text = "gamma_deg,theta_deg,power,sigma\n-10,0,1,0.3\n-10,0,2,0.4\n-10,5,3,0.1\n"
    with pytest.warns(DataNotice, match="averaged 1 duplicated"):
        m = read_measurements(_csv(tmp_path, text), average_duplicates=True)
    assert m.n_points == 2
    assert m.power[m.theta_deg == 0][0] == pytest.approx(1.5)
    assert m.sigma[m.theta_deg == 0][0] == pytest.approx(0.25)  # sqrt(0.09+0.16)/2
    assert any("averaged 1 duplicated" in n for n in m.notes)


def test_average_duplicates_must_be_a_bool(tmp_path):
    # 'no' is a true value: the duplicates were averaged
    text = "gamma_deg,theta_deg,power\n-10,0,1\n-10,0,2\n-10,5,3\n"
    with pytest.raises(IrreflectError, match="^average_duplicates must be True or False; "
                       "found 'no'$"):
        read_measurements(_csv(tmp_path, text), average_duplicates="no")
    with pytest.raises(IrreflectError, match="average_duplicates must be True or False"):
        validate_table(pd.read_csv(_csv(tmp_path, text)), average_duplicates="no")


def test_blank_material_cells_are_unlabelled_not_a_second_material(tmp_path):
    # refused as "2 materials (a, )"
    text = ("gamma_deg,theta_deg,power,material\n-10,0,1,a\n-10,10,2,\n-20,5,3, \n"
            "-20,15,2,a\n")
    assert read_measurements(_csv(tmp_path, text)).material == "a"
    frame = pd.DataFrame({"gamma_deg": [-10.0, -10.0, -20.0], "theta_deg": [0.0, 10.0, 5.0],
                          "power": [1.0, 2.0, 3.0], "material": ["a", None, np.nan]})
    assert validate_table(frame).material == "a"
    assert validate_table(frame.assign(material=[None, "", np.nan])).material is None
    with pytest.raises(DataError, match=r"names 2 materials \(a, b\)"):
        validate_table(frame.assign(material=["a", "", "b"]))


def test_positive_gammas_read_as_magnitudes_and_said_once(tmp_path):
    text = "gamma_deg,theta_deg,power\n10,0,1\n10,10,2\n20,5,3\n"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        m = read_measurements(_csv(tmp_path, text))
    notices = [w for w in caught if issubclass(w.category, DataNotice)]
    assert len(notices) == 1 and "magnitudes" in str(notices[0].message)
    np.testing.assert_array_equal(m.gamma_deg, [-10, -10, -20])
    np.testing.assert_array_equal(m.theta_deg, [0, 10, 5])  # mirror stays on +theta


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_glossy_table_in_the_mirrored_frame_reads_as_the_paper_frame(seed):
    """gamma >= 0 with the readings peaking at theta = -gamma (the paper's frame mirrored):
    both angles change sign. The same table with only gamma as magnitudes keeps theta."""
    from irreflect.synthetic import synthetic_material

    m = synthetic_material(seed, "glossy").measurements
    df = pd.DataFrame({"gamma_deg": m.gamma_deg, "theta_deg": m.theta_deg, "power": m.power})
    with pytest.warns(DataNotice, match="paper's frame mirrored"):
        mirrored = validate_table(df.assign(gamma_deg=-df.gamma_deg, theta_deg=-df.theta_deg))
    with pytest.warns(DataNotice, match="read as magnitudes"):
        magnitudes = validate_table(df.assign(gamma_deg=df.gamma_deg.abs()))
    for read in (mirrored, magnitudes):
        np.testing.assert_array_equal(read.gamma_deg, m.gamma_deg)
        np.testing.assert_array_equal(read.theta_deg, m.theta_deg)
    # the paper's gamma with theta counted the other way: kept, and said
    with pytest.warns(DataNotice, match="peak at theta = gamma"):
        flipped = validate_table(df.assign(theta_deg=-df.theta_deg))
    np.testing.assert_array_equal(flipped.theta_deg, -m.theta_deg)
    # a matte curve has no peak to tell the frames apart: magnitudes, theta kept
    flat = pd.DataFrame({"gamma_deg": [30.0] * 5, "theta_deg": [-40.0, -30, 0, 30, 40],
                         "power": [1.0, 1.1, 1.2, 1.1, 1.0]})
    with pytest.warns(DataNotice, match="read as magnitudes"):
        read = validate_table(flat)
    np.testing.assert_array_equal(read.theta_deg, flat.theta_deg)


def test_a_curve_whose_highest_readings_tie_has_no_peak_side():
    """Readings tied at the highest power all over a curve show no peak: a near-flat table
    (its first reading, on the source side, had been taken for the peak) is not told that
    it peaks at the source direction. A clipped lobe, its tied top at the mirror, still
    shows the side it peaks on."""
    import warnings as _w

    from irreflect.data import _peak_sides

    theta = np.tile(np.arange(-30.0, 31.0, 10.0), 2)
    gamma = np.repeat([-20.0, -40.0], 7)
    power = np.full(14, 2.5)
    power[[6, 13]] = 2.0
    with _w.catch_warnings(record=True) as said:
        _w.simplefilter("always")
        validate_table(pd.DataFrame({"gamma_deg": gamma, "theta_deg": theta, "power": power}))
    assert not [w for w in said if "peak at theta = gamma" in str(w.message)]
    assert _peak_sides(gamma, theta, power) == [0, 0]
    lobe = np.exp(-((theta + gamma) / 8.0) ** 2) + 0.1
    clipped = np.minimum(lobe, 0.3)  # three readings tied at the top of each lobe
    assert _peak_sides(-gamma, -theta, clipped) == [-1, -1]


def test_additive_noise_on_dark_readings_is_kept_and_an_offset_is_not():
    """Without a sigma column, negative readings deeper than 2 % of the largest are kept
    when they look like noise around zero (their own RMS sets the allowance); a sign
    error or a detector offset is still refused."""
    rng = np.random.default_rng(3)
    theta = np.arange(-85.0, 86.0, 2.5)
    lobe = 1000.0 * np.exp(-0.5 * ((theta - 30.0) / 3.0) ** 2)  # a mirror-like material
    power = lobe + 30.0 * rng.standard_normal(theta.size)  # additive noise, 3 % of the peak
    assert power.min() < -0.02 * power.max()
    df = pd.DataFrame({"gamma_deg": -30.0, "theta_deg": theta, "power": power})
    with pytest.warns(DataNotice, match="show an additive noise of"):
        m = validate_table(df)
    np.testing.assert_array_equal(m.power, power)
    with pytest.raises(DataError, match="power must be >= 0 up to noise"):
        validate_table(df.assign(power=-power))  # the column's sign
    offset = lobe - 80.0 + 5.0 * rng.standard_normal(theta.size)  # dark readings all at -80
    with pytest.raises(DataError, match="power must be >= 0 up to noise"):
        validate_table(df.assign(power=offset))


def test_small_negative_power_is_kept_and_reported():
    df = pd.DataFrame({"gamma_deg": [-10, -10, -10], "theta_deg": [0, 10, 20],
                       "power": [1.0, 0.5, -0.01]})
    with pytest.warns(DataNotice, match="1 slightly negative power"):
        m = validate_table(df)
    assert m.power[2] == -0.01
    assert any("slightly negative" in n for n in m.notes)


def test_extra_columns_are_ignored(tmp_path):
    text = "gamma_deg,theta_deg,purpose,power\n-10,0,mirror,1\n-10,10,diffuse,2\n"
    m = read_measurements(_csv(tmp_path, text))
    assert m.power.tolist() == [1.0, 2.0]


@settings(max_examples=40, deadline=None)
@given(
    rows=st.lists(
        st.tuples(st.integers(-89, 0), st.integers(-89, 89),
                  st.floats(0, 1e3, allow_nan=False, allow_infinity=False)),
        min_size=1, max_size=30, unique_by=lambda r: (r[0], r[1])),
    suffix=st.sampled_from([".csv", ".parquet"]),
)
def test_any_valid_table_round_trips_exactly(tmp_path_factory, rows, suffix):
    """Property: write then read returns the same numbers, bit for bit."""
    g, t, p = (np.array(c, float) for c in zip(*rows, strict=True))
    assume(p.max() >= 1e-100)  # an all-zero (or subnormal) power column is refused
    meas = validate_table(pd.DataFrame({"gamma_deg": g, "theta_deg": t, "power": p}))
    path = write_measurements(meas, tmp_path_factory.mktemp("rt") / f"m{suffix}")
    back = read_measurements(path)
    for column in ("gamma_deg", "theta_deg", "power"):
        np.testing.assert_array_equal(getattr(back, column), getattr(meas, column))


def test_jittered_angles_of_incidence_are_read_as_their_settings(tmp_path):
    """A goniometer reporting its encoder (each gamma setting +-0.04 deg) gave 108 angles of
    incidence in 108 rows: the verdict listed each, the campaign searched 204,156 triples of
    them (82 s). Runs of close values are read at their mean, with a note; a fine sweep of
    gamma, and settings 0.3 deg apart, are left as measured."""
    rng = np.random.default_rng(3)
    settings_ = np.repeat([-10.0, -40.0, -70.0], 20)
    theta = np.tile(np.linspace(-60.0, 60.0, 20), 3)
    frame = pd.DataFrame({"gamma_deg": settings_ + rng.uniform(-0.04, 0.04, 60),
                          "theta_deg": theta, "power": 1.0 + 0.5 * np.cos(np.radians(theta))})
    frame.to_csv(tmp_path / "j.csv", index=False)
    with pytest.warns(DataNotice, match=r"gamma_deg holds 60 distinct values in 3 groups, "
                                        r"each within 0\.0[0-9]+ deg: .*\(-10, -40, -70 deg\)"):
        m = read_measurements(tmp_path / "j.csv")
    assert sorted(set(m.gamma_deg)) == [-70.0, -40.0, -10.0]
    assert m.theta_deg.tolist() == theta.tolist()
    # a sweep of gamma in 0.05-deg steps, and two settings 0.3 deg apart: as measured
    for gammas in (np.repeat(np.arange(-12.0, -9.99, 0.05), 2), np.repeat([-10.0, -10.3], 20)):
        t = np.resize([-30.0, 30.0], gammas.size) + np.arange(gammas.size) * 1e-3
        f = pd.DataFrame({"gamma_deg": gammas, "theta_deg": t, "power": np.ones(gammas.size)})
        f.to_csv(tmp_path / "s.csv", index=False)
        with warnings.catch_warnings():
            warnings.simplefilter("error", DataNotice)
            assert read_measurements(tmp_path / "s.csv").gamma_deg.tolist() == \
                f["gamma_deg"].tolist()


def test_a_table_in_radians_is_told_it_may_be(tmp_path):
    """Angles in radians were read as degrees (a scan of +-1.4 deg) and fitted without a
    word; a table that sweeps its receiver over degrees is not told so."""
    theta = np.linspace(-1.38, 1.38, 12)
    for gammas, told in (([-0.17, -0.52, -0.87], True), ([-10.0, -40.0, -70.0], False)):
        scale = 1.0 if told else 180 / np.pi
        f = pd.DataFrame({"gamma_deg": np.repeat(gammas, 12), "theta_deg": np.tile(theta * scale, 3),
                          "power": np.tile(np.cos(theta), 3)})
        f.to_csv(tmp_path / "r.csv", index=False)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            read_measurements(tmp_path / "r.csv")
        said = [str(w.message) for w in caught if "may give radians" in str(w.message)]
        assert bool(said) == told
        if told:
            assert "every angle lies within +-1.571 (pi/2)" in said[0]
