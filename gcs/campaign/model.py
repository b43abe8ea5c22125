"""A campaign as read from its file: its axes (a grid), its Monte-Carlo draws, what it keeps."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from common.config.keys import Key, KeyTable

TRANSPORTS = ("in-process", "udp", "tcp", "zenoh")
KEEP = ("none", "failed", "all")
DISTRIBUTIONS = {"uniform": ("low", "high"), "normal": ("mean", "sigma"),
                 "loguniform": ("low", "high"), "integers": ("low", "high"),
                 "choice": ("values",)}


# The keys of a campaign file, one declaration each: the loader (gcs.campaign.load) refuses
# every other key and takes its defaults and choices from here; docs/configuration.md lists
# them (`python -m tools.config_doc`).
CAMPAIGN_KEYS = KeyTable("", (
    Key("name", "string", "the campaign's name (not empty)"),
    Key("base", "string", "the base scenario file, relative to the campaign file; every run "
        "is it with the keys below set"),
    Key("description", "string", "free text for people", default_doc="none"),
    Key("transport", "string", "how each run flies: in one process, or through processes "
        "over that transport", default="in-process", choices=TRANSPORTS),
    Key("set", "table", "scenario keys set on every run (nested tables are key paths)",
        default_doc="none"),
    Key("axis", "tables", "the grid's axes (`[[axis]]`): every combination of their values",
        default_doc="none"),
    Key("monte_carlo", "table", "draws per grid point (`[monte_carlo]`)",
        default_doc="none: one run per grid point"),
    Key("keep", "table", "what run folders are kept (`[keep]`)", default_doc="none kept"),
))

AXIS_KEYS = KeyTable("axis[]", (
    Key("key", "string", "the scenario key the axis moves (`disturbance.force[0].magnitude`)",
        default_doc="`key` or `keys`"),
    Key("keys", "raw", "several keys moving together (each value a list, one per key)",
        type_doc="list of strings", default_doc="`key` or `keys`"),
    Key("values", "raw", "the axis's values", type_doc="list",
        default_doc="`values` or `start`, `stop`, `num`"),
    Key("start", "number", "the first of `num` evenly spaced values (integers when start, "
        "stop and every step are)", default_doc="with `stop`, `num`"),
    Key("stop", "number", "the last of them", default_doc="with `start`, `num`"),
    Key("num", "integer", "how many", lo=1, default_doc="with `start`, `stop`"),
))

MONTE_CARLO_KEYS = KeyTable("monte_carlo", (
    Key("draws", "integer", "the number of draws per grid point", lo=1),
    Key("seed", "integer", "the draws' seed", default=0, lo=0),
    Key("draw", "tables", "what is drawn (`[[monte_carlo.draw]]`), at least one"),
))

DRAW_KEYS = KeyTable("monte_carlo.draw[]", (
    Key("key", "string", "the scenario key drawn (on no axis)"),
    Key("distribution", "string", "the distribution it is drawn from",
        choices=tuple(DISTRIBUTIONS)),
    Key("low", "number", "`uniform`, `loguniform` (> 0), `integers` (whole): the lower bound",
        range_doc="<= high"),
    Key("high", "number", "the same distributions' upper bound"),
    Key("mean", "number", "`normal`: the mean"),
    Key("sigma", "number", "`normal`: the standard deviation", lo=0.0),
    Key("values", "raw", "`choice`: the values drawn from (not empty)", type_doc="list"),
), "A draw takes `key`, `distribution` and that distribution's own keys, no other.")

KEEP_KEYS = KeyTable("keep", (
    Key("run_folders", "string", "which runs keep their run folder (logs, plots)",
        default="none", choices=KEEP),
))


class CampaignError(ValueError):
    """A campaign file or a run it describes is invalid (exit status 2)."""


@dataclass(frozen=True)
class Axis:
    """One [[axis]]: its keys moving together and their values, one tuple per grid value."""

    keys: tuple[str, ...]
    values: tuple[tuple[Any, ...], ...]  # one tuple per grid value, one entry per key


@dataclass(frozen=True)
class Draw:
    """One [[monte_carlo.draw]]: a key and the distribution (with its arguments) it is drawn
    from."""

    key: str
    distribution: str
    args: dict[str, Any]


@dataclass(frozen=True)
class Campaign:
    """A checked campaign file: the base scenario (inlined), [set], the axes, the draws."""

    name: str
    source: str
    base: Path
    base_data: dict[str, Any]
    fixed: dict[str, Any]
    axes: tuple[Axis, ...]
    draws: tuple[Draw, ...] = ()
    n_draws: int = 1
    mc_seed: int = 0
    transport: str = "in-process"
    keep: str = "none"

    @property
    def columns(self) -> tuple[str, ...]:
        """The parameter columns of results.csv: each axis key, then each drawn key."""
        keys = [k for a in self.axes for k in a.keys]
        if self.draws:
            keys.append("draw")
            keys += [d.key for d in self.draws if d.key not in keys]
        return tuple(keys)

