"""Layers import downward only.

    cli  ->  report  ->  plots  ->  capabilities  ->  fitting  ->  data and models

Every import in the package (at module level and inside functions) is read from the
source; a module may import its own layer's modules or lower layers, never a higher one.
Among the capabilities the order is explicit (the protocol's points are used by the
selection, the noise estimate of the diagnosis by the selection's "enough points").
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import irreflect

PACKAGE = Path(irreflect.__file__).parent

#: layer -> module prefixes, lowest first
LAYERS = [
    ("data and models", ["errors", "validation", "schema", "_atomic", "_inputs", "_progress",
                         "_text", "_jsonio", "paper",
                         "data", "metrics", "models"]),
    ("fitting", ["fitting", "_compiled", "synthetic", "verdict"]),
    ("capabilities", ["diagnose", "protocol", "compare", "selection", "campaign", "room"]),
    ("plots", ["plots"]),
    ("report", ["report"]),
    ("cli", ["cli", "__main__"]),
]
#: the order among the capabilities (a capability imports only those before it)
CAPABILITIES = ["diagnose", "protocol", "compare", "selection", "campaign", "room"]


def _module_name(path: Path) -> str:
    rel = path.relative_to(PACKAGE).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(["irreflect", *parts])


def _top(module: str) -> str | None:
    """The first component below ``irreflect`` (``irreflect.selection.run`` -> selection)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[0] == "irreflect" else None


def _layer(top: str) -> int:
    for i, (_, members) in enumerate(LAYERS):
        if top in members:
            return i
    raise AssertionError(f"irreflect.{top} is in no layer: add it to LAYERS in {__file__}")


def _imports(path: Path):
    module = _module_name(path)
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    tree = ast.parse(path.read_text(), str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if node.module is None:  # from . import x: x may be a module
                for alias in node.names:
                    yield node.lineno, f"{target}.{alias.name}"
            else:
                yield node.lineno, target


MODULES = sorted(p for p in PACKAGE.rglob("*.py"))


def test_every_module_is_in_a_layer():
    tops = {_top(_module_name(p)) for p in MODULES} - {None}
    for top in tops:
        _layer(top)


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_imports_go_downward(path):
    importer = _top(_module_name(path))
    if importer is None:  # irreflect/__init__.py: the public API may gather any layer
        return
    wrong = []
    for line, target in _imports(path):
        top = _top(target)
        if top is None or top == importer or target == "irreflect":
            continue
        if top not in {m for _, ms in LAYERS for m in ms}:
            continue  # an attribute imported from the package (from . import __version__)
        mine, theirs = _layer(importer), _layer(top)
        if theirs > mine or (theirs == mine and mine == 2 and
                             CAPABILITIES.index(top) > CAPABILITIES.index(importer)):
            wrong.append(f"line {line}: {target} ({LAYERS[theirs][0]})")
    assert not wrong, (f"{path.relative_to(PACKAGE)} ({LAYERS[_layer(importer)][0]}) imports "
                       f"upward: {wrong}")


# ----------------------------------------------------------------------------- no circles
def _module_file(name: str) -> str | None:
    """The module (``irreflect.a.b``) an imported name belongs to: the longest prefix
    that is a module or package of irreflect."""
    known = {_module_name(p) for p in MODULES}
    while name and name not in known:
        name = name.rpartition(".")[0]
    return name or None


def _import_graph() -> dict[str, set[str]]:
    """Module -> the irreflect modules it imports (at module level or inside functions)."""
    graph = {}
    for path in MODULES:
        module = _module_name(path)
        targets = {_module_file(t) for _, t in _imports(path)}
        graph[module] = {t for t in targets if t and t != module and t != "irreflect"}
    return graph


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iteratively)."""
    index, low, on_stack, stack, out = {}, {}, set(), [], []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in graph:
                    continue
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[v] = min(low[v], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def test_no_import_circles():
    """No two modules import each other, directly or through others (a function-level
    import counts: it is a circle all the same, only deferred)."""
    circles = _circles(_import_graph())
    assert not circles, f"import circles: {circles}"


def test_circle_finder_finds_circles():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": {"e2"}, "e2": set()}
    assert _circles(graph) == [["a", "b", "c"]]
    assert _circles({"a": {"b"}, "b": set()}) == []


def test_the_campaign_and_the_cli_do_not_import_scipy_stats_on_the_way_in():
    # scipy.stats took 1.7 s to import, paid by every `irreflect next` through
    # protocol.advice's module-level import (next on no readings: 2.4 s -> 1.1 s without it)
    import subprocess
    import sys

    code = "import sys, irreflect.campaign, irreflect.cli; print('scipy.stats' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False", out.stderr
