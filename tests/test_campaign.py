"""The adaptive measurement campaign (issue 23): the instrument, the opening design, the
adaptive proposals within the instrument's limits, replays on a glossy and a matte material,
the stopping verdict, and the commands ``irreflect next`` and ``irreflect campaign``."""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from irreflect.campaign import Campaign, DenseInstrument, Instrument, opening_design, replay
from irreflect.campaign.replay import replay_adaptive
from irreflect.cli import main
from irreflect.data import DataNotice, Measurements, bundled_dir, read_measurements
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
    # None said 'found nan' (read as NaN), and text was a bare numpy ValueError
    (dict(gammas_deg=None), r"^gammas_deg must list the angles of incidence the source arm can "
                            r"be set to, in degrees; found None: pass e\.g\. "
                            r"gammas_deg=\(-10, -30, -50\) \(--gammas G \[G \.\.\.\]\)$"),
    (dict(gammas_deg=[-10, None]), r"^the instrument: gammas_deg \(the angles of incidence\) "
                                   r"must be numbers; found None at index 1: "),
    (dict(gammas_deg="abc"), r"gammas_deg \(the angles of incidence\) must be numbers; "
                             r"found (np\.str_\()?'abc'"),
    (dict(gammas_deg=(-20, 30)), "mix signs"),
    (dict(gammas_deg=(-95,)), "strictly between -90 and 90"),
    (dict(gammas_deg=(-20,), theta_min=50, theta_max=-50), "theta_min < theta_max"),
    (dict(gammas_deg=(-20,), theta_step=0), "theta_step"),
    (dict(gammas_deg=(-20,), theta_min=-10, theta_max=10, theta_step=30), "wider than"),
    (dict(gammas_deg=(-20,), max_gamma_settings=0), "max_gamma_settings"),
    (dict(gammas_deg=(0,), theta_min=-2, theta_max=2, source_clearance=5), "no reading"),
    (dict(gammas_deg=(-20,), resolution=-1), "resolution"),
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
    # the instrument's span, 0 to -75, though gamma 0 has its mirror on the source (the
    # verdict waits for every angle of incidence; an opening from -15 had left campaigns
    # that never stopped); the middle one is an angle whose mirror it reaches
    assert gammas == [0.0, -30.0, -75.0]
    mirrors = plan[np.isclose(plan["theta_deg"], -plan["gamma_deg"])]
    assert sorted(mirrors["gamma_deg"], key=abs) == [-30.0, -75.0]
    # at normal incidence the "mirror" reading is the setting nearest it, and says so
    first = plan[(plan["gamma_deg"] == 0.0) & plan["why"].str.contains("mirror direction")]
    assert len(first) == 1 and abs(first["theta_deg"].iloc[0]) == 5.0
    assert "not available" in first["why"].iloc[0]
    assert "the specular peak" not in first["why"].iloc[0]
    assert plan.duplicated(["gamma_deg", "theta_deg"]).sum() == 0
    # measurement order: each angle of incidence once, by |gamma|, the receiver sweeping
    order = np.abs(plan["gamma_deg"].to_numpy())
    assert np.all(np.diff(order) >= 0)
    assert plan["new_gamma"].sum() == 3
    # the same every time, and the first 8 of a longer opening
    assert plan.equals(Campaign(tool).propose(8))
    assert len(opening_design(tool, 20)) > 8


def test_an_opening_reading_the_receiver_cannot_place_is_not_called_what_it_missed(tmp_path):
    """A receiver range that misses the mirror direction: the nearest setting is not called
    "the specular peak", nor a far-side reading "source side"; `next` warns that the peak
    will be extrapolated (the labels were the plan's, whatever the instrument allowed)."""
    tool = Instrument(gammas_deg=(-30,), theta_min=50, theta_max=60)
    assert tool.mirror_misses() == (-30.0,)
    plan = Campaign(tool).propose(8)
    assert not plan["why"].str.contains("specular peak|source side$").any(), plan["why"]
    first = plan.iloc[0]
    assert (first["theta_deg"], first["why"]) == (
        50.0, "opening design: mirror direction: not available (the mirror direction is "
              "beyond the receiver's range), so the nearest free setting, 20 deg beyond the "
              "mirror direction")
    # where the plan's setting is possible its reason stays
    wide = Campaign(Instrument(gammas_deg=(-10, -40, -70), theta_min=-30, theta_max=40,
                               theta_step=5)).propose(8)
    assert Instrument(gammas_deg=(-10, -40, -70), theta_min=-30, theta_max=40,
                      theta_step=5).mirror_misses() == (-70.0,)
    said = {(r.gamma_deg, r.theta_deg): r.why for r in wide.itertuples()}
    assert said[(-40.0, 40.0)].endswith("mirror direction: the specular peak")
    assert said[(-10.0, -30.0)].endswith("diffuse lobe, source side")
    assert "5 deg short of the mirror" in said[(-40.0, 35.0)]  # "far side" could not be
    measured = tmp_path / "m.csv"
    measured.write_text("gamma_deg,theta_deg,power\n")
    code, _, err = _run(["next", measured, "--gammas", "10,40,70", "--theta-min", "-30",
                         "--theta-max", "40", "--theta-step", "5"])
    assert code == 0 and err.count("warning") == 1
    assert ("the specular peak (theta = -gamma) cannot be measured at gamma -70 deg (beyond "
            "the receiver range -30..40 deg" in err)
    code, _, err = _run(["next", measured, "--gammas", "10,40"])
    assert code == 0 and "warning" not in err
    # at normal incidence the mirror is the source direction: the clearance blocks it
    code, _, err = _run(["next", measured, "--gammas", "0,20", "--theta-min", "-30"])
    assert code == 0 and "at gamma 0 deg (within 5 deg of the source direction" in err


def test_opening_design_honours_the_gamma_settings():
    tool = Instrument(gammas_deg=(-10, -20, -30, -40, -50, -60, -70), max_gamma_settings=2)
    plan = Campaign(tool).propose(8)
    assert set(plan["gamma_deg"]) == {-10.0, -70.0}


def test_opening_labels_say_where_the_reading_stands_and_one_angle_does_not_crowd():
    """With --gamma-settings 1 the plan's readings for three angles fell on -70 deg: theta
    +20 was called "diffuse lobe, source side" (the far side), and five of ten readings
    crowded at theta -80, -79, 78, 79, 80; at gamma 0 the opening spoke of "grazing
    incidence" and of a source side the normal incidence has not."""
    one = Campaign(Instrument(gammas_deg=(-10, -20, -30, -40, -50, -60, -70), theta_min=-80,
                              theta_max=80, max_gamma_settings=1)).propose(10)
    said = dict(zip(one.theta_deg, one.why, strict=True))
    assert set(one.gamma_deg) == {-70.0} and len(one) == 10
    assert said[20.0] == ("opening design: diffuse lobe on the far side, 50 deg short of the "
                          "mirror direction")
    assert all(t < 0 for t, why in said.items() if "source side" in why), said
    assert said[70.0].endswith("mirror direction: the specular peak")
    assert said[0.0].endswith("diffuse lobe near the normal, grazing incidence")
    assert int(np.sum(np.abs(one.theta_deg) >= 78)) == 2, said  # -80 and 80, not five
    normal = Campaign(Instrument(gammas_deg=(0,), theta_min=-80, theta_max=80)).propose(10)
    assert not normal.why.str.contains("grazing|source side|toward|short of").any(), normal
    assert normal.why.str.contains("normal incidence").any()
    assert "diffuse lobe, 50 deg from the normal" in set(normal.why.str[16:])
    from irreflect.campaign.design import region  # the adaptive proposals' words alike

    assert region(0.0, -50.0, 5.0) == "the diffuse lobe, 50 deg from the normal"
    assert region(-40.0, -50.0, 5.0) == "the diffuse lobe on the source side"
    small = Campaign(Instrument(gammas_deg=(-10, -20, -30, -40))).propose(8)
    assert not small.why.str.contains("grazing incidence").any()
    assert small.why.str.contains("40 deg incidence \\(the largest\\)").any()


@pytest.mark.parametrize("name, kw", [
    ("cli", dict(gammas_deg=(-10, -20, -30, -40, -50, -60, -70), theta_min=-80, theta_max=80)),
    ("docs", dict(gammas_deg=(0, -15, -30, -45, -60, -75), theta_min=-64, theta_max=64)),
    ("coarse", dict(gammas_deg=(-10, -30, -50, -70, -80), theta_step=2.0, min_separation=3.0,
                    source_clearance=10.0)),
])
def test_the_opening_of_a_standard_instrument_is_the_same_settings_as_before(name, kw):
    """The opening's settings before the labels and the one-angle crowding were mended
    (stop 45), on instruments with three or more angles: the whole plan, and the readings
    of a campaign asking for 3, 3 and 2 at a time."""
    before = {
        "cli": (
            [(-10, 10), (-40, 40), (-70, 70), (-10, -40), (-70, 0), (-70, 68), (-40, 75),
             (-10, 11), (-70, -80), (-40, -60), (-10, 35), (-70, 80)],
            [(-10, 10), (-40, 40), (-70, 70), (-10, -40), (-70, 0), (-70, 68), (-10, 11),
             (-40, 75)]),
        "docs": (
            [(0, -5), (-30, 30), (-75, 64), (0, -50), (-75, 0), (-75, 63), (-30, 64), (0, 5),
             (-75, -64), (-30, -50), (0, 25), (-75, 62)],
            [(0, -5), (-30, 30), (-75, 64), (0, -50), (-75, 0), (-75, 63), (0, 5), (-30, 64)]),
        "coarse": (
            [(-10, 9), (-50, 49), (-80, 79), (-10, -41), (-80, -1), (-80, 75), (-50, 85),
             (-10, 13), (-80, -69), (-50, -71), (-10, 35), (-80, 85)],
            [(-10, 9), (-50, 49), (-80, 79), (-10, -41), (-80, -1), (-80, 75), (-10, 13),
             (-50, 85)]),
    }
    tool = Instrument(**kw)
    plan, walk = before[name]
    assert [(g, t) for g, t, _ in opening_design(tool, 15)] == plan
    campaign, taken = Campaign(tool, seed=0), []
    for k in (3, 3, 2):
        rows = campaign.propose(k)[["gamma_deg", "theta_deg"]]
        taken += list(zip(rows.gamma_deg, rows.theta_deg, strict=True))
        campaign.add(_answer(GLOSSY, np.random.default_rng(0), noise=0.0)(rows))
    assert taken == walk


def test_the_verdict_stops_once_the_allowed_angles_of_incidence_are_spent():
    # 0 deg cannot be set for the specular peak (the source stands there), so the two
    # allowed angles are 15 and 75 deg and 0 deg stays outside the measured span for good:
    # the verdict stops on the curve, says what is extrapolated, and never asks for 0 deg
    tool = Instrument(gammas_deg=(0, 15, 30, 45, 60, 75), theta_step=1, max_gamma_settings=2)
    read = _answer(GLOSSY, np.random.default_rng(0))
    campaign = Campaign(tool, seed=0)
    verdict = None
    while campaign.n_measured < 20:
        campaign.add(read(campaign.propose(1)[["gamma_deg", "theta_deg"]]))
        verdict = campaign.verdict()
        assert not any("outside the measured span" in r for r in verdict.reasons)
        if verdict.stop:
            break
    assert set(np.abs(campaign.measurements.gamma_deg)) == {15.0, 75.0}
    assert verdict.stop and campaign.n_measured <= 14
    assert "extrapolated to |gamma| 0 deg" in verdict.text


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


# ----------------------------------------------------------------------------- the fit
def test_range_weights_give_each_reading_the_share_of_the_range_nearest_to_it():
    from irreflect.campaign.core import range_weights

    tool = Instrument(gammas_deg=(-20.0, -60.0), theta_min=-80, theta_max=80, theta_step=1.0)
    rng = tool.settings()
    # three readings crowded at the mirror of -20 deg, one alone at -60 deg
    g = np.array([-20.0, -20.0, -20.0, -60.0])
    t = np.array([19.0, 20.0, 21.0, 0.0])
    w = range_weights(rng, g, t)
    assert w.mean() == pytest.approx(1.0)
    # the lone reading stands for (nearly) the whole row of -60 deg, the crowded ones for
    # a share of the row of -20 deg: the middle one for a single setting
    counts = w / w.sum() * len(rng)
    assert counts[3] >= 0.9 * np.sum(rng[:, 0] == -60.0)
    assert counts[1] == pytest.approx(1.0)
    assert counts[0] > 30 and counts[2] > 30  # each the rest of its side of the row



def test_power_weights_give_a_reading_the_predicted_power_of_its_cell():
    from irreflect.campaign.core import power_weights

    # reading 0 stands for four settings predicted at its own power, reading 1 for four
    # predicted at 3x its power (a reading on the lobe's flank standing for its peak)
    nearest = np.array([0, 0, 0, 0, 1, 1, 1, 1])
    f_read = np.array([1.0, 1.0])
    f_range = np.array([1.0, 1.0, 1.0, 1.0, 3.0, 3.0, 3.0, 3.0])
    w = power_weights(nearest, f_range, f_read)
    assert w.mean() == pytest.approx(1.0)
    assert w[1] / w[0] == pytest.approx(9.0, rel=1e-4)  # (f_r / f_i)^2 summed over the cell
    capped = power_weights(nearest, f_range, f_read, cap=2.0)
    assert capped[1] / capped[0] == pytest.approx(4.0, rel=1e-4)
    # a floor of the peak's share pulls the ratio toward 1: (3 + 3) / (1 + 3) = 1.5
    floored = power_weights(nearest, f_range, f_read, floor=1.0)
    assert floored[1] / floored[0] == pytest.approx(1.5 ** 2, rel=1e-3)
    # a reading whose cell is predicted dark keeps the weight of one setting
    dark = power_weights(nearest, np.r_[np.zeros(4), np.ones(4)], np.array([1.0, 1.0]))
    assert dark[0] / dark[1] == pytest.approx(0.25, rel=1e-4)

#: the 25 settings the campaign chose on the RGL satin (seed 0, before its fit weighed the
#: readings): the 25th, 7 deg off the mirror at 69 deg, sits where the model misfits
SATIN = [(0.0, 0.0), (-39.7407, 39.7407), (-68.7703, 68.7703), (0.0, -50.0),
         (-68.7703, 0.0), (-68.7703, 67.7703), (-39.7407, 75.0), (0.0, 1.0),
         (-59.3795, 60.8795), (-68.7703, 73.0), (-68.7703, 64.5203), (-49.9236, 46.4236),
         (-68.7703, 71.7703), (-49.9236, 48.0), (-27.4879, 18.0), (-27.4879, 27.4879),
         (-49.9236, 53.4236), (-59.3795, 57.6295), (0.0, -6.0), (-27.4879, 22.9879),
         (-49.9236, -14.0), (-59.3795, 63.6295), (-27.4879, 31.2379), (-39.7407, 36.7407),
         (-68.7703, 62.0)]


