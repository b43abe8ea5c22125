"""The wire's rounding without the wire: what a MAVLink float field makes of a value.

Every float of the simulator link's messages is a float32 (IEEE 754, round to nearest even);
a run in one process rounds the state and the commands as the wire would, so that it flies
what the two processes fly. Rounding each field commutes with the wire's frame changes that
only permute axes and flip signs (ENU <-> NED, FLU <-> FRD), so vectors are rounded in the
code's frames; a quaternion's frame change mixes its components (`common.frames`), so an
attitude is rounded in the wire's frame (`q_enu_flu_as_wire`).

`struct` rounds as the wire's packer does: a value beyond float32's range raises
OverflowError, as packing it into a message would.
"""

from __future__ import annotations

import struct
from typing import TYPE_CHECKING

from common.frames import q_enu_flu_to_ned_frd, q_ned_frd_to_enu_flu

if TYPE_CHECKING:
    from common.quaternion import Quat, Vec3

_F32 = struct.Struct("<f")
_F32x3 = struct.Struct("<3f")
_F32x4 = struct.Struct("<4f")


def f32(x: float) -> float:
    """x rounded to float32, as one float field of a MAVLink message carries it."""
    return float(_F32.unpack(_F32.pack(x))[0])


_F32N: dict[int, struct.Struct] = {}  # "<nf" by n


def f32s(values: tuple[float, ...]) -> tuple[float, ...]:
    """Each value rounded to float32 (a message's float fields)."""
    n = len(values)
    packer = _F32N.get(n)
    if packer is None:
        packer = _F32N[n] = struct.Struct(f"<{n}f")
    return packer.unpack(packer.pack(*values))


def f32_vec3(v: Vec3) -> Vec3:
    """A 3-vector rounded to float32 in whatever frame it is (axes permuted or flipped by a
    frame change round the same)."""
    x, y, z = _F32x3.unpack(_F32x3.pack(*v))
    return (x, y, z)


def f32_quat(q: Quat) -> Quat:
    """A quaternion's components rounded to float32 (as `f32` each)."""
    w, x, y, z = _F32x4.unpack(_F32x4.pack(*q))
    return (w, x, y, z)


def q_enu_flu_as_wire(q_enu_flu: Quat) -> Quat:
    """An ENU/FLU attitude as the wire carries it: NED/FRD (w >= 0), float32 per component,
    back to ENU/FLU (w >= 0), as ODOMETRY's q field sends it and the FCU reads it."""
    w, x, y, z = _F32x4.unpack(_F32x4.pack(*q_enu_flu_to_ned_frd(q_enu_flu)))
    return q_ned_frd_to_enu_flu((w, x, y, z))


def controls_as_wire(speeds_rad_s: tuple[float, ...], tilts_rad: tuple[float, ...],
                     w_max_rad_s: float) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Rotor speeds and tilts as HIL_ACTUATOR_CONTROLS carries them and the plant reads
    them back (docs/simulator-link.md): controls[0..n) float32(speed / w_max), read back
    x w_max; controls[n..2n) float32(tilt). One rounding of the message's 2n fields."""
    n = len(speeds_rad_s)
    c = f32s((*[w / w_max_rad_s for w in speeds_rad_s], *tilts_rad))
    return tuple([x * w_max_rad_s for x in c[:n]]), c[n:]
