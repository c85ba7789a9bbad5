"""``irreflect reproduce``: the paper's tables and figures beside its own numbers."""

from __future__ import annotations

from .options import SEED


def _cmd_reproduce(args) -> int:
    from ..data import resolve_scene
    from ..report.runner import reproduce

    if args.scene is not None:  # what the scene's materials say of themselves, up front
        from ..room.checks import material_notes
        from ..room.scene import load_scene

        args.scene = resolve_scene(args.scene)
        for line in material_notes(load_scene(args.scene), args.allow_unphysical):
            print(line)
    reproduce(out_dir=args.out, data_dir=args.data_dir, quick=args.quick, seed=args.seed,
              progress=not args.no_progress, scene=args.scene,
              allow_unphysical=args.allow_unphysical)
    return 0


def register(sub) -> None:
    p = sub.add_parser("reproduce", help="reproduce the paper's tables and figures beside its numbers",
                       description="Run every capability on the bundled datasets (or every table "
                                   "of --data-dir) and write report.md, report.html, tables/*.csv "
                                   "and figures/*.png to --out.")
    p.add_argument("--data-dir", default=None, help="folder of measurement tables (default: bundled)")
    p.add_argument("--out", default="out", help="output folder (default out/)")
    p.add_argument("--quick", action="store_true", help="small optimiser budgets (about a minute)")
    p.add_argument("--seed", type=SEED, default=0,
                   help="seed of every fit and search (default 0)")
    p.add_argument("--no-progress", action="store_true",
                   help="no progress display (a bar on a terminal, one line per step through "
                        "a pipe)")
    p.add_argument("--scene", default=None, metavar="SCENE.toml",
                   help="add the room multipath section for this scene (a TOML file or a "
                        "bundled scene's name, e.g. office; default: none)")
    p.add_argument("--allow-unphysical", action="store_true",
                   help="with --scene: simulate a material whose model predicts negative power "
                        "in the room (clipped to 0; default: refused)")
    p.set_defaults(handler=_cmd_reproduce)
