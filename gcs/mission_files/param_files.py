"""Parameter files in QGroundControl's `.params` format (what QGC's parameter editor saves and
loads; Mission Planner reads it too):

    # Onboard parameters for Vehicle 1
    #
    # Stack: MAVLink Generic
    # Vehicle: Multi-Rotor
    # Version: 0.1.0 dev
    # Git Revision: 0000000000000000
    #
    # Vehicle-Id Component-Id Name Value Type
    1  1  DQ_DAMPING  0.000000000000000000  9      (fields separated by tabs)

one tab-separated line per parameter: system id, component id, name, value, MAV_PARAM_TYPE.
Floating values are written as QGC writes them (18 decimals: a float32 reads back exactly),
integer types as integers, each with its real MAV_PARAM_TYPE (`gcs param save` writes the
type the vehicle announced). Lines starting with '#' and blank lines are comments.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from pathlib import Path

from common.process.cliargs import read_text_file
from gcs.vehicle_link.param_wire import FLOAT_TYPES as _FLOAT_TYPES
from gcs.vehicle_link.param_wire import INT_RANGES as _INT_RANGES
from gcs.vehicle_link.param_wire import REAL32

HEADER = "# Vehicle-Id Component-Id Name Value Type"
__all__ = ["HEADER", "REAL32", "ParamEntry", "ParamFileError", "format_params",
           "parse_params", "read_params"]


class ParamFileError(ValueError):
    """A parameter file that cannot be read: names the file, the line and why."""


@dataclass(frozen=True)
class ParamEntry:
    system_id: int
    component_id: int
    name: str
    value: float
    param_type: int = REAL32


def _value_text(value: float, param_type: int) -> str:
    if param_type in _FLOAT_TYPES:
        return f"{value:.18f}"
    return str(int(value))


def format_params(entries: list[ParamEntry], *, system_id: int, stack: str = "",
                  vehicle: str = "", version: str = "", git_revision: str = "") -> str:
    """The `.params` text of `entries` (in their order), with QGC's header."""
    lines = [f"# Onboard parameters for Vehicle {system_id}", "#", f"# Stack: {stack}",
             f"# Vehicle: {vehicle}", f"# Version: {version}", f"# Git Revision: {git_revision}",
             "#", HEADER]
    for e in entries:
        lines.append("\t".join([str(e.system_id), str(e.component_id), e.name,
                                _value_text(e.value, e.param_type), str(e.param_type)]))
    return "\n".join(lines) + "\n"


def parse_params(text: str, source: str = "<params>") -> list[ParamEntry]:
    """The entries of a `.params` text; a malformed line is a ParamFileError naming it."""
    entries: list[ParamEntry] = []
    seen: dict[tuple[int, str], int] = {}
    for n, line in enumerate(text.splitlines(), start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        where = f"{source}: line {n}"
        entry = _parse_line(line, where)
        key = (entry.component_id, entry.name)
        if key in seen:
            raise ParamFileError(f"{where}: {entry.name} again (first on line {seen[key]})")
        seen[key] = n
        entries.append(entry)
    return entries


def _parse_line(line: str, where: str) -> ParamEntry:
    """One parameter line: 5 fields, tab- (or space-) separated, each checked."""
    fields = line.split("\t") if "\t" in line else line.split()
    if len(fields) != 5:
        raise ParamFileError(f"{where}: expected 5 tab-separated fields (Vehicle-Id "
                             f"Component-Id Name Value Type), got {len(fields)}")
    sys_text, comp_text, name, value_text, type_text = (f.strip() for f in fields)
    try:
        system_id, component_id, param_type = int(sys_text), int(comp_text), int(type_text)
    except ValueError:
        raise ParamFileError(f"{where}: Vehicle-Id, Component-Id and Type must be "
                             "integers") from None
    if not (0 <= system_id <= 255 and 0 <= component_id <= 255):
        raise ParamFileError(f"{where}: Vehicle-Id and Component-Id must be 0..255")
    if param_type not in _FLOAT_TYPES and param_type not in _INT_RANGES:
        raise ParamFileError(f"{where}: type {param_type} is not a MAV_PARAM_TYPE")
    if not name or len(name.encode()) > 16 or not name.isascii() or \
            not name.isprintable():
        raise ParamFileError(f"{where}: {name!r} is not a parameter name (1..16 ASCII "
                             "characters)")
    value = _parse_value(value_text, param_type, where)
    return ParamEntry(system_id, component_id, name, value, param_type)


def _parse_value(value_text: str, param_type: int, where: str) -> float:
    """A parameter's value: a finite number that fits its MAV_PARAM_TYPE."""
    try:
        value = float(value_text)
    except ValueError:
        raise ParamFileError(f"{where}: value {value_text!r} is not a number") from None
    if not math.isfinite(value):
        raise ParamFileError(f"{where}: value {value_text} is not finite")
    if param_type in _INT_RANGES:
        lo, hi = _INT_RANGES[param_type]
        if not (value.is_integer() and lo <= value <= hi):
            raise ParamFileError(f"{where}: value {value_text} does not fit type "
                                 f"{param_type}")
    elif param_type == REAL32:
        try:
            struct.pack("<f", value)
        except OverflowError:
            raise ParamFileError(f"{where}: value {value_text} does not fit a "
                                 "float32") from None
    return value


def read_params(path: Path) -> list[ParamEntry]:
    text = read_text_file(path, ParamFileError)
    entries = parse_params(text, str(path))
    if not entries:
        raise ParamFileError(f"{path}: no parameters")
    return entries
