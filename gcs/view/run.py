"""`gcs view`'s two loops and their entry points: live (a Session's telemetry on a wall-clock
tick) and replay (a run folder's logs on the run's timeline)."""

from __future__ import annotations

import math
import signal
import threading
import time
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Any

from common.config.scenario import ConfigError, VehicleConfig, load_vehicle
from common.process.diagnostics import say
from gcs.view.mavlink_input import apply_message
from gcs.view.publisher import Outputs, Publisher
from gcs.view.replay import ReplayLog, load_replay, replay_vehicle_path
from gcs.view.sample import PathBuffer, ViewState
from gcs.view.settings import BASE_HZ, DEFAULT_PORT, DEFAULT_VEHICLE, ViewError, replay_ticks

if TYPE_CHECKING:
    from gcs.vehicle_link.session import Session


class _Stop:
    """SIGINT and SIGTERM set a flag (restored on exit) so that the loops end cleanly."""

    def __init__(self) -> None:
        self.event = threading.Event()
        self._old: dict[int, Any] = {}

    def __enter__(self) -> threading.Event:
        def handler(signum: int, frame: FrameType | None) -> None:
            self.event.set()

        for sig in (signal.SIGINT, signal.SIGTERM):
            self._old[sig] = signal.signal(sig, handler)
        return self.event

    def __exit__(self, *exc: object) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)


def _load_geometry(path: Path | None) -> VehicleConfig:
    try:
        return load_vehicle(path or DEFAULT_VEHICLE)
    except ConfigError as exc:
        raise ViewError(str(exc)) from None



def _announce(outputs: Outputs) -> None:
    say(f"gcs view: {outputs.url}")
    say("gcs view: open it in Foxglove or Lichtblick (Open connection > Foxglove WebSocket); "
        "display frame: world")
    if outputs.mcap_path is not None:
        say(f"gcs view: recording to {outputs.mcap_path}")


def run_live(session: Session, publisher: Publisher, stop: threading.Event,
             duration_s: float | None = None) -> None:
    """Take the vehicle's messages and publish on a wall-clock tick of BASE_HZ until `stop`
    (or `duration_s`); a late tick never makes a burst."""
    view = ViewState()
    period = 1.0 / BASE_HZ
    start = time.monotonic()
    next_tick = start
    tick = 0
    while not stop.is_set():
        now = time.monotonic()
        if duration_s is not None and now - start >= duration_s:
            return
        if now >= next_tick:
            if publisher.tick(view, tick):
                tick += 1
            next_tick = max(next_tick + period, now)
            continue
        msg = session.recv(None, timeout=min(0.05, next_tick - now))
        if not session.from_autopilot(msg):  # none, bad data, or another component's
            continue
        t_before = view.sample.time_us
        if apply_message(view.sample, msg):
            t_after = view.sample.time_us
            if t_before is not None and t_after is not None and t_after < t_before:
                view.flown, view.desired = PathBuffer(), PathBuffer()  # a new flight
            view.update_paths()


def run_replay(log: ReplayLog, publisher: Publisher, speed: float,
               stop: threading.Event) -> bool:
    """Publish the log on its timeline at `speed` x real time (0: at once); False if
    stopped before the end."""
    first, last = log.span_us
    view = ViewState()
    wall0 = time.monotonic()
    for tick, t_us in enumerate(replay_ticks(first, last)):
        if speed > 0.0:
            delay = wall0 + (t_us - first) * 1e-6 / speed - time.monotonic()
            if delay > 0.0 and stop.wait(delay):
                return False
        if stop.is_set():
            return False
        view.sample = log.sample_at(t_us)
        view.update_paths()
        publisher.tick(view, tick)
    return True


def _wait_vehicle(session: Session, timeout: float, system_id: int | None,
                  stop: threading.Event) -> bool:
    """Session.wait_vehicle in short slices, so that Ctrl-C ends the wait at once."""
    from gcs.vehicle_link.session import GcsError

    deadline = time.monotonic() + timeout
    while not stop.is_set():
        try:
            session.wait_vehicle(timeout=min(0.5, max(0.05, deadline - time.monotonic())),
                                 system_id=system_id)
            return True
        except GcsError:
            if time.monotonic() >= deadline:
                raise GcsError(f"no vehicle heartbeat within {timeout:g} s") from None
    return False


def view_live(connect: str, *, port: int = DEFAULT_PORT, mcap: Path | None = None,
              vehicle_file: Path | None = None, system_id: int | None = None,
              wait_s: float = 10.0, signing_key: bytes | None = None,
              duration_s: float | None = None) -> int:
    """`gcs view [--connect URL]`: serve the vehicle's telemetry until Ctrl-C or SIGTERM.
    Raises ViewError (bad input), LinkError (bad URL), GcsError (no vehicle)."""
    from gcs.vehicle_link.session import Session

    vehicle = _load_geometry(vehicle_file)
    outputs = Outputs(port, mcap)
    try:
        with _Stop() as stop:
            publisher = Publisher(outputs.context, vehicle, "live")
            try:
                session = Session(connect, vehicle=system_id or 0, signing_key=signing_key)
            except OSError as exc:  # e.g. a host name that does not resolve
                raise ViewError(f"cannot open {connect}: {exc.strerror or exc}") from None
            try:
                _announce(outputs)
                if _wait_vehicle(session, wait_s, system_id, stop):
                    say(f"gcs view: vehicle {session.target_system} on {connect}")
                    run_live(session, publisher, stop, duration_s)
            finally:
                session.close()
    finally:
        outputs.close()
    if mcap is not None:
        say(f"gcs view: wrote {mcap}")
    return 0


def view_replay(run_dir: Path, *, port: int = DEFAULT_PORT, mcap: Path | None = None,
                speed: float = 1.0, vehicle_file: Path | None = None) -> int:
    """`gcs view RUN_DIR`: replay the run's logs at `speed` x real time, then exit."""
    if not (speed >= 0.0 and math.isfinite(speed)):
        raise ViewError(f"--speed must be a finite number >= 0, got {speed}")
    log = load_replay(run_dir)
    vehicle = _load_geometry(vehicle_file or replay_vehicle_path(run_dir))
    outputs = Outputs(port, mcap)
    try:
        with _Stop() as stop:
            publisher = Publisher(outputs.context, vehicle, "replay")
            _announce(outputs)
            finished = run_replay(log, publisher, speed, stop)
    finally:
        outputs.close()
    first, last = log.span_us
    say(f"gcs view: replayed {(last - first) * 1e-6:.2f} s of {run_dir}"
        + ("" if finished else " (stopped)"))
    if mcap is not None:
        say(f"gcs view: wrote {mcap}")
    return 0
