"""The import graph of the package follows aquarom_fenics.layers: no import runs upward, no cycle.

Every module is parsed (not imported), so an import inside a function or under TYPE_CHECKING counts
as much as one at the top of the file.
"""
from __future__ import annotations

import ast
import tomllib
from pathlib import Path

import pytest

from aquarom_fenics.layers import LAYERS, PACKAGE, layer_name, layer_of

REPOSITORY = Path(__file__).resolve().parents[1]

def package_folders() -> dict[str, Path]:
    """Package name → folder: aquarom_fenics and the folders pyproject.toml maps into it (forms/, ...)."""
    settings = tomllib.loads((REPOSITORY / "pyproject.toml").read_text())["tool"]["setuptools"]
    mapped = {name: REPOSITORY / folder for name, folder in settings.get("package-dir", {}).items()}
    return {PACKAGE: REPOSITORY / PACKAGE} | mapped


def module_files() -> dict[str, Path]:
    """Dotted module name → file, packages by their __init__.py."""
    modules = {}
    folders = package_folders()
    for package, folder in folders.items():
        for path in folder.rglob("*.py"):
            parts = list(path.relative_to(folder).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            modules[".".join([package, *parts])] = path
    return modules


def imported_modules(module: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The package's modules that ``module`` imports anywhere in its file (``from X import name``
    counts as X.name when that is a module, else as X)."""
    is_package = path.name == "__init__.py"
    found = set()

    def known(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".")[: len(module.split(".")) - node.level + is_package]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            names = [f"{source}.{alias.name}" if f"{source}.{alias.name}" in modules else source
                     for alias in node.names]
        else:
            continue
        found.update(known(name) for name in names if name == PACKAGE or name.startswith(PACKAGE + "."))
    found.discard(None)
    found.discard(module)
    return found


def import_graph() -> dict[str, set[str]]:
    modules = module_files()
    return {module: imported_modules(module, path, modules) for module, path in modules.items()}


def upward_imports(graph: dict[str, set[str]]) -> list[str]:
    """Every import of a module from a higher layer, as one line each."""
    return sorted(f"{module} ({layer_name(module)}) imports {target} ({layer_name(target)})"
                  for module, targets in graph.items() for target in targets if layer_of(target) > layer_of(module))


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index, low, stack, on_stack, components = {}, {}, [], set(), []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for target in sorted(graph.get(node, ())):
            if target not in index:
                visit(target)
                low[node] = min(low[node], low[target])
            elif target in on_stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                components.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return sorted(components)


def test_every_module_is_in_a_layer():
    unplaced = []
    for module in module_files():
        try:
            layer_of(module)
        except ValueError as error:
            unplaced.append(str(error))
    assert not unplaced, "\n".join(unplaced)


def test_no_import_runs_upward():
    upward = upward_imports(import_graph())
    assert not upward, "imports that run upward (aquarom_fenics/layers.py gives the order):\n" + "\n".join(upward)


def test_no_import_cycle_between_modules():
    cycles = import_cycles(import_graph())
    assert not cycles, "import cycles:\n" + "\n".join(" ↔ ".join(cycle) for cycle in cycles)


def test_the_graph_sees_imports_inside_functions_and_relative_ones(tmp_path):
    """The parser resolves what the layering depends on: a function's import, ``from . import x``."""
    modules = {f"{PACKAGE}.a": tmp_path / "a.py", f"{PACKAGE}.b": tmp_path / "b.py", f"{PACKAGE}.c": tmp_path / "c.py",
               PACKAGE: tmp_path / "__init__.py"}
    source = "def f():\n    from aquarom_fenics.b import thing\n    from . import c\n    import numpy\n"
    (tmp_path / "a.py").write_text(source)
    assert imported_modules(f"{PACKAGE}.a", tmp_path / "a.py", modules) == {f"{PACKAGE}.b", f"{PACKAGE}.c"}
    assert import_cycles({"x": {"y"}, "y": {"z"}, "z": {"x"}, "w": {"x"}}) == [["x", "y", "z"]]
    assert [name for name, _ in LAYERS][0] == "base"


def test_the_pools_import_nothing_of_the_application_but_the_base_layer():
    """aquarom_fenics.parallel knows futures, processes and Dask; the caller hands it a WorkerSetup. Below
    it lies only the base layer (the errors, the check of files read back)."""
    graph = import_graph()
    outside = {f"{module} imports {target}" for module, targets in graph.items() if module.startswith(f"{PACKAGE}.parallel")
               for target in targets if not target.startswith(f"{PACKAGE}.parallel") and layer_of(target) != 0}
    assert not outside, sorted(outside)
