"""``irreflect protocol`` and ``irreflect evaluate-protocol``."""

from __future__ import annotations

import sys
from pathlib import Path

from ..errors import IrreflectError
from .options import (
    ANGLE,
    ANGLES,
    FINITE,
    NON_NEGATIVE,
    NON_NEGATIVE_INT,
    POSITIVE,
    POSITIVE_INT,
    SEED,
    Flatten,
    int_at_least,
    load_data,
    print_json,
)

#: ``--out`` extensions and the format each one means
SUFFIXES = {".csv": "csv", ".json": "json", ".md": "md", ".markdown": "md"}


#: options of ``protocol`` that tune one kind of design, the kinds they act on, and their
#: defaults (None in the parser, so that an option given where it has no effect is told)
_TUNING = {
    "layout": (("specular",), "paper"),
    "mirror_offset": (("paper",), 10.0),
    "min_separation": (("paper",), None),
    "wide_offset": (("paper", "specular", "lobe"), 60.0),
    "central_offset": (("paper", "specular", "lobe"), 20.0),
    "model": (("design",), "two-lobe"),
    "selector": (("design",), "nsga2"),
    "pop_size": (("design",), 100),
    "generations": (("design",), 200),
    "seed": (("design", "lobe"), 0),
    "average_duplicates": (("design", "lobe"), False),
}
_KIND_TEXT = {"paper": "--gammas without --specular-index", "specular": "--specular-index",
              "design": "--design-from", "lobe": "--lobe-from"}
_KIND_NAME = {"paper": "the paper's protocol (--gammas without --specular-index)",
              "specular": "a --specular-index design", "design": "a --design-from design",
              "lobe": "a --lobe-from design"}


def _check_options(args) -> None:
    """Refuse options that contradict the kind of design asked for; warn of options that
    have no effect on it (and fill in their defaults)."""
    kind = ("design" if args.design_from else "lobe" if args.lobe_from
            else "specular" if args.specular_index is not None else "paper")
    source = {"design": "--design-from", "lobe": "--lobe-from"}.get(kind, "--gammas")
    if kind != "design" and (args.n is not None or args.gamma_settings is not None):
        extra = " (which always gives 12 points)" if kind == "lobe" else ""
        raise IrreflectError(f"--n and --gamma-settings apply to --design-from, not to "
                             f"{source}{extra}")
    if kind in ("design", "lobe") and args.specular_index is not None:
        why = ("it measures the specular lobe on the pilot" if kind == "lobe"
               else "it picks its points from the pilot scan")
        raise IrreflectError(f"--specular-index applies to --gammas (not to {source}: {why}):"
                             f" leave it out, or give --gammas G1 G2 G3 instead of {source}")
    unused = []
    for dest, (kinds, default) in _TUNING.items():
        value = getattr(args, dest)
        if value is None or value is False:
            setattr(args, dest, default)
        elif kind not in kinds:
            unused.append(f"--{dest.replace('_', '-')} acts only with "
                          + " or ".join(_KIND_TEXT[k] for k in kinds))
    if unused:
        names = [u.split()[0] for u in unused]
        print(f"irreflect: warning: {' and '.join(names)} "
              f"{'has' if len(names) == 1 else 'have'} no effect on {_KIND_NAME[kind]}: "
              f"{'; '.join(unused)}", file=sys.stderr)


def _cmd_protocol(args) -> int:
    import contextlib

    from .._atomic import claim_output

    _check_options(args)
    fmt = args.format
    if args.out is not None and not args.out.strip():
        raise IrreflectError("--out must name a file; found an empty name (leave it out to "
                             "print on stdout)")
    if args.out and Path(args.out).is_dir():
        raise IrreflectError(f"--out {args.out}: is a folder; expected a file name ending in "
                             ".csv, .json or .md")
    suffix = Path(args.out).suffix.lower() if args.out else ""
    if fmt is not None and SUFFIXES.get(suffix, fmt) != fmt:
        raise IrreflectError(
            f"--out {args.out}: the extension '{suffix}' means {SUFFIXES[suffix]}, but "
            f"--format is {fmt}: name the file {Path(args.out).with_suffix('.' + fmt)} or "
            "drop --format (the extension then decides)")
    if args.out and fmt is None:
        if suffix not in SUFFIXES:
            raise IrreflectError(
                f"--out {args.out}: unknown extension '{suffix or 'none'}': name the file "
                ".csv, .json or .md, or pass --format csv|json|md"
            )
        fmt = SUFFIXES[suffix]
    fmt = fmt or "csv"
    claim = claim_output(args.out, "file", "--out") if args.out else contextlib.nullcontext()
    with claim:
        return _protocol(args, fmt)


