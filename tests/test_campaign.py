"""The adaptive measurement campaign (issue 23): the instrument, the opening design, the
adaptive proposals within the instrument's limits, replays on a glossy and a matte material,
the stopping verdict, and the commands ``irreflect next`` and ``irreflect campaign``."""

from __future__ import annotations

import contextlib
import io
import json
import warnings

import numpy as np
import pandas as pd
import pytest

from irreflect.campaign import Campaign, DenseInstrument, Instrument, opening_design, replay
from irreflect.campaign.replay import replay_adaptive
from irreflect.cli import main
from irreflect.data import Measurements, bundled_dir, read_measurements
from irreflect.errors import DataError, IrreflectError
from irreflect.models import two_lobe_power

TERRAZZO = bundled_dir() / "terrazzo.csv"
#: a gloss paint: specular lobe half width 1.5 deg at normal incidence, 30 % specular
GLOSSY = np.array([0.3, -0.5, 1.2, 0.3, 2000.0, 0.4, 1.0])
#: a matte wall: a broad forward lobe
MATTE = np.array([0.03, -1.0, 1.0, 0.2, 20.0, 0.0, 1.0])


def _material(params, step=1.0, noise=0.01, seed=0, name="material"):
    """A dense scan of a two-lobe material: gamma -10..-70, theta every ``step`` deg."""
    rng = np.random.default_rng(seed)
    g, t = [], []
    for gamma in (-10.0, -20.0, -30.0, -40.0, -50.0, -60.0, -70.0):
        th = np.arange(-80.0, 80.0 + 1e-9, step)
        th = th[np.abs(th - gamma) >= 5.0]
        g.append(np.full(th.size, gamma))
        t.append(th)
    g, t = np.concatenate(g), np.concatenate(t)
    clean = two_lobe_power(np.radians(g), np.radians(t), *params)
    power = clean * (1.0 + noise * rng.standard_normal(clean.size))
    return Measurements(gamma_deg=g, theta_deg=t, power=power, name=name)


def _run(argv):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in argv])
    return code, out.getvalue(), err.getvalue()


# ----------------------------------------------------------------------------- instrument
def test_instrument_settings_follow_its_limits():
    tool = Instrument(gammas_deg=(30, 10, 60), theta_min=-40, theta_max=70, theta_step=2.5,
                      source_clearance=8)
    assert tool.gammas_deg == (-10.0, -30.0, -60.0)  # magnitudes read as gamma <= 0
    s = tool.settings()
    assert set(np.round(s[:, 0], 6)) == {-10.0, -30.0, -60.0}
    assert s[:, 1].min() >= -40 and s[:, 1].max() <= 70
    assert np.allclose(((s[:, 1] + 40) / 2.5) % 1.0, 0.0)  # on the receiver's step
    assert np.all(np.abs(s[:, 1] - s[:, 0]) >= 8 - 1e-9)  # clear of the source
    # -30 deg: 45 grid angles from -40 to 70, minus the 7 within 8 deg of theta = -30
    assert (s[:, 0] == -30).sum() == 45 - 7


@pytest.mark.parametrize("kwargs, fragment", [
    (dict(gammas_deg=()), "at least one angle of incidence"),
    (dict(gammas_deg=(-20, 30)), "mix signs"),
    (dict(gammas_deg=(-95,)), "strictly between -90 and 90"),
    (dict(gammas_deg=(-20,), theta_min=50, theta_max=-50), "theta_min < theta_max"),
    (dict(gammas_deg=(-20,), theta_step=0), "theta_step"),
    (dict(gammas_deg=(-20,), theta_min=-10, theta_max=10, theta_step=30), "wider than"),
    (dict(gammas_deg=(-20,), max_gamma_settings=0), "max_gamma_settings"),
    (dict(gammas_deg=(0,), theta_min=-2, theta_max=2, source_clearance=5), "no reading"),
])
def test_instrument_refuses_bad_limits_in_one_line(kwargs, fragment):
    with pytest.raises(IrreflectError, match=fragment) as info:
        Instrument(**kwargs)
    assert "\n" not in str(info.value)


