"""Shared fixtures for closed-loop runs of the FCU core over the independent plant."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from common.config.scenario import Scenario, load_scenario

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "config" / "scenarios"


def scenario(name: str, **changes) -> Scenario:
    return dataclasses.replace(load_scenario(SCENARIOS / f"{name}.toml"), **changes)


@pytest.fixture
def hover_ideal() -> Scenario:
    """Airborne at the origin, ground off, no disturbance, ideal actuators."""
    return scenario("case2_impulse", force_terms=(), torque_terms=(), ideal_actuators=True)
