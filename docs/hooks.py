"""MkDocs hook: the command reference (docs/cli.md) is the commands' own ``--help``.

A line ``<!-- irreflect-help -->`` in a page is replaced by the help of every command of
:data:`irreflect.cli.COMMANDS`, so the reference lists every option as the installed
version has it and cannot drift from the code.
"""

from __future__ import annotations

import contextlib
import io

MARKER = "<!-- irreflect-help -->"


def _help(argv) -> str:
    from irreflect.cli import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        main(argv)
    return out.getvalue().rstrip()


def on_page_markdown(markdown, page, config, files):
    if MARKER not in markdown:
        return markdown
    import os

    from irreflect.cli import COMMANDS

    os.environ.setdefault("COLUMNS", "100")  # argparse wraps at the terminal's width
    parts = ["## irreflect\n", "```\n" + _help(["--help"]) + "\n```\n"]
    for command in COMMANDS:
        parts.append(f"## irreflect {command}\n")
        parts.append("```\n" + _help([command, "--help"]) + "\n```\n")
    return markdown.replace(MARKER, "\n".join(parts))