def _replayed(real_dir, name, settings):
    """A real table of the RGL set as the instrument, and its readings at ``settings``
    (seeded): ``(dense, source, rows)`` with ``rows`` a table of gamma, theta, power."""
    dense = read_measurements(real_dir / "rgl_epfl" / f"{name}.csv")
    source = DenseInstrument(dense)
    s = np.array(settings)
    power = source.read(s[:, 0], s[:, 1], np.random.default_rng(0))
    return dense, source, pd.DataFrame({"gamma_deg": s[:, 0], "theta_deg": s[:, 1],
                                        "power": power})


def test_the_campaign_fit_is_not_dragged_by_one_reading_where_the_model_misfits(real_dir):
    # equally weighted, the satin's 25 readings give R^2 0.963 on all points, below the
    # all-points fit's 0.976 - 0.01: the last reading pulls the fit as much as a whole row
    # of settings would; weighted by the range each stands for, they stay within 0.01
    import irreflect
    from irreflect import metrics

    dense, source, readings = _replayed(real_dir, "rgl_satin_rosaline", SATIN)
    s, power = np.array(SATIN), readings["power"].to_numpy()
    reference = irreflect.fit(dense, seed=0).r2
    plain = irreflect.fit(Measurements(gamma_deg=s[:, 0], theta_deg=s[:, 1], power=power),
                          seed=0)
    assert metrics.r2(dense.power, plain.predict(dense.gamma_deg, dense.theta_deg)) \
        < reference - 0.01
    campaign = Campaign(source.instrument(), readings, seed=0)
    assert campaign.r2_against(dense) >= reference - 0.01
    # the result is a fit of the readings: no sigma was given, none is reported
    assert campaign.fit.sigma is None and np.isnan(campaign.fit.chi2_reduced)
    assert np.all(np.isfinite(campaign.fit.stderr))


#: the first 10 settings the campaign chose on the RGL golden yellow paint (seed 0)
GOLDEN = [(0.0, 0.0), (-31.6178, 31.6178), (-66.3495, 66.3495), (0.0, -50.0),
          (-66.3495, 0.0), (-66.3495, 65.3495), (-31.6178, 67.0), (0.0, 1.0),
          (-45.3703, 49.0), (-45.3703, 46.6203)]


@pytest.mark.parametrize("continuation", [True, False])
def test_a_fit_that_overshoots_where_nothing_is_measured_gives_way(real_dir, continuation):
    # at 10 readings the golden yellow's global optimum sends the diffuse law to its bound
    # and predicts a spike of many times the largest reading at an unmeasured setting (R^2
    # far below 0 on all points); the continuation of the 9-reading fit explains the
    # readings nearly as well and does not: the campaign keeps it, and tests the spike
    import dataclasses

    from irreflect.campaign import DesignRule
    from irreflect.campaign.core import OVERSHOOT

    dense, source, rows = _replayed(real_dir, "rgl_vch_golden_yellow", GOLDEN)
    s, power = np.array(GOLDEN), rows["power"].to_numpy()
    # the readings and the weights of the campaign that met it (stop 31: power_cap 10; with
    # the default of 5 since stop 33 the continuation of these readings overshoots too)
    rule = dataclasses.replace(DesignRule(), continuation=continuation, power_cap=10.0)
    campaign = Campaign(source.instrument(), rows.iloc[:9], seed=0, rule=rule)
    assert campaign.r2_against(dense) > 0.85
    campaign.add(rows.iloc[9:])
    over = campaign._overshoot(campaign.fit.values, float(power.max()))
    if continuation:
        assert over <= OVERSHOOT
        assert campaign.r2_against(dense) > 0.9
        # the next proposals test the rejected fit where it put its spike: near the normal
        # at an angle of incidence not measured yet, and say so
        proposal = campaign.propose(3)
        spike = proposal[proposal["why"].str.contains("rival fit")]
        assert len(spike) == 1
        assert abs(spike["theta_deg"].iloc[0]) <= 5.0
        assert spike["gamma_deg"].iloc[0] not in set(s[:, 0])
    else:
        assert over > 5 * OVERSHOOT
        assert campaign.r2_against(dense) < 0.0


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
    # a material the model describes: no word of a missing effect
    assert not any("explains the readings only" in verdicts[n].text for n in stops)
    low, high = verdicts[first].r2_band
    assert low <= high <= 1.0


def test_the_verdict_carries_the_moves_it_judged_and_what_blocks_it():
    # the verdict's moves (fits without the last 1..3 readings) and its blocking reasons
    # are what experiments/stop_rules.py replays other stop rules on
    from irreflect.campaign.core import STOP_HOLD, STOP_TOLERANCE

    dense = _material(GLOSSY, step=2.0, noise=0.005, name="gloss")
    _, verdicts, _ = replay_adaptive(DenseInstrument(dense), 16, seed=0)
    assert verdicts[4].blocking == verdicts[4].reasons and verdicts[4].moves == ()
    judged = [v for v in verdicts.values() if v.moves]
    assert judged and all(len(v.moves) == STOP_HOLD + 1 for v in judged)
    for v in judged:
        assert v.stability == max(v.moves)
        assert v.stop == (not v.blocking)
        moved = any(b.startswith(("the last ", "the curve must hold")) for b in v.blocking)
        assert moved == (not v.stability <= STOP_TOLERANCE)
        assert set(v.blocking) <= set(v.reasons)
    # the first fit has no earlier fits: every move infinite, and the verdict waits
    first = min(v.n_measured for v in judged)
    assert np.all(np.isinf(verdicts[first].moves))
    assert any(v.stop for v in judged) and any(not v.stop for v in judged)
    d = json.loads(json.dumps(judged[-1].to_dict(), allow_nan=False))
    assert d["moves"] == pytest.approx(list(judged[-1].moves))
    assert d["blocking"] == list(judged[-1].blocking)


def test_stop_rules_replays_the_campaigns_own_stops_from_a_recording(tmp_path):
    # experiments/stop_rules.py: the campaign's rule (the largest move) replayed on the
    # recorded verdicts gives the recorded stops; a more lenient rule stops no later
    import importlib.util

    here = Path(__file__).resolve().parents[1] / "experiments" / "stop_rules.py"
    spec = importlib.util.spec_from_file_location("stop_rules", here)
    stop_rules = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(stop_rules)
    dense = _material(GLOSSY, step=2.0, noise=0.005, name="gloss")
    curve, verdicts, _ = replay_adaptive(DenseInstrument(dense), 16, seed=0)
    rows = [{"n": n, "stop": v.stop, "moves": [None if not np.isfinite(m) else m
                                                for m in v.moves],
             "blocking": list(v.blocking), "r2rep": curve.r2.get(n)}
            for n, v in sorted(verdicts.items())]
    recorded = next(n for n, v in sorted(verdicts.items()) if v.stop)
    largest = stop_rules.RULES["largest (the campaign's)"]
    assert stop_rules.stop_at(rows, largest, 0.01) == recorded
    assert stop_rules.stop_at(rows, stop_rules.RULES["mean"], 0.01) <= recorded
    # a tolerance no move meets: never
    assert stop_rules.stop_at(rows, largest, 1e-12) is None
    # judged as bench_campaign judges: all points 0.99, within 0.01 from 9 readings on
    r2 = {8: 0.95, 9: 0.985, 10: 0.983, 11: 0.99, 12: 0.99, 13: 0.99, 14: 0.99}
    table = {"r2_all": 0.99, "rows": [{"n": n, "r2rep": v} for n, v in r2.items()]}
    assert stop_rules.holds_from(table["rows"], 0.98) == 9
    assert [stop_rules.judge(table, n) for n in (None, 8, 9, 12, 13)] == [
        "never", "below", "ok", "ok", "late"]
    path = tmp_path / "rec.json"
    path.write_text(json.dumps([{"label": "gloss", "r2_all": 0.99, "rows": rows}]))
    assert stop_rules.main([str(path)]) == 0
    # a file that is not a recording: one line, no traceback
    bad = tmp_path / "bad.json"
    bad.write_text('{"rows": 1}')
    with pytest.raises(SystemExit, match="expected a list of recorded campaigns"):
        stop_rules.main([str(bad)])
    with pytest.raises(SystemExit, match="expected a JSON recording"):
        stop_rules.main([str(tmp_path / "missing.json")])


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


def test_a_settled_curve_takes_the_missing_angle_of_incidence_next():
    """The verdict waits for every angle of incidence; with a high cost of a new angle the
    rule kept proposing the measured ones (gamma -50, a campaign that never stopped): once
    the curve has settled and only the missing angle keeps it going, it is proposed."""
    tool = Instrument(gammas_deg=(-10, -30, -50, -70), theta_step=2.0, gamma_change_cost=1e4)
    read = _answer(MATTE, np.random.default_rng(0), noise=0.002)
    frame = pd.DataFrame({"gamma_deg": np.repeat([-10.0, -30.0, -50.0], 6),
                          "theta_deg": np.tile([-60.0, -30.0, 0.0, 20.0, 40.0, 70.0], 3)})
    campaign = Campaign(tool, read(frame))
    reasons = campaign.verdict().reasons
    assert len(reasons) == 1 and reasons[0].startswith("angles of incidence outside")
    first = campaign.propose(2).iloc[0]
    assert first["gamma_deg"] == -70.0 and first["new_gamma"]
    assert "this one lies outside their span" in first["why"]


def test_a_fine_receiver_step_keeps_settings_at_every_mirror():
    """With a 0.1-deg receiver step the design's settings (at most 900) had kept the
    near-mirror settings of the first angles of incidence only: from -30 deg on, none was
    within 10 deg of the mirror, and no proposal could go there."""
    tool = Instrument(gammas_deg=range(0, 81, 10), theta_step=0.1, source_clearance=5.0)
    settings = Campaign(tool)._settings
    assert len(settings) <= 900
    for gamma in tool.gammas:
        at = settings[np.isclose(settings[:, 0], gamma)]
        nearest = np.min(np.abs(at[:, 1] + gamma))
        assert nearest <= (0.1 if gamma else 5.0) + 1e-9, (gamma, nearest)
        assert np.min(np.abs(at[:, 1])) <= 0.5 or gamma == 0  # the normal too


def test_the_new_angle_clause_stands_on_the_row_that_opens_the_angle():
    """A batch is chosen greedily and then put in measurement order: the clause "a new
    angle of incidence" stayed with the row chosen first, after another row of that angle."""
    from irreflect.campaign.core import _new_gamma_reason_first

    out = pd.DataFrame({
        "gamma_deg": [-60.0, -60.0, -40.0],
        "theta_deg": [58.25, 60.25, 0.5],
        "why": ["the specular lobe's flank, 1.75 deg from the mirror",
                "the specular lobe's body, 0.25 deg from the mirror; a new angle of incidence "
                "between the measured ones (60 deg); shrinks the standard error of u_ns by 2%",
                "the diffuse lobe near the normal"],
        "new_gamma": [True, False, False]})
    why = _new_gamma_reason_first(out)
    assert why[0] == ("the specular lobe's flank, 1.75 deg from the mirror; a new angle of "
                      "incidence between the measured ones (60 deg)")
    assert why[1] == ("the specular lobe's body, 0.25 deg from the mirror; shrinks the "
                      "standard error of u_ns by 2%")
    assert why[2] == out["why"][2]


def _dielectric_table(alpha=0.05, n=1.5, kd=0.5, seed=0):
    """A smooth dielectric (GGX microfacets, Smith shadowing, full Fresnel; the diffuse part
    times (1 - F) in and out): a model irreflect does not fit, its specular share rising to
    1 at grazing. Angles of incidence 0 to -80 deg, the receiver every deg with a 0.25-deg
    ring round the mirror and 5 deg clear of the source; 1 % noise plus 1e-4 of the peak."""
    def fresnel(cos_b):
        cos_b = np.clip(cos_b, 0.0, 1.0)
        cos_t = np.sqrt(np.clip(1.0 - (1.0 - cos_b ** 2) / n ** 2, 0.0, 1.0))
        rs = (cos_b - n * cos_t) / (cos_b + n * cos_t)
        rp = (n * cos_b - cos_t) / (n * cos_b + cos_t)
        return 0.5 * (rs ** 2 + rp ** 2)

    def smith(x):
        return 2.0 / (1.0 + np.sqrt(1.0 + alpha ** 2 * np.tan(np.abs(x)) ** 2))

    rng = np.random.default_rng(seed)
    g, t = [], []
    for gamma in np.arange(0.0, -81.0, -10.0):
        th = np.union1d(np.arange(-85.0, 85.5, 1.0),
                        np.arange(-gamma - 3.0, -gamma + 3.1, 0.25))
        th = th[(np.abs(th) <= 85.0) & (np.abs(th - gamma) > 5.0)]
        g.append(np.full(th.size, gamma))
        t.append(th)
    g, t = np.concatenate(g), np.concatenate(t)
    gi, tr = np.radians(np.abs(g)), np.radians(t)
    half, beta = (tr - gi) / 2.0, np.abs(tr + gi) / 2.0
    ggx = alpha ** 2 / (np.pi * np.cos(half) ** 4 * (alpha ** 2 + np.tan(half) ** 2) ** 2)
    spec = ggx * fresnel(np.cos(beta)) * smith(gi) * smith(tr) / (4 * np.cos(gi) * np.cos(tr))
    diffuse = kd / np.pi * (1.0 - fresnel(np.cos(gi))) * (1.0 - fresnel(np.cos(tr)))
    clean = (spec + diffuse) * np.cos(tr)
    clean /= clean.max()
    power = (clean * (1.0 + 0.01 * rng.standard_normal(clean.size))
             + 1e-4 * rng.standard_normal(clean.size))
    return Measurements(gamma_deg=g, theta_deg=t, power=power, name="dielectric")


def test_a_needle_where_nothing_is_measured_is_tested_and_never_stopped_on():
    """A smooth dielectric: every fit of the readings at gamma 0, -40 and -80 put the
    diffuse index law at its bound, a needle at the normal at -70 deg, 0.3 deg wide and
    20-70 times the largest reading, that the design's thinned settings did not hold: R^2
    -505 from 11 readings on, and a stop at -342. The fit's largest prediction is now taken
    on the normal as well, tested by the next reading, and no stop is made on it."""
    from irreflect.fitting import fit

    table = _dielectric_table()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        target = fit(table, "two-lobe", seed=0).r2 - 0.01
    source = DenseInstrument(table)
    campaign = Campaign(source.instrument(), seed=0,
                        noise_floor=max(0.0, -float(table.power.min())))
    rng = np.random.default_rng([0, 11])
    tested, r2 = False, {}
    for _ in range(16):
        proposal = campaign.propose(1)
        tested |= proposal["why"].str.contains("tests the fit's prediction of").any()
        power = source.read(proposal["gamma_deg"], proposal["theta_deg"], rng)
        campaign.add(proposal[["gamma_deg", "theta_deg"]].assign(power=power))
        verdict = campaign.verdict()
        if campaign.fit is not None:
            r2[campaign.n_measured] = campaign.r2_against(table)
            peak = np.max(campaign.fit.predict(*source.instrument().settings().T))
            if verdict.stop:
                assert peak <= 3.0 * campaign.measurements.power.max()
                assert r2[campaign.n_measured] >= target - 0.01
    assert tested
    # within 0.01 of the all-points fit from 12 readings, but for the 15th: there the
    # picture of the quadrature estimate holds a bump at the normal at -60 deg that no
    # reading is near (0.21 by differences, 0.30 by the ratio since stop 55, where the
    # table gives 0.002), and the estimate gives 0.966 (by differences 0.9742, 0.0001 above
    # this bound); the weighted fit of the same readings 0.992
    assert min(r2[n] for n in (12, 13, 14, 16)) >= target - 0.01, r2
    assert r2[15] >= target - 0.02, r2


