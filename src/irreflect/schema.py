"""Declared schemas of the documents irreflect reads: scenes, material files, checkpoint
metadata.

A schema is a tree of small nodes (:class:`Table`, :class:`MapOf`, :class:`ListOf`,
:class:`Vector`, :class:`Number`, :class:`Integer`, :class:`Text`, :class:`Name`,
:class:`Choice`, :class:`AnyOf`, :class:`Nullable`, :class:`Document`) that says for every
key its type, range and finiteness, and how many items a list may hold. ``node.check(value,
key)`` returns the value converted (floats, ints, tuples of floats, dicts with defaults) or
raises :class:`SchemaError`, a one-line :class:`~irreflect.errors.IrreflectError` naming the
file, the key, what was expected, what was found and the fix::

    office.toml: [[emitter]] 1: power_w must be a number > 0 and <= 1e+06 (W); found 1e+308

Rules that tie several keys together (a position inside the room, exactly one of two keys)
stay with the reader; the schema makes sure that they only ever see well-typed values.
Booleans are never numbers (TOML's ``true`` is not 1.0), NaN and infinities are refused
wherever a number is expected (unless a node allows them), integers too large for a float
are refused, and the nesting depth of free-form objects is bounded.
"""

from __future__ import annotations

import difflib
import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass, field

from .errors import SchemaError


def dotted(parts: tuple) -> str:
    """``("params", "u_as")`` -> ``params.u_as``; ``("emitter", 0, "name")`` ->
    ``emitter[1].name`` (list items counted from 1, as people count them)."""
    out = ""
    for part in parts:
        if isinstance(part, int):
            out += f"[{part + 1}]"
        else:
            out += ("." if out else "") + str(part)
    return out


@dataclass
class Context:
    """Where a document came from and how its keys are named in messages: ``style``
    ``"json"`` (``params.u_as``) or ``"toml"`` (``[[emitter]] 2: power_w``,
    ``[materials.wood]: lambertian``, as the keys are written in a TOML file)."""

    source: str | None = None
    style: str = "json"
    arrays: frozenset = frozenset()  # TOML: top-level keys that are arrays of tables
    error: type = SchemaError  # the kind of error raised (a SchemaError subclass)

    def place(self, key: tuple) -> str:
        """How the table (or list item) at ``key`` is named."""
        if self.style != "toml":
            return dotted(key)
        if not key:
            return "top level"
        if len(key) >= 2 and isinstance(key[1], int):
            rest = dotted(key[2:])
            return f"[[{key[0]}]] {key[1] + 1}" + (f" {rest}" if rest else "")
        if len(key) == 1 and key[0] in self.arrays:
            return f"[[{key[0]}]]"
        return f"[{dotted(key)}]"

    def fail(self, key: tuple, message: str, fix: str = "") -> None:
        where = self.place(tuple(key))
        prefix = f"{self.source}: " if self.source else ""
        raise self.error(f"{prefix}{where + ': ' if where else ''}{message}"
                         + (f": {fix}" if fix else ""))

    def refuse(self, key: tuple, expected: str, value, fix: str = "", *,
               shown: str | None = None) -> None:
        """``KEY must be EXPECTED; found VALUE: FIX`` (``shown``: how to show the value)."""
        key = tuple(key)
        seen = found(value) if shown is None else shown
        if not key:
            self.fail(key, f"expected {expected}; found {seen}", fix)
        if self.style == "toml":  # the table's header, then the key within it
            j = max((i for i, k in enumerate(key) if isinstance(k, str)), default=0)
            if j + 1 < len(key) and isinstance(key[j + 1], int) and j == 0 and \
                    key[0] in self.arrays:  # an item of an array of tables
                self.fail(key, f"expected {expected}; found {seen}", fix)
            self.fail(key[:j], f"{dotted(key[j:])} must be {expected}; found {seen}", fix)
        prefix = f"{self.source}: " if self.source else ""
        raise self.error(f"{prefix}{dotted(key)} must be {expected}; found {seen}"
                         + (f": {fix}" if fix else ""))