# ----------------------------------------------------------------------------- opening
def test_opening_design_spans_the_angles_of_incidence_and_finds_the_mirrors():
    tool = Instrument(gammas_deg=(0, -15, -30, -45, -60, -75), theta_min=-80, theta_max=80,
                      theta_step=1.0, source_clearance=5.0)
    plan = Campaign(tool).propose(8)
    assert len(plan) == 8 and plan["why"].str.startswith("opening design").all()
    gammas = sorted(set(plan["gamma_deg"]), key=abs)
    # gamma 0 has its mirror on the source: the smallest reachable is -15; largest -75
    assert gammas == [-15.0, -45.0, -75.0]
    mirrors = plan[np.isclose(plan["theta_deg"], -plan["gamma_deg"])]
    assert sorted(mirrors["gamma_deg"], key=abs) == [-15.0, -45.0, -75.0]
    assert plan.duplicated(["gamma_deg", "theta_deg"]).sum() == 0
    # measurement order: each angle of incidence once, by |gamma|, the receiver sweeping
    order = np.abs(plan["gamma_deg"].to_numpy())
    assert np.all(np.diff(order) >= 0)
    assert plan["new_gamma"].sum() == 3
    # the same every time, and the first 8 of a longer opening
    assert plan.equals(Campaign(tool).propose(8))
    assert len(opening_design(tool, 20)) > 8


def test_opening_design_honours_the_gamma_settings():
    tool = Instrument(gammas_deg=(-10, -20, -30, -40, -50, -60, -70), max_gamma_settings=2)
    plan = Campaign(tool).propose(8)
    assert set(plan["gamma_deg"]) == {-10.0, -70.0}


# ----------------------------------------------------------------------------- adaptive
def _answer(params, rng, noise=0.01):
    def read(frame):
        clean = two_lobe_power(np.radians(frame["gamma_deg"].to_numpy()),
                               np.radians(frame["theta_deg"].to_numpy()), *params)
        return frame.assign(power=clean * (1.0 + noise * rng.standard_normal(len(frame))))
    return read


def test_adaptive_proposals_stay_within_the_instrument():
    tool = Instrument(gammas_deg=(-10, -20, -30, -40, -50, -60, -70), theta_min=-60,
                      theta_max=65, theta_step=2.0, min_separation=3.0, source_clearance=10.0,
                      max_gamma_settings=4)
    read = _answer(GLOSSY, np.random.default_rng(1))
    campaign = Campaign(tool, seed=0)
    while campaign.n_measured < 16:
        campaign.add(read(campaign.propose(4)[["gamma_deg", "theta_deg"]]))
    m = campaign.measurements
    assert m.n_points == 16
    assert len(np.unique(m.gamma_deg)) <= 4
    assert m.theta_deg.min() >= -60 and m.theta_deg.max() <= 65
    assert np.allclose(((m.theta_deg + 60) / 2.0) % 1.0, 0.0)
    assert np.all(np.abs(m.theta_deg - m.gamma_deg) >= 10 - 1e-9)
    for g in np.unique(m.gamma_deg):  # readings of one gamma at least 3 deg apart
        th = np.sort(m.theta_deg[m.gamma_deg == g])
        assert np.all(np.diff(th) > 3.0 - 1e-9)
    # every adaptive proposal says why
    more = campaign.propose(3)
    assert more["why"].str.len().min() > 10 and not more["why"].str.startswith("opening").any()


def test_proposals_are_seeded():
    tool = Instrument(gammas_deg=(-10, -30, -50, -70), theta_step=2.0)
    read = _answer(MATTE, np.random.default_rng(3))
    first = Campaign(tool, seed=4)
    first.add(read(first.propose(9)[["gamma_deg", "theta_deg"]]))
    second = Campaign(tool, first.measurements, seed=4)
    assert first.propose(3).equals(second.propose(3))


