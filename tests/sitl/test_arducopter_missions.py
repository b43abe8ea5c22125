"""Missions and parameters against a real ArduCopter SITL with its own physics (`--model
hexa`, speedup 10), inside a private network namespace (tests/arducopter.py).

`gcs` talks on ArduCopter's default link, TCP 5760; the independent pymavlink observer of
tests/sitl/test_arducopter_gcs.py records on TCP 5762 what the vehicle really does
(HEARTBEAT armed, GLOBAL_POSITION_INT relative_alt, LOCAL_POSITION_NED), so that the flight
is judged from the vehicle, not from the CLI. One ArduCopter serves the whole module.
"""

from __future__ import annotations

import json
import math
import sys
import time

import pytest

from common.geodetic import ned_to_geodetic
from common.wire.mav_enums import MAV_CMD
from gcs.mission_files.param_files import parse_params
from tests.arducopter import ROOT, namespace, needs_arducopter, start_arducopter, wait_port
from tests.sitl.test_arducopter_gcs import Copter

pytestmark = [needs_arducopter, pytest.mark.xdist_group("arducopter")]

GCS_PORT, OBSERVER_PORT = 5760, 5762
CONNECT = ("--connect", f"tcp:127.0.0.1:{GCS_PORT}")
HOME = (-35.3632621, 149.1652374)  # where ArduPilot's SITL starts (its default location)
ALT_M = 10.0
# north, east of the three waypoints (m from home), flown at ALT_M above home
LEGS_M = ((15.0, 0.0), (15.0, 15.0), (0.0, 15.0))
WP_RADIUS_M = 2.0  # ArduCopter's WPNAV_RADIUS: a waypoint within it is reached
RTL_ALT_M = 15.0  # ArduCopter's RTL_ALT: RTL climbs to it before it returns
MAV_CMD_NAV_TAKEOFF = MAV_CMD.MAV_CMD_NAV_TAKEOFF
MAV_CMD_NAV_WAYPOINT = MAV_CMD.MAV_CMD_NAV_WAYPOINT
MAV_CMD_NAV_RETURN_TO_LAUNCH = MAV_CMD.MAV_CMD_NAV_RETURN_TO_LAUNCH
INT8, INT16, INT32, REAL32 = 2, 4, 6, 9


def qgc_plan() -> dict:
    """A plan as QGroundControl saves it for ArduCopter: takeoff, 3 waypoints, RTL."""
    def item(n: int, command: int, north: float = 0.0, east: float = 0.0) -> dict:
        lat, lon, _ = ned_to_geodetic((north, east, -ALT_M), HOME[0], HOME[1], 0.0)
        return {"AMSLAltAboveTerrain": None, "Altitude": ALT_M, "AltitudeMode": 1,
                "autoContinue": True, "command": command, "doJumpId": n, "frame": 3,
                "params": [0, 0, 0, None, round(lat, 7), round(lon, 7), ALT_M],
                "type": "SimpleItem"}
    items = [item(1, MAV_CMD_NAV_TAKEOFF, 0.0, 0.0),
             *(item(n + 2, MAV_CMD_NAV_WAYPOINT, north, east)
               for n, (north, east) in enumerate(LEGS_M)),
             {"autoContinue": True, "command": MAV_CMD_NAV_RETURN_TO_LAUNCH, "doJumpId": 5,
              "frame": 2, "params": [0, 0, 0, 0, 0, 0, 0], "type": "SimpleItem"}]
    return {"fileType": "Plan", "geoFence": {"circles": [], "polygons": [], "version": 2},
            "groundStation": "QGroundControl",
            "mission": {"cruiseSpeed": 15, "firmwareType": 3, "globalPlanAltitudeMode": 1,
                        "hoverSpeed": 5, "items": items,
                        "plannedHomePosition": [HOME[0], HOME[1], 584], "vehicleType": 2,
                        "version": 2},
            "rallyPoints": {"points": [], "version": 2}, "version": 1}


@pytest.fixture(scope="module")
def copter(tmp_path_factory):
    work = tmp_path_factory.mktemp("arducopter_missions")
    # a vehicle armed on the ground disarms after DISARM_DELAY s of its time: at speedup 10
    # the default 10 s is 1 s of ours, less than the next gcs takes to start
    slower_disarm = work / "disarm.parm"
    slower_disarm.write_text("DISARM_DELAY 60\n")
    with namespace() as ns:
        start_arducopter(ns, work, model="hexa", speedup=10, defaults=[slower_disarm])
        wait_port(ns, GCS_PORT)
        copter = Copter(ns, work / "observer.jsonl")
        first = ns.gcs("status", *CONNECT, timeout=60)  # ArduCopter starts once 5760 connects
        assert first.returncode == 0, first.stderr
        wait_port(ns, OBSERVER_PORT)
        ns.popen([sys.executable, "-c", "import sys; from tests.sitl.test_arducopter_gcs "
                  "import observe; observe(int(sys.argv[1]), sys.argv[2])",
                  str(OBSERVER_PORT), str(copter.log)], cwd=ROOT)
        deadline = time.monotonic() + 30
        while not copter.log.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        copter.wait_for("SYS_STATUS", lambda r: r["prearm"], 60.0)  # ready to arm
        yield copter


