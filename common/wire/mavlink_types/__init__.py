"""Typed views of the MAVLink messages the code handles (generated: state.py, protocol.py).

`as_message(msg, Heartbeat)` checks a received message's type and gives it to mypy with its
fields typed; everything else about a message stays pymavlink's."""

from common.wire.mavlink_types.base import Message, as_message

__all__ = ["Message", "as_message"]
