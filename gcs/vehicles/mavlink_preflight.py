"""The preflight of a MAVLink vehicle session, step by step (each a refusal with its reason, exit 7).

HEARTBEAT (refused if already armed) -> AUTOPILOT_VERSION (what the firmware is and takes) ->
TIMESYNC round trip (refused if longer than the stale timeout) -> streams requested ->
parameters an earlier flight left changed put back -> the autopilot profile's parameters and
the output adapter -> the vehicle ready: fresh ATTITUDE and LOCAL_POSITION_NED (a firmware
whose EKF is still aligning is waited for up to the ready timeout, its progress said every
5 s) -> battery -> the profile's flight mode, confirmed by HEARTBEAT (never arm in a mode the
vehicle did not report) -> 0.5 s of level idle setpoints -> arm, confirmed by HEARTBEAT
(refusals with a "PreArm:"/"Arm:" reason tried again every second until the ready timeout) ->
the profile's spool-up (ArduCopter: 2 s arming delay + MOT_SPOOL_TIME) at low thrust, so the
mission starts when the motors deliver what it commands.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.errors import PreflightRefused
from gcs.link.mavlink import LinkError
from gcs.vehicles.autopilots import profile_for
from gcs.vehicles.firmware import Firmware

__all__ = ["MavlinkPreflight", "PROGRESS_PERIOD_S", "ARM_RETRY_S"]

#: Vehicle seconds between two progress lines while waiting for the vehicle.
PROGRESS_PERIOD_S = 5.0
#: Vehicle seconds between two arming attempts the vehicle refused (still initialising).
ARM_RETRY_S = 1.0
#: Share of hover thrust sent while the motors spool up on the ground.
SPOOL_THRUST_SHARE = 0.25
#: MAV_RESULTs of an arming refusal worth trying again (TEMPORARILY_REJECTED, FAILED: pre-arm checks).
_RETRY_RESULTS = (mavlink.MAV_RESULT_TEMPORARILY_REJECTED, mavlink.MAV_RESULT_FAILED)
#: EKF_STATUS_REPORT flags: attitude, horizontal position (relative).
_EKF_ATTITUDE, _EKF_POS_HORIZ_REL = 1, 8


class MavlinkPreflight:
    """The preflight of ``session`` (a :class:`gcs.vehicles.mavlink.MavlinkSession`)."""

    def __init__(self, session) -> None:
        self.s = session
        self.link = session.link
        self.config = session.config
        self.telemetry = session.telemetry
        self.profile = session.profile

    def run(self) -> None:
        """Everything before arming, then arm; raises :class:`PreflightRefused` or :class:`LinkError`."""
        link, fc, st = self.link, self.config.flight, self.telemetry.status
        hb = link.wait_heartbeat(on_message=self.s.handle)
        self.s.event("link", f"connected to system {link.target_system} on {link.url} "
                            f"(autopilot {hb.autopilot}, type {hb.type})")
        self.s.check_interrupt()
        if st.armed:
            raise PreflightRefused(f"the vehicle is already armed (mode {st.mode}); gcs fly starts from a "
                                   "disarmed vehicle on the ground")
        self._identify(hb)
        self._timesync(fc.telemetry_stale_s)
        self._request_streams(fc.telemetry_rate_hz)
        self.s.params.recover()
        self.s.configure_output(self.profile.configure(self.s.params, self.s.firmware, self.s.output_kind))
        deadline_ns = self.s.ctx.now_ns() + int(self.s.ready_timeout_s * 1e9)
        self._wait_ready(deadline_ns)
        self._check_battery(fc.min_battery_v)
        # Setpoints stream before arming (0.5 s of idle, level) and, where the autopilot needs an
        # offboard signal to enter the flight mode (PX4), before the mode is asked for too.
        steps = int(round(0.5 / self.s.period_s))
        if self.profile.stream_before_mode:
            self.s.wait(lambda: False, steps * self.s.period_s - 1e-9, thrust_n=0.0, until_interrupt=False)
        self._enter_flight_mode()
        self.s.wait(lambda: False, steps * self.s.period_s - 1e-9, thrust_n=0.0, until_interrupt=False)
        self._arm(max(deadline_ns, self.s.ctx.now_ns() + int(5e9)))
        self._spool_up()

    def _identify(self, hb) -> None:
        """AUTOPILOT_VERSION (MAV_CMD_REQUEST_MESSAGE 148): the firmware, its version and capabilities."""
        tm = self.telemetry
        try:
            self.link.command_long(mavlink.MAV_CMD_REQUEST_MESSAGE, [mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION],
                                   timeout_s=1.0, retries=1, on_message=self.s.handle)
            if tm.autopilot_version is None:
                self.link.wait(lambda m: tm.autopilot_version is not None, 1.0, self.s.handle)
        except LinkError:
            pass  # an autopilot that does not answer: nothing known of its capabilities
        fw = Firmware.from_messages(hb.autopilot, tm.autopilot_version)
        self.s.firmware = fw
        if not self.s.profile_given:
            self.s.use_profile(profile_for(int(hb.autopilot), events=self.s.event_metadata))
            self.profile = self.s.profile
        # Integer parameters bytewise where the autopilot says so (PX4), else C-cast floats.
        self.link.param_bytewise = fw.params_bytewise()
        caps = "capabilities unknown" if fw.capabilities is None else f"capabilities 0x{fw.capabilities:x}"
        self.s.event("link", f"firmware {fw.describe()} ({caps})")

    def _wait_ready(self, deadline_ns: int) -> None:
        """Fresh ATTITUDE and LOCAL_POSITION_NED, the estimator initialised; progress every 5 s of vehicle time."""
        st, ctx, stale_s = self.telemetry.status, self.s.ctx, self.config.flight.telemetry_stale_s
        t0 = ctx.now_ns()
        next_say = [t0 + int(PROGRESS_PERIOD_S * 1e9)]

        def ready() -> bool:
            ok = self.telemetry.fresh(ctx.now_ns(), stale_s) and self.s.estimator.initialised
            if not ok and ctx.now_ns() >= next_say[0]:
                next_say[0] += int(PROGRESS_PERIOD_S * 1e9)
                self.s.event("preflight", f"waiting for the vehicle ({(ctx.now_ns() - t0) / 1e9:.0f} s of "
                                          f"{self.s.ready_timeout_s:g} s): {self._not_ready()}")
            return ok

        if not self.s.wait(ready, max(0.0, (deadline_ns - t0) / 1e9)):
            self.s.check_interrupt()
            raise PreflightRefused(f"the vehicle is not ready after {self.s.ready_timeout_s:g} s "
                                   f"(--ready-timeout): {self._not_ready()}")
        self.s.ready = True
        self._leave_boot_speed()
        if ctx.now_ns() - t0 > 1e9:
            self.s.event("preflight", f"vehicle ready after {(ctx.now_ns() - t0) / 1e9:.1f} s"
                                      + (f" (EKF flags 0x{st.ekf_flags:04x})" if st.ekf_flags is not None else ""))

    def _leave_boot_speed(self) -> None:
        """A firmware SITL we started booted faster than it flies: SIM_SPEEDUP to the flight's speed-up."""
        boot, flight = self.s.boot_speedup, self.s.speedup
        if boot is None or flight is None or boot == flight:
            return
        held = self.link.param_set("SIM_SPEEDUP", flight, on_message=self.s.handle)
        if held != flight:
            raise PreflightRefused(f"the SITL did not take SIM_SPEEDUP = {flight:g} (holds {held:g})")
        clock = self.s.ctx.clock
        if hasattr(clock, "speedup"):
            clock.speedup = flight
        self.s.event("preflight", f"booted at speed-up {boot:g}, flying at {flight:g} (SIM_SPEEDUP)")

    def _not_ready(self) -> str:
        """What is missing, in words."""
        now, stale_s, st = self.s.ctx.now_ns(), self.config.flight.telemetry_stale_s, self.telemetry.status
        missing = [f"{name} {'never received' if age == float('inf') else f'{age:.1f} s old'}"
                   for name in ("ATTITUDE", "LOCAL_POSITION_NED")
                   if (age := self.telemetry.age_s(name, now)) > stale_s]
        if not missing and not self.s.estimator.initialised:
            missing.append("state estimate not initialised")
        if st.ekf_flags is not None:
            f = st.ekf_flags
            ekf = "no attitude" if not f & _EKF_ATTITUDE else (
                "no horizontal position yet" if not f & _EKF_POS_HORIZ_REL else "position ok")
            missing.append(f"EKF flags 0x{f:04x} ({ekf})")
        texts = [t for t in st.statustext if "EKF" in t or "GPS" in t or "PreArm" in t]
        if texts:
            missing.append(f"last said: {texts[-1]!r}")
        return "; ".join(missing) or "waiting"

    def _timesync(self, stale_s: float) -> None:
        self.telemetry.timesync_sent.add(self.link.send_timesync())
        self.link.wait(lambda m: m.get_type() == "TIMESYNC" and self.telemetry.timesync_rtt_ms is not None,
                       1.0, self.s.handle)
        rtt = self.telemetry.timesync_rtt_ms
        if rtt is None:
            self.s.event("warning", "no TIMESYNC reply: link latency unknown")
            return
        self.s.event("link", f"round trip {rtt:.1f} ms (TIMESYNC)")
        if rtt / 1000.0 > stale_s:
            raise PreflightRefused(f"link round trip {rtt:.0f} ms exceeds the telemetry stale timeout "
                                   f"({stale_s * 1000:.0f} ms): telemetry would arrive too late to control "
                                   "(lower the stream rates or raise the baud rate)")

    def _request_streams(self, rate_hz: float) -> None:
        rates = {mavlink.MAVLINK_MSG_ID_ATTITUDE: rate_hz, mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: rate_hz,
                 mavlink.MAVLINK_MSG_ID_SYS_STATUS: 2.0}
        for mid, hz in rates.items():
            res = self.link.set_message_interval(mid, hz, on_message=self.s.handle)
            if res != mavlink.MAV_RESULT_ACCEPTED:
                self.s.event("warning", f"stream {mid} at {hz:g} Hz not accepted (MAV_RESULT {res})")
        # For the readiness report only (not every autopilot has it): not waited for.
        self.s.io.quietly(lambda: self.link.send_message_interval(mavlink.MAVLINK_MSG_ID_EKF_STATUS_REPORT, 1.0))
        # For the log only (the vehicle's global position, for review on a map), 5 Hz: not waited for.
        self.s.io.quietly(lambda: self.link.send_message_interval(mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 5.0))
        # For the log only, as the profile asks (PX4: its rate setpoint): not waited for.
        for mid, hz in getattr(self.profile, "log_streams_hz", {}).items():
            self.s.io.quietly(lambda mid=mid, hz=hz: self.link.send_message_interval(mid, hz))

    def _check_battery(self, min_v: float) -> None:
        st = self.telemetry.status
        if min_v <= 0:
            return
        self.s.wait(lambda: st.battery_voltage_v is not None, 2.0)
        if st.battery_voltage_v is None:
            self.s.event("warning", "no battery voltage reported; battery not checked")
        elif st.battery_voltage_v < min_v:
            raise PreflightRefused(f"battery {st.battery_voltage_v:.2f} V below {min_v:g} V")

    def _enter_flight_mode(self) -> None:
        self.s.check_interrupt()
        p, st = self.profile, self.telemetry.status
        name = p.mode_name(p.flight_mode)
        res = p.request_mode(self.link, p.flight_mode, on_message=self.s.handle)
        if res != mavlink.MAV_RESULT_ACCEPTED:
            raise PreflightRefused(f"mode {name} refused (MAV_RESULT {res})")
        if not self.s.wait(lambda: st.custom_mode == p.flight_mode, 3.0):
            # A mode is trusted only once the vehicle reports it: never arm in another one.
            raise PreflightRefused(f"mode {name} acknowledged but not confirmed: the vehicle reports {st.mode}")

    def _arm(self, deadline_ns: int) -> None:
        """Arm; a refusal of a vehicle still initialising is tried again every second until ``deadline_ns``."""
        ctx, st = self.s.ctx, self.telemetry.status
        said = None
        p = self.profile
        while True:
            self.s.check_interrupt()
            if st.custom_mode != p.flight_mode:
                # Never arm in a mode the vehicle does not report (it may have left it while we waited).
                raise PreflightRefused(f"the vehicle left {p.mode_name(p.flight_mode)} before arming: it reports "
                                       f"{st.mode}")
            self.s.armed_sent = True
            st.statustext.clear()
            st.events.clear()
            res = self.link.arm(True, on_message=self.s.handle)
            if res == mavlink.MAV_RESULT_ACCEPTED:
                break
            # The reason comes as STATUSTEXT (PX4: EVENT), before or just after the acknowledgement.
            self.link.wait(lambda m: m.get_type() in ("STATUSTEXT", "UNKNOWN_410"), 0.5, self.s.handle)
            why = self.profile.arming_refusal(st, res)
            if res not in _RETRY_RESULTS or ctx.now_ns() + int(ARM_RETRY_S * 1e9) > deadline_ns:
                raise PreflightRefused(f"arming refused: {why}" + ("" if res not in _RETRY_RESULTS else
                                       f" (still refused at the ready timeout, {self.s.ready_timeout_s:g} s)"))
            if why != said:
                said = why
                self.s.event("preflight", f"arming refused for now ({why}); trying again every {ARM_RETRY_S:g} s")
            self.s.wait(lambda: False, ARM_RETRY_S, thrust_n=0.0)
        if not self.s.wait(lambda: st.armed, 3.0):
            raise PreflightRefused("the vehicle acknowledged arming but does not report armed")

    def _spool_up(self) -> None:
        """Low thrust, level, until the motors deliver the commanded thrust (the profile says how long)."""
        spool_s = self.profile.spool_up_s(self.s.params, self.s.firmware)
        if spool_s <= 0:
            return
        self.s.event("arming", f"motors spooling up: {spool_s:.1f} s before the mission starts")
        thrust = SPOOL_THRUST_SHARE * self.s.model.hover_thrust_n
        self.s.wait(lambda: not self.telemetry.status.armed, spool_s, thrust_n=thrust, until_interrupt=False)
        if not self.telemetry.status.armed:
            raise PreflightRefused("the vehicle disarmed while its motors spooled up")
