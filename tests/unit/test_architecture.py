"""The plant and the controller stay independent (docs/architecture.md)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


# The purity rule, by package: every module of common/, fcu/ and sitl/ is pure (no MAVLink,
# no links, no clocks, no threads) except its I/O edge, named here. A new module is pure
# unless it joins an edge, so a split keeps every part under the rule. gcs/ is all edge.
EDGE = {
    "common": ("common/links", "common/zenoh_link.py", "common/mavlink.py", "common/simlink.py",
               "common/mission_items.py", "common/jit.py", "common/ulog.py",
               "common/entry.py", "common/startup.py", "common/program.py", "common/parent.py",
               "common/cliargs.py"),
    "fcu": ("fcu/node.py", "fcu/sim_bridge.py", "fcu/gcs_server.py", "fcu/gcs_commands.py",
            "fcu/gcs_params.py", "fcu/mission_protocol.py", "fcu/telemetry.py",
            "fcu/onboard_log.py", "fcu/params_doc.py", "fcu/work_process.py",
            "fcu/node_args.py"),
    "sitl": ("sitl/node.py", "sitl/server.py", "sitl/ardupilot_json.py", "sitl/px4_hil.py",
             "sitl/sensor_feed.py", "sitl/truth_log.py"),
}
IO = {"pymavlink", "zenoh", "time", "socket", "threading", "select", "subprocess", "signal",
      "common.mavlink", "common.links", "common.simlink", "common.zenoh_link"}


def _pure_modules() -> list[str]:
    found = []
    for package, edge in EDGE.items():
        for path in sorted((ROOT / package).rglob("*.py")):
            name = str(path.relative_to(ROOT))
            if not any(name == e or name.startswith(e + "/") for e in edge):
                found.append(name)
    return found


PURE_MODULES = _pure_modules()


def _imports(package: str) -> set[str]:
    found = set()
    paths = (ROOT / package).rglob("*.py") if (ROOT / package).is_dir() else [ROOT / package]
    for path in paths:
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                found |= {alias.name for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                found.add(node.module)
    return found


@pytest.mark.parametrize(("package", "forbidden"), [
    ("sitl", {"fcu", "gcs"}),  # an independent plant makes closed-loop tests mean something
    ("fcu", {"sitl", "gcs"}),
    ("common", {"fcu", "sitl", "gcs"}),
])
def test_package_does_not_import(package, forbidden):
    """Given a package, then it imports none of the packages it must stay apart from."""
    imported = {m.split(".")[0] for m in _imports(package)}
    assert imported, f"no imports found in {package}: the scan is broken"
    assert not imported & forbidden


def test_the_edges_exist_and_the_rule_covers_the_core():
    """Given the edge lists, then each names a module that exists (a renamed edge would
    silently become pure-checked or unchecked), and the core modules are under the rule."""
    for edge in EDGE.values():
        for name in edge:
            assert (ROOT / name).exists(), f"{name} in EDGE does not exist"
    for core in ("fcu/tracker.py", "fcu/allocation.py", "fcu/pipeline.py", "sitl/plant.py",
                 "common/frames.py", "fcu/commander.py"):
        assert core in PURE_MODULES


@pytest.mark.parametrize("module", PURE_MODULES)
def test_pure_modules_import_no_io(module):
    """Given a module outside its package's edge, then it imports neither pymavlink, zenoh,
    the links nor clocks, threads or processes."""
    imported = _imports(module)
    assert not {m for m in imported if m in IO or m.split(".")[0] in IO
                or any(m.startswith(i + ".") for i in IO)}


PACKAGES = ("common", "fcu", "sitl", "gcs")


def _module_paths(root: Path = ROOT, packages: tuple[str, ...] = PACKAGES) -> dict[str, Path]:
    """Every module of the packages by dotted name (a package by its __init__)."""
    found = {}
    for package in packages:
        for path in (root / package).rglob("*.py"):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            found[".".join(parts)] = path
    return found


def _import_graph(modules: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the project's modules it imports, counting every import statement: at the
    top, inside functions and under `if TYPE_CHECKING:` alike (a circle hidden in a function
    is still a circle), relative imports resolved, `from a import b` naming module a.b when
    b is one."""
    graph: dict[str, set[str]] = {name: set() for name in modules}
    for name, path in modules.items():
        package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package[:len(package) - (node.level - 1)]
                    module = ".".join(base + ([node.module] if node.module else []))
                else:
                    module = node.module or ""
                targets = [module] + [f"{module}.{alias.name}" for alias in node.names]
            else:
                continue
            for target in targets:
                while target and target not in modules:  # the deepest module named
                    target = target.rpartition(".")[0]
                if target and target != name:
                    graph[name].add(target)
    return graph


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


def test_circle_finder_finds_hidden_circles(tmp_path):
    """Given modules that import each other only inside a function, under TYPE_CHECKING or
    relatively, then the finder reports each circle (so the next test's silence means
    something), and not a one-way import."""
    assert _circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("from .x import f\n")
    (pkg / "a.py").write_text("def g():\n    from pkg import b\n")
    (pkg / "b.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                              "    from pkg.a import g\n")
    (pkg / "sub" / "x.py").write_text("def f():\n    from .. import sub\n")
    (pkg / "c.py").write_text("import pkg.a\n")
    graph = _import_graph(_module_paths(tmp_path, ("pkg",)))
    assert graph["pkg.c"] == {"pkg.a"}
    assert _circles(graph) == [["pkg.a", "pkg.b"], ["pkg.sub", "pkg.sub.x"]]


def test_no_import_circle():
    """Given every import in common, fcu, sitl and gcs, wherever it is written, then no
    module reaches itself through its imports."""
    assert _circles(_import_graph(_module_paths())) == []


MAX_LINES = 500  # one job per file: past this a module has several (split it by job)


def test_no_module_over_the_line_limit():
    """Given every module of the four packages, generated ones included, then none is longer
    than MAX_LINES."""
    lengths = {str(path.relative_to(ROOT)): len(path.read_text().splitlines())
               for path in _module_paths().values()}
    assert len(lengths) > 50, "the scan found too few modules: it is broken"
    assert {path: n for path, n in lengths.items() if n > MAX_LINES} == {}
