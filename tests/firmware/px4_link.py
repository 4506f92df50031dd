"""A small UDP proxy between ``gcs fly --connect`` and PX4's offboard link, for the PX4 failure tests.

PX4 instance N sends its offboard link to 127.0.0.1:14540 + N (fixed by its startup script) and
listens on 14580 + N.  The proxy takes 14540 + N, forwards everything to ``gcs fly --connect
udpin:127.0.0.1:G`` and back, and can:

* ``swallow_offboard``: drop our MAV_CMD_DO_SET_MODE(OFFBOARD) and answer it with a forged
  COMMAND_ACK ACCEPTED from the vehicle (the ACK lies; HEARTBEAT keeps telling the truth);
* watch PX4's ATTITUDE throughout (the largest tilt, whatever the ground station was doing);
* :meth:`Px4LinkProxy.blackout`: forward nothing either way for a while (a dead radio link),
  while it keeps decoding PX4's ATTITUDE so the test sees how the vehicle flew meanwhile.

Only pymavlink and the standard library.
"""

from __future__ import annotations

import math
import selectors
import socket
import threading
import time

from pymavlink.dialects.v20 import common as mavlink

__all__ = ["Px4LinkProxy"]

OFFBOARD_MAIN = 6


class Px4LinkProxy:
    """The proxy thread.

    Parameters
    ----------
    instance : int
        The PX4 instance (its ports).
    gcs_port : int
        Where ``gcs fly --connect udpin:127.0.0.1:<gcs_port>`` listens.
    swallow_offboard : bool
        Forge the OFFBOARD acknowledgement and never let the command through.
    """

    def __init__(self, instance: int, gcs_port: int, *, swallow_offboard: bool = False) -> None:
        self.vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.vehicle.bind(("127.0.0.1", 14540 + instance))
        self.ground = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.ground.bind(("127.0.0.1", 0))
        for s in (self.vehicle, self.ground):
            s.setblocking(False)
        self.px4_addr: tuple[str, int] | None = None
        self.gcs_addr = ("127.0.0.1", gcs_port)
        self.swallow_offboard = swallow_offboard
        self.swallowed = 0
        self.armed = False
        self.armed_at: float | None = None
        self.disarmed_at: float | None = None
        self.custom_modes: list[int] = []
        self.max_tilt_deg_in_blackout = 0.0
        self.tilt_deg: list[tuple[float, float]] = []  # (monotonic time [s], tilt [deg]) of every ATTITUDE
        #: (monotonic time [s], LOCAL_POSITION_NED z [m], vz [m/s]), NED: down positive.
        self.z_ned_m: list[tuple[float, float, float]] = []
        self._blackout: tuple[float, float] | None = None
        self._after_arming: tuple[float, float] | None = None
        self._down = mavlink.MAVLink(None)
        self._up = mavlink.MAVLink(None)
        self._forger = mavlink.MAVLink(None, srcSystem=instance + 1, srcComponent=1)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="px4-proxy", daemon=True)

    def __enter__(self) -> Px4LinkProxy:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(5.0)
        self.vehicle.close()
        self.ground.close()

    def blackout(self, start_in_s: float, length_s: float) -> None:
        """Forward nothing from ``start_in_s`` from now, for ``length_s`` [s]."""
        t0 = time.monotonic() + start_in_s
        self._blackout = (t0, t0 + length_s)

    def blackout_after_arming(self, after_s: float, length_s: float) -> None:
        """A :meth:`blackout` ``after_s`` [s] after PX4 reports itself armed."""
        self._after_arming = (after_s, length_s)

    def tilt_split_deg(self, since: float, *, near_m: float = 0.5,
                       still_m_s: float = 0.2) -> tuple[float, float, float]:
        """The largest tilt [deg] from monotonic time ``since`` [s] until touchdown, after it, and the
        touchdown's monotonic time [s] (inf: none seen).

        Touchdown is the first LOCAL_POSITION_NED after ``since``, once the vehicle has been higher,
        within ``near_m`` of the height PX4 estimated when it last disarmed and descending slower than
        ``still_m_s`` (the estimate drifts by tenths of a metre between boot, touchdown and disarming).
        On the ground SIH's contact model lets the airframe rock while the land detector decides
        (measured up to 14 deg on a loaded machine), which says nothing about how it flew down.
        """
        samples = [(t, z, vz) for t, z, vz in list(self.z_ned_m) if t >= since]
        end = self.disarmed_at if self.disarmed_at is not None else math.inf
        at_end = [z for t, z, _ in samples if t < end]
        tilts = list(self.tilt_deg)
        if not at_end:
            return max((a for t, a in tilts if t >= since), default=0.0), 0.0, math.inf
        ground = at_end[-1]
        touchdown, airborne = math.inf, False
        for t, z, vz in samples:
            if z < ground - near_m - 0.2:
                airborne = True
            elif airborne and z >= ground - near_m and vz < still_m_s:
                touchdown = t
                break
        air = max((a for t, a in tilts if since <= t < touchdown), default=0.0)
        ground_tilt = max((a for t, a in tilts if touchdown <= t), default=0.0)
        return air, ground_tilt, touchdown

    def in_blackout(self) -> bool:
        b = self._blackout
        return b is not None and b[0] <= time.monotonic() < b[1]

    def _run(self) -> None:
        sel = selectors.DefaultSelector()
        sel.register(self.vehicle, selectors.EVENT_READ, "down")
        sel.register(self.ground, selectors.EVENT_READ, "up")
        while not self._stop.is_set():
            for key, _ in sel.select(0.1):
                while True:
                    try:
                        data, addr = key.fileobj.recvfrom(65535)  # type: ignore[union-attr]
                    except (BlockingIOError, InterruptedError):
                        break
                    except OSError:
                        continue
                    if key.data == "down":
                        self.px4_addr = addr
                        self._from_px4(data)
                    else:
                        self._from_gcs(data)

    def _decode(self, parser, data: bytes) -> list:
        try:
            return parser.parse_buffer(data) or []
        except mavlink.MAVError:
            return []

    def _from_px4(self, data: bytes) -> None:
        dark = self.in_blackout()
        for m in self._decode(self._down, data):
            t = m.get_type()
            if t == "HEARTBEAT" and m.get_srcComponent() == 1:
                armed = bool(m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
                if armed and not self.armed:
                    self.armed_at = time.monotonic()
                    if self._after_arming is not None:
                        self.blackout(*self._after_arming)
                if self.armed and not armed:
                    self.disarmed_at = time.monotonic()
                self.armed = armed
                if not self.custom_modes or self.custom_modes[-1] != m.custom_mode:
                    self.custom_modes.append(m.custom_mode)
            elif t == "LOCAL_POSITION_NED":
                self.z_ned_m.append((time.monotonic(), m.z, m.vz))
            elif t == "ATTITUDE":
                tilt = math.degrees(math.acos(max(-1.0, min(1.0, math.cos(m.roll) * math.cos(m.pitch)))))
                self.tilt_deg.append((time.monotonic(), tilt))
                if dark:
                    self.max_tilt_deg_in_blackout = max(self.max_tilt_deg_in_blackout, tilt)
        if not dark:
            self.ground.sendto(data, self.gcs_addr)

    def _from_gcs(self, data: bytes) -> None:
        if self.in_blackout() or self.px4_addr is None:
            return
        if self.swallow_offboard:
            for m in self._decode(self._up, data):
                if (m.get_type() == "COMMAND_LONG" and m.command == mavlink.MAV_CMD_DO_SET_MODE
                        and int(m.param2) == OFFBOARD_MAIN):
                    self.swallowed += 1
                    ack = self._forger.command_ack_encode(m.command, mavlink.MAV_RESULT_ACCEPTED, 0, 0,
                                                          m.get_srcSystem(), m.get_srcComponent())
                    self.ground.sendto(ack.pack(self._forger), self.gcs_addr)
                    return
        self.vehicle.sendto(data, self.px4_addr)
