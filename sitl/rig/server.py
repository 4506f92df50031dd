"""The 4-DOF rig emulator behind a serial port: :class:`~sitl.rig.firmware.RigFirmware` on a :class:`SerialLink`.

Usage from Python (lockstep, serial port on a pseudo-terminal)::

    from quadrotor.clock import MonotonicClock
    from sitl.net.pty import PtyTransport
    from sitl.net.radio import RadioParams
    from sitl.rig.server import RigServer

    clock = MonotonicClock()
    with RigServer(PtyTransport(clock.now_ns), lockstep=True, radio=RadioParams(baud=115200),
                   clock=clock, seed=1) as rig:
        port = serial.Serial(rig.connection_string, 115200, timeout=0.05)
        port.write(encode(Heartbeat(0)))      # the rig answers with STATUS
        ...
        rig.snapshot()["plant"]               # the true state, for tests

Real time: every 5 ms tick sends one TELEMETRY and applies the latest control frame.  Lockstep:
one control period (10 ms = two ticks by default) per CONTROL or CONTROL_PWM frame received,
applied or not (e.g. while disarmed); the step's TELEMETRY frames follow it (the last stamped with
the step's end, a multiple of the period), and a STATUS when a whole second was crossed.  ARM,
DISARM and HEARTBEAT are answered at once without moving time.  The link watchdog counts rig time,
so it never trips in lockstep.  Until the PC has sent something, the serial port discards its
unread output (:class:`~sitl.net.pty.PtyTransport`): the PC should send a HEARTBEAT first, which
is greeted with a STATUS.
"""

from __future__ import annotations

from typing import Any

from quadrotor import rig_protocol as rp
from quadrotor.clock import Clock, MonotonicClock
from quadrotor.state import State
from sitl.errors import UsageError
from sitl.net.loop import LoopServer, ServerLoop, ticks_per_step
from sitl.net.radio import RadioParams
from sitl.net.transport import Transport
from sitl.rig.dynamics import RigParams
from sitl.rig.firmware import TICK_NS, RigFirmware, RigSafetyParams
from sitl.rig.link import SerialLink
from sitl.rig.sensors import RigSensorParams

__all__ = ["RigServer", "RIG_KINDS"]

#: Rig models the ``sitl --rig`` option knows.
RIG_KINDS = ("4dof",)


class RigServer(LoopServer):
    """The emulated 4-DOF rig on a transport.

    Parameters
    ----------
    transport : Transport
        Normally :class:`~sitl.net.pty.PtyTransport`; the server closes it.
    params : RigParams or None
        Plant parameters.
    sensors : RigSensorParams or None
        Sensor noise and ranges (:meth:`RigSensorParams.ideal` for none).
    safety : RigSafetyParams or None
        Cut-off limits, command limits, watchdog.
    lockstep : bool
        Advance time by control frames (see the module docstring).
    control_period_s : float
        Lockstep step, a multiple of the 5 ms onboard period.
    seed : int
        Seeds sensor noise, loss and bit errors.
    radio : RadioParams or None
        Baud limit / loss / latency of both directions (the rig's XBee: ``RadioParams(baud=115200)``).
    bit_error_rate : float
        Probability of flipping each bit, both directions.
    clock : Clock or None
        Monotonic clock (default :class:`~quadrotor.clock.MonotonicClock`).
    initial : State or None
        Initial true state (default landed at the origin).
    """

    def __init__(self, transport: Transport, *, params: RigParams | None = None,
                 sensors: RigSensorParams | None = None, safety: RigSafetyParams | None = None,
                 lockstep: bool = False, control_period_s: float = 0.01, seed: int = 0,
                 radio: RadioParams | None = None, bit_error_rate: float = 0.0, clock: Clock | None = None,
                 initial: State | None = None) -> None:
        try:
            self._ticks_per_step = ticks_per_step(control_period_s, 1e9 / TICK_NS, "onboard")
            if not 0.0 <= bit_error_rate < 1.0:
                raise UsageError(f"bit error rate must be in [0, 1), got {bit_error_rate!r}")
        except BaseException:
            transport.close()
            raise
        self.transport = transport
        self.lockstep = lockstep
        self.control_period_s = control_period_s
        self.clock: Clock = clock or MonotonicClock()
        self.decoder = rp.RigDecoder(rp.TO_RIG)
        self.firmware = RigFirmware(params, sensors, safety, seed, self.decoder.counters, initial)
        self.link = SerialLink(transport, radio, bit_error_rate, seed)
        self.steps = 0
        self._out: list[bytes] = []
        self.loop = ServerLoop(self, self.link, self.clock, lockstep=lockstep, tick_ns=TICK_NS,
                               release=self.link.close, name="rig server")

    # ------------------------------------------------------------------ public API
    @property
    def connection_string(self) -> str:
        """The serial device the ground station opens (for a PtyTransport)."""
        return self.transport.connection_string

    @property
    def time_s(self) -> float:
        """Rig time [s]."""
        return self.firmware.time_s

    @property
    def time_ns(self) -> int:
        """Rig time [ns]."""
        return self.firmware.time_ns

    def snapshot(self) -> dict[str, Any]:
        """A consistent copy of the rig's true state and counters, for tests and tools.

        Keys: those of :meth:`RigFirmware.snapshot` (``time_s``, ``state``, ``flags``,
        ``plant``, ``motors_n``, ...), plus ``steps``, ``overruns``, ``rx`` (decoder
        counters) and ``link`` (:meth:`SerialLink.counters`).
        """
        with self.lock:
            snap = self.firmware.snapshot()
            snap.update({"steps": self.steps, "overruns": self.loop.overruns, "rx": self.decoder.counters.as_dict(),
                         "link": self.link.counters()})
            return snap

    # ------------------------------------------------------------------ what the loop drives
    def announce(self) -> None:
        """Queue a STATUS."""
        self._queue(self.firmware.status())

    def take_input(self, now_ns: int) -> None:
        """Handle the frames received (stepping in lockstep); greet a new peer with a STATUS."""
        self.handle_input(self.link.receive(now_ns))
        if self.link.take_new_peer():
            self.announce()

    def handle_input(self, chunks: list[bytes]) -> None:
        """Decode and handle received bytes; in lockstep a control frame steps and flushes at once."""
        for data in chunks:
            for msg in self.decoder.feed(data):
                replies, is_control = self.firmware.handle(msg)
                for r in replies:
                    self._queue(r)
                if is_control and self.lockstep:
                    self.step()
                    self.flush(self.clock.now_ns())

    def tick(self) -> None:
        """One 5 ms onboard tick; queues its TELEMETRY (and STATUS)."""
        for m in self.firmware.tick():
            self._queue(m)

    def step(self) -> None:
        """One lockstep control period."""
        for _ in range(self._ticks_per_step):
            self.tick()
        self.steps += 1

    def flush(self, now_ns: int) -> None:
        """Send what is queued."""
        frames, self._out = self._out, []
        self.link.send(frames, now_ns)

    def _queue(self, msg: rp.Message) -> None:
        self._out.append(rp.encode(msg))
