"""The run folder: scenario as run, metrics.json, the plant's truth log, the onboard log."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from common.config import Scenario
from gcs.inprocess import ONBOARD_COLUMNS, TRUTH_COLUMNS, RunResult


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
    (out / "metrics.json").write_text(json.dumps(_finite(metrics), indent=2,
                                                 allow_nan=False) + "\n")
    np.savez_compressed(out / "truth_log.npz", columns=np.array(TRUTH_COLUMNS),
                        data=result.truth)
    np.savez_compressed(out / "onboard_log.npz", columns=np.array(ONBOARD_COLUMNS),
                        data=result.onboard)


def read_log(path: Path) -> dict[str, np.ndarray]:
    """A log as {column: array}."""
    with np.load(path) as z:
        return {str(c): z["data"][:, i] for i, c in enumerate(z["columns"])}
