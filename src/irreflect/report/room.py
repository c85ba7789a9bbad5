"""The room section of the reproduction report (``irreflect reproduce --scene SCENE.toml``).

It shows what the paper is for: the scene's room simulated with Lambertian surfaces of the
same total reflectance, with the fitted two-lobe materials, and with a glossy real material
(fitted from ``../shared/datasets/real`` when present) as floor; then a validation page
(line of sight against the closed form, one bounce against numerical integration, Barry's
configuration A with the recursive method and Monte Carlo, swapped links, every order against
Monte Carlo in Lambertian and glossy rooms, energy).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..fitting import fit
from ..paper import real_data_dir
from ..plots.room import plot_bounce_gains, plot_impulse_response, plot_map, plot_material_3d, save
from ..room.checks import material_notes
from ..room.engine import simulate
from ..room.materials import from_model
from ..room.results import safe_name, summary_table
from ..room.scene import load_scene
from ..room.validation import (
    barry_configuration_a,
    glossy_material,
    glossy_room,
    line_of_sight_closed_form,
    one_bounce_reference,
    single_floor_scene,
    swap_ready,
)
from .base import ReportContext, Section

TITLE = "Room multipath from the fitted materials: DC gain, delay spread and range error"
#: Barry's configuration A, 3 bounces, 0.125 m cells, from vlc-rm (PyPI) run by
#: experiments/bench_room.py (an independent implementation; not run by the report)
VLCRM_A_0125 = (1.2318e-06, 5.0568e-07, 4.3237e-07, 2.6319e-07)
GLOSSY_CANDIDATES = ("cornell/cornell_krylon_blue.csv", "rgl_epfl/rgl_satin_rosaline.csv")


def _shared_real() -> Path | None:
    return real_data_dir()


def glossy_floor(rho: float):
    """A glossy real material (two-lobe fit of a measured medium-gloss paint) with total
    reflectance ``rho``, or (None, reason) when the real data are not beside the checkout."""
    real = _shared_real()
    if real is None:
        return None, "the real data (../shared/datasets/real) are not beside this checkout"
    for rel in GLOSSY_CANDIDATES:
        path = real / rel
        if path.exists():
            res = fit(str(path), "two-lobe", seed=0)
            params = dict(zip(res.param_names, map(float, res.values), strict=True))
            gmax = float(np.max(np.abs(res.gamma_deg)))
            mat = from_model("two-lobe", params, rho, name="glossy floor",
                             source=f"{path.name} (two-lobe fit, R^2 {res.r2:.3f})",
                             gamma_max_deg=gmax)
            return mat, f"{path.name} (R^2 {res.r2:.3f})"
    return None, "no glossy real table found"


def _variants(scene, quick):
    out = [("Lambertian (same reflectances)", scene.lambertian_equivalent()),
           ("fitted materials (scene as given)", scene)]
    floor = scene.room_materials[4]
    rho = scene.materials[floor].reflectance
    note = ""
    if rho is not None:
        mat, note = glossy_floor(rho)
        if mat is not None:
            out.append((f"fitted + glossy real floor ({note})",
                        scene.with_materials({floor: mat}, name=f"{scene.name} (glossy floor)")))
    return out, note


@dataclass(frozen=True)
class RoomResults:
    """What the room section found (computed by :func:`compute`, written out by
    :func:`render`): the scene and its simulation settings, what its materials' files
    say of their fits, the scene's and the materials' table rows, every surface variant's
    simulation ``(label, result, summary)``, why there is no glossy floor (when there is
    none), the comparison rows and the validation page's tables and numbers."""

    scene: object
    rays: int
    bounces: int
    notes: list
    scene_rows: list
    materials: pd.DataFrame
    results: list
    glossy_note: str
    rows: list
    validation: Validation


def section(ctx: ReportContext) -> Section:
    """The scene's room with Lambertian, fitted and glossy-floor surfaces, and the
    validation page (``ctx.scene``: the scene's TOML file)."""
    return render(ctx, compute(ctx))


