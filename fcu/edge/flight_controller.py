"""The flight controller's loop (`fcu`'s process, `fcu.edge.node` its command line): its
clocks, its links and the work beside it.

The work is done by stages without I/O (`fcu.pipeline`); this shell selects over the links
and the work beside the loop (`fcu.work`), feeds the simulator bridge and the ground-station
server, ticks the pipeline and writes the onboard log.

Clocks (docs/clocks.md). Lockstep: each new ODOMETRY is one control period at its own
stamp, answered with HIL_ACTUATOR_CONTROLS; before the flight starts (armed and MISSION,
OFFBOARD, LAND, TAKEOFF, RTL or POSCTL) states are not answered, so simulated time stands
still. A simulator that stops answering is reported ("simulator not responding"), never a
reason to disarm.
Real time: a fixed-rate loop on the monotonic clock (`fcu.edge.deadlines`), integrating with the
measured period (clamped to `MAX_DT_PERIODS`). Heartbeat, telemetry and link timeouts: the
wall clock.
"""

from __future__ import annotations

import json
import os
import select
import time
from pathlib import Path
from typing import Any

from common.links import Link, LinkError, open_link
from common.outcome import Event
from common.wire.mavlink import MAV, encoder, pack
from common.wire.mission_items import HomePosition
from fcu.compose import param_store, published_home
from fcu.edge.deadlines import Deadlines
from fcu.edge.gcs_server import COMPONENT, GcsServer
from fcu.edge.mission_protocol import MissionServer
from fcu.edge.onboard_log import OnboardLog, set_aside
from fcu.edge.run_stats import run_stats
from fcu.edge.sim_bridge import Resent, SimBridge, StateSample
from fcu.edge.telemetry import heartbeat
from fcu.edge.work_process import make_work
from fcu.estimator.ekf import warm as warm_estimator
from fcu.estimator.inputs import ImuInput, PoseInput
from fcu.mission.limits import MissionLimits
from fcu.params import ParamStore, apply_params
from fcu.pipeline import Pipeline
from fcu.warm import warm as warm_plans
from fcu.work import Work

M = MAV
HOUSEKEEPING_S = 0.002
SPIN_S = 0.002  # lockstep: poll this long after each state if it came within SPIN_GAP_S
SPIN_GAP_S = 0.0005  # of the one before (a paced simulator is waited for in select)
SIM_SILENT_S = 1.0  # lockstep: report a simulator silent this long (wall clock)
MAX_DT_PERIODS = 5  # real time: the integrated period is clamped to this many periods
# Per-step stages timed in lockstep flight (`stage_us` in the stats): waiting for the next
# state (housekeeping excluded), reading it, the pipeline's step, sending the answer, the
# onboard log's records, the link-facing housekeeping (telemetry, heartbeats, log writes).
STAGES = ("wait", "rx", "step", "tx", "log", "housekeeping")


