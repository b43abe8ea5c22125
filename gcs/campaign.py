"""`gcs campaign FILE.toml --out DIR`: many flights of one base scenario, on Dask.

A campaign file names a base scenario, keys to set on every run (`[set]`), axes (a grid:
every combination of the axes' values) and Monte-Carlo draws (`[monte_carlo]`: N draws of
stated distributions per grid point). A key is a path into the scenario's TOML with its
vehicle and gain files inlined (common.config.resolved_scenario_data): `controller`,
`seed`, `sensors`, `vehicle.rotor_tau_up_s`, `gains.pid.kp_d`, `params.CA_LAG_COMP`,
`disturbance.force[0].magnitude`, `actuator_fault[0].index`, ...; every run's scenario is
validated by the same loader as a scenario file, before anything flies.

    name = "example"
    base = "../scenarios/case2_impulse.toml"
    transport = "in-process"          # or "udp", "tcp", "zenoh": through processes
    [set]
    duration_s = 8.0
    [[axis]]
    key = "controller"
    values = ["pid", "pd"]
    [[axis]]                           # several keys moving together
    keys = ["disturbance.force[0].azimuth_deg", "disturbance.force[0].elevation_deg"]
    values = [[0.0, 0.0], [90.0, 0.0]]
    [monte_carlo]
    draws = 20
    seed = 1
    [[monte_carlo.draw]]
    key = "vehicle.mass_kg"
    distribution = "normal"           # uniform (low, high), normal (mean, sigma),
    mean = 4.27                       # loguniform (low, high), integers (low, high),
    sigma = 0.1                       # choice (values)
    [keep]
    run_folders = "failed"            # "none" (default), "failed" or "all"

Results: DIR/runs.jsonl, the campaign's journal, gets one line per finished run as it
finishes (flushed; a line cut short by a kill is ignored); DIR/results.csv is rewritten from
it atomically, a row per run: its id (a hash of its full configuration), its axis values,
status and every metric. A run whose id is in the journal is not flown again, so a stopped
campaign resumes where it stopped and a finished one flies nothing. DIR/summary.md and its
figures are written at the end (gcs/campaign_report.py).

Execution: Dask distributed. By default a LocalCluster on 127.0.0.1 (worker processes, one
thread each, one per CPU) with its dashboard; `--scheduler tcp://HOST:8786` submits to a
running cluster. A worker lost mid-run (killed, out of memory) has its run re-executed on
another worker by the scheduler; a run is recorded once, when its result first arrives.
"""

from __future__ import annotations

import copy
import csv
import dataclasses
import hashlib
import io
import json
import math
import os
import re
import shutil
import socket
import sys
import tempfile
import time
import tomllib
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from itertools import pairwise, product
from pathlib import Path
from typing import Any

import numpy as np

from common.config import ConfigError, resolved_scenario_data, scenario_from_data

TRANSPORTS = ("in-process", "udp", "tcp", "zenoh")
KEEP = ("none", "failed", "all")
DISTRIBUTIONS = {"uniform": ("low", "high"), "normal": ("mean", "sigma"),
                 "loguniform": ("low", "high"), "integers": ("low", "high"),
                 "choice": ("values",)}
JOURNAL = "runs.jsonl"
RESULTS = "results.csv"
FORMAT = 1  # of the hashed configuration (a change re-flies every run)
# Bookkeeping columns of results.csv, first; then the axis keys, then the metrics.
HEAD = ("run_id", "index", "status", "status_reason")


class CampaignError(ValueError):
    """A campaign file or a run it describes is invalid (exit status 2)."""


# ----------------------------------------------------------------------------------------
# The campaign file
# ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Axis:
    keys: tuple[str, ...]
    values: tuple[tuple[Any, ...], ...]  # one tuple per grid value, one entry per key


@dataclass(frozen=True)
class Draw:
    key: str
    distribution: str
    args: dict[str, Any]


@dataclass(frozen=True)
class Campaign:
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


# ----------------------------------------------------------------------------------------
# Runs
# ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RunSpec:
    """One run as a worker needs it: self-contained and small (pickled to the worker)."""

    run_id: str
    index: int
    params: dict[str, Any]  # results.csv's parameter columns
    data: dict[str, Any]  # the scenario, everything inlined
    base: str  # the base scenario's file (relative names in data resolve against it)
    transport: str
    keep: str  # "none", "failed", "all"
    folder: str  # where its run folder goes, if kept