def compute(ctx: ReportContext) -> RoomResults:
    """Simulate the scene's room with every surface variant and run the validation."""
    if ctx.scene is None:
        raise ValueError("the room section needs a scene: ReportContext(scene=SCENE.toml)")
    scene = load_scene(ctx.scene)
    rays = 1500 if ctx.quick else int(scene.settings.get("rays", 20000))
    bounces = int(scene.settings.get("bounces", 3))
    notes = material_notes(scene, ctx.allow_unphysical)
    scene_rows = _scene_rows(scene)
    materials = materials_table(scene)
    variants, glossy_note = _variants(scene, ctx.quick)
    results = []
    for label, variant in variants:
        ctx.progress(f"room: {label}")  # whole: a line per step through a pipe
        res = simulate(variant, method="montecarlo", bounces=bounces, rays=rays, seed=ctx.seed)
        results.append((label, res, summary_table(res)))
    rows = _comparison_rows(scene, results)
    ctx.progress("room: validation")
    return RoomResults(scene, rays, bounces, notes, scene_rows, materials, results,
                       glossy_note, rows, validation(ctx.quick))


def render(ctx: ReportContext, res: RoomResults) -> Section:
    """The room section from its results: tables, figures and the markdown."""
    scene = res.scene
    tables, figures, md = {}, {}, []
    if res.notes:  # what the materials' own fits said of them
        md.append("What the scene's materials say of their own fits (their material files' "
                  "verdicts and warnings, `irreflect fit --save`):\n\n```\n"
                  + "\n".join(res.notes) + "\n```\n")
    tables["room_scene"] = pd.DataFrame(res.scene_rows)
    tables["room_materials"] = res.materials
    md.append(_scene_markdown(ctx, scene, (res.rays, res.bounces), figures))
    tables["room_comparison"] = pd.DataFrame(res.rows)
    md.append("### What the fitted materials change\n\nThe same room three ways: every surface "
              "Lambertian with the scene's total reflectance; the fitted two-lobe materials; and "
              "the fitted materials with a glossy real material as floor (same total reflectance, "
              "its measured angular shape). Range error: phase-based ranging at the emitter's "
              "modulation frequency, multipath phasor against the geometric line of sight "
              "(positive = the range looks longer). Monte Carlo standard errors are in "
              "`irreflect room`'s outputs (about 1 % of the reflected gain per order at 20000 "
              "rays).\n\n{table:room_comparison}\n\n")
    if len(res.results) < 3:
        md.append(f"*No glossy real floor: {res.glossy_note}.*\n\n")
    md.append(_result_figures(ctx, scene, res.results, figures))
    tables.update(res.validation.tables)
    md.append(validation_markdown(res.validation))
    return Section("room", TITLE, "".join(md), tables, figures)


def _scene_rows(scene) -> list:
    """The scene's table: every surface with its material, source and 3D model."""
    rows = [{"surface": face, "material": name, "source": scene.materials[name].source,
             "3D model": scene.materials[name].describe()}
            for face, name in zip(("wall x=0", "wall x=max", "wall y=0", "wall y=max", "floor",
                                   "ceiling"), scene.room_materials, strict=True)]
    rows += [{"surface": f"box {b.name}", "material": b.materials[5],
              "source": scene.materials[b.materials[5]].source,
              "3D model": scene.materials[b.materials[5]].describe()} for b in scene.boxes]
    return rows


