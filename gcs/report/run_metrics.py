"""A run's metrics as a typed record: what `gcs.report.metrics.build_metrics` and the runners
write to metrics.json (docs/architecture.md#a-run-folder) and what the reports and the
command line read back (`metrics_from_json`). The keys are the file's keys; a key a kind of
run does not have is absent (total=False below the required ones).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, TypedDict, cast

if TYPE_CHECKING:  # the type only: reading a run folder needs no flight code (nor numba)
    from common.outcome import Event


class ErrorStats(TypedDict):
    """One error's figures over the rows counted (Table I): max, mean and RMS."""

    max: float
    mean: float
    rmse: float


class StepPercentiles(TypedDict):
    p50: float
    p99: float
    max: float


class ErrorRows(TypedDict):
    """Which rows the errors count (`gcs.report.metrics.followed_rows`)."""

    rule: str
    counted: int
    on_ground_reference_below: int


class EventRecord(TypedDict):
    """An event as `common.outcome.Event.as_json` writes it (flight clock, seconds)."""

    t_s: float
    severity: int
    text: str
    kind: str


def event_record(event: Event) -> EventRecord:
    """An event as metrics.json holds it (`Event.as_json`'s keys, in its order)."""
    return {"t_s": event.t_us * 1e-6, "severity": event.severity, "text": event.text,
            "kind": event.kind}


class Overrides(TypedDict):
    controller: str
    ideal_actuators: bool
    duration_s: float


class Tracking(TypedDict):
    """Table I's figures of a run (`gcs.report.metrics.tracking_metrics`)."""

    position_error_m: ErrorStats
    attitude_error_rad: ErrorStats


class Estimation(TypedDict, total=False):
    """Runs with the estimator: its error against the truth."""

    estimation_error: dict[str, ErrorStats]


class LinkTiming(TypedDict, total=False):
    """The lockstep path's timing of a run through processes (`add_link_timing`)."""

    step_wall_us: float | None
    link_rtt_us: float | None
    step_per_rtt: float | None
    udp_rtt_us: float | None
    step_stages_us: dict[str, Any]


class Compile(TypedDict, total=False):
    """Seconds the run's processes spent compiling or loading kernels."""

    compile_time_s: float


class _Required(TypedDict):
    """What every run's metrics hold (`build_metrics`)."""

    scenario: str
    sensors: str
    alignment_s: float
    controller: str
    lockstep: bool
    transport: str
    sim_time_s: float
    wall_time_s: float
    real_time_factor: float
    control_rate_hz: float
    physics_rate_hz: float
    ideal_actuators: bool
    damping: str
    position_error_m: ErrorStats
    attitude_error_rad: ErrorStats
    error_rows: ErrorRows
    fcu_step_us: StepPercentiles
    deadline_misses: int
    saturated_steps: int
    samples: int
    mission_completed: bool
    status: str
    status_reason: str
    divergence_t_s: float | None
    failsafe: str
    events: list[EventRecord]
    seed: int


class RunMetrics(_Required, Estimation, Compile, LinkTiming, total=False):
    """metrics.json: the required figures, then what some runs add."""

    error: str  # why a run could not finish
    system_id: int  # runs through processes: the vehicle's
    fcu_params: dict[str, float]
    start_position_enu_m: list[float]
    fcu: dict[str, Any]  # the FCU process's own stats (fcu_stats.json)
    sitl: dict[str, Any]  # the simulator process's (sitl_stats.json)
    overrides: Overrides
    logs: dict[str, dict[str, Any]]  # each log's size and SHA-256 (`write_metrics`)


class FleetMetrics(TypedDict):
    """fleet.json: a fleet's run, each vehicle's metrics by system id."""

    fleet: int
    spacing_m: float
    transport: str
    scenario: str
    all_completed: bool
    vehicles: dict[str, RunMetrics]


REQUIRED: frozenset[str] = _Required.__required_keys__
_TYPES: dict[str, type | tuple[type, ...]] = {
    "scenario": str, "status": str, "controller": str, "transport": str,
    "sim_time_s": (int, float), "wall_time_s": (int, float), "samples": int,
    "position_error_m": dict, "attitude_error_rad": dict, "events": list,
    "mission_completed": bool, "lockstep": bool,
}


class MetricsError(ValueError):
    """A metrics.json that is not a run's metrics (a key missing or of the wrong type)."""


def metrics_from_json(obj: object) -> RunMetrics:
    """metrics.json's parsed content as the record, checked: every required key present and
    the keys the readers branch on of their type."""
    if not isinstance(obj, dict):
        raise MetricsError(f"not a JSON object but {type(obj).__name__}")
    missing = sorted(REQUIRED - obj.keys())
    if missing:
        raise MetricsError(f"missing {', '.join(missing)}")
    for key, kind in _TYPES.items():
        if not isinstance(obj[key], kind) or (kind is int and isinstance(obj[key], bool)):
            raise MetricsError(f"{key} is {type(obj[key]).__name__}")
    return cast(RunMetrics, obj)
