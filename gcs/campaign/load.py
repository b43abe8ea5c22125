"""Reading a campaign file and checking every key of it (CampaignError names the file and
the key)."""

from __future__ import annotations

import math
import tomllib
from collections.abc import Collection, Iterator
from pathlib import Path
from typing import Any, TypeGuard

import numpy as np

from common.config.scenario import ConfigError, resolved_scenario_data
from gcs.campaign.keys import key_path
from gcs.campaign.model import (
    AXIS_KEYS,
    CAMPAIGN_KEYS,
    DISTRIBUTIONS,
    DRAW_KEYS,
    KEEP_KEYS,
    MONTE_CARLO_KEYS,
    Axis,
    Campaign,
    CampaignError,
    Draw,
)

_TOP_KEYS = CAMPAIGN_KEYS.names()
_AXIS_KEYS = AXIS_KEYS.names()
_MONTE_CARLO_KEYS = MONTE_CARLO_KEYS.names()
_DRAW_KEYS = DRAW_KEYS.names()


def _refuse_unknown(t: dict[str, Any], allowed: Collection[str], where: str,
                    suffix: str = "") -> None:
    """CampaignError naming the first (sorted) key of `t` not in `allowed`."""
    unknown = set(t) - set(allowed)
    if unknown:
        raise CampaignError(f"{where}: unknown key '{sorted(unknown)[0]}'{suffix}")


def _is_int_from(v: object, low: int) -> TypeGuard[int]:
    """An integer (not a bool) >= low."""
    return not isinstance(v, bool) and isinstance(v, int) and v >= low


def _flat(table: dict[str, Any], prefix: str = "") -> Iterator[tuple[str, Any]]:
    """[set]'s entries as (key, value): nested tables are paths, other values are set."""
    for k, v in table.items():
        name = f"{prefix}{k}"
        if isinstance(v, dict):
            yield from _flat(v, name + ".")
        else:
            yield name, v


def _number(t: dict[str, Any], key: str, where: str) -> float:
    """t[key] as a finite number (not a bool)."""
    v = t.get(key)
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise CampaignError(f"{where}: key '{key}': expected a finite number, got {v!r}")
    return float(v)


# ------------------------------------------------------------------ [[axis]]


def _axis_keys(t: dict[str, Any], where: str) -> tuple[str, ...]:
    """An axis's 'key' (one) or 'keys' (several moving together), each a valid key path."""
    if ("key" in t) == ("keys" in t):
        raise CampaignError(f"{where}: give 'key' (one) or 'keys' (several moving together)")
    keys = (t["key"],) if "key" in t else t["keys"]
    if not isinstance(keys, list | tuple) or not keys:
        raise CampaignError(f"{where}: 'keys' must be a non-empty list of keys")
    keys = tuple(keys)
    for k in keys:
        key_path(k)
    return keys


def _spaced_values(t: dict[str, Any], where: str) -> list[Any]:
    """An axis's 'start', 'stop', 'num': num values evenly spaced, integers when start and
    stop are integers and every step lands on one."""
    num = t.get("num")
    if not _is_int_from(num, 1):
        raise CampaignError(f"{where}: key 'num': expected an integer >= 1, got {num!r}")
    lo, hi = _number(t, "start", where), _number(t, "stop", where)
    values = [float(v) for v in np.linspace(lo, hi, num)]
    if (all(isinstance(t[k], int) for k in ("start", "stop"))
            and all(v.is_integer() for v in values)):
        return [int(v) for v in values]  # whole steps between integers: integers
    return values


def _axis_values(t: dict[str, Any], where: str) -> list[Any]:
    """An axis's 'values' list, or the values 'start', 'stop', 'num' space (not both)."""
    if "values" not in t:
        return _spaced_values(t, where)
    if any(k in t for k in ("start", "stop", "num")):
        raise CampaignError(f"{where}: give 'values' or 'start', 'stop', 'num', not both")
    values = t["values"]
    if not isinstance(values, list) or not values:
        raise CampaignError(f"{where}: 'values' must be a non-empty list")
    return values


