"""The CLI contract, over every command of :data:`irreflect.cli.COMMANDS`.

Adding a command is one module in ``irreflect/cli/`` plus its line in ``COMMANDS``; this
suite then checks it without edits: ``--help`` works and every option says what it does,
``--json`` (where offered) prints one strict JSON object, and a missing input file is
refused in one line with exit code 2 and nothing written.
"""

from __future__ import annotations

import contextlib
import io
import json
import subprocess
import sys
from pathlib import Path

import pytest

from irreflect.cli import COMMANDS, build_parser, main
from irreflect.data import bundled_dir

TERRAZZO = str(bundled_dir() / "terrazzo.csv")
PROTOCOL = ("gamma_deg,theta_deg,purpose\n-20,20,mirror\n-20,10,lobe_width\n-20,30,lobe_width\n"
            "-20,-40,diffuse\n-40,40,mirror\n-40,30,lobe_width\n-40,50,lobe_width\n"
            "-40,-20,diffuse\n-60,60,mirror\n-60,50,lobe_width\n-60,70,lobe_width\n"
            "-60,0,diffuse\n")


def _run(argv):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


def _parser(command):
    return build_parser(command)._subparsers._group_actions[0].choices[command]


#: the smallest real run of each command that offers --json (inputs under ``root``)
def _json_argv(command, root: Path):
    (root / "protocol.csv").write_text(PROTOCOL)
    (root / "empty.csv").write_text("gamma_deg,theta_deg,power\n")
    return {
        "fit": ["fit", TERRAZZO, "--json"],
        "compare": ["compare", TERRAZZO, "--models", "two-lobe,phong@10", "--json"],
        "diagnose": ["diagnose", TERRAZZO, "--max-effects", "0", "--json"],
        "evaluate-protocol": ["evaluate-protocol", str(root / "protocol.csv"), TERRAZZO,
                              "--json"],
        "next": ["next", str(root / "empty.csv"), "--n", "3", "--json"],
        "campaign": ["campaign", TERRAZZO, "--strategies", "adaptive,paper", "--n-max", "9",
                     "--json"],
        "datasets": ["datasets", "--json"],
    }[command]


def _offers_json(command) -> bool:
    return any("--json" in a.option_strings for a in _parser(command)._actions)


@pytest.mark.parametrize("command", list(COMMANDS))
def test_help_lists_every_option(command):
    code, out, err = _run([command, "--help"])
    assert code == 0 and err == ""
    assert out.startswith(f"usage: irreflect {command}")
    for action in _parser(command)._actions:
        for flag in action.option_strings:
            assert flag in out, f"{command} --help does not show {flag}"


@pytest.mark.parametrize("command", [c for c in COMMANDS if _offers_json(c)])
def test_json_is_one_strict_object(command, tmp_path):
    code, out, err = _run(_json_argv(command, tmp_path))
    assert code == 0, err
    doc = json.loads(out, parse_constant=lambda c: pytest.fail(f"{command}: {c} in JSON"))
    assert isinstance(doc, dict) and doc


def test_the_json_catalogue_covers_every_command_that_offers_it(tmp_path):
    for command in COMMANDS:
        if _offers_json(command):
            _json_argv(command, tmp_path)  # KeyError: a new --json command needs a case


@pytest.mark.parametrize("command", [c for c in COMMANDS if c not in ("models", "datasets")])
def test_a_missing_input_is_one_line(command, tmp_path):
    parser = _parser(command)
    positionals = [a for a in parser._actions if not a.option_strings and a.dest != "help"]
    missing = str(tmp_path / "missing.csv")
    argv = [command] + [missing for _ in positionals]
    argv += {"protocol": ["--design-from", missing],  # the commands without a positional
             "reproduce": ["--data-dir", str(tmp_path / "missing"), "--out",
                           str(tmp_path / "report")]}.get(command, [])
    for a in parser._actions:  # required options: an output under tmp_path
        if a.required and a.option_strings:
            suffix = Path(a.metavar or "").suffix  # FILE.png -> x.png
            argv += [a.option_strings[0], str(tmp_path / "out" / f"x{suffix}")]
    before = sorted(tmp_path.rglob("*"))
    code, out, err = _run(argv)
    assert code == 2, (argv, err)
    assert err.count("\n") == 1 and err.startswith("irreflect: error: ")
    assert "missing" in err and "Traceback" not in err
    assert sorted(tmp_path.rglob("*")) == before


def test_every_command_module_registers_only_its_commands():
    import importlib

    for module in dict.fromkeys(COMMANDS.values()):
        parser = build_parser(next(c for c, m in COMMANDS.items() if m == module))
        names = set(parser._subparsers._group_actions[0].choices)
        assert names == {c for c, m in COMMANDS.items() if m == module}
        assert hasattr(importlib.import_module(f"irreflect.cli.{module}"), "register")


def test_python_dash_m_and_version():
    for module in ("irreflect", "irreflect.cli"):
        proc = subprocess.run([sys.executable, "-m", module, "--version"], capture_output=True,
                              text=True, timeout=60)
        assert proc.returncode == 0 and proc.stdout.strip().startswith("irreflect ")


def test_version_does_not_import_the_commands():
    code = ("import sys; from irreflect.cli import main; main(['--version']); "
            "print(sorted(m for m in sys.modules if m.startswith(('irreflect.fitting', "
            "'irreflect.selection', 'scipy', 'pandas', 'matplotlib', 'pymoo', 'numba'))))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0 and proc.stdout.strip().endswith("[]"), proc.stdout