def test_a_glossy_material_is_pinned_down_within_a_dozen_readings():
    dense = _material(GLOSSY, name="gloss paint")
    result = replay(dense, ("adaptive", "paper", "random"), n_max=14, seed=0)
    adaptive = result.curves["adaptive"]
    reached = adaptive.reached(result.target)
    assert reached is not None and reached <= 12, adaptive.r2
    assert adaptive.r2[12] >= result.curves["paper"].r2[12] - 0.002
    # random readings rarely find a 1.5-deg lobe at 7 angles of incidence
    assert result.curves["random"].reached(result.target) is None


def test_a_matte_material_is_reached_within_a_dozen_readings():
    dense = _material(MATTE, step=2.0, name="matte wall")
    curve, verdicts, _ = replay_adaptive(DenseInstrument(dense), 14, seed=0)
    import irreflect

    reference = irreflect.fit(dense, seed=0).r2
    reached = curve.reached(reference - 0.01)
    assert reached is not None and reached <= 12, curve.r2
    assert set(verdicts) == set(range(1, 15))


def test_a_real_glossy_paint_beats_the_paper_protocol(real_dir):
    dense = read_measurements(real_dir / "cornell" / "cornell_cayman.csv")
    result = replay(dense, ("adaptive", "paper"), n_max=12, seed=0)
    # the paper's protocol predicts a high-gloss lacquer worse than a constant
    assert result.curves["paper"].r2[12] < 0.5
    assert result.curves["adaptive"].r2[12] >= result.reference_r2 - 0.01


# ----------------------------------------------------------------------------- verdict
def test_the_verdict_continues_until_the_curve_holds_then_stops():
    dense = _material(GLOSSY, step=2.0, noise=0.005, name="gloss")
    curve, verdicts, _ = replay_adaptive(DenseInstrument(dense), 20, seed=0)
    import irreflect

    reference = irreflect.fit(dense, seed=0).r2
    assert not any(verdicts[n].stop for n in range(1, 10))
    assert "needs 8 readings" in verdicts[3].text
    stops = [n for n in sorted(verdicts) if verdicts[n].stop]
    assert stops, [verdicts[n].text for n in sorted(verdicts)][-3:]
    first = stops[0]
    assert curve.r2[first] >= reference - 0.02
    assert verdicts[first].text.startswith("stop: ")
    low, high = verdicts[first].r2_band
    assert low <= high <= 1.0


def test_the_verdict_stops_within_three_readings_of_the_target_on_a_matte_material():
    # issue 23: the verdict stops within 3 readings of the first N that keeps the
    # all-points fit's R^2 - 0.01, never 0.02 below it (at a 0.5 % tolerance on the
    # curve's moves it stopped 4 readings after on this table)
    import irreflect
    from irreflect.synthetic import synthetic_material

    dense = synthetic_material(2, "matte").measurements
    curve, verdicts, _ = replay_adaptive(DenseInstrument(dense), 14, seed=0)
    reference = irreflect.fit(dense, seed=0).r2
    reached = curve.reached(reference - 0.01)
    assert reached is not None, curve.r2
    stop = next(n for n in sorted(verdicts) if verdicts[n].stop)
    assert stop <= reached + 3, (reached, stop)
    assert curve.r2[stop] >= reference - 0.02


def test_the_verdict_names_missing_angles_of_incidence():
    tool = Instrument(gammas_deg=(-10, -30, -50, -70), theta_step=2.0)
    rows = []
    read = _answer(MATTE, np.random.default_rng(0))
    frame = pd.DataFrame({"gamma_deg": np.repeat([-10.0, -30.0], 6),
                          "theta_deg": np.tile([-60.0, -30.0, 0.0, 20.0, 40.0, 70.0], 2)})
    rows = read(frame)
    v = Campaign(tool, rows).verdict()
    assert not v.stop and "outside the measured span" in v.text and "-70" in v.text


