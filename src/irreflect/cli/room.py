"""``irreflect room SCENE.toml --out DIR``: impulse response, DC gain, delay spread and range
error for every emitter-receiver pair of a scene (see :mod:`irreflect.room`)."""

from __future__ import annotations

from .options import NON_NEGATIVE_INT, POSITIVE, POSITIVE_INT, SEED


def _cmd_room(args) -> int:
    from .._atomic import claim_output

    with claim_output(args.out, "dir", "--out"):  # checked and locked before any work
        return _room(args)


def _room(args) -> int:
    from pathlib import Path

    from ..data import resolve_scene
    from ..room.checks import CLI_OPTIONS, check_room_budget, material_notes, resolve_settings
    from ..room.engine import simulate
    from ..room.scene import load_scene

    if args.scheduler is not None:
        from ..selection.parallel import check_scheduler_address

        check_scheduler_address(args.scheduler)
    out = Path(args.out)
    scene = load_scene(resolve_scene(args.scene), materials_dir=args.materials_dir)
    brdf = args.brdf or scene.settings.get("brdf")
    if brdf is not None:
        scene = scene.with_brdf(brdf)
    settings = resolve_settings(scene, {"method": args.method, "bounces": args.bounces,
                                        "cell_m": args.cell, "rays": args.rays,
                                        "time_resolution_ns": args.dt})
    check_room_budget(scene, settings, CLI_OPTIONS, args.workers)  # before any work
    from .._compiled import ensure_room_compiled
    from ..room.warm import warm

    ensure_room_compiled(warm)  # a cold cache: built now, announced, not silently
    for line in material_notes(scene, allow_unphysical=args.allow_unphysical):
        print(line)
    _warn_materials(scene)
    result = simulate(scene, method=args.method, bounces=args.bounces, cell_m=args.cell,
                      rays=args.rays, seed=args.seed, time_resolution_ns=args.dt,
                      scheduler=args.scheduler, workers=args.workers, progress=not args.quiet)
    figures = None
    if not args.no_figures:  # matplotlib only when figures are drawn
        from ..plots.room import write_figures as figures
    written = result.write(out, figures=figures)
    summary = result.summary()
    print(_report(result, summary))
    _warn_dark(summary)
    _warn_wrapped(summary)
    print(f"wrote {out}/: {', '.join(written[:6])}{' ...' if len(written) > 6 else ''} "
          f"({len(written)} files)")
    return 0


def _warn_materials(scene) -> None:
    """Each material's warnings (energy cap; the paper's form is not reciprocal), once, on
    stderr."""
    import sys

    seen = set()
    for mat in scene.materials.values():
        for w in mat.warnings:
            text = w.replace(f"material '{mat.name}': ", "")
            if text.startswith("the paper's surface model"):
                if "paper" in seen:
                    continue
                seen.add("paper")
                print(f"irreflect: warning: {text} (--brdf paper)", file=sys.stderr)
                continue
            print(f"irreflect: warning: material '{mat.name}': {text}", file=sys.stderr)


def _warn_dark(summary) -> None:
    """A pair that receives no light at all is worth a word: a receiver turned to a wall,
    shut in by boxes, or out of every emitter's reach (its delays are NaN)."""
    import sys

    dark = summary[~(summary.dc_gain_total > 0)]
    if len(dark):
        first = dark.iloc[0]
        print(f"irreflect: warning: {len(dark)} emitter-receiver pair(s) receive no light, "
              f"e.g. {first.emitter} -> {first.receiver} (their delays are NaN): check that "
              "the receivers face the room and are not shut in by boxes, or follow more "
              "--bounces", file=sys.stderr)


def _warn_wrapped(summary) -> None:
    """A modulation so fast that its unambiguous range ``c / f`` is shorter than the paths
    (their mean delay is over one period): the range error printed is known only modulo
    ``c / f`` (at 1 THz it read -0.00 cm)."""
    import sys

    import numpy as np

    from ..room.kernels import C_LIGHT

    mod = summary[(summary.modulation_hz > 0) & (summary.mean_delay_ns > 0)]
    if not len(mod):
        return
    periods = (mod.mean_delay_ns * 1e-9 * mod.modulation_hz).to_numpy()
    i = int(np.argmax(periods))
    if not periods[i] > 1.0:
        return
    row = mod.iloc[i]
    print(f"irreflect: warning: {row.emitter} -> {row.receiver}: the mean path delay "
          f"({row.mean_delay_ns:.3g} ns) is {periods[i]:.3g} periods of the "
          f"{row.modulation_hz / 1e6:g} MHz modulation: phase ranging's unambiguous range "
          f"({C_LIGHT / row.modulation_hz * 100:.3g} cm) is shorter than the paths, and the "
          "range error printed is known only modulo it; a modulation below "
          f"{1e3 / row.mean_delay_ns:.3g} MHz measures the range here", file=sys.stderr)