def test_a_replay_warns_when_its_target_fit_explains_the_table_poorly():
    """With a sigma column the all-points fit is weighted by it but scored by R^2, which
    weighs every point alike: on a generated GGX surface with 1 % relative noise the target
    was R^2 >= 0.26, met by almost any campaign, and nothing said so."""
    from irreflect.campaign.replay import _reference_misfit
    from irreflect.fitting import fit

    table = _dielectric_table(alpha=0.07)
    table = table.subset(np.arange(table.n_points) % 3 == 0)
    sigma = np.sqrt((0.01 * np.abs(table.power)) ** 2 + 1e-4 ** 2)
    weighted = Measurements(gamma_deg=table.gamma_deg, theta_deg=table.theta_deg,
                            power=table.power, sigma=sigma, name="weighted")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        by_sigma, plain = fit(weighted, "two-lobe", seed=0), fit(table, "two-lobe", seed=0)
    assert by_sigma.r2 < 0.9 < plain.r2
    said = _reference_misfit(by_sigma, weighted)
    assert f"only to R^2 {by_sigma.r2:.4g}" in said and "weighted by the sigma column" in said
    assert _reference_misfit(plain, table) == ""


def test_a_campaign_whose_weighted_fit_cannot_beat_a_constant_fits_its_readings_equally():
    """A foreign material (a Lafortune lobe peaking off the mirror at grazing): from its
    14th reading the range-weighted fit could not beat a constant on the readings (the
    peak's four readings stand for a sliver of the range), and the campaign had no fit for
    the rest of its 25 readings, proposing opening readings and never stopping. The
    readings are then fitted equally weighted, and the campaign goes on."""
    from irreflect.synthetic import foreign_material

    dense = foreign_material(602).measurements
    curve, verdicts, _ = replay_adaptive(DenseInstrument(dense), n_max=16)
    assert sorted(curve.r2) == list(range(8, 17))
    assert all(np.isfinite(curve.r2[n]) for n in range(8, 17))
    assert not any("no usable fit" in " ".join(verdicts[n].reasons) for n in range(8, 17))
    assert max(curve.r2.values()) > 0.4  # all points: 0.52
    said = [n for n in verdicts if "fitted equally weighted" in verdicts[n].text]
    assert said and min(said) >= 14  # and the verdict says so


def test_the_verdict_dict_is_strict_json_before_any_reading():
    # r2_band and stability are NaN before a fit: to_dict held NaN (json allow_nan=False failed)
    v = Campaign(Instrument(gammas_deg=(-30,))).verdict()
    assert np.isnan(v.stability)
    d = json.loads(json.dumps(v.to_dict(), allow_nan=False))
    assert d["r2_low"] is None and d["r2_high"] is None and d["stability"] is None
    assert d["verdict"] == "continue" and d["n_measured"] == 0



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


def test_readings_of_zero_power_or_negative_noise_are_taken(tmp_path):
    # beyond the lobe of a glossy material whose share saturates a reading is 0, and a
    # lone reading of additive noise is as often below 0 as above: a whole table of either
    # would be refused, but they are a campaign's readings so far (a generated saturating
    # material and a noisy one stopped the benchmark's replays on them)
    from irreflect.data import validate_table

    tool = Instrument(gammas_deg=(-20, -40, -60))
    zeros = [(-60.0, 0.0, 0.0), (-40.0, -30.0, 0.0)]
    with pytest.raises(DataError, match="power is 0 in every row"):
        validate_table(pd.DataFrame(zeros, columns=["gamma_deg", "theta_deg", "power"]))
    campaign = Campaign(tool, zeros)
    campaign.add([(-20.0, 50.0, -0.02)])
    campaign.add([(-20.0, 20.0, 1e-120)])
    assert campaign.n_measured == 4 and campaign.fit is None
    assert "continue" in campaign.verdict().text
    assert len(campaign.propose(2)) == 2
    # the same through 'irreflect next'
    measured = tmp_path / "measured.csv"
    measured.write_text("gamma_deg,theta_deg,power\n-60,0,0\n-40,-30,-0.5\n")
    code, stdout, err = _run(["next", measured, "--n", "2", "--gammas", "-20", "-40", "-60"])
    assert code == 0, err
    assert "verdict: continue" in stdout
    # a whole table of them is still refused by the commands that fit it
    code, _, err = _run(["fit", measured])
    assert code != 0 and "power must be >= 0 up to noise" in err


def test_readings_negative_beyond_noise_are_refused_in_one_line(tmp_path):
    # a reading below -25 % of a larger positive one is a sign or offset error, as are
    # mostly negative readings; a lone negative reading with nothing larger is kept above
    from irreflect.data import validate_table

    cols = ["gamma_deg", "theta_deg", "power"]
    rows = [(-30.0, 30.0, 1.0), (-30.0, 0.0, 0.1), (-60.0, 60.0, 0.8), (-60.0, 0.0, -0.3)]
    with pytest.raises(DataError, match=r"found -0.3 .*beyond 25% of the largest reading"):
        validate_table(pd.DataFrame(rows, columns=cols), partial=True)
    rows[-1] = (-60.0, 0.0, -0.2)  # within 25 % of the peak: noise around a dark reading
    assert validate_table(pd.DataFrame(rows, columns=cols), partial=True).n_points == 4
    flipped = [(g, t, -p) for g, t, p in rows]
    with pytest.raises(DataError, match="3 of the 4 nonzero readings are negative"):
        validate_table(pd.DataFrame(flipped, columns=cols), partial=True)
    measured = tmp_path / "measured.csv"
    pd.DataFrame(flipped, columns=cols).to_csv(measured, index=False)
    code, stdout, err = _run(["next", measured, "--gammas", "-30", "-60"])
    assert code == 2 and stdout == "" and err.count("\n") == 1
    assert "nonzero readings are negative" in err
    # a specular peak typed with its sign flipped: below every positive reading, so no
    # larger one stands beside it, but 8 times the typical reading: refused too
    peaks = [(-30.0, 30.0, 0.8), (-30.0, 0.0, 0.1), (-30.0, -40.0, 0.08), (-60.0, 0.0, 0.12),
             (-60.0, -30.0, 0.09), (-45.0, 10.0, 0.11), (-45.0, 45.0, -0.9)]
    with pytest.raises(DataError, match=r"found -0.9 .*beyond 25% of the largest reading"):
        validate_table(pd.DataFrame(peaks, columns=cols), partial=True)
    peaks[-1] = (-45.0, 45.0, 0.9)
    assert validate_table(pd.DataFrame(peaks, columns=cols), partial=True).n_points == 7


def test_a_known_noise_floor_keeps_the_first_noisy_readings_of_a_replay():
    # a mirror-like material with additive detector noise (bench_campaign.py wild-710): its
    # first readings off the unresolved peak are mostly noise, 3 of 5 below zero and one
    # at -2.2e6 against a largest reading of 2.5e6. Without a noise floor the campaign
    # took them for a sign error and the replay stopped at its 5th reading
    from irreflect.data import validate_table
    from irreflect.synthetic import wild_material

    cols = ["gamma_deg", "theta_deg", "power"]
    rows = [(-30.0, 30.0, 2.5e6), (-60.0, 60.0, -2.2e6), (-45.0, 45.0, -1.0e6),
            (-30.0, -20.0, 3.0e5), (-60.0, 0.0, -4.0e5)]
    with pytest.raises(DataError, match="3 of the 5 nonzero readings are negative"):
        validate_table(pd.DataFrame(rows, columns=cols), partial=True)
    with pytest.raises(DataError, match="give the readings' noise"):
        validate_table(pd.DataFrame(rows[:2], columns=cols), partial=True)
    kept = validate_table(pd.DataFrame(rows, columns=cols), partial=True, noise_floor=3e6)
    assert kept.n_points == 5
    # beyond the floor: still a sign error
    with pytest.raises(DataError, match="beyond 25% of the largest reading"):
        validate_table(pd.DataFrame(rows, columns=cols), partial=True, noise_floor=2e6)
    with pytest.raises(IrreflectError, match="noise_floor"):
        Campaign(Instrument(gammas_deg=(-30, -60)), noise_floor=-1.0)
    dense = wild_material(710).measurements
    assert float(np.min(dense.power)) < -2e6  # the table's own noise, which it accepts
    curve, verdicts, _ = replay_adaptive(DenseInstrument(dense), n_max=10)
    # all 10 readings taken (whether 9 or 10 mostly-noise readings and one peak of 1.1e7
    # give a fit that beats a constant is the fit's business, and it says so)
    assert max(verdicts) == 10 and len(curve.points) == 10 and curve.r2


def test_a_coarse_receiver_step_says_the_mirror_is_not_reached(tmp_path):
    measured = tmp_path / "measured.csv"
    measured.write_text("gamma_deg,theta_deg,power\n")
    code, stdout, err = _run(["next", measured, "--n", "8", "--theta-step", "20"])
    assert code == 0, err
    # the default gammas -10..-70: on a 20-deg grid the mirrors of -10, -30, -50, -70 are
    # 10 deg from the nearest setting
    assert "10 deg from it at gamma -10, -30, -50, -70" in err
    labels = [line for line in stdout.splitlines() if "design: mirror direction" in line]
    assert labels and all("the setting nearest it, 10 deg" in line or
                          "the specular peak" in line for line in labels)
    assert any("gamma     -10  theta        0" in line and "nearest it" in line
               for line in labels)
    # the lobe probes stand 1.5 steps (30 deg) out: named the flank, not the lobe's body
    probes = [line for line in stdout.splitlines() if "starts bracketing" in line]
    assert len(probes) == 2 and all("the specular lobe's flank, 30 deg from the mirror" in line
                                    for line in probes)
    code, stdout, err = _run(["next", measured, "--n", "8", "--theta-step", "1"])
    assert code == 0 and "nearest setting to the specular peak" not in err
    assert "the setting nearest it" not in stdout
    assert stdout.count("the specular lobe's body, 1 deg from the mirror") == 1


@pytest.mark.parametrize("step", ["2.5", "5", "1"])
def test_a_mirror_within_the_source_clearance_is_blamed_on_it_whatever_the_step(tmp_path,
                                                                                step):
    # at gamma 0 the mirror is the source direction: a step of 2.5 deg was told "a
    # --theta-step of 2 deg or less near the mirror reaches it", which no step does
    measured = tmp_path / "measured.csv"
    measured.write_text("gamma_deg,theta_deg,power\n")
    code, stdout, err = _run(["next", measured, "--gammas", "0", "-30", "-60",
                              "--theta-min=-80", "--theta-max", "80", "--theta-step", step])
    assert code == 0, err
    assert ("the specular peak (theta = -gamma) cannot be measured at gamma 0 deg (within 5 "
            "deg of the source direction, --source-clearance)") in err
    assert "--theta-step of 2 deg or less" not in err
    label = next(line for line in stdout.splitlines() if "design: mirror direction" in line
                 and line.split()[1] == "0")
    assert "receiver's step" not in label
    tool = Instrument(gammas_deg=(0, -30, -60), theta_min=-80, theta_max=80, theta_step=2.5)
    assert [tool.mirror_blocked(g) for g in (0.0, -2.0, -30.0)] == ["source", "source", None]
    assert Instrument(gammas_deg=(-70,), theta_min=-80, theta_max=60).mirror_blocked(
        -70) == "range"


def test_next_notes_readings_the_instrument_cannot_take(tmp_path):
    measured = tmp_path / "measured.csv"
    rows = [(g, t, 1.0 + 0.01 * abs(t)) for g in (-20.0, -40.0) for t in (-50.0, 0.0, 30.0)]
    pd.DataFrame(rows, columns=["gamma_deg", "theta_deg", "power"]).to_csv(measured,
                                                                          index=False)
    code, _, err = _run(["next", measured, "--gammas", "-20", "-40", "--theta-min", "-40",
                         "--theta-max", "40", "--gamma-settings", "1"])
    assert code == 0, err
    assert "2 reading(s) at theta beyond the receiver range -40..40 deg" in err
    assert "already use 2 angles of incidence, more than max_gamma_settings (--gamma-settings) 1" in err
    code, _, err = _run(["next", measured, "--gammas", "-20", "-40"])
    assert code == 0 and "beyond the receiver range" not in err and "already use" not in err


def test_a_separation_wider_than_the_receiver_range_is_refused():
    with pytest.raises(IrreflectError, match=r"min_separation .* 200 deg is wider than the "
                                             r"receiver's range \(-60..60 deg, 120 deg\)"):
        Instrument(gammas_deg=(-30,), theta_min=-60, theta_max=60, min_separation=200)
    assert Instrument(gammas_deg=(-30,), theta_min=-60, theta_max=60,
                      min_separation=120).min_separation == 120


def test_an_interpolated_replay_warns_of_a_table_with_no_reading_near_the_mirror():
    # readings every 5 deg, but none within 15 deg of the mirror at -20 and -60: the
    # interpolation along theta reaches every setting, but the specular peak there is the
    # interpolation's, not a measurement
    rows = [(g, t, 1.0 + 0.01 * t) for g in (-20.0, -40.0, -60.0)
            for t in np.arange(-80.0, 81.0, 5.0) if g == -40.0 or abs(t + g) > 15.0]
    dense = Measurements(*map(np.array, zip(*rows, strict=True)), name="sparse")
    for method in ("interpolate", "nearest"):
        warning = DenseInstrument(dense, method=method).mirror_gaps()
        assert "at gamma -20, -60 deg" in warning, (method, warning)
    full = _material(GLOSSY, step=2.0)
    assert DenseInstrument(full, method="interpolate").mirror_gaps() == ""


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
    code, stdout, err = _run(["next", measured, "--n", "2", "--gammas", "-20,-40", "-60",
                              "--json"])  # comma- or space-separated alike
    assert code == 0, err
    doc = json.loads(stdout)
    assert doc["n_measured"] == 8 and len(doc["proposals"]) == 2
    assert doc["verdict"]["verdict"] == "continue" and doc["verdict"]["stop"] is False
    assert "at least 10 readings before stopping" in doc["verdict"]["reasons"]