def _protocol(args, fmt: str) -> int:
    from ..protocol.core import paper_protocol
    from ..protocol.export import render, write_protocol

    if args.lobe_from:
        from ..protocol.evaluate import glossy_protocol_for

        pilot = load_data(args, "protocol-lobe-from", args.lobe_from)
        protocol = glossy_protocol_for(pilot, theta_min=args.theta_min,
                                       theta_max=args.theta_max, seed=args.seed,
                                       wide_offset=args.wide_offset,
                                       central_offset=args.central_offset)
        print(f"irreflect: note: glossy-aware protocol designed from {pilot.name}: "
              f"{_placed_text(protocol)}, R^2 {protocol.settings['pilot_r2']:.4f} on the "
              "pilot's points", file=sys.stderr)
    elif args.specular_index is not None:
        from ..protocol.core import glossy_protocol

        protocol = glossy_protocol(
            args.gammas,
            -70.0 if args.theta_min is None else args.theta_min,
            70.0 if args.theta_max is None else args.theta_max,
            specular_index=args.specular_index, wide_offset=args.wide_offset,
            central_offset=args.central_offset, layout=args.layout,
        )
    elif args.design_from:
        from ..selection.design import design_protocol
        from ..validation import check_search_budget

        dense = load_data(args, "protocol", args.design_from)
        check_search_budget(args.pop_size, args.generations, dense.n_points,
                            pop_option="--pop-size", gen_option="--generations")
        protocol = design_protocol(
            dense, args.n, args.model, theta_min=args.theta_min, theta_max=args.theta_max,
            n_gamma_settings=args.gamma_settings, selector=args.selector, seed=args.seed,
            pop_size=args.pop_size, generations=args.generations, progress=True,
        )
    else:
        protocol = paper_protocol(
            args.gammas,
            -70.0 if args.theta_min is None else args.theta_min,
            70.0 if args.theta_max is None else args.theta_max,
            mirror_offset=args.mirror_offset, wide_offset=args.wide_offset,
            central_offset=args.central_offset, min_separation=args.min_separation,
        )
    warning = {protocol.settings.get("placement_warning"),
               protocol.settings.get("pilot_warning")} - {None}
    for note in protocol.notes:
        kind = "warning" if note in warning else "note"
        print(f"irreflect: {kind}: {note}", file=sys.stderr)
    if args.out:
        write_protocol(protocol, args.out, fmt)
        print(f"wrote {args.out} ({protocol.n_points} points, {len(protocol.gammas)} angles of "
              f"incidence, {fmt})")
    else:
        sys.stdout.write(render(protocol, fmt))
    return 0


def _placed_text(protocol) -> str:
    """A glossy-aware protocol's angles, layout and where its lobe-width points stand, as
    written in its file (``settings["lobe_offsets_deg"]``, measured from the points)."""
    st = protocol.settings
    placed = st["lobe_offsets_deg"]
    parts = [f"{g}: {'/'.join(f'{o:g}' for o in offs)}" for g, offs in placed.items() if offs]
    return (f"gammas {', '.join(f'{g:g}' for g in st['gammas_deg'])} deg, layout "
            f"{st['layout']}, lobe-width points at "
            + ("; ".join(f"gamma {p}" for p in parts) if parts else "none")
            + " deg from the mirror (as written)")


