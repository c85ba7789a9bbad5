"""Command-line interface: ``irreflect <command> ...``.

Commands live with their capability: each module in :data:`COMMAND_MODULES` exposes
``register(subparsers)``, which adds its parser(s) with ``set_defaults(handler=...)``; a
handler takes the parsed arguments and returns the exit code. User errors
(:class:`~irreflect.errors.IrreflectError`) are printed as one line on stderr with exit
code 2, failed fits with exit code 1; nothing is written half-way.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import json
import sys
import warnings

from . import __version__
from .errors import FitError, IrreflectError

#: Modules that add subcommands (the ones not yet in the package are skipped).
COMMAND_MODULES = (
    "irreflect.cli",
    "irreflect.selection.cli",
    "irreflect.protocol",
    "irreflect.compare",
    "irreflect.diagnose",
    "irreflect.report",
    "irreflect.room.command",
)
#: Which module provides each command, so that running one command imports only its
#: module (the optimiser, the statistics and the plotting stacks cost seconds to import).
COMMANDS = {
    "fit": "irreflect.cli", "plot": "irreflect.cli", "models": "irreflect.cli",
    "select": "irreflect.selection.cli",
    "protocol": "irreflect.protocol", "evaluate-protocol": "irreflect.protocol",
    "compare": "irreflect.compare",
    "diagnose": "irreflect.diagnose",
    "reproduce": "irreflect.report",
    "room": "irreflect.room.command",
}


# ----------------------------------------------------------------------------- parsing
class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (no usage block), exit code 2."""

    def error(self, message):
        self.exit(2, f"irreflect: error: {self.prog}: {message} (see '{self.prog} --help')\n")


def _argument_type(check, label: str):
    """An argparse ``type`` from a ``validation.check_*`` helper; its name shows in errors."""

    def convert(text: str):
        try:
            return check(text)
        except (IrreflectError, ValueError) as exc:
            raise argparse.ArgumentTypeError(f"expected {label}, found '{text}'") from exc

    convert.__name__ = label
    return convert


def _int(text, minimum):
    from .validation import check_int

    return check_int(int(text), "value", minimum)


def _float(text, **bounds):
    from .validation import check_number

    return check_number(text, "value", **bounds)


def int_at_least(minimum: int):
    """argparse type: an integer >= ``minimum``."""
    return _argument_type(lambda t: _int(t, minimum), f"an integer >= {minimum}")


#: argparse types: a seed (integer >= 0), integers >= 1 / >= 0, finite numbers
SEED = _argument_type(lambda t: _int(t, 0), "a seed (an integer >= 0)")
POSITIVE_INT = _argument_type(lambda t: _int(t, 1), "an integer >= 1")
NON_NEGATIVE_INT = _argument_type(lambda t: _int(t, 0), "an integer >= 0")
FINITE = _argument_type(lambda t: _float(t), "a finite number")
NON_NEGATIVE = _argument_type(lambda t: _float(t, low=0.0), "a finite number >= 0")
POSITIVE = _argument_type(lambda t: _float(t, low=0.0, low_open=True), "a number > 0")
ANGLE = _argument_type(lambda t: _float(t, low=-90.0, high=90.0, low_open=True,
                                         high_open=True),
                       "an angle in degrees strictly between -90 and 90")


# ----------------------------------------------------------------------------- shared helpers
def add_data_argument(parser: argparse.ArgumentParser) -> None:
    """The DATA positional and the options every command that reads a table shares."""
    parser.add_argument("data", metavar="DATA",
                        help="measurement table (CSV or Parquet: gamma_deg, theta_deg, power"
                             "[, sigma, material])")
    parser.add_argument("--average-duplicates", action="store_true",
                        help="average the power of duplicated (gamma, theta) rows instead of refusing them")


def add_model_argument(parser: argparse.ArgumentParser, default: str = "two-lobe") -> None:
    parser.add_argument("--model", default=default,
                        help=f"reflection model (default {default}; see 'irreflect models')")


