"""Every figure kind, drawn on a glossy and on a matte set, checked from its drawn artists:
no legend over data or captions, every marker kind named in a legend (or a colour bar for
colour-mapped markers), units on every axis label, and no two panels of a figure alike.
Then the cases found by reading the figures (issue 25), one by one.
"""

from __future__ import annotations

import re
import tomllib

import matplotlib
import matplotlib.colors as mcolors
import numpy as np
import pytest
from matplotlib.collections import PathCollection, QuadMesh
from matplotlib.container import BarContainer
from matplotlib.lines import Line2D
from matplotlib.patches import Rectangle
from matplotlib.transforms import Bbox

from irreflect.compare import compare_models
from irreflect.data import bundled_dir, load_bundled
from irreflect.diagnose import diagnose
from irreflect.fitting import fit
from irreflect.plots import (
    plot_polar,
    plot_polar_per_gamma,
    plot_residual_histogram,
    plot_residual_map,
    plot_surface,
    plt,
)
from irreflect.plots.compare import plot_comparison_polar, plot_error_lines, plot_errors_per_gamma
from irreflect.plots.diagnose import (
    plot_diagnosis_polar,
    plot_diagnosis_residuals,
    plot_residual_maps,
)
from irreflect.plots.protocol import plot_protocol
from irreflect.plots.room import (
    plot_bounce_gains,
    plot_impulse_response,
    plot_map,
    plot_material_3d,
)
from irreflect.plots.selection import plot_points, plot_selection
from irreflect.protocol import paper_protocol
from irreflect.protocol.points import protocol_points_mask
from irreflect.room.engine import simulate
from irreflect.room.results import summary_table
from irreflect.room.scene import scene_from_dict
from irreflect.selection.run import compare_methods, run_selection
from irreflect.synthetic import synthetic_material

#: A unit (or an explicit "unitless"/count) in parentheses, as every axis label must carry.
UNIT = re.compile(r"\([^()]*(?:%|(?<![\w/])(?:deg|m|ns|1/ns|1/sr|W/W|W|points|count|sigmas?|"
                  r"unitless|order|table's power units)(?![\w/]))[^()]*\)")


# ----------------------------------------------------------------------------- the sets
def _glossy():
    meas = synthetic_material(7, "glossy", grid="paper").measurements
    return meas


def _matte():
    return load_bundled("terrazzo")


SETS = {"glossy": _glossy, "matte": _matte}


def _room_scene(kind: str):
    doc = tomllib.loads((bundled_dir() / "rooms" / "office.toml").read_text())
    doc["receiver_grid"][0]["n"] = [4, 4]
    doc["simulation"]["rays"] = 300
    if kind == "glossy":  # a glossy floor: a narrow specular lobe, little diffuse share
        doc["materials"]["terrazzo"] = {
            "model": "two-lobe", "reflectance": 0.3,
            "params": {"u_as": 0.6, "v_as": 0.2, "u_nd": 1.0, "v_nd": 0.1, "u_ns": 3000.0,
                       "v_ns": 0.0, "K": 1.0}}
    return scene_from_dict(doc, str(bundled_dir() / "rooms" / "office.toml"))