class FlightController:
    def __init__(self, pipeline: Pipeline, sim_url: str, gcs_urls: list[str], *,
                 system_id: int, lockstep: bool, home: HomePosition, onboard_log: Path | None,
                 stats_path: Path | None, signing_key: bytes | None = None,
                 rtt_probes: int = 0, params: ParamStore | None = None,
                 work: Work | None = None) -> None:
        """`params`: those `pipeline` was built with (default: the FCU's, put in force);
        `work`: `fcu.work` (default: inline in lockstep, beside the loop in real time)."""
        self.pipeline = pipeline
        self.work = work if work is not None else \
            make_work("inline" if lockstep else "beside", lockstep=lockstep)
        self.system_id = system_id
        self.lockstep = lockstep
        vehicle = pipeline.vehicle
        self.params = params if params is not None else \
            param_store(pipeline, pipeline.core.tracker.gains)
        self.missions = MissionServer(system_id, COMPONENT, pipeline.commander.limits,
                                      home=published_home(home), work=self.work)
        pipeline.commander.work = self.work
        self.missions.on_mission_changed = pipeline.commander.set_mission
        sim = open_link(sim_url, role="sim_client", system_id=system_id)
        try:
            gcs = [open_link(u, role="vehicle", system_id=system_id) for u in gcs_urls]
        except LinkError:
            sim.close()
            raise
        self.sim = SimBridge(sim, system_id, COMPONENT, lockstep=lockstep,
                             w_max=vehicle.rotor_speed_max_rad_s)
        self.server = GcsServer(gcs, pipeline, self.params, self.missions,
                                system_id=system_id, home=home, signing_key=signing_key,
                                on_params=self._apply_params)
        self.missions.on_set_current = lambda seq: (  # accepted, or under way
            self.server.set_mission_current(seq) != M.MAV_RESULT_DENIED)
        self.sim_mav = encoder(system_id, COMPONENT)
        self.log_path, self.home = onboard_log, home
        self.log = self._new_log()
        self.rotate_log = False  # SIGHUP: end the onboard log, start the next
        self.server.on_text = self._log_text
        self.stats_path = stats_path
        self.period_us = pipeline.period_us
        self.running = True
        self.boot_s = time.monotonic()
        self.time_us = 0  # the flight clock: simulated in lockstep, monotonic in real time
        self.input_us = 0.0  # estimator work on inputs since the last control step
        self.steps = 0
        self.deadlines = Deadlines(self.period_us * 1e-6)  # real time: misses
        self.events: list[Event] = []  # everything the pipeline said, on the flight clock
        self.sim_heartbeat_due = 0.0
        self.last_sim_rx_s = time.monotonic()
        self.sim_gap_s = 0.0  # between the last two datagrams of the simulator
        self.sim_silent = False
        # TIMESYNC round trips at the simulator's first word; lockstep only
        self.rtt_probes = rtt_probes if lockstep else 0
        self.rtt: dict[str, Any] | None = None
        self.sim_heard = False
        self.stage_ns = dict.fromkeys(STAGES, 0)
        self.timed_steps = 0
        self.rx_ns = 0  # when the datagram being handled was read
        self.done_ns = 0  # when the last control step's work (answer, log records) was done
        self.work.steps = lambda: self.steps
        warm_plans(pipeline.commander.limits)  # before the loop, not in its first plan
        if not lockstep:  # EKF_EN may turn the estimator on later: making it must not stall
            warm_estimator()
        if not self.work.immediate:  # the worker started and warmed before the flight
            self.work.submit(warm_plans, (pipeline.commander.limits,), lambda _: None,
                             warm_up=True)
        if lockstep:  # offboard loss judged on the flight clock too (fcu.modes.offboard_stream)
            off = pipeline.commander.offboard
            off.flight_clock, off.wall_clock = (lambda: self.time_us * 1e-6), time.monotonic
        self._params_in_force(pipeline.commander.limits)

    def _flush_log(self) -> None:
        """Write the queued records; a log that cannot be written any more (full disk, I/O
        error) is said once and closed, and the vehicle flies on."""
        log = self.log
        if log is None:
            return
        log.flush()
        if log.failed:
            self.log = None
            log.close()
            self.pipeline.commander.say(M.MAV_SEVERITY_WARNING,
                                        f"onboard log stopped: {log.failed}")

    def _new_log(self) -> OnboardLog | None:
        return OnboardLog(self.log_path, self.pipeline, self.params.values,
                          system_id=self.system_id, home=self.home) if self.log_path else None

    def _rotate(self) -> None:
        """SIGHUP (log rotation): the onboard log ends, complete; one still at its path is
        set aside (`set_aside`: name.N.ulg, nothing overwritten); a new one starts there."""
        self.rotate_log = False
        if self.log is None or self.log_path is None:
            return
        self.log.events(self.pipeline.commander.events)  # said so far: in the old one
        self.events.extend(self.pipeline.commander.events)
        self.pipeline.commander.events.clear()
        self.log.close(beside=True)  # its fsync in a thread: the loop flies on meanwhile
        aside = set_aside(self.log_path)
        self.log = self._new_log()
        self.pipeline.commander.say(M.MAV_SEVERITY_INFO, "onboard log: a new file" + (
            f" ({aside.name} kept)" if aside is not None else ""))

    def _log_text(self, severity: int, text: str) -> None:
        if self.log is not None:
            self.log.log(self.time_us, severity, text)  # a STATUSTEXT that is not an event

    # ------------------------------------------------------------------ parameters

    def _apply_params(self) -> None:
        self._params_in_force(apply_params(self.params, self.pipeline))

    def _params_in_force(self, limits: MissionLimits) -> None:
        """What follows the parameters in force: the mission limits, the simulator link's
        inputs (the estimator's or the exact state), the onboard log's copy."""
        self.missions.limits = limits
        self.sim.use_estimator = self.pipeline.estimator is not None
        if self.log is not None:
            self.log.set_params(self.params.values)

    # ------------------------------------------------------------------ simulator link

    def _measure_rtt(self) -> None:
        """The simulator link's round trip (TIMESYNC ping-pong), once, when the simulator
        is first heard: before the flight, both processes otherwise idle."""
        n, self.rtt_probes = self.rtt_probes, 0
        rt = self.sim.round_trips(n)
        self.rtt = rt.summary()
        for peer, data in rt.other:
            self._on_sim_datagram(peer, data)
        self.last_sim_rx_s = time.monotonic()

    def _on_sim_datagram(self, peer: object, data: bytes) -> None:
        self.sim_heard = True
        now = time.monotonic()
        self.sim_gap_s, self.last_sim_rx_s = now - self.last_sim_rx_s, now
        pipe = self.pipeline
        for sample in self.sim.receive(peer, data):
            if not self.lockstep and self.log is not None and \
                    isinstance(sample, ImuInput | StateSample):
                stamp = sample.t_us if isinstance(sample, ImuInput) else sample.stamp_us
                self.log.set_source_clock(stamp, round((self.last_sim_rx_s - self.boot_s) * 1e6))
            if isinstance(sample, PoseInput):
                t0 = time.perf_counter()
                pipe.on_pose(sample)
                self.input_us += (time.perf_counter() - t0) * 1e6
                continue
            if isinstance(sample, Resent) and self.sim.repeat(sample.t_us):
                continue  # answered already: the same answer went again
            if isinstance(sample, ImuInput | Resent):
                if isinstance(sample, ImuInput):
                    t0 = time.perf_counter()
                    pipe.on_imu(sample)
                    self.input_us += (time.perf_counter() - t0) * 1e6
                t_us = sample.t_us
                if self.lockstep and t_us % self.period_us == 0:
                    self.time_us = t_us
                    if pipe.flight_started or pipe.needs_time:
                        self._control_step(t_us, self.period_us * 1e-6)
                continue
            if self.lockstep:
                self.time_us = sample.stamp_us
                rx_us = sample.stamp_us
            else:
                rx_us = round((self.last_sim_rx_s - self.boot_s) * 1e6)
            self.pipeline.on_state(sample.stamp_us, sample.state, rx_us)
            if self.lockstep and self.pipeline.flight_started:
                self._control_step(self.time_us, self.period_us * 1e-6)

    def _control_step(self, t_us: int, dt_s: float) -> None:
        """One control period; its compute time includes the estimator's work on the
        period's inputs (IMU samples and poses), spent as they arrived. The answer goes out
        before the step is logged and the log written (the simulator works meanwhile)."""
        perf = time.perf_counter_ns
        timed = self.lockstep and self.done_ns > 0 and self.pipeline.flight_started
        t0 = perf()
        out = self.pipeline.step(t_us, dt_s)
        t1 = perf()
        step_us = (t1 - t0) * 1e-3 + self.input_us
        self.input_us = 0.0
        self.sim.send(out)
        t2 = perf()
        self.steps += 1
        if self.log is not None:
            self.log.step(out, step_us, t_us)
            self._flush_log()  # in the file when the step returns (the answer went first)
        t3 = perf()
        if timed:
            ns = self.stage_ns
            ns["wait"] += self.rx_ns - self.done_ns
            ns["rx"] += t0 - self.rx_ns
            ns["step"] += t1 - t0
            ns["tx"] += t2 - t1
            ns["log"] += t3 - t2
            self.timed_steps += 1
        self.done_ns = t3 if self.lockstep and self.pipeline.flight_started else 0

    # ------------------------------------------------------------------ housekeeping

    def _housekeeping(self, now: float) -> None:
        pipe = self.pipeline
        c = pipe.commander
        if now >= self.sim_heartbeat_due:
            # Simulators learn where we are from this, as from PX4's first packets.
            self.sim.link.send(pack(self.sim_mav, heartbeat(c.armed, c.mode.custom_mode,
                                                            c.armed)))
            self.sim_heartbeat_due = now + 1.0
        if self.lockstep and pipe.flight_started:
            silent = now - self.last_sim_rx_s > SIM_SILENT_S and not select.select(
                self.sim.link.filenos(), [], [], 0)[0]  # not our own stall: nothing waits
            if silent != self.sim_silent:
                self.sim_silent = silent
                c.say(M.MAV_SEVERITY_WARNING if silent else M.MAV_SEVERITY_INFO,
                      "simulator not responding" if silent else "simulator responding again")
        self.server.time_us = self.time_us
        pipe.check_links(now, self.server.gcs_seen_s)
        if c.events:
            self.server.announce(c.events)
            self.events.extend(c.events)
            if self.log is not None:
                self.log.events(c.events)
            c.events.clear()
        if c.mission_events:
            for ev in c.mission_events:
                if ev.kind == "reached":
                    self.server.send(M.MAVLink_mission_item_reached_message(ev.seq))
            self.server.send_message(M.MAVLINK_MSG_ID_MISSION_CURRENT)  # on change
            c.mission_events.clear()
        self.server.tick(now)
        self._flush_log()  # logged strings and parameter changes
        if self.rotate_log:
            self._rotate()

    # ------------------------------------------------------------------ loop

    def run(self) -> None:
        try:
            self._loop()
        finally:
            self.close()

    def _loop(self) -> None:
        period_s = self.period_us * 1e-6
        next_tick = time.monotonic()
        last_tick = next_tick
        next_housekeeping = next_tick
        sim_link = self.sim.link
        links = [(-1, sim_link), *enumerate(self.server.links[i].link
                                            for i in range(len(self.server.links)))]
        c = self.pipeline.commander
        fast = self.lockstep and sim_link.spin
        while self.running:
            now = time.monotonic()
            if fast and self._state_due(now) and now < next_housekeeping:
                next_housekeeping = self._spin_once(sim_link, next_housekeeping)
                continue
            fds = {fd: entry for entry in links for fd in entry[1].filenos()}
            work_fds = self.work.filenos()  # a result of work beside the loop wakes it
            timeout = self._wait_timeout(now, next_tick, next_housekeeping)
            try:
                readable, _, _ = select.select([*fds, *work_fds], [], [], timeout)
            except InterruptedError:
                continue
            if not readable and timeout == 0.0:
                os.sched_yield()  # polling: let a process that has work run on this core
            self.rx_ns = time.perf_counter_ns()
            if self.work.pending and self.work.take():  # results in, at a step boundary
                next_housekeeping = 0.0  # their answers out at once (real time: after a step)
            self._read_links([fds[fd] for fd in readable if fd in fds])
            if self.rtt_probes and self.sim_heard:
                self._measure_rtt()
            now = time.monotonic()
            stepped = self.lockstep or now >= next_tick
            if not self.lockstep and now >= next_tick:
                next_tick, last_tick = self._real_time_step(now, next_tick, last_tick, period_s)
            if stepped and (now >= next_housekeeping or c.events or c.mission_events):
                # Link-facing work at most every few ms: the lockstep path stays lean; in
                # real time right after a step, the most time before the next one is due.
                self._timed_housekeeping(now)
                next_housekeeping = now + HOUSEKEEPING_S

    def _spin_once(self, sim_link: Link, next_housekeeping: float) -> float:
        """Lockstep, the next state microseconds away: poll the simulator link alone (the GCS
        links wait for the housekeeping); the next housekeeping's time (sooner on events)."""
        if not select.select(sim_link.filenos(), [], [], 0.0)[0]:
            os.sched_yield()  # let a process that has work run on this core
            return next_housekeeping
        self.rx_ns = time.perf_counter_ns()
        for peer, data in sim_link.recv(1):  # one is ready; more: the next turn
            self._on_sim_datagram(peer, data)
        if self.rtt_probes:
            self._measure_rtt()
        c = self.pipeline.commander
        if c.events or c.mission_events:
            self._timed_housekeeping(time.monotonic())
            return time.monotonic() + HOUSEKEEPING_S
        return next_housekeeping

    def _state_due(self, now: float) -> bool:
        """Lockstep: the next state is microseconds away (worth polling for)."""
        return now - self.last_sim_rx_s < SPIN_S and self.sim_gap_s < SPIN_GAP_S

    def _wait_timeout(self, now: float, next_tick: float, next_housekeeping: float) -> float:
        """How long the loop may wait for its links: until telemetry is due with the
        housekeeping (lockstep) or the next tick (real time); 0 to poll for a state due."""
        # telemetry goes out with the housekeeping (real time: after a step), not sooner
        wake = min(max(self.server.next_due(), next_housekeeping), next_housekeeping + 0.05) \
            if self.lockstep else next_tick
        timeout = min(max(0.0, wake - now), 0.05)
        if self.lockstep and self.sim.link.spin and self._state_due(now):
            timeout = 0.0  # lockstep: the next state is microseconds away, poll for it
        return timeout

    def _read_links(self, ready: list[tuple[int, Link]]) -> None:
        """Every datagram of the ready links: the simulator's (index -1) and the GCS's."""
        for index, link in set(ready):
            for peer, data in link.recv():
                if index < 0:
                    self._on_sim_datagram(peer, data)
                else:
                    self.server.on_datagram(index, peer, data, time.monotonic())

    def _real_time_step(self, now: float, next_tick: float, last_tick: float,
                        period_s: float) -> tuple[float, float]:
        """Real time: a control step over the time since the last; the next tick, this one."""
        next_tick = self.deadlines.step(now, next_tick, self.boot_s)
        dt_s = min(max(now - last_tick, 0.0), MAX_DT_PERIODS * period_s) or period_s
        self.time_us = round((now - self.boot_s) * 1e6)
        self._control_step(self.time_us, dt_s)
        return next_tick, now

    def _timed_housekeeping(self, now: float) -> None:
        if not self.done_ns:
            self._housekeeping(now)
            return
        t0 = time.perf_counter_ns()
        self._housekeeping(now)
        spent = time.perf_counter_ns() - t0
        self.stage_ns["housekeeping"] += spent
        self.done_ns += spent  # not waiting meanwhile

    def stats(self) -> dict[str, Any]:
        """What the stats file records at exit (`fcu.edge.run_stats`)."""
        return run_stats(self)

    def close(self) -> None:
        c = self.pipeline.commander
        self.events.extend(c.events)
        if self.log is not None:
            self.log.events(c.events)
        c.events.clear()
        if self.log is not None:
            self.log.close()
            self.log = None
        if self.stats_path is not None:
            tmp = self.stats_path.with_suffix(".tmp")
            tmp.write_text(json.dumps(self.stats(), indent=2) + "\n")
            os.replace(tmp, self.stats_path)
        for link in (self.sim.link, *(gl.link for gl in self.server.links)):
            link.close()
        self.work.close()
