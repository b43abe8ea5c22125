"""A campaign's runs: every grid point times every draw, each validated, with its id."""

from __future__ import annotations

import copy
import hashlib
import json
import math
from dataclasses import dataclass
from itertools import product
from pathlib import Path
from typing import Any

import numpy as np

from common.config.scenario import ConfigError, scenario_from_data
from gcs.campaign.keys import set_key
from gcs.campaign.model import Campaign, CampaignError, Draw

FORMAT = 1  # of the hashed configuration (a change re-flies every run)



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