def test_next_refuses_readings_in_the_mirrored_frame_and_reads_a_campaigns_own(tmp_path):
    """Readings with gamma >= 0 peaking at theta = -gamma (the paper's frame mirrored) were
    read by `next` as magnitudes, so the lobe stood on the wrong side (predicted R^2 down to
    -1, "1.66e+12 times the largest reading"): refused in one line, as `fit`'s detection
    finds them. A campaign's own readings (its opening, 8-13 of them, or a scan) in the
    paper's frame or as magnitudes are read as before, theta kept."""
    from irreflect.campaign.io import read_readings

    g = np.repeat([-10.0, -30.0, -50.0, -70.0], 33)
    t = np.tile(np.arange(-80.0, 81.0, 5.0), 4)
    keep = np.abs(t - g) >= 5.0
    scan = _answer(GLOSSY, np.random.default_rng(0))(
        pd.DataFrame({"gamma_deg": g[keep], "theta_deg": t[keep]}))
    mirrored = tmp_path / "mirrored.csv"
    scan.assign(gamma_deg=-scan.gamma_deg, theta_deg=-scan.theta_deg).to_csv(mirrored,
                                                                            index=False)
    code, stdout, err = _run(["next", mirrored, "--n", "2", "--out", tmp_path / "n.csv"])
    assert code == 2 and stdout == "" and err.count("\n") == 1, err
    assert err.startswith("irreflect: error: ") and "the paper's frame mirrored" in err
    assert "change the sign of both gamma_deg and theta_deg" in err
    assert not (tmp_path / "n.csv").exists()
    with pytest.warns(DataNotice, match="paper's frame mirrored"):  # fit turns it
        assert np.array_equal(read_measurements(mirrored).theta_deg, scan.theta_deg)
    opening = _answer(GLOSSY, np.random.default_rng(1))(
        Campaign(Instrument(gammas_deg=(-10, -20, -30, -40, -50, -60, -70))).propose(13)[["gamma_deg", "theta_deg"]])
    for n, table in [(n, opening.iloc[:n]) for n in range(8, 14)] + [(len(scan), scan)]:
        for frame in (table, table.assign(gamma_deg=table.gamma_deg.abs())):
            path = tmp_path / f"readings{n}.csv"
            frame.to_csv(path, index=False)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                read = read_readings(path)
            assert np.array_equal(read.theta_deg, table.theta_deg), n
            assert np.array_equal(read.gamma_deg, table.gamma_deg), n


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


def test_next_saves_the_campaign_fit_as_a_material_file(tmp_path):
    measured = tmp_path / "measured.csv"
    measured.write_text("gamma_deg,theta_deg,power\n")
    material = tmp_path / "material.json"
    args = ["--gammas", "-20", "-40", "-60", "--theta-min", "-70", "--theta-max", "70"]
    # nothing fitted yet: one line, exit 2, no file
    code, _, err = _run(["next", measured, *args, "--save", material])
    assert code == 2 and err.count("\n") == 1 and "first fit needs 8" in err, err
    assert not material.exists()
    # 10 readings of the glossy material: the campaign's fit is written
    tool = Instrument(gammas_deg=(-20, -40, -60), theta_min=-70, theta_max=70)
    rows = pd.DataFrame(opening_design(tool, 10), columns=["gamma_deg", "theta_deg", "why"])
    rows["power"] = two_lobe_power(np.radians(rows["gamma_deg"]), np.radians(rows["theta_deg"]),
                                   *GLOSSY)
    rows[["gamma_deg", "theta_deg", "power"]].to_csv(measured, index=False)
    code, stdout, err = _run(["next", measured, *args, "--save", material])
    assert code == 0, err
    assert "wrote" in stdout and "campaign's fit of 10 readings" in stdout
    saved = json.loads(material.read_text())
    assert saved["format"] == "irreflect-material" and "verdict" in saved
    campaign = Campaign(tool, measured, seed=0)
    assert np.allclose(list(saved["params"].values()), campaign.fit.values)
    # its notes say which fit it is
    said = "quadrature estimate" if campaign.estimated else "readings weighted by the share"
    assert said in json.dumps(saved)
    # never onto the input
    code, _, err = _run(["next", measured, *args, "--save", measured])
    assert code == 2 and "input" in err


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


#: a glossy material whose specular share u_as cos^v_as reaches 1 near 50 deg (the draw of
#: experiments/bench_campaign.py saturating-108, with its angles and noise)
SATURATING = np.array([0.2556, -4.958, 1.2825, -0.8777, 60.50, -0.5597, 0.1508])


def _saturating_table():
    """A dense scan of :data:`SATURATING` on the generated table's nine angles of
    incidence."""
    rng = np.random.default_rng(108)
    g, t = [], []
    for gamma in (0.0, -17.65, -27.44, -29.65, -36.88, -47.49, -48.1, -51.11, -74.08):
        th = np.unique(np.r_[np.arange(-85.0, 85.01, 1.0), -gamma + np.arange(-3, 3.01, 0.5)])
        th = th[np.abs(th) <= 85.0]
        g.append(np.full(th.size, gamma))
        t.append(th)
    g, t = np.concatenate(g), np.concatenate(t)
    clean = two_lobe_power(np.radians(g), np.radians(t), *SATURATING)
    return Measurements(gamma_deg=g, theta_deg=t,
                        power=clean * (1 + 0.0106 * rng.standard_normal(g.size)),
                        name="saturating")


def _campaign_until_stop(source, rule=None, n_max=20, tool=None):
    from irreflect.campaign import DesignRule

    campaign = Campaign(tool or source.instrument(), seed=0, rule=rule or DesignRule())
    whys = []
    for _ in range(n_max):
        proposal = campaign.propose(1)
        whys.append(str(proposal["why"].iloc[0]))
        power = source.read(proposal["gamma_deg"], proposal["theta_deg"],
                            np.random.default_rng(0))
        campaign.add(proposal[["gamma_deg", "theta_deg"]].assign(power=power))
        if campaign.verdict().stop:
            break
    return campaign, whys


def test_a_saturating_share_is_not_left_to_interpolation_over_a_wide_gap():
    """Three angles of incidence (0, 37, 74 deg) with the share saturated at 74: the fit
    may settle on a wrong share law that no reading at those angles moves. On an
    instrument that can set an angle in between, the verdict does not stop while the gap
    is open, and the next reading fills it."""
    import irreflect
    from irreflect.campaign import DesignRule

    dense = _saturating_table()
    reference = irreflect.fit(dense, seed=0).r2
    # readings at the three angles only (a campaign on an instrument that sets those)
    three = DenseInstrument(dense.subset(np.isin(dense.gamma_deg, (0.0, -36.88, -74.08))))
    held, _ = _campaign_until_stop(three, n_max=14)
    assert set(held.measurements.gamma_deg) == {0.0, -36.88, -74.08}
    assert held.verdict().stop  # the curve holds there
    full_tool = DenseInstrument(dense).instrument()
    full = Campaign(full_tool, held.measurements.to_frame(), seed=0)
    verdict = full.verdict()
    assert not verdict.stop
    assert verdict.reasons == ("the specular share saturates and |gamma| 36.88-74.08 deg is "
                               "not measured (the instrument sets 51.11): the share's law is "
                               "interpolated over it",)
    why = full.propose(1)["why"].iloc[0]
    assert "a new angle of incidence in the gap |gamma| 36.88-74.08 deg" in why
    # without the check the verdict stops on the same readings
    loose = Campaign(full_tool, held.measurements.to_frame(), seed=0,
                     rule=DesignRule(saturated_gap=0))
    assert loose.verdict().stop
    # the whole campaign on the full instrument fills the gap by its own design (its prior
    # sees the saturated share since stop 33) and stops on a good fit
    campaign, whys = _campaign_until_stop(DenseInstrument(dense))
    assert [x for x in campaign.measurements.gamma_deg if 36.9 < abs(x) < 74.0]
    assert campaign.verdict().stop and campaign.n_measured <= 16
    assert campaign.r2_against(dense) >= reference - 0.01


@pytest.mark.parametrize("knob,value", [("saturated_gap", -5.0), ("power_weights", 2.0),
                                        ("power_cap", float("nan")), ("range_weights", -1.0)])
def test_design_rule_refuses_a_knob_out_of_its_range(knob, value):
    from irreflect.campaign import DesignRule

    with pytest.raises(IrreflectError, match=knob):
        DesignRule(**{knob: value})
    assert getattr(DesignRule(**{knob: 0.0}), knob) == 0.0


@pytest.mark.parametrize("knob,value", [("lobe_factors", (0.1, -10.0)),
                                        ("diffuse_factors", (0.0,)),
                                        ("law_sd", {"u_as": float("inf")})])
def test_design_rule_refuses_a_bad_entry_of_its_tuple_and_table_knobs(knob, value):
    from irreflect.campaign import DesignRule

    with pytest.raises(IrreflectError, match=knob):
        DesignRule(**{knob: value})


def test_diffuse_factors_bracket_the_diffuse_lobe_as_lobe_factors_do_the_specular_one():
    from irreflect.campaign import DesignRule
    from irreflect.campaign.design import build_prior
    from irreflect.fitting import fit
    from irreflect.models import get_model

    model = get_model("two-lobe")
    rule_off = DesignRule(lobe_factors=())
    rule_on = DesignRule(lobe_factors=(), diffuse_factors=(0.5, 2.0))
    spread = {}
    for name, params in (("matte", MATTE), ("glossy", GLOSSY)):
        meas = _material(params, step=10.0)
        few = meas.subset(np.arange(meas.n_points) % 9 == 0)  # 13 readings
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = fit(few, model)
        g, t = meas.gamma_deg, meas.theta_deg
        off = build_prior(model, res, few, g, t, rule_off)
        on = build_prior(model, res, few, g, t, rule_on)
        assert on.features.shape[1] == off.features.shape[1] + 2
        assert np.all(np.isfinite(on.features))
        spread[name] = np.max(np.abs(on.features[: len(g), -2:]), axis=0) / np.max(meas.power)
    # the matte readings pin the diffuse index down: a lobe half or twice as wide no longer
    # explains them and carries no weight; the glossy readings leave it open
    assert np.all(spread["matte"] < 1e-6)
    assert np.all(spread["glossy"] > 1e-2)


def test_the_protocols_are_replayed_with_the_instruments_errors():
    # the paper's protocol read from a noisy instrument is scored on noisy readings, as
    # the adaptive campaign's are (it was read noiseless before stop 33)
    dense = _material(MATTE, step=2.0, noise=0.0)
    clean = replay(dense, ("paper",), n_max=10)
    noisy = replay(dense, ("paper",), n_max=10, noise=0.2, seed=1)
    again = replay(dense, ("paper",), n_max=10, noise=0.2, seed=1)
    r_clean = clean.curves["paper"].r2[12]
    r_noisy = noisy.curves["paper"].r2[12]
    assert r_clean > 0.999  # the model's own material, read exactly
    assert r_noisy < r_clean - 0.002
    assert again.curves["paper"].r2[12] == r_noisy  # seeded
    shifted = replay(dense, ("paper",), n_max=10, angle_error_deg=3.0, seed=1)
    assert shifted.curves["paper"].r2[12] != r_clean
    # the replay's dict is strict JSON: a score that could not be made is null, not NaN
    clean.curves["paper"].r2[13] = float("nan")
    d = json.loads(json.dumps(clean.to_dict(), allow_nan=False))
    assert d["curves"]["paper"]["r2"]["12"] == pytest.approx(r_clean)
    assert d["curves"]["paper"]["r2"]["13"] is None


@pytest.mark.real
def test_an_interpolated_table_whose_own_fit_misses_the_target_is_warned(real_dir):
    """Cornell Krylon, interpolated every 2 deg: the model fitted to all 539 settings the
    instrument answers scores 0.9706 against the table's points (target 0.9716), and the
    adaptive campaign never held the target while the paper's 12 points did: the replay
    says the interpolation limits it. The lobe is broad enough for coarse_peaks to stay
    silent; read as the table's own points, or on PTFE (0.9950 against 0.9951), no word."""
    krylon = read_measurements(real_dir / "cornell" / "cornell_krylon_blue.csv")
    said = replay(krylon, ("paper",), method="interpolate", theta_step=2.0).warnings
    limit = [w for w in said if "learns the interpolation" in w]
    assert len(limit) == 1 and "539 settings" in limit[0], said
    r2 = float(limit[0].split("scores R^2 ")[1].split()[0])
    assert 0.96 < r2 < 0.9716
    assert DenseInstrument(krylon, method="interpolate", theta_step=2.0).coarse_peaks() == ""
    assert not any("learns the interpolation" in w for w in replay(krylon, ("paper",)).warnings)
    ptfe = read_measurements(real_dir / "ptfe_nist" / "ptfe_sintered_1064nm.csv")
    assert not any("learns the interpolation" in w
                   for w in replay(ptfe, ("paper",), method="interpolate").warnings)


def test_interpolating_a_lobe_the_table_does_not_resolve_is_warned(tmp_path):
    coarse = _material(GLOSSY, step=8.0, name="coarse")
    fine = _material(GLOSSY, step=0.5, name="fine")
    assert "replay with --method nearest" in DenseInstrument(
        coarse, method="interpolate", theta_step=1.0).coarse_peaks()
    assert DenseInstrument(coarse).coarse_peaks() == ""  # the table's own points
    assert DenseInstrument(fine, method="interpolate", theta_step=1.0).coarse_peaks() == ""
    matte = _material(MATTE, step=8.0, name="matte")  # a broad lobe interpolates fine
    assert DenseInstrument(matte, method="interpolate", theta_step=1.0).coarse_peaks() == ""
    path = tmp_path / "coarse.csv"
    coarse.to_frame().to_csv(path, index=False)
    code, out, err = _run(["campaign", path, "--strategies", "paper", "--method",
                           "interpolate"])
    assert code == 0 and "irreflect: warning: coarse: its readings next to the specular" in err


def test_a_stop_on_a_model_that_misfits_its_readings_says_so():
    # a Lafortune material (a sharp forward lobe that drifts off the mirror, a broad one
    # leaning back) that no two-lobe fit describes (R^2 0.77 on all points at best): the
    # campaign's fit settles at the bounds of its coefficients and explains its own
    # readings poorly; its stop must not read as a good material file
    from irreflect.synthetic import foreign_material

    table = foreign_material(107)
    assert table.model == "lafortune"
    source = DenseInstrument(table.measurements)
    # (the reported estimate keeps moving between two optima until 24 readings: stop 40)
    curve, verdicts, _ = replay_adaptive(source, 25, seed=0)
    stop = min(n for n, v in verdicts.items() if v.stop)
    verdict = verdicts[stop]
    assert curve.r2[stop] < 0.7  # far below the model's best, 0.77: what the text must flag
    assert "the model explains the readings only to R^2" in verdict.text
    assert "irreflect diagnose" in verdict.text
    assert verdict.at_bound and "at a bound of its range: " in verdict.text
    # (a material the model describes stops without it:
    # test_the_verdict_continues_until_the_curve_holds_then_stops)


