"""The layers of docs/architecture.md, read from the source (ast) and enforced.

Each package has a rank; a module may import only from packages of a lower rank (and its own):

====  =========================================================================================
rank  package
====  =========================================================================================
0     ``fdi`` (and ``firmware_host`` itself, the package's ``__init__``: the version, no import)
1     ``drivers`` (of ``fdi`` only the error tree, ``fdi.errors``)
2     ``firmware_host.runtime``
3     ``firmware_host.mavlink`` (the router)
4     the vehicles ``firmware_host.rover``, ``firmware_host.rov``, ``firmware_host.insgnss``
5     ``firmware_host.commands``
6     ``firmware_host.cli``
7     ``firmware_host.devtools``
====  =========================================================================================

Nothing of the product (ranks 0-6) imports ``firmware_host.devtools``: the CLI names the dev
commands by module name and imports one only when the dev extra is installed. An edge counts
wherever it is written: at the top of a module, inside a function or under ``TYPE_CHECKING``,
and as ``importlib.import_module("...")`` on a string literal (or a module-level name bound to
one). The vehicles do not import each other, with one allowed edge (:data:`ALLOWED`).
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TOPS = ("fdi", "drivers", "firmware_host")

RANKS: dict[str, int] = {
    "firmware_host": 0,
    "fdi": 0,
    "drivers": 1,
    "firmware_host.runtime": 2,
    "firmware_host.mavlink": 3,
    "firmware_host.rover": 4,
    "firmware_host.rov": 4,
    "firmware_host.insgnss": 4,
    "firmware_host.commands": 5,
    "firmware_host.cli": 6,
    "firmware_host.devtools": 7,
}
DEVTOOLS = "firmware_host.devtools"

# Package -> package edges allowed against the ranks, each with its reason.
ALLOWED: dict[tuple[str, str], str] = {
    ("firmware_host.insgnss", "firmware_host.rover"):
        "the live INS/GNSS reads the rover's GPS receiver and writes the rover's outputs "
        "(its RoverPipeline front end, NmeaSink, GPS_INPUT records): a vehicle built on the "
        "rover, as the INS/GNSS method is built on a GNSS receiver",
}
# What drivers may import of fdi: the one error tree.
DRIVERS_FROM_FDI = frozenset({"fdi.errors"})


def _modules() -> dict[str, Path]:
    out = {}
    for top in TOPS:
        for path in sorted((ROOT / top).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            out[name] = path
    return out


MODULES = _modules()


def package(module: str) -> str:
    """The layer a module belongs to (a key of :data:`RANKS`)."""
    parts = module.split(".")
    if parts[0] != "firmware_host" or len(parts) == 1:
        return parts[0]
    return "firmware_host." + parts[1]


def imports(source: str, module: str, is_package: bool = False) -> Iterator[tuple[int, str]]:
    """``(line, module name)`` for every import in ``source``, wherever it is written:
    ``import a.b``, ``from a import b`` (``a`` and ``a.b``), relative imports resolved against
    ``module``, and ``importlib.import_module`` / ``import_module`` on a string literal or on a
    module-level name bound to one."""
    tree = ast.parse(source)
    constants = {t.id: n.value.value for n in tree.body if isinstance(n, ast.Assign)
                 and isinstance(n.value, ast.Constant) and isinstance(n.value.value, str)
                 for t in n.targets if isinstance(t, ast.Name)}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield node.lineno, a.name
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                pkg = module.split(".") if is_package else module.split(".")[:-1]
                pkg = pkg[: len(pkg) - (node.level - 1)]
                base = ".".join([*pkg, base] if base else pkg)
            yield node.lineno, base
            for a in node.names:
                yield node.lineno, f"{base}.{a.name}"
        elif isinstance(node, ast.Call) and node.args:
            f = node.func
            name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
            if name != "import_module":
                continue
            arg = node.args[0]
            if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
                yield node.lineno, arg.value
            elif isinstance(arg, ast.Name) and arg.id in constants:
                yield node.lineno, constants[arg.id]


def _project(name: str) -> str | None:
    """The project module ``name`` is or is in (``a.b.C`` -> ``a.b``), None outside it."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def edges() -> list[tuple[str, str, str]]:
    """``(importing module, imported module, "path:line")`` over the project."""
    out = set()
    for module, path in MODULES.items():
        src = path.read_text(encoding="utf-8")
        for line, name in imports(src, module, path.name == "__init__.py"):
            target = _project(name)
            if target is not None and target != module:
                out.add((module, target, f"{path.relative_to(ROOT)}:{line}"))
    return sorted(out)