def _report(result, summary) -> str:
    import numpy as np

    from ..room.engine import worst_error_estimate

    scene = result.scene
    lines = [f"{scene.name}: {len(scene.emitters)} emitter(s), {len(scene.receivers)} receiver(s), "
             f"method {result.method}, {result.bounces} bounce(s)"
             + (f", {result.n_cells} cells of {result.cell_m:g} m" if result.cell_m else "")
             + (f", {result.rays} rays per link, seed {result.seed}" if result.rays else "")
             + f", {result.seconds:.1f} s"]
    if result.ray_bounces_per_s:
        lines.append(f"  Monte Carlo: {result.ray_bounces_per_s:,.0f} ray-bounces/s per process (tracing time only)")
    for name, mat in scene.materials.items():
        lines.append(f"  material {name}: {mat.describe()}")
    est = np.array(list((result.error_estimate or {}).values()), float)
    if est.size and np.isfinite(est).any():
        worst = worst_error_estimate(result)
        lines.append("  recursive method, estimated error per order (worst link; from a run at "
                     "twice the cell size, and with glossy materials that run with a quarter of "
                     "the lobe rays): " + ", ".join(
                         f"{k} {100 * worst[k]:.2f} %" for k in range(1, len(worst))))
    for note in result.notes:
        lines.append(f"  note: {note}")
    singles = summary[summary.grid == ""]
    cols = [c for c in summary.columns if c.startswith("dc_gain_b") and not c.endswith("stderr")]
    for _, row in singles.iterrows():
        gains = "  ".join(f"{c[8:]} {row[c]:.4g}" for c in cols)
        rng = ("" if row.range_error_m != row.range_error_m else
               f"  range error {row.range_error_m * 100:+.2f} cm ({row.phase_error_deg:+.3f} deg at "
               f"{row.modulation_hz / 1e6:g} MHz)")
        lines.append(f"  {row.emitter} -> {row.receiver}: H total {row.dc_gain_total:.4g} "
                     f"(LoS {row.dc_gain_los:.4g}  {gains})  mean delay {row.mean_delay_ns:.2f} ns  "
                     f"RMS spread {row.rms_delay_spread_ns:.2f} ns{rng}")
    for grid in scene.grids:
        sub = summary[summary.grid == grid.name]
        for em, part in sub.groupby("emitter", sort=False):
            text = (f"  grid {grid.name} ({len(part)} receivers) from {em}: H total "
                    f"{part.dc_gain_total.min():.3g}..{part.dc_gain_total.max():.3g}, RMS spread "
                    f"{part.rms_delay_spread_ns.min():.2f}..{part.rms_delay_spread_ns.max():.2f} ns")
            if part.range_error_m.notna().any():
                text += (f", range error {part.range_error_m.min() * 100:+.2f}.."
                         f"{part.range_error_m.max() * 100:+.2f} cm")
            lines.append(text)
    return "\n".join(lines)


def register(sub) -> None:
    p = sub.add_parser(
        "room", help="multipath in a room from fitted materials: h(t), DC gain, delay spread, "
                     "range error",
        description="Line of sight and reflections (Barry's recursive method or Monte Carlo with "
                    "next-event estimation) for every emitter-receiver pair of a scene; writes "
                    "summary/bounces/impulse_response as CSV and Parquet, run.json and figures "
                    "to --out. Options override the scene's [simulation] table.")
    p.add_argument("scene", metavar="SCENE.toml", help="scene file (TOML), or the name of a bundled scene (office; see 'irreflect datasets')")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--method", choices=("recursive", "montecarlo"), default=None,
                   help="reflections by Barry's recursive method or Monte Carlo (default: the "
                        "scene's, else montecarlo)")
    p.add_argument("--bounces", type=NON_NEGATIVE_INT, default=None, metavar="K",
                   help="reflections to follow (default 3)")
    p.add_argument("--cell", type=POSITIVE, default=None, metavar="M",
                   help="cell size of the recursive method in metres (default 0.25)")
    p.add_argument("--brdf", choices=("reciprocal", "paper"), default=None,
                   help="surface model of the fitted materials: 'reciprocal' (default: obeys "
                        "Helmholtz reciprocity, fitted to the material's curve) or 'paper' (the "
                        "paper's lobes of revolution; not reciprocal, with a warning)")
    p.add_argument("--rays", type=POSITIVE_INT, default=None, metavar="R",
                   help="Monte Carlo rays per emitter-receiver pair (default 20000)")
    p.add_argument("--seed", type=SEED, default=None, metavar="S",
                   help="seed of the Monte Carlo rays (default 0)")
    p.add_argument("--dt", type=POSITIVE, default=None, metavar="NS",
                   help="h(t) bin width in ns (default 0.25)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="dask.distributed scheduler (e.g. tcp://host:8786) for the receivers "
                        "(default: local)")
    p.add_argument("--workers", type=POSITIVE_INT, default=None,
                   help="local worker processes for the receivers (default 1)")
    p.add_argument("--materials-dir", default=None, metavar="DIR",
                   help="also read the scene's material files from DIR (default: only from "
                        "the scene's own folder)")
    p.add_argument("--allow-unphysical", action="store_true",
                   help="simulate a material whose model predicts negative power in the room "
                        "(clipped to 0; default: refused)")
    p.add_argument("--no-figures", action="store_true", help="numbers only")
    p.add_argument("--quiet", action="store_true",
                   help="no progress display (a bar on a terminal, lines through a pipe)")
    p.set_defaults(handler=_cmd_room)

