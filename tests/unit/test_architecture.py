"""The plant and the controller stay independent (DESIGN.md section 1)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


PURE_MODULES = ("common/config.py", "common/geometry.py", "common/frames.py",
                "fcu/dualquat.py", "fcu/trajectory.py", "fcu/tracker.py", "fcu/allocation.py",
                "fcu/core.py", "fcu/mission.py", "fcu/supervisor.py", "common/modes.py",
                "fcu/commander.py", "fcu/failsafe.py", "fcu/pipeline.py", "common/outcome.py",
                "fcu/feasibility.py", "common/quaternion.py", "fcu/actuator_monitor.py",
                "sitl/plant.py", "sitl/disturbance.py", "fcu/estimator.py", "fcu/rate_filter.py",
                "sitl/sensors.py", "common/sensors_config.py", "sitl/px4_wire.py",
                "sitl/rotor_layout.py", "fcu/approach.py", "fcu/offboard.py")


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


@pytest.mark.parametrize("module", PURE_MODULES)
def test_math_imports_no_io(module):
    """The algebra, tracker, allocation and plant import neither pymavlink, zenoh nor clocks."""
    imported = _imports(module)
    assert imported, f"no imports found in {module}: the scan is broken"
    io = {"pymavlink", "zenoh", "time", "socket", "threading", "select", "common.mavlink",
          "common.links", "common.simlink"}
    assert not {m for m in imported if m in io or m.split(".")[0] in io}
