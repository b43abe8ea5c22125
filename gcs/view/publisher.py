"""The view's outputs: the five channels on one Foxglove context (`Publisher`), and the
context's sinks (`Outputs`): the WebSocket server on 127.0.0.1 (behind its front, which
accepts both names of the protocol) and the optional MCAP file."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from common.config.scenario import VehicleConfig
from gcs.view.sample import ViewState, arm_mounts, state_message, transforms
from gcs.view.scenes import airframe_scene, frame_transforms, path_scene
from gcs.view.settings import HOST, RATES_HZ, STATE_SCHEMA, ViewError, due_topics
from gcs.view.ws_front import WebSocketFront

if TYPE_CHECKING:
    import foxglove


class Publisher:
    """The five channels on one Foxglove context (the server and the MCAP writer are its
    sinks); `tick` publishes the channels due at a tick of the BASE_HZ clock."""

    def __init__(self, context: foxglove.Context, vehicle: VehicleConfig, source: str) -> None:
        import foxglove
        from foxglove.channels import FrameTransformsChannel, SceneUpdateChannel

        def meta(topic: str) -> dict[str, str]:
            return {"rate_hz": str(RATES_HZ[topic])}

        self.vehicle = vehicle
        self.mounts = arm_mounts(vehicle)
        self.source = source
        self.tf = FrameTransformsChannel("/tf", metadata=meta("/tf"), context=context)
        self.state = foxglove.Channel("/vehicle/state", schema=STATE_SCHEMA,
                                      metadata=meta("/vehicle/state"), context=context)
        self.flown = SceneUpdateChannel("/path/flown", metadata=meta("/path/flown"),
                                        context=context)
        self.desired = SceneUpdateChannel("/path/desired", metadata=meta("/path/desired"),
                                          context=context)
        self.airframe = SceneUpdateChannel("/airframe", metadata=meta("/airframe"),
                                           context=context)

    def tick(self, view: ViewState, tick: int) -> bool:
        """Publish what is due; nothing before the vehicle's time is known."""
        t_us = view.sample.time_us
        if t_us is None:
            return False
        log_time = t_us * 1000
        for topic in due_topics(tick):
            if topic == "/tf":
                self.tf.log(frame_transforms(transforms(view.sample, self.mounts)),
                            log_time=log_time)
            elif topic == "/vehicle/state":
                self.state.log(state_message(view.sample, self.source), log_time=log_time)
            elif topic == "/path/flown":
                self.flown.log(path_scene("path/flown", view.flown.points(),
                                          (1.0, 0.55, 0.1, 1.0), t_us), log_time=log_time)
            elif topic == "/path/desired":
                self.desired.log(path_scene("path/desired", view.desired.points(),
                                            (0.2, 0.9, 0.3, 0.8), t_us), log_time=log_time)
            elif topic == "/airframe":
                self.airframe.log(airframe_scene(self.vehicle, t_us), log_time=log_time)
        return True


class Outputs:
    """The Foxglove context with its sinks: the WebSocket server on 127.0.0.1 (the SDK's on
    a free port, reached through the front on `port`) and the optional MCAP writer; closed
    (MCAP finalised) by `close`."""

    def __init__(self, port: int, mcap: Path | None) -> None:
        try:
            import foxglove
        except ImportError:
            raise ViewError("needs the foxglove-sdk package (pip install foxglove-sdk)") from None
        if mcap is not None and mcap.exists():
            raise ViewError(f"{mcap} exists; not overwriting a recording")
        self.context = foxglove.Context()
        self.mcap_path = mcap
        # The SDK's server on a free loopback port, behind the front on `port` that also
        # accepts the spec's name of the protocol (gcs/view/ws_front.py).
        try:
            self.server = foxglove.start_server(name="dqflight gcs view", host=HOST, port=0,
                                                context=self.context)
        except (RuntimeError, OSError, ValueError, OverflowError) as exc:
            raise ViewError(f"cannot serve on {HOST}:{port}: "
                            f"{str(exc).removeprefix('FoxgloveError: ')}") from None
        try:
            self.front = WebSocketFront(port, self.server.port)
        except (OSError, OverflowError) as exc:
            self.server.stop()
            why = (f"Failed to bind port: {exc.strerror} (os error {exc.errno})"
                   if isinstance(exc, OSError) and exc.strerror else str(exc))
            raise ViewError(f"cannot serve on {HOST}:{port}: {why}") from None
        self.writer = None
        if mcap is not None:
            try:
                self.writer = foxglove.open_mcap(mcap, context=self.context)
            except OSError as exc:
                self.front.stop()
                self.server.stop()
                raise ViewError(f"{mcap}: {exc.strerror or exc}") from None

    @property
    def url(self) -> str:
        return f"ws://{HOST}:{self.front.port}"

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
            self.writer = None
        self.front.stop()
        self.server.stop()