def _scene_markdown(ctx, scene, rays_bounces, figures) -> str:
    """The scene's text, the surface model's text and the materials' figures (added to
    ``figures``)."""
    rays, bounces = rays_bounces
    md = []
    md.append(f"Scene `{scene.path}`: {scene.size[0]:g} x {scene.size[1]:g} x {scene.size[2]:g} m, "
              f"{len(scene.emitters)} emitter(s), {len(scene.receivers)} receivers "
              f"({len(scene.grids)} grid(s)); Monte Carlo with next-event estimation, {rays} rays "
              f"per emitter-receiver pair, {bounces} reflections, seed {ctx.seed}.\n\n"
              "{table:room_scene}\n\n"
              "**The surface model.** The fitted models live in the plane of incidence. In the room "
              "each fitted material is a BRDF that obeys Helmholtz reciprocity by construction "
              "(f(i, o) = f(o, i)): a non-negative sum of symmetric diffuse terms, lobes of "
              "revolution about the mirror direction (the paper's specular lobe, section 3.4, "
              "with Fresnel-like weights of the half angle) and retro lobes, fitted to the "
              "material's fitted curve over its measured angles of incidence; its albedo follows "
              "the incidence as the fitted curve's does and is capped at 1. The paper's own form "
              "(its laws of the angle of incidence, normalised per incidence) is not reciprocal "
              "and is available with --brdf paper. How far the reciprocal form's in-plane curve "
              "departs from the fitted one:\n\n{table:room_materials}\n\n"
              "The polar plots show a material's intensity in the plane of incidence and in "
              "planes rotated about the normal.\n\n")
    for name, mat in scene.materials.items():
        if mat.model == "two-lobe":
            ax = plot_material_3d(mat, 50.0)
            key = f"room_material_{safe_name(name)}"
            save(ax, ctx.figure_path(key))
            figures[key] = ctx.figure_path(key)
            md.append(f"{{figure:{key}}} ")
    md.append("\n\n")

    return "".join(md)


def _comparison_rows(scene, results) -> list:
    """Per receiver (and grid mean) and surface variant: gain, reflected share, delay
    spread, range error and their change against the Lambertian room."""
    rows = []
    base = results[0][2].set_index(["emitter", "receiver"])
    for label, _res, summ in results:
        singles = summ[summ.grid == ""]
        for _, r in singles.iterrows():
            b = base.loc[(r.emitter, r.receiver)]
            rows.append({
                "receiver": r.receiver, "surfaces": label,
                "DC gain total": float(f"{r.dc_gain_total:.4g}"),
                "reflected share %": round(100 * r.dc_gain_reflected / r.dc_gain_total, 1),
                "RMS delay spread (ns)": round(r.rms_delay_spread_ns, 3),
                "range error (cm)": round(100 * r.range_error_m, 2),
                "d DC gain vs Lambertian %": round(100 * (r.dc_gain_total / b.dc_gain_total - 1), 2),
                "d range error vs Lambertian (cm)": round(100 * (r.range_error_m - b.range_error_m), 2),
            })
        for grid in scene.grids:
            sub = summ[summ.grid == grid.name]
            bsub = results[0][2][results[0][2].grid == grid.name]
            rows.append({
                "receiver": f"grid {grid.name} (mean of {len(sub)})", "surfaces": label,
                "DC gain total": float(f"{sub.dc_gain_total.mean():.4g}"),
                "reflected share %": round(100 * (sub.dc_gain_reflected / sub.dc_gain_total).mean(), 1),
                "RMS delay spread (ns)": round(sub.rms_delay_spread_ns.mean(), 3),
                "range error (cm)": round(100 * sub.range_error_m.mean(), 2),
                "d DC gain vs Lambertian %": round(100 * (sub.dc_gain_total.mean()
                                                          / bsub.dc_gain_total.mean() - 1), 2),
                "d range error vs Lambertian (cm)": round(100 * (sub.range_error_m.mean()
                                                                 - bsub.range_error_m.mean()), 2),
            })
    return rows


