"""Logging simulated flights: every control tick of every flight of a ``gcs sim`` run, one file.

:func:`gcs.sim.simulate` feeds a :class:`SimRecorder` the lists it keeps anyway (states,
references, commands, steps to go) plus the estimates; the recorder hands them over in
blocks of :data:`BLOCK_TICKS` ticks — a :class:`SimFlightHeader` first, :class:`SimBlock` blocks,
a :class:`SimFlightEnd` — to a sink: a :class:`~gcs.log.writer.FlightLog` (written in this
process) or a :class:`BackgroundSimLog` (written by another process, so that on two or more
cores the simulation does not wait for the JSON formatting and compression).
:class:`SimFlightWriter` turns them into messages, each tick at its simulated time:

* ``/flight`` and an ``/events`` ``flight_start`` at the flight's start;
* per tick k (log time ``start + k * ts``): ``/control/state`` (estimate),
  ``/control/reference``, ``/control/error``, ``/control/command``, ``/control/horizon``,
  ``/control/cost`` (LOC and NLSOC) and ``/sim/truth``;
* after the last command (k = K): ``/control/reference`` and ``/sim/truth`` once more,
  ``/sim/metrics`` and an ``/events`` ``flight_end``;
* ``/events`` ``phase`` at each mission phase change and ``horizon_end`` when the horizon
  runs out within the flight.

Flights follow each other on the file's time line, :data:`GAP_NS` apart.
"""

from __future__ import annotations

import itertools
import math
import os
import pickle
import queue
import struct
import subprocess
import sys
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from gcs.errors import LogError
from gcs.log import topics as T
from gcs.log.writer import FlightLog, _TEMPLATES, check_writable

__all__ = ["SimFlightHeader", "SimBlock", "SimFlightEnd", "SimFlightWriter", "SimRecorder", "InlineSimSink",
           "BackgroundSimLog", "stage_costs", "horizon_modes", "GAP_NS", "BLOCK_TICKS", "BYTES_PER_TICK"]

#: Time between two flights on a file's time line [ns].
GAP_NS = 1_000_000_000
#: Ticks handed to the log at a time.
BLOCK_TICKS = 1000
#: Generous size of one logged simulation tick, compressed [bytes] (for the free-space check).
BYTES_PER_TICK = 700


@dataclass(frozen=True)
class SimFlightHeader:
    """What is known of a simulated flight before it flies."""

    controller: str
    experiment: str
    run: int
    seed: int
    ts_s: float
    steps: int
    horizon_steps: int | None = None
    after_horizon: str | None = None
    phases: tuple[tuple[float, str, int], ...] = ()
    cost: Any = None
    mass_kg: float = 1.0
    gravity_m_s2: float = 9.81


@dataclass(frozen=True)
class SimBlock:
    """Ticks ``k0 .. k0 + n - 1`` of a flight: truth, estimate, reference (n, 12), command (n, 4), steps to go (n,)."""

    k0: int
    truth: np.ndarray
    estimate: np.ndarray
    reference: np.ndarray
    command: np.ndarray
    steps_to_go: np.ndarray


@dataclass(frozen=True)
class SimFlightEnd:
    """The end of a flight: K ticks flown, the state and reference after the last command, the metrics."""

    steps: int
    truth: np.ndarray
    reference: np.ndarray
    metrics: Mapping[str, float] = field(default_factory=dict)


def horizon_modes(k0: int, n: int, horizon_steps: int | None, after: str | None) -> list[str]:
    """Mode of ticks k0 .. k0 + n - 1 (:func:`gcs.control.base.horizon_mode` of each)."""
    from gcs.control.base import horizon_mode

    if horizon_steps is None:
        return ["pd"] * n
    inside = max(0, min(n, horizon_steps - k0))
    return ["horizon"] * inside + [horizon_mode(horizon_steps, horizon_steps, after)] * (n - inside)


