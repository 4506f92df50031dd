"""The preflight of a MAVLink vehicle session, step by step (each a refusal with its reason, exit 7).

HEARTBEAT (refused if already armed) -> TIMESYNC round trip (refused if longer than the
stale timeout) -> streams requested -> the autopilot profile's parameters and the output
adapter -> fresh telemetry -> battery -> the profile's flight mode, confirmed by HEARTBEAT
(never arm in a mode the vehicle did not report) -> 0.5 s of level idle setpoints -> arm,
confirmed by HEARTBEAT.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.errors import PreflightRefused

__all__ = ["MavlinkPreflight"]


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
        self._timesync(fc.telemetry_stale_s)
        self._request_streams(fc.telemetry_rate_hz)
        self.s.configure_output(self.profile.configure(self.s.params))
        if not self.s.wait(lambda: self.telemetry.fresh(self.s.ctx.now_ns(), fc.telemetry_stale_s)
                          and self.s.estimator.initialised, 5.0):
            raise PreflightRefused("no fresh ATTITUDE and LOCAL_POSITION_NED telemetry within 5 s")
        self._check_battery(fc.min_battery_v)
        self._enter_flight_mode()
        # Stream setpoints before arming (0.5 s of idle, level).
        steps = int(round(0.5 / self.s.period_s))
        self.s.wait(lambda: False, steps * self.s.period_s - 1e-9, thrust_n=0.0, until_interrupt=False)
        self._arm()

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

    def _arm(self) -> None:
        self.s.check_interrupt()
        self.s.armed_sent = True
        res = self.link.arm(True, on_message=self.s.handle)
        if res != mavlink.MAV_RESULT_ACCEPTED:
            # The reason comes as STATUSTEXT, before or just after the acknowledgement.
            self.link.wait(lambda m: m.get_type() == "STATUSTEXT", 0.5, self.s.handle)
            raise PreflightRefused(f"arming refused: {self.profile.arming_refusal(self.telemetry.status.statustext, res)}")
        if not self.s.wait(lambda: self.telemetry.status.armed, 3.0):
            raise PreflightRefused("the vehicle acknowledged arming but does not report armed")