def _drawn(draw: Draw, rng: np.random.Generator) -> Any:
    a = draw.args
    if draw.distribution == "uniform":
        return float(rng.uniform(a["low"], a["high"]))
    if draw.distribution == "normal":
        return float(rng.normal(a["mean"], a["sigma"]))
    if draw.distribution == "loguniform":
        return float(math.exp(rng.uniform(math.log(a["low"]), math.log(a["high"]))))
    if draw.distribution == "integers":
        return int(rng.integers(int(a["low"]), int(a["high"]), endpoint=True))
    values = a["values"]
    return values[int(rng.integers(0, len(values)))]


def run_id(data: dict[str, Any], transport: str) -> str:
    """A hash of a run's full configuration: the same run has the same id in any campaign."""
    text = json.dumps({"format": FORMAT, "transport": transport, "scenario": data},
                      sort_keys=True, separators=(",", ":"), allow_nan=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def expand(campaign: Campaign, out: Path) -> list[RunSpec]:
    """Every run of the campaign, validated (CampaignError names the run and the problem).

    Draw d of a grid point takes its values from a generator seeded with (seed, d), so the
    same draws go with every grid point and adding an axis does not change them.
    """
    base = copy.deepcopy(campaign.base_data)
    for k, v in campaign.fixed.items():
        set_key(base, k, v)
    draws = [dict(zip([d.key for d in campaign.draws],
                      [_drawn(d, rng) for d in campaign.draws], strict=True))
             for rng in (np.random.default_rng([campaign.mc_seed, i])
                         for i in range(campaign.n_draws))] if campaign.draws else [{}]
    specs: list[RunSpec] = []
    seen: dict[str, int] = {}
    grid = product(*[a.values for a in campaign.axes]) if campaign.axes else [()]
    for point in grid:
        for d, drawn in enumerate(draws):
            data = copy.deepcopy(base)
            params: dict[str, Any] = {}
            for axis, values in zip(campaign.axes, point, strict=True):
                for k, v in zip(axis.keys, values, strict=True):
                    set_key(data, k, copy.deepcopy(v))
                    params[k] = v
            if campaign.draws:
                params["draw"] = d
            for k, v in drawn.items():
                set_key(data, k, v)
                params[k] = v
            index = len(specs)
            try:
                scenario_from_data(copy.deepcopy(data), campaign.base)
            except ConfigError as exc:
                raise CampaignError(f"run {index} ({_describe(params)}): {exc}") from None
            rid = run_id(data, campaign.transport)
            if rid in seen:
                raise CampaignError(f"runs {seen[rid]} and {index} ({_describe(params)}) are "
                                    "the same run: an axis or draw does not change it")
            seen[rid] = index
            specs.append(RunSpec(rid, index, params, data, str(campaign.base),
                                 campaign.transport, campaign.keep,
                                 str(out / "runs" / f"{index:05d}_{rid}")))
    return specs


def _describe(params: dict[str, Any]) -> str:
    return ", ".join(f"{k} = {v!r}" for k, v in params.items()) or "the base scenario"


def flatten(metrics: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """metrics.json as flat columns: nested tables joined with '.', events as JSON text."""
    out: dict[str, Any] = {}
    for k, v in metrics.items():
        name = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(flatten(v, name + "."))
        elif isinstance(v, list):
            out[name] = json.dumps(v, separators=(",", ":"))
        else:
            out[name] = v
    return out


def _write_scenario_files(data: dict[str, Any], folder: Path) -> Path:
    """The run's scenario as files the processes read: scenario.toml naming vehicle.toml and
    one gain file per controller, beside it."""
    import tomli_w

    folder.mkdir(parents=True, exist_ok=True)
    data = copy.deepcopy(data)
    (folder / "vehicle.toml").write_text(tomli_w.dumps(data["vehicle"]))
    data["vehicle"] = "vehicle.toml"
    for ctrl, table in list(data["gains"].items()):
        (folder / f"gains_{ctrl}.toml").write_text(tomli_w.dumps(table))
        data["gains"][ctrl] = f"gains_{ctrl}.toml"
    path = folder / "scenario_run.toml"
    path.write_text(tomli_w.dumps(data))
    return path


def warm_worker() -> None:
    """Import what a run needs, once per worker, before the runs are timed."""
    import gcs.inprocess
    import gcs.process_run  # noqa: F401


START_ATTEMPTS = 3  # a run through processes that could not start is tried again (new ports)


def _through_processes(spec: RunSpec, folder: Path) -> dict[str, Any]:
    """A run through sitl and fcu processes on their own free ports (or Zenoh prefix), in
    its run folder or a temporary one."""
    from common.config import load_scenario
    from common.links import free_port
    from gcs.process_run import RunError, run_processes

    where = folder if spec.keep != "none" else Path(tempfile.mkdtemp(prefix="campaign-run-"))
    metrics: dict[str, Any] = {}
    try:
        scenario = load_scenario(_write_scenario_files(spec.data, where))
        for attempt in range(1, START_ATTEMPTS + 1):
            # Zenoh: the run's own prefix and its own router on a free port (a router
            # shared by concurrent runs would stop with the run that started it).
            router = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
            try:
                metrics = run_processes(scenario, where, transport=spec.transport,
                                        zenoh_url=f"zenoh:campaign/{spec.run_id}@{router}")
                break
            except RunError:
                if attempt == START_ATTEMPTS:
                    raise
    finally:
        completed = metrics.get("status") == "completed"
        if spec.keep == "none" or (spec.keep == "failed" and completed):
            shutil.rmtree(where, ignore_errors=True)
    return metrics


def execute_run(spec: RunSpec) -> dict[str, Any]:
    """Fly one run (on a worker) and return its row of results.csv. What happened to the
    vehicle is a status; in-process, a vehicle that refuses the run (its mission, arming)
    is status "refused" with the reason. A run that cannot be carried out raises (through
    processes after START_ATTEMPTS tries): it is not recorded, and a rerun tries again."""
    from gcs.inprocess import InProcessError, run_scenario
    from gcs.runio import write_run

    t0 = time.monotonic()
    folder = Path(spec.folder)
    row: dict[str, Any] = {"run_id": spec.run_id, "index": spec.index, **spec.params}
    if spec.transport == "in-process":
        scenario = scenario_from_data(copy.deepcopy(spec.data), spec.base)
        try:
            result = run_scenario(scenario, logs=spec.keep != "none")
        except InProcessError as exc:
            row.update(status="refused", status_reason=str(exc))
            return row
        metrics = result.metrics
        if spec.keep == "all" or (spec.keep == "failed" and metrics["status"] != "completed"):
            src = _write_scenario_files(spec.data, folder)
            write_run(folder, dataclasses.replace(scenario, source=str(src)), result)
    else:
        metrics = _through_processes(spec, folder)
    row.update(flatten({k: v for k, v in metrics.items() if k != "logs"}))
    row["run_wall_s"] = time.monotonic() - t0
    return row


# ----------------------------------------------------------------------------------------
# The journal and the table
# ----------------------------------------------------------------------------------------


def read_journal(out: Path) -> dict[str, dict[str, Any]]:
    """The rows recorded so far, by run id (a line cut short by a kill is skipped)."""
    rows: dict[str, dict[str, Any]] = {}
    try:
        text = (out / JOURNAL).read_text()
    except FileNotFoundError:
        return rows
    for line in text.splitlines():
        try:
            row = json.loads(line)
        except ValueError:
            continue
        if isinstance(row, dict) and isinstance(row.get("run_id"), str):
            rows.setdefault(row["run_id"], row)
    return rows


class Journal:
    """Append-only record of finished runs (one JSON line each, flushed and synced)."""

    def __init__(self, out: Path) -> None:
        path = out / JOURNAL
        # A line a kill cut short would join the next one: end the file with a newline.
        if path.exists() and path.stat().st_size:
            with path.open("rb") as fh:
                fh.seek(-1, os.SEEK_END)
                if fh.read(1) != b"\n":
                    with path.open("ab") as fa:
                        fa.write(b"\n")
        self._fh = path.open("a", encoding="utf-8")

    def add(self, row: dict[str, Any]) -> None:
        self._fh.write(json.dumps(_jsonable(row), separators=(",", ":")) + "\n")
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def close(self) -> None:
        self._fh.close()


def _jsonable(row: dict[str, Any]) -> dict[str, Any]:
    out = {}
    for k, v in row.items():
        if isinstance(v, float) and not math.isfinite(v):
            v = None
        elif isinstance(v, np.generic):
            v = v.item()
        out[k] = v
    return out


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, list | dict):
        return json.dumps(v, separators=(",", ":"))
    return str(v)


def write_table(out: Path, campaign: Campaign, specs: list[RunSpec],
                rows: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """results.csv (atomically) from the recorded rows of this campaign's runs, in run
    order; returns those rows."""
    ordered = [rows[s.run_id] for s in specs if s.run_id in rows]
    params = list(campaign.columns)
    metrics: list[str] = []
    seen = set(HEAD) | set(params)
    for r in ordered:
        for k in r:
            if k not in seen:
                seen.add(k)
                metrics.append(k)
    header = [*HEAD, *params, *metrics]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for r in ordered:
        w.writerow([_cell(r.get(k)) for k in header])
    tmp = out / (RESULTS + ".tmp")
    tmp.write_text(buf.getvalue())
    tmp.replace(out / RESULTS)
    return ordered


# ----------------------------------------------------------------------------------------
# Progress and execution
# ----------------------------------------------------------------------------------------


@dataclass
class Progress:
    """A progress bar with the ETA on a terminal; a line every 10 % otherwise."""

    total: int
    stream: Any = field(default_factory=lambda: sys.stderr)
    done: int = 0
    t0: float = field(default_factory=time.monotonic)
    statuses: dict[str, int] = field(default_factory=dict)
    _last_decile: int = -1

    def update(self, status: str) -> None:
        self.done += 1
        self.statuses[status] = self.statuses.get(status, 0) + 1
        elapsed = time.monotonic() - self.t0
        eta = elapsed / self.done * (self.total - self.done)
        counts = "  ".join(f"{k} {v}" for k, v in sorted(self.statuses.items()))
        if self.stream.isatty():
            width = 30
            fill = round(width * self.done / max(self.total, 1))
            self.stream.write(f"\r[{'#' * fill}{'.' * (width - fill)}] {self.done}/"
                              f"{self.total}  ETA {_clock(eta)}  {counts}\x1b[K")
            if self.done == self.total:
                self.stream.write("\n")
            self.stream.flush()
            return
        decile = 10 * self.done // max(self.total, 1)
        if decile != self._last_decile or self.done == self.total:
            self._last_decile = decile
            print(f"campaign: {self.done}/{self.total} runs, {_clock(elapsed)} elapsed, "
                  f"ETA {_clock(eta)}  ({counts})", file=self.stream, flush=True)


def _clock(s: float) -> str:
    s = max(0, round(s))
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" if s >= 3600 else \
        f"{s // 60}:{s % 60:02d}"


@dataclass
class Outcome:
    """What `run_campaign` did: runs recorded (before and now), runs not executed."""

    total: int
    recorded_before: int
    flown: int
    failed: dict[int, str]  # run index -> why it could not be executed
    rows: list[dict[str, Any]]
    wall_s: float  # from the first run submitted to the summary written
    startup_s: float  # the cluster's start (or the connection to the scheduler)
    sim_s: float  # simulated seconds flown by this invocation
    workers: int
    dashboard: str | None

    @property
    def exit_code(self) -> int:
        return 1 if self.failed else 0


def default_workers() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def run_campaign(campaign: Campaign, out: Path, *, scheduler: str | None = None,
                 workers: int | None = None, dashboard: str | None = "127.0.0.1:8787",
                 progress_stream: Any = None, report: bool = True,
                 on_result: Callable[[dict[str, Any]], None] | None = None) -> Outcome:
    """Fly every run of the campaign not yet in DIR's journal, on Dask, and write
    results.csv (and, with `report`, summary.md and its figures)."""
    out.mkdir(parents=True, exist_ok=True)
    specs = expand(campaign, out)
    recorded = read_journal(out)
    todo = [s for s in specs if s.run_id not in recorded]
    before = len(specs) - len(todo)
    failed: dict[int, str] = {}
    t0 = t_runs = time.monotonic()
    sim_s = 0.0
    n_workers = 0
    link: str | None = None
    try:  # the table is written however the runs end (an interrupt included)
        if todo:
            progress = Progress(len(todo), progress_stream or sys.stderr)
            journal = Journal(out)
            try:
                with _client(scheduler, workers, dashboard) as (client, link):
                    n_workers = len(client.scheduler_info().get("workers", {}))
                    if link:
                        print(f"campaign: dashboard {link}", file=progress.stream, flush=True)
                    client.run(warm_worker)  # part of the start-up, not of the first runs
                    t_runs = time.monotonic()
                    progress.t0 = t_runs
                    for spec, row, error in _results(client, todo):
                        if error is not None:
                            failed[spec.index] = error
                            progress.update("not executed")
                            continue
                        assert row is not None
                        if row["run_id"] in recorded:
                            continue  # a run's result arrived twice: recorded once
                        recorded[row["run_id"]] = row
                        journal.add(row)
                        sim_s += float(row.get("sim_time_s") or 0.0)
                        progress.update(str(row.get("status")))
                        if on_result is not None:
                            on_result(row)
            finally:
                journal.close()
    finally:
        rows = write_table(out, campaign, specs, recorded)
    if report:
        from gcs.campaign_report import write_report

        write_report(out, campaign, rows)
    t_end = time.monotonic()
    return Outcome(len(specs), before, len(todo) - len(failed), failed, rows,
                   t_end - t_runs, t_runs - t0, sim_s, n_workers, link)


CONNECT_TIMEOUT_S = 10.0  # to a running scheduler


class _client:
    """A Dask client on the given scheduler, or on a LocalCluster started (and stopped)
    here: worker processes with one thread each, everything on 127.0.0.1."""

    def __init__(self, scheduler: str | None, workers: int | None,
                 dashboard: str | None) -> None:
        self.scheduler, self.workers, self.dashboard = scheduler, workers, dashboard
        self.cluster: Any = None
        self.client: Any = None

    def __enter__(self) -> tuple[Any, str | None]:
        import logging

        from dask.distributed import Client, LocalCluster

        if self.scheduler is not None:
            self.client = Client(self.scheduler, timeout=CONNECT_TIMEOUT_S)
            services = self.client.scheduler_info().get("services", {})
            has_dashboard = "dashboard" in services and self._bokeh_dashboard()
            return self.client, self.client.dashboard_link if has_dashboard else None
        n = self.workers or default_workers()
        # The dashboard's own warnings (a busy port: it takes another) are not errors.
        logging.getLogger("distributed").setLevel(logging.ERROR)
        # Without a dashboard the scheduler's HTTP server (health, metrics) still runs: on
        # a free port of 127.0.0.1, not on the dashboard's 8787.
        self.cluster = LocalCluster(
            n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
            scheduler_port=0, dashboard_address=self.dashboard or None,
            scheduler_kwargs=None if self.dashboard else {"dashboard_address": "127.0.0.1:0"},
            silence_logs=logging.ERROR, worker_dashboard_address=None)
        self.client = Client(self.cluster)
        self.client.wait_for_workers(n, timeout=60)
        return self.client, (self.client.dashboard_link if self.dashboard else None)

    def _bokeh_dashboard(self) -> bool:
        """Whether the scheduler serves its dashboard pages (not only health and metrics)."""
        import urllib.request

        try:
            with urllib.request.urlopen(self.client.dashboard_link, timeout=2.0) as r:
                return bool(r.status == 200)
        except OSError:
            return False

    def __exit__(self, *exc: object) -> None:
        if self.client is not None:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def _results(client: Any, todo: list[RunSpec]
             ) -> Iterable[tuple[RunSpec, dict[str, Any] | None, str | None]]:
    """(spec, row, None) for each run as it finishes; (spec, None, why) for a run that could
    not be executed (it raised, or the workers running it kept dying)."""
    from dask.distributed import as_completed

    by_key: dict[str, RunSpec] = {}
    futures = []
    for spec in todo:
        fut = client.submit(execute_run, spec, key=f"run-{spec.run_id}", pure=False)
        by_key[fut.key] = spec
        futures.append(fut)
    for fut in as_completed(futures):
        spec = by_key[fut.key]
        if fut.status == "finished":
            yield spec, fut.result(), None
        else:
            exc = fut.exception()
            yield spec, None, f"{type(exc).__name__}: {exc}"
        fut.release()