def stage_costs(state: np.ndarray, ref: np.ndarray, command: np.ndarray, cost: Any, mass_kg: float,
                g: float) -> np.ndarray:
    """Stage terms ``[1/2 x'Qx, 1/2 u'Ru, sum]`` of a controller's J at each tick, shape (K, 3).

    Same x and u as :func:`gcs.metrics.flight_metrics` uses for J (eq. 5 / eq. 17), so
    ``J = sum over the first min(N, K) ticks + 1/2 x(M)' H x(M)``.
    """
    from gcs.model import MIN_TILT_COS, SUBSYSTEMS

    k = command.shape[0]
    s, r = state[:k], ref[:k]
    cc = np.maximum(np.cos(s[:, 6]) * np.cos(s[:, 7]), MIN_TILT_COS)
    if cost.kind == "loc":
        idx = list(SUBSYSTEMS["z"])
        x = s[:, idx] - r[:, idx]
        u = (command[:, 0] * cc / mass_kg - g)[:, None]
    else:
        idx = list(SUBSYSTEMS["z_psi"])
        x = s[:, idx] - r[:, idx]
        x[:, 2] = (x[:, 2] + np.pi) % (2 * np.pi) - np.pi
        thrust = command[:, 0] - (mass_kg * g / cc if cost.gravity_compensated else 0.0)
        u = np.column_stack([thrust, command[:, 3]])
    xs = 0.5 * np.einsum("ki,ij,kj->k", x, cost.Q, x)
    us = 0.5 * np.einsum("ki,ij,kj->k", u, cost.R, u)
    return np.column_stack([xs, us, xs + us])