def _figures(kind: str) -> dict:
    """Every figure kind irreflect draws, on one set."""
    meas = SETS[kind]()
    full = fit(meas, seed=0)
    figs = {}
    figs["polar"] = plot_polar(meas, full.predict, title=f"{kind}: fit").figure
    figs["polar_per_gamma"] = plot_polar_per_gamma(
        meas, {"fit on all points": full.predict}, title=f"{kind}: per gamma")
    figs["surface"] = plot_surface(meas, full.predict, title=kind).figure
    resid = meas.power - full.predict(meas.gamma_deg, meas.theta_deg)
    figs["residual_map"] = plot_residual_map(meas.gamma_deg, meas.theta_deg, resid,
                                             title=kind, label="measured - model "
                                             "(table's power units)").figure
    figs["histogram"] = plot_residual_histogram(100 * resid / meas.power.max(), title=kind,
                                                robust=True).figure
    res = run_selection(meas, "two-lobe", pop_size=16, generations=6, max_points=20, seed=0)
    methods = compare_methods(meas, res, "two-lobe", seed=0, full_fit=full)
    try:
        mask = protocol_points_mask(meas)
    except ValueError:
        mask = None
    figs["selection"] = plot_selection(res, methods=methods, protocol_mask=mask)
    figs["points"] = plot_points(meas, {"best 12": res.best_mask(12)}, title=kind).figure
    figs["protocol"] = plot_protocol(paper_protocol([-20, -40, -60]), meas, title=kind).figure
    comp = compare_models(meas, ["two-lobe", "phong", "lafortune", "phong@20"], seed=0,
                          skip_failures=True)
    figs["compare_polar"] = plot_comparison_polar(comp)
    figs["compare_errors"] = plot_errors_per_gamma(comp).figure
    near = compare_models(meas.subset(np.abs(meas.gamma_deg) <= 40), ["two-lobe", "phong"],
                          seed=0, skip_failures=True)
    figs["compare_error_lines"] = plot_error_lines({kind: comp, f"{kind}, |gamma| <= 40": near})
    diag = diagnose(meas, max_effects=1, seed=0)
    figs["diagnose_residuals"] = plot_diagnosis_residuals({kind: diag})
    figs["diagnose_maps"] = plot_residual_maps(diag)
    figs["diagnose_polar"] = plot_diagnosis_polar(diag, meas)
    scene = _room_scene(kind)
    room = simulate(scene, method="montecarlo", bounces=2, rays=300, seed=0)
    summary = summary_table(room)
    singles = [i for i, r in enumerate(scene.receivers) if r.grid is None]
    figs["impulse"] = plot_impulse_response(room, 0, 0).figure
    figs["bounce_gains"] = plot_bounce_gains(room, 0, singles).figure
    figs["room_map"] = plot_map(room, summary, scene.grids[0], "range_error_m",
                                scene.emitters[0].name, label="range error (m)").figure
    figs["material_3d"] = plot_material_3d(scene.materials["terrazzo"], 50.0).figure
    return figs


@pytest.fixture(scope="module", params=list(SETS))
def figures(request):
    with matplotlib.rc_context({"figure.max_open_warning": 0}):  # all open at once here
        figs = _figures(request.param)
        for fig in figs.values():
            fig.canvas.draw()
        yield request.param, figs
        for fig in figs.values():
            plt.close(fig)


