"""Reading a campaign file and checking every key of it (CampaignError names the file and
the key)."""

from __future__ import annotations

import math
import tomllib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from common.config import ConfigError, resolved_scenario_data
from gcs.campaign.keys import key_path
from gcs.campaign.model import DISTRIBUTIONS, KEEP, TRANSPORTS, Axis, Campaign, CampaignError, Draw


def _flat(table: dict[str, Any], prefix: str = "") -> Iterator[tuple[str, Any]]:
    """[set]'s entries as (key, value): nested tables are paths, other values are set."""
    for k, v in table.items():
        name = f"{prefix}{k}"
        if isinstance(v, dict):
            yield from _flat(v, name + ".")
        else:
            yield name, v


def _number(t: dict[str, Any], key: str, where: str) -> float:
    v = t.get(key)
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise CampaignError(f"{where}: key '{key}': expected a finite number, got {v!r}")
    return float(v)


def _axis(t: Any, where: str) -> Axis:
    if not isinstance(t, dict):
        raise CampaignError(f"{where}: expected a table")
    unknown = set(t) - {"key", "keys", "values", "start", "stop", "num"}
    if unknown:
        raise CampaignError(f"{where}: unknown key '{sorted(unknown)[0]}'")
    if ("key" in t) == ("keys" in t):
        raise CampaignError(f"{where}: give 'key' (one) or 'keys' (several moving together)")
    keys = (t["key"],) if "key" in t else t["keys"]
    if not isinstance(keys, list | tuple) or not keys:
        raise CampaignError(f"{where}: 'keys' must be a non-empty list of keys")
    keys = tuple(keys)
    for k in keys:
        key_path(k)
    if "values" in t:
        if any(k in t for k in ("start", "stop", "num")):
            raise CampaignError(f"{where}: give 'values' or 'start', 'stop', 'num', not both")
        values = t["values"]
        if not isinstance(values, list) or not values:
            raise CampaignError(f"{where}: 'values' must be a non-empty list")
    else:
        num = t.get("num")
        if isinstance(num, bool) or not isinstance(num, int) or num < 1:
            raise CampaignError(f"{where}: key 'num': expected an integer >= 1, got {num!r}")
        lo, hi = _number(t, "start", where), _number(t, "stop", where)
        values = [float(v) for v in np.linspace(lo, hi, num)]
        if (all(isinstance(t[k], int) for k in ("start", "stop"))
                and all(v.is_integer() for v in values)):
            values = [int(v) for v in values]  # whole steps between integers: integers
    if len(keys) == 1:
        rows = tuple((v,) for v in values)
    else:
        if not all(isinstance(v, list) and len(v) == len(keys) for v in values):
            raise CampaignError(f"{where}: each value must be a list of {len(keys)} "
                                f"(one per key)")
        rows = tuple(tuple(v) for v in values)
    return Axis(keys, rows)


def _draw(t: Any, where: str) -> Draw:
    if not isinstance(t, dict):
        raise CampaignError(f"{where}: expected a table")
    dist = t.get("distribution")
    if dist not in DISTRIBUTIONS:
        raise CampaignError(f"{where}: key 'distribution': expected one of "
                            f"{', '.join(DISTRIBUTIONS)}, got {dist!r}")
    names = DISTRIBUTIONS[dist]
    unknown = set(t) - {"key", "distribution", *names}
    if unknown:
        raise CampaignError(f"{where}: unknown key '{sorted(unknown)[0]}' for {dist}")
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
    if dist == "normal" and not args["sigma"] >= 0.0:
        raise CampaignError(f"{where}: key 'sigma': expected >= 0, got {args['sigma']}")
    if dist in ("uniform", "loguniform", "integers") and not args["low"] <= args["high"]:
        raise CampaignError(f"{where}: expected low <= high, got {args['low']} > "
                            f"{args['high']}")
    if dist == "loguniform" and not args["low"] > 0.0:
        raise CampaignError(f"{where}: key 'low': a log-uniform draw needs low > 0")
    if dist == "integers" and not all(float(args[n]).is_integer() for n in names):
        raise CampaignError(f"{where}: integers need whole low and high")
    return Draw(key, dist, args)


def load_campaign(path: str | Path) -> Campaign:
    """Read and check a campaign file (CampaignError naming the file and the key)."""
    path = Path(path)
    src = str(path)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise CampaignError(f"{src}: file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise CampaignError(f"{src}: unreadable: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise CampaignError(f"{src}: not valid TOML: {exc}") from None
    unknown = set(data) - {"name", "base", "description", "transport", "set", "axis",
                           "monte_carlo", "keep"}
    if unknown:
        raise CampaignError(f"{src}: unknown key '{sorted(unknown)[0]}'")
    name = data.get("name")
    if not isinstance(name, str) or not name:
        raise CampaignError(f"{src}: key 'name': expected a non-empty string")
    base_name = data.get("base")
    if not isinstance(base_name, str):
        raise CampaignError(f"{src}: key 'base': expected a scenario file name")
    base = (path.parent / base_name).resolve()
    try:
        base_data = resolved_scenario_data(base)
    except ConfigError as exc:
        raise CampaignError(f"{src}: key 'base': {exc}") from None
    transport = data.get("transport", "in-process")
    if transport not in TRANSPORTS:
        raise CampaignError(f"{src}: key 'transport': expected one of "
                            f"{', '.join(TRANSPORTS)}, got {transport!r}")
    fixed = data.get("set", {})
    if not isinstance(fixed, dict):
        raise CampaignError(f"{src}: key 'set': expected a table")
    fixed = dict(_flat(fixed))
    for k in fixed:
        key_path(k)
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
    mc = data.get("monte_carlo")
    draws: tuple[Draw, ...] = ()
    n_draws, mc_seed = 1, 0
    if mc is not None:
        where = f"{src}: monte_carlo"
        if not isinstance(mc, dict):
            raise CampaignError(f"{where}: expected a table")
        unknown = set(mc) - {"draws", "seed", "draw"}
        if unknown:
            raise CampaignError(f"{where}: unknown key '{sorted(unknown)[0]}'")
        raw_n, raw_seed = mc.get("draws"), mc.get("seed", 0)
        if isinstance(raw_n, bool) or not isinstance(raw_n, int) or raw_n < 1:
            raise CampaignError(f"{where}: key 'draws': expected an integer >= 1")
        if isinstance(raw_seed, bool) or not isinstance(raw_seed, int) or raw_seed < 0:
            raise CampaignError(f"{where}: key 'seed': expected an integer >= 0")
        n_draws, mc_seed = raw_n, raw_seed
        raw = mc.get("draw", [])
        if not isinstance(raw, list) or not raw:
            raise CampaignError(f"{where}: expected at least one [[monte_carlo.draw]]")
        draws = tuple(_draw(t, f"{where}.draw[{i}]") for i, t in enumerate(raw))
        for d in draws:
            if d.key in seen:
                raise CampaignError(f"{src}: key {d.key!r} is both an axis and a draw")
    keep_t = data.get("keep", {})
    if not isinstance(keep_t, dict) or set(keep_t) - {"run_folders"}:
        raise CampaignError(f"{src}: key 'keep': expected a table with 'run_folders'")
    keep = keep_t.get("run_folders", "none")
    if keep not in KEEP:
        raise CampaignError(f"{src}: key 'keep.run_folders': expected one of "
                            f"{', '.join(KEEP)}, got {keep!r}")
    return Campaign(name, src, base, base_data, fixed, axes, draws, n_draws, mc_seed,
                    transport, keep)