class SimFlightWriter:
    """Writes one simulated flight into a :class:`FlightLog`, after what it already holds."""

    def __init__(self, log: FlightLog, header: SimFlightHeader, *, gap_ns: int = GAP_NS) -> None:
        self.log = log
        self.header = header
        self.index = log.flight_count
        self.start_ns = 0 if log.end_time_ns is None else log.end_time_ns + gap_ns
        self.ts_ns = int(round(header.ts_s * 1e9))
        h = header
        log.flight_start(self.start_ns, controller=h.controller, flight=self.index, experiment=h.experiment,
                         run=h.run, seed=h.seed, ts_s=h.ts_s, steps=h.steps, source="sim")
        log.event(self.start_ns, "flight_start", f"{h.controller} run {h.run} (seed {h.seed})",
                  flight=self.index, controller=h.controller, run=h.run)
        self.events: dict[int, list[tuple[str, str, dict]]] = {}
        for t_s, kind, i in h.phases:
            kk = int(round(t_s / h.ts_s))
            self.events.setdefault(kk, []).append(("phase", f"phase {i}: {kind}", {"phase": kind, "index": i}))
        n = h.horizon_steps
        if n is not None:
            self.events.setdefault(n, []).append(("horizon_end", f"horizon over after {n} steps: {h.after_horizon}",
                                                  {"after_horizon": h.after_horizon}))
        self._last_ref: np.ndarray | None = None
        self._ref_text = b""

    def block(self, b: SimBlock) -> None:
        """Write ticks ``b.k0 ..`` (every per-tick topic)."""
        h, log = self.header, self.log
        n = b.command.shape[0]
        if n == 0:
            return
        enc = _TEMPLATES
        e_state, e_ref, e_err, e_cmd, e_cost, e_truth = (enc[T.STATE].encode, enc[T.REFERENCE].encode,
                                                          enc[T.ERROR].encode, enc[T.COMMAND].encode,
                                                          enc[T.COST].encode, enc[T.TRUTH].encode)
        err = b.reference - b.estimate
        err[:, 8] = (err[:, 8] + math.pi) % (2 * math.pi) - math.pi
        costs = None
        if h.cost is not None:
            costs = stage_costs(b.truth, b.reference, b.command, h.cost, h.mass_kg, h.gravity_m_s2).tolist()
        # References hold still most of a flight: format a row only when it differs from the one before.
        prev = b.reference[:1] if self._last_ref is None else self._last_ref[None, :]
        new_ref = np.any(b.reference != np.vstack([prev, b.reference[:-1]]), axis=1)
        if self._last_ref is None:
            new_ref[0] = True
        self._last_ref = b.reference[-1].copy()
        new_ref = new_ref.tolist()
        truth, ref, est, errs = b.truth.tolist(), b.reference.tolist(), b.estimate.tolist(), err.tolist()
        cmd, j = b.command.tolist(), b.steps_to_go.tolist()
        modes = horizon_modes(b.k0, n, h.horizon_steps, h.after_horizon)
        horizon, add, events = log.horizon_json, log._add, self.events
        STATE, REF, ERR, CMD, HOR, COST, TRUTH = (T.STATE, T.REFERENCE, T.ERROR, T.COMMAND, T.HORIZON, T.COST,
                                                  T.TRUTH)
        ref_text = self._ref_text
        t = self.start_ns + b.k0 * self.ts_ns
        for i in range(n):
            k = b.k0 + i
            if k in events:
                for kind, text, fields in events[k]:
                    log.event(t, kind, text, **fields)
            if new_ref[i]:
                ref_text = e_ref(tuple(ref[i]))
            items = [(STATE, e_state(tuple(est[i]))), (REF, ref_text), (ERR, e_err(tuple(errs[i]))),
                     (CMD, e_cmd(tuple(cmd[i]))), (HOR, horizon(k, j[i], modes[i]))]
            if costs is not None:
                items.append((COST, e_cost(tuple(costs[i]))))
            items.append((TRUTH, e_truth(tuple(truth[i]))))
            add(items, t, None)
            t += self.ts_ns
        self._ref_text = ref_text

    def end(self, e: SimFlightEnd) -> None:
        """Write the state and reference after the last command, the run's metrics and ``flight_end``."""
        log, h = self.log, self.header
        t_end = self.start_ns + e.steps * self.ts_ns
        log._add([(T.REFERENCE, _TEMPLATES[T.REFERENCE].encode(tuple(np.asarray(e.reference).tolist()))),
                  (T.TRUTH, _TEMPLATES[T.TRUTH].encode(tuple(np.asarray(e.truth).tolist())))], t_end, None)
        metrics = {"flight": self.index, "controller": h.controller, "run": h.run}
        metrics.update({key: float(v) for key, v in e.metrics.items()})
        log.write(T.SIM_METRICS, t_end, metrics)
        log.event(t_end, "flight_end", f"{h.controller} run {h.run}: {e.steps} steps", flight=self.index)


class InlineSimSink:
    """Writes simulated flights into a :class:`FlightLog` in this process (what ``simulate(log=FlightLog)`` uses)."""

    def __init__(self, log: FlightLog) -> None:
        self.log = log
        self._writer: SimFlightWriter | None = None

    def sim_begin(self, header: SimFlightHeader) -> None:
        self._writer = SimFlightWriter(self.log, header)

    def sim_block(self, block: SimBlock) -> None:
        self._writer.block(block)  # type: ignore[union-attr]

    def sim_end(self, end: SimFlightEnd) -> None:
        self._writer.end(end)  # type: ignore[union-attr]
        self._writer = None


def _rows(rows: list, k0: int, k1: int, width: int) -> np.ndarray:
    """``rows[k0:k1]`` (tuples of ``width`` floats) as an array, faster than ``np.array``."""
    n = k1 - k0
    flat = np.fromiter(itertools.chain.from_iterable(rows[k0:k1]), dtype=float, count=n * width)
    return flat.reshape(n, width)


