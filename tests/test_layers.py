"""The package is a stack of layers (docs/architecture.md), checked on the source of every module.

(a) A module imports only its own layer and the layers below it (function-level imports too).
(b) A module imports another subpackage only through its public names: never ``femrom.x._y``
    (nor ``from femrom.x import _y``) from outside ``femrom.x``.
(c) The modules of one subpackage import each other without cycles.

The package helpers (``femrom._errors``, ``_progress``, ``_json``, ``_registry``, ``_timing`` and the
package root) sit below every layer; the command line is the top one (the case scripts,
outside the package, sit on it).
"""

from __future__ import annotations

import ast
import collections
from pathlib import Path

import femrom

PACKAGE = Path(femrom.__file__).resolve().parent

#: The layers, lowest first (the cases on top: the command line finds them by name, at run time).
LAYERS = ("solvers", "mesh", "fem", "scene", "integrators", "snapshots", "linalg", "basis", "inference",
          "rom", "control", "post", "study", "cli", "cases")

#: Top-level modules usable from every layer.
HELPERS = {"_errors", "_progress", "_json", "_registry", "_timing"}

#: Import cycles between modules of one subpackage that are known and not yet broken, each
#: as a set of module names with the owner of its files. None now; the last two
#: (scene._config <-> scene._sweep, snapshots._store <-> snapshots._writer) were broken
#: by moving the helpers they shared to a module both import.
KNOWN_CYCLES: list[frozenset[str]] = []


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


MODULES = {_module_name(path): path for path in sorted(PACKAGE.rglob("*.py"))}


def _layer(module: str) -> int:
    """0 for the package root and its helpers, then 1, 2, ... in the order of :data:`LAYERS`."""
    parts = module.split(".")
    if len(parts) == 1 or parts[1] in HELPERS:
        return 0
    name = "cli" if parts[1] == "__main__" else parts[1]
    return LAYERS.index(name) + 1


def _imports(path: Path):
    """``(line, module)`` of every femrom module the file imports, anywhere in it.

    ``from femrom.x import y`` is an import of the module ``femrom.x.y`` when that is a
    module, else of ``femrom.x`` (a name it exports).
    """
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "femrom":
                    yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module \
                and node.module.split(".")[0] == "femrom":
            for alias in node.names:
                name = f"{node.module}.{alias.name}"
                yield node.lineno, name if name in MODULES else node.module


def _where(module: str, line: int) -> str:
    return f"{MODULES[module].relative_to(PACKAGE.parent).as_posix()}:{line}"


def test_every_subpackage_has_a_layer():
    for module in MODULES:
        _layer(module)      # a subpackage or top-level module missing from LAYERS raises here


def test_no_module_imports_a_higher_layer():
    offenders = [f"{_where(module, line)} imports {target} (layer {LAYERS[_layer(target) - 1]})"
                 for module, path in MODULES.items() for line, target in _imports(path)
                 if _layer(target) > _layer(module)]
    assert not offenders, "imports of a higher layer:\n" + "\n".join(offenders)


def test_no_module_imports_a_private_module_of_another_subpackage():
    offenders = []
    for module, path in MODULES.items():
        own = module.split(".")[1] if "." in module else None
        for line, target in _imports(path):
            parts = target.split(".")
            private = any(part.startswith("_") for part in parts[2:])
            if len(parts) > 2 and parts[1] not in HELPERS and parts[1] != own and private:
                offenders.append(f"{_where(module, line)} imports {target}")
    assert not offenders, "use the subpackage's public names instead:\n" + "\n".join(offenders)


def _cycles(edges: dict[str, set[str]]) -> list[frozenset[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.add(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(frozenset(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return found


def test_no_import_cycle_within_a_subpackage():
    edges = collections.defaultdict(set)
    for module, path in MODULES.items():
        parts = module.split(".")
        for _, target in _imports(path):
            if len(parts) > 1 and target.split(".")[1:2] == parts[1:2] and target != module:
                edges[module].add(target)
    cycles = [c for c in _cycles(edges) if c not in KNOWN_CYCLES]
    assert not cycles, "import cycles:\n" + "\n".join(" <-> ".join(sorted(c)) for c in cycles)


def test_the_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [frozenset("abc")]


def test_the_package_never_imports_the_case_scripts_or_benchmarks():
    for module, path in MODULES.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) else []
            assert not any(n.split(".")[0] in ("cases", "benchmarks") for n in names), _where(module, node.lineno)