def _axis(t: Any, where: str) -> Axis:
    """One [[axis]]: its keys and one row of values per grid value (a list per row when
    several keys move together)."""
    if not isinstance(t, dict):
        raise CampaignError(f"{where}: expected a table")
    _refuse_unknown(t, _AXIS_KEYS, where)
    keys = _axis_keys(t, where)
    values = _axis_values(t, where)
    if len(keys) == 1:
        return Axis(keys, tuple((v,) for v in values))
    if not all(isinstance(v, list) and len(v) == len(keys) for v in values):
        raise CampaignError(f"{where}: each value must be a list of {len(keys)} "
                            f"(one per key)")
    return Axis(keys, tuple(tuple(v) for v in values))


def _axes(data: dict[str, Any], src: str) -> tuple[Axis, ...]:
    """The [[axis]] tables, no key on two of them."""
    raw_axes = data.get("axis", [])
    if not isinstance(raw_axes, list):
        raise CampaignError(f"{src}: key 'axis': expected an array of tables ([[axis]])")
    axes = tuple(_axis(t, f"{src}: axis[{i}]") for i, t in enumerate(raw_axes))
    seen: set[str] = set()
    for a in axes:
        for k in a.keys:
            if k in seen:
                raise CampaignError(f"{src}: key {k!r} is on two axes")
            seen.add(k)
    return axes


# ------------------------------------------------------------------ [monte_carlo]


def _draw_args_checked(dist: str, args: dict[str, float], where: str) -> None:
    """The arguments of a numeric distribution: sigma >= 0, low <= high, low > 0 for a
    log-uniform draw, whole bounds for integers."""
    if dist == "normal" and not args["sigma"] >= 0.0:
        raise CampaignError(f"{where}: key 'sigma': expected >= 0, got {args['sigma']}")
    if dist in ("uniform", "loguniform", "integers") and not args["low"] <= args["high"]:
        raise CampaignError(f"{where}: expected low <= high, got {args['low']} > "
                            f"{args['high']}")
    if dist == "loguniform" and not args["low"] > 0.0:
        raise CampaignError(f"{where}: key 'low': a log-uniform draw needs low > 0")
    if dist == "integers" and not all(float(args[n]).is_integer() for n in args):
        raise CampaignError(f"{where}: integers need whole low and high")


def _draw(t: Any, where: str) -> Draw:
    """One [[monte_carlo.draw]]: its key, its distribution and that distribution's
    arguments."""
    if not isinstance(t, dict):
        raise CampaignError(f"{where}: expected a table")
    dist = t.get("distribution")
    if dist not in DISTRIBUTIONS:
        raise CampaignError(f"{where}: key 'distribution': expected one of "
                            f"{', '.join(DISTRIBUTIONS)}, got {dist!r}")
    names = DISTRIBUTIONS[dist]
    _refuse_unknown(t, {"key", "distribution", *names} & _DRAW_KEYS, where, f" for {dist}")
    key = t.get("key")
    if not isinstance(key, str):
        raise CampaignError(f"{where}: key 'key': expected a key, got {key!r}")
    key_path(key)
    if dist == "choice":
        values = t.get("values")
        if not isinstance(values, list) or not values:
            raise CampaignError(f"{where}: key 'values': expected a non-empty list")
        return Draw(key, dist, {"values": values})
    args = {n: _number(t, n, where) for n in names}
    _draw_args_checked(dist, args, where)
    return Draw(key, dist, args)


