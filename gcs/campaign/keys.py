"""Keys: paths into a scenario's TOML data (`disturbance.force[0].magnitude`), and setting one."""

from __future__ import annotations

import re
from itertools import pairwise
from typing import Any

from gcs.campaign.model import CampaignError

_SEGMENT = re.compile(r"^([A-Za-z_][A-Za-z0-9_\-]*)((?:\[\d+\])*)$")


def key_path(key: str) -> list[str | int]:
    """'disturbance.force[0].amplitude' -> ['disturbance', 'force', 0, 'amplitude']."""
    if not isinstance(key, str) or not key:
        raise CampaignError(f"a key must be a non-empty string, got {key!r}")
    out: list[str | int] = []
    for seg in key.split("."):
        m = _SEGMENT.match(seg)
        if m is None:
            raise CampaignError(f"key {key!r}: {seg!r} is not a name or name[index]")
        out.append(m.group(1))
        out += [int(i) for i in re.findall(r"\[(\d+)\]", m.group(2))]
    return out


def set_key(data: dict[str, Any], key: str, value: Any) -> None:
    """Set `key` (key_path syntax) in nested TOML data; missing tables are created, and an
    index one past an array's end appends a table."""
    path = key_path(key)
    node: Any = data
    for here, nxt in pairwise(path):
        if isinstance(here, int):
            if not isinstance(node, list) or here > len(node):
                raise CampaignError(f"key {key!r}: no element [{here}] "
                                    f"(the array has {len(node) if isinstance(node, list) else 0})")
            if here == len(node):
                node.append([] if isinstance(nxt, int) else {})
            node = node[here]
            continue
        if not isinstance(node, dict):
            raise CampaignError(f"key {key!r}: {here!r} is not inside a table")
        if here not in node:
            node[here] = [] if isinstance(nxt, int) else {}
        node = node[here]
    last = path[-1]
    if isinstance(last, int):
        if not isinstance(node, list) or last > len(node):
            raise CampaignError(f"key {key!r}: no element [{last}]")
        if last == len(node):
            node.append(value)
        else:
            node[last] = value
    else:
        if not isinstance(node, dict):
            raise CampaignError(f"key {key!r}: {last!r} is not inside a table")
        node[last] = value

