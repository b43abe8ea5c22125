"""A MAVProxy module that makes MAVProxy's `mode NAME` work with PX4 (this FCU, and PX4
itself):

    mavproxy.py --master=udpin:127.0.0.1:14550 --load-module gcs.mavproxy_px4modes
    MAV> module load gcs.mavproxy_px4modes          (or, once running)

MAVProxy names a PX4 vehicle's modes with pymavlink's PX4 table (`mavutil.px4_map`: LOITER,
MISSION, RTL, LAND, TAKEOFF, POSCTL, OFFBOARD, ...), whose entries are (base_mode, main_mode,
sub_mode) tuples. Its `mode NAME` command hands that tuple to `mavfile.set_mode`, which puts
it whole into MAV_CMD_DO_SET_MODE's param1 and fails ("ERROR in command ['LOITER']: required
argument is not a float", MAVProxy 1.8.75 with pymavlink 2.4.50). This module unpacks the
tuple, so that `mode LOITER` sends DO_SET_MODE (base_mode, main_mode, sub_mode) as PX4 reads
it; everything else is left as it was. `module unload px4modes` restores pymavlink.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from pymavlink import mavutil

if TYPE_CHECKING:
    class _MPModule:
        """What this module takes from MAVProxy's MPModule (MAVProxy has no type hints)."""

        def __init__(self, mpstate: Any, name: str, description: str | None = None,
                     public: bool = False, multi_instance: bool = False,
                     multi_vehicle: bool = False) -> None: ...
else:
    from MAVProxy.modules.lib.mp_module import MPModule as _MPModule

_ORIGINAL = "_set_mode_before_px4modes"


def _set_mode(self: Any, mode: Any, custom_mode: int = 0, custom_sub_mode: int = 0) -> Any:
    if isinstance(mode, tuple) and len(mode) == 3:  # a px4_map entry
        base, main, sub = mode
        return self.set_mode_px4(base, main, sub)
    return getattr(mavutil.mavfile, _ORIGINAL)(self, mode, custom_mode, custom_sub_mode)


def install() -> None:
    """Patch pymavlink's `mavfile.set_mode` (idempotent)."""
    if not hasattr(mavutil.mavfile, _ORIGINAL):
        setattr(mavutil.mavfile, _ORIGINAL, mavutil.mavfile.set_mode)
    mavutil.mavfile.set_mode = _set_mode


def uninstall() -> None:
    original = getattr(mavutil.mavfile, _ORIGINAL, None)
    if original is not None:
        mavutil.mavfile.set_mode = original
        delattr(mavutil.mavfile, _ORIGINAL)


class PX4ModesModule(_MPModule):
    def __init__(self, mpstate: Any) -> None:
        super().__init__(mpstate, "px4modes", "set PX4 modes by name")
        install()

    def unload(self) -> None:
        uninstall()


def init(mpstate: Any) -> PX4ModesModule:
    """MAVProxy's entry point."""
    return PX4ModesModule(mpstate)
