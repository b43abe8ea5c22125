"""The plant and the controller stay independent (DESIGN.md section 1)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _imports(package: str) -> set[str]:
    found = set()
    for path in (ROOT / package).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                found |= {alias.name.split(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                found.add(node.module.split(".")[0])
    return found


@pytest.mark.parametrize(("package", "forbidden"), [
    ("sitl", {"fcu", "gcs"}),  # an independent plant makes closed-loop tests mean something
    ("fcu", {"sitl", "gcs"}),
    ("common", {"fcu", "sitl", "gcs"}),
])
def test_package_does_not_import(package, forbidden):
    """Given a package, then it imports none of the packages it must stay apart from."""
    imported = _imports(package)
    assert imported, f"no imports found in {package}: the scan is broken"
    assert not imported & forbidden


@pytest.mark.parametrize("package", ["common", "fcu", "sitl"])
def test_math_imports_no_io(package):
    """The algebra, tracker, allocation and plant import neither pymavlink, zenoh nor clocks."""
    assert not _imports(package) & {"pymavlink", "zenoh", "time", "socket", "threading"}
