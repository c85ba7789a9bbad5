"""Command-line interface: ``irreflect <command> ...``.

:data:`COMMANDS` is the one command table: command name -> the module of this package that
defines it. Each module has ``register(subparsers)``, which adds its parser(s) with
``set_defaults(handler=...)``; a handler takes the parsed arguments and returns the exit
code. Running one command imports only its module (the optimiser, statistics and plotting
stacks cost seconds to import); shared options and types live in :mod:`.options`.

User errors (:class:`~irreflect.errors.IrreflectError`) are printed as one line on stderr
with exit code 2, failed fits with exit code 1; nothing is written half-way.

Adding a command is one module here plus its line(s) in :data:`COMMANDS`; the CLI contract
tests (``tests/test_contracts_cli.py``) then check its ``--help``, ``--json`` and bad input.
"""

from __future__ import annotations

import importlib
import sys
import warnings

from .. import __version__
from ..errors import FitError, IrreflectError
from .options import OneLineParser

#: command -> module of this package that registers it (in the order of ``--help``)
COMMANDS = {
    "fit": "fit",
    "plot": "fit",
    "models": "fit",
    "select": "select",
    "protocol": "protocol",
    "evaluate-protocol": "protocol",
    "compare": "compare",
    "diagnose": "diagnose",
    "next": "campaign",
    "campaign": "campaign",
    "reproduce": "reproduce",
    "room": "room",
    "datasets": "datasets",
}

#: Commands that fit with the compiled kernel: a cold on-disk cache is built (and announced)
#: before they start. ``fit``, ``plot`` and ``next`` may fit with numpy only (a small
#: table, or nothing to fit yet) and do not wait: their first compiled fit announces the
#: build (:func:`irreflect._compiled.build_notice`).
COMPILED_COMMANDS = frozenset({"select", "protocol", "evaluate-protocol", "compare",
                               "diagnose", "reproduce", "campaign"})

__all__ = ["COMMANDS", "COMPILED_COMMANDS", "build_parser", "main"]


def build_parser(command: str | None = None) -> OneLineParser:
    """The parser with every command, or only ``command``'s module when it is known."""
    parser = OneLineParser(
        prog="irreflect",
        description="Reflection models for infrared / visible-light indoor multipath.",
    )
    parser.add_argument("--version", action="version", version=f"irreflect {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=OneLineParser)
    modules = [COMMANDS[command]] if command in COMMANDS else list(dict.fromkeys(COMMANDS.values()))
    for name in modules:
        importlib.import_module(f"{__name__}.{name}").register(sub)
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
    from .._atomic import RUNNING_COMMAND
    from ..validation import forget_memory_options

    forget_memory_options()
    running = RUNNING_COMMAND.set(args.command)
    try:
        return _run(args, parser)
    finally:
        RUNNING_COMMAND.reset(running)


def _run(args, parser) -> int:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            if args.command in COMPILED_COMMANDS:
                from .._compiled import ensure_compiled
                from ..fitting import warm

                ensure_compiled(warm)  # a cold cache: built now, announced, not silently
            code = args.handler(args)
            sys.stdout.flush()
        except BrokenPipeError:  # `irreflect ... | head`: the reader left; no error to report
            _silence_stdout()
            return 141
        except IrreflectError as exc:
            _print_notes(caught)
            print(f"irreflect: error: {_one_line(exc)}", file=sys.stderr)
            return 2
        except FitError as exc:
            _print_notes(caught)
            print(f"irreflect: fit failed: {_one_line(exc)}", file=sys.stderr)
            return 1
        except MemoryError:
            from ..validation import memory_hint

            hint = memory_hint("the table's size: subsample the table")
            print(f"irreflect: error: out of memory in '{args.command}': its size is set by "
                  f"{hint}: change it, or lower the memory budget IRREFLECT_BUDGET_MEMORY "
                  "(GB) on a machine shared with other work (docs/bad-input.md)",
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


def _silence_stdout() -> None:
    """Point stdout at /dev/null, so that the interpreter's final flush into a closed pipe
    does not print a traceback (the recipe of Python's signal documentation)."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # stdout is not a file (e.g. captured by a test)
        pass


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split("\n")).strip() or type(exc).__name__


def _print_notes(caught) -> None:
    """Reader notes and fit warnings, each once, one line each, on stderr."""
    from ..data import DataNotice
    from ..errors import FitWarning

    seen = set()
    for w in caught:
        kind = ("note" if issubclass(w.category, DataNotice) else
                "warning" if issubclass(w.category, FitWarning) else None)
        if kind and str(w.message) not in seen:
            seen.add(str(w.message))
            print(f"irreflect: {kind}: {w.message}", file=sys.stderr)
