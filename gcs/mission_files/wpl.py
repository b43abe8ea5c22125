"""QGC WPL 110: the plain-text mission of MAVProxy's `wp load` / `wp save` (QGC reads it),
one tab-separated line per item."""

from __future__ import annotations

from collections.abc import Sequence

from common.wire.mission_items import MissionItem
from gcs.mission_files.items import MissionFileError, checked, float_text, xy_int, xy_unit

WPL_HEADER = "QGC WPL 110"


def format_wpl(items: Sequence[MissionItem]) -> str:
    lines = [WPL_HEADER]
    for it in items:
        lines.append("\t".join([str(it.seq), str(it.current), str(it.frame), str(it.command),
                                *(float_text(v) for v in (it.param1, it.param2, it.param3,
                                                          it.param4)),
                                float_text(xy_unit(it.frame, it.x)),
                                float_text(xy_unit(it.frame, it.y)),
                                float_text(it.z), str(it.autocontinue)]))
    return "\n".join(lines) + "\n"


def parse_wpl(text: str, source: str = "<mission>") -> list[MissionItem]:
    lines = text.splitlines()
    if not lines or not lines[0].strip().startswith("QGC WPL"):
        raise MissionFileError(f"{source}: line 1: expected the header '{WPL_HEADER}'")
    if lines[0].split()[-1] != "110":
        raise MissionFileError(f"{source}: line 1: only version 110 is supported")
    items = []
    for n, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        fields = line.split("\t") if "\t" in line else line.split()
        if len(fields) != 12:
            raise MissionFileError(f"{source}: line {n}: expected 12 fields, got {len(fields)}")
        try:
            seq, current, frame, command = (int(f) for f in fields[:4])
            p = [float(f) for f in fields[4:11]]
            autocontinue = int(fields[11])
        except ValueError as exc:
            raise MissionFileError(f"{source}: line {n}: {exc}") from None
        try:
            x, y = xy_int(frame, p[4]), xy_int(frame, p[5])
        except (OverflowError, ValueError):
            raise MissionFileError(f"{source}: line {n}: x/y not finite") from None
        items.append(checked(MissionItem(seq, frame, command, current, autocontinue, p[0],
                                          p[1], p[2], p[3], x, y, p[6]),
                              f"{source}: line {n}"))
    return items