def load_data(args, command: str | None = None, path=None):
    """Read the DATA table of a command and refuse it up front when it is larger than the
    command's memory budget (:data:`irreflect.validation.POINT_BUDGET`)."""
    from .data import read_measurements
    from .validation import check_points_budget

    path = args.data if path is None else path
    meas = read_measurements(path, average_duplicates=args.average_duplicates)
    check_points_budget(meas.n_points, command or args.command, str(path))
    return meas


#: Up to this many points, a command that fits once uses the numpy fitter: loading the
#: compiled kernel (about a second) costs more than it saves on one fit.
SINGLE_FIT_NUMPY_POINTS = 5000


def single_fit_engine(n_points: int) -> str | None:
    """The fitting engine of a command that fits one table once."""
    return "numpy" if n_points <= SINGLE_FIT_NUMPY_POINTS else None


def print_json(obj) -> None:
    json.dump(obj, sys.stdout, indent=2, default=json_default)
    sys.stdout.write("\n")


def json_default(o):
    """``json.dump(default=...)`` for numpy scalars and arrays."""
    import numpy as np

    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


# ----------------------------------------------------------------------------- core commands
def _cmd_fit(args) -> int:
    import contextlib

    from ._atomic import claim_output

    claim = (claim_output(args.save, "file", "--save", suffixes=(".json",)) if args.save
             else contextlib.nullcontext())
    with claim:  # the material file's path is checked and locked before any work
        return _fit(args)


def _fit(args) -> int:
    from .fitting import fit
    from .models import get_model

    model = get_model(args.model)
    if args.save and args.reflectance is not None:
        from .room.materials import parse_reflectance

        parse_reflectance(args.reflectance, "--reflectance")  # before the fit, not after
    meas = load_data(args)
    result = fit(meas, model, seed=args.seed, engine=single_fit_engine(meas.n_points))
    if args.save:
        from .room.materials import save_material

        save_material(result, args.save, data_file=args.data, wavelength_nm=args.wavelength,
                      notes=args.notes, reflectance=args.reflectance)
    if args.json:
        d = result.to_dict()
        print_json({k: d[k] for k in ("model", "params", "stderr", "r2", "rmse", "mse",
                                      "n_points", "fit_ms", "converged", "message",
                                      "at_bound", "ill_determined", "warnings")}
                   | {"polar_error_pct": result.polar_errors()})
    else:
        print(f"{meas.name}: {meas.n_points} points, angles of incidence "
              f"{', '.join(f'{g:g}' for g in meas.gammas)} deg")
        print(result.report(warnings=False))  # the warnings go to stderr
        if args.save:
            print(f"wrote {args.save} (material file for 'irreflect room' scenes)")
    return 0


def _cmd_plot(args) -> int:
    from ._atomic import claim_output
    from .fitting import fit
    from .models import get_model
    from .plots import plot_polar, save_figure

    model = get_model(args.model)
    with claim_output(args.out, "file", "--out", suffixes=(".png", ".svg", ".pdf")):
        meas = load_data(args)
        predict, title = None, meas.name
        if args.fit:
            result = fit(meas, model, seed=args.seed, engine=single_fit_engine(meas.n_points))
            predict = result.predict
            title = f"{meas.name}: {result.model} fit, R^2 = {result.r2:.4f}"
        ax = plot_polar(meas, predict, title=title)
        save_figure(ax.figure, args.out)
    print(f"wrote {args.out}")
    return 0


def _cmd_models(args) -> int:
    from .models import get_model, model_names

    for name in model_names():
        m = get_model(name)
        print(f"{name:<18} {m.n_params:>2} parameters  {m.formula}")
    return 0


