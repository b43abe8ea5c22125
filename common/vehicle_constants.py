"""Figures of the vehicle that the code's array layouts are built on.

The truth and onboard logs, the actuator packing of the simulator link (six speeds, six
tilts), the telemetry and the compiled kernels' flat arrays assume a hexarotor; the geometry
code itself is general, and `common.config.scenario` refuses a vehicle with another rotor count.
"""

from __future__ import annotations

N_ROTORS = 6  # the hexarotor
