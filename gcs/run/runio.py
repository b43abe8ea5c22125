"""The run folder: scenario as run, the plant's truth log (truth.ulg), the onboard log
(onboard.ulg), and metrics.json, written last.

A folder holds one run: `prepare_run_dir` refuses a folder that is not empty unless told to
empty it first, and metrics.json records the size and SHA-256 of each log beside it, so a
report can refuse logs and metrics that do not belong together (`check_run_dir`).
"""

from __future__ import annotations

import hashlib
import json
import math
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from common.config.scenario import Scenario
from common.logs.columns import ONBOARD_COLUMNS, TRUTH_COLUMNS
from common.logs.ulog import ULogError, read_topic
from common.outcome import Event
from gcs.report.metrics import onboard_on_truth_clock
from gcs.report.run_metrics import RunMetrics, metrics_from_json

TRUTH_LOG = "truth.ulg"  # written by the simulator (sitl.truth_log)
ONBOARD_LOG = "onboard.ulg"  # written by the FCU (fcu.edge.onboard_log)
TRUTH_TOPIC = "dq_truth"
ONBOARD_TOPIC = "dq_onboard"


@dataclass
class RunResult:
    metrics: RunMetrics
    truth: np.ndarray  # rows of sitl.plant.TRUTH_COLUMNS
    onboard: np.ndarray  # rows of fcu.control.core.ONBOARD_COLUMNS
    events: list[Event] = field(default_factory=list)
    truth_ulog: bytes | None = None  # truth.ulg as the simulator writes it
    onboard_ulog: bytes | None = None  # onboard.ulg as the FCU writes it

    def truth_col(self, *names: str) -> np.ndarray:
        return self.truth[:, [TRUTH_COLUMNS.index(n) for n in names]]

    def onboard_col(self, *names: str) -> np.ndarray:
        return self.onboard[:, [ONBOARD_COLUMNS.index(n) for n in names]]


def _finite(obj: Any) -> Any:
    """JSON without inf/NaN: a non-finite figure is a bug, refuse to write it silently."""
    if isinstance(obj, float) and not math.isfinite(obj):
        raise ValueError(f"non-finite value in metrics: {obj}")
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_finite(v) for v in obj]
    return obj


class RunDirError(ValueError):
    """A run folder that cannot take this run (not empty, not a folder, inconsistent)."""


def prepare_run_dir(out: Path, force: bool) -> None:
    """Make `out` an empty folder for one run: refused if it holds anything, unless `force`,
    which empties it first."""
    if out.exists() and not out.is_dir():
        raise RunDirError(f"{out} is not a folder")
    if out.is_dir() and any(out.iterdir()):
        if not force:
            raise RunDirError(f"{out} is not empty (a folder holds one run; --force empties "
                              "it first)")
        for entry in out.iterdir():
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry)
            else:
                entry.unlink()
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RunDirError(f"{out}: {exc.strerror}") from None


def write_run(out: Path, scenario: Scenario, result: RunResult) -> None:
    out.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(scenario.source, out / "scenario.toml")
    if result.truth_ulog is None or result.onboard_ulog is None:
        raise ValueError("a run written to a folder must be flown with its logs")
    (out / TRUTH_LOG).write_bytes(result.truth_ulog)
    (out / ONBOARD_LOG).write_bytes(result.onboard_ulog)
    metrics = result.metrics.copy()
    metrics["overrides"] = {"controller": scenario.controller,
                            "ideal_actuators": scenario.ideal_actuators,
                            "duration_s": scenario.duration_s}
    write_metrics(out, metrics)


def _fingerprint(path: Path) -> dict[str, Any]:
    digest = hashlib.sha256()
    with path.open("rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            digest.update(chunk)
    return {"bytes": path.stat().st_size, "sha256": digest.hexdigest()}


def write_metrics(out: Path, metrics: RunMetrics) -> None:
    """metrics.json, last, with the fingerprints of the logs it was computed from."""
    metrics = metrics.copy()
    metrics["logs"] = {name: _fingerprint(out / name) for name in (TRUTH_LOG, ONBOARD_LOG)
                       if (out / name).exists()}
    tmp = out / "metrics.json.tmp"
    tmp.write_text(json.dumps(_finite(metrics), indent=2, allow_nan=False) + "\n")
    tmp.replace(out / "metrics.json")


def check_run_dir(run_dir: Path) -> RunMetrics:
    """metrics.json of a run folder whose logs are the ones it was computed from."""
    try:
        metrics = metrics_from_json(json.loads((run_dir / "metrics.json").read_text()))
    except (OSError, ValueError) as exc:  # MetricsError is a ValueError
        raise RunDirError(f"{run_dir}: no readable metrics.json ({exc})") from None
    for name, expected in metrics.get("logs", {}).items():
        path = run_dir / name
        if not path.exists() or _fingerprint(path) != expected:
            raise RunDirError(f"{run_dir}: {name} is not the log metrics.json was computed "
                              "from (another run's files?)")
    if "logs" not in metrics:
        raise RunDirError(f"{run_dir}: metrics.json names no logs (written by an older "
                          "version?)")
    return metrics


def read_run_logs(run_dir: Path) -> tuple[tuple[str, ...], np.ndarray, tuple[str, ...],
                                          np.ndarray]:
    """(truth columns, truth rows, onboard columns, onboard rows) of a run folder: the float64
    topics `dq_truth` and `dq_onboard` of its ULogs, as the metrics read them."""
    try:
        tc, truth = read_topic(run_dir / TRUTH_LOG, TRUTH_TOPIC)
        oc, onboard = onboard_on_truth_clock(*read_topic(run_dir / ONBOARD_LOG, ONBOARD_TOPIC))
    except ULogError as exc:
        raise RunDirError(str(exc)) from None
    return tc, truth, oc, onboard