def register(sub) -> None:
    p = sub.add_parser("fit", help="fit a reflection model to a measurement table",
                       description="Fit a reflection model and print coefficients with standard "
                                   "errors, R^2, RMSE, MSE and the per-gamma polar-area error.")
    add_data_argument(p)
    add_model_argument(p)
    p.add_argument("--seed", type=SEED, default=0,
                   help="seed of the random extra starts (default 0)")
    p.add_argument("--json", action="store_true", help="one JSON object on stdout")
    p.add_argument("--save", metavar="MATERIAL.json",
                   help="also write the fit as a material file for room scenes (default: no)")
    p.add_argument("--reflectance", default=None, metavar="RHO|K",
                   help="with --save: total reflectance of the material (0..1), or K when the "
                        "power column is BRDF x cos(theta) in 1/sr (default: none, the scene "
                        "gives it)")
    p.add_argument("--wavelength", type=float, default=None, metavar="NM",
                   help="with --save: wavelength of the measurement (nm; default: none)")
    p.add_argument("--notes", default=None,
                   help="with --save: free text kept in the file (default: none)")
    p.set_defaults(handler=_cmd_fit)

    p = sub.add_parser("plot", help="polar diagram per angle of incidence (Figs. 15-17)")
    add_data_argument(p)
    add_model_argument(p)
    p.add_argument("--fit", action="store_true", help="draw the fitted model over the markers")
    p.add_argument("--seed", type=SEED, default=0,
                   help="seed of the fit's random extra starts, with --fit (default 0)")
    p.add_argument("--out", required=True, metavar="FILE.png",
                   help="figure file (.png, .svg or .pdf)")
    p.set_defaults(handler=_cmd_plot)

    p = sub.add_parser("models", help="list the reflection models")
    p.set_defaults(handler=_cmd_models)


# ----------------------------------------------------------------------------- entry point
def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser with every command, or only ``command``'s module when it is known."""
    parser = OneLineParser(
        prog="irreflect",
        description="Reflection models for infrared / visible-light indoor multipath.",
    )
    parser.add_argument("--version", action="version", version=f"irreflect {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=OneLineParser)
    modules = (COMMANDS[command],) if command in COMMANDS else COMMAND_MODULES
    for name in modules:
        if name == __name__:
            register(sub)
            continue
        if importlib.util.find_spec(name.rsplit(".", 1)[0]) is None:
            continue
        if importlib.util.find_spec(name) is None:
            continue
        module = importlib.import_module(name)
        if hasattr(module, "register"):
            module.register(sub)
    return parser


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv in (["--version"], ["-V"]):  # without importing every command's module
        print(f"irreflect {__version__}")
        return 0
    command = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser(command)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version, or a one-line usage error
        return exc.code if isinstance(exc.code, int) else 2
    if not getattr(args, "handler", None):
        parser.print_help(sys.stderr)
        return 2
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            code = args.handler(args)
        except IrreflectError as exc:
            _print_notes(caught)
            print(f"irreflect: error: {_one_line(exc)}", file=sys.stderr)
            return 2
        except FitError as exc:
            _print_notes(caught)
            print(f"irreflect: fit failed: {_one_line(exc)}", file=sys.stderr)
            return 1
        except MemoryError:
            print("irreflect: error: out of memory: subsample the table or lower the budget "
                  "options (see 'Bad input' in the README for each command's limit)",
                  file=sys.stderr)
            return 1
        except OSError as exc:  # a full disk, a file removed under us: the system's reason
            where = f" {exc.filename}" if exc.filename else ""
            print(f"irreflect: error: cannot read or write{where}: "
                  f"{exc.strerror or _one_line(exc)}", file=sys.stderr)
            return 1
        except KeyboardInterrupt:
            print("irreflect: interrupted", file=sys.stderr)
            return 130
    _print_notes(caught)
    return int(code or 0)


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split("\n")).strip() or type(exc).__name__


def _print_notes(caught) -> None:
    """Reader notes and fit warnings, each once, one line each, on stderr."""
    from .data import DataNotice
    from .errors import FitWarning

    seen = set()
    for w in caught:
        kind = ("note" if issubclass(w.category, DataNotice) else
                "warning" if issubclass(w.category, FitWarning) else None)
        if kind and str(w.message) not in seen:
            seen.add(str(w.message))
            print(f"irreflect: {kind}: {w.message}", file=sys.stderr)


if __name__ == "__main__":
    sys.exit(main())