def test_a_generated_foreign_table_stays_within_the_power_a_table_may_hold():
    # a Lafortune lobe with |C_x| > 1 and an exponent near 1e4 reached 2e191 (seed 602):
    # no table loader accepts it (data.POWER_RANGE) and the benchmark's fit failed with
    # 'no start reached a finite cost'; its peak is now set to 1
    from irreflect.data import POWER_RANGE, validate_table
    from irreflect.synthetic import foreign_material

    table = foreign_material(602)
    assert table.model == "lafortune"
    assert 0.5 < float(np.max(table.measurements.power)) < 2.0
    frame = table.measurements.to_frame()
    assert validate_table(frame, "602").n_points == len(frame)
    assert POWER_RANGE[0] < float(np.max(foreign_material(107).measurements.power)) < 1e6


def test_a_replayed_r2_far_below_zero_is_printed_in_exponent_form():
    from irreflect.cli.campaign import _r2

    assert (_r2(0.98765), _r2(-1349228816089424128.0), _r2(-51500.0)) == (
        "0.9877", "-1.35e+18", "-5.15e+04")


def test_next_notes_readings_at_angles_the_instrument_does_not_list(tmp_path):
    measured = tmp_path / "m.csv"
    g = np.repeat([-20.0, -40.0, -60.0], 4)
    t = np.tile([-30.0, 0.0, 25.0, 50.0], 3)
    pd.DataFrame({"gamma_deg": g, "theta_deg": t, "power": two_lobe_power(
        np.radians(g), np.radians(t), *GLOSSY)}).to_csv(measured, index=False)
    code, _, err = _run(["next", measured, "--gammas", "20,40", "--json"])
    assert code == 0 and ("note: readings at gamma -60 deg, which the instrument does not list "
                          "(gammas_deg, --gammas)") in err and err.count("gamma -60 deg") == 1
    code, stdout, err = _run(["next", measured, "--gammas", "20,40,60", "--json"])
    assert code == 0 and "note" not in err and json.loads(stdout)["notes"] == []


def test_a_dense_table_without_the_specular_peak_is_warned(tmp_path):
    # a scan that skipped the mirror direction at gamma -40 (no reading within 10 deg of
    # theta = 40): every strategy extrapolates the peak there, and nothing scores it
    full = _material(GLOSSY, step=2.0)
    assert DenseInstrument(full).mirror_gaps() == ""
    keep = ~((full.gamma_deg == -40.0) & (np.abs(full.theta_deg - 40.0) < 10.0))
    gap = full.subset(keep)
    text = DenseInstrument(gap).mirror_gaps()
    assert "at gamma -40 deg: every strategy's fit extrapolates the peak" in text, text
    assert "-10," not in text and "-70" not in text  # the other rows have their peaks
    path = tmp_path / "gap.csv"
    gap.to_frame().to_csv(path, index=False)
    code, out, err = _run(["campaign", path, "--strategies", "paper"])
    assert code == 0 and "irreflect: warning: the table has no reading within 4 deg" in err


@pytest.mark.parametrize("strategies, warned", [("paper", True), ("adaptive,paper", True),
                                                ("paper,hindsight", False)])
def test_campaign_generations_without_hindsight_is_warned_of(strategies, warned, tmp_path):
    # --generations sets only the hindsight subsets' search; without that strategy it was
    # ignored without a word (the table is missing: refused right after the options)
    code, _, err = _run(["campaign", tmp_path / "missing.csv", "--generations", "7",
                         "--strategies", strategies])
    assert code == 2
    assert ("irreflect: warning: --generations has no effect" in err) is warned, err


@pytest.mark.parametrize("method, warned", [(None, True), ("interpolate", False)])
def test_campaign_theta_step_with_the_nearest_method_is_warned_of(method, warned, tmp_path):
    # --theta-step only sets the interpolated readings' grid: with the nearest method (the
    # default) it was refused as an error, where every other option that does nothing is
    # warned of (docs/bad-input.md)
    path = tmp_path / "glossy.csv"
    _material(GLOSSY, step=2.0).to_frame().to_csv(path, index=False)
    extra = [] if method is None else ["--method", method]
    code, out, err = _run(["campaign", path, "--strategies", "paper", "--theta-step", "2",
                           *extra])
    assert code == 0, err
    assert ("irreflect: warning: --theta-step 2 has no effect" in err) is warned, err
    assert "paper" in out


def test_the_receivers_resolution_spaces_the_readings_and_flags_a_lobe_it_cannot_resolve(
        tmp_path):
    # a receiver that averages over 4 deg: readings at least 2 deg apart, the opening's lobe
    # probes 4 deg from the mirror, and the glossy lobe (full width at half maximum about
    # 3 deg) is flagged once it is fitted; a 2-deg receiver resolves it
    kw = dict(gammas_deg=(-10, -40, -70), theta_min=-80, theta_max=80, theta_step=0.5)
    coarse, fine, point = (Instrument(**kw, resolution=4.0), Instrument(**kw, resolution=2.0),
                           Instrument(**kw))
    assert coarse.min_separation == 2.0 and point.min_separation == 0.25
    assert "resolution 4 deg" in coarse.describe() and "resolution" not in point.describe()
    probes = [(g, t) for g, t, why in opening_design(coarse, 8) if "lobe's body" in why]
    assert len(probes) == 2 and all(abs(abs(g + t) - 4.0) < 1e-9 for g, t in probes)
    probes = [(g, t) for g, t, why in opening_design(point, 8) if "lobe's body" in why]
    assert all(abs(abs(g + t) - 1.0) < 1e-9 for g, t in probes)
    texts = {}
    for name, tool in (("coarse", coarse), ("fine", fine), ("point", point)):
        readings = _receiver_readings(GLOSSY, tool.resolution)
        c = Campaign(tool, readings)
        assert c.fit is not None and c.fit.r2 > 0.999
        texts[name] = c.unresolved_lobe()
    assert texts["coarse"].startswith("the fitted specular lobe is narrower than the "
                                      "receiver resolves at gamma -10, -40, -70 deg")
    assert "against a resolution of 4 deg" in texts["coarse"]
    assert texts["fine"] == "" and texts["point"] == ""
    readings = _receiver_readings(GLOSSY, 4.0)
    path = tmp_path / "readings.csv"
    readings.to_csv(path, index=False)
    code, out, err = _run(["next", path, "--gammas", "10,40,70",
                           "--theta-step", "0.5", "--resolution", "4", "--json"])
    assert code == 0, err
    doc = json.loads(out)
    assert "resolution 4 deg" in doc["instrument"]
    assert any(w.startswith("the fitted specular lobe is narrower") for w in doc["warnings"])
    taken = np.column_stack([readings["gamma_deg"], readings["theta_deg"]])
    for p in doc["proposals"]:  # no proposal within half the resolution of a reading
        same = np.abs(taken[:, 0] - p["gamma_deg"]) < 1e-9
        assert np.min(np.abs(taken[same, 1] - p["theta_deg"]), initial=99.0) >= 2.0 - 1e-9


def test_readings_of_a_wide_receiver_are_fitted_as_its_average_and_give_the_material():
    # a 4-deg receiver blurs the glossy lobe (full width about 3 deg): fitted as point
    # readings, the lobe comes out about twice as wide and a third too weak; the campaign fits
    # them as the model averaged over the receiver and recovers the material's coefficients
    from irreflect.fitting import fit as plain_fit

    readings = _receiver_readings(GLOSSY, 4.0)
    tool = Instrument(gammas_deg=(-10, -40, -70), theta_min=-80, theta_max=80,
                      theta_step=0.5, resolution=4.0)
    got = Campaign(tool, readings).fit.values
    assert np.allclose(got, GLOSSY, rtol=2e-3), got
    point = plain_fit(Measurements(gamma_deg=readings["gamma_deg"].to_numpy(),
                                   theta_deg=readings["theta_deg"].to_numpy(),
                                   power=readings["power"].to_numpy())).values
    assert point[4] < 0.7 * GLOSSY[4] and point[6] < 0.8 * GLOSSY[6]  # u_ns and K


def test_fit_takes_the_receivers_resolution_as_next_does(tmp_path):
    # `irreflect fit --resolution` and `next --resolution` answer alike on a wide receiver's
    # readings; without it, fit gives the blurred lobe; the material file says how
    path = tmp_path / "wide.csv"
    _receiver_readings(GLOSSY, 4.0).to_csv(path, index=False)
    code, out, err = _run(["fit", path, "--resolution", "4", "--json",
                           "--save", tmp_path / "m.json"])
    assert code == 0, err
    # the lobe (full width about 3 deg) is narrower than the 4-deg receiver: said, as next does
    assert "the fitted specular lobe is narrower than the receiver resolves" in err
    params = json.loads(out)["params"]
    assert params["u_ns"] == pytest.approx(GLOSSY[4], rel=2e-3)
    assert params["K"] == pytest.approx(GLOSSY[6], rel=2e-3)
    saved = json.loads((tmp_path / "m.json").read_text())
    assert saved["model"] == "two-lobe" and "averaged over the receiver's 4 deg" in saved["notes"]
    code, out, _ = _run(["fit", path, "--json"])
    assert code == 0 and json.loads(out)["params"]["u_ns"] < 0.7 * GLOSSY[4]
    code, _, err = _run(["fit", path, "--resolution", "95", "--save", tmp_path / "x.json"])
    assert code != 0 and "resolution (--resolution, deg) must be" in err
    assert not (tmp_path / "x.json").exists()
    code, _, err = _run(["fit", path, "--model", "phong@10", "--resolution", "4"])
    assert code != 0 and "drop '@G' or --resolution" in err and "\n" not in err.strip()


def test_fit_averaged_of_one_angle_of_incidence_says_what_to_call():
    """fit_averaged(m, 'phong@10') said 'give it where a fit is made (irreflect fit,
    compare)', naming commands to an API caller already making a fit: at width 0 it is the
    plain fit that fit_averaged documents; wider, the error names the calls that work."""
    from irreflect.data import load_bundled
    from irreflect.fitting import fit, fit_averaged, points_at_incidence
    from irreflect.models import get_model

    meas = load_bundled("terrazzo")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        point = fit_averaged(meas, "phong@10")
        plain = fit(meas, "phong@10")
        assert point.model == "phong@10" and point.n_points == plain.n_points < meas.n_points
        np.testing.assert_array_equal(point.values, plain.values)
        with pytest.raises(IrreflectError, match=(
                r"^fit_averaged: model 'phong@10' with width_deg 2: '@10' fits the readings of "
                r"one angle of incidence as points, not averaged over a receiver: call "
                r"fit\(measurements, 'phong@10'\) for that fit, or fit_averaged\("
                r"points_at_incidence\(measurements, 10\), 'phong', 2\) to fit those readings "
                r"averaged$")):
            fit_averaged(meas, "phong@10", 2.0)
        # the call the message names works
        averaged = fit_averaged(points_at_incidence(meas, 10), "phong", 2.0)
        assert averaged.model == "phong" and averaged.n_points == plain.n_points
    with pytest.raises(IrreflectError, match=r"resolution \(--resolution, deg\) must be"):
        fit_averaged(meas, "phong@10", -1.0)  # the width is checked first, as without '@'
    with pytest.raises(IrreflectError, match=r"in Python fit\(data, 'phong@10'\)\), or the "
                       r"model alone \('phong'\)$"):
        get_model("phong@10")


def _receiver_readings(params, width):
    """Readings of a two-lobe material by a receiver ``width`` deg wide (0: a point): every
    degree within 6 deg of each mirror and 9 receiver angles across -80..80 deg, at gamma
    -10, -40 and -70."""
    rows = []
    for gam in (-10.0, -40.0, -70.0):
        th = np.unique(np.r_[-gam + np.arange(-6.0, 6.5, 1.0), np.linspace(-80, 80, 9)])
        th = th[np.abs(th) <= 80]
        rows.append(pd.DataFrame({"gamma_deg": gam, "theta_deg": th}))
    table = pd.concat(rows, ignore_index=True)
    g, t = np.radians(table["gamma_deg"].to_numpy()), table["theta_deg"].to_numpy()
    if width:
        x, w = np.polynomial.legendre.leggauss(41)
        table["power"] = sum(0.5 * wi * two_lobe_power(g, np.radians(t + 0.5 * width * xi),
                                                       *params)
                             for xi, wi in zip(x, w, strict=True))
    else:
        table["power"] = two_lobe_power(g, np.radians(t), *params)
    return table


def test_readings_at_one_angle_of_incidence_leave_the_laws_in_gamma_ill_determined():
    """Noise-free readings at one gamma cannot separate u from v in u cos^v(gamma): the
    weighted fit flags a near-singular covariance, and the campaign's fit (its errors
    rescaled by residuals of 1e-10) once dropped the flags and called itself trustworthy."""
    tool = Instrument(gammas_deg=(-30,), theta_min=-80, theta_max=80)
    params = np.array([0.3, -0.5, 1.2, 0.3, 40.0, 0.4, 1.0])
    campaign = Campaign(tool, seed=0)
    for k in (8, 2):  # the opening, then two proposals from the first fit
        s = campaign.propose(k)
        power = two_lobe_power(np.radians(s.gamma_deg.to_numpy()),
                               np.radians(s.theta_deg.to_numpy()), *params)
        campaign.add(s[["gamma_deg", "theta_deg"]].assign(power=power))
    fit = campaign.fit
    assert fit.rmse < 1e-6  # the readings are explained exactly ...
    assert {"v_as", "v_nd", "v_ns"} <= set(fit.ill_determined)  # ... the laws are not
    assert not fit.verdict().trustworthy


def test_instruments_and_campaigns_that_cannot_work_are_refused_in_one_line():
    # a resolution wider than the receiver's range leaves 4 distinct readings: the campaign
    # proposed nothing and said "continue" for ever
    tool = Instrument(gammas_deg=(-30, -50), theta_min=20, theta_max=40, resolution=30)
    assert tool.capacity() == 4
    with pytest.raises(IrreflectError, match=r"at most 4 distinct reading\(s\) .*fewer than "
                                             r"the 8 a first fit of 'two-lobe' needs"):
        Campaign(tool)
    wide = Instrument(gammas_deg=(-30, -50))  # every 1-deg setting is a distinct reading
    assert wide.capacity() == len(wide.settings()) == 324
    for bad, words in ((float("nan"), "stop_tolerance must be a finite number > 0"),
                       (-1, "stop_tolerance must be"), ("x", "stop_tolerance must be")):
        with pytest.raises(IrreflectError, match=words):
            Campaign(wide, stop_tolerance=bad)
    with pytest.raises(IrreflectError, match="rule must be a DesignRule"):
        Campaign(wide, rule=None)
    with pytest.raises(IrreflectError, match=r"shape \(n, 2\) .*found shape \(1, 3\)"):
        Instrument(gammas_deg=(-30,), settings_deg=[[1, 2, 3]])
    with pytest.raises(IrreflectError, match="found 0 gamma"):
        Instrument.from_table([], [])