def _result_figures(ctx, scene, results, figures) -> str:
    """h(t) and the gains per order at the first receiver, and the first grid's maps, of
    the fitted materials (added to ``figures``); their markdown."""
    md = []
    label, res, summ = results[1]
    ax = plot_impulse_response(res, 0, 0)
    save(ax, ctx.figure_path("room_impulse"))
    figures["room_impulse"] = ctx.figure_path("room_impulse")
    singles = [i for i, r in enumerate(scene.receivers) if r.grid is None]
    if singles:
        ax = plot_bounce_gains(res, 0, singles)
        save(ax, ctx.figure_path("room_gains"))
        figures["room_gains"] = ctx.figure_path("room_gains")
    md.append("{figure:room_impulse} {figure:room_gains}\n\n")
    for grid in scene.grids[:1]:
        em = scene.emitters[0].name
        lam = results[0][2]
        diff = summ.copy()
        diff["range_error_change_cm"] = 100 * (summ.range_error_m.to_numpy()
                                               - lam.range_error_m.to_numpy())
        for key, (r_, s_, col, lab, center) in {
            "room_map_range_error": (res, summ, "range_error_m", "range error (m), fitted materials", None),
            "room_map_range_change": (res, diff, "range_error_change_cm",
                                      "range error: fitted - Lambertian (cm)", 0.0),
            "room_map_gain": (res, summ, "dc_gain_total", "DC gain, fitted materials", None),
        }.items():
            ax = plot_map(r_, s_, grid, col, em, label=lab, center=center)
            save(ax, ctx.figure_path(key))
            figures[key] = ctx.figure_path(key)
        md.append("{figure:room_map_range_error} {figure:room_map_range_change} "
                  "{figure:room_map_gain}\n\n")
    return "".join(md)


def materials_table(scene) -> pd.DataFrame:
    """Per material: surface model, terms, in-plane fidelity, albedo range, warnings."""
    rows = []
    for name, mat in scene.materials.items():
        fid = mat.fidelity
        rows.append({
            "material": name, "surface model": "Lambertian" if mat.is_lambertian else mat.brdf,
            "terms": fid.get("terms", np.nan),
            "R^2 vs fitted curve": round(fid["r2_curve"], 4) if "r2_curve" in fid else np.nan,
            "R^2 on table (reciprocal)": (round(fid["r2_table_reciprocal"], 4)
                                          if "r2_table_reciprocal" in fid else np.nan),
            "R^2 on table (paper form)": (round(fid["r2_table_paper"], 4)
                                          if "r2_table_paper" in fid else np.nan),
            "albedo over incidence": f"{mat.rho_table.min():.3g}-{mat.rho_table.max():.3g}",
            "notes": "; ".join(w.replace(f"material '{name}': ", "") for w in mat.warnings),
        })
    return pd.DataFrame(rows)


@dataclass(frozen=True)
class Validation:
    """The validation page's numbers: its tables, the closed-form line of sight of
    Barry's configuration A (W) and its delay (s), and the Monte Carlo rays per link."""

    tables: dict
    los: float
    tau: float
    rays: int


def validation_page(quick: bool):
    """Checks against what exists, as report tables (numbers measured in this run):
    (markdown, tables)."""
    checks = validation(quick)
    return validation_markdown(checks), checks.tables


