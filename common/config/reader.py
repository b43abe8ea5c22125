"""The typed reader of TOML configuration files: `Table` reads a table's keys with their
types and ranges checked and refuses unknown keys; every mistake is a `ConfigError` naming the
file, the key and what was expected. Used by `common.config.scenario` (vehicles, gains, scenarios)
and `common.config.sensors` (sensor profiles).
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Any

Vec3 = tuple[float, float, float]


class ConfigError(ValueError):
    """A configuration file is unreadable, has a wrong type, a missing or unknown key."""


class Table:
    """A TOML table that remembers where it came from, for error messages."""

    def __init__(self, data: dict[str, Any], source: str, prefix: str = "") -> None:
        self.data = data
        self.source = source
        self.prefix = prefix
        self.used: set[str] = set()

    def _name(self, key: str) -> str:
        return f"{self.prefix}{key}"

    def error(self, key: str, expected: str) -> ConfigError:
        got = self.data.get(key, "<missing>")
        return ConfigError(
            f"{self.source}: key '{self._name(key)}': expected {expected}, got {got!r}")

    def has(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str, default: Any = ...) -> Any:
        self.used.add(key)
        if key not in self.data:
            if default is ...:
                raise ConfigError(f"{self.source}: missing key '{self._name(key)}'")
            return default
        return self.data[key]

    def number(self, key: str, default: Any = ..., *, lo: float | None = None,
               hi: float | None = None, lo_open: bool = False) -> float:
        value = self.raw(key, default)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(key, "a number")
        value = float(value)
        bounds = f"[{lo if lo is not None else '-inf'}, {hi if hi is not None else 'inf'}]"
        if lo_open:
            bounds = "(" + bounds[1:]
        if not math.isfinite(value):
            raise self.error(key, f"a finite number in {bounds}")
        if lo is not None and (value < lo or (lo_open and value == lo)):
            raise self.error(key, f"a number in {bounds}")
        if hi is not None and value > hi:
            raise self.error(key, f"a number in {bounds}")
        return value

    def integer(self, key: str, default: Any = ..., *, lo: int | None = None,
                hi: int | None = None) -> int:
        value = self.raw(key, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(key, "an integer")
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise self.error(key, f"an integer in [{lo}, {hi}]")
        return value

    def boolean(self, key: str, default: Any = ...) -> bool:
        value = self.raw(key, default)
        if not isinstance(value, bool):
            raise self.error(key, "true or false")
        return value

    def string(self, key: str, default: Any = ..., *, choices: tuple[str, ...] = ()) -> str:
        value = self.raw(key, default)
        if not isinstance(value, str):
            raise self.error(key, "a string")
        if choices and value not in choices:
            raise self.error(key, "one of " + ", ".join(repr(c) for c in choices))
        return value

    def numbers(self, key: str, n: int, default: Any = ..., *, lo: float | None = None,
                hi: float | None = None, lo_open: bool = False) -> tuple[float, ...]:
        value = self.raw(key, default)
        ok = (isinstance(value, list | tuple) and len(value) == n
              and all(isinstance(v, int | float) and not isinstance(v, bool) for v in value))
        if not ok:
            raise self.error(key, f"a list of {n} numbers")
        out = tuple(float(v) for v in value)
        for v in out:
            if (not math.isfinite(v) or (lo is not None and (v < lo or (lo_open and v == lo)))
                    or (hi is not None and v > hi)):
                raise self.error(key, f"a list of {n} finite numbers in [{lo}, {hi}]")
        return out

    def vec3(self, key: str, default: Any = ..., *, lo: float | None = None,
             hi: float | None = None, lo_open: bool = False) -> Vec3:
        """`numbers(key, 3, ...)` as a 3-vector."""
        v = self.numbers(key, 3, default, lo=lo, hi=hi, lo_open=lo_open)
        return (v[0], v[1], v[2])

    def table(self, key: str, default: Any = ...) -> Table:
        value = self.raw(key, default)
        if not isinstance(value, dict):
            raise self.error(key, "a table")
        return Table(value, self.source, f"{self._name(key)}.")

    def tables(self, key: str) -> list[Table]:
        value = self.raw(key, [])
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise self.error(key, "an array of tables")
        return [Table(v, self.source, f"{self._name(key)}[{i}].") for i, v in enumerate(value)]

    def finish(self) -> None:
        """Refuse keys this loader did not read (typos must not pass silently)."""
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            raise ConfigError(
                f"{self.source}: unknown key '{self._name(unknown[0])}' "
                f"(known: {', '.join(sorted(self.used))})")


def read_toml(path: Path) -> dict[str, Any]:
    try:
        with path.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"{path}: file not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