def _monte_carlo(data: dict[str, Any], src: str,
                 axes: tuple[Axis, ...]) -> tuple[tuple[Draw, ...], int, int]:
    """(draws, number of draws, seed) of [monte_carlo] (none: (), 1, 0); no drawn key on an
    axis."""
    mc = data.get("monte_carlo")
    if mc is None:
        return (), 1, 0
    where = f"{src}: monte_carlo"
    if not isinstance(mc, dict):
        raise CampaignError(f"{where}: expected a table")
    _refuse_unknown(mc, _MONTE_CARLO_KEYS, where)
    n_draws, seed = mc.get("draws"), mc.get("seed", MONTE_CARLO_KEYS["seed"].default)
    if not _is_int_from(n_draws, 1):
        raise CampaignError(f"{where}: key 'draws': expected an integer >= 1")
    if not _is_int_from(seed, 0):
        raise CampaignError(f"{where}: key 'seed': expected an integer >= 0")
    raw = mc.get("draw", [])
    if not isinstance(raw, list) or not raw:
        raise CampaignError(f"{where}: expected at least one [[monte_carlo.draw]]")
    draws = tuple(_draw(t, f"{where}.draw[{i}]") for i, t in enumerate(raw))
    on_axes = {k for a in axes for k in a.keys}
    for d in draws:
        if d.key in on_axes:
            raise CampaignError(f"{src}: key {d.key!r} is both an axis and a draw")
    return draws, n_draws, seed


# ------------------------------------------------------------------ the file


def _read_toml(path: Path, src: str) -> dict[str, Any]:
    """The file's TOML (not found, unreadable, not TOML: CampaignError)."""
    try:
        return tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise CampaignError(f"{src}: file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise CampaignError(f"{src}: unreadable: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise CampaignError(f"{src}: not valid TOML: {exc}") from None


def _name(data: dict[str, Any], src: str) -> str:
    """'name': a non-empty string."""
    name = data.get("name")
    if not isinstance(name, str) or not name:
        raise CampaignError(f"{src}: key 'name': expected a non-empty string")
    return name


def _base(data: dict[str, Any], path: Path, src: str) -> tuple[Path, dict[str, Any]]:
    """(the 'base' scenario's resolved path, its data resolved), relative to the file."""
    base_name = data.get("base")
    if not isinstance(base_name, str):
        raise CampaignError(f"{src}: key 'base': expected a scenario file name")
    base = (path.parent / base_name).resolve()
    try:
        return base, resolved_scenario_data(base)
    except ConfigError as exc:
        raise CampaignError(f"{src}: key 'base': {exc}") from None


def _transport(data: dict[str, Any], src: str) -> str:
    """'transport': one of TRANSPORTS (default in-process)."""
    key = CAMPAIGN_KEYS["transport"]
    transport = data.get(key.name, key.default)
    if transport not in key.choices:
        raise CampaignError(f"{src}: key 'transport': expected one of "
                            f"{', '.join(key.choices)}, got {transport!r}")
    return str(transport)


def _fixed(data: dict[str, Any], src: str) -> dict[str, Any]:
    """[set] flattened to key paths (`_flat`), each valid."""
    fixed = data.get("set", {})
    if not isinstance(fixed, dict):
        raise CampaignError(f"{src}: key 'set': expected a table")
    fixed = dict(_flat(fixed))
    for k in fixed:
        key_path(k)
    return fixed


def _keep(data: dict[str, Any], src: str) -> str:
    """[keep] run_folders: one of KEEP (default none)."""
    keep_t = data.get("keep", {})
    if not isinstance(keep_t, dict) or set(keep_t) - KEEP_KEYS.names():
        raise CampaignError(f"{src}: key 'keep': expected a table with 'run_folders'")
    key = KEEP_KEYS["run_folders"]
    keep = keep_t.get(key.name, key.default)
    if keep not in key.choices:
        raise CampaignError(f"{src}: key 'keep.run_folders': expected one of "
                            f"{', '.join(key.choices)}, got {keep!r}")
    return str(keep)


def load_campaign(path: str | Path) -> Campaign:
    """Read and check a campaign file (CampaignError naming the file and the key)."""
    path = Path(path)
    src = str(path)
    data = _read_toml(path, src)
    _refuse_unknown(data, _TOP_KEYS, src)
    name = _name(data, src)
    base, base_data = _base(data, path, src)
    transport = _transport(data, src)
    fixed = _fixed(data, src)
    axes = _axes(data, src)
    draws, n_draws, mc_seed = _monte_carlo(data, src, axes)
    keep = _keep(data, src)
    return Campaign(name, src, base, base_data, fixed, axes, draws, n_draws, mc_seed,
                    transport, keep)