def validation(quick: bool) -> Validation:
    """Run the validation page's checks (simulations against closed forms, numerical
    integration, Monte Carlo, swapped links and energy)."""
    tables = {}
    scene = barry_configuration_a()
    los, tau = line_of_sight_closed_form(scene.emitters[0], scene.receivers[0])
    cell = 0.25
    rays = 100_000 if quick else 2_000_000
    rec = simulate(scene, method="recursive", bounces=3, cell_m=cell)
    mc = simulate(scene, method="montecarlo", bounces=3, rays=rays, seed=0)
    rows = []
    for k in range(4):
        rows.append({
            "order": "LoS" if k == 0 else k,
            f"recursive {cell:g} m": float(f"{rec.link().power_w[k]:.5g}"),
            "Monte Carlo": float(f"{mc.link().power_w[k]:.5g}"),
            "MC std. error": float(f"{mc.link().stderr_w[k]:.2g}"),
            "vlc-rm 0.125 m (benchmark)": VLCRM_A_0125[k],
            "closed form": float(f"{los:.5g}") if k == 0 else np.nan,
        })
    tables["room_barry_a"] = pd.DataFrame(rows)
    floor = single_floor_scene()
    ref = one_bounce_reference(floor)
    rows = []
    for c in (0.5, 0.25) if quick else (0.5, 0.25, 0.125):
        got = simulate(floor, method="recursive", bounces=1, cell_m=c,
                       estimate_error=False).link().power_w[1]
        rows.append({"cell (m)": c, "recursive H1": float(f"{got:.6g}"),
                     "numerical integration": float(f"{ref:.6g}"),
                     "relative error": float(f"{got / ref - 1:.2e}")})
    tables["room_one_bounce"] = pd.DataFrame(rows)
    tables["room_swapped"] = swapped_table(rays)
    tables["room_convergence"] = convergence_table(rays, cell)
    tables["room_checks"] = energy_checks(rays)
    return Validation(tables, los, tau, rays)


def validation_markdown(checks: Validation) -> str:
    """The validation page's text around its tables."""
    los, tau, rays = checks.los, checks.tau, checks.rays
    return ("### Validation\n\nBarry et al. (1993), configuration A (5 x 5 x 3 m, walls and ceiling "
            "0.8, floor 0.3, emitter at the ceiling centre facing down, receiver at (0.5, 1, 0), "
            "1 cm^2, 85 deg): DC gain per order. The vlc-rm column is the independent "
            "implementation run by `.venv/bin/python experiments/bench_room.py` (not by this report) "
            "with Barry's point-to-point coupling between cells, which overestimates orders 2 and "
            "up by about 1-2 % (near cells); irreflect integrates near cell pairs. Barry's paper "
            "publishes h(t) curves, not gains; the line of sight is the closed form "
            f"(Eq. 5), {los:.5g} at {tau * 1e9:.3f} ns.\n\n{{table:room_barry_a}}\n\n"
            "One reflection off a single Lambertian floor (every other surface black): the "
            "recursive method converges to the numerical integral as the cells shrink.\n\n"
            "{table:room_one_bounce}\n\n"
            "**Swapped links.** Emitter and receiver exchanged, the same (order-1) pattern at both "
            "ends, in a room with a glossy floor and glossy walls (the two-lobe material of "
            "`irreflect.room.validation`): with a reciprocal surface model every order must come "
            "back the same; the paper's form does not.\n\n{table:room_swapped}\n\n"
            "**Every order against Monte Carlo** at the default 0.25 m cells, Lambertian and glossy "
            f"rooms, wide and narrow fields of view ({rays} rays per link; the recursive method's "
            "own estimate of its error beside it: from a run at twice the cell size, and with "
            "glossy materials that run again with a quarter of the lobe rays, whose error does "
            "not shrink with the cells; before stop 49 the estimate saw only the first, and on "
            "glossy walls the method read 0.25-0.66 % off a 4-million-ray Monte Carlo at orders "
            "2 and 3 while estimating 0.02 %; it now says 0.7-2.3 % there: a bound, about "
            "three times the error).\n\n"
            "{table:room_convergence}\n\n"
            "**Energy.** In a closed room every reflected watt lands on a surface: the recursive "
            "method's power arriving after k + 1 reflections against the power reflected at the "
            "k-th (the albedo evaluated at each cell's incidence), and Monte Carlo's power left "
            "after k reflections (its weights f cos / pdf) against the recursive method's.\n\n"
            "{table:room_checks}\n")


