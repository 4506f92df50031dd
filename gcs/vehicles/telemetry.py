"""Telemetry decoding: MAVLink messages into the estimator (paper frame) and the vehicle status.

Conversions go through :mod:`quadrotor.frames` only: LOCAL_POSITION_NED becomes
(x, y, z up) and (vx, vy, vz up); ATTITUDE's body rates become Euler-angle
rates.  The vehicle's own time (``time_boot_ms``) is tracked: it is the clock of a
lockstep or paced flight.  Freshness is kept per stream twice: by arrival on the loop's clock,
and by the sample's own time stamp on the vehicle's clock (:class:`~gcs.vehicles.time_map.VehicleTimeMap`,
which tracks the vehicle clock's rate and offset), so that
old samples delivered late (a link or a ground station that stalled, a radio that buffered)
count as old.  EKF_STATUS_REPORT flags are kept for the readiness report, EXTENDED_SYS_STATE's
landed state and PX4's EVENTs (arming refusals) for the profile.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field
from collections.abc import Callable

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.estimate import StateEstimator
from gcs.flight.validate import TelemetryValidator
from gcs.vehicles.px4_events import parse_event
from gcs.vehicles.px4_modes import px4_mode_name
from gcs.vehicles.time_map import VehicleTimeMap
from quadrotor.mavlink.modes import copter_mode_name
from quadrotor.frames import body_rates_to_euler_rates, ned_to_paper_position, ned_to_paper_velocity

__all__ = ["VehicleStatus", "Telemetry", "VehicleTimeMap"]

_LANDED = {0: "landed state unknown", 1: "on the ground", 2: "in the air", 3: "taking off", 4: "landing"}

@dataclass
class VehicleStatus:
    """What the vehicle last said about itself."""

    armed: bool = False
    custom_mode: int = -1
    system_status: int = 0
    battery_voltage_v: float | None = None
    battery_remaining_pct: int | None = None
    time_boot_ms: int = 0
    #: EKF_STATUS_REPORT flags (None: never reported).
    ekf_flags: int | None = None
    statustext: deque = field(default_factory=lambda: deque(maxlen=64))
    #: PX4 EVENTs (:class:`~gcs.vehicles.px4_events.Px4Event`), newest last.
    events: deque = field(default_factory=lambda: deque(maxlen=16))
    #: EXTENDED_SYS_STATE landed_state (MAV_LANDED_STATE: 1 on ground, 2 in air, 3 taking off, 4 landing;
    #: None: never reported).
    landed_state: int | None = None
    #: custom_mode -> the mode's name (the autopilot profile's).
    mode_name: Callable[[int], str] = field(default=copter_mode_name, repr=False)

    @property
    def mode(self) -> str:
        return self.mode_name(self.custom_mode)


class Telemetry:
    """Feeds the estimator and the status from received messages.

    Parameters
    ----------
    estimator : StateEstimator
    position_var_m2, velocity_var_m2_s2 : (float, float, float)
        Variances given to LOCAL_POSITION_NED positions and velocities.
    on_event : callable (kind, text) or None
        Told of mode changes, arming, disarming and STATUSTEXT.
    """

    def __init__(self, estimator: StateEstimator, position_var_m2=(0.0025,) * 3, velocity_var_m2_s2=(0.0025,) * 3,
                 on_event: Callable[[str, str], None] | None = None, target_component: int = 1,
                 validator: TelemetryValidator | None = None,
                 mode_name: Callable[[int], str] = copter_mode_name) -> None:
        self.target_component = target_component
        self.estimator = estimator
        self.position_var = tuple(position_var_m2)
        self.velocity_var = tuple(velocity_var_m2_s2)
        self.status = VehicleStatus(mode_name=mode_name)
        self.on_event = on_event
        self.last_ns: dict[str, int] = {}
        #: The vehicle's time stamp of the newest ATTITUDE / LOCAL_POSITION_NED sample [ns].
        self.stamp_ns: dict[str, int] = {}
        self.time_map = VehicleTimeMap()
        #: The loop's clock is the vehicle's own time (lockstep, paced): set by the session.
        self.on_vehicle_clock = False
        #: PX4 EVENT -> its text (the profile's metadata), or None: events kept, not said.
        self.describe_event: Callable | None = None
        #: The autopilot's AUTOPILOT_VERSION, once received.
        self.autopilot_version = None
        self.timesync_rtt_ms: float | None = None
        self.timesync_samples_ms: list[float] = []
        self.timesync_sent: set[int] = set()
        #: Valid messages received, per type (the loop's stream-rate monitor reads it).
        self.counts: dict[str, int] = {}
        self.validator = validator or TelemetryValidator(on_first=lambda why: self._event(
            "warning", f"telemetry rejected: {why} (further ones are counted)"))

    def _event(self, kind: str, text: str) -> None:
        if self.on_event is not None:
            self.on_event(kind, text)

    def handle(self, msg, now_ns: int) -> None:
        """Take one message received at loop time ``now_ns`` (validated first: see :mod:`gcs.flight.validate`)."""
        if msg.get_srcComponent() != self.target_component:
            return  # a companion computer or gimbal of the same system: not the autopilot
        t = msg.get_type()
        st = self.status
        v = self.validator
        if t == "ATTITUDE":
            if not v.attitude(msg.roll, msg.pitch, msg.yaw, msg.rollspeed, msg.pitchspeed, msg.yawspeed,
                              int(msg.time_boot_ms)):
                return
            er = body_rates_to_euler_rates(msg.roll, msg.pitch, msg.rollspeed, msg.pitchspeed, msg.yawspeed)
            self.estimator.set_attitude(msg.roll, msg.pitch, msg.yaw, *er)
            self._stamp(t, int(msg.time_boot_ms), now_ns)
        elif t == "LOCAL_POSITION_NED":
            if not v.position(msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.vz, int(msg.time_boot_ms)):
                return
            self.estimator.correct_position(ned_to_paper_position(msg.x, msg.y, msg.z), self.position_var)
            self.estimator.correct_velocity(ned_to_paper_velocity(msg.vx, msg.vy, msg.vz), self.velocity_var)
            self._stamp(t, int(msg.time_boot_ms), now_ns)
        self.last_ns[t] = now_ns
        self.counts[t] = self.counts.get(t, 0) + 1
        if t in ("ATTITUDE", "LOCAL_POSITION_NED"):
            return
        if t == "HEARTBEAT":
            self._heartbeat(msg)
        elif t == "SYS_STATUS":
            self._sys_status(msg)
        elif t == "EKF_STATUS_REPORT":
            st.ekf_flags = int(msg.flags)
        elif t in ("EXTENDED_SYS_STATE", "UNKNOWN_410"):
            self._px4_status(msg)
        elif t == "AUTOPILOT_VERSION":
            self.autopilot_version = msg
        elif t == "STATUSTEXT":
            text = msg.text.decode(errors="replace") if isinstance(msg.text, bytes) else str(msg.text)
            text = text.rstrip("\x00")
            st.statustext.append(text)
            self._event("statustext", text)
        elif t == "TIMESYNC" and msg.ts1 in self.timesync_sent:
            # Our request carried ts1 = our wall-clock monotonic ns (not the loop clock, which
            # is the vehicle's own in lockstep); the reply echoes it.
            rtt_ms = (time.monotonic_ns() - msg.ts1) / 1e6
            self.timesync_sent.discard(msg.ts1)
            if 0.0 <= rtt_ms < 60_000.0:
                self.timesync_rtt_ms = rtt_ms
                self.timesync_samples_ms.append(rtt_ms)

    def _heartbeat(self, msg) -> None:
        """Arming, flight mode and system status from a HEARTBEAT (events for the changes)."""
        st = self.status
        armed = bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
        if armed != st.armed:
            st.armed = armed
            self._event("arming", "armed" if armed else "disarmed")
        if msg.custom_mode != st.custom_mode:
            st.custom_mode = int(msg.custom_mode)
            namer = st.mode_name
            if namer is copter_mode_name and msg.autopilot == mavlink.MAV_AUTOPILOT_PX4:
                namer = px4_mode_name  # the first HEARTBEAT, before the profile is chosen from it
            self._event("mode", namer(st.custom_mode))
        st.system_status = int(msg.system_status)

    def _px4_status(self, msg) -> None:
        """EXTENDED_SYS_STATE's landed state, PX4's EVENTs (kept; said when the profile can put them in words)."""
        st = self.status
        if msg.get_type() == "EXTENDED_SYS_STATE":
            if msg.landed_state != st.landed_state and st.landed_state is not None:
                self._event("landed_state", _LANDED.get(int(msg.landed_state), str(msg.landed_state)))
            st.landed_state = int(msg.landed_state)
            return
        ev = parse_event(msg)
        if ev is not None:
            st.events.append(ev)
            if self.describe_event is not None and ev.level != "unknown":
                self._event("px4_event", f"[{ev.level}] {self.describe_event(ev)}")

    def _sys_status(self, msg) -> None:
        """Battery voltage (validated; 65535 = not reported) and remaining charge (-1 = not reported)."""
        st = self.status
        if msg.voltage_battery != 65535 and self.validator.voltage(msg.voltage_battery / 1000.0):
            st.battery_voltage_v = msg.voltage_battery / 1000.0
        if msg.battery_remaining >= 0:
            st.battery_remaining_pct = int(msg.battery_remaining)

    def _stamp(self, message: str, time_boot_ms: int, now_ns: int) -> None:
        stamp = time_boot_ms * 1_000_000
        self.stamp_ns[message] = max(self.stamp_ns.get(message, 0), stamp)
        # On the vehicle's own clock (lockstep, paced) the loop's "now" is the newest stamp so far: this
        # sample cannot have arrived before its own time.
        self.time_map.observe(max(now_ns, stamp) if self.on_vehicle_clock else now_ns, stamp)
        st = self.status
        st.time_boot_ms = max(st.time_boot_ms, time_boot_ms)

    def vehicle_time_ns(self) -> int:
        """The newest vehicle time stamp received [ns] (the clock of lockstep and paced flights)."""
        return self.status.time_boot_ms * 1_000_000

    def age_s(self, message: str, now_ns: int) -> float:
        """How old the newest ``message`` is (inf if never): since it arrived, or by its own time stamp on
        the vehicle's clock when that is older (a sample delivered late)."""
        t = self.last_ns.get(message)
        if t is None:
            return float("inf")
        age = now_ns - t
        stamp = self.stamp_ns.get(message)
        if stamp is not None:
            age = max(age, self.time_map.age_ns(now_ns, stamp))
        return age / 1e9

    def fresh(self, now_ns: int, stale_s: float) -> bool:
        """Attitude and position both newer than ``stale_s``."""
        return max(self.age_s("ATTITUDE", now_ns), self.age_s("LOCAL_POSITION_NED", now_ns)) <= stale_s
