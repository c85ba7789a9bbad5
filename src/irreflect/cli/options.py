"""What every command shares: the one-line parser, option types, the DATA and --model
arguments, reading a table within the command's budget, JSON on stdout."""

from __future__ import annotations

import argparse
import re
import sys

from .._jsonio import dumps
from ..errors import IrreflectError
from ..validation import check_int, check_number


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (no usage block), exit code 2, and
    that reads whatever starts like a negative number as a value, as it reads ``-20``,
    rather than as an unknown option: a comma-separated list (``--gammas -20,-40``, with
    a stray comma ``-20,`` or ``-20,,-40``), an exponent (``-2e1``, ``-1e-12``), ``-inf``
    and ``-nan``. argparse's own pattern took only ``-20`` and ``-2.5``: the others ended
    in "expected at least one argument" (no option starts with a digit, so none is lost);
    a malformed one (``-20x``) now reaches the option's type and its one-line error."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-(\.?\d|(inf|infinity|nan)(,|$))",
                                                   re.IGNORECASE)

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
    return check_int(int(text), "value", minimum)


def int_at_least(minimum: int):
    """argparse type: an integer >= ``minimum``."""
    return _argument_type(lambda t: _int(t, minimum), f"an integer >= {minimum}")


#: argparse types: a seed (integer >= 0), integers >= 1 / >= 0, finite numbers, angles
SEED = _argument_type(lambda t: _int(t, 0), "a seed (an integer >= 0)")
POSITIVE_INT = _argument_type(lambda t: _int(t, 1), "an integer >= 1")
NON_NEGATIVE_INT = _argument_type(lambda t: _int(t, 0), "an integer >= 0")
FINITE = _argument_type(lambda t: check_number(t, "value"), "a finite number")
NON_NEGATIVE = _argument_type(lambda t: check_number(t, "value", low=0.0), "a finite number >= 0")
POSITIVE = _argument_type(lambda t: check_number(t, "value", low=0.0, low_open=True),
                          "a number > 0")
ANGLE = _argument_type(lambda t: check_number(t, "value", low=-90.0, high=90.0, low_open=True,
                                              high_open=True),
                       "an angle in degrees strictly between -90 and 90")
#: argparse type: one angle or several, comma-separated ("10,40,70"); with
#: ``nargs="+", action=Flatten`` the option takes them space- or comma-separated alike
def _angles(text: str) -> tuple[float, ...]:
    parts = [a for a in text.split(",") if a.strip()]
    if not parts:
        raise ValueError(text)
    return tuple(check_number(a, "value", low=-90.0, high=90.0, low_open=True,
                              high_open=True) for a in parts)


ANGLES = _argument_type(
    _angles, "angles in degrees strictly between -90 and 90 (space- or comma-separated)")


class Flatten(argparse.Action):
    """Store the values of an ``nargs`` option whose type returns tuples as one flat list."""

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, [x for v in values for x in v])


def add_data_argument(parser: argparse.ArgumentParser, *, nargs=None) -> None:
    """The DATA positional and the options every command that reads a table shares."""
    parser.add_argument("data", metavar="DATA", nargs=nargs,
                        help="measurement table (CSV or Parquet: gamma_deg, theta_deg, power"
                             "[, sigma, material]), or the name of a bundled dataset "
                             "(terrazzo, plasterboard, foam_board; 'irreflect datasets' lists "
                             "them)" + ("; several run in parallel" if nargs else ""))
    parser.add_argument("--average-duplicates", action="store_true",
                        help="average the power of duplicated (gamma, theta) rows instead of "
                             "refusing them")


def add_model_argument(parser: argparse.ArgumentParser, default: str = "two-lobe",
                       what: str = "reflection model") -> None:
    """``--model``: one grammar everywhere, ``name[:N][+extension...][@G]``."""
    parser.add_argument("--model", default=default,
                        help=f"{what} (default {default}): a name from 'irreflect models', "
                             "with ':N' lobes, '+extension' effects (e.g. "
                             "two-lobe+background)")


def add_resolution_argument(parser: argparse.ArgumentParser, effect: str) -> None:
    """``--resolution DEG``: the receiver's angular resolution, one wording everywhere, and
    what it does in the command (``effect``)."""
    parser.add_argument("--resolution", type=NON_NEGATIVE, default=0.0, metavar="DEG",
                        help="the receiver's angular resolution: the full width of receiver "
                             "angle one reading averages over (deg, default 0: a point "
                             f"receiver); {effect}")


def load_data(args, command: str | None = None, path=None):
    """Read the DATA table of a command and refuse it up front when it is larger than the
    command's memory budget (:data:`irreflect.validation.POINT_BUDGET`)."""
    from ..data import SIGMA_LEFT_OUT, read_measurements
    from ..validation import check_points_budget

    path = args.data if path is None else path
    # --ignore-sigma: the column is left out before it is checked (a column of zeros is
    # then no error: the option is the way around it)
    drop = bool(getattr(args, "ignore_sigma", False))
    meas = read_measurements(path, average_duplicates=args.average_duplicates,
                             ignore_sigma=drop)
    check_points_budget(meas.n_points, command or args.command, str(path))
    if drop and SIGMA_LEFT_OUT not in meas.notes:
        print(f"irreflect: warning: --ignore-sigma has no effect: {meas.name} has no "
              "sigma column", file=sys.stderr)
    return meas


def warn_if_sigma_decides(meas, model: str, what: str) -> None:
    """Warn when the table's sigma column, not the power, decides the weighted all-points fit
    of ``model`` (:func:`irreflect.fitting.weights_check`); ``what``: what the command does
    with that fit."""
    if meas.sigma is None:
        return
    import warnings

    from ..errors import FitError, FitWarning
    from ..fitting import fit, weights_check

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)  # the command's own fits say theirs
        try:
            text, _ = weights_check(meas, fit(meas, model), model)
        except FitError:
            return
    if text:
        print(f"irreflect: warning: {meas.name}, {model} on all points: {text}; {what} "
              "(--ignore-sigma: unweighted)", file=sys.stderr)


def add_ignore_sigma_argument(p) -> None:
    """``--ignore-sigma``: the table's sigma column is left out (:func:`load_data`)."""
    p.add_argument("--ignore-sigma", action="store_true",
                   help="fit unweighted, leaving the table's sigma column out before it is "
                        "checked (default: weighted by 1/sigma^2; when a model misfits beyond "
                        "the noise, the points of smallest sigma decide a weighted fit, which "
                        "is warned of: for a curve of power, fit unweighted)")


#: Up to this many points, a command that fits once uses the numpy fitter: loading the
#: compiled kernel (about a second) costs more than it saves on one search. A second
#: search (the retry) runs compiled ("numpy-first"): on tables the model misfits it took
#: 7.7-10.7 s with numpy (held-out tables of 1668-2880 points), 2.1-2.4 s so.
SINGLE_FIT_NUMPY_POINTS = 5000


def single_fit_engine(n_points: int) -> str | None:
    """The fitting engine of a command that fits one table once."""
    return "numpy-first" if n_points <= SINGLE_FIT_NUMPY_POINTS else None


def print_json(obj) -> None:
    """One strict JSON object on stdout (NaN as null)."""
    sys.stdout.write(dumps(obj))
