"""The room section of the reproduction report (``irreflect reproduce --scene SCENE.toml``).

It shows what the paper is for: the scene's room simulated with Lambertian surfaces of the
same total reflectance, with the fitted two-lobe materials, and with a glossy real material
(fitted from ``../shared/datasets/real`` when present) as floor; then a validation page
(line of sight against the closed form, one bounce against numerical integration, Barry's
configuration A with the recursive method and Monte Carlo, reciprocity, energy).
"""

from __future__ import annotations

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
    line_of_sight_closed_form,
    one_bounce_reference,
    single_floor_scene,
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


def section(ctx: ReportContext) -> Section:
    """The scene's room with Lambertian, fitted and glossy-floor surfaces, and the
    validation page (``ctx.scene``: the scene's TOML file)."""
    if ctx.scene is None:
        raise ValueError("the room section needs a scene: ReportContext(scene=SCENE.toml)")
    scene = load_scene(ctx.scene)
    rays = 1500 if ctx.quick else int(scene.settings.get("rays", 20000))
    bounces = int(scene.settings.get("bounces", 3))
    tables, figures, md = {}, {}, []
    notes = material_notes(scene, ctx.allow_unphysical)
    if notes:  # what the materials' own fits said of them
        md.append("What the scene's materials say of their own fits (their material files' "
                  "verdicts and warnings, `irreflect fit --save`):\n\n```\n"
                  + "\n".join(notes) + "\n```\n")

    # the scene
    rows = [{"surface": face, "material": name, "source": scene.materials[name].source,
             "3D model": scene.materials[name].describe()}
            for face, name in zip(("wall x=0", "wall x=max", "wall y=0", "wall y=max", "floor",
                                   "ceiling"), scene.room_materials, strict=True)]
    rows += [{"surface": f"box {b.name}", "material": b.materials[5],
              "source": scene.materials[b.materials[5]].source,
              "3D model": scene.materials[b.materials[5]].describe()} for b in scene.boxes]
    tables["room_scene"] = pd.DataFrame(rows)
    md.append(f"Scene `{scene.path}`: {scene.size[0]:g} x {scene.size[1]:g} x {scene.size[2]:g} m, "
              f"{len(scene.emitters)} emitter(s), {len(scene.receivers)} receivers "
              f"({len(scene.grids)} grid(s)); Monte Carlo with next-event estimation, {rays} rays "
              f"per emitter-receiver pair, {bounces} reflections, seed {ctx.seed}.\n\n"
              "{table:room_scene}\n\n"
              "**The 3D extension.** The fitted models live in the plane of incidence; in the room "
              "the diffuse lobe is a solid of revolution about the surface normal and the specular "
              "lobe one about the mirror direction (the paper's section 3.4), with the share and "
              "indices of the angle of incidence as fitted; the lobes are cut by the surface and "
              "scaled per angle of incidence so that the reflected power is the total reflectance "
              "times the incident power. The polar plots show a material's intensity in the plane "
              "of incidence and in planes rotated about the normal.\n\n")
    for name, mat in scene.materials.items():
        if mat.model == "two-lobe":
            ax = plot_material_3d(mat, 50.0)
            key = f"room_material_{safe_name(name)}"
            save(ax, ctx.figure_path(key))
            figures[key] = ctx.figure_path(key)
            md.append(f"{{figure:{key}}} ")
    md.append("\n\n")

    # the comparison
    variants, glossy_note = _variants(scene, ctx.quick)
    results = []
    for label, variant in variants:
        ctx.progress(f"room: {label}")  # whole: a line per step through a pipe
        res = simulate(variant, method="montecarlo", bounces=bounces, rays=rays, seed=ctx.seed)
        results.append((label, res, summary_table(res)))
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
    tables["room_comparison"] = pd.DataFrame(rows)
    md.append("### What the fitted materials change\n\nThe same room three ways: every surface "
              "Lambertian with the scene's total reflectance; the fitted two-lobe materials; and "
              "the fitted materials with a glossy real material as floor (same total reflectance, "
              "its measured angular shape). Range error: phase-based ranging at the emitter's "
              "modulation frequency, multipath phasor against the geometric line of sight "
              "(positive = the range looks longer). Monte Carlo standard errors are in "
              "`irreflect room`'s outputs (about 1 % of the reflected gain per order at 20000 "
              "rays).\n\n{table:room_comparison}\n\n")
    if len(variants) < 3:
        md.append(f"*No glossy real floor: {glossy_note}.*\n\n")
    # figures: h(t) and gains for the first receiver, maps
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
    ctx.progress("room: validation")
    val_md, val_tables = validation_page(ctx.quick)
    tables.update(val_tables)
    md.append(val_md)
    return Section("room", TITLE, "".join(md), tables, figures)


def validation_page(quick: bool):
    """Checks against what exists, as report tables (numbers measured in this run)."""
    tables = {}
    scene = barry_configuration_a()
    los, tau = line_of_sight_closed_form(scene.emitters[0], scene.receivers[0])
    cell = 0.25 if quick else 0.125
    rec = simulate(scene, method="recursive", bounces=3, cell_m=cell)
    mc = simulate(scene, method="montecarlo", bounces=3, rays=20000 if quick else 200000, seed=0)
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
        got = simulate(floor, method="recursive", bounces=1, cell_m=c).link().power_w[1]
        rows.append({"cell (m)": c, "recursive H1": float(f"{got:.6g}"),
                     "numerical integration": float(f"{ref:.6g}"),
                     "relative error": float(f"{got / ref - 1:.2e}")})
    tables["room_one_bounce"] = pd.DataFrame(rows)
    rscene = barry_configuration_a(receiver_fov_deg=90.0)
    a = simulate(rscene, method="recursive", bounces=3, cell_m=0.5).link()
    b = simulate(rscene.swapped(), method="recursive", bounces=3, cell_m=0.5).link()
    rho = 0.7
    closed = barry_configuration_a(walls=rho, floor=rho, ceiling=rho)
    left = simulate(closed, method="montecarlo", bounces=4, rays=2000, seed=0).link().reflected_w
    rows = [{"check": "reciprocity (swap emitter/receiver, recursive 0.5 m, orders 1-3)",
             "result": "max relative difference "
                       f"{np.max(np.abs(a.power_w[1:] / b.power_w[1:] - 1)):.1e}"},
            {"check": "energy: closed room rho = 0.7, power left after k = 1..4 reflections / rho^k "
                      "(Monte Carlo)",
             "result": ", ".join(f"{v:.6f}" for v in left / rho ** np.arange(1, 5))}]
    tables["room_checks"] = pd.DataFrame(rows)
    md = ("### Validation\n\nBarry et al. (1993), configuration A (5 x 5 x 3 m, walls and ceiling "
          "0.8, floor 0.3, emitter at the ceiling centre facing down, receiver at (0.5, 1, 0), "
          "1 cm^2, 85 deg): DC gain per order. The vlc-rm column is the independent "
          "implementation run by `.venv/bin/python experiments/bench_room.py` (not by this report); "
          "Barry's paper publishes h(t) curves, not gains; the line of sight is the closed form "
          f"(Eq. 5), {los:.5g} at {tau * 1e9:.3f} ns.\n\n{{table:room_barry_a}}\n\n"
          "One reflection off a single Lambertian floor (every other surface black): the "
          "recursive method converges to the numerical integral as the cells shrink.\n\n"
          "{table:room_one_bounce}\n\n{table:room_checks}\n")
    return md, tables