# ----------------------------------------------------------------------------- readings
def test_add_refuses_a_repeated_reading_and_mixed_sigma():
    tool = Instrument(gammas_deg=(-20, -40))
    campaign = Campaign(tool, [(-20, 10, 1.0), (-20, 20, 2.0)])
    with pytest.raises(DataError, match="given twice"):
        campaign.add([(-20, 20, 2.5)])
    with pytest.raises(DataError, match="sigma"):
        campaign.add(pd.DataFrame({"gamma_deg": [-40.0], "theta_deg": [0.0], "power": [1.0],
                                   "sigma": [0.1]}))
    assert campaign.n_measured == 2


# ----------------------------------------------------------------------------- commands
def test_next_on_a_header_only_table_writes_the_opening(tmp_path):
    measured = tmp_path / "measured.csv"
    measured.write_text("gamma_deg,theta_deg,power\n")
    out = tmp_path / "next.csv"
    code, stdout, err = _run(["next", measured, "--n", "8", "--gammas", "-20", "-40", "-60",
                              "--theta-min", "-70", "--theta-max", "70", "--out", out])
    assert code == 0, err
    table = pd.read_csv(out)
    assert list(table.columns) == ["gamma_deg", "theta_deg", "why", "new_gamma", "power"]
    assert len(table) == 8 and table["power"].isna().all()
    assert set(table["gamma_deg"]) == {-20.0, -40.0, -60.0}
    assert "verdict: continue" in stdout and measured.read_text() == "gamma_deg,theta_deg,power\n"
    # fill in the power of a glossy material, and ask again
    clean = two_lobe_power(np.radians(table["gamma_deg"]), np.radians(table["theta_deg"]),
                           *GLOSSY)
    table.assign(power=clean)[["gamma_deg", "theta_deg", "power"]].to_csv(measured, index=False)
    code, stdout, err = _run(["next", measured, "--n", "2", "--gammas", "-20", "-40", "-60",
                              "--json"])
    assert code == 0, err
    doc = json.loads(stdout)
    assert doc["n_measured"] == 8 and len(doc["proposals"]) == 2
    assert doc["verdict"]["verdict"] == "continue" and doc["verdict"]["stop"] is False
    assert "at least 10 readings before stopping" in doc["verdict"]["reasons"]


@pytest.mark.parametrize("content, fragment", [
    ("gamma,theta_deg,power\n", "missing column 'gamma_deg'"),
    ("gamma_deg;theta_deg;power\n", "separated by"),
    ("gamma_deg,theta_deg,power\n-20,10,x\n", "must be numeric"),
])
def test_next_refuses_bad_tables_in_one_line(tmp_path, content, fragment):
    measured = tmp_path / "measured.csv"
    measured.write_text(content)
    code, stdout, err = _run(["next", measured, "--out", tmp_path / "next.csv"])
    assert code == 2 and err.count("\n") == 1 and fragment in err, err
    assert not (tmp_path / "next.csv").exists()


def test_next_never_replaces_its_input(tmp_path):
    measured = tmp_path / "measured.csv"
    measured.write_text("gamma_deg,theta_deg,power\n")
    code, _, err = _run(["next", measured, "--out", measured])
    assert code == 2 and "input" in err
    assert measured.read_text() == "gamma_deg,theta_deg,power\n"


def test_campaign_command_prints_and_writes_the_replay(tmp_path):
    out = tmp_path / "camp"
    code, stdout, err = _run(["campaign", TERRAZZO, "--strategies", "adaptive,paper,random",
                              "--n-max", "10", "--out", out])
    assert code == 0, err
    assert "terrazzo: 132 points" in stdout and "R^2 against all points by number" in stdout
    table = pd.read_csv(out / "r2_by_n.csv")
    assert list(table.columns)[:4] == ["N", "adaptive", "paper", "random"]
    assert table.dropna(subset=["adaptive"])["N"].max() == 10
    assert (out / "campaign.png").read_bytes()[:4] == b"\x89PNG"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        doc = json.loads((out / "replay.json").read_text())
    assert doc["curves"]["paper"]["r2"]["12"] < doc["reference_r2"]