# ----------------------------------------------------------------------------- artists
def _legends(fig) -> list:
    out = list(fig.legends)
    out += [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    return out


def _data_axes(fig) -> list:
    """Axes that show data (not colour bars, not text-only cells)."""
    out = []
    for ax in fig.axes:
        if not ax.axison and ax.name != "3d":
            continue
        if ax.get_label() == "<colorbar>":
            continue
        if ax.get_lines() or ax.collections or ax.patches or ax.images:
            out.append(ax)
    return out


def _points(artist) -> np.ndarray:
    """Display coordinates of an artist's data (lines interpolated along their path)."""
    if isinstance(artist, Line2D):
        if not artist.get_visible() or len(artist.get_xdata()) == 0:
            return np.empty((0, 2))
        path = artist.get_path()
        if artist.get_linestyle() not in ("None", "", " ") and len(path.vertices) > 1:
            path = path.interpolated(20)
        return artist.get_transform().transform(path.vertices)
    if isinstance(artist, PathCollection):
        offsets = np.asarray(artist.get_offsets(), float)
        if offsets.size == 0:
            return np.empty((0, 2))
        return artist.get_offset_transform().transform(offsets)
    return np.empty((0, 2))


def _texts(fig, legends) -> list:
    """Every caption of the figure: titles, axis and tick labels, colour bar labels,
    annotations, figure texts (not the legends' own)."""
    own = {id(t) for lg in legends for t in [*lg.get_texts(), lg.get_title()]}
    texts = list(fig.texts) + ([fig._suptitle] if fig._suptitle is not None else [])
    for ax in fig.axes:
        if not ax.get_visible():
            continue
        texts += [ax.title, ax._left_title, ax._right_title, ax.xaxis.label, ax.yaxis.label]
        texts += list(ax.texts)
        if ax.name != "polar":
            texts += list(ax.get_xticklabels()) + list(ax.get_yticklabels())
        if ax.name == "3d":
            texts += [ax.zaxis.label]
    return [t for t in texts if t.get_visible() and t.get_text().strip() and id(t) not in own]


def _shrunk(bbox: Bbox, px: float = 1.5) -> Bbox:
    return Bbox.from_extents(bbox.x0 + px, bbox.y0 + px, bbox.x1 - px, bbox.y1 - px)


def _marker_key(artist) -> tuple | None:
    if isinstance(artist, Line2D):
        marker = artist.get_marker()
        if marker in (None, "None", "", " ") or not len(artist.get_xdata()):
            return None
        face = artist.get_markerfacecolor()
        colour = artist.get_markeredgecolor() if (isinstance(face, str) and face == "none") \
            else face
        return ("line", str(marker), mcolors.to_hex(colour))
    if isinstance(artist, PathCollection) and artist.get_array() is None:
        colours = artist.get_facecolor()
        if len(colours) == 0 or not len(artist.get_offsets()):
            return None
        return ("collection", mcolors.to_hex(colours[0]))
    return None


def _drawn_marker_kinds(fig) -> dict:
    kinds = {}
    for ax in fig.axes:
        for artist in [*ax.get_lines(), *ax.collections]:
            key = _marker_key(artist)
            if key is not None and artist.get_visible():
                kinds.setdefault(key, f"{ax.get_title()!r}: {artist.get_label()!r}")
        for patch in ax.patches:  # outlines drawn as symbols (a box seen from above)
            if isinstance(patch, Rectangle) and not patch.get_fill() and patch.get_visible():
                kinds.setdefault(("outline", mcolors.to_hex(patch.get_edgecolor())),
                                 f"{ax.get_title()!r}: an outline")
    return kinds


def _legend_marker_kinds(fig) -> set:
    kinds = set()
    for legend in _legends(fig):
        for artist in legend.findobj(Line2D) + legend.findobj(PathCollection):
            key = _marker_key(artist)
            if key is not None:
                kinds.add(key)
        for patch in legend.findobj(Rectangle):
            if not patch.get_fill():
                kinds.add(("outline", mcolors.to_hex(patch.get_edgecolor())))
    return kinds


def _signature(ax) -> tuple:
    parts = []
    for line in ax.get_lines():
        parts.append(np.round(np.asarray(line.get_xydata(), float), 9).tobytes())
    for coll in ax.collections:
        if isinstance(coll, PathCollection):
            parts.append(np.round(np.asarray(coll.get_offsets(), float), 9).tobytes())
            if coll.get_array() is not None:
                parts.append(np.round(np.asarray(coll.get_array(), float), 9).tobytes())
        elif isinstance(coll, QuadMesh):
            parts.append(np.round(np.asarray(coll.get_array(), float), 9).tobytes())
    return tuple(sorted(parts))


# ----------------------------------------------------------------------------- generic checks
def test_no_legend_covers_data_or_a_caption(figures):
    kind, figs = figures
    problems = []
    for name, fig in figs.items():
        renderer = fig.canvas.get_renderer()
        legends = _legends(fig)
        texts = _texts(fig, legends)
        for legend in legends:
            box = _shrunk(legend.get_window_extent(renderer))
            for text in texts:
                if box.overlaps(text.get_window_extent(renderer)):
                    problems.append(f"{name}: legend over the caption {text.get_text()!r}")
            for ax in _data_axes(fig):
                frame = ax.get_window_extent(renderer)  # what lies outside is clipped away
                for artist in [*ax.get_lines(), *ax.collections]:
                    pts = _points(artist)
                    if len(pts) and artist.get_clip_on():
                        pts = pts[(pts[:, 0] >= frame.x0) & (pts[:, 0] <= frame.x1)
                                  & (pts[:, 1] >= frame.y0) & (pts[:, 1] <= frame.y1)]
                    inside = ((pts[:, 0] > box.x0) & (pts[:, 0] < box.x1)
                              & (pts[:, 1] > box.y0) & (pts[:, 1] < box.y1)) if len(pts) else []
                    if np.any(inside):
                        problems.append(f"{name}: legend over {artist.get_label()!r} "
                                        f"({int(np.sum(inside))} points)")
                for coll in ax.collections:
                    if isinstance(coll, QuadMesh) and box.overlaps(
                            coll.get_window_extent(renderer)):
                        problems.append(f"{name}: legend over the colour map")
    assert not problems, f"{kind}: {problems}"


def test_every_marker_kind_is_in_a_legend(figures):
    kind, figs = figures
    problems = []
    for name, fig in figs.items():
        drawn = _drawn_marker_kinds(fig)
        named = _legend_marker_kinds(fig)
        problems += [f"{name}: {where} {key}" for key, where in drawn.items()
                     if key not in named]
        for ax in fig.axes:  # colour-mapped markers are explained by a colour bar
            if ax.get_label() == "<colorbar>":
                continue
            for coll in ax.collections:
                if isinstance(coll, PathCollection | QuadMesh) and coll.get_array() is not None:
                    if getattr(coll, "colorbar", None) is None:
                        problems.append(f"{name}: colour-mapped data without a colour bar")
    assert not problems, f"{kind}: {problems}"


def test_every_axis_label_carries_a_unit(figures):
    kind, figs = figures
    problems = []
    for name, fig in figs.items():
        captions = " ".join([lg.get_title().get_text() for lg in _legends(fig)]
                            + ([fig._suptitle.get_text()] if fig._suptitle else []))
        for ax in fig.axes:
            if not ax.get_visible() or (not ax.axison and ax.name != "3d"):
                continue
            if ax.name == "polar":  # the caption: angle and radius with their units
                if not (re.search(r"theta \(deg\)", captions)
                        and re.search(r"radius: \w+ \(", captions)
                        and UNIT.search(captions.split("radius:", 1)[1])):
                    problems.append(f"{name}: polar axes without angle and radius units")
                continue
            if ax.get_label() == "<colorbar>":
                labels = [ax.get_ylabel() or ax.get_xlabel()]
            else:
                labels = [ax.get_xlabel(), ax.get_ylabel()]
                if ax.name == "3d":
                    labels.append(ax.get_zlabel())
            problems += [f"{name}: axis label {label!r}" for label in labels
                         if not UNIT.search(label or "")]
    assert not problems, f"{kind}: {problems}"


def test_no_two_panels_of_a_figure_are_alike(figures):
    kind, figs = figures
    problems = []
    for name, fig in figs.items():
        seen = {}
        for ax in _data_axes(fig):
            sig = _signature(ax)
            if sig and sig in seen:
                problems.append(f"{name}: {ax.get_title()!r} repeats {seen[sig]!r}")
            seen.setdefault(sig, ax.get_title())
    assert not problems, f"{kind}: {problems}"


# ----------------------------------------------------------------------------- the cases
def test_polar_radius_is_logarithmic_where_the_dynamic_range_exceeds_100():
    from irreflect.plots.common import dynamic_range

    glossy, matte = _glossy(), _matte()
    assert dynamic_range(glossy.power) > 100 > dynamic_range(matte.power)
    assert plot_polar(glossy).get_yscale() == "log"
    assert plot_polar(matte).get_yscale() == "linear"
    assert plot_polar(matte, radius="log").get_yscale() == "log"
    assert plot_polar(glossy, radius="linear").get_yscale() == "linear"
    plt.close("all")


def test_polar_flags_negative_power_and_an_unmeasured_model_peak():
    meas = _matte()
    sel = meas.gamma_deg == -30
    th = np.unique(meas.theta_deg[sel])
    gap = th[np.argmax(np.diff(th))] + np.diff(th).max() / 2  # between two receivers

    def spiky(g, t):
        t = np.asarray(t, float)
        return 0.1 + 0.9 * np.exp(-0.5 * ((t - gap) / 0.5) ** 2) * (np.asarray(g) == -30) \
            - 0.3 * (t < -60)

    ax = plot_polar(meas, spiky)
    labels = ax.get_legend_handles_labels()[1]
    assert any("power < 0" in lb for lb in labels)
    assert any("no measured point near it" in lb for lb in labels)
    diamonds = [ln for ln in ax.get_lines() if ln.get_marker() == "D"]
    assert len(diamonds) == 1 and np.degrees(diamonds[0].get_xdata()[0]) == pytest.approx(
        gap, abs=0.3)
    ax = plot_polar(meas, lambda g, t: 0.1 + 0 * np.asarray(t))  # nothing to flag
    assert not [ln for ln in ax.get_lines() if ln.get_marker() in ("v", "D")]
    fig = plot_polar_per_gamma(meas, {"12-point fit": spiky})
    titles = [a.get_title() for a in fig.axes if a.name == "polar"]
    assert sum("power < 0" in t for t in titles) == len(titles)  # t < -60 at every gamma
    plt.close("all")


def test_polar_flags_readings_it_cannot_draw_at_their_value():
    # zero and negative readings (noise around zero) sat at the centre unflagged
    import dataclasses

    glossy = _glossy()
    power = glossy.power.copy()
    lows = np.flatnonzero(glossy.gamma_deg == glossy.gammas[0])[:3]
    power[lows] = [0.0, -1e-4, 0.0]
    meas = dataclasses.replace(glossy, power=power)
    for radius, word in (("log", "below the radius' floor or <= 0"), ("linear", "< 0")):
        ax = plot_polar(meas, radius=radius)
        flagged = [ln for ln in ax.get_lines() if ln.get_label().startswith("measured ")
                   and word in ln.get_label()]
        assert len(flagged) == 1 and flagged[0].get_markerfacecolor() == "none"
        assert len(flagged[0].get_xdata()) == (3 if radius == "log" else 1)
    fig = plot_polar_per_gamma(meas, {}, radius="log")
    assert "measured below the radius' floor or <= 0 (drawn at the centre, open)" in [
        t.get_text() for t in fig.legends[0].get_texts()]
    assert plot_polar(glossy, radius="log").get_lines()[0].get_label().startswith("gamma")
    assert not [ln for ln in plot_polar(glossy, radius="log").get_lines()
                if ln.get_label().startswith("measured ")]
    plt.close("all")


def test_selection_shows_the_ideal_point_over_the_knee_and_the_threshold_in_its_axis():
    meas = _matte()
    res = run_selection(meas, "two-lobe", pop_size=16, generations=6, max_points=20, seed=0)
    fig = plot_selection(res)
    ax = fig.axes[0]
    lines = {ln.get_label(): ln for ln in ax.get_lines()}
    ideal = next(ln for lb, ln in lines.items() if lb.startswith("ideal point"))
    knee = next(ln for lb, ln in lines.items() if lb.startswith("knee"))
    assert ideal.get_zorder() > max(ln.get_zorder() for ln in ax.get_lines() if ln is not ideal)
    assert ideal.get_marker() != knee.get_marker() and knee.get_markerfacecolor() == "none"
    assert ideal.get_markersize() < knee.get_markersize()
    threshold = next(lb for lb in lines if lb.startswith("enough-points threshold"))
    value = float(re.search(r"1 - R² = ([0-9.e+-]+)", threshold).group(1))
    assert value == pytest.approx(res.enough.threshold_one_minus_r2(meas.power), rel=1e-3)
    assert "RMSE" in threshold and "1 - R" in ax.get_ylabel()
    plt.close("all")


def test_diagnosis_figure_has_no_copy_of_a_panel_when_nothing_was_added():
    meas = load_bundled("plasterboard")  # the two-lobe model plus noise: nothing to add
    diag = diagnose(meas, seed=0)
    assert len(diag.steps) == 1
    fig = plot_diagnosis_residuals({"plasterboard": diag})
    assert len(_data_axes(fig)) == 1
    assert any("no effect added" in t.get_text() for ax in fig.axes for t in ax.texts)
    assert len(_data_axes(plot_residual_maps(diag))) == 1
    plt.close("all")


def test_room_map_names_emitter_and_box_and_gains_are_points_not_bars():
    scene = _room_scene("matte")
    room = simulate(scene, method="montecarlo", bounces=2, rays=300, seed=0)
    summary = summary_table(room)
    ax = plot_map(room, summary, scene.grids[0], "range_error_m", scene.emitters[0].name,
                  label="range error (m)")
    labels = ax.get_legend().get_texts()
    assert any("emitter 'beacon'" in t.get_text() for t in labels)
    assert any(t.get_text().startswith("box") for t in labels)
    singles = [i for i, r in enumerate(scene.receivers) if r.grid is None]
    ax = plot_bounce_gains(room, 0, singles)
    assert not [c for c in ax.containers if isinstance(c, BarContainer)]
    assert not [p for p in ax.patches if isinstance(p, Rectangle)]
    markers = {ln.get_marker() for ln in ax.get_lines()} - {"None", "", None, "_"}  # caps
    assert len(markers) == len(singles)
    plt.close("all")


@pytest.mark.parametrize("n", [[3, 1], [1, 3], [1, 1]])
def test_a_room_map_one_receiver_wide_draws_its_receivers(n):
    # pcolormesh has no cell to shade on a grid one receiver wide: the map was empty
    doc = tomllib.loads((bundled_dir() / "rooms" / "office.toml").read_text())
    doc["receiver_grid"][0]["n"] = n
    doc["simulation"]["rays"] = 100
    scene = scene_from_dict(doc, str(bundled_dir() / "rooms" / "office.toml"))
    room = simulate(scene, method="montecarlo", bounces=1, rays=100, seed=0)
    summary = summary_table(room)
    ax = plot_map(room, summary, scene.grids[0], "dc_gain_total", scene.emitters[0].name)
    drawn = [c for c in ax.collections if np.size(c.get_array()) > 0]
    assert len(drawn) == 1 and np.size(drawn[0].get_array()) == n[0] * n[1]
    assert np.all(np.isfinite(np.asarray(drawn[0].get_array(), float)))
    c = drawn[0]
    if hasattr(c, "get_coordinates"):  # shaded cells: each of some width and height
        xy = c.get_coordinates()
        assert np.all(np.diff(xy[..., 0], axis=1) > 0) and np.all(np.diff(xy[..., 1], axis=0) > 0)
    else:  # markers: each of some size
        assert np.all(c.get_sizes() > 0)
    plt.close("all")


def test_checks_catch_what_they_are_for():
    """The checks above fail on figures made to break them."""
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1], "o", label="data")
    ax.plot([0.5], [0.5], "s", color="tab:red")  # no label: not in the legend
    ax.legend(loc="center", fontsize=30)  # over the data
    ax.set_xlabel("x")
    fig.canvas.draw()
    figs = {"broken": fig}
    with pytest.raises(AssertionError, match="legend over"):
        test_no_legend_covers_data_or_a_caption(("broken", figs))
    with pytest.raises(AssertionError, match="broken"):
        test_every_marker_kind_is_in_a_legend(("broken", figs))
    with pytest.raises(AssertionError, match="axis label 'x'"):
        test_every_axis_label_carries_a_unit(("broken", figs))
    fig2, (a1, a2) = plt.subplots(1, 2)
    for a in (a1, a2):
        a.plot([0, 1], [2, 3])
    fig2.canvas.draw()
    with pytest.raises(AssertionError, match="repeats"):
        test_no_two_panels_of_a_figure_are_alike(("pair", {"pair": fig2}))
    plt.close("all")
    assert matplotlib.get_backend().lower() == "agg"


