"""The 4-DOF rig emulator behind a serial port: real time or lockstep.

The rig of the paper's indoor experiments (section 4.1): a quadrotor on a
4-DOF stand (x, z, roll, pitch) whose 200 Hz onboard autopilot talks to the
PC over an XBee link at 115200 baud with the frames of
:mod:`quadrotor.rig_protocol`.  The physics is :mod:`sitl.rig_dynamics`, the
sensors :mod:`sitl.rig_sensors`, the onboard logic (arming, cut-off,
watchdog) :mod:`sitl.rig_firmware`; this module adds the link: a transport
(normally :class:`~sitl.transport.PtyTransport`), the baud limit / loss /
latency of :mod:`sitl.radio`, bit errors (:mod:`sitl.rig_link`) and the clock.

Usage from Python (lockstep, serial port on a pseudo-terminal)::

    from sitl.rig import RigServer
    from sitl.transport import PtyTransport
    from sitl.radio import RadioParams
    from quadrotor.clock import MonotonicClock

    clock = MonotonicClock()
    with RigServer(PtyTransport(clock.now_ns), lockstep=True, radio=RadioParams(baud=115200),
                   clock=clock, seed=1) as rig:
        port = serial.Serial(rig.connection_string, 115200, timeout=0.05)
        port.write(encode(Heartbeat(0)))      # the rig answers with STATUS
        ...
        rig.snapshot()["plant"]               # the true state, for tests

Time
----
* **Real time**: rig time follows the injected monotonic clock; the 200 Hz
  loop catches up in bursts if the process was late (more than one second
  behind: it skips ahead and counts an overrun).  Every tick sends one
  TELEMETRY; the latest control frame is applied every tick.
* **Lockstep**: rig time advances by one control period (10 ms = two ticks by
  default) per CONTROL or CONTROL_PWM frame received (applied or not, e.g.
  while disarmed).  A step is: apply the frame, run the ticks, send their
  TELEMETRY frames (two per step; the last one is stamped with the step's end,
  a multiple of the period), and a STATUS when a whole second was crossed.
  ARM, DISARM and HEARTBEAT are answered at once without moving time.  While
  no step arrives a STATUS goes out every wall-clock second.  The link
  watchdog counts rig time, so it never trips in lockstep.  Same seed + same
  frames = same trajectory.

A new peer (first bytes on the serial line) is greeted with a STATUS.  Until
then the serial port discards its unread output (see
:class:`~sitl.transport.PtyTransport`): the PC should send a HEARTBEAT first.
"""

from __future__ import annotations

import logging
import math
import random
import select
import socket
import threading
from typing import Any

from quadrotor import rig_protocol as rp
from quadrotor.clock import Clock, MonotonicClock
from sitl.errors import SitlError, UsageError
from sitl.radio import RadioLink, RadioParams
from quadrotor.state import State
from sitl.rig_dynamics import RigParams
from sitl.rig_firmware import TICK_NS, RigFirmware, RigSafetyParams
from sitl.rig_link import BitErrors
from sitl.rig_sensors import RigSensorParams
from sitl.transport import Transport

__all__ = ["RigServer", "RIG_KINDS"]

log = logging.getLogger(__name__)

#: Rig models the ``sitl --rig`` option knows.
RIG_KINDS = ("4dof",)
_MAX_CATCHUP_S = 1.0
_IDLE_STATUS_NS = 1_000_000_000


