"""The parameter table (fcu/params.py) and the settings dataclasses it sets agree on every
default: a table default is read from its dataclass field, the converters build each
dataclass from the table's defaults as the dataclass's own defaults, and the one deliberate
difference (`DEFAULT_OVERRIDES`) is a real difference, named once."""

from __future__ import annotations

import dataclasses
import math

import pytest

from common.config.scenario import Gains
from fcu.estimator.settings import EstimatorSettings
from fcu.mission.limits import MissionLimits
from fcu.modes.manual import StickSettings
from fcu.modes.settings import FlightSettings
from fcu.params import (
    DAMPING_CODES,
    DEFAULT_OVERRIDES,
    SPECS,
    estimator_settings,
    failsafe_settings,
    field_default,
    flight_settings,
    mission_limits,
)
from fcu.safety.failsafe import FailsafeSettings

DEFAULTS = {s.name: s.default for s in SPECS}
COVERED = (FlightSettings, StickSettings, FailsafeSettings, EstimatorSettings, MissionLimits,
           Gains)


@pytest.mark.parametrize("spec", [s for s in SPECS if s.field], ids=lambda s: s.name)
def test_a_bound_parameter_defaults_to_its_field(spec):
    """Given a parameter that sets a dataclass field, then its default is the field's (or a
    declared override that differs from it)."""
    if spec.name in DEFAULT_OVERRIDES:
        assert spec.default == DEFAULT_OVERRIDES[spec.name][0]
        assert spec.default != field_default(spec.field), "stale override: remove it"
    else:
        assert spec.default == field_default(spec.field)


def test_every_override_names_a_bound_parameter_with_a_reason():
    bound = {s.name for s in SPECS if s.field}
    for name, (_, reason) in DEFAULT_OVERRIDES.items():
        assert name in bound and reason


@pytest.mark.parametrize("cls", COVERED, ids=lambda c: c.__name__)
def test_every_covered_dataclass_has_parameters(cls):
    assert any(s.field.startswith(cls.__name__ + ".") for s in SPECS)


def test_the_table_defaults_build_the_dataclass_defaults():
    """Given the table's defaults, then each converter gives its dataclass's defaults (the
    overrides aside): a parameter wired to the wrong field fails here too."""
    assert failsafe_settings(DEFAULTS) == FailsafeSettings()
    assert flight_settings(DEFAULTS) == FlightSettings()
    assert mission_limits(DEFAULTS) == MissionLimits()
    assert estimator_settings(DEFAULTS, 9.81) is None  # EKF_EN = 0 by default
    overrides = {f: DEFAULT_OVERRIDES[s.name][0] for s in SPECS
                 if s.name in DEFAULT_OVERRIDES and (f := s.field.split(".")[1])}
    expected = dataclasses.replace(EstimatorSettings(), **overrides)
    assert estimator_settings({**DEFAULTS, "EKF_EN": 1.0}, 9.81) == expected


def test_the_gains_come_from_the_configuration():
    """Given the gain parameters, then they have no table default (the vehicle's configuration
    gives them, as Gains has none) and the damping code defaults to Gains' damping."""
    no_default = {f.name for f in dataclasses.fields(Gains)
                  if f.default is dataclasses.MISSING}
    assert no_default == {"kp_r", "kp_d", "ki_r", "ki_d", "kd_r", "kd_d"}
    assert all(math.isnan(s.default) for s in SPECS if s.name.startswith("DQ_K"))
    damping = next(f.default for f in dataclasses.fields(Gains) if f.name == "damping")
    assert DAMPING_CODES[round(DEFAULTS["DQ_DAMPING"])] == damping
