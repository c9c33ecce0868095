"""The layering of src/sweep, read from the source with `ast` (nothing is imported or run):

* no import cycle among the modules, and no module imports one on a higher floor (the floors are
  the longest import chain below each module, so this is the same as: the graph is a DAG);
* no kernel of the core takes more than MAX_PARAMS parameters.

Run as a script it prints the import graph of src/sweep/core, the floors, the functions over the
parameter limit, and the functions that the run's settings vector passes through on its way into
the step loop:

    .venv/bin/python tests/test_architecture.py
"""
from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "sweep"
MAX_PARAMS = 8


def modules() -> dict[str, ast.Module]:
    """Every module of the package, by dotted name (sweep.core.contact, ...)."""
    out = {}
    for path in sorted(SRC.rglob("*.py")):
        rel = path.relative_to(SRC.parent).with_suffix("")
        name = ".".join(rel.parts)
        if name.endswith(".__init__"):
            name = name[: -len(".__init__")]
        out[name] = ast.parse(path.read_text(), str(path))
    return out


def _resolve(module: str, node: ast.ImportFrom, is_pkg: bool) -> str:
    if node.level == 0:
        return node.module or ""
    base = module.split(".")
    base = base if is_pkg else base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def import_graph(mods: dict[str, ast.Module]) -> dict[str, set[str]]:
    """module -> the package's modules it imports (at any depth of its body)."""
    names = set(mods)
    graph: dict[str, set[str]] = {m: set() for m in mods}
    for m, tree in mods.items():
        is_pkg = (SRC.parent / Path(*m.split("."))).is_dir()
        for node in ast.walk(tree):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = _resolve(m, node, is_pkg)
                targets = [base] + [f"{base}.{a.name}" for a in node.names]
            for t in targets:
                while t and t not in names:
                    t = t.rpartition(".")[0]
                if t and t != m and t in names:
                    graph[m].add(t)
    return graph


def floors(graph: dict[str, set[str]]) -> dict[str, int]:
    """The longest import chain below each module (0: imports none of the package); raises on a cycle."""
    memo: dict[str, int] = {}
    active: list[str] = []

    def depth(m: str) -> int:
        if m in memo:
            return memo[m]
        if m in active:
            raise ValueError("import cycle: " + " -> ".join(active[active.index(m):] + [m]))
        active.append(m)
        d = 1 + max((depth(t) for t in graph[m] if not _is_parent(t, m)), default=-1)
        active.pop()
        memo[m] = d
        return d

    for m in graph:
        depth(m)
    return memo


def _is_parent(t: str, m: str) -> bool:
    """A package's __init__ imported by one of its own modules on the way in (sweep.core by
    sweep.core.x) is not an edge of the layering."""
    return m.startswith(t + ".")


def kernel_functions(mods: dict[str, ast.Module]):
    """(module, function name, parameter names) of every top-level function in sweep.core."""
    for m, tree in mods.items():
        if not m.startswith("sweep.core."):
            continue
        for node in tree.body:
            if isinstance(node, ast.FunctionDef):
                args = node.args
                names = [a.arg for a in args.posonlyargs + args.args + args.kwonlyargs]
                yield m, node.name, names


def settings_path(mods: dict[str, ast.Module]) -> list[str]:
    """The core functions that take the settings vector (a parameter named `settings`)."""
    return sorted(f"{m.rpartition('.')[2]}.{f}" for m, f, ps in kernel_functions(mods) if "settings" in ps)


def test_the_package_has_no_import_cycle():
    floors(import_graph(modules()))


def test_no_module_imports_upwards():
    graph = import_graph(modules())
    fl = floors(graph)
    for m, targets in graph.items():
        for t in targets:
            if not _is_parent(t, m):
                assert fl[t] < fl[m], (m, t)


def test_no_core_kernel_takes_more_than_eight_parameters():
    wide = [(m, f, len(ps)) for m, f, ps in kernel_functions(modules()) if len(ps) > MAX_PARAMS]
    assert not wide, wide


def main() -> int:
    mods = modules()
    graph = import_graph(mods)
    fl = floors(graph)
    print("import graph of sweep.core (module: floor <- what it imports):")
    for m in sorted((m for m in graph if m.startswith("sweep.core")), key=lambda m: (fl[m], m)):
        deps = sorted(t.rpartition(".")[2] for t in graph[m] if t.startswith("sweep.core.") or t == "sweep.outcomes")
        print(f"  {m.rpartition('.')[2]:10s} {fl[m]:2d} <- {', '.join(deps)}")
    wide = [(m, f, len(ps)) for m, f, ps in kernel_functions(mods) if len(ps) > MAX_PARAMS]
    print(f"core functions with more than {MAX_PARAMS} parameters: {len(wide)} of "
          f"{sum(1 for _ in kernel_functions(mods))}")
    for m, f, n in sorted(wide, key=lambda w: -w[2]):
        print(f"  {m.rpartition('.')[2]}.{f}: {n}")
    path = settings_path(mods)
    print(f"core functions that take `settings`: {len(path)}: {', '.join(path)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
