"""The FCU's run statistics, as `fcu --stats FILE` writes them at exit: counts of what the
links and the pipeline saw, the per-step stage times, the events (JSON)."""

from __future__ import annotations

from typing import Any, Protocol

from common.outcome import Event
from common.process.startup import compile_time_s
from fcu.edge.deadlines import Deadlines
from fcu.edge.gcs_server import GcsServer
from fcu.edge.sim_bridge import SimBridge
from fcu.pipeline import Pipeline
from fcu.work import Work


class Run(Protocol):
    """What the statistics read of the FCU's process
    (`fcu.edge.flight_controller.FlightController`)."""

    pipeline: Pipeline
    server: GcsServer
    sim: SimBridge
    deadlines: Deadlines
    work: Work
    lockstep: bool
    steps: int
    timed_steps: int
    stage_ns: dict[str, int]
    rtt: dict[str, Any] | None
    events: list[Event]


def run_stats(fc: Run) -> dict[str, Any]:
    """The statistics of `fc`'s run so far."""
    pipe, server, sim = fc.pipeline, fc.server, fc.sim
    return {"steps": fc.steps, "deadline_misses": fc.deadlines.misses,
            "misses": fc.deadlines.first,
            "compile_time_s": compile_time_s(),
            "signing_rejects": server.signing_rejects,
            "resent_answers": sim.resent_answers,
            "repeated_commands": server.repeated_commands,
            "flight_start_us": pipe.flight_start_us,
            "rejected_bytes": server.rejected_bytes + sim.rejected_bytes,
            "ignored_messages": server.ignored_messages + sim.ignored_messages,
            "internal_errors": server.internal_errors,
            "mission_completed": pipe.commander.mission_done,
            "saturated_steps": pipe.saturated_steps,
            "tilt_rate_limited_steps": pipe.tilt_rate_limited_steps,
            "lockstep": fc.lockstep,
            "sim_rtt": fc.rtt,
            "work": {**fc.work.stats(),
                     "late_anchors": pipe.commander.modes.ahead.late_anchors,
                     "inline_plans": pipe.commander.modes.ahead.inline_plans},
            "timed_steps": fc.timed_steps,
            "stage_us": {k: v / max(fc.timed_steps, 1) * 1e-3
                         for k, v in fc.stage_ns.items()},
            "events": [e.as_json() for e in fc.events]}

