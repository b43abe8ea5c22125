"""What every decoded pymavlink message offers, and the narrowing to a typed view."""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar, Protocol, TypeVar, cast


class Message(Protocol):
    """A decoded MAVLink message (pymavlink's MAVLink_message), as the code uses it."""

    msgname: ClassVar[str]

    def get_type(self) -> str: ...

    def get_srcSystem(self) -> int: ...

    def get_srcComponent(self) -> int: ...

    def get_msgId(self) -> int: ...


M = TypeVar("M", bound=Message)


def as_message(msg: object, view: Callable[..., M]) -> M:
    """`msg` as the typed `view` of its message (common.wire.mavlink_types.state / protocol),
    after checking at run time that it is that message; a ValueError otherwise.

    `view` is a view class; it is typed as a callable because mypy refuses a Protocol class
    where `type[M]` is expected (type-abstract)."""
    get_type = getattr(msg, "get_type", None)
    kind = get_type() if callable(get_type) else type(msg).__name__
    msgname: str = vars(view)["msgname"]  # the view class's own ClassVar
    if kind != msgname:
        raise ValueError(f"a {kind} message is not a {msgname}")
    return cast(M, msg)