def test_an_instrument_from_a_table_of_magnitudes_proposes_in_the_papers_frame():
    # the gammas were negated but the settings kept +gamma: proposals at +gamma, flagged as
    # new angles, and settings already measured proposed again
    table = read_measurements(bundled_dir() / "terrazzo.csv").to_frame()
    tool = Instrument.from_table(table.gamma_deg.abs(), table.theta_deg)
    assert (tool.settings()[:, 0] < 0).all()
    assert set(tool.settings()[:, 0]) == set(tool.gammas_deg)
    campaign = Campaign(tool, seed=0)
    first = campaign.propose(8)
    assert (first.gamma_deg < 0).all()
    look = table.set_index(["gamma_deg", "theta_deg"]).power
    campaign.add(first[["gamma_deg", "theta_deg"]].assign(
        power=[look[(g, t)] for g, t in zip(first.gamma_deg, first.theta_deg, strict=True)]))
    taken = set(zip(first.gamma_deg, first.theta_deg, strict=True))
    more = campaign.propose(30)
    assert not taken & set(zip(more.gamma_deg, more.theta_deg, strict=True))
    assert not more[more.gamma_deg.isin(first.gamma_deg)].new_gamma.any()


def test_a_campaign_held_to_one_angle_of_incidence_stops():
    # once the instrument has set the one angle it may, the curve elsewhere is extrapolated
    # and moved for ever (45 readings, "continue"): the verdict now judges where it can read
    params = np.array([0.3, -0.5, 1.2, 0.3, 40.0, 0.4, 1.0])
    tool = Instrument(gammas_deg=(-10, -30, -50, -70), max_gamma_settings=1)
    campaign = Campaign(tool, seed=0)
    while not campaign.verdict().stop and campaign.n_measured < 20:
        s = campaign.propose(4)
        campaign.add(s[["gamma_deg", "theta_deg"]].assign(power=two_lobe_power(
            np.radians(s.gamma_deg.to_numpy()), np.radians(s.theta_deg.to_numpy()), *params)))
    verdict = campaign.verdict()
    assert verdict.stop and campaign.n_measured <= 16
    assert len(set(campaign.measurements.gamma_deg)) == 1
    assert "the 1 angle of incidence the instrument allows is set" in verdict.text


def test_a_replay_with_the_receivers_resolution_fits_the_averaged_model(tmp_path):
    # a dense table read by a receiver 4 deg wide (a glossy lobe of about 1.2 deg half
    # width, blurred): fitted as points, no fit reaches it (the all-points fit 0.9990, the
    # paper's 12 points 0.971); with --resolution 4 every fit is the model averaged over
    # the receiver, and the table is recovered (R^2 1.0000), as 'next --resolution' fits
    from conftest import blurred_glossy

    dense = blurred_glossy(4.0)
    point = replay(dense, ["adaptive", "paper"], n_max=12)
    wide = replay(dense, ["adaptive", "paper"], n_max=12, resolution=4.0)
    assert point.reference_r2 < 0.9995 < 0.99999 < wide.reference_r2
    assert point.curves["paper"].r2[12] < 0.98 < 0.9999 < wide.curves["paper"].r2[12]
    assert wide.curves["adaptive"].r2[12] > 0.9999 > point.curves["adaptive"].r2[12]
    assert wide.settings["resolution_deg"] == 4.0 and point.settings["resolution_deg"] == 0.0
    hind = replay(dense, ["hindsight"], n_max=9, generations=2, resolution=4.0)
    assert "selected and scored as points" in hind.curves["hindsight"].note
    path = tmp_path / "blur4.csv"
    dense.to_frame().to_csv(path, index=False)
    code, stdout, err = _run(["campaign", path, "--strategies", "paper", "--resolution", "4",
                              "--json"])
    assert code == 0, err
    out = json.loads(stdout)
    assert out["settings"]["resolution_deg"] == 4.0 and out["reference_r2"] > 0.99999
    code, _, err = _run(["campaign", path, "--strategies", "paper", "--resolution", "-1"])
    assert code != 0 and err.count("\n") == 1
    code, _, err = _run(["campaign", path, "--strategies", "paper", "--resolution", "95"])
    assert code != 0 and "receiver's resolution (--resolution, deg) must be" in err


def test_a_fit_with_the_receivers_resolution_warns_of_its_own_result_only(tmp_path,
                                                                          monkeypatch):
    # fit_averaged starts from a point fit; on readings blurred by a 4-deg receiver that
    # point fit left v_nd ill-determined (-0.096 +- 0.19 by the rule of stop 43; since stop
    # 44 an exponent's error is judged against 1), and `fit --resolution` printed its
    # warning under a result that has v_nd = 0.5002 +- 0.0005. Now only the result warns:
    # the point fit is made to warn here, and its warning must not reach the output
    from conftest import BLURRED_TRUTH, blurred_glossy

    from irreflect.errors import FitWarning
    from irreflect.fitting import api, fit_averaged
    from irreflect.models import get_model

    real_fit = api.fit

    def point_fit_that_warns(measurements, model, *args, **kwargs):
        result = real_fit(measurements, model, *args, **kwargs)
        if model == "two-lobe" or model is get_model("two-lobe"):  # not the averaged model
            warnings.warn("ill-determined by these data: v_nd (the point fit)", FitWarning,
                          stacklevel=2)
        return result

    monkeypatch.setattr(api, "fit", point_fit_that_warns)
    path = tmp_path / "blur4.csv"
    meas = blurred_glossy(4.0)
    meas.to_frame().to_csv(path, index=False)
    with pytest.warns(FitWarning, match="ill-determined by these data: v_nd"):
        api.fit(meas, "two-lobe")  # the point fit's warning, as a point fit
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = fit_averaged(meas, "two-lobe", 4.0)
    assert res.values[3] == pytest.approx(BLURRED_TRUTH[3], rel=1e-3)  # the aperture model against this helper's own integral
    code, _, err = _run(["fit", path, "--resolution", "4"])
    assert code == 0 and "ill-determined" not in err
    # plot --fit draws the averaged fit; --resolution without --fit is said to do nothing
    code, out, err = _run(["plot", path, "--fit", "--resolution", "4", "--out",
                           tmp_path / "p.png"])
    assert code == 0 and "ill-determined" not in err and (tmp_path / "p.png").stat().st_size
    code, _, err = _run(["plot", path, "--resolution", "4", "--out", tmp_path / "q.png"])
    assert code == 0 and "--resolution has no effect without --fit" in err
    code, _, err = _run(["plot", path, "--fit", "--model", "phong@10", "--resolution", "4",
                         "--out", tmp_path / "r.png"])
    assert code != 0 and "drop '@G' or --resolution" in err and not (tmp_path / "r.png").exists()


# ----------------------------------------------------------------------------- the estimate
#: the first 12 settings the campaign chose on the RGL golden yellow paint (seed 0, the
#: weighted fit's campaign of stop 39)
GOLDEN12 = [(0.0, 0.0), (-31.6178, 31.6178), (-66.3495, 66.3495), (0.0, -50.0),
            (-66.3495, 0.0), (-66.3495, 65.3495), (-31.6178, 67.0), (0.0, 1.0),
            (-45.3703, 48.6203), (-45.3703, 46.8703), (-56.4581, -1.0), (-45.3703, 40.0)]


def _rule(**knobs):
    import dataclasses

    from irreflect.campaign import DesignRule

    return dataclasses.replace(DesignRule(), **knobs)


def test_the_quadrature_estimate_reaches_the_all_points_fit_where_the_weighted_fit_does_not(
        real_dir):
    # the golden yellow paint's 12 readings: the weighted fit of the readings gives R^2
    # 0.969 against all points, the model fitted to the posterior's picture of the whole
    # range 0.977, within 0.01 of the all-points fit (0.985) and above the paper's 12
    # points (0.9755)
    import irreflect

    dense, source, rows = _replayed(real_dir, "rgl_vch_golden_yellow", GOLDEN12)
    power = rows["power"].to_numpy()
    reference = irreflect.fit(dense, seed=0).r2
    weighted = Campaign(source.instrument(), rows, seed=0, rule=_rule(quadrature=False))
    estimate = Campaign(source.instrument(), rows, seed=0)
    assert weighted.r2_against(dense) < reference - 0.01
    assert estimate.r2_against(dense) >= reference - 0.01
    assert estimate.r2_against(dense) > weighted.r2_against(dense) + 0.004
    # an estimate must stay a refinement of the weighted fit's curve: asked to agree with
    # it to R^2 0.9999 over the range, this one does not, and the weighted fit is reported
    strict = Campaign(source.instrument(), rows, seed=0, rule=_rule(quadrature_agree=0.9999))
    assert strict.fit is strict._current().fit
    assert strict.r2_against(dense) == pytest.approx(weighted.r2_against(dense), abs=1e-9)
    # the verdict's flags are the reported fit's, checked on its own values
    assert estimate.verdict().at_bound == estimate.fit.at_bound
    assert estimate.verdict().ill_determined == estimate.fit.ill_determined
    from irreflect.models import get_model

    bounds = {p.name: (p.lower, p.upper) for p in get_model("two-lobe").params}
    for name, value in zip(estimate.fit.param_names, estimate.fit.values, strict=True):
        near = min(abs(value - b) for b in bounds[name]) <= 1e-6 * max(1.0, abs(value))
        assert (name in estimate.fit.at_bound) == near, (name, value, bounds[name])
    # it is still a fit of these readings: its residuals are theirs
    assert np.allclose(estimate.fit.fitted + estimate.fit.residuals, power)
    assert estimate.fit.r2 == pytest.approx(
        1.0 - np.sum(estimate.fit.residuals ** 2) / np.sum((power - power.mean()) ** 2))


#: the first 20 settings the campaign chose on the RGL sunflower film (seed 0, stop 53's
#: rule, whose picture added the posterior mean of a difference to the fit)
SUNFLOWER20 = [(0.0, 0.0), (-39.8852, 39.8852), (-68.776, 68.776), (0.0, -50.0),
               (-68.776, 0.0), (-68.776, 67.776), (-39.8852, 75.0), (0.0, 1.0),
               (-50.0247, 50.0247), (-68.776, 69.526), (-59.4294, 58.9294), (-59.4294, 0.0),
               (-68.776, 68.526), (-27.6586, 27.0), (-59.4294, 59.6794),
               (-27.6586, 27.6586), (-50.0247, 51.0), (-68.776, 69.0), (0.0, -2.0),
               (-68.776, 69.276)]


def test_the_picture_departs_from_the_fit_by_ratios_on_a_narrow_lobe(real_dir, monkeypatch):
    # the sunflower film's lobe is 0.6 deg wide at half maximum; its 20th reading, 0.5 deg
    # beyond the mirror at 68.8 deg, lies 38 above the fit, and a picture that adds the
    # posterior mean of the difference raises the other flank with it (77 at 68.28 deg
    # where the film gives 42), and 0.11 deg from the only reading on the 40 deg lobe
    # (50.1 against a fit of 63.6) falls to 7 where the film gives 49. The departure as a
    # ratio to the fit keeps each flank nearer its own readings
    import irreflect.campaign.core as core

    dense, source, rows = _replayed(real_dir, "rgl_cg_sunflower", SUNFLOWER20)
    pictures = []

    def spy(*args):
        pictures.append(core_picture(*args))
        return pictures[-1]

    core_picture = core._picture
    monkeypatch.setattr(core, "_picture", spy)

    def picture(ratio):
        campaign = Campaign(source.instrument(), rows, seed=0, rule=_rule(picture_ratio=ratio))
        assert campaign.estimated
        return campaign._settings, pictures[-1]

    settings, difference = picture(0.0)
    _, ratio = picture(_rule().picture_ratio)
    _, linear = picture(1e6)
    film = {(round(g, 3), round(t, 3)): p
            for g, t, p in zip(dense.gamma_deg, dense.theta_deg, dense.power, strict=True)}
    for g, t in [(-68.776, 68.276), (-39.8852, 40.0)]:
        i = int(np.argmin(np.hypot(settings[:, 0] - g, settings[:, 1] - t)))
        truth = film[(round(settings[i, 0], 3), round(settings[i, 1], 3))]
        assert abs(ratio[i] - truth) < abs(difference[i] - truth) - 5.0
    # the ratio's floor is a share of the peak: far above it the picture is the
    # difference's again
    np.testing.assert_allclose(linear, difference, rtol=1e-3, atol=1e-3 * difference.max())


def test_the_quadrature_estimate_of_every_setting_measured_is_the_all_points_fit():
    # with a reading at every setting the posterior's picture of the range is the readings
    # themselves, and the estimate is the all-points fit (a bump the model lacks included)
    import irreflect

    rng = np.random.default_rng(1)
    g, t = np.meshgrid([-15.0, -40.0, -65.0], np.arange(-80.0, 81.0, 8.0), indexing="ij")
    g, t = g.ravel(), t.ravel()
    clean = two_lobe_power(np.radians(g), np.radians(t), 0.3, -0.5, 1.2, 0.3, 200.0, 0.4,
                           1.0) * (1.0 + 0.3 * np.exp(-((t - 30.0) / 15.0) ** 2))
    power = clean * (1.0 + 0.01 * rng.standard_normal(clean.size))
    dense = Measurements(gamma_deg=g, theta_deg=t, power=power)
    tool = Instrument(gammas_deg=(-15, -40, -65), theta_min=-80, theta_max=80, theta_step=8)
    rows = pd.DataFrame({"gamma_deg": g, "theta_deg": t, "power": power})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reference = irreflect.fit(dense, seed=0)
    campaign = Campaign(tool, rows, seed=0)
    assert campaign._current().estimate is not None
    assert campaign.r2_against(dense) == pytest.approx(reference.r2, abs=1e-5)
    assert campaign.fit.values[-1] == pytest.approx(reference.values[-1], rel=1e-3)


#: a clear coat of the held-out tables (experiments/unseen_tables.py --random 30
#: --first-seed 9100, clearcoat-14): the campaign's 15 readings (gamma, theta, power)
CLEARCOAT = [(0.0, -9.0, 8.08894e-05), (-40.0, 40.0, 0.00104917), (-80.0, 80.0, 0.00838744),
             (0.0, -30.0, 4.50673e-05), (-80.0, 0.0, 8.19703e-06),
             (-80.0, 79.0, 0.00670245), (-40.0, 75.0, 1.37981e-05), (0.0, 9.0, 8.10285e-05),
             (-70.0, 70.25, 0.00372789), (-70.0, 68.25, 0.002232),
             (-80.0, 80.75, 0.00771758), (-80.0, 82.0, 0.00521366),
             (-60.0, 60.5, 0.00190607), (-60.0, 62.75, 0.00089311),
             (-20.0, 19.25, 0.000855746)]


