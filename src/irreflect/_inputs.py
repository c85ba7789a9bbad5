"""Reading the user's input files: regular files only, bounded by what is read, never a
file this run is about to replace.

Every reader of irreflect (measurement tables, scenes, material files, protocols,
checkpoints) opens its file through :func:`read_bytes`:

* the path must name an existing **regular file** (a symlink to one is fine): a folder, a
  device (``/dev/zero``), a FIFO or a socket is refused before it is opened, so nothing
  hangs and nothing is read without end;
* at most ``limit`` bytes are **read** (one more to tell that there are more): the size is
  what the file gives, not what ``stat`` or a header declares (``/proc`` files say 0);
* a file that an output of the same run would replace (``protocol --lobe-from data.csv
  --out data.csv``) is refused (:func:`irreflect._atomic.check_not_output`).

Parsed documents (JSON, TOML) are checked for their nesting depth before they are parsed
(:func:`check_nesting`), so a 100,000-deep document is one line, not a ``RecursionError``.
"""

from __future__ import annotations

import json
import os
import stat
import tomllib
from pathlib import Path

from ._atomic import check_not_output
from .errors import IrreflectError

#: Deepest nesting of brackets/braces accepted in a JSON or TOML document read by irreflect
#: (a scene nests 4 deep, a material file 3).
MAX_NESTING = 32
#: Scene TOML files and material JSON files larger than this are refused (they are a few KB).
MAX_DOCUMENT_BYTES = 4 * 2**20


