"""The layers, read from the source (ast): who may import whom.

* no import cycle among the project's modules (every ``import``, wherever it is written, counts:
  an import inside a function or under ``TYPE_CHECKING`` is still an edge);
* no import of a project module inside a function (it would hide a cycle or a heavy
  dependency; the CLI's table of commands, loaded by name, is the one dynamic import);
* ``drivers/`` imports nothing from ``firmware_host/``; ``fdi/`` nothing from ``drivers/`` or
  ``firmware_host/``;
* ``fdi/`` is free of I/O. Checked by an allowlist rather than a list of I/O modules, so that a
  new way to reach a file, a port or the clock is caught without anyone thinking of it: the
  estimators may import only pure computation (:data:`FDI_ALLOWED`); the builtins that do I/O
  (``open``, ``print``, ``input``) and numpy's file functions are not called. ``logging`` is
  not allowed either: the estimators return counts and decisions, the runtime logs them. Time
  (``time``, ``datetime``) is I/O here too: an estimator is given its times, it never reads a
  clock, which is what keeps replays deterministic.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("drivers", "fdi", "firmware_host")

FDI_ALLOWED = frozenset({
    "__future__", "abc", "bisect", "cmath", "collections", "collections.abc", "copy",
    "dataclasses", "enum", "fractions", "functools", "heapq", "itertools", "math", "numbers",
    "types",
    "operator", "statistics", "typing", "numpy", "numpy.typing",
    "array",  # typed flat buffers (fdi/drift.py); its tofile/fromfile are refused below
    "importlib",  # fdi/__init__.py's public names, imported on first use: fdi's own modules
})
IO_BUILTINS = frozenset({"open", "print", "input", "breakpoint", "exec", "eval", "__import__"})
NUMPY_IO = frozenset({"load", "save", "savez", "savez_compressed", "loadtxt", "savetxt",
                      "genfromtxt", "fromfile", "tofile", "memmap"})


def _modules() -> dict[str, Path]:
    out = {}
    for top in PACKAGES:
        for path in sorted((ROOT / top).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            out[name] = path
    return out


MODULES = _modules()
TREES = {name: ast.parse(path.read_text(encoding="utf-8"), str(path))
         for name, path in MODULES.items()}


def _imported(node: ast.Import | ast.ImportFrom, module: str) -> list[str]:
    """The modules an import statement names (``from a import b`` names ``a`` and, when it
    is a module, ``a.b``)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    base = node.module or ""
    if node.level:  # relative: resolve against the importing module's package
        pkg = module.split(".")
        if MODULES[module].name != "__init__.py":
            pkg = pkg[:-1]
        pkg = pkg[: len(pkg) - (node.level - 1)]
        base = ".".join([*pkg, base] if base else pkg)
    return [base, *(f"{base}.{a.name}" for a in node.names)]


def _imports(module: str) -> Iterator[tuple[ast.Import | ast.ImportFrom, str]]:
    for node in ast.walk(TREES[module]):
        if isinstance(node, ast.Import | ast.ImportFrom):
            for name in _imported(node, module):
                yield node, name


def _project_edges() -> dict[str, set[str]]:
    return {m: {n for _, n in _imports(m) if n in MODULES and n != m} for m in MODULES}


def test_the_graph_is_the_whole_project() -> None:
    assert len(MODULES) > 60
    assert "firmware_host.cli" in MODULES and "drivers.configload" in MODULES


def test_no_import_cycle() -> None:
    edges = _project_edges()
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(edges[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    assert cycles == [], "import cycles: " + "; ".join(" <-> ".join(c) for c in cycles)


def test_a_cycle_would_be_found() -> None:
    """The check itself: a graph with a cycle is reported (so the test above can fail)."""
    tree = ast.parse("def f():\n    from fdi.rover import X\n")
    names = [n for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
             for n in _imported(node, "fdi.chi2")]
    assert "fdi.rover" in names  # an import inside a function is an edge too


def test_no_function_level_imports_of_project_modules() -> None:
    found = []
    for module, tree in TREES.items():
        for fn in ast.walk(tree):
            if not isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef):
                continue
            for node in ast.walk(fn):
                if isinstance(node, ast.Import | ast.ImportFrom):
                    names = _imported(node, module)
                    if any(n.split(".")[0] in PACKAGES for n in names):
                        found.append(f"{MODULES[module].relative_to(ROOT)}:{node.lineno} "
                                     f"in {fn.name}()")
    assert found == [], "import at the top of the module instead:\n" + "\n".join(found)


@pytest.mark.parametrize(("layer", "forbidden"), [
    ("drivers", ("firmware_host",)),
    ("fdi", ("drivers", "firmware_host")),
])
def test_lower_layers_do_not_import_upward(layer: str, forbidden: tuple[str, ...]) -> None:
    bad = [f"{m} imports {n}" for m in MODULES if m.split(".")[0] == layer
           for _, n in _imports(m) if n.split(".")[0] in forbidden]
    assert bad == []


def test_fdi_is_free_of_io() -> None:
    bad = []
    for module, tree in TREES.items():
        if module.split(".")[0] != "fdi":
            continue
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                names = [_imported(node, module)[0]]  # the module imported from
            else:
                continue
            bad += [f"{module}:{node.lineno} imports {n}" for n in names
                    if n.split(".")[0] != "fdi" and n not in FDI_ALLOWED]
        for call in ast.walk(tree):
            if not isinstance(call, ast.Call):
                continue
            f = call.func
            if isinstance(f, ast.Name) and f.id in IO_BUILTINS:
                bad.append(f"{module}:{call.lineno} calls {f.id}()")
            if (isinstance(f, ast.Attribute) and f.attr in NUMPY_IO
                    and isinstance(f.value, ast.Name) and f.value.id in ("np", "numpy")):
                bad.append(f"{module}:{call.lineno} calls np.{f.attr}()")
            elif isinstance(f, ast.Attribute) and f.attr in ("tofile", "fromfile"):
                bad.append(f"{module}:{call.lineno} calls .{f.attr}()")  # array / ndarray
    assert bad == []


def test_the_io_check_would_catch_io() -> None:
    """The allowlist refuses what it should (so the test above can fail)."""
    for name in ("os", "io", "sys", "socket", "serial", "pathlib", "time", "logging",
                 "threading", "subprocess", "select"):
        assert name not in FDI_ALLOWED