class RigServer:
    """The emulated 4-DOF rig on a transport.

    Parameters
    ----------
    transport : Transport
        Normally :class:`~sitl.transport.PtyTransport`; the server closes it.
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
            ticks = control_period_s * 1e9 / TICK_NS
            if not 0 < control_period_s < math.inf or abs(ticks - round(ticks)) > 1e-6 or round(ticks) < 1:
                raise UsageError(f"control period {control_period_s!r} s is not a multiple of the "
                                 f"{TICK_NS / 1e6:g} ms onboard period")
            if not 0.0 <= bit_error_rate < 1.0:
                raise UsageError(f"bit error rate must be in [0, 1), got {bit_error_rate!r}")
        except BaseException:
            transport.close()
            raise
        self.transport = transport
        self.lockstep = lockstep
        self.control_period_s = control_period_s
        self._ticks_per_step = int(round(ticks))
        self.clock: Clock = clock or MonotonicClock()
        self.decoder = rp.RigDecoder(rp.TO_RIG)
        self.firmware = RigFirmware(params, sensors, safety, seed, self.decoder.counters, initial)
        self.radio = RadioLink(radio, seed) if radio is not None and radio.active else None
        self.bits_up = BitErrors(bit_error_rate, random.Random(f"{seed}/rig/bits/up"))
        self.bits_down = BitErrors(bit_error_rate, random.Random(f"{seed}/rig/bits/down"))
        self.steps = 0
        self.overruns = 0
        self.tx_frames = 0
        self.tx_bytes = 0
        self.lost_in = 0
        self.lost_out = 0
        self.dropped_out = 0
        self._out: list[bytes] = []
        self._greet = False
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None
        self._closed = False
        self.running = False

    # ------------------------------------------------------------------ public API
    @property
    def connection_string(self) -> str:
        """The serial device the ground station opens (for a PtyTransport)."""
        return self.transport.connection_string

    @property
    def time_s(self) -> float:
        """Rig time [s]."""
        return self.firmware.time_s

    def snapshot(self) -> dict[str, Any]:
        """A consistent copy of the rig's true state and counters, for tests and tools.

        Keys: those of :meth:`RigFirmware.snapshot` (``time_s``, ``state``, ``flags``,
        ``plant``, ``motors_n``, ...), plus ``steps``, ``overruns``, ``rx`` (decoder
        counters) and ``link`` (frames/bytes sent, chunks lost or dropped, bits flipped).
        """
        with self._lock:
            snap = self.firmware.snapshot()
            snap.update({
                "steps": self.steps, "overruns": self.overruns, "rx": self.decoder.counters.as_dict(),
                "link": {"tx_frames": self.tx_frames, "tx_bytes": self.tx_bytes, "lost_in": self.lost_in,
                         "lost_out": self.lost_out, "dropped_out": self.dropped_out,
                         "bits_flipped_in": self.bits_up.flipped_bits,
                         "bits_flipped_out": self.bits_down.flipped_bits},
            })
            return snap

    def start(self) -> "RigServer":
        """Run :meth:`run` in a background thread; returns self."""
        if self._thread is not None:
            raise SitlError("rig server already started")
        self._thread = threading.Thread(target=self._thread_main, name="sitl-server", daemon=True)
        self._thread.start()
        return self

    def _thread_main(self) -> None:
        try:
            self.run()
        except BaseException as exc:  # noqa: BLE001 - re-raised by stop()
            log.exception("rig server failed")
            self._error = exc

    def request_stop(self) -> None:
        """Ask :meth:`run` to return (thread- and signal-handler-safe)."""
        self._stop.set()
        try:
            self._wake_w.send(b"x")
        except OSError:
            pass

    def stop(self, timeout: float = 5.0) -> None:
        """Stop the background thread, close everything; re-raises a failure of the loop."""
        self.request_stop()
        if self._thread is not None:
            self._thread.join(timeout)
            if self._thread.is_alive():
                raise SitlError("rig server thread did not stop")
            self._thread = None
        self.close()
        if self._error is not None:
            err, self._error = self._error, None
            raise err

    def close(self) -> None:
        """Release the transport and wake-up sockets (idempotent; stop the loop first)."""
        if not self._closed:
            self._closed = True
            self.transport.close()
            self._wake_r.close()
            self._wake_w.close()

    def __enter__(self) -> "RigServer":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def run(self) -> None:
        """Serve until :meth:`request_stop` (blocking)."""
        self.running = True
        try:
            with self._lock:
                self._queue(self.firmware.status())
                self._flush(self.clock.now_ns())
            if self.lockstep:
                self._run_lockstep()
            else:
                self._run_realtime()
        finally:
            self.running = False

    # ------------------------------------------------------------------ loops
    def _run_realtime(self) -> None:
        fw = self.firmware
        wall0 = self.clock.now_ns()
        sim0 = fw.time_ns
        while not self._stop.is_set():
            now = self.clock.now_ns()
            with self._lock:
                self._process(self._poll_input(now))
                self._greet_new_peers()
                target = sim0 + (now - wall0)
                n = 0
                while fw.time_ns + TICK_NS <= target:
                    self._tick()
                    n += 1
                    if n * TICK_NS > _MAX_CATCHUP_S * 1e9:
                        self.overruns += 1
                        wall0 = now - (fw.time_ns - sim0)
                        break
                self._flush(now)
            self._wait(wall0 + (fw.time_ns + TICK_NS - sim0))

    def _run_lockstep(self) -> None:
        last_status = self.clock.now_ns()
        steps_seen = self.steps
        while not self._stop.is_set():
            now = self.clock.now_ns()
            with self._lock:
                self._process(self._poll_input(now))
                self._greet_new_peers()
                if self.steps != steps_seen:
                    steps_seen = self.steps
                    last_status = now
                elif now - last_status >= _IDLE_STATUS_NS:
                    self._queue(self.firmware.status())
                    last_status = now
                self._flush(now)
            self._wait(last_status + _IDLE_STATUS_NS)

    def _wait(self, until_ns: int) -> None:
        if self.radio is not None:
            t = self.radio.next_event_ns()
            if t is not None and t < until_ns:
                until_ns = t
        timeout = max(0.0, (until_ns - self.clock.now_ns()) * 1e-9)
        rlist = [*self.transport.filenos(), self._wake_r.fileno()]
        wlist = self.transport.write_filenos()
        try:
            r, w, _ = select.select(rlist, wlist, [], timeout)
        except (OSError, ValueError) as exc:  # a descriptor closed under us: retry next loop
            log.debug("select: %s", exc)
            return
        if self._wake_r.fileno() in r:
            try:
                while self._wake_r.recv(4096):
                    pass
            except (BlockingIOError, InterruptedError):
                pass
        if w:
            self.transport.flush()

    # ------------------------------------------------------------------ I/O
    def _poll_input(self, now_ns: int) -> list[bytes]:
        items = self.transport.receive()
        self.transport.take_gone_peers()
        if self.transport.take_new_peers():
            self._greet = True
        if self.radio is None:
            chunks = [data for _, data, _ in items]
        else:
            for peer, data, _ in items:
                if not self.radio.up.push(peer, data, now_ns):
                    self.lost_in += 1
            chunks = [data for _, data in self.radio.up.pop_ready(now_ns)]
        return [self.bits_up.apply(c) for c in chunks]

    def _process(self, chunks: list[bytes]) -> None:
        for data in chunks:
            for msg in self.decoder.feed(data):
                replies, is_control = self.firmware.handle(msg)
                for r in replies:
                    self._queue(r)
                if is_control and self.lockstep:
                    self._step()
                    self._flush(self.clock.now_ns())

    def _greet_new_peers(self) -> None:
        if self._greet:
            self._greet = False
            self._queue(self.firmware.status())

    def _queue(self, msg: rp.Message) -> None:
        self._out.append(rp.encode(msg))

    def _flush(self, now_ns: int) -> None:
        frames, self._out = self._out, []
        if self.radio is not None:
            for f in frames:
                if not self.radio.down.push(None, f, now_ns):
                    self.lost_out += 1
            frames = [f for _, f in self.radio.down.pop_ready(now_ns)]
        if frames:
            frames = [self.bits_down.apply(f) for f in frames]
            self.tx_frames += len(frames)
            self.tx_bytes += sum(len(f) for f in frames)
            self.dropped_out += self.transport.send(frames)

    # ------------------------------------------------------------------ simulation
    def _tick(self) -> None:
        for m in self.firmware.tick():
            self._queue(m)

    def _step(self) -> None:
        for _ in range(self._ticks_per_step):
            self._tick()
        self.steps += 1
