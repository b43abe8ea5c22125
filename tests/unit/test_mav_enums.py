"""common/wire/mav_enums.py: every member's name and value as pymavlink's dialects have them
(common and ardupilotmega), so a typed-in number that is wrong fails here."""

from __future__ import annotations

import enum
import inspect
import os

import pytest

os.environ["MAVLINK20"] = "1"

from pymavlink.dialects.v20 import ardupilotmega
from pymavlink.dialects.v20 import common as common_xml

from common.wire import mav_enums

ENUMS = [cls for _, cls in inspect.getmembers(mav_enums, inspect.isclass)
         if issubclass(cls, enum.IntEnum | enum.IntFlag) and cls.__module__ == mav_enums.__name__]


def test_the_module_has_its_enums() -> None:
    names = {cls.__name__ for cls in ENUMS}
    assert {"MAV_CMD", "MAV_RESULT", "MAV_FRAME", "MAV_MODE_FLAG", "MAV_STATE", "MAV_SEVERITY",
            "MAV_MISSION_RESULT", "MAV_MISSION_TYPE", "POSITION_TARGET_TYPEMASK",
            "ATTITUDE_TARGET_TYPEMASK", "MAV_PARAM_TYPE", "MAV_TYPE", "MAV_AUTOPILOT"} <= names


@pytest.mark.parametrize("dialect", [common_xml, ardupilotmega], ids=["common", "ardupilotmega"])
@pytest.mark.parametrize("cls", ENUMS, ids=lambda cls: cls.__name__)
def test_every_member_as_in_the_dialect(cls: type[enum.Enum], dialect: object) -> None:
    entries = dialect.enums[cls.__name__]  # type: ignore[attr-defined]
    members = list(cls.__members__.items())
    assert members
    for name, member in members:
        assert name == member.name, f"{cls.__name__}.{name} is an alias"
        assert getattr(dialect, name) == member.value, f"{cls.__name__}.{name}"
        assert entries[member.value].name == name, f"{cls.__name__}.{name}"


@pytest.mark.parametrize("cls", [c for c in ENUMS if issubclass(c, enum.IntFlag)],
                         ids=lambda cls: cls.__name__)
def test_flags_are_single_bits(cls: type[enum.IntFlag]) -> None:
    for member in cls:
        assert member.value and not member.value & (member.value - 1), member.name