def _cmd_evaluate(args) -> int:
    from ..models import get_model
    from ..protocol.evaluate import evaluate_protocol
    from ..protocol.export import read_protocol
    from ..validation import check_number, check_trials_budget

    get_model(args.model)
    if args.monte_carlo == 1:
        raise IrreflectError("--monte-carlo: expected 0 (none) or at least 2 trials (a spread "
                             "needs two); found 1")
    unused = [o for o, v in (("--angle-error", args.angle_error),
                             ("--power-noise", args.power_noise)) if v is not None]
    if unused and not args.monte_carlo:
        print(f"irreflect: warning: {' and '.join(unused)} {'has' if len(unused) == 1 else 'have'}"
              " no effect without --monte-carlo TRIALS (they set its goniometer errors)",
              file=sys.stderr)
    args.angle_error = 1.0 if args.angle_error is None else args.angle_error
    args.power_noise = 0.01 if args.power_noise is None else args.power_noise
    if args.monte_carlo:
        check_trials_budget(args.monte_carlo, "--monte-carlo")
        check_number(args.angle_error, "--angle-error (deg)", low=0.0, high=10.0)
    protocol = read_protocol(args.protocol)
    dense = load_data(args, "evaluate-protocol", args.dense)
    ev = evaluate_protocol(protocol, dense, args.model, tolerance_deg=args.tolerance,
                           method="snap" if args.snap else "interpolate", seed=args.seed)
    rob = None
    if args.monte_carlo:
        from ..protocol.robustness import protocol_robustness

        rob = protocol_robustness(protocol, dense, model=args.model,
                                  n_trials=args.monte_carlo, angle_error_deg=args.angle_error,
                                  power_noise=args.power_noise, seed=args.seed,
                                  progress=not args.json)
    if args.json:
        out = ev.to_dict()
        if rob is not None:
            out["robustness"] = rob.to_dict()
        print_json(out)
    else:
        print(ev.summary())
        if rob is not None:
            print(rob.summary())
    return 0


def register(sub) -> None:
    p = sub.add_parser(
        "protocol", help="where to put emitter and detector: the paper's 12 points, or a design",
        description="Write a measurement protocol: the paper's 12-point protocol (section 4.3) "
                    "for your tool's receiver range (--gammas), or the points a subset optimiser "
                    "picks from a pilot dense scan (--design-from). Angles in degrees; gamma "
                    "negative on the source side (magnitudes also accepted).")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--gammas", nargs="+", type=ANGLES, action=Flatten, metavar="G",
                     help="three angles of incidence in degrees, e.g. -20 -40 -60 (or 20,40,60); "
                          "one of --gammas, --design-from, --lobe-from is required")
    src.add_argument("--design-from", metavar="DENSE.csv",
                     help="design from a pilot dense scan of the material (CSV or Parquet; "
                          "default: none)")
    src.add_argument("--lobe-from", metavar="PILOT.csv",
                     help="glossy-aware 12 points designed from a pilot scan: lobe-width "
                          "offsets from its fitted specular lobe, points at its receiver "
                          "angles, the layout that predicts it best (default: none)")
    p.add_argument("--specular-index", type=POSITIVE, default=None, metavar="N",
                   help="with --gammas: glossy-aware 12 points for a specular lobe index N "
                        "(lobe-width points at its half width acos(2^(-1/N)) instead of "
                        "--mirror-offset; default: none, the paper's offsets)")
    p.add_argument("--layout", choices=("paper", "balanced"), default=None,
                   help="with --specular-index: 'paper' (5+2+5 points, default) or 'balanced' "
                        "(4 per gamma: mirror, lobe width, two diffuse)")
    p.add_argument("--theta-min", type=ANGLE, default=None,
                   help="lowest receiver angle the tool can set (deg; default -70 for --gammas, "
                        "the pilot's lowest for --design-from and --lobe-from)")
    p.add_argument("--theta-max", type=ANGLE, default=None,
                   help="highest receiver angle (deg; default 70 for --gammas, the pilot's "
                        "highest for --design-from and --lobe-from)")
    p.add_argument("--mirror-offset", type=POSITIVE, default=None,
                   help="lobe-width points around the mirror angle (deg, Eqs. 29-30; default 10)")
    p.add_argument("--wide-offset", type=POSITIVE, default=None,
                   help="diffuse points from the mirror angle (deg, Eqs. 31-32; default 60)")
    p.add_argument("--central-offset", type=FINITE, default=None,
                   help="offset of the central gamma's points (deg, Eqs. 33-34; default 20)")
    p.add_argument("--min-separation", type=POSITIVE, default=None,
                   help="points of one gamma closer than this coincide (deg; default "
                        "mirror-offset / 2)")
    p.add_argument("--n", type=POSITIVE_INT, default=None,
                   help="--design-from: number of points (default: the knee of the front)")
    p.add_argument("--gamma-settings", type=POSITIVE_INT, default=None, metavar="K",
                   help="--design-from: use only K angle-of-incidence settings (default: any)")
    p.add_argument("--model", default=None, help="--design-from: model (default two-lobe)")
    p.add_argument("--selector", default=None, help="--design-from: optimiser (default nsga2)")
    p.add_argument("--pop-size", type=int_at_least(2), default=None,
                   help="--design-from: NSGA-II population (default 100)")
    p.add_argument("--generations", type=POSITIVE_INT, default=None,
                   help="--design-from: NSGA-II generations (default 200)")
    p.add_argument("--seed", type=SEED, default=None,
                   help="seed of the optimiser and of the fits' random starts (default 0)")
    p.add_argument("--average-duplicates", action="store_true",
                   help="--design-from / --lobe-from: average duplicated (gamma, theta) rows")
    p.add_argument("--format", choices=("csv", "json", "md"), default=None,
                   help="output format (default: from --out's extension .csv, .json or .md; "
                        "csv on stdout)")
    p.add_argument("--out", metavar="FILE",
                   help="write here (atomically) instead of stdout (default: stdout)")
    p.set_defaults(handler=_cmd_protocol)
    _register_evaluate(sub)


