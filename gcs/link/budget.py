"""Link budget: can this serial link carry the 100 Hz control exchange?

A MAVLink 2 frame is a 10-byte header, the payload and a 2-byte CRC (13 more
bytes when signed).  Payload sizes come from pymavlink's message definitions
(the full payload: MAVLink 2 may truncate trailing zero bytes, which only
helps, so the budget is conservative).  A UART at ``baud`` with 8N1 framing
carries ``baud / 10`` bytes per second each way.  A SiK-style telemetry radio
also shares its air rate between both directions (half duplex), halved again
with error correction on; give ``air_rate_bps`` to check that too.

The budget is met when every direction uses at most ``max_utilisation`` of
its capacity (default 80 %: the rest is for parameters, status text, command
acknowledgements and retries).
"""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Iterable

from pymavlink.dialects.v20 import ardupilotmega as mavlink

__all__ = ["Stream", "LinkBudget", "frame_bytes", "control_streams", "compute_budget", "suggest_fixes",
           "STANDARD_BAUDS", "format_budget"]

HEADER_BYTES = 10
CRC_BYTES = 2
SIGNATURE_BYTES = 13
STANDARD_BAUDS = (57600, 115200, 230400, 460800, 921600)

OUTPUT_MESSAGES = {"attitude": "SET_ATTITUDE_TARGET", "rates": "SET_ATTITUDE_TARGET",
                   "actuator": "SET_ACTUATOR_CONTROL_TARGET"}


def frame_bytes(message: str, signed: bool = False) -> int:
    """Bytes on the wire of one MAVLink 2 frame of ``message`` (e.g. ``"ATTITUDE"``)."""
    cls = getattr(mavlink, f"MAVLink_{message.lower()}_message", None)
    if cls is None:
        raise ValueError(f"unknown MAVLink message {message!r}")
    return HEADER_BYTES + cls.unpacker.size + CRC_BYTES + (SIGNATURE_BYTES if signed else 0)


@dataclass(frozen=True)
class Stream:
    """A periodic message: ``direction`` is ``"down"`` (vehicle to ground) or ``"up"``."""

    message: str
    rate_hz: float
    direction: str
    why: str = ""


def control_streams(control_rate_hz: float = 100.0, telemetry_rate_hz: float | None = None,
                    output: str = "attitude") -> list[Stream]:
    """The streams ``gcs fly`` needs: full-state telemetry down, setpoints up, plus housekeeping."""
    if output not in OUTPUT_MESSAGES:
        raise ValueError(f"output must be one of {sorted(OUTPUT_MESSAGES)}, got {output!r}")
    tel = control_rate_hz if telemetry_rate_hz is None else telemetry_rate_hz
    return [
        Stream("ATTITUDE", tel, "down", "attitude and body rates"),
        Stream("LOCAL_POSITION_NED", tel, "down", "position and velocity"),
        Stream("SYS_STATUS", 2.0, "down", "battery, health"),
        Stream("HEARTBEAT", 1.0, "down", "mode, armed"),
        Stream("TIMESYNC", 1.0, "down", "latency (reply)"),
        Stream(OUTPUT_MESSAGES[output], control_rate_hz, "up", "the control command"),
        Stream("HEARTBEAT", 1.0, "up", "ground station alive"),
        Stream("TIMESYNC", 1.0, "up", "latency (request)"),
    ]


@dataclass(frozen=True)
class LinkBudget:
    """Bytes per second each way against the link's capacity."""

    baud: int
    signed: bool
    streams: tuple[Stream, ...]
    down_bytes_s: float
    up_bytes_s: float
    capacity_bytes_s: float
    max_utilisation: float
    air_capacity_bytes_s: float | None = None

    @property
    def down_utilisation(self) -> float:
        return self.down_bytes_s / self.capacity_bytes_s

    @property
    def up_utilisation(self) -> float:
        return self.up_bytes_s / self.capacity_bytes_s

    @property
    def air_utilisation(self) -> float | None:
        if self.air_capacity_bytes_s is None:
            return None
        return (self.down_bytes_s + self.up_bytes_s) / self.air_capacity_bytes_s

    @property
    def fits(self) -> bool:
        u = [self.down_utilisation, self.up_utilisation]
        if self.air_utilisation is not None:
            u.append(self.air_utilisation)
        return max(u) <= self.max_utilisation


