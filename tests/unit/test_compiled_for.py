"""`common.jit.compiled_for`: a kernel's machine code for fixed argument types, called
without numba's dispatch, computes what the dispatched kernel computes, to the bit, and
refuses the arguments it can tell are wrong."""

from __future__ import annotations

import numpy as np
import pytest

from common.config.vehicle import load_vehicle
from common.jit import ROOT, compiled_for
from fcu.safety.actuator_monitor import ROWS, SETTINGS, monitor_kernel
from sitl.layouts import PC_SIZE
from sitl.plant import STATE_SIZE, Plant, state_row
from sitl.plant_kernels import steps_kernel


def _plant_case() -> tuple[Plant, np.ndarray, np.ndarray]:
    plant = Plant(load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml"), dt_us=1000)
    row = state_row(plant.initial_state((0.5, -0.2, 2.0), on_ground=False,
                                        rotor_speed_rad_s=(600.0,) * 6,
                                        tilt_rad=(0.1, -0.2, 0.3, -0.1, 0.2, 0.0)))
    cmd = np.array([650.0, 640.0, 700.0, 610.0, 660.0, 630.0,
                    0.3, -0.25, 0.2, 0.05, -0.3, 0.12])
    assert cmd.shape == (PC_SIZE,)
    return plant, row, cmd


def test_the_machine_code_steps_the_plant_as_the_dispatched_kernel_does() -> None:
    plant, row, cmd = _plant_case()
    by_entry, by_dispatch = np.empty((2, STATE_SIZE)), np.empty((2, STATE_SIZE))
    plant.step_rows(row, cmd, by_entry)  # the plant's own call goes through compiled_for
    steps_kernel(plant.params, plant.disturbance.table, row, cmd, by_dispatch)
    assert by_entry.tobytes() == by_dispatch.tobytes()
    assert by_entry[1, 0] == row[0] + 2000.0  # it did step: two physics steps of 1 ms


def test_it_is_the_kernels_machine_code_for_exactly_these_types() -> None:
    plant, row, cmd = _plant_case()
    out = np.empty((2, STATE_SIZE))
    entry = compiled_for(steps_kernel, plant.params, plant.disturbance.table, row, cmd, out)
    signature = next(s for s, c in steps_kernel.overloads.items() if c.entry_point is entry)
    assert len(signature) == 5 and signature[4].ndim == 2
    assert entry is not steps_kernel  # no dispatcher in between


def test_a_tuple_of_another_length_or_a_non_number_is_refused() -> None:
    st = np.zeros((ROWS, 12))
    st[SETTINGS, :3] = (3.0, 1800.0, 600.0)  # tilt rate limit, w_max, hold speed
    entry = compiled_for(monitor_kernel, st, 0.0, 0.0, (0.0,) * 6, (0.0,) * 6, False)
    assert entry(st.copy(), 2e-3, 0.1, (0.0,) * 6, (1.0,) * 6, False) == \
        monitor_kernel(st.copy(), 2e-3, 0.1, (0.0,) * 6, (1.0,) * 6, False)
    with pytest.raises(ValueError, match="size mismatch"):
        entry(st, 2e-3, 0.1, (0.0,) * 6, (1.0,) * 12, False)
    for not_a_number in (None, [2e-3], object()):
        with pytest.raises(TypeError):
            entry(st, not_a_number, 0.1, (0.0,) * 6, (1.0,) * 6, False)
    with pytest.raises(TypeError):  # a list where a tuple goes
        entry(st, 2e-3, 0.1, [0.0] * 6, (1.0,) * 6, False)
