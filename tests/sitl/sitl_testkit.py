"""A small pymavlink ground station for the SITL tests (imported by conftest.py and the tests)."""

from __future__ import annotations

import time
from collections.abc import Iterable

from pymavlink import mavutil

M = mavutil.mavlink


class Gcs:
    """A pymavlink ground station with the helpers the tests need.

    Every message received is kept in :attr:`log` (type -> list); STATUSTEXT
    texts in :attr:`texts`.
    """

    def __init__(self, connection_string: str, hello: bool = True, **kwargs) -> None:
        self.conn = mavutil.mavlink_connection(connection_string, source_system=255, **kwargs)
        self.log: dict[str, list] = {}
        self.texts: list[str] = []
        if hello:  # udpout: the vehicle only learns our address from a first message
            self.conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)

    def close(self) -> None:
        self.conn.close()

    # -------------------------------------------------------------- receiving
    def _keep(self, m) -> None:
        kind = m.get_type()
        self.log.setdefault(kind, []).append(m)
        if kind == "STATUSTEXT":
            self.texts.append(m.text)

    def recv(self, types: Iterable[str] | str | None = None, timeout: float = 5.0, cond=None):
        """Next message of ``types`` (and ``cond``) within ``timeout`` s; keeps everything seen."""
        if isinstance(types, str):
            types = {types}
        end = time.monotonic() + timeout
        while True:
            left = end - time.monotonic()
            if left <= 0:
                return None
            m = self.conn.recv_match(blocking=True, timeout=min(left, 0.5))
            if m is None:
                continue
            self._keep(m)
            if (types is None or m.get_type() in types) and (cond is None or cond(m)):
                return m

    def drain(self) -> None:
        """Read what is already buffered (no waiting)."""
        while True:
            m = self.conn.recv_match(blocking=False)
            if m is None:
                return
            self._keep(m)

    def wait_heartbeat(self, timeout: float = 5.0):
        return self.recv("HEARTBEAT", timeout)

    # -------------------------------------------------------------- commands
    def command(self, command: int, *params: float, target_system: int = 1, timeout: float = 5.0):
        p = list(params) + [0.0] * (7 - len(params))
        self.conn.mav.command_long_send(target_system, 1, command, 0, *p)
        return self.recv("COMMAND_ACK", timeout, cond=lambda m: m.command == command)

    def set_mode(self, mode: int):
        return self.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode)

    def arm(self, force: bool = False):
        return self.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1, 21196 if force else 0)

    def request(self, msg_id: int, rate_hz: float):
        return self.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / rate_hz if rate_hz > 0 else -1)

    def param_set(self, name: str, value: float, timeout: float = 5.0):
        self.conn.mav.param_set_send(1, 1, name.encode(), value, M.MAV_PARAM_TYPE_REAL32)
        return self.recv("PARAM_VALUE", timeout, cond=lambda m: m.param_id == name)

    def param_get(self, name: str, timeout: float = 5.0):
        self.conn.mav.param_request_read_send(1, 1, name.encode(), -1)
        return self.recv("PARAM_VALUE", timeout, cond=lambda m: m.param_id == name)

    # -------------------------------------------------------------- lockstep
    def step(self, thrust: float = 0.5, q=(1.0, 0.0, 0.0, 0.0), type_mask: int = 0b111,
             rates=(0.0, 0.0, 0.0), timeout: float = 5.0):
        """One lockstep step; returns the LOCAL_POSITION_NED of the step's end (stream at 100 Hz needed)."""
        self.conn.mav.set_attitude_target_send(0, 1, 1, type_mask, list(q), rates[0], rates[1], rates[2], thrust)
        m = self.recv("LOCAL_POSITION_NED", timeout)
        assert m is not None, "no LOCAL_POSITION_NED after a lockstep step (stream requested?)"
        return m

    def start_lockstep_streams(self) -> None:
        for msg_id in (M.MAVLINK_MSG_ID_ATTITUDE, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED):
            ack = self.request(msg_id, 100)
            assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED

    def last_heartbeat(self):
        hb = self.log.get("HEARTBEAT")
        return hb[-1] if hb else None