@pytest.mark.timeout(60)
def test_parameters_keep_their_types_and_a_clamp_is_not_taken(copter, tmp_path):
    """param save writes ArduCopter's real types (DISARM_DELAY INT8 2, MAV_SYSID INT16 4,
    LOG_BITMASK INT32 6, ATC_RAT_RLL_P REAL32 9); param set DISARM_DELAY 300 is exit 1
    "not taken: the vehicle keeps 127"; a .params file with integer and float parameters
    loads back exactly."""
    saved = tmp_path / "copter.params"
    out = copter.gcs("param", "save", str(saved))
    assert out.returncode == 0, out.stdout + out.stderr
    entries = {e.name: e for e in parse_params(saved.read_text())}
    assert len(entries) > 1000
    types = {name: entries[name].param_type for name in
             ("DISARM_DELAY", "MAV_SYSID", "LOG_BITMASK", "ATC_RAT_RLL_P", "FRAME_CLASS")}
    assert types == {"DISARM_DELAY": INT8, "MAV_SYSID": INT16, "LOG_BITMASK": INT32,
                     "ATC_RAT_RLL_P": REAL32, "FRAME_CLASS": INT8}
    assert {e.param_type for e in entries.values()} >= {INT8, INT16, INT32, REAL32}
    assert entries["DISARM_DELAY"].value == 60.0 and entries["FRAME_CLASS"].value == 2.0
    clamped = copter.gcs("param", "set", "DISARM_DELAY", "300")
    assert clamped.returncode == 1, clamped.stdout + clamped.stderr
    assert "not taken: the vehicle keeps 127" in clamped.stdout, clamped.stdout
    assert copter.gcs("param", "get", "DISARM_DELAY").stdout.strip() == "DISARM_DELAY = 127"
    bitmask = int(entries["LOG_BITMASK"].value)
    subset = tmp_path / "subset.params"
    subset.write_text("".join(
        f"1\t1\t{name}\t{value}\t{ptype}\n" for name, value, ptype in (
            ("DISARM_DELAY", "60", INT8), ("LOG_BITMASK", str(bitmask ^ 1), INT32),
            ("ATC_RAT_RLL_P", "0.125", REAL32))))
    loaded = copter.gcs("param", "load", str(subset))
    assert loaded.returncode == 0 and "loaded 3 of 3" in loaded.stdout, loaded.stdout
    assert copter.gcs("param", "get", "LOG_BITMASK").stdout.strip() == \
        f"LOG_BITMASK = {bitmask ^ 1}"
    assert copter.gcs("param", "get", "ATC_RAT_RLL_P").stdout.strip() == \
        "ATC_RAT_RLL_P = 0.125"
    for name, value in (("LOG_BITMASK", str(bitmask)),
                        ("ATC_RAT_RLL_P", repr(entries["ATC_RAT_RLL_P"].value))):
        assert copter.gcs("param", "set", name, value).returncode == 0
    assert copter.gcs("param", "get", "DISARM_DELAY").stdout.strip() == "DISARM_DELAY = 60"


@pytest.mark.timeout(60)
def test_plan_uploads_with_every_item_and_home(copter, tmp_path):
    """A 5-item QGC plan (takeoff, 3 waypoints, RTL) uploads to ArduCopter with home at seq
    0: the download has all 5 after home, plannedHomePosition the vehicle's home and
    firmwareType 3; as WPL, home is line 0 and the 5 items follow."""
    plan = tmp_path / "square.plan"
    plan.write_text(json.dumps(qgc_plan(), indent=4))
    up = copter.gcs("mission", "upload", str(plan))
    assert up.returncode == 0, up.stdout + up.stderr
    assert "upload of 5 items: MAV_MISSION_ACCEPTED" in up.stdout, up.stdout
    back = tmp_path / "back.plan"
    down = copter.gcs("mission", "download", str(back))
    assert down.returncode == 0 and "downloaded 5 items" in down.stdout, down.stdout
    mission = json.loads(back.read_text())["mission"]
    assert mission["firmwareType"] == 3
    lat, lon, alt = mission["plannedHomePosition"]
    assert (lat, lon) == pytest.approx(HOME, abs=2e-6) and 580 < alt < 590
    assert [it["command"] for it in mission["items"]] == [
        MAV_CMD_NAV_TAKEOFF, MAV_CMD_NAV_WAYPOINT, MAV_CMD_NAV_WAYPOINT, MAV_CMD_NAV_WAYPOINT,
        MAV_CMD_NAV_RETURN_TO_LAUNCH]
    sent = qgc_plan()["mission"]["items"]
    for got, want in zip(mission["items"][1:4], sent[1:4], strict=True):
        assert got["params"][4:7] == pytest.approx(want["params"][4:7], abs=1e-6)
    wpl = copter.gcs("mission", "download", "--format", "wpl")
    lines = [line.split("\t") for line in wpl.stdout.splitlines()[1:]]
    assert [int(f[0]) for f in lines] == [0, 1, 2, 3, 4, 5]
    assert lines[0][2:4] == ["0", "16"]  # home: NAV_WAYPOINT, MAV_FRAME_GLOBAL (AMSL)
    assert [int(f[3]) for f in lines[1:]] == [22, 16, 16, 16, 20]


