"""The campaign's files, ports and limits."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "config" / "scenarios" / "case1_figure8.toml"
VEHICLE = ROOT / "config" / "vehicles" / "hexa_tilted.toml"
PID = ROOT / "config" / "gains" / "pid_eq30.toml"
PORTS = ("gcs", "sim", "sitl")
CAMPAIGN_PORTS = (*PORTS, "gcs-signed")  # the GCS link again, with MAVLink 2 signing
ERR_POS_LIMIT_M = 0.1
GAP_LIMIT_S = 2.5  # the listening link's HEARTBEAT (1 Hz) may never pause this long