@pytest.mark.parametrize("quadrature", [True, False])
def test_a_needle_of_the_fit_is_not_what_the_campaign_reports(quadrature):
    # at 15 readings every fit of the clear coat's readings sends the diffuse index law to
    # a needle at the normal at grazing incidence, 150 times the largest reading, where
    # nothing is measured (R^2 -1468 against all points); the estimate, taken around the
    # previous estimate there, does not, and the next reading still tests the needle
    from irreflect.campaign.core import OVERSHOOT, TEST_OVERSHOOT

    tool = Instrument(gammas_deg=(0, -10, -20, -30, -40, -50, -60, -70, -80), theta_min=-30,
                      theta_max=85, theta_step=0.25, source_clearance=0.0)
    rows = pd.DataFrame(CLEARCOAT, columns=["gamma_deg", "theta_deg", "power"])
    campaign = Campaign(tool, rows.iloc[:8], seed=0, rule=_rule(quadrature=quadrature))
    for i in range(8, 15):  # one reading at a time, the verdict read after each
        campaign.verdict()
        campaign.add(rows.iloc[i:i + 1])
    top = float(rows["power"].max())
    assert campaign._overshoot(campaign._current().fit.values, top) > TEST_OVERSHOOT
    reported = campaign._overshoot(campaign.fit.values, top)
    if quadrature:
        assert reported <= OVERSHOOT
    else:
        assert reported > TEST_OVERSHOOT
    verdict = campaign.verdict()
    assert not verdict.stop and any("times the largest reading" in r for r in verdict.reasons)
    assert "tests the fit's prediction" in campaign.propose(1)["why"].iloc[0]


def test_the_quadrature_knobs_are_checked_and_a_strict_ratio_keeps_the_weighted_fit():
    from irreflect.campaign import DesignRule

    with pytest.raises(IrreflectError, match="quadrature_ratio"):
        DesignRule(quadrature_ratio=-1.0)
    with pytest.raises(IrreflectError, match="quadrature_agree"):
        DesignRule(quadrature_agree=1.5)
    # a ratio below 1 refuses any estimate that explains the readings worse than the
    # weighted fit does: the reported fit is then the weighted fit itself
    dense = _material(GLOSSY, step=4.0, noise=0.02, name="gloss")
    source = DenseInstrument(dense)
    campaign, _ = _campaign_until_stop(source, rule=_rule(quadrature_ratio=1e-9), n_max=12)
    state = campaign._current()
    assert state.estimate is None and campaign.fit is state.fit


def test_readings_given_at_once_give_what_they_give_one_at_a_time(real_dir):
    # `irreflect next` reads every reading from a file: the campaign fits, reports and
    # judges as the scripted loop that took them one at a time (before stop 40 the verdict
    # refitted the earlier readings afresh: its curve had moved by 310 % of its variance
    # on these 12 readings, against 4.9 % one at a time)
    _, source, rows = _replayed(real_dir, "rgl_vch_golden_yellow", GOLDEN12)
    stepwise = Campaign(source.instrument(), rows.iloc[:8], seed=0)
    for i in range(8, 12):
        stepwise.verdict()
        stepwise.add(rows.iloc[i:i + 1])
    at_once = Campaign(source.instrument(), rows, seed=0)
    a, b = stepwise.verdict(), at_once.verdict()
    assert np.isfinite(a.stability) and np.isfinite(b.stability)
    assert b.stability == pytest.approx(a.stability, rel=1e-6)
    assert b.stop == a.stop
    np.testing.assert_allclose(at_once.fit.values, stepwise.fit.values, rtol=1e-6)


def test_a_campaign_that_goes_on_says_when_the_model_explains_its_readings_poorly():
    # a foreign (Lafortune) material the model fits to R^2 0.77 on all points: its curve
    # keeps moving, and the verdict says why more readings will not mend it (a held-out
    # sheen table never stopped in 25 readings with no word on the model)
    from irreflect import metrics
    from irreflect.synthetic import foreign_material

    dense = foreign_material(107).measurements
    _, verdicts, _ = replay_adaptive(DenseInstrument(dense), 12, seed=0)
    v = verdicts[12]
    hint = [r for r in v.reasons if r.startswith("the model explains the readings only")]
    assert not v.stop and len(hint) == 1
    r2_readings = float(hint[0].split("R^2 ")[1].split(":")[0])
    assert r2_readings < metrics.MISFIT_R2
    # before the fewest readings a stop needs, no such word: a first fit is rough
    assert not any("explains the readings only" in r for r in verdicts[9].reasons)


def test_the_hindsight_curve_says_when_select_thorough_fits_are_no_bound(monkeypatch):
    # a noisy matte table (held-out lambert-16): the thorough fits of select's best subsets
    # gave R^2 -235.6 against all points, the search's own fits of the same 12 points 0.9156
    from types import SimpleNamespace

    import irreflect.selection as selection
    from irreflect.campaign.replay import NO_BOUND, replay_hindsight

    dense = _material(MATTE, step=5.0, name="matte wall")
    mask = np.zeros(dense.n_points, bool)
    mask[:12] = True

    def fake(search_r2):
        front = pd.DataFrame({"n_points": [10, 12], "r2": [-244.06, -235.6]})
        return SimpleNamespace(front=front, search_best={12: (1.0 - search_r2, mask)},
                               best_mask=lambda n: mask if n == 12 else None, knee_n=12)

    for search_r2, flagged in ((0.9156, True), (-235.58, False)):
        monkeypatch.setattr(selection, "run_selection", lambda *a, s=search_r2, **k: fake(s))
        curve = replay_hindsight(DenseInstrument(dense), 14, generations=1)
        assert curve.r2[12] == -235.6 and curve.r2[11] == -244.06
        assert (NO_BOUND in curve.note) is flagged
        # and the figure's legend says it
        from irreflect.campaign.replay import ReplayResult
        from irreflect.plots.campaign import plot_campaign
        from irreflect.plots.common import plt

        ax = plot_campaign(ReplayResult("matte wall", dense.n_points, 0.9156,
                                        {"hindsight": curve}))
        labels = ax.get_legend_handles_labels()[1]
        plt.close(ax.figure)
        assert any(NO_BOUND in label for label in labels) is flagged


def test_a_replayed_protocol_says_how_its_readings_were_read_and_what_its_fit_left_open():
    # three commands scored "the paper's protocol" on a held-out noisy matte table at
    # R^2 0.8828 (select, points snapped), 0.8993 and 0.3619 (interpolated readings, other
    # thetas): a fit with 5 of 7 coefficients ill-determined swings with its readings
    import irreflect
    from irreflect.campaign.replay import replay_protocol
    from irreflect.protocol.evaluate import paper_protocol_for, sample_protocol

    dense = _material(MATTE, step=3.0, name="matte wall")
    curve = replay_protocol(DenseInstrument(dense), "paper")
    _, frame = sample_protocol(paper_protocol_for(dense), dense, tolerance_deg=5.0)
    moved = int(np.sum(frame["source"] == "interpolated"))
    assert moved > 0
    assert f"{moved} of {len(frame)} readings interpolated along theta" in curve.note
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = irreflect.fit(Measurements(gamma_deg=curve.points["gamma_deg"].to_numpy(),
                                         theta_deg=curve.points["theta_deg"].to_numpy(),
                                         power=curve.points["power"].to_numpy()), seed=0)
    ill = f"{len(res.ill_determined)} of 7 coefficients ill-determined"
    assert (ill in curve.note) is bool(res.ill_determined)
    assert ("at a bound: " + ", ".join(res.at_bound) in curve.note) is bool(res.at_bound)


def _sigma_campaign(effect, seed, n):
    """A campaign replayed on a hidden-effect table (the benchmark's draws), its readings
    given with the table's noise as a sigma column: the verdicts by N."""
    from irreflect.diagnose.hidden import hidden_case

    case = hidden_case(effect, seed, sigma_column=False)
    dense, sigma = case.measurements, case.truth["sigma0"]
    source = DenseInstrument(dense)
    rng = np.random.default_rng([0, 11])
    campaign = Campaign(source.instrument(), seed=0,
                        noise_floor=max(0.0, -float(np.min(dense.power))))
    verdicts = {}
    while campaign.n_measured < n:
        p = campaign.propose(1)
        power = source.read(p["gamma_deg"], p["theta_deg"], rng)
        campaign.add(p[["gamma_deg", "theta_deg"]].assign(power=power, sigma=sigma))
        verdicts[campaign.n_measured] = campaign.verdict()
    return campaign, verdicts


def test_readings_with_sigma_say_when_they_depart_from_the_fit_beyond_their_noise():
    # a hidden retroreflection: its readings are fitted to R^2 0.98, above the R^2 rule,
    # but at chi^2/dof 70-160 against their noise; diagnose on them names it (test_diagnose)
    campaign, verdicts = _sigma_campaign("retroreflection", 100, 15)
    assert campaign.fit is not None and campaign.fit.r2 > 0.9
    hint = [r for r in verdicts[15].reasons if r.startswith("the readings depart")]
    assert len(hint) == 1 and "irreflect diagnose on the readings names it" in hint[0]
    assert float(hint[0].split("chi^2/dof ")[1].split()[0]) > 10
    # the same campaign on a table with nothing hidden: readings within their noise
    _, clean = _sigma_campaign(None, 1, 15)
    assert not any("depart" in r or "explains the readings only" in r
                   for v in clean.values() for r in v.reasons)


def test_a_replay_on_a_table_with_sigma_gives_every_strategys_readings_its_sigma():
    # the protocols' and the hindsight subsets' readings carried the table's sigma, the
    # adaptive and random ones did not: on a table with sigma the strategies' fits were
    # weighted differently (foam board: the adaptive verdict stopped at 16, 2 readings
    # after the target held; with the sigma, at 14)
    from irreflect.campaign.replay import replay_random

    dense = read_measurements(TERRAZZO)
    source = DenseInstrument(dense)
    curve, verdicts, _ = replay_adaptive(source, 10, seed=0)
    pts = curve.points
    assert "sigma" in pts and len(pts) == 10
    look = dense.to_frame().set_index(["gamma_deg", "theta_deg"])["sigma"]
    expected = [look[(g, t)] for g, t in zip(pts.gamma_deg, pts.theta_deg, strict=True)]
    np.testing.assert_allclose(pts["sigma"], expected)
    np.testing.assert_allclose(source.sigma_at(pts.gamma_deg, pts.theta_deg), expected)
    # a table without sigma: none is invented
    bare = dataclasses.replace(dense, sigma=None)
    assert DenseInstrument(bare).sigma_at([-10.0], [0.0]) is None
    assert "sigma" not in replay_adaptive(DenseInstrument(bare), 9, seed=0)[0].points
    # the random readings are weighted as the others: their R^2 differs from unweighted
    # fits when the sigma is not one constant
    noisy = dataclasses.replace(dense, sigma=dense.sigma * (1 + 5 * dense.power / dense.power.max()))
    weighted = replay_random(DenseInstrument(noisy), 12, seed=0, n_draws=1).r2[12]
    plain = replay_random(DenseInstrument(bare), 12, seed=0, n_draws=1).r2[12]
    assert weighted != pytest.approx(plain, abs=1e-6)
    # with the instrument's own noise on top, the readings' sigma says so
    loud = DenseInstrument(dense, noise=0.05)
    power = np.array([0.05, 1.0])
    np.testing.assert_allclose(loud.reading_sigma([-10.0, -10.0], [-70.0, -60.0], power),
                               np.sqrt(0.006 ** 2 + (0.05 * power) ** 2))


def test_next_takes_jittered_readings_at_the_instrument_s_angles(tmp_path):
    """Readings at -69.96 and -40.12 for the instrument's -70 and -40 were fitted as angles
    it does not list, and the proposals and the verdict's range left them out. Within
    0.25 deg they are taken at the listed angle, with a note; farther off they stay."""
    tool = Instrument(gammas_deg=(-10, -40, -70), theta_step=1.0)
    rows = pd.DataFrame({"gamma_deg": [-10.02, -40.12, -69.96, -69.5],
                         "theta_deg": [10.0, 40.0, 70.0, 60.0], "power": [1.0, 2.0, 3.0, 1.0]})
    meas = Measurements(gamma_deg=rows.gamma_deg, theta_deg=rows.theta_deg, power=rows.power)
    snapped, note = tool.snap_gammas(meas)
    assert snapped.gamma_deg.tolist() == [-10.0, -40.0, -70.0, -69.5]
    assert note.startswith("3 reading(s) within 0.25 deg of an angle of incidence")
    assert "-40.12 -> -40" in note and "-69.96 -> -70" in note
    assert tool.snap_gammas(snapped)[1] is None
    rows.iloc[:3].to_csv(tmp_path / "r.csv", index=False)
    code, out, err = _run(["next", tmp_path / "r.csv", "--gammas", "-10", "-40", "-70"])
    assert code == 0 and err.count("3 reading(s) within 0.25 deg") == 1
    assert "does not list" not in err


def test_campaign_add_snaps_jittered_gammas_and_notes_readings_off_the_instrument():
    """In Python, Campaign.add took -29.97 for the instrument's -30 as an angle it does not
    list, silently: the next proposals called -30 'a new angle of incidence' and the verdict
    saw -70 as extrapolated. It now snaps them as `next` does, and notes (DataNotice)
    readings at angles the instrument does not list or beyond its receiver range."""
    tool = Instrument(gammas_deg=(-10, -30, -70), theta_min=-60, theta_max=60)
    rows = [(-9.97, 10.0, 1.0), (-30.02, 30.0, 2.0), (-69.9, 55.0, 1.5)]
    with pytest.warns(DataNotice, match=r"^3 reading\(s\) within 0.25 deg .*-30.02 -> -30"):
        campaign = Campaign(tool).add(rows)
    assert campaign.measurements.gamma_deg.tolist() == [-10.0, -30.0, -70.0]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        campaign.add([(-80.0, 10.0, 1.0), (-30.0, 65.0, 0.5), (-10.0, 20.0, 1.0)])
    notes = [str(w.message) for w in caught if issubclass(w.category, DataNotice)]
    assert len(notes) == 2 and notes[0].startswith("readings at gamma -80 deg, which the "
                                                   "instrument does not list")
    assert notes[1].startswith("1 reading(s) at theta beyond the receiver range -60..60 deg")


def test_campaign_r2_against_reads_a_table_by_name_or_path_and_checks_its_name():
    """r2_against("terrazzo") raised AttributeError ('str' has no gamma_deg): it reads any
    table now; Campaign(name=5) was refused only at the first add, by Measurements."""
    from irreflect import fit

    truth = fit("terrazzo", seed=0)
    campaign = Campaign(Instrument(gammas_deg=(-10, -30, -50, -70), theta_min=-80,
                                   theta_max=80))
    assert np.isnan(campaign.r2_against("terrazzo"))
    opening = campaign.propose(8)
    campaign.add(opening[["gamma_deg", "theta_deg"]].assign(
        power=truth.predict(opening.gamma_deg, opening.theta_deg)))
    # readings of the fitted curve itself: the campaign's fit recovers it
    assert campaign.r2_against("terrazzo") == pytest.approx(truth.r2, abs=1e-4)
    with pytest.raises(DataError, match="expected a measurement table"):
        campaign.r2_against([1.0, 2.0])
    with pytest.raises(IrreflectError, match="name must be text .*; found 5"):
        Campaign(Instrument(gammas_deg=(-10, -50)), name=5)


