"""Ground-station actions on a connected vehicle, in standard MAVLink only, so that they work
against PX4 and ArduPilot for the standard parts: status, arming, modes, parameters,
offboard pose setpoints, recording. What differs between autopilots (mode names and
encodings, takeoff, which set-points a pose goto streams, health and readiness) comes from
`gcs.autopilot`, chosen by the vehicle's HEARTBEAT.

Modules: `snapshot` (the latest of each message heard), `status` (gcs status, the names
of modes and landed states, the vehicles on a link), `actions` (arm, mode, takeoff),
`params` (parameters in their real types), `pose` (6-DoF set-points) and `goto`.
"""