@pytest.mark.timeout(90)
def test_the_mission_flies_and_lands(copter, tmp_path):
    """gcs arm, then gcs mission start: ArduCopter flies the uploaded plan in AUTO (climbs
    to 10 m, passes each waypoint 15 m out within its radius), returns and lands, and
    disarms."""
    plan = tmp_path / "square.plan"
    plan.write_text(json.dumps(qgc_plan()))
    assert copter.gcs("mission", "upload", str(plan)).returncode == 0
    t0 = time.time()
    armed = copter.gcs("arm")
    assert armed.returncode == 0, armed.stdout + armed.stderr
    start = copter.gcs("mission", "start")
    assert start.returncode == 0, start.stdout + start.stderr
    top = copter.wait_for("GLOBAL_POSITION_INT", lambda r: r["rel"] > ALT_M - 0.5, 30.0, t0)
    disarmed = copter.wait_for("HEARTBEAT", lambda r: not r["armed"], 60.0, top["t"])
    track = copter.records("LOCAL_POSITION_NED", top["t"])
    nearest = [min(track, key=lambda r, n=n, e=e: math.hypot(r["x"] - n, r["y"] - e))
               for n, e in LEGS_M]
    misses = [math.hypot(r["x"] - n, r["y"] - e) for r, (n, e) in zip(nearest, LEGS_M,
                                                                      strict=True)]
    assert max(misses) < WP_RADIUS_M, misses  # each waypoint reached, at its altitude
    assert [-r["z"] for r in nearest] == pytest.approx([ALT_M] * 3, abs=1.0), nearest

    def last_before(kind: str) -> dict:
        return [r for r in copter.records(kind, top["t"]) if r["t"] <= disarmed["t"]][-1]

    assert abs(last_before("GLOBAL_POSITION_INT")["rel"]) < 0.5  # on the ground
    where = last_before("LOCAL_POSITION_NED")
    assert math.hypot(where["x"], where["y"]) < 2.0, where  # back home (RTL)
    peak = max(r["rel"] for r in copter.records("GLOBAL_POSITION_INT", t0))
    assert peak < RTL_ALT_M + 1.5, peak  # RTL climbs to RTL_ALT first


@pytest.mark.timeout(90)
def test_a_refused_upload_leaves_the_mission_the_vehicle_had(copter, tmp_path):
    """Given ArduCopter holding the 5-item plan, when a 6-item WPL whose item 3 is a command
    ArduCopter has no mission item for (MAV_CMD_MISSION_START, 300: refused with
    MAV_MISSION_UNSUPPORTED, items 1-2 already written over its old mission) is uploaded,
    then the CLI says the
    vehicle refused it and that it put the old mission back, exit 1, and the vehicle holds
    the 5-item plan again, item for item."""
    plan = tmp_path / "square.plan"
    plan.write_text(json.dumps(qgc_plan(), indent=4))
    assert copter.gcs("mission", "upload", str(plan)).returncode == 0
    before = copter.gcs("mission", "download", "--format", "wpl")
    assert before.returncode == 0, before.stderr
    lines = before.stdout.splitlines()
    header, home, items = lines[0], lines[1], lines[2:]
    odd = items[1].split("\t")
    odd[3] = "300"  # MAV_CMD_MISSION_START: a command, not a mission item
    bad = [header, home, items[0], items[1], "\t".join(odd), *items[2:]]
    bad = [bad[0]] + [f"{n}\t" + line.split("\t", 1)[1] for n, line in enumerate(bad[1:])]
    wpl = tmp_path / "bad.waypoints"
    wpl.write_text("\n".join(bad) + "\n")
    up = copter.gcs("mission", "upload", str(wpl))
    assert up.returncode == 1, up.stdout + up.stderr
    said = up.stdout + up.stderr
    assert "refused" in said and "restored the" in said, said
    after = copter.gcs("mission", "download", "--format", "wpl")
    assert after.returncode == 0, after.stderr
    assert after.stdout.splitlines()[2:] == items  # the plan's 5 items, as before
