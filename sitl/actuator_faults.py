"""Actuator failures injected into the plant's commands ([[actuator_fault]] of a scenario).

A failure replaces what the failed actuator is told, never the physics: the plant's rotor
lag and servo rate limit (docs/model.md#plant) carry on as they are, so a rotor switched off spins
down with its time constant tau_down, and a stuck servo simply stops where it was. The
FCU is not told (it sees the consequences only through the state), as on a real vehicle
whose ESC or servo fails silently.

Pure: the flight's clock comes in with the state (time since the flight's start, as the
scenario's disturbances count it).
"""

from __future__ import annotations

from common.config.scenario import ActuatorFault
from sitl.plant import ActuatorCommand, PlantState


class ActuatorFaults:
    """The scenario's actuator faults over one flight; `apply` before every plant step.

    At a fault's onset (the first step at or after start_s) the held values are taken from
    the plant's state: the rotor's speed (rotor_stuck) or the servo's tilt (tilt_stuck,
    tilt_off); a fault with an end releases the actuator to its commands again.
    """

    def __init__(self, faults: tuple[ActuatorFault, ...], flight_start_us: int = 0) -> None:
        self.faults = faults
        self.start_us = flight_start_us
        self._held: dict[int, float] = {}  # fault number -> the value it holds

    @property
    def active(self) -> bool:
        return bool(self.faults)

    def start_flight(self, flight_start_us: int) -> None:
        """The flight starts now: fault times count from here."""
        self.start_us = flight_start_us
        self._held.clear()

    def apply(self, cmd: ActuatorCommand, state: PlantState) -> ActuatorCommand:
        """The command the actuators receive at `state` (the step's start)."""
        if not self.faults:
            return cmd
        t_s = (state.time_us - self.start_us) * 1e-6
        speeds: list[float] | None = None
        tilts: list[float] | None = None
        for n, f in enumerate(self.faults):
            if not f.active(t_s):
                self._held.pop(n, None)
                continue
            i = f.index
            if f.kind == "rotor_off":
                speeds = speeds or list(cmd.rotor_speed_rad_s)
                speeds[i] = 0.0
            elif f.kind == "rotor_stuck":
                held = self._held.setdefault(n, state.rotor_speed_rad_s[i])
                speeds = speeds or list(cmd.rotor_speed_rad_s)
                speeds[i] = held
            else:  # tilt_stuck, tilt_off: the servo stays where it was
                held = self._held.setdefault(n, state.tilt_rad[i])
                tilts = tilts or list(cmd.tilt_rad)
                tilts[i] = held
        if speeds is None and tilts is None:
            return cmd
        return ActuatorCommand(tuple(speeds) if speeds is not None else cmd.rotor_speed_rad_s,
                               tuple(tilts) if tilts is not None else cmd.tilt_rad)
