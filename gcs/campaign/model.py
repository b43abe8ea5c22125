"""A campaign as read from its file: its axes (a grid), its Monte-Carlo draws, what it keeps."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

TRANSPORTS = ("in-process", "udp", "tcp", "zenoh")
KEEP = ("none", "failed", "all")
DISTRIBUTIONS = {"uniform": ("low", "high"), "normal": ("mean", "sigma"),
                 "loguniform": ("low", "high"), "integers": ("low", "high"),
                 "choice": ("values",)}


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