def found(value) -> str:
    """A short description of a value for messages (never hundreds of characters)."""
    if isinstance(value, bool):
        return f"{str(value).lower()} (a boolean)"
    if value is None:
        return "nothing (null)"
    if isinstance(value, dict):
        return f"a table of {len(value)} key(s)"
    if isinstance(value, list | tuple):
        text = repr(list(value))
        return text if len(text) <= 60 else f"a list of {len(value)} item(s)"
    if isinstance(value, int) and abs(value) > 10**18:
        return f"an integer of {len(str(abs(value)))} digits"
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


# ----------------------------------------------------------------------------- nodes
@dataclass(frozen=True)
class Node:
    """A schema node; ``fix`` is appended to its messages."""

    fix: str = field(default="", kw_only=True)

    def check(self, value, key: tuple, ctx: Context):  # pragma: no cover - abstract
        raise NotImplementedError

    def refuse(self, value, key: tuple, ctx: Context, expected: str):
        ctx.refuse(key, expected, value, self.fix)


def as_float(value) -> float | None:
    """``value`` as a finite float, or None: no booleans, no text, no NaN or infinity, no
    integer beyond the float range."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return None
    try:
        x = float(value)
    except (OverflowError, ValueError, TypeError):
        return None
    return x if math.isfinite(x) else None


@dataclass(frozen=True)
class Number(Node):
    """A finite real number (not a boolean) within optional bounds; ``unit`` for messages."""

    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    unit: str = ""
    allow_nan: bool = False  # NaN kept (a value that was not determined, e.g. a stderr)

    def expected(self) -> str:
        parts = []
        if self.lo is not None:
            parts.append(f"{'>' if self.lo_open else '>='} {self.lo:g}")
        if self.hi is not None:
            parts.append(f"{'<' if self.hi_open else '<='} {self.hi:g}")
        text = "a number" + (" " + " and ".join(parts) if parts else " (finite)")
        return text + (f" ({self.unit})" if self.unit else "")

    def check(self, value, key, ctx):
        if self.allow_nan and isinstance(value, float) and not math.isfinite(value):
            return value
        x = as_float(value)
        if x is None or not self._within(x):
            self.refuse(value, key, ctx, self.expected())
        return x

    def _within(self, x: float) -> bool:
        if self.lo is not None and (x < self.lo or (self.lo_open and x == self.lo)):
            return False
        return not (self.hi is not None and (x > self.hi or (self.hi_open and x == self.hi)))


@dataclass(frozen=True)
class Integer(Node):
    """An integer (not a boolean, not 2.0) within optional bounds."""

    lo: int | None = None
    hi: int | None = None

    def expected(self) -> str:
        if self.lo is not None and self.hi is not None:
            return f"an integer from {self.lo} to {self.hi}"
        if self.lo is not None:
            return f"an integer >= {self.lo}"
        return "an integer" + (f" <= {self.hi}" if self.hi is not None else "")

    def check(self, value, key, ctx):
        ok = isinstance(value, numbers.Integral) and not isinstance(value, bool)
        if ok:
            ok = (self.lo is None or value >= self.lo) and (self.hi is None or value <= self.hi)
        if not ok:
            self.refuse(value, key, ctx, self.expected())
        return int(value)


@dataclass(frozen=True)
class Text(Node):
    """A string of at most ``max_len`` characters, without control characters (newlines
    and tabs allowed with ``multiline``)."""

    max_len: int = 200
    multiline: bool = False
    what: str = "text"

    def check(self, value, key, ctx):
        if not isinstance(value, str):
            self.refuse(value, key, ctx, f"{self.what} (in quotes)")
        if len(value) > self.max_len:
            self.refuse(value, key, ctx, f"{self.what} of at most {self.max_len} characters")
        allowed = "\n\t\r" if self.multiline else ""
        bad = next((c for c in value if (ord(c) < 32 or 127 <= ord(c) < 160)
                    and c not in allowed), None)
        if bad is not None:
            self.refuse(value, key, ctx, f"{self.what} without control characters "
                                         f"(found U+{ord(bad):04X})")
        return value


#: Characters a name may hold besides letters and digits (no '$', '\\', quotes, '/').
NAME_PUNCTUATION = " _-.,:+#()[]"


@dataclass(frozen=True)
class Name(Text):
    """A name shown in figures and used in file names: letters, digits and
    :data:`NAME_PUNCTUATION`, starting with a letter or digit, at most 64 characters (no
    matplotlib mathtext, no path separators)."""

    max_len: int = 64
    what: str = "a name"

    def check(self, value, key, ctx):
        value = super().check(value, key, ctx)
        if not value.strip():
            self.refuse(value, key, ctx, "a name that is not empty")
        bad = next((c for c in value if not (c.isalnum() or c in NAME_PUNCTUATION)), None)
        if bad is not None or not value[0].isalnum():
            what = (f"'{bad}'" if bad is not None else f"a first character '{value[0]}'")
            self.refuse(value, key, ctx, f"letters, digits, spaces and "
                                         f"'{NAME_PUNCTUATION.strip()}', starting with a letter "
                                         f"or digit (it names figures and files); it has {what}")
        return value


@dataclass(frozen=True)
class Choice(Node):
    """One of a few strings (exactly)."""

    options: tuple[str, ...] = ()

    def check(self, value, key, ctx):
        if not isinstance(value, str) or value not in self.options:
            close = (difflib.get_close_matches(value, self.options, n=1)
                     if isinstance(value, str) else [])
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            self.refuse(value, key, ctx, f"one of {', '.join(self.options)}{hint}")
        return value


@dataclass(frozen=True)
class Boolean(Node):
    """true or false (never a number: 1 is not true)."""

    def check(self, value, key, ctx):
        if not isinstance(value, bool):
            self.refuse(value, key, ctx, "true or false")
        return value


@dataclass(frozen=True)
class Nullable(Node):
    """``inner`` or null (JSON ``null``, kept as None)."""

    inner: Node = None

    def check(self, value, key, ctx):
        return None if value is None else self.inner.check(value, key, ctx)


@dataclass(frozen=True)
class AnyOf(Node):
    """The first of ``options`` that accepts the value; ``expected`` names them all."""

    options: tuple[Node, ...] = ()
    expected: str = ""
    shape: Callable | None = None  # picks the option by the value's type when given
    whole: bool = False  # with shape: a refusal names all options, not the one picked

    def check(self, value, key, ctx):
        if self.shape is not None:
            node = self.shape(value)
            if node is None:
                self.refuse(value, key, ctx, self.expected)
            if not self.whole:
                return node.check(value, key, ctx)
            try:
                return node.check(value, key, ctx)
            except SchemaError:
                self.refuse(value, key, ctx, self.expected)
        for node in self.options:
            try:
                return node.check(value, key, ctx)
            except SchemaError:
                continue
        self.refuse(value, key, ctx, self.expected)
        return None  # unreachable


@dataclass(frozen=True)
class Vector(Node):
    """``length`` numbers (each checked by ``item``) as a tuple of floats; with
    ``nonzero`` not all zero (a direction)."""

    length: int = 3
    item: Number = Number()
    nonzero: bool = False
    what: str = "[x, y, z]"

    def expected(self) -> str:
        bounds = self.item.expected().removeprefix("a number").strip()
        return f"{self.length} numbers {self.what}" + (f", each {bounds}" if bounds else "")

    def check(self, value, key, ctx):
        if not isinstance(value, list | tuple) or len(value) != self.length:
            self.refuse(value, key, ctx, self.expected())
        out = []
        for v in value:
            x = as_float(v)
            if x is None or not self.item._within(x):
                self.refuse(value, key, ctx, self.expected())
            out.append(x)
        if self.nonzero and not any(out):
            self.refuse(value, key, ctx, "a direction, not [0, 0, 0]")
        return tuple(out)


@dataclass(frozen=True)
class ListOf(Node):
    """A list of ``item``s, ``min_items`` to ``max_items`` long."""

    item: Node = None
    min_items: int = 0
    max_items: int = 10_000
    what: str = "a list"

    def check(self, value, key, ctx):
        if not isinstance(value, list | tuple):
            self.refuse(value, key, ctx, self.what)
        if not self.min_items <= len(value) <= self.max_items:
            size = (f"at least {self.min_items}" if len(value) < self.min_items
                    else f"at most {self.max_items}")
            ctx.refuse(key, f"{self.what} of {size} item(s)", value, self.fix,
                       shown=f"{len(value)}")
        return [self.item.check(v, (*key, i), ctx) for i, v in enumerate(value)]


@dataclass(frozen=True)
class Table(Node):
    """A table (dict) of known keys. ``fields``: key -> node; ``required``: keys that must be
    there; ``defaults``: key -> value used when the key is absent (checked by its node
    too). Unknown keys are refused with the closest known one."""

    fields: dict = field(default_factory=dict)
    required: tuple[str, ...] = ()
    defaults: dict = field(default_factory=dict)
    what: str = "a table of keys"

    def check(self, value, key, ctx):
        if not isinstance(value, dict):
            self.refuse(value, key, ctx, self.what)
        for name in self.required:
            if name not in value:
                ctx.fail(key, f"missing key '{name}' (expected {', '.join(self.required)})",
                         self.fix)
        for name in value:
            if name not in self.fields:
                close = difflib.get_close_matches(str(name), list(self.fields), n=1)
                hint = (f"; did you mean '{close[0]}'?" if close
                        else f"; allowed: {', '.join(self.fields)}")
                ctx.fail(key, f"unknown key '{name}'{hint}")
        out = {}
        for name, node in self.fields.items():
            if name in value:
                out[name] = node.check(value[name], (*key, name), ctx)
            elif name in self.defaults:
                out[name] = node.check(self.defaults[name], (*key, name), ctx)
        return out


@dataclass(frozen=True)
class MapOf(Node):
    """A table whose keys are names (checked by ``keys``) and whose values are ``values``."""

    keys: Node = Name()
    values: Node = None
    max_items: int = 1_000
    what: str = "a table"

    def check(self, value, key, ctx):
        if not isinstance(value, dict):
            self.refuse(value, key, ctx, self.what)
        if len(value) > self.max_items:
            ctx.refuse(key, f"{self.what} of at most {self.max_items} entries", value,
                       self.fix, shown=f"{len(value)}")
        out = {}
        for name, item in value.items():
            name = self.keys.check(name, (*key, str(name)), ctx)
            out[name] = self.values.check(item, (*key, name), ctx)
        return out


@dataclass(frozen=True)
class Document(Node):
    """Free-form JSON-like data (tables, lists, text, finite numbers, booleans, null),
    nested at most ``max_depth`` deep with at most ``max_items`` values in all: kept as
    read (for example a fit's verdict stored in a material file)."""

    max_depth: int = 8
    max_items: int = 10_000
    top: type | None = dict

    def check(self, value, key, ctx):
        if self.top is not None and not isinstance(value, self.top):
            self.refuse(value, key, ctx, "a table" if self.top is dict else "a list")
        count = 0
        stack = [(value, 1)]
        while stack:
            item, depth = stack.pop()
            count += 1
            if count > self.max_items:
                ctx.fail(key, f"holds more than {self.max_items} values", self.fix)
            if isinstance(item, dict | list):
                if depth > self.max_depth:
                    ctx.fail(key, f"nests more than {self.max_depth} deep", self.fix)
                children = item.values() if isinstance(item, dict) else item
                if isinstance(item, dict) and not all(isinstance(k, str) for k in item):
                    ctx.fail(key, "has a key that is not text", self.fix)
                stack.extend((c, depth + 1) for c in children)
            elif isinstance(item, float) and not math.isfinite(item):
                ctx.fail(key, f"holds {item!r}; expected finite numbers", self.fix)
            elif not (item is None or isinstance(item, str | bool | int | float)):
                ctx.fail(key, f"holds {found(item)}; expected text, numbers, booleans, "
                              "lists and tables", self.fix)
        return value


def validate(node: Node, value, source: str | None = None, style: str = "json",
             arrays=(), error: type = SchemaError):
    """Check ``value`` against ``node``; returns the converted value. ``source`` (the file)
    starts every message; ``style`` names the keys as in JSON or TOML, ``arrays`` the
    top-level keys that are arrays of tables, ``error`` the kind of error raised
    (:class:`Context`)."""
    return node.check(value, (), Context(source, style, frozenset(arrays), error))


__all__ = ["SchemaError", "Context", "Node", "Number", "Integer", "Text", "Name", "Choice", "Boolean",
           "Nullable", "AnyOf", "Vector", "ListOf", "Table", "MapOf", "Document", "validate",
           "dotted", "found", "as_float", "NAME_PUNCTUATION"]
