"""The package's rooms and what each may import (docs/architecture.md, "The Python package"):
every module imports, and no module imports one of a room above its own or forms an import cycle.
Lazy imports inside functions count too: they are imports all the same."""

from __future__ import annotations

import ast
import importlib
import pkgutil
from pathlib import Path

import pytest

import so101

# Bottom up; each room may import its own modules and those of the rooms it lists.
SHARED = (
    "so101.contract",
    "so101.units",
    "so101.ee",
    "so101.paths",
    "so101.messages",
    "so101.sim_options",
    "so101.subcommands",
    "so101.arguments",
)
MAY_IMPORT = {
    "shared": set(),
    "dataset": {"shared"},
    "policies": {"shared"},
    "stack": {"shared", "dataset"},
    "envs": {"shared", "stack"},
    "evaluate": {"shared", "dataset", "stack", "envs", "policies"},
    "lerobot": {"shared", "dataset", "stack", "envs", "evaluate", "policies"},
    "learn": {"shared", "dataset", "stack", "envs", "evaluate", "lerobot", "policies"},
    "sysid": {"shared", "dataset", "stack", "envs", "evaluate"},
    "bench": {"shared", "dataset", "stack", "envs", "evaluate", "lerobot", "learn", "sysid", "cameras", "policies"},
    "tools": {"shared", "stack", "envs"},
    "cameras": {"shared"},
}


def modules() -> list[str]:
    names = [info.name for info in pkgutil.walk_packages(so101.__path__, "so101.")]
    return sorted(name for name in names if not name.endswith("__main__")) + ["so101.bench.__main__"]


def room_of(module: str) -> str:
    if module in SHARED:
        return "shared"
    parts = module.split(".")
    if len(parts) >= 2 and parts[1] in MAY_IMPORT:
        return parts[1]
    raise AssertionError(f"{module} is in no room: add it to one (and to docs/architecture.md)")


def source_of(module: str) -> Path:
    return Path(importlib.util.find_spec(module).origin)


def imports_of(module: str) -> set[str]:
    """The so101 modules `module` imports anywhere in its code (packages resolved to modules where
    a name is one)."""
    path = source_of(module)
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names if alias.name.split(".")[0] == "so101")
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "so101":
                continue
            for alias in node.names:
                candidate = f"{target}.{alias.name}"
                found.add(candidate if importlib.util.find_spec(target) and _is_module(candidate) else target)
    return found - {module}


def _is_module(name: str) -> bool:
    try:
        return importlib.util.find_spec(name) is not None
    except ModuleNotFoundError:
        return False


ALL = modules()


@pytest.mark.parametrize("module", ALL)
def test_every_module_imports(module):
    importlib.import_module(module)


@pytest.mark.parametrize("module", [m for m in ALL if m != "so101"])
def test_no_module_imports_a_room_above_its_own(module):
    room = room_of(module)
    allowed = MAY_IMPORT[room] | {room}
    for target in sorted(imports_of(module)):
        if target == "so101":
            continue  # the package itself: importing it registers the environments
        assert room_of(target) in allowed, f"{module} ({room}) imports {target} ({room_of(target)})"


def test_no_import_cycle():
    graph = {module: imports_of(module) & set(ALL) for module in ALL if module != "so101"}
    state: dict[str, str] = {}

    def visit(module: str, path: list[str]) -> None:
        state[module] = "open"
        for target in sorted(graph.get(module, ())):
            assert state.get(target) != "open", "import cycle: " + " -> ".join([*path, module, target])
            if target not in state:
                visit(target, [*path, module])
        state[module] = "done"

    for module in graph:
        if module not in state:
            visit(module, [])