def _kind(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISFIFO(mode):
        return "a pipe (FIFO)"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def input_path(path, what: str, expected: str) -> Path:
    """``path`` as a :class:`~pathlib.Path`, after checking its type and that it names an
    existing regular file (``what``: how messages name it; ``expected``: what it should be,
    e.g. "a scene TOML file")."""
    if isinstance(path, bytes):
        path = os.fsdecode(path)
    if not isinstance(path, str | os.PathLike):
        raise IrreflectError(f"{what}: expected a path to {expected}; found "
                             f"{type(path).__name__}")
    if str(path).strip() == "":
        raise IrreflectError(f"{what}: expected a path to {expected}; found an empty path")
    path = Path(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise IrreflectError(f"{path}: no such file: expected {expected}") from None
    except NotADirectoryError:
        raise IrreflectError(f"{path}: no such file (a part of the path is a file): "
                             f"expected {expected}") from None
    except OSError as exc:
        raise IrreflectError(f"{path}: cannot be read ({exc.strerror or exc}): expected "
                             f"{expected}") from None
    if not stat.S_ISREG(st.st_mode):
        raise IrreflectError(f"{path}: is {_kind(st.st_mode)}; expected {expected} (a "
                             "regular file)")
    return path


def read_bytes(path, what: str, expected: str, limit: int, fix: str = "",
               reading: str | None = None) -> bytes:
    """The content of a regular file, at most ``limit`` bytes (else one line naming the
    limit and ``fix``). ``reading``: the option of an output of this run that may be read
    back (a checkpoint)."""
    path = input_path(path, what, expected)
    check_not_output(path, expected, reading)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise IrreflectError(f"{path}: cannot be read ({exc.strerror or exc}): expected "
                             f"{expected}") from None
    try:
        st = os.fstat(fd)  # the file opened, not the one stat'ed a moment ago
        if not stat.S_ISREG(st.st_mode):
            raise IrreflectError(f"{path}: is {_kind(st.st_mode)}; expected {expected} (a "
                                 "regular file)")
        chunks, size = [], 0
        while size <= limit:
            chunk = os.read(fd, min(1 << 20, limit + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as exc:
        raise IrreflectError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    finally:
        os.close(fd)
    if size > limit:
        raise IrreflectError(f"{path}: more than {_size(limit)}, the most irreflect reads as "
                             f"{expected}" + (f": {fix}" if fix else ""))
    return b"".join(chunks)


def _size(n: int) -> str:
    return f"{n // 2**20} MB" if n >= 2**20 else f"{n // 2**10} KB" if n >= 2**10 else f"{n} bytes"


def read_text(path, what: str, expected: str, limit: int = MAX_DOCUMENT_BYTES,
              fix: str = "") -> str:
    """A UTF-8 text file (a byte-order mark is allowed), read as :func:`read_bytes`."""
    raw = read_bytes(path, what, expected, limit, fix)
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise IrreflectError(f"{path}: not UTF-8 text (byte 0x{raw[exc.start]:02x} on line "
                             f"{line}); expected {expected}") from None


# ----------------------------------------------------------------------------- nesting
def check_nesting(text: str, source: str, expected: str, limit: int = MAX_NESTING,
                  comments: str = "") -> None:
    """Refuse a JSON or TOML text whose brackets/braces nest deeper than ``limit``
    (counted outside strings; ``comments``: the comment character, '#' for TOML)."""
    depth = worst = 0
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if c in "\"'":
            i = _skip_string(text, i)
            continue
        if comments and c == comments:
            j = text.find("\n", i)
            i = n if j < 0 else j
            continue
        if c in "[{":
            depth += 1
            if depth > worst:
                worst = depth
                if worst > limit:
                    line = text.count("\n", 0, i) + 1
                    raise IrreflectError(
                        f"{source}: brackets nest more than {limit} deep (line {line}); "
                        f"expected {expected}, which nests a few levels")
        elif c in "]}":
            depth -= 1
        i += 1


def _skip_string(text: str, i: int) -> int:
    """Index after the string starting at ``i`` (JSON/TOML basic, literal and multi-line
    strings; an unterminated string ends the text)."""
    quote = text[i]
    triple = text.startswith(quote * 3, i)
    end_mark = quote * 3 if triple else quote
    j = i + len(end_mark)
    while True:
        k = text.find(end_mark, j)
        if k < 0:
            return len(text)
        if quote == '"':
            backslashes = 0
            m = k - 1
            while m >= j and text[m] == "\\":
                backslashes += 1
                m -= 1
            if backslashes % 2:
                j = k + 1
                continue
        if not triple and "\n" in text[j:k]:  # a one-line string ends at the line's end
            return text.find("\n", j)
        return k + len(end_mark)


def depth_of(value, limit: int = MAX_NESTING) -> int:
    """Nesting depth of a parsed document (dicts and lists), without recursion; stops
    counting beyond ``limit + 1``."""
    worst = 0
    stack = [(value, 0)]
    while stack:
        item, d = stack.pop()
        if isinstance(item, dict | list):
            d += 1
            worst = max(worst, d)
            if worst > limit:
                return worst
            stack.extend((v, d) for v in (item.values() if isinstance(item, dict) else item))
    return worst


def parse_json(text: str, source: str, expected: str):
    """A JSON document (NaN/Infinity allowed, as Python writes them) after the nesting
    check; one line for anything that is not JSON."""
    check_nesting(text, source, expected)
    try:
        return json.loads(text, object_pairs_hook=_unique_keys)
    except _DuplicateKey as exc:
        raise IrreflectError(f"{source}: key '{exc.args[0]}' appears twice in one object; "
                             f"expected {expected}: keep one") from None
    except (ValueError, RecursionError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise IrreflectError(f"{source}: not JSON ({first}); expected {expected}") from None


class _DuplicateKey(Exception):
    pass


def _unique_keys(pairs) -> dict:
    """A JSON object whose keys are distinct (``json`` would keep the last one silently)."""
    out = {}
    for key, value in pairs:
        if key in out:
            raise _DuplicateKey(key)
        out[key] = value
    return out


def parse_toml(text: str, source: str, expected: str) -> dict:
    """A TOML document after the nesting check (dotted keys and table headers nest too:
    the parsed document is checked again); one line for anything that is not TOML."""
    check_nesting(text, source, expected, comments="#")
    try:
        doc = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, RecursionError, ValueError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise IrreflectError(f"{source}: not valid TOML ({first}): fix the syntax") from None
    if depth_of(doc) > MAX_NESTING:
        raise IrreflectError(f"{source}: tables nest more than {MAX_NESTING} deep; expected "
                             f"{expected}, which nests a few levels")
    return doc
