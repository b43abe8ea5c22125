"""`gcs view`: a live 3D view of the vehicle over the Foxglove WebSocket protocol.

Serves on 127.0.0.1 only, to Foxglove or Lichtblick ("Open connection", Foxglove WebSocket,
ws://127.0.0.1:8765), from one of two sources:

- live (`gcs view [--connect URL]`): the vehicle's standard MAVLink telemetry through a
  `Session`: LOCAL_POSITION_NED + ATTITUDE_QUATERNION (pose), POSITION_TARGET_LOCAL_NED +
  ATTITUDE_TARGET (desired pose), ACTUATOR_OUTPUT_STATUS (actuator[0..5] rotor speeds rad/s,
  actuator[6..11] tilts rad, as this project's FCU reports them), HEARTBEAT (mode, armed);
- replay (`gcs view RUN_DIR [--speed X]`): the run folder's ULog logs, `truth.ulg` (topic
  `dq_truth`: pose, rotor speeds and tilts as they physically were) and `onboard.ulg` (topic
  `dq_onboard`: desired pose, armed flag), on the simulated timeline at X times real time
  (0: as fast as possible, then exit: with `--mcap` this converts a run to MCAP).

Channels (topic, schema, rate in its channel's metadata as `rate_hz`):

| topic | schema | rate |
|---|---|---|
| `/tf` | foxglove.FrameTransforms | 20 Hz |
| `/vehicle/state` | JSON, dqflight.VehicleState | 10 Hz |
| `/path/flown` | foxglove.SceneUpdate (line strip in `world`) | 5 Hz |
| `/path/desired` | foxglove.SceneUpdate (line strip in `world`) | 5 Hz |
| `/airframe` | foxglove.SceneUpdate (body, arms, rotor disks, desired ghost) | 1 Hz |

Rates are per second of wall time live, and per second of the run's timeline in a replay
(so at `--speed 1` also of wall time). Frames: `world` (ENU) -> `base_link` (FLU, the
vehicle), `world` -> `desired` (the desired pose), `base_link` -> `arm_i` (arm i's mounting
Rz(gamma_i) Ry(beta_i) at r_i, turned about the arm axis x by the tilt alpha_i: its z axis
is the thrust direction cos(alpha) e_v + sin(alpha) e_l of `common.geometry`) and `arm_i` ->
`rotor_i` (the rotor hub, identity: spinning it at a few Hz would only alias). Each transform
is stamped with the vehicle time of the sample it comes from (live: time_boot_ms or
time_usec of its message; replay: the log row's time_us), and every message's log time is
the latest vehicle time, so live and replay share one timeline. Paths keep one point per
0.1 s of vehicle time over the last 60 s.

The wire is NED/FRD; everything published is ENU/FLU, converted by `common.frames` only.
The pure parts (samples, transforms, paths, state) are separate from the I/O (server,
session, clocks) at the end of the module.
"""

from __future__ import annotations

from gcs.view.run import view_live, view_replay
from gcs.view.settings import ViewError

# `gcs view`'s interface (gcs/cli.py); the parts: settings.py (ports, channels, rates,
# schedule), sample.py (the pure model), mavlink_input.py (live telemetry -> sample),
# replay.py (run folder -> samples), scenes.py (Foxglove messages), publisher.py (channels
# and sinks), ws_front.py (the loopback front accepting both names of the WebSocket
# protocol), run.py (the loops).
__all__ = ["ViewError", "view_live", "view_replay"]