def violations(graph: list[tuple[str, str, str]]) -> list[str]:
    """Every edge against the ranks, the allowed ones excepted; drivers' fdi imports."""
    bad = []
    for a, b, where in graph:
        pa, pb = package(a), package(b)
        if pa == pb or (pa, pb) in ALLOWED:
            continue
        if pb == DEVTOOLS:
            bad.append(f"{where}: {a} imports {b} (the product never imports devtools)")
        elif pa not in RANKS or pb not in RANKS:
            bad.append(f"{where}: {a} imports {b} (a package without a rank: add it to RANKS)")
        elif RANKS[pb] >= RANKS[pa]:
            bad.append(f"{where}: {a} (rank {RANKS[pa]}) imports {b} (rank {RANKS[pb]})")
        elif pa == "drivers" and pb == "fdi" and b not in DRIVERS_FROM_FDI:
            bad.append(f"{where}: {a} imports {b} (drivers take only fdi.errors from fdi)")
    return bad


def mutual_pairs(graph: list[tuple[str, str, str]]) -> list[tuple[str, str]]:
    """Package pairs that import each other."""
    pkg_edges = {(package(a), package(b)) for a, b, _ in graph if package(a) != package(b)}
    return sorted((a, b) for a, b in pkg_edges if a < b and (b, a) in pkg_edges)


GRAPH = edges()


def test_every_package_has_a_rank() -> None:
    assert {package(m) for m in MODULES} == set(RANKS)
    assert len(GRAPH) > 200  # the whole project was read


def test_imports_follow_the_layers() -> None:
    bad = violations(GRAPH)
    assert bad == [], "imports against the layers (docs/architecture.md):\n" + "\n".join(bad)


def test_no_two_packages_import_each_other() -> None:
    pairs = mutual_pairs(GRAPH)
    assert len(pairs) == 0, f"{len(pairs)} package pairs import each other: {pairs}"


def test_the_product_does_not_import_devtools() -> None:
    bad = [f"{where}: {a} imports {b}" for a, b, where in GRAPH
           if package(a) != DEVTOOLS and package(b) == DEVTOOLS]
    assert bad == []


@pytest.mark.parametrize(("module", "source", "expected"), [
    # an upward import inside a function
    ("firmware_host.runtime.x", "def f():\n    from firmware_host.rover import pipeline\n",
     "rank 2) imports firmware_host.rover"),
    # a dynamic import of devtools by a string literal
    ("firmware_host.commands.x",
     "import importlib\nM = importlib.import_module('firmware_host.devtools.eval')\n",
     "never imports devtools"),
    # by a module-level constant
    ("firmware_host.rov.x", "import importlib\nNAME = 'firmware_host.commands.tables'\n"
     "def f():\n    return importlib.import_module(NAME)\n", "imports firmware_host.commands"),
    # drivers taking more of fdi than its error tree
    ("drivers.x", "from fdi.kalman import KalmanFilter\n", "take only fdi.errors"),
    # a vehicle importing another
    ("firmware_host.rov.x", "from ..rover import outputs\n", "rank 4) imports firmware_host"),
    # the package's own __init__ (the version) importing anything of the project
    ("firmware_host", "from firmware_host.runtime import config\n", "rank 0) imports"),
])
def test_the_checks_would_catch(module: str, source: str, expected: str) -> None:
    """Each rule fails on a source that breaks it (so the tests above can fail)."""
    graph = [(module, t, "x.py") for _, n in imports(source, module)
             if (t := _project(n)) is not None]
    assert graph, source
    assert any(expected in v for v in violations(graph)), violations(graph)


def test_a_mutual_pair_would_be_counted() -> None:
    graph = [("firmware_host.runtime.a", "firmware_host.rover.b", "a.py:1"),
             ("firmware_host.rover.b", "firmware_host.runtime.c", "b.py:1")]
    assert mutual_pairs(graph) == [("firmware_host.rover", "firmware_host.runtime")]


def test_the_allowed_edges_are_used() -> None:
    """An exception that nothing needs any more is removed from :data:`ALLOWED`."""
    used = {(package(a), package(b)) for a, b, _ in GRAPH}
    assert set(ALLOWED) <= used, set(ALLOWED) - used
