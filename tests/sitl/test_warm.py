"""`fcu.warm`: after it, a flight's first armed step, HOLD brake from speed, OFFBOARD anchor,
TAKEOFF and POSCTL fit load no numba kernel (a first call compiles or loads one: 2-12 ms
inside a control step in real time). Judged in a fresh process by the kernels' signatures,
not by time."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

SCRIPT = r'''
import gc, json
from pathlib import Path
from numba.core.registry import CPUDispatcher
from common.config.scenario import load_gains, load_vehicle
from common.wire.modes import Mode
from fcu.modes import manual
from fcu.mission.limits import MissionLimits
from fcu.pipeline import Pipeline
from fcu.edge.setpoint_wire import position_target
from fcu.stages import VehicleState
from fcu.warm import warm

def kernels():
    return {f"{d.py_func.__module__}.{d.py_func.__name__}": sorted(map(str, d.signatures))
            for d in gc.get_objects() if isinstance(d, CPUDispatcher)}

vehicle = load_vehicle(Path("config/vehicles/hexa_tilted.toml"))
pipe = Pipeline(vehicle, load_gains(Path("config/gains/pid_eq30.toml")), 500,
                limits=MissionLimits(vehicle=vehicle))
warm(pipe.commander.limits)
t, st = 0, VehicleState((0.0, 0.0, 2.0), (1.0, 0.0, 0.0, 0.0), (0.0,) * 3, (0.0,) * 3)
def fly(n):
    global t
    for _ in range(n):
        t += 2000
        pipe.on_state(t, st, t)
        pipe.step(t, 0.002)
fly(5)
before = kernels()
c = pipe.commander
pipe.arm(); fly(5)
c.offboard_position(0.0, position_target(1, 0b0000_1101_1111_1000, (5.0, 0.0, -2.0),
                                         (0.0,) * 3, (0.0,) * 3, 0.0))
c.set_mode(Mode.OFFBOARD, 0.0); fly(300)
c.set_mode(Mode.HOLD, 0.0); fly(300)
c.manual_input(0.0, manual.CENTRED); c.set_mode(Mode.POSCTL, 0.0); fly(50)
c.set_mode(Mode.HOLD, 0.0); fly(50)
c.set_mode(Mode.LAND, 0.0); fly(50)
after = kernels()
print(json.dumps({k: v for k, v in after.items() if before.get(k) != v}))
'''


def test_a_flight_after_warm_loads_no_kernel():
    out = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, capture_output=True,
                         text=True, timeout=300, check=True).stdout
    assert json.loads(out.strip().splitlines()[-1]) == {}
