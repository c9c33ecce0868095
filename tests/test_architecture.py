"""The layering of src/sweep, read from the source with `ast` (nothing is imported or run):

* no import cycle among the modules;
* the layers (TIERS): the shared definitions at the bottom, then the numerical core, the scene and
  output definitions, the runners, the drivers and the front door on top; a module imports only
  from its own tier or below (the kernel knows no file, config or command line; nothing but the
  front door imports the front door);
* no function of the core takes more than MAX_PARAMS parameters, beyond the listed exceptions
  (WIDE_ALLOWED, each with its reason; the list is exact: a listed function that fits is removed);
* no module of the package (the core or not) is longer than MAX_MODULE_LINES lines;
* the stepper (dop853.py) and the step-size controller (controller.py) know no state layout;
* a shared name of the core (EPS, the contact modes, the hand-over states) has one home, and no
  module imports a core module's name through another core module that only imports it (no
  re-exports).

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
MAX_PARAMS = 6
# The core functions over MAX_PARAMS, by reason: Python's entry points. Every kernel takes its groups
# as records (layout.py: System, Work, Record, RunConsts, Run, Eval, Point, Span, Segment, Bracket,
# Hermite, Peak; model.Contact) or small tuples ((sin, cos) of alpha, a 2x2 system (m, b)). A new
# wide function must be added here with its reason (or take a group instead).
WIDE_ALLOWED = {
    "fits.summary_fits": "the fits' inputs as plain arrays and counts: called from Python (sweep.simulate) as from numba (core.ensemble)",
    "integrate.integrate": "the Python entry point's public signature (state, parameters, settings, levels, samples, capacities)",
    "model.make_params": "the physical inputs of a disk (Python, once per scene)",
}
# a module of src/sweep that outgrows this is split along its seams (the core's contact_rhs / slip /
# moments / event_rules and integrate / scan / accept; the pipeline's chunkfiles / verify / gather / cf)
MAX_MODULE_LINES = 700


def modules() -> dict[str, ast.Module]:
    """Every module of the package, by dotted name (sweep.core.contact_rhs, ...)."""
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


# The package's layers, bottom first. Every module of src/sweep has a tier (sweep.core.* all the
# core's); an import may go down or stay in its tier, never up.
TIERS = (
    ("definitions", {"sweep.errors", "sweep.outcomes", "sweep.reasons", "sweep.fields", "sweep.yamlio",
                     "sweep.plate", "sweep.axes", "sweep.atomic"}),
    ("core", {"sweep.core"}),
    ("scene and outputs", {"sweep.scene", "sweep.outputs", "sweep.diagnostics", "sweep.numerical_error",
                           "sweep.lattice", "sweep.surplus", "sweep.errorbars", "sweep.interpolation", "sweep.refine",
                           "sweep.reconstruct"}),
    ("runners", {"sweep.simulate", "sweep.validation", "sweep.configfiles", "sweep.grid", "sweep.chunking",
                 "sweep.cf", "sweep.chunkfiles", "sweep.verify", "sweep.gather", "sweep.figures", "sweep.notebooks"}),
    ("drivers", {"sweep", "sweep.batch", "sweep.ensemble", "sweep.animate", "sweep.audio", "sweep.plots",
                 "sweep.adaptive"}),
    ("front door", {"sweep.snakemake_args", "sweep.progress", "sweep.warmup", "sweep.runlock", "sweep.frontdoor",
                    "sweep.cli", "sweep.__main__"}),
)


def tier(module: str) -> int:
    """The index in TIERS of `module` (a core module: the core's); KeyError for a module in none."""
    name = "sweep.core" if module.startswith("sweep.core.") else module
    for i, (_, members) in enumerate(TIERS):
        if name in members:
            return i
    raise KeyError(f"{module} is in no tier of tests/test_architecture.py's TIERS: give it one")


def upward_imports(graph: dict[str, set[str]]) -> list[tuple[str, str]]:
    """(importer, imported) for every import of a module on a higher tier (a package's __init__
    imported by its own modules on the way in aside)."""
    return sorted((m, t) for m, targets in graph.items() for t in targets
                  if not _is_parent(t, m) and tier(t) > tier(m))


def test_the_package_has_no_import_cycle():
    floors(import_graph(modules()))


def test_the_import_graph_finds_what_a_module_imports():
    graph = import_graph(modules())
    assert "sweep.core.model" in graph["sweep.core.contact_rhs"]          # `from .model import ...`
    assert "sweep.core.integrate" in graph["sweep.simulate"]          # `from .core.integrate import ...`
    assert "sweep.errors" in graph["sweep.scene"]


def test_every_module_has_a_tier_and_imports_none_above_it():
    graph = import_graph(modules())
    for m in graph:
        tier(m)
    assert upward_imports(graph) == []


def test_an_upward_import_is_caught():
    """The check can fail: the kernel reading a scene, or a runner calling the command line."""
    graph = import_graph(modules())
    graph["sweep.core.model"] = graph["sweep.core.model"] | {"sweep.scene"}
    graph["sweep.gather"] = graph["sweep.gather"] | {"sweep.cli"}
    assert upward_imports(graph) == [("sweep.core.model", "sweep.scene"), ("sweep.gather", "sweep.cli")]
    with pytest.raises(KeyError, match="sweep.newthing is in no tier"):
        tier("sweep.newthing")
    with pytest.raises(ValueError, match="import cycle"):
        floors({"a": {"b"}, "b": {"a"}})


def module_lengths() -> dict[str, int]:
    """Lines of every module of the package, by its path under src/ (sweep/core/model.py, ...)."""
    return {p.relative_to(SRC.parent).as_posix(): len(p.read_text().splitlines()) for p in sorted(SRC.rglob("*.py"))}


def long_modules(limit: int = MAX_MODULE_LINES) -> list[tuple[str, int]]:
    """(module file under src/, lines) of the package's modules, the core's and the others, over
    limit lines."""
    return [(f, n) for f, n in module_lengths().items() if n > limit]


def test_no_module_is_longer_than_the_limit():
    long = long_modules()
    assert long == [], "; ".join(f"src/{f} has {n} lines, over the limit of {MAX_MODULE_LINES}: split it along "
                                 "its seams" for f, n in long)


def test_a_long_module_is_caught():
    """The check can fail: at a limit below the longest module's length it names that module with
    its length, and a module outside the core counts as one inside it does."""
    lengths = module_lengths()
    for pool in (lengths, {f: n for f, n in lengths.items() if not f.startswith("sweep/core/")}):
        longest = max(pool, key=pool.get)
        assert (longest, pool[longest]) in long_modules(pool[longest] - 1)


def wide_functions(mods: dict[str, ast.Module]) -> dict[str, int]:
    """module.function: parameter count of the core functions over MAX_PARAMS."""
    return {f"{m.rpartition('.')[2]}.{f}": len(ps) for m, f, ps in kernel_functions(mods) if len(ps) > MAX_PARAMS}


def test_no_core_function_takes_more_than_six_parameters_beyond_the_listed():
    """Every core function over MAX_PARAMS is listed with its reason, and every listed one is over it
    (the list shrinks as functions take groups)."""
    assert set(wide_functions(modules())) == set(WIDE_ALLOWED)
    assert all(WIDE_ALLOWED.values())


def test_a_wide_function_is_caught():
    mods = modules()
    mods["sweep.core.scan"].body.append(ast.parse("def wide(a, b, c, d, e, f, g):\n    pass\n").body[0])
    assert set(wide_functions(mods)) - set(WIDE_ALLOWED) == {"scan.wide"}


def top_level_names(tree: ast.Module) -> set[str]:
    """The names a module defines at its top level (functions, classes, assignments)."""
    out: set[str] = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            out.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            for target in (node.targets if isinstance(node, ast.Assign) else [node.target]):
                for n in ast.walk(target):
                    if isinstance(n, ast.Name):
                        out.add(n.id)
    return out


def core_imports(mods: dict[str, ast.Module]):
    """(importer, imported module, name) of every `from ... import name` of a core module's names,
    anywhere in the package."""
    for m, tree in mods.items():
        is_pkg = (SRC.parent / Path(*m.split("."))).is_dir()
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                base = _resolve(m, node, is_pkg)
                if base.startswith("sweep.core.") and base in mods:
                    for a in node.names:
                        yield m, base, a.name


def reexports(mods: dict[str, ast.Module]) -> list[tuple[str, str, str]]:
    """(importer, module, name) where a module imports `name` from a core module that does not
    define it (it only imports it in turn)."""
    return sorted((m, base, name) for m, base, name in core_imports(mods)
                  if name not in top_level_names(mods[base]))


def homes(mods: dict[str, ast.Module], name: str) -> list[str]:
    """The modules of the package that define `name` at their top level."""
    return sorted(m for m, tree in mods.items() if name in top_level_names(tree))


SHARED_NAMES = ("EPS", "ROLL", "SLIDE", "SLAVED", "HANDOVER_ARMED", "HANDOVER_OFF", "SLOW_OFF", "BELOW", "AT_FLOOR")


def test_a_shared_core_name_has_one_home():
    mods = modules()
    for name in SHARED_NAMES:
        assert homes(mods, name) == ["sweep.core.constants"], name


def test_machine_epsilon_is_written_out_only_in_its_home():
    eps = 2.220446049250313e-16
    found = sorted({m for m, tree in modules().items() for n in ast.walk(tree)
                    if isinstance(n, ast.Constant) and n.value == eps})
    assert found == ["sweep.core.constants"], found


def test_no_module_imports_a_core_name_through_another():
    assert reexports(modules()) == []


def test_a_reexport_is_caught():
    mods = modules()
    mods["sweep.core.roots"] = ast.parse("from .contact_rhs import ROLL\n")
    assert ("sweep.core.roots", "sweep.core.contact_rhs", "ROLL") in reexports(mods)


STEPPER_MODULES = {"sweep.core.jit", "sweep.core.dop853_sums", "sweep.core.layout", "sweep.core.tableau", "sweep.core"}
STATE_NAMES = ("Y_", "X_", "CS_", "EV_", "P_", "N_CORE", "N_FULL", "N_THETA")


def stepper_layout_leaks(mods: dict[str, ast.Module]) -> list[str]:
    """What dop853.py or controller.py knows of the state's layout: an import of a core module
    beyond the compiler, the tableau, its generated sums and layout.py's work-buffer rows (W_*, its
    scratch), or a name of a state, aux, contact-state, event or parameter slot."""
    graph = import_graph(mods)
    out = [f"dop853 imports {t}" for t in sorted(graph["sweep.core.dop853"] - STEPPER_MODULES)]
    out += [f"controller imports {t}" for t in sorted(graph["sweep.core.controller"] - {"sweep.core.jit", "sweep.core"})]
    out += [f"dop853 imports layout.{name}" for m, base, name in core_imports(mods)
            if m == "sweep.core.dop853" and base == "sweep.core.layout" and not name.startswith("W_")]
    for m in ("sweep.core.dop853", "sweep.core.controller"):
        out += sorted({f"{m.rpartition('.')[2]} names {n.id}" for n in ast.walk(mods[m])
                       if isinstance(n, ast.Name) and n.id.startswith(STATE_NAMES)})
    return out


def test_the_stepper_and_its_controller_know_no_state_layout():
    """dop853.py takes its error scales from its caller (accept.error_scale): it imports nothing
    of the model, the events, the contact state or the integrator; controller.py only the compiler."""
    assert stepper_layout_leaks(modules()) == []


def test_a_stepper_that_knows_the_state_is_caught():
    mods = modules()
    tree = mods["sweep.core.dop853"]
    mods["sweep.core.dop853"] = ast.Module(body=list(tree.body) + ast.parse(
        "from .model import N_CORE, Y_ALPHA\nfrom .layout import CS_MODE\n").body, type_ignores=[])
    leaks = stepper_layout_leaks(mods)
    assert "dop853 imports sweep.core.model" in leaks
    assert "dop853 imports layout.CS_MODE" in leaks


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
