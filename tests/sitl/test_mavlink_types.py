"""The typed views of MAVLink messages (common/wire/mavlink_types) match pymavlink."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from common.wire.mavlink import encoder
from common.wire.mavlink_types import as_message, protocol, state
from common.wire.mavlink_types.protocol import CommandLong
from common.wire.mavlink_types.state import Heartbeat, HilActuatorControls

ROOT = Path(__file__).resolve().parents[2]


def test_generated_views_are_current():
    """Given the generator and pymavlink as installed, then the generated modules are what
    it writes now (a new pymavlink or message list would otherwise go unseen)."""
    result = subprocess.run([sys.executable, str(ROOT / "tools" / "gen_mavlink_types.py"),
                             "--check"], capture_output=True, text=True, cwd=ROOT)
    assert result.returncode == 0, result.stdout + result.stderr


def _round_trip(msg):
    """`msg` packed and decoded, with the ardupilotmega dialect (the views' source; the
    ground station decodes ArduPilot's messages with it)."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    decoded = mavlink.MAVLink(None).parse_buffer(msg.pack(mav))
    assert decoded, "nothing decoded"
    return decoded[0]


def _views():
    return [view for module in (state, protocol) for view in vars(module).values()
            if isinstance(view, type) and view.__module__ == module.__name__]


def _sample(view, mav):
    """A message of `view`'s type with every field set to a distinct non-default value."""
    cls = next(c for c in mavlink.mavlink_map.values() if c.msgname == view.msgname)
    values = []
    for i, (c_type, wire_index) in enumerate(zip(cls.fieldtypes, cls.orders, strict=True)):
        length = cls.array_lengths[wire_index]
        one = b"x" if c_type == "char" else (0.5 + i if c_type in ("float", "double") else i + 1)
        values.append(one * min(length, 5) if c_type == "char" else
                      ([one] * length if length else one))
    return cls(*values)


@pytest.mark.parametrize("view", _views(), ids=lambda v: v.msgname)
def test_every_view_names_the_fields_pymavlink_decodes(view):
    """Given each message with a view, sent through the wire with every field set, then the
    decoded message has every field the view declares, with the declared kind of value, and
    narrows to its view."""
    decoded = _round_trip(_sample(view, mavlink))
    assert as_message(decoded, view) is decoded
    fields = {f: k for f, k in view.__annotations__.items() if f != "msgname"}
    assert list(fields) == decoded.get_fieldnames()
    for field, kind in fields.items():
        value = getattr(decoded, field)
        expected = {"int": int, "float": float, "str": str}.get(kind, (list, tuple))
        assert isinstance(value, expected), (field, kind, value)
        if kind.startswith("Sequence"):
            inner = float if "float" in kind else int
            assert all(isinstance(x, inner) for x in value), (field, kind, value)


def test_two_views_read_their_fields():
    """Given a HEARTBEAT and a HIL_ACTUATOR_CONTROLS, then the views read their values."""
    enc = encoder(1, 1)
    hb = as_message(_round_trip(enc.heartbeat_encode(2, 12, 129, 65536, 4, 3)), Heartbeat)
    assert (hb.type, hb.autopilot, hb.base_mode, hb.custom_mode) == (2, 12, 129, 65536)
    hil = as_message(_round_trip(enc.hil_actuator_controls_encode(
        7, [0.5] * 16, 128, 1)), HilActuatorControls)
    assert hil.time_usec == 7 and list(hil.controls) == [0.5] * 16 and hil.flags == 1


def test_a_message_of_another_type_is_refused():
    """Given a HEARTBEAT, when it is narrowed to COMMAND_LONG, then a ValueError names both."""
    hb = _round_trip(encoder(1, 1).heartbeat_encode(2, 12, 0, 0, 4, 3))
    with pytest.raises(ValueError, match="HEARTBEAT message is not a COMMAND_LONG"):
        as_message(hb, CommandLong)
