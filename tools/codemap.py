"""The code's map in figures: modules per folder, the longest import chain and the citations
of notes that are not in the repository. `tests/unit/test_architecture.py` checks its rules
on the same import graph.

    .venv/bin/python tools/codemap.py

The graph counts every import statement of the four packages (at the top, inside functions,
under `if TYPE_CHECKING:`), relative imports resolved, `from a import b` naming module a.b
where b is one; modules outside the packages (numpy, pymavlink, time) are kept by their
top-level name as leaves, so a rule can ask what a module loads through other modules.
"""

from __future__ import annotations

import argparse
import ast
import re
import sys
from collections.abc import Iterable
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("common", "fcu", "sitl", "gcs")
Graph = dict[str, set[str]]


def module_paths(root: Path = ROOT, packages: tuple[str, ...] = PACKAGES) -> dict[str, Path]:
    """Every module of the packages by dotted name (a package by its __init__)."""
    found = {}
    for package in packages:
        for path in (root / package).rglob("*.py"):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            found[".".join(parts)] = path
    return found


def _targets(node: ast.AST, package: list[str]) -> list[str]:
    """The dotted names an import statement names (empty for any other node)."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    if not isinstance(node, ast.ImportFrom):
        return []
    if node.level:
        base = package[:len(package) - (node.level - 1)]
        module = ".".join(base + ([node.module] if node.module else []))
    else:
        module = node.module or ""
    return [module] + [f"{module}.{alias.name}" for alias in node.names]


def import_graph(modules: dict[str, Path]) -> Graph:
    """Module -> what it imports: the project's modules by full name (the deepest module a
    statement names), anything else by its top-level name (`pymavlink`, `time`)."""
    graph: Graph = {name: set() for name in modules}
    for name, path in modules.items():
        package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            for target in _targets(node, package):
                inside = target
                while inside and inside not in modules:
                    inside = inside.rpartition(".")[0]
                if inside and inside != name:
                    graph[name].add(inside)
                elif not inside and target.split(".")[0] not in PACKAGES:
                    graph[name].add(target.split(".")[0])
    return graph


def loading_graph(graph: Graph) -> Graph:
    """`graph` with what Python also runs on an import: importing `a.b.c` runs the packages
    `a` and `a.b` first (their `__init__`), so each module also loads its parent packages."""
    loads = {name: set(targets) for name, targets in graph.items()}
    for name in graph:
        parts = name.split(".")
        loads[name] |= {".".join(parts[:i]) for i in range(1, len(parts))} & graph.keys()
    return loads


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
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


def project_graph(graph: Graph) -> Graph:
    """The graph between the project's modules alone."""
    return {name: {t for t in targets if t in graph} for name, targets in graph.items()}


def closure(graph: Graph, start: str) -> set[str]:
    """Everything `start` loads, directly or through other modules (itself excluded)."""
    seen: set[str] = set()
    todo = list(graph.get(start, ()))
    while todo:
        name = todo.pop()
        if name not in seen:
            seen.add(name)
            todo.extend(graph.get(name, ()))
    return seen


def path_to(graph: Graph, start: str, goal: str) -> list[str]:
    """One import chain from `start` to `goal` (breadth-first: a shortest one), or []."""
    before: dict[str, str] = {}
    frontier = [start]
    while frontier:
        nxt = []
        for name in frontier:
            for target in sorted(graph.get(name, ())):
                if target in before or target == start:
                    continue
                before[target] = name
                if target == goal:
                    chain = [goal]
                    while chain[-1] != start:
                        chain.append(before[chain[-1]])
                    return chain[::-1]
                nxt.append(target)
        frontier = nxt
    return []


def longest_chain(graph: Graph) -> list[str]:
    """The longest import chain between the project's modules (the graph has no circle:
    `test_no_import_circle`)."""
    inner = project_graph(graph)

    @cache
    def longest_from(name: str) -> tuple[str, ...]:
        best: tuple[str, ...] = ()
        for target in inner[name]:
            chain = longest_from(target)
            if len(chain) > len(best):
                best = chain
        return (name, *best)

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10_000))
    chains: list[tuple[str, ...]] = [longest_from(n) for n in sorted(inner)]
    longest = max(chains, key=len)
    return list(longest)


def modules_per_folder(root: Path = ROOT, packages: Iterable[str] = PACKAGES) -> dict[str, int]:
    """Folder -> its modules (`__init__.py` not counted), for every folder of the packages."""
    found: dict[str, int] = {}
    for package in packages:
        for folder in sorted({p.parent for p in (root / package).rglob("*.py")}):
            found[str(folder.relative_to(root))] = sum(
                1 for p in folder.glob("*.py") if p.name != "__init__.py")
    return found


NOTES = re.compile(r"\b(?:MODEL|DESIGN|SENSORS|MAVLINK)\.md\b|\.\./shared\b")
CITED = re.compile(r"docs/([a-z0-9_-]+\.md)")


def outside_citations(root: Path = ROOT) -> list[str]:
    """Citations in code and config of a note that is not in the repository: the background
    notes by name, or a docs page that does not exist."""
    found = []
    for top in (*PACKAGES, "config", "benchmarks", "tests", "tools"):
        for path in sorted((root / top).rglob("*")):
            if path.suffix not in (".py", ".toml") or path.name in ("test_doc_links.py",
                                                                   "codemap.py"):
                continue
            text = path.read_text(errors="replace")
            where = str(path.relative_to(root))
            found += [f"{where}: {m.group(0)}" for m in NOTES.finditer(text)]
            found += [f"{where}: docs/{page}" for page in CITED.findall(text)
                      if not (root / "docs" / page).exists()]
    return found


def main(argv: list[str] | None = None) -> int:
    argparse.ArgumentParser(description=__doc__.split("\n\n")[0]).parse_args(argv)
    graph = import_graph(module_paths())
    chain = longest_chain(graph)
    print(f"modules: {len(graph)}")
    print(f"longest import chain: {len(chain)} modules, {len(chain) - 1} levels")
    print("  " + " -> ".join(chain))
    print("modules per folder (largest first):")
    for folder, n in sorted(modules_per_folder().items(), key=lambda kv: (-kv[1], kv[0])):
        print(f"  {n:3d}  {folder}/")
    outside = outside_citations()
    print(f"citations outside the repository: {len(outside)}")
    for line in outside:
        print(f"  {line}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
