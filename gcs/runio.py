"""The run folder: scenario as run, metrics.json, the plant's truth log, the onboard log."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path
from typing import Any

from common.binlog import write_log
from common.config import Scenario
from fcu.core import ONBOARD_COLUMNS
from gcs.inprocess import RunResult
from sitl.plant import TRUTH_COLUMNS

TRUTH_LOG = "truth_log.bin"
ONBOARD_LOG = "onboard_log.bin"


def _finite(obj: Any) -> Any:
    """JSON without inf/NaN: a non-finite figure is a bug, refuse to write it silently."""
    if isinstance(obj, float) and not math.isfinite(obj):
        raise ValueError(f"non-finite value in metrics: {obj}")
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_finite(v) for v in obj]
    return obj


def write_run(out: Path, scenario: Scenario, result: RunResult) -> None:
    out.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(scenario.source, out / "scenario.toml")
    metrics = dict(result.metrics)
    metrics["overrides"] = {"controller": scenario.controller,
                            "ideal_actuators": scenario.ideal_actuators,
                            "duration_s": scenario.duration_s}
    write_metrics(out, metrics)
    write_log(out / TRUTH_LOG, TRUTH_COLUMNS, result.truth)
    write_log(out / ONBOARD_LOG, ONBOARD_COLUMNS, result.onboard)


def write_metrics(out: Path, metrics: dict[str, Any]) -> None:
    (out / "metrics.json").write_text(json.dumps(_finite(metrics), indent=2,
                                                 allow_nan=False) + "\n")
