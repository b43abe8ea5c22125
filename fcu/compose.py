"""The FCU composed: its pipeline with the parameters in force, a mission taken as the mission
protocol takes it, arming and the mission's start.

The FCU process (`fcu.edge.node`) and the in-process runner (`gcs.run.inprocess`) build the vehicle
here, so both fly the same pipeline with the same parameters; the process then takes
missions and commands from its links, the in-process runner through `accept_mission` and
`arm_and_start`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from common.config.scenario import Gains, VehicleConfig
from common.wire.mission_items import HomePosition, MissionItem
from fcu.mission.validation import check_mission, localize, refusal
from fcu.params import ParamStore, apply_params
from fcu.pipeline import Pipeline


def param_store(pipeline: Pipeline, gains: Gains,
                params: Mapping[str, float] | None = None) -> ParamStore:
    """The FCU's parameters (defaults and `gains`, then `params` set in their order; a value
    the FCU refuses raises fcu.params.ParamError), put in force in `pipeline`."""
    store = ParamStore(gains)
    for name, value in (params or {}).items():
        store.set(name, value)
    apply_params(store, pipeline)
    return store


def fcu_pipeline(vehicle: VehicleConfig, gains: Gains, control_rate_hz: int,
                 params: Mapping[str, float] | None = None) -> tuple[Pipeline, ParamStore]:
    """The FCU's pipeline with its parameters in force (`param_store`)."""
    pipeline = Pipeline(vehicle, gains, control_rate_hz)
    return pipeline, param_store(pipeline, gains, params)


def published_home(home: HomePosition) -> HomePosition:
    """The home global-frame mission items are converted through, as HOME_POSITION
    publishes it."""
    return HomePosition.published(home.lat_deg, home.lon_deg, home.alt_m)


def accept_mission(pipeline: Pipeline, items: Sequence[MissionItem],
                   home: HomePosition) -> str:
    """Take a whole mission as the mission protocol does once its last item arrived:
    validated against the limits in force (`check_mission`), then flown as its local
    equivalent. Returns why it is refused, as the mission protocol says it (the result by
    name, the item and the reason: "MAV_MISSION_UNSUPPORTED: item 2: command 177 is not
    supported"), "" if taken."""
    check = check_mission(items, pipeline.commander.limits, home)
    if refusal(check):
        return refusal(check)
    pipeline.commander.set_mission(localize(items, home))
    return ""


def arm_and_start(pipeline: Pipeline, first_item: int = 0) -> str:
    """Arm, then start the mission at `first_item` (MAV_CMD_COMPONENT_ARM_DISARM,
    MAV_CMD_MISSION_START); returns why one is refused (the vehicle's words: "arming
    refused: ..."), "" if both are accepted."""
    code, text = pipeline.arm()
    if code != 0:
        return text
    code, text = pipeline.commander.mission_start(first_item)
    return f"mission start refused: {text}" if code != 0 else ""