def test_a_log_radius_of_less_than_two_decades_has_three_readable_labels():
    # matplotlib's log labels overprinted each other ('4x3x10^-1...') on a table whose power
    # spans less than a decade
    meas = load_bundled("terrazzo")
    ax = plot_polar(meas, radius="log")
    fig = ax.figure
    fig.canvas.draw()
    low, high = ax.get_ylim()
    shown = [(loc, t.get_text()) for loc, t in zip(ax.yaxis.get_majorticklocs(),
                                                   ax.yaxis.get_majorticklabels(), strict=True)
             if t.get_text() and low <= loc <= high]
    assert len(shown) == 3, shown  # three labels inside the radius drawn, not one
    assert not [t for t in ax.yaxis.get_minorticklabels() if t.get_text()]
    plt.close("all")


@pytest.mark.parametrize("radius", ["log", "linear"])
def test_a_panel_whose_readings_are_all_zero_or_negative_is_drawn(radius):
    # plot_polar_per_gamma (diagnose's polar_fits.png) stopped with 'Geometric sequence
    # cannot include zero' when one angle of incidence read only zeros on a log radius
    from irreflect.data import Measurements

    theta = np.arange(-70.0, 71.0, 10.0)
    lobe = 1e-4 * np.exp(-0.5 * ((theta - 30.0) / 8.0) ** 2) + 1e-8
    gamma = np.repeat([-30.0, -80.0, -60.0], theta.size)
    power = np.concatenate([lobe, np.zeros(theta.size), np.full(theta.size, -1e-9)])
    meas = Measurements(gamma, np.tile(theta, 3), power)
    fig = plot_polar_per_gamma(meas, {"fit": lambda g, t: 1e-6 + 0 * np.asarray(t)},
                               radius=radius)
    panels = {a.get_title(): a for a in fig.axes if a.name == "polar"}
    full = panels["gamma = -30 deg"].get_ylim()
    for title in ("gamma = -80 deg", "gamma = -60 deg"):
        low, high = panels[title].get_ylim()
        assert panels[title].get_yscale() == radius
        assert (low, high) == pytest.approx(full)  # the table's radius, not an empty one
    assert full[1] == pytest.approx(1e-4 * (1.6 if radius == "log" else 1.25), rel=0.01)
    plt.close("all")