def _register_evaluate(sub) -> None:
    p = sub.add_parser(
        "evaluate-protocol", help="fit on a protocol's points of a dense scan, judge on all",
        description="Fit the model on the protocol's points of a dense dataset and print R^2, "
                    "RMSE and the per-gamma polar-area error against all its points. Protocol "
                    "angles missing from the dataset are interpolated along theta (or snapped) "
                    "within --tolerance degrees, and listed.")
    p.add_argument("protocol", metavar="PROTOCOL", help="protocol CSV or JSON")
    p.add_argument("dense", metavar="DENSE", help="dense measurement table (CSV or Parquet)")
    p.add_argument("--model", default="two-lobe",
                   help="reflection model fitted on the protocol's points (default two-lobe; "
                        "see 'irreflect models')")
    p.add_argument("--tolerance", type=NON_NEGATIVE, default=5.0,
                   help="largest gap (deg) to the nearest measured theta that may be bridged "
                        "(default 5)")
    p.add_argument("--snap", action="store_true",
                   help="use the nearest measured angle instead of interpolating")
    p.add_argument("--monte-carlo", type=NON_NEGATIVE_INT, default=0, metavar="TRIALS",
                   help="also run a Monte Carlo of goniometer errors with this many trials, "
                        "at least 2 (default 0: none)")
    p.add_argument("--angle-error", type=NON_NEGATIVE, default=None,
                   help="Monte Carlo: half-width of the uniform angle error (deg, 0-10, default 1)")
    p.add_argument("--power-noise", type=NON_NEGATIVE, default=None,
                   help="Monte Carlo: relative power noise, 1-sigma (default 0.01)")
    p.add_argument("--seed", type=SEED, default=0,
                   help="seed of the fit's random starts and of the Monte Carlo (default 0)")
    p.add_argument("--average-duplicates", action="store_true",
                   help="average the power of duplicated (gamma, theta) rows of DENSE")
    p.add_argument("--json", action="store_true", help="one JSON object on stdout")
    p.set_defaults(handler=_cmd_evaluate)