def compute_budget(streams: Iterable[Stream], baud: int, *, signed: bool = False, max_utilisation: float = 0.8,
                   air_rate_bps: float | None = None, ecc: bool = False) -> LinkBudget:
    """Budget of ``streams`` over a UART at ``baud`` (8N1), optionally behind a half-duplex radio."""
    if baud <= 0:
        raise ValueError(f"baud must be > 0, got {baud}")
    if not 0 < max_utilisation <= 1:
        raise ValueError(f"max_utilisation must be in (0, 1], got {max_utilisation}")
    streams = tuple(streams)
    down = sum(s.rate_hz * frame_bytes(s.message, signed) for s in streams if s.direction == "down")
    up = sum(s.rate_hz * frame_bytes(s.message, signed) for s in streams if s.direction == "up")
    air = None
    if air_rate_bps is not None:
        air = air_rate_bps / 8.0 * (0.5 if ecc else 1.0)
    return LinkBudget(baud, signed, streams, down, up, baud / 10.0, max_utilisation, air)


def suggest_fixes(budget: LinkBudget, control_rate_hz: float, output: str = "attitude") -> list[str]:
    """Configurations that fit, most conservative change first."""
    out = []
    for b in STANDARD_BAUDS:
        if b > budget.baud:
            nb = compute_budget(budget.streams, b, signed=budget.signed, max_utilisation=budget.max_utilisation)
            if nb.fits and budget.air_capacity_bytes_s is None:
                out.append(f"--baud {b} (radio and autopilot serial port set to {b}): "
                           f"{nb.down_utilisation:.0%} down, {nb.up_utilisation:.0%} up")
                break
    for tel in (50.0, 25.0, 20.0, 10.0):
        nb = compute_budget(control_streams(control_rate_hz, tel, output), budget.baud, signed=budget.signed,
                            max_utilisation=budget.max_utilisation,
                            air_rate_bps=(None if budget.air_capacity_bytes_s is None
                                          else budget.air_capacity_bytes_s * 8),
                            ecc=False)
        if nb.fits:
            out.append(f"--telemetry-rate {tel:g} (the estimator fills the gaps): "
                       f"{nb.down_utilisation:.0%} down, {nb.up_utilisation:.0%} up")
            break
    for rate in (50.0, 25.0):
        nb = compute_budget(control_streams(rate, rate, output), budget.baud, signed=budget.signed,
                            max_utilisation=budget.max_utilisation)
        if nb.fits:
            out.append(f"control and telemetry at {rate:g} Hz: [experiment] ts_s = {1 / rate:g} in the config "
                       "(changes the discretisation the gains are designed for)")
            break
    if budget.air_capacity_bytes_s is not None:
        out.append("radio: ECC off, or a higher air rate (the air link is shared by both directions)")
    return out


def format_budget(budget: LinkBudget) -> str:
    """A table of the streams and the totals."""
    lines = [f"{'direction':<6} {'message':<28} {'rate [Hz]':>9} {'frame [B]':>9} {'B/s':>8}  purpose"]
    for s in budget.streams:
        fb = frame_bytes(s.message, budget.signed)
        lines.append(f"{s.direction:<6} {s.message:<28} {s.rate_hz:>9g} {fb:>9d} {fb * s.rate_hz:>8.0f}  {s.why}")
    cap = budget.capacity_bytes_s
    lines.append(f"serial {budget.baud} baud 8N1: {cap:.0f} B/s each way; "
                 f"MAVLink 2{' signed' if budget.signed else ''}")
    lines.append(f"down {budget.down_bytes_s:.0f} B/s = {budget.down_utilisation:.0%}, "
                 f"up {budget.up_bytes_s:.0f} B/s = {budget.up_utilisation:.0%} (limit {budget.max_utilisation:.0%})")
    if budget.air_capacity_bytes_s is not None:
        lines.append(f"radio air link (half duplex): {budget.air_capacity_bytes_s:.0f} B/s shared, "
                     f"{budget.air_utilisation:.0%} used")
    lines.append("fits" if budget.fits else "DOES NOT FIT")
    return "\n".join(lines)