class SimRecorder:
    """What :func:`gcs.sim.simulate` calls: shares the simulation's lists and hands them to the log in blocks.

    Parameters
    ----------
    log : FlightLog or BackgroundSimLog (anything with ``sim_begin/sim_block/sim_end``)
    config : gcs.config.Config
    controller : gcs.control.Controller
        The controller flown (for its horizon schedule).
    name : str
        Its name as given to ``simulate``.
    states, refs, cmds, j_log : list
        The simulation's own lists (states has one more entry than the others), appended by it.
    """

    def __init__(self, log: Any, config: Any, controller: Any, name: str, *, run: int, seed: int, mission: Any,
                 steps: int, cost: Any, states: list, refs: list, cmds: list, j_log: list) -> None:
        self.sink = InlineSimSink(log) if isinstance(log, FlightLog) else log
        self.states, self.refs, self.cmds, self.j_log = states, refs, cmds, j_log
        self.estimates: list = []
        self.sent = 0
        header = SimFlightHeader(
            name, config.experiment.name, run, seed, config.experiment.ts_s, steps,
            getattr(controller, "horizon_steps", None), getattr(controller, "after", None),
            tuple((float(s.t_start_s), s.phase.kind, int(s.index)) for s in mission.segments), cost,
            config.vehicle.mass_kg, config.vehicle.gravity_m_s2)
        self.sink.sim_begin(header)

    def tick(self, estimate: Sequence[float]) -> None:
        """After each tick (the simulation has appended to its lists)."""
        self.estimates.append(estimate)
        if len(self.estimates) >= BLOCK_TICKS:
            self._send(self.sent + len(self.estimates))

    def _send(self, k1: int) -> None:
        k0 = self.sent
        if k1 <= k0:
            return
        n = k1 - k0
        self.sink.sim_block(SimBlock(k0, _rows(self.states, k0, k1, 12), _rows(self.estimates, 0, n, 12),
                                     _rows(self.refs, k0, k1, 12), _rows(self.cmds, k0, k1, 4),
                                     np.array(self.j_log[k0:k1], dtype=np.int64)))
        self.estimates.clear()  # sent: the simulation keeps only what its metrics need
        self.sent = k1

    def finish(self, metrics: Mapping[str, float]) -> None:
        """After the flight: the remaining ticks, the final state and reference, the metrics."""
        k = len(self.cmds)
        self._send(k)
        self.sink.sim_end(SimFlightEnd(k, np.array(self.states[k], float), np.array(self.refs[k], float),
                                       dict(metrics)))


# --------------------------------------------------------------------------- background writer process

def spawn_writer(path: Path) -> subprocess.Popen:
    """Start ``python -m gcs.log.worker`` (stdin/stdout pipes) for the log at ``path``.

    Its own session: a Ctrl-C at the terminal reaches this process only, which decides when
    the log ends.

    Raises
    ------
    LogError
        When the process cannot start.
    """
    import gcs

    env = dict(os.environ)
    root = str(Path(gcs.__file__).resolve().parent.parent)
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    try:
        return subprocess.Popen([sys.executable, "-m", "gcs.log.worker"], stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, env=env, start_new_session=True)
    except OSError as exc:
        raise LogError(f"{path}: cannot start the log writer process: {exc.strerror or exc}") from None


def _send(stream: Any, obj: Any) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(struct.pack("<Q", len(data)))
    stream.write(data)
    stream.flush()


def _recv(stream: Any) -> Any:
    """One framed object, or None at the end of the stream."""
    head = stream.read(8)
    if len(head) < 8:
        return None
    (n,) = struct.unpack("<Q", head)
    data = stream.read(n)
    if len(data) < n:
        return None
    return pickle.loads(data)


