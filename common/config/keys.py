"""One declaration per configuration key: its name, type, unit, default, range and meaning.

The loaders read each key through its `Key` (`Key.read` calls the `Table` reader with the
declared type, default and range), and docs/configuration.md prints the same declarations
(`python -m tools.config_doc`): the page and the loaders cannot disagree.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from common.config.reader import Table

REQUIRED: Any = ...  # the default of a key that must be given (as `Table` takes it)
_DECLARED: Any = object()  # `Key.read`'s default: the declared one

# What each type reads (`Key.read`) and how the page names it.
TYPES = {
    "number": "number", "integer": "integer", "boolean": "boolean", "string": "string",
    "numbers": "list of numbers", "vec3": "list of 3 numbers", "table": "table",
    "tables": "array of tables", "raw": "",
}


@dataclass(frozen=True)
class Key:
    """A key of a configuration table. `type` is one of TYPES ("raw": the loader checks the
    value itself, `type_doc` says what it takes); `default_doc` and `range_doc` describe a
    default or a rule the declared fields cannot (one that depends on other keys)."""

    name: str
    type: str
    meaning: str
    unit: str = ""
    default: Any = REQUIRED
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    n: int = 3
    choices: tuple[str, ...] = ()
    type_doc: str = ""
    default_doc: str = ""
    range_doc: str = ""

    def __post_init__(self) -> None:
        if self.type not in TYPES:
            raise ValueError(f"key {self.name!r}: unknown type {self.type!r}")

    def read(self, t: Table, default: Any = _DECLARED) -> Any:
        """The key's value from `t`, checked as declared; `default` (REQUIRED included)
        replaces the declared default where it depends on other keys."""
        d = self.default if default is _DECLARED else default
        if self.type == "number":
            return t.number(self.name, d, lo=self.lo, hi=self.hi, lo_open=self.lo_open)
        if self.type == "integer":
            return t.integer(self.name, d, lo=_int(self.lo), hi=_int(self.hi))
        if self.type == "boolean":
            return t.boolean(self.name, d)
        if self.type == "string":
            return t.string(self.name, d, choices=self.choices)
        if self.type == "numbers":
            return t.numbers(self.name, self.n, d, lo=self.lo, hi=self.hi, lo_open=self.lo_open)
        if self.type == "vec3":
            return t.vec3(self.name, d, lo=self.lo, hi=self.hi, lo_open=self.lo_open)
        if self.type == "table":
            return t.table(self.name, d)
        if self.type == "tables":
            return t.tables(self.name)
        return t.raw(self.name, d)

    # ------------------------------------------------------------------ the page's cells

    def type_text(self) -> str:
        if self.type_doc:
            return self.type_doc
        if self.type == "numbers":
            return f"list of {self.n} numbers"
        return TYPES[self.type]

    def default_text(self) -> str:
        if self.default_doc:
            return self.default_doc
        if self.default is REQUIRED:
            return "required"
        return value_text(self.default)

    def range_text(self) -> str:
        parts = []
        if self.choices:
            parts.append(", ".join(f"`{c}`" for c in self.choices))
        if self.lo is not None or self.hi is not None:
            lo = "-inf" if self.lo is None else value_text(self.lo)
            hi = "inf" if self.hi is None else value_text(self.hi)
            parts.append(f"{'(' if self.lo_open else '['}{lo}, {hi}]")
        if self.range_doc:
            parts.append(self.range_doc)
        return "; ".join(parts)


def _int(x: float | None) -> int | None:
    return None if x is None else int(x)


def value_text(value: Any) -> str:
    """A default or a bound as the page shows it (TOML's spelling)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return f"{value:.6g}"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, tuple | list):
        return "[" + ", ".join(value_text(v) for v in value) + "]"
    if isinstance(value, dict) and not value:
        return "none"
    return str(value)


@dataclass(frozen=True)
class KeyTable:
    """The keys of one TOML table, in the order the page lists them. `path` is the table's
    name in the file ("" for the top level, `disturbance.force[]` for an array of tables);
    `any_key`: besides its declared keys the table takes names of its own (one `Key`, named
    `*`, declares them); `also`: other tables that take the same keys; `title`: how the page
    heads the table, where its path alone does not tell it (an array of tables by kind)."""

    path: str
    keys: tuple[Key, ...]
    note: str = ""
    also: tuple[str, ...] = ()
    title: str = ""

    def __getitem__(self, name: str) -> Key:
        for k in self.keys:
            if k.name == name:
                return k
        raise KeyError(f"{self.path or 'top level'}: no key {name!r} declared")

    def names(self) -> frozenset[str]:
        return frozenset(k.name for k in self.keys)

    @property
    def any_key(self) -> bool:
        return any(k.name == "*" for k in self.keys)
