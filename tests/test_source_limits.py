"""Size limits over the source tree (issue 26): every module and function small enough to
read, every compiled kernel's signature short enough to read without counting positions.

* no module over :data:`MAX_MODULE_LINES` lines;
* no function over :data:`MAX_FUNCTION_LINES` lines of code (its docstring not counted),
  except the compiled kernels' inner loops (functions compiled by numba), which may take
  up to :data:`MAX_KERNEL_LINES`;
* no compiled kernel function with more than :data:`MAX_KERNEL_ARGS` arguments or
  returning a tuple of more than :data:`MAX_KERNEL_RETURNS` values (its state travels in
  a few named structures instead);
* no module imports a private name (``_name``) of another package of irreflect.

:data:`KNOWN` lists the functions over a limit that belong to work in progress elsewhere
(each with the issue that shrinks it; empty since issue 26's last ones were split). The list
may only shrink: an entry that no longer exceeds its limit fails the test until it is
removed.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import irreflect

PACKAGE = Path(irreflect.__file__).parent
MAX_MODULE_LINES = 1200
MAX_FUNCTION_LINES = 80
MAX_KERNEL_LINES = 160
MAX_KERNEL_ARGS = 10
MAX_KERNEL_RETURNS = 4

#: "module:function" -> why it is over a limit today (the list only shrinks)
KNOWN: dict[str, str] = {}

MODULES = sorted(PACKAGE.rglob("*.py"))


def _rel(path: Path) -> str:
    return path.relative_to(PACKAGE).as_posix()


def _compiled(node) -> bool:
    """Whether a function is compiled by numba (an ``njit``/``jit`` decorator)."""
    for dec in node.decorator_list:
        target = dec.func if isinstance(dec, ast.Call) else dec
        name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
        if name in ("njit", "jit"):
            return True
    return False


def _code_lines(node) -> int:
    """Lines of a function from ``def`` to its end, its docstring not counted."""
    lines = node.end_lineno - node.lineno + 1
    body = node.body
    if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
            and isinstance(body[0].value.value, str):
        lines -= body[0].end_lineno - body[0].lineno + 1
    return lines


def _functions(path: Path):
    tree = ast.parse(path.read_text(), str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            yield node


def _returns(node) -> int:
    """The most values a function returns as one tuple literal (nested functions aside)."""
    most = 0
    stack = list(node.body)
    while stack:
        n = stack.pop()
        if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda):
            continue
        if isinstance(n, ast.Return) and isinstance(n.value, ast.Tuple):
            most = max(most, len(n.value.elts))
        stack.extend(ast.iter_child_nodes(n))
    return most


def _offences(path: Path) -> dict[str, str]:
    """``module:function`` -> what limit it exceeds."""
    out = {}
    for node in _functions(path):
        key = f"{_rel(path)}:{node.name}"
        compiled = _compiled(node)
        lines = _code_lines(node)
        limit = MAX_KERNEL_LINES if compiled else MAX_FUNCTION_LINES
        why = []
        if lines > limit:
            why.append(f"{lines} lines > {limit}")
        if compiled:
            args = node.args
            n_args = len(args.posonlyargs) + len(args.args) + len(args.kwonlyargs)
            if n_args > MAX_KERNEL_ARGS:
                why.append(f"{n_args} arguments > {MAX_KERNEL_ARGS}")
            n_ret = _returns(node)
            if n_ret > MAX_KERNEL_RETURNS:
                why.append(f"returns {n_ret} values > {MAX_KERNEL_RETURNS}")
        if why:
            out[key] = ", ".join(why)
    return out


@pytest.mark.parametrize("path", MODULES, ids=_rel)
def test_module_size(path):
    n = len(path.read_text().splitlines())
    assert n <= MAX_MODULE_LINES, (f"{_rel(path)} has {n} lines (at most {MAX_MODULE_LINES}): "
                                   "split it by role")


@pytest.mark.parametrize("path", MODULES, ids=_rel)
def test_function_limits(path):
    found = _offences(path)
    new = {k: v for k, v in found.items() if k not in KNOWN}
    assert not new, f"over the limits (split them, or pack a kernel's state): {new}"


def test_known_exceptions_still_apply():
    """An entry of KNOWN that no longer exceeds a limit must be removed (the list shrinks)."""
    found = {}
    for path in MODULES:
        found.update(_offences(path))
    stale = sorted(k for k in KNOWN if k not in found)
    assert not stale, f"remove from KNOWN in {__file__}: {stale} (now within the limits)"


def test_the_checks_can_fail(tmp_path):
    """The measures themselves, on a made-up module: a long function, a long kernel, a
    kernel of many arguments and one returning a long tuple are all caught."""
    body = "\n".join(f"    x{i} = {i}" for i in range(90))
    src = (f"def long():\n    '''doc\n    more'''\n{body}\n    return x0\n\n"
           "@njit(cache=True)\ndef wide(a, b, c, d, e, f, g, h, i, j, k):\n    return a\n\n"
           "@njit\ndef many(a):\n    return a, a, a, a, a\n\n"
           "def short():\n    '''a docstring\n" + "\n" * 100 + "'''\n    return 1\n")
    path = tmp_path / "_limits_probe.py"
    path.write_text(src)
    nodes = {n.name: n for n in _functions(path)}
    assert _code_lines(nodes["long"]) == 92
    assert _code_lines(nodes["short"]) == 2
    assert _compiled(nodes["wide"]) and _compiled(nodes["many"])
    assert not _compiled(nodes["long"])
    assert _returns(nodes["many"]) == 5
    assert len(nodes["wide"].args.args) == 11


def _is_module(parts: list[str]) -> bool:
    where = PACKAGE.joinpath(*parts)
    return where.with_suffix(".py").is_file() or (where / "__init__.py").is_file()


def _private_imports(path: Path) -> list[str]:
    """``from irreflect.X import _name`` (or relative) where X is another top-level package
    or module of irreflect than the importer's own."""
    rel = path.relative_to(PACKAGE)
    own = rel.parts[0].removesuffix(".py")
    package = ["irreflect", *rel.parts[:-1]]
    tree = ast.parse(path.read_text(), str(path))
    wrong = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.ImportFrom):
            continue
        if node.level:
            base = package[: len(package) - node.level + 1]
            target = base + (node.module.split(".") if node.module else [])
        else:
            target = (node.module or "").split(".")
        if target[0] != "irreflect":
            continue
        top = target[1] if len(target) > 1 else None
        if top is None or top == own:
            continue
        for alias in node.names:
            if _is_module(target[1:] + [alias.name]):
                continue  # a module (irreflect._atomic), not a private name in one
            if alias.name.startswith("_") and not alias.name.startswith("__"):
                wrong.append(f"line {node.lineno}: {'.'.join(target)}.{alias.name}")
    return wrong


@pytest.mark.parametrize("path", MODULES, ids=_rel)
def test_no_private_imports_across_packages(path):
    wrong = _private_imports(path)
    assert not wrong, f"{_rel(path)} imports private names of another package: {wrong}"