class BackgroundSimLog:
    """A :class:`FlightLog` written by a separate process (``python -m gcs.log.worker``), fed simulated flights.

    Parameters
    ----------
    path : path-like
    expected_bytes : int
        For the free-space check (run here, before the process starts).
    max_pending : int
        Items (blocks of :data:`BLOCK_TICKS` ticks, about 0.3 MB each) queued here before
        the simulation waits for the writer.
    **log_kwargs
        Passed to :class:`FlightLog` in the writer process.

    Items are pickled here and written to the writer's stdin by a sender thread, so the
    simulation neither waits for the writer to start nor for each block to be taken.
    :meth:`close` (or leaving the ``with`` block, also on an exception or Ctrl-C, which the
    writer does not see) waits for it to finish the file; should this process die, the writer
    sees its stdin close and finishes the file too.
    """

    def __init__(self, path: str | os.PathLike, *, expected_bytes: int = 0, max_pending: int = 32,
                 **log_kwargs: Any) -> None:
        self.path = check_writable(path, expected_bytes)
        self._proc = spawn_writer(self.path)
        self._closed = False
        self.stats: dict[str, int] = {}
        self._queue: queue.Queue = queue.Queue(maxsize=max_pending)
        self._broken = threading.Event()
        self._sender = threading.Thread(target=self._send_loop, name="gcs-log-sender", daemon=True)
        self._sender.start()
        self._put(("open", str(self.path), log_kwargs))

    def __enter__(self) -> "BackgroundSimLog":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            self.close()
        except LogError:
            if exc_type is None:
                raise

    def _send_loop(self) -> None:
        """Writes queued frames to the writer (the GIL is released while the pipe is full)."""
        stdin = self._proc.stdin
        while True:
            frame = self._queue.get()
            if frame is None:
                break
            try:
                stdin.write(frame)  # type: ignore[union-attr]
                stdin.flush()  # type: ignore[union-attr]
            except (BrokenPipeError, OSError, ValueError):
                self._broken.set()
                break
        try:
            stdin.close()  # type: ignore[union-attr]
        except OSError:
            pass

    def _result(self) -> LogError | None:
        """Wait for the writer's last word: None when it finished the file, else the error."""
        self._sender.join()
        result = _recv(self._proc.stdout)
        self._proc.wait()
        self._closed = True
        if result is not None and result[0] == "done":
            self.stats = dict(result[1])
            return None
        if result is not None and result[0] == "error":
            return LogError(f"{self.path}: the log writer failed: {result[1]}")
        return LogError(f"{self.path}: the log writer process ended unexpectedly (exit code {self._proc.returncode})")

    def _put(self, item: tuple) -> None:
        if self._closed:
            raise LogError(f"{self.path}: the log is closed")
        data = pickle.dumps(item, protocol=pickle.HIGHEST_PROTOCOL)
        self._enqueue(struct.pack("<Q", len(data)) + data)

    def _enqueue(self, frame: bytes | None) -> None:
        """Queue a frame (None: stop the sender), unless the writer stopped reading: then its error."""
        while True:
            if self._broken.is_set() or not self._sender.is_alive():
                self._drain()
                raise self._result() or LogError(f"{self.path}: the log writer stopped early")
            try:
                self._queue.put(frame, timeout=0.5)
                return
            except queue.Full:
                continue

    def _drain(self) -> None:
        """Empty the queue and stop the sender (after the writer stopped reading)."""
        while True:
            try:
                self._queue.get_nowait()
            except queue.Empty:
                break
        try:
            self._queue.put_nowait(None)
        except queue.Full:  # pragma: no cover - just emptied
            pass

    def sim_begin(self, header: SimFlightHeader) -> None:
        self._put(("begin", header))

    def sim_block(self, block: SimBlock) -> None:
        """Hand ticks to the writer (waits only when ``max_pending`` items are queued)."""
        self._put(("block", block))

    def sim_end(self, end: SimFlightEnd) -> None:
        self._put(("end", end))

    def metadata(self, name: str, data: Mapping[str, Any]) -> None:
        self._put(("metadata", name, {str(k): str(v) for k, v in data.items()}))

    def attachment(self, name: str, media_type: str, data: bytes | str) -> None:
        self._put(("attachment", name, media_type, data.encode() if isinstance(data, str) else bytes(data)))

    def close(self) -> dict[str, int]:
        """Wait for the writer to finish the file; returns ``{"messages", "flights", "bytes"}``.

        Raises
        ------
        LogError
            When the writer failed.
        """
        if self._closed:
            return self.stats
        self._put(("close",))
        self._enqueue(None)  # the sender stops after the close frame and closes the pipe
        error = self._result()
        if error is not None:
            raise error
        return self.stats
