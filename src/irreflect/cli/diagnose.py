"""``irreflect diagnose DATA [--model NAME] [--json] [--out DIR]``."""

from __future__ import annotations

import argparse
import sys

from .options import (
    FINITE,
    NON_NEGATIVE_INT,
    SEED,
    add_data_argument,
    add_ignore_sigma_argument,
    add_model_argument,
    load_data,
    print_json,
    warn_if_sigma_decides,
)


def register(sub) -> None:
    """Add the ``diagnose`` subcommand to the CLI's subparsers."""
    from ..models.extensions import EXTENSIONS, GAIN_DRIFT

    p = sub.add_parser(
        "diagnose",
        help="find what a model misses: residual structure, named effect, extended fit",
        description="Fit the model, estimate the noise (sigma column, or estimated: additive "
                    "and proportional to the power), test the residual for structure, fit "
                    "explanations made of catalogue effects on top of the model and compare "
                    "them by likelihood ratio; end with a verdict: 'no missing effect', "
                    "'effects found', 'ambiguous' (the explanations the data cannot tell "
                    "apart, and the measurements that would separate them) or 'unexplained "
                    "structure remains'. Extensions: " + ", ".join(EXTENSIONS) + "; and "
                    f"{GAIN_DRIFT} (a factor per angle of incidence: a measurement "
                    "artefact) on tables of at least 3 angles of incidence.",
    )
    add_data_argument(p)
    add_model_argument(p, what="base model")
    add_ignore_sigma_argument(p)
    p.add_argument("--json", action="store_true", help="one JSON object on stdout")
    p.add_argument("--out", metavar="DIR",
                   help="write residual maps before/after, polar fits and diagnosis.json here "
                        "(default: print only)")
    p.add_argument("--separate-out", metavar="FILE",
                   help="when ambiguous, write the measurements that would separate the "
                        "alternatives as a plan (gamma_deg, theta_deg, why, separation_sigma; "
                        "CSV); header only when nothing is ambiguous (default: not written)")
    p.add_argument("--extensions", metavar="A,B",
                   help="candidate extensions, comma-separated (default: all registered)")
    p.add_argument("--max-effects", type=NON_NEGATIVE_INT, default=3, metavar="N",
                   help="add at most N effects (default 3)")
    p.add_argument("--alpha", type=FINITE, default=0.01,
                   help="significance level of the lack-of-fit and structure tests (default 0.01)")
    p.add_argument("--seed", type=SEED, default=0,
                   help="seed of the fits' random starts (default 0)")
    p.set_defaults(handler=_cmd_diagnose)


def _cmd_diagnose(args: argparse.Namespace) -> int:
    from .._atomic import claim_outputs
    from ..errors import IrreflectError
    from ..models import get_model
    from ..models.extensions import GAIN_DRIFT, get_extension
    from ..validation import split_names

    if not 0.0 < args.alpha < 1.0:
        raise IrreflectError(f"--alpha must lie strictly between 0 and 1 (e.g. 0.01), found "
                             f"{args.alpha:g}")
    extensions = None
    if args.extensions is not None:
        extensions = split_names(args.extensions, "--extensions", "background,retroreflection")
        if not extensions:
            raise IrreflectError("--extensions is empty: expected a comma-separated list of "
                                 "extensions (see 'irreflect models'), or leave the option out "
                                 "to try them all")
        for name in extensions:
            if name != GAIN_DRIFT:  # built per table, not registered
                get_extension(name)
        twice = sorted({n for n in extensions if extensions.count(n) > 1})
        if twice:  # as compare --models refuses a model listed twice
            raise IrreflectError(f"--extensions lists '{twice[0]}' twice: list each "
                                 "extension once")
    get_model(args.model)
    # outputs are claimed before the table is read: an output never replaces an input
    # (the table, also through a link or a hard link) of the same run
    with claim_outputs((args.out, "dir", "--out"),
                       (args.separate_out, "file", "--separate-out", (".csv",))):
        return _diagnose(args, extensions)


def _diagnose(args, extensions) -> int:
    from ..diagnose.workflow import diagnose
    from ..plots.diagnose import write_outputs

    meas = load_data(args)
    warn_if_sigma_decides(meas, args.model, "diagnose looks for what it misses")
    bar = _progress()
    try:
        result = diagnose(meas, args.model, extensions=extensions, max_effects=args.max_effects,
                          seed=args.seed, alpha=args.alpha, progress=bar)
    finally:
        bar.close()
    from pathlib import Path

    from .._atomic import atomic_path

    inside = None  # --separate-out inside --out: written with the folder, in its manifest
    if args.separate_out is not None and args.out is not None:
        try:
            inside = Path(args.separate_out).resolve().relative_to(Path(args.out).resolve())
        except ValueError:
            inside = None
    written = (write_outputs(result, meas, args.out, extra_tables=None if inside is None else
                             {inside.as_posix(): result.separating_table()})
               if args.out is not None else [])
    if args.separate_out is not None and inside is None:
        path = Path(args.separate_out)
        with atomic_path(path, "--separate-out") as tmp:
            result.separating_table().to_csv(tmp, index=False)
        written.append(path)
    if args.json:
        print_json(result.to_dict())
    else:
        print(result.report())
        for path in written:
            print(f"wrote {path}")
    return 0


class _progress:
    """tqdm on stderr when it is a terminal, fed with step messages; elsewhere (a pipe, a
    log) a line at most every :attr:`EVERY` seconds, so that a long diagnosis is seen to
    go on (a held-out 2,976-point table took 157 s with nothing printed) and a short one
    prints nothing."""

    EVERY = 10.0

    def __init__(self):
        import time

        from tqdm import tqdm

        from .._progress import on_terminal

        self.clock = time.perf_counter
        self.t0 = self.last = self.clock()
        self.fits = 0
        self.bar = (tqdm(desc="diagnose", unit="fit", file=sys.stderr, leave=False)
                    if on_terminal() else None)

    def __call__(self, message: str) -> None:
        self.fits += 1
        if self.bar is not None:
            self.bar.set_postfix_str(message, refresh=False)
            self.bar.update(1)
            return
        now = self.clock()
        if now - self.last >= self.EVERY:
            self.last = now
            print(f"diagnose: {self.fits} fits, {message} ({now - self.t0:.0f} s)",
                  file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
