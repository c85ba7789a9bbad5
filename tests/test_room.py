"""Room multipath: checks against closed forms, numerical integration, reciprocity, energy,
Monte Carlo vs the recursive method, seeds and parallel runs, scenes, files and the CLI."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from irreflect.errors import IrreflectError
from irreflect.room import (
    Box,
    from_model,
    lambertian,
    load_material,
    load_scene,
    scene_from_dict,
    simulate,
)
from irreflect.room.materials import lobe_fraction_above
from irreflect.room.validation import (
    barry_configuration_a,
    line_of_sight_closed_form,
    one_bounce_reference,
    single_floor_scene,
)

ROOT = Path(__file__).resolve().parents[1]
ROOMS = ROOT / "datasets" / "rooms"


def _mc_vs(result_mc, reference, k, extra=0.0):
    """|MC - reference| within 4 standard errors (+ an allowance) at order k."""
    link = result_mc.link()
    diff = abs(link.power_w[k] - reference)
    return diff <= 4 * link.stderr_w[k] + extra * reference, (link.power_w[k], reference,
                                                              link.stderr_w[k])


# ----------------------------------------------------------------------------- materials
def test_lobe_fraction_above_limits():
    # axis on the normal: the whole lobe is above; axis in the surface: half of it
    assert lobe_fraction_above(0.0, 5.0) == pytest.approx(1.0, abs=1e-12)
    assert lobe_fraction_above(np.pi / 2, 5.0) == pytest.approx(0.5, abs=1e-6)
    # Lambertian lobe tilted by 60 deg: the analytic fraction (1 + cos 60)/2 = 0.75
    assert lobe_fraction_above(np.radians(60), 1.0) == pytest.approx(0.75, abs=1e-6)


@pytest.mark.parametrize("spec", [
    ("two-lobe", "terrazzo.json"), ("two-lobe", "foam_board.json"),
    ("phong", {"k_s": 0.3, "n": 40.0, "K": 1.0}),
    ("ward", None),
])
def test_reflected_power_equals_reflectance(spec):
    """Energy: the 3D intensity integrated over the hemisphere is rho at every angle of
    incidence (here rho = 0.6), by a brute-force quadrature independent of the normaliser."""
    model, source = spec
    if isinstance(source, str):
        mat = load_material(ROOMS / source, reflectance=0.6)
    elif source is None:
        from irreflect.models import get_model

        m = get_model(model)
        params = {p.name: (min(max(0.3, p.lower), p.upper) if np.isfinite(p.upper) else 1.0)
                  for p in m.params}
        mat = from_model(model, params, 0.6, name=model)
    else:
        mat = from_model(model, source, 0.6, name=model)
    from irreflect.room.kernels import hemisphere_integral, pack_materials

    gammas = np.radians([0.0, 20.0, 45.0, 70.0, 85.0])
    total = hemisphere_integral(pack_materials([mat]), 0, gammas, n_mu=500, n_az=600)
    np.testing.assert_allclose(total, 0.6, rtol=3e-3)


def test_3d_extension_keeps_the_fitted_curve_in_the_plane_of_incidence():
    """In the plane of incidence the 3D two-lobe intensity is proportional to the fitted
    model at every theta (only the overall scale changes with gamma)."""
    doc = json.loads((ROOMS / "terrazzo.json").read_text())
    mat = load_material(ROOMS / "terrazzo.json", reflectance=0.3)
    from irreflect.models import get_model

    model = get_model("two-lobe")
    params = [doc["params"][k] for k in model.param_names]
    for gamma in (10.0, 40.0, 60.0):
        theta = np.linspace(-80, 80, 33)
        fitted = model.predict_deg(params, -gamma, theta)
        ratio = mat.intensity(gamma, theta) / fitted
        assert np.ptp(ratio) / ratio.mean() < 1e-9
    # out of the plane the specular lobe is a solid of revolution about the mirror direction:
    # at gamma = 60 deg, theta = 60 deg rotated 20 deg in azimuth is 17 deg from the mirror
    peak, off = mat.intensity(60, 60, 0.0), mat.intensity(60, 60, 20.0)
    assert peak > 1.2 * off


def test_material_scale_K_is_checked_against_energy():
    # BRDF x cos units: K = 0.9 with a lobe that keeps ~all its power above the surface is fine,
    params = {"u_as": 0.1, "v_as": 0.0, "u_nd": 1.0, "v_nd": 0.0, "u_ns": 30.0, "v_ns": 0.0,
              "K": 0.9}
    mat = from_model("two-lobe", params, "K")
    assert mat.rho_table.max() <= 0.9 + 1e-12
    assert mat.rho_table[0] == pytest.approx(0.9, rel=1e-6)
    # K = 1.2 would reflect more than arrives
    with pytest.raises(IrreflectError, match="more than the incident power"):
        from_model("two-lobe", params | {"K": 1.2}, "K")
    with pytest.raises(IrreflectError, match=r"in \[0, 1\]"):
        lambertian(1.3)


# ----------------------------------------------------------------------------- line of sight
@pytest.mark.parametrize("method", ["recursive", "montecarlo"])
def test_line_of_sight_against_closed_form(method):
    scene = barry_configuration_a()
    power, tau = line_of_sight_closed_form(scene.emitters[0], scene.receivers[0])
    assert power == pytest.approx(1.2318e-6, rel=1e-4)  # Barry's configuration A
    res = simulate(scene, method=method, bounces=0)
    link = res.link()
    assert link.power_w[0] == pytest.approx(power, rel=1e-12)
    assert link.los_delay_s == pytest.approx(tau, rel=1e-12)
    assert tau * 1e9 == pytest.approx(13.026, abs=1e-3)


def test_line_of_sight_blocked_by_a_box():
    scene = barry_configuration_a()
    desk = Box("desk", np.array([0.2, 0.7, 0.0]), np.array([1.0, 1.3, 0.5]), ("walls",) * 6)
    rx = replace(scene.receivers[0], position=np.array([0.5, 1.0, 0.5]))
    blocked = replace(scene, boxes=(Box("screen", np.array([1.0, 1.4, 0.6]),
                                        np.array([2.4, 2.0, 2.0]), ("walls",) * 6), desk),
                      receivers=(rx,))
    assert simulate(blocked, method="recursive", bounces=0).link().power_w[0] == 0.0


# ----------------------------------------------------------------------------- one bounce
def test_one_bounce_converges_to_numerical_integration():
    scene = single_floor_scene()
    reference = one_bounce_reference(scene)
    errors = []
    for cell in (0.5, 0.25, 0.125):
        res = simulate(scene, method="recursive", bounces=1, cell_m=cell)
        errors.append(abs(res.link().power_w[1] / reference - 1))
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 2e-3
    mc = simulate(scene, method="montecarlo", bounces=1, rays=40000, seed=3)
    ok, info = _mc_vs(mc, reference, 1)
    assert ok, info


# ----------------------------------------------------------------------------- Barry, MC
def test_configuration_a_recursive_and_montecarlo_agree():
    """Barry's configuration A: the recursive method (0.125 m cells) and Monte Carlo agree
    per order within the Monte Carlo error plus 2 % (the recursive discretisation)."""
    scene = barry_configuration_a()
    rec = simulate(scene, method="recursive", bounces=3, cell_m=0.125)
    gains = rec.link().power_w
    # independent implementation (vlc-rm, same cells; see experiments/bench_room.py)
    np.testing.assert_allclose(gains, [1.2318e-06, 5.0568e-07, 4.3237e-07, 2.6319e-07], rtol=2e-3)
    mc = simulate(scene, method="montecarlo", bounces=3, rays=60000, seed=1)
    for k in (1, 2, 3):
        ok, info = _mc_vs(mc, gains[k], k, extra=0.02)
        assert ok, (k, info)
    # moments: the recursive mean delay of order 1 is between the first arrival and the end
    link = rec.link()
    assert 15e-9 < link.m1[1] / link.power_w[1] < 25e-9
    # h(t) carries the same power as the exact sums
    np.testing.assert_allclose(link.hist.sum(axis=1), link.power_w, rtol=1e-3)


def test_reciprocity_on_lambertian_surfaces():
    """Swap emitter and receiver (order-1 emitters, 90 deg fields of view, equal areas):
    the same response, exactly for the recursive method, within errors for Monte Carlo."""
    scene = barry_configuration_a(receiver_fov_deg=90.0)
    scene = replace(scene, boxes=(Box("desk", np.array([1.5, 0.5, 0.0]), np.array([2.5, 1.2, 0.8]),
                                      ("walls",) * 6),))
    swapped = scene.swapped()
    a = simulate(scene, method="recursive", bounces=3, cell_m=0.5).link()
    b = simulate(swapped, method="recursive", bounces=3, cell_m=0.5).link()
    np.testing.assert_allclose(a.power_w, b.power_w, rtol=1e-9)
    np.testing.assert_allclose(a.m1, b.m1, rtol=1e-9)
    ma = simulate(scene, method="montecarlo", bounces=2, rays=30000, seed=2).link()
    mb = simulate(swapped, method="montecarlo", bounces=2, rays=30000, seed=2).link()
    for k in (1, 2):
        assert abs(ma.power_w[k] - mb.power_w[k]) < 4 * np.hypot(ma.stderr_w[k], mb.stderr_w[k])


@pytest.mark.parametrize("material", ["lambertian", "two-lobe"])
def test_energy_closed_room_bounded_by_rho_k(material):
    """In a closed room of reflectance rho the power left after k reflections is rho^k times
    the emitted power (Monte Carlo: exactly, since every reflection keeps rho of a ray)."""
    rho = 0.7
    scene = barry_configuration_a(walls=rho, floor=rho, ceiling=rho)
    if material == "two-lobe":
        mat = load_material(ROOMS / "terrazzo.json", reflectance=rho)
        scene = scene.with_materials({"walls": mat, "floor": mat, "ceiling": mat})
    link = simulate(scene, method="montecarlo", bounces=4, rays=5000, seed=0).link()
    left = link.reflected_w / scene.emitters[0].power_w
    expected = rho ** np.arange(1, 5)
    assert np.all(left <= expected * (1 + 1e-12))
    np.testing.assert_allclose(left, expected, rtol=1e-9)
    if material == "lambertian":
        # Barry's point-to-point couplings overestimate between near cells (edges, corners):
        # the excess over rho^k is small and shrinks with the cell size
        excess = [simulate(scene, method="recursive", bounces=3, cell_m=c).link().reflected_w[:2]
                  / expected[:2] - 1 for c in (0.5, 0.25)]
        assert np.all(excess[1] < excess[0])
        assert np.all(excess[1] < 0.025)


def test_recursive_fourth_order_converges_to_montecarlo():
    """Order 4 (one cell-to-cell propagation of delay histograms) approaches Monte Carlo as
    the cells shrink (0.5 m: +24 %, 0.25 m: +9 %, 0.125 m: +4 % in our runs)."""
    scene = barry_configuration_a()
    mc = simulate(scene, method="montecarlo", bounces=4, rays=40000, seed=5).link()
    errors = [simulate(scene, method="recursive", bounces=4, cell_m=c).link().power_w[4]
              / mc.power_w[4] - 1 for c in (0.5, 0.25)]
    assert errors[1] < errors[0]
    assert abs(errors[1]) < 0.12 + 4 * mc.stderr_w[4] / mc.power_w[4]


def test_non_lambertian_recursive_orders_1_2_are_exact():
    """With the fitted two-lobe materials, orders 1 and 2 of the recursive method use the
    exact incidence at every reflection: they agree with Monte Carlo within its error."""
    scene = load_scene(ROOMS / "office.toml")
    scene = scene.with_receivers(scene.receivers[:1])
    rec = simulate(scene, method="recursive", bounces=2, cell_m=0.25).link()
    mc = simulate(scene, method="montecarlo", bounces=2, rays=40000, seed=4).link()
    for k in (1, 2):
        assert abs(rec.power_w[k] - mc.power_w[k]) < 4 * mc.stderr_w[k] + 0.03 * rec.power_w[k], k


# ----------------------------------------------------------------------------- ranging
def test_range_error_of_a_single_delayed_path():
    from irreflect.room.results import ranging_error

    f = 10e6
    tau0 = 10e-9
    # LoS 1 W at tau0, one echo 0.5 W delayed by 2 ns: phase of 1 + 0.5 exp(-j w 2ns)
    w = 2 * np.pi * f
    phasor = np.exp(-1j * w * tau0) * (1 + 0.5 * np.exp(-1j * w * 2e-9))
    phase, rng = ranging_error(phasor, tau0, f)
    expected = np.angle(1 + 0.5 * np.exp(-1j * w * 2e-9))
    assert phase == pytest.approx(np.degrees(expected))
    assert rng == pytest.approx(-299_792_458.0 * expected / w)
    assert 0 < rng < 0.2  # a later echo makes the range look longer, by less than 1/3 of 60 cm


# ----------------------------------------------------------------------------- seeds, parallel
def test_seed_and_parallel_runs_are_identical(tmp_path):
    scene = load_scene(ROOMS / "office.toml")
    scene = scene.with_receivers(scene.receivers[:18])
    kw = dict(method="montecarlo", bounces=2, rays=1000, seed=7)
    serial = simulate(scene, **kw)
    again = simulate(scene, **kw)
    pooled = simulate(scene, workers=2, **kw)
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        dasked = simulate(scene, scheduler=client, **kw)
    other = simulate(scene, **(kw | {"seed": 8}))
    for key, link in serial.links.items():
        for res in (again, pooled, dasked):
            np.testing.assert_array_equal(link.power_w, res.links[key].power_w)
            np.testing.assert_array_equal(link.hist, res.links[key].hist)
        assert not np.array_equal(link.power_w[1:], other.links[key].power_w[1:])


# ----------------------------------------------------------------------------- scenes and files
BASE = {
    "room": {"size_m": [4, 4, 3], "materials": {"walls": "lambertian(0.8)", "floor": "lambertian(0.3)",
                                                "ceiling": "lambertian(0.8)"}},
    "emitter": [{"position_m": [2, 2, 3], "direction": [0, 0, -1], "lambertian_order": 1}],
    "receiver": [{"position_m": [1, 1, 0], "direction": [0, 0, 1]}],
}


@pytest.mark.parametrize("patch, message", [
    ({"room": {"size_m": [4, 4], "materials": BASE["room"]["materials"]}}, "size_m must be 3 numbers"),
    ({"emitter": [{"position_m": [2, 2, 3.5], "direction": [0, 0, -1], "lambertian_order": 1}]},
     "outside the room"),
    ({"emitter": [{"position_m": [2, 2, 3], "direction": [0, 0, -1]}]}, "exactly one of lambertian_order"),
    ({"receiver": [{"position_m": [1, 1, 0], "fov_deg": 120}]}, r"fov_deg must be .*<= 90"),
    ({"room": {"size_m": [4, 4, 3], "materials": {"walls": "marble"}}}, "unknown material 'marble'"),
    ({"room": {"size_m": [4, 4, 3], "materials": {"walls": "lambertian(1.4)", "floor": "lambertian(0.3)",
                                                  "ceiling": "lambertian(0.8)"}}}, r"in \[0, 1\]"),
    ({"receivr": []}, "did you mean 'receiver'"),
    ({"simulation": {"method": "raytrace"}}, "method must be one of"),
])
def test_scene_errors_are_one_line(patch, message):
    with pytest.raises(IrreflectError, match=message) as info:
        scene_from_dict(BASE | patch, path="bad.toml")
    assert "\n" not in str(info.value)
    assert str(info.value).startswith("bad.toml: ")


def test_material_file_round_trip(tmp_path):
    from irreflect.cli import main

    out = tmp_path / "mat.json"
    assert main(["fit", str(ROOT / "datasets" / "terrazzo.csv"), "--save", str(out),
                 "--reflectance", "0.4", "--wavelength", "850", "--notes", "test"]) == 0
    doc = json.loads(out.read_text())
    assert doc["format"] == "irreflect-material" and doc["format_version"] == 1
    assert doc["reflectance"] == 0.4 and doc["wavelength_nm"] == 850.0
    assert set(doc["stderr"]) == set(doc["params"]) and doc["r2"] > 0.98
    mat = load_material(out)
    assert mat.reflectance == 0.4 and mat.model == "two-lobe"
    assert mat.params["u_ns"] == pytest.approx(doc["params"]["u_ns"])
    # no reflectance anywhere: refused with the fix
    doc["reflectance"] = None
    out.write_text(json.dumps(doc))
    with pytest.raises(IrreflectError, match="gives no total reflectance"):
        load_material(out)


def test_room_cli_writes_results_and_refuses_bad_input(tmp_path, capsys):
    from irreflect.cli import main

    out = tmp_path / "room"
    code = main(["room", str(ROOMS / "office.toml"), "--out", str(out), "--rays", "500",
                 "--bounces", "2", "--quiet"])
    assert code == 0
    text = capsys.readouterr().out
    assert "beacon -> barry_A" in text and "range error" in text
    import pandas as pd

    summary = pd.read_parquet(out / "summary.parquet")
    assert len(summary) == 103
    assert {"dc_gain_total", "dc_gain_b1", "dc_gain_b2", "rms_delay_spread_ns",
            "range_error_m", "phase_error_deg"} <= set(summary.columns)
    assert (summary.dc_gain_total > 0).all()
    assert (out / "map_range_error_m_desk_plane_beacon.png").exists()
    run = json.loads((out / "run.json").read_text())
    assert run["rays_per_link"] == 500 and run["seed"] == 0
    # bad scene: exit 2, one line, nothing written
    bad = tmp_path / "bad.toml"
    bad.write_text("[room]\nsize_m = [4, 4, 3]\n")
    target = tmp_path / "never"
    assert main(["room", str(bad), "--out", str(target)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "missing key" in err and "Traceback" not in err
    assert not target.exists()


def test_report_room_section(tmp_path):
    from irreflect.report import ReportContext
    from irreflect.report.room import section as room_section

    ctx = ReportContext(datasets={}, fits={}, out_dir=tmp_path, quick=True,
                        scene=ROOMS / "office.toml")
    section = room_section(ctx)
    comp = section.tables["room_comparison"]
    lam = comp[comp.surfaces.str.startswith("Lambertian")]
    assert (lam["d DC gain vs Lambertian %"] == 0).all()
    assert comp["range error (cm)"].notna().all() and (comp["range error (cm)"] > 0).all()
    barry = section.tables["room_barry_a"]
    assert barry.loc[0, "closed form"] == pytest.approx(1.2318e-6, rel=1e-4)
    one = section.tables["room_one_bounce"]
    assert abs(one["relative error"]).is_monotonic_decreasing
    for key in ("room_impulse", "room_map_range_change"):
        assert Path(section.figures[key]).exists()
    for name in ("room_scene", "room_comparison", "room_barry_a", "room_checks"):
        assert "{table:" + name + "}" in section.markdown


def test_reproduce_refuses_a_bad_scene_first(tmp_path, capsys):
    from irreflect.cli import main

    bad = tmp_path / "bad.toml"
    bad.write_text("[room]\nsize_m = [4, 4, 3]\n")
    assert main(["reproduce", "--quick", "--out", str(tmp_path / "out"), "--no-progress",
                 "--scene", str(bad)]) == 2
    assert "missing key" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
