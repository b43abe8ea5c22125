"""Geodetic positions and the local NED frame around a home point: a local tangent plane
(flat-earth) approximation, ample for the few kilometres a SITL flies. The global-frame
mission items (`common.wire.mission_items`) and the telemetry's GLOBAL_POSITION_INT go
through here."""

from __future__ import annotations

import math

Vec3 = tuple[float, float, float]

EARTH_RADIUS_M = 6_378_137.0


def ned_to_geodetic(p_ned: Vec3, home_lat_deg: float, home_lon_deg: float,
                    home_alt_m: float) -> tuple[float, float, float]:
    """(lat deg, lon deg, alt m AMSL) of a local NED position relative to the home."""
    lat = home_lat_deg + math.degrees(p_ned[0] / EARTH_RADIUS_M)
    lon = home_lon_deg + math.degrees(
        p_ned[1] / (EARTH_RADIUS_M * math.cos(math.radians(home_lat_deg))))
    return lat, lon, home_alt_m - p_ned[2]


def geodetic_to_ned(lat_deg: float, lon_deg: float, alt_m: float, home_lat_deg: float,
                    home_lon_deg: float, home_alt_m: float) -> Vec3:
    """The local NED position (m) of a geodetic point (lat deg, lon deg, alt m AMSL) relative
    to the home: the exact inverse of `ned_to_geodetic` (the same tangent plane), so a
    position taken there and back agrees to float rounding (nanometres at the kilometres a
    SITL flies; tests/unit/test_frames.py)."""
    north = math.radians(lat_deg - home_lat_deg) * EARTH_RADIUS_M
    east = math.radians(lon_deg - home_lon_deg) * (
        EARTH_RADIUS_M * math.cos(math.radians(home_lat_deg)))
    return north, east, home_alt_m - alt_m
