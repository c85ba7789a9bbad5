"""``irreflect compare``: several reflection models on the same table (section 5.3)."""

from __future__ import annotations

import contextlib
import sys

from .options import (
    FINITE,
    SEED,
    add_data_argument,
    add_ignore_sigma_argument,
    add_resolution_argument,
    load_data,
    print_json,
)


def _cmd_compare(args) -> int:
    from .._atomic import claim_output
    from ..compare import PAPER_PHONG_DEG, compare_models, parse_model_list
    from ..errors import IrreflectError
    from ..plots.compare import write_outputs

    at = args.phong_at_deg
    if at is not None and not 0 <= abs(at) < 90:
        raise IrreflectError(
            f"--phong-at-deg must lie between 0 and 90 degrees, found {at:g}"
        )
    if args.models is not None and not args.models.strip():
        raise IrreflectError("--models is empty: expected a comma-separated list, e.g. "
                             "two-lobe,phong (leave the option out for the default models)")
    parse_model_list(args.models, PAPER_PHONG_DEG if at is None else abs(at))  # names first
    if at is not None and args.models is not None and not any(
            t.strip().endswith("@") for t in args.models.split(",")):
        print("irreflect: warning: --phong-at-deg has no effect: no model of --models ends "
              "in '@' (it sets the incidence of 'MODEL@'; 'MODEL@G' gives its own)",
              file=sys.stderr)
    claim = (claim_output(args.out, "dir", "--out") if args.out is not None
             else contextlib.nullcontext())
    with claim:
        meas = load_data(args)
        comparison = compare_models(meas, args.models,
                                    phong_at_deg=None if at is None else abs(at),
                                    seed=args.seed, progress=True, skip_failures=True,
                                    resolution=args.resolution)
        written = write_outputs(comparison, args.out) if args.out is not None else []
    for text in comparison.warnings:
        print(f"irreflect: warning: {comparison.data_name}: {text}", file=sys.stderr)
    for label, why in comparison.skipped.items():  # said on stderr too, whatever the format
        print(f"irreflect: warning: {comparison.data_name}: {label} left out of the comparison: "
              f"{why}", file=sys.stderr)
    if args.json:
        print_json(comparison.to_dict() | {"written": [str(p) for p in written]})
    else:
        print(comparison.format())
        for p in written:
            print(f"wrote {p}")
    return 0


def register(sub) -> None:
    from ..compare import DEFAULT_MODELS

    p = sub.add_parser(
        "compare", help="compare reflection models on the same data (section 5.3, Table 6)",
        description="Fit several reflection models to the same table and compare the relative "
                    "polar-area error per angle of incidence (section 5.3), R^2, RMSE, the "
                    "number of parameters and BIC. 'MODEL@G' fits a model at |gamma| = G deg "
                    "only and applies it to all angles, as the paper did with Phong.")
    add_data_argument(p)
    p.add_argument("--models", default=None, metavar="A,B,C",
                   help="comma-separated models (default: "
                        + ",".join(DEFAULT_MODELS).replace("{G}", "<G>")
                        + "); see 'irreflect models'")
    p.add_argument("--phong-at-deg", type=FINITE, default=None, metavar="G",
                   help="angle of incidence (deg) at which phong@ is fitted (default 10 as in "
                        "the paper, or the nearest measured one when the table has no 10 deg; "
                        "an explicit G must be measured)")
    p.add_argument("--seed", type=SEED, default=0, help="seed of every fit (default 0)")
    add_resolution_argument(p, "every model is fitted and scored as its average over it, "
                               "as 'fit --resolution' fits")
    add_ignore_sigma_argument(p)
    p.add_argument("--json", action="store_true", help="one JSON object on stdout")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="write polar plots per angle of incidence (Fig. 25), a line chart of "
                        "the error per angle of incidence, comparison.csv and comparison.json "
                        "into DIR (default: none)")
    p.set_defaults(handler=_cmd_compare)
