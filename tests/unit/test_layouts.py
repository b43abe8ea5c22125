"""The flat arrays' layouts (common/layouts.py): one declaration gives the offsets the kernels
index with and the views the Python side fills and shares (the fused control step's buffers
are its stages' buffers)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from common.config.scenario import load_scenario
from common.layouts import Layout
from fcu.control import layouts as lay
from fcu.control.core import FlightCore

CASE1 = Path(__file__).resolve().parents[2] / "config" / "scenarios" / "case1_figure8.toml"


def test_offsets_spans_and_views_come_from_one_declaration():
    """Given a layout, then each field's offset is the sum of the sizes before it, its span
    covers its size, and its view writes the array it was taken from."""
    layout = Layout(("a", 3), ("b", 1), ("c", 2))
    assert (layout.at("a"), layout.at("b"), layout.at("c"), layout.size) == (0, 3, 4, 6)
    assert layout.span("c") == slice(4, 6)
    x = np.zeros(6)
    layout.view(x, "c")[:] = (7.0, 8.0)
    layout.view(x, "a")[1] = 5.0
    assert x.tolist() == [0.0, 5.0, 0.0, 0.0, 7.0, 8.0]
    with pytest.raises(ValueError, match="not of this layout"):
        layout.view(np.zeros(5), "a")
    with pytest.raises(KeyError):
        layout.view(x, "d")


def test_the_constants_are_the_declarations_offsets():
    """Given the control step's layouts, then the constants the kernels index with are the
    offsets of their declarations (a field moved in a table moves its constant)."""
    assert (lay.X_P, lay.X_Q, lay.X_V, lay.X_W) == tuple(
        lay.VEHICLE_STATE.at(n) for n in lay.VEHICLE_STATE.names())
    assert (lay.CP_TRACKER, lay.CP_ALLOC, lay.CP_LAG) == tuple(
        lay.CORE_PARAMS.at(n) for n in lay.CORE_PARAMS.names())
    assert (lay.CS_INTEGRAL, lay.CS_TILT, lay.CS_LAG) == tuple(
        lay.CORE_STATE.at(n) for n in lay.CORE_STATE.names())


def test_the_stages_keep_their_arrays_in_the_fused_steps_buffers():
    """Given the flight core, then its tracker's, allocator's and lag compensator's
    parameters and state are views of the fused step's buffers, at their fields: a gain set
    on the tracker is in the buffer the fused kernel reads."""
    scenario = load_scenario(CASE1)
    core = FlightCore(scenario.vehicle, scenario.gains, 500)
    pairs = [(core.tracker.params, lay.CORE_PARAMS, core.params, "tracker"),
             (core.tracker.integral_array, lay.CORE_STATE, core.state, "integral"),
             (core.allocator.params, lay.CORE_PARAMS, core.params, "allocator"),
             (core.allocator.tilt_array, lay.CORE_STATE, core.state, "tilt_rad"),
             (core.compensator.params, lay.CORE_PARAMS, core.params, "compensator"),
             (core.compensator.state, lay.CORE_STATE, core.state, "compensator")]
    for part, layout, buffer, name in pairs:
        assert np.shares_memory(part, buffer), name
        assert part.shape == (layout.span(name).stop - layout.span(name).start,), name
        assert np.array_equal(part, buffer[layout.span(name)]), name
    core.tracker.params[lay.K_P] = 123.0
    assert core.params[lay.CP_TRACKER + lay.K_P] == 123.0