def swapped_table(rays: int) -> pd.DataFrame:
    """Direct and swapped links per order: recursive, Monte Carlo, and Monte Carlo with the
    paper's (non-reciprocal) form."""
    scene = swap_ready(glossy_room(walls=glossy_material(0.6), receiver_pos=(2.9, 1.1, 0.9)))
    rows = []
    for label, sc, method, kw in (
            ("recursive", scene, "recursive", {"estimate_error": False}),
            ("Monte Carlo", scene, "montecarlo", {"rays": rays, "seed": 4}),
            ("Monte Carlo, paper's form", scene.with_brdf("paper"), "montecarlo",
             {"rays": rays, "seed": 4})):
        a = simulate(sc, method=method, bounces=3, **kw).link()
        b = simulate(sc.swapped(), method=method, bounces=3, **kw).link()
        for k in (1, 2, 3):
            sigma = float(np.hypot(a.stderr_w[k], b.stderr_w[k]) / a.power_w[k])
            rows.append({"method": label, "order": k, "direct": float(f"{a.power_w[k]:.5g}"),
                         "swapped": float(f"{b.power_w[k]:.5g}"),
                         "swapped / direct - 1": round(float(b.power_w[k] / a.power_w[k] - 1), 4),
                         "MC 3 sigma": round(3 * sigma, 4) if method == "montecarlo" else np.nan})
    return pd.DataFrame(rows)


def convergence_cases():
    """The scenes of the per-order check: (label, scene)."""
    return [("Barry A, Lambertian", barry_configuration_a()),
            ("glossy floor, Lambertian walls", glossy_room()),
            ("glossy floor and walls", glossy_room(walls=glossy_material(0.6))),
            ("glossy floor and walls, 30 deg FOV facing a wall",
             glossy_room(walls=glossy_material(0.6), receiver_facing=(-1.0, 0.0, 0.2),
                         fov_deg=30.0))]


def convergence_table(rays: int, cell: float) -> pd.DataFrame:
    rows = []
    for label, scene in convergence_cases():
        rec = simulate(scene, method="recursive", bounces=3, cell_m=cell)
        mc = simulate(scene, method="montecarlo", bounces=3, rays=rays, seed=1).link()
        a = rec.link()
        est = rec.error_estimate[(0, 0)]
        for k in (1, 2, 3):
            rows.append({"scene": label, "order": k,
                         f"recursive {cell:g} m": float(f"{a.power_w[k]:.5g}"),
                         "Monte Carlo": float(f"{mc.power_w[k]:.5g}"),
                         "recursive / Monte Carlo - 1": round(float(a.power_w[k] / mc.power_w[k] - 1), 4),
                         "Monte Carlo 3 sigma": round(float(3 * mc.stderr_w[k] / mc.power_w[k]), 4),
                         "estimated error (recursive)": round(float(est[k]), 4)})
    return pd.DataFrame(rows)


def energy_checks(rays: int) -> pd.DataFrame:
    from ..room import recursive as R
    from ..room.geometry import boxes_array

    rows = []
    for label, scene in (("Lambertian 0.7 everywhere",
                          barry_configuration_a(walls=0.7, floor=0.7, ceiling=0.7)),
                         ("glossy floor and walls", glossy_room(walls=glossy_material(0.6)))):
        geo = R.prepare(scene, 0.25, boxes_array(scene))
        st = R.emitter_state(geo, scene.emitters[0], 3, 0.25e-9, 200)
        mc = simulate(scene, method="montecarlo", bounces=3, rays=rays // 4, seed=5).link()
        for k in range(3):
            rows.append({
                "room": label, "reflections k": k + 1,
                "reflected (recursive, evaluated albedo)": round(float(st.reflected[k]), 5),
                "arriving after k (recursive) / reflected at k - 1": (
                    round(float(st.arrived[k] / st.reflected[k - 1]), 5) if k else np.nan),
                "power left (Monte Carlo, f cos / pdf)": round(float(mc.reflected_w[k]), 5),
                "rho^k (Lambertian)": round(0.7 ** (k + 1), 5) if "Lambertian" in label else np.nan,
            })
    return pd.DataFrame(rows)