def test_next_notes_readings_clipped_at_the_detector_top(tmp_path):
    # a dense table with 3+ readings at exactly its largest power gets the saturation note;
    # a campaign's readings did not (partial tables skipped it)
    measured = tmp_path / "measured.csv"
    rows = ["gamma_deg,theta_deg,power", "-20,20,5.0", "-40,40,5.0", "-60,60,5.0",
            "-20,-30,0.8", "-40,0,0.9", "-60,0,0.7", "-20,21,4.1", "-60,10,0.6"]
    measured.write_text("\n".join(rows) + "\n")
    code, _, err = _run(["next", measured, "--gammas", "-20", "-40", "-60"])
    assert code == 0, err
    assert "3 readings (38%) equal the largest power, 5, exactly" in err
    measured.write_text("\n".join(rows[:3] + ["-60,60,4.9"] + rows[4:]) + "\n")
    code, _, err = _run(["next", measured, "--gammas", "-20", "-40", "-60"])
    assert code == 0, err
    assert "saturated detector" not in err


def test_instrument_settings_at_an_unlisted_angle_of_incidence_are_refused():
    # settings at gamma 50 were taken by an instrument that lists 20 and 40 only, and
    # proposed as if it could set 50
    with pytest.raises(IrreflectError, match=r"angle\(s\) of incidence 50 deg are not among "
                                             r"gammas_deg \(20, 40\)"):
        Instrument(gammas_deg=(20, 40), settings_deg=[(-20, 10), (-40, 30), (-50, 40)])
    tool = Instrument(gammas_deg=(20, 40), settings_deg=[(20, 10), (40, 30), (40, 50)])
    assert sorted(np.unique(tool.settings()[:, 0])) == [-40.0, -20.0]


def test_a_stop_on_one_angle_of_incidence_says_the_laws_in_gamma_stay_open():
    # unseen_tables3 one_gamma stopped at 11 readings with every law in gamma ill-determined
    # and no word that this is what one angle allows
    from irreflect.models import two_lobe_power

    t = np.arange(-80.0, 81.0, 4.0)
    t = t[np.abs(t + 30.0) >= 5]
    g = np.full(t.size, -30.0)
    clean = two_lobe_power(np.radians(g), np.radians(t), 0.3, 0.5, 1.0, 0.5, 40.0, 0.0, 1.0)
    power = clean * (1 + 0.002 * np.random.default_rng(0).standard_normal(t.size))
    tool = Instrument(gammas_deg=(30,), theta_min=-80, theta_max=80, theta_step=4)
    verdict = Campaign(tool, list(zip(g, t, power, strict=True))).verdict()
    assert verdict.stop, verdict.text
    assert "one angle of incidence (30 deg): the laws in gamma stay ill-determined" in (
        verdict.text)
    # at three angles the same material's stop says nothing of the kind
    g3 = np.repeat([-20.0, -40.0, -60.0], t.size)
    t3 = np.tile(t, 3)
    keep = np.abs(t3 - g3) >= 5
    g3, t3 = g3[keep], t3[keep]
    p3 = two_lobe_power(np.radians(g3), np.radians(t3), 0.3, 0.5, 1.0, 0.5, 40.0, 0.0, 1.0)
    three = Campaign(Instrument(gammas_deg=(20, 40, 60), theta_min=-80, theta_max=80,
                                theta_step=4), list(zip(g3, t3, p3, strict=True))).verdict()
    assert "one angle of incidence" not in three.text


def _oren_nayar_on_cornell_grid(real_dir, sigma_rough: float, seed: int) -> Measurements:
    """A matte Oren-Nayar surface (no specular lobe) read on the Cornell sets' own grid
    (receivers about 8 deg apart), 1 % relative noise."""
    grid = read_measurements(real_dir / "cornell" / "cornell_cayman.csv")
    g, t = np.radians(np.abs(grid.gamma_deg)), np.radians(grid.theta_deg)
    s2 = sigma_rough ** 2
    a, b = 1 - 0.5 * s2 / (s2 + 0.33), 0.45 * s2 / (s2 + 0.09)
    tr = np.abs(t)
    cos_dphi = np.where(t < 0, 1.0, -1.0)  # receiver on the source's side or beyond
    alpha, beta = np.maximum(g, tr), np.minimum(g, tr)
    f = (a + b * np.maximum(0, cos_dphi) * np.sin(alpha) * np.tan(beta)) * np.cos(tr)
    rng = np.random.default_rng(seed)
    power = 1e-3 * f / f.max() * (1 + 0.01 * rng.standard_normal(f.shape))
    return Measurements(gamma_deg=grid.gamma_deg, theta_deg=grid.theta_deg, power=power,
                        name="oren-nayar-cornell")


@pytest.mark.real
def test_a_replay_warns_when_its_target_fit_hides_a_lobe_between_the_receivers(real_dir):
    """On a matte Oren-Nayar table on the Cornell grid the all-points fit reached R^2 0.966
    with a specular lobe 0.46-0.0008 deg wide that no reading sees (v_ns at its bound), and
    the campaign, which stayed at 0.950, was said never to keep the target without a word
    on why. Cayman, a glossy Cornell set whose lobe one reading sees, is not warned of."""
    from irreflect.campaign.replay import _reference_unseen_lobe
    from irreflect.fitting import fit

    table = _oren_nayar_on_cornell_grid(real_dir, 0.6, seed=7006)
    cayman = read_measurements(real_dir / "cornell" / "cornell_cayman.csv")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        matte, glossy = fit(table, "two-lobe", seed=0), fit(cayman, "two-lobe", seed=0)
    said = _reference_unseen_lobe(matte)
    assert "where no reading of the table falls, at each of its 7 angles" in said, said
    assert f"({matte.r2:.4g})" in said and "NOT TRUSTWORTHY" in said
    assert _reference_unseen_lobe(glossy) == ""


def test_a_hindsight_curve_below_the_papers_12_points_is_called_no_bound():
    """One rule for 'no bound' (the benchmark's, select's warning and irreflect campaign's
    hindsight line): best 12 points more than 0.01 below the paper's 12 are no bound, and
    the campaign's note says so; within 0.01 they are."""
    from irreflect.campaign.replay import NO_BOUND, StrategyCurve, _below_paper

    def curves(h12, p12):
        return {"hindsight": StrategyCurve("hindsight", {12: h12}, pd.DataFrame(), 1.0,
                                           note="select's best subsets"),
                "paper": StrategyCurve("paper", {12: p12}, pd.DataFrame(), 1.0)}

    low = curves(0.95, 0.9701)
    _below_paper(low)
    assert f"{NO_BOUND}: its best 12 points give R^2 0.95, more than 0.01 below the paper's " \
           "12 points' 0.9701" in low["hindsight"].note
    close = curves(0.961, 0.9701)
    _below_paper(close)
    assert NO_BOUND not in close["hindsight"].note


def test_the_reason_of_a_proposal_does_not_depend_on_the_power_unit(real_dir):
    """Seen (metamorphic audit): irreflect next on 16 Cornell Cayman readings in W proposed
    (-10, -1) 'shrinks the standard error of u_nd (ill-determined) by 92%', the same
    readings in nW 'shrinks the standard error of K by 4%': the coefficients' scales in
    coefficient_gain were
    floored at 1e-3, in power units for K, far above a K of 5e-11 W. (A factor of 2**-30,
    about 1e-9, scales every power exactly: the leave-one-out refits, which a rounding
    can send to another optimum, stay the same.)"""
    table = pd.read_csv(real_dir / "cornell" / "cornell_cayman.csv")
    rows = table.sample(16, random_state=3).sort_values(["gamma_deg", "theta_deg"])
    tool = Instrument(gammas_deg=(-10, -20, -30, -40, -50, -60, -70))
    whys = []
    for factor in (1.0, 2.0 ** -30):
        scaled = rows.assign(power=rows["power"] * factor)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            whys.append(Campaign(tool, scaled, seed=0).propose(2))
    assert whys[0][["gamma_deg", "theta_deg"]].equals(whys[1][["gamma_deg", "theta_deg"]])
    assert list(whys[0]["why"]) == list(whys[1]["why"])
    assert "u_nd" in whys[0]["why"][0]


def test_leverage_gain_counts_only_the_picture_a_fit_of_the_model_follows():
    """DesignRule.leverage: a reading's gain projected on the fit's tangent space. A
    covariance orthogonal to the Jacobian's columns (a misfit no fit follows) gains nothing
    projected, while the plain integrated variance counts it; the tangent part is kept."""
    from irreflect.campaign.design import Posterior

    n = 6
    x = np.linspace(-1.0, 1.0, n)
    jac = np.column_stack([np.ones(n), x])  # the fit follows a level and a slope
    w = np.ones(n)
    m = np.linalg.pinv(jac.T @ jac)
    along = 1.0 + 0.5 * x  # in the tangent space
    across = x ** 2 - np.mean(x ** 2)  # orthogonal to both columns
    across = 3.0 * (across - jac @ (m @ (jac.T @ across)))
    assert np.max(np.abs(jac.T @ across)) < 1e-12
    noise = np.full(n, 1e-3)
    post = Posterior(cov=np.outer(across, across), noise=noise)
    plain = post.gains()
    assert plain[0] > 0.1  # the plain criterion counts the misfit
    assert np.max(np.abs(post.gains((jac, m, w), 1.0))) < 1e-12
    both = Posterior(cov=np.outer(across, across) + np.outer(along, along), noise=noise)
    lever = both.gains((jac, m, w), 1.0)
    alone = Posterior(cov=np.outer(along, along), noise=noise).gains()
    # projected, the gain is the tangent part's reduction, seen through each reading's
    # whole variance: the plain criterion reads the end where the misfit is largest
    # (x = -1: 8.43 against 6.81 at x = 0.6), the projected one where the misfit is small
    # and the slope bright (x = 0.6: 6.31 against 0.60 at x = -1)
    var = np.diag(both.cov)
    np.testing.assert_allclose(lever, alone * (along ** 2 + 1e-3) / (var + 1e-3), rtol=1e-9)
    assert int(np.argmax(both.gains())) == 0 and int(np.argmax(lever)) == 4
    assert lever[0] < 0.1 * lever[4]
    half = both.gains((jac, m, w), 0.5)
    np.testing.assert_allclose(half, 0.5 * both.gains() + 0.5 * lever, rtol=1e-12)
    from irreflect.campaign.design import DEFAULT_RULE

    with pytest.raises(IrreflectError):
        dataclasses.replace(DEFAULT_RULE, leverage=1.5)


def test_a_fully_measured_instrument_ends_the_scripted_loop_with_one_line(tmp_path):
    """The documented loop ``while not verdict().stop: add(read(propose(3)))`` ran for ever
    on an instrument whose 16 settings were all measured: propose returned an empty table,
    add took it, and the verdict said continue (the curve moved by 156 % of its variance).
    propose now refuses with what is left and the fix; ``next`` still prints its line."""
    tool = Instrument(gammas_deg=(-30, -50), theta_min=0, theta_max=70, theta_step=10)
    campaign = Campaign(tool, seed=0)
    assert campaign.n_free == 16
    rows = campaign.propose(50)[["gamma_deg", "theta_deg"]]
    assert len(rows) == 16
    power = two_lobe_power(np.radians(rows.gamma_deg.to_numpy()),
                           np.radians(rows.theta_deg.to_numpy()), *GLOSSY)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        campaign.add(rows.assign(power=power))
        assert campaign.n_free == 0
        with pytest.raises(IrreflectError, match=r"^no setting left to propose: every one of "
                                                 r"the 16 settings") as info:
            campaign.propose(3)
    assert "\n" not in str(info.value) and "take campaign.fit as it is" in str(info.value)
    measured = tmp_path / "m.csv"
    rows.assign(power=power).to_csv(measured, index=False)
    code, out, err = _run(["next", measured, "--n", "3", "--gammas", "-30", "-50",
                           "--theta-min", "0", "--theta-max", "70", "--theta-step", "10"])
    assert code == 0 and "no setting left to propose" in out and "verdict: " in out


def test_the_reasons_call_ill_determined_what_the_verdict_does():
    """Fourteen readings of a GGX + Oren-Nayar material (a simulator of the lab's, 2 %
    noise): the verdict said "ill-determined: u_ns" (the reported fit, the quadrature
    estimate) while a proposal said "shrinks the standard error of u_as (ill-determined)"
    and no lobe proposal said it brackets the lobe's width: the reasons named the weighted
    fit's coefficients. The proposals themselves are unchanged."""
    rows = [(-10, -40, 0.177286), (-10, 10, 0.295756), (-10, 11, 0.301279),
            (-40, 40, 0.217214), (-40, 75, 0.056693), (-70, 0, 0.080195),
            (-70, 68, 0.273346), (-70, 70, 0.293998), (-55, 0, 0.134496),
            (-40, 7, 0.182664), (-55, 33, 0.132185), (-10, -3, 0.273908),
            (-70, -18, 0.079698), (-25, -2, 0.217426)]
    tool = Instrument(gammas_deg=(-10, -25, -40, -55, -70), theta_min=-80, theta_max=80)
    campaign = Campaign(tool, rows, seed=5)
    ill = campaign.verdict().ill_determined
    proposals = campaign.propose(2)
    assert [(r.gamma_deg, r.theta_deg) for r in proposals.itertuples()] == [(-55, 63),
                                                                             (-70, 39)]
    names = campaign.model.param_names
    for why in proposals["why"]:
        for name in names:
            assert (f"{name} (ill-determined)" in why) <= (name in ill), why
            assert (f"of {name} by" in why) <= (name not in ill), why
        if "specular lobe" in why:
            assert ("brackets the specular lobe's width" in why) == ("u_ns" in ill), why
    assert "u_as" not in ill and "of u_as by 39%" in proposals["why"].iloc[0]


def test_the_python_campaign_reads_measured_csv_as_next_does(tmp_path):
    """``Campaign(tool, "measured.csv")`` refused the file the walkthrough starts from (its
    header alone: "the table has no rows"), and a file of readings that are all 0 so far
    (a glossy material's first readings beyond its lobe) was checked as a whole table;
    ``irreflect next`` reads both."""
    tool = Instrument(gammas_deg=(-10, -30, -50, -70), theta_min=-80, theta_max=80)
    measured = tmp_path / "measured.csv"
    measured.write_text("gamma_deg,theta_deg,power\n")
    campaign = Campaign(tool, measured, seed=0)
    assert campaign.n_measured == 0
    assert campaign.propose(8).equals(Campaign(tool, seed=0).propose(8))
    assert campaign.add(measured).n_measured == 0
    measured.write_text("gamma_deg,theta_deg,power\n-10,-40,0\n-70,0,0\n")
    assert Campaign(tool, measured).n_measured == 2
    measured.write_text("gamma,theta_deg,power\n")
    with pytest.raises(DataError, match="missing column 'gamma_deg'"):
        Campaign(tool, measured)


@pytest.mark.parametrize("k", [0, -1, 2.0, "3", True])
def test_propose_names_its_argument_when_k_is_not_a_count(k):
    """propose(0) said "k must be an integer >= 1; found 0"."""
    campaign = Campaign(Instrument(gammas_deg=(-10, -30, -50)))
    with pytest.raises(IrreflectError, match=r"^propose\(k\): k, the number of settings to "
                                             r"propose, must be an integer >= 1; found "):
        campaign.propose(k)
