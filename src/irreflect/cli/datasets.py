"""``irreflect datasets``: what ships with irreflect (datasets, scenes, material files, the
paper's published tables), where each came from and where it lies once installed.

The names it lists are what the commands accept in place of a path: ``irreflect fit
terrazzo``, ``irreflect room office``. ``--path NAME`` prints one file's installed path
(``cp "$(irreflect datasets --path terrazzo)" .``), ``--json`` everything as one object.
"""

from __future__ import annotations

import sys

from .options import print_json

_HEADINGS = {
    "table": "measurement tables (accepted by name wherever a DATA table is: "
             "'irreflect fit terrazzo')",
    "scene": "room scenes (accepted by name: 'irreflect room office')",
    "material": "material files (irreflect fit --save), used by the scene",
    "paper table": "the paper's published tables (numbers as printed, not measurements; "
                   "source: {source})",
}


def _cmd_datasets(args) -> int:
    from .. import __version__
    from ..data import bundled_files, real_data_dir, real_datasets
    from ..errors import unknown_name

    files = bundled_files()
    if args.path is not None:
        hits = [f for f in files if args.path in (f.name, f.path.name)]
        if not hits:
            raise unknown_name("bundled file", args.path, [f.name for f in files])
        print(hits[0].path)
        return 0
    real = real_data_dir()
    if args.json:
        print_json({
            "version": __version__,
            "bundled": [{"name": f.name, "kind": f.kind, "points": f.points,
                         "origin": f.origin, "path": str(f.path)} for f in files],
            "real_data_dir": None if real is None else str(real),
            "real_tables": sorted(real_datasets()) if real is not None else [],
        })
        return 0
    from ..paper import PAPER_SOURCE

    print(f"shipped with irreflect {__version__}:")
    width = max(len(f.name) for f in files)
    for kind, heading in _HEADINGS.items():
        group = [f for f in files if f.kind == kind]
        if not group:
            continue
        print(f"\n{heading.format(source=PAPER_SOURCE)}:")
        for f in group:
            points = f" ({f.points} points)" if f.points is not None else ""
            origin = f.origin.split(", as published in ")[0]  # the source is in the heading
            print(f"  {f.name:<{width}}  {origin}{points}")
            print(f"  {'':<{width}}  {f.path}")
    if real is not None:
        print(f"\nreal measured data (not shipped; read from {real}): "
              f"{len(real_datasets())} tables")
    else:
        print("\nreal measured data: not found (set IRREFLECT_REAL_DATA to its folder)")
    sys.stdout.flush()
    return 0


def register(sub) -> None:
    p = sub.add_parser(
        "datasets",
        help="list the datasets, scenes and paper tables shipped with irreflect (by name, "
             "with origin and path)",
        description="List every file shipped inside the package: the bundled measurement "
                    "tables (reconstructions of the paper's materials), the example room "
                    "scene and its material files, and the paper's published tables, each "
                    "with where it came from and its installed path. Commands accept the "
                    "names of tables and scenes in place of a path.")
    p.add_argument("--path", metavar="NAME", default=None,
                   help="print only the installed path of the file NAME, e.g. terrazzo (default: list "
                        "everything)")
    p.add_argument("--json", action="store_true", help="one JSON object on stdout")
    p.set_defaults(handler=_cmd_datasets)
