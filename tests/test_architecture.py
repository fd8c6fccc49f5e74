"""The package's shape: stage subpackages in layers, no import circles, no private names across modules.

The layers are those drawn in docs/architecture.md. A module may import from its own subpackage
and from the subpackages of lower layers, never from a higher one; within a subpackage, the
modules' imports form no circle either. Every import counts: at module level, inside functions
(imported on first use), and under ``TYPE_CHECKING``. The graph is read from the sources with
:mod:`ast`, so nothing is imported to check it.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "python" / "gnomon"

#: Lowest first. A module of layer k imports only from layers ≤ k (and from its own unit).
LAYERS: list[set[str]] = [
    {"errors", "_kernel", "_lazy"},
    {"util", "simulate"},
    {"capture"},
    {"camera"},
    {"geometry"},
    {"outputs"},
    {"light"},
    {"config"},
    {"reconstruct"},
    {"recording"},
    {"fuse"},
    {"runs"},
    {"api", "commands", "cli", "__main__", ""},
]
LAYER = {unit: k for k, units in enumerate(LAYERS) for unit in units}

#: What ``from gnomon import NAME`` means for each name the root package gives.
ROOT_NAMES = {"_kernel": "gnomon._kernel", "__version__": "gnomon._kernel", "GnomonError": "gnomon.errors"}


def _modules() -> dict[str, Path]:
    mods = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        mods[name] = path
    return mods


def _unit(module: str) -> str:
    """The subpackage (or top-level module) a module belongs to: ``gnomon.capture.frames`` → ``capture``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def _imports(mods: dict[str, Path]) -> tuple[dict[str, set[str]], list[str]]:
    """Each module's imports of other gnomon modules, and every private name imported across modules."""
    edges: dict[str, set[str]] = defaultdict(set)
    private = []
    for name, path in mods.items():
        package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            targets: list[str] = []
            if isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(up + ([base] if base else []))
                if not base.startswith("gnomon"):
                    continue
                for alias in node.names:
                    full = f"{base}.{alias.name}"
                    if base == "gnomon" and alias.name in ROOT_NAMES:
                        targets.append(ROOT_NAMES[alias.name])
                    elif full in mods:
                        targets.append(full)
                    else:
                        targets.append(base)
                        if alias.name.startswith("_") and not alias.name.startswith("__"):
                            private.append(f"{name} imports {base}.{alias.name}")
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names if a.name.startswith("gnomon")]
            for target in targets:
                if target != name and (target in mods or target == "gnomon._kernel"):
                    edges[name].add(target)
    return edges, private


def _cycles(edges: dict[str, set[str]], nodes: set[str]) -> list[list[str]]:
    """Strongly connected components of more than one node (Tarjan), restricted to ``nodes``."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in edges.get(v, ()):
            if w not in nodes:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(nodes):
        if v not in index:
            visit(v)
    return found


def test_every_module_sits_in_a_declared_layer() -> None:
    units = {_unit(m) for m in _modules()}
    assert units - set(LAYER) == set(), "a new subpackage needs its place in LAYERS and docs/architecture.md"


def test_few_top_level_modules() -> None:
    top = sorted(p.name for p in PACKAGE.glob("*.py"))
    assert len(top) <= 12, top


def test_no_import_reaches_up_a_layer() -> None:
    mods = _modules()
    edges, _ = _imports(mods)
    upward = [
        f"{a} -> {b}"
        for a, targets in sorted(edges.items())
        for b in sorted(targets)
        if LAYER[_unit(b)] > LAYER[_unit(a)]
    ]
    assert upward == []


def test_no_import_circles() -> None:
    mods = _modules()
    edges, _ = _imports(mods)
    # Between modules …
    assert _cycles(edges, set(mods)) == []
    # … and between subpackages (a curated __init__ imports its modules, so a circle of packages is a real one).
    unit_edges: dict[str, set[str]] = defaultdict(set)
    for a, targets in edges.items():
        for b in targets:
            if _unit(a) != _unit(b):
                unit_edges[_unit(a)].add(_unit(b))
    assert _cycles(unit_edges, set(LAYER)) == []


def test_no_private_name_crosses_a_module() -> None:
    _, private = _imports(_modules())
    assert private == []


def test_the_checker_sees_a_circle_and_an_upward_import() -> None:
    """The graph code itself: a circle and a layer violation planted in a tiny graph are found."""
    edges = {"gnomon.capture.a": {"gnomon.capture.b"}, "gnomon.capture.b": {"gnomon.capture.a"}}
    assert _cycles(edges, set(edges)) == [["gnomon.capture.a", "gnomon.capture.b"]]
    assert LAYER[_unit("gnomon.runs.scan")] > LAYER[_unit("gnomon.capture.frames")]


def test_every_subpackage_says_what_it_owns_and_gives_its_names() -> None:
    """Each subpackage has a docstring and an ``__all__`` whose every name resolves (also the ones loaded
    on first use)."""
    import importlib

    for init in sorted(PACKAGE.glob("*/__init__.py")):
        name = f"gnomon.{init.parent.name}"
        package = importlib.import_module(name)
        assert package.__doc__ and len(package.__doc__.split()) >= 20, name
        if name in ("gnomon.commands", "gnomon.simulate"):
            continue
        assert package.__all__, name
        for public in package.__all__:
            assert getattr(package, public) is not None, f"{name}.{public}"
