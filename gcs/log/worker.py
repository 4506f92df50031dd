"""The log writer process of :class:`gcs.log.simlog.BackgroundSimLog` and
:class:`gcs.log.flightlog.BackgroundFlightLog`: ``python -m gcs.log.worker``.

Flight logs (``("open", path, {..., "flight": True})``): then framed pickled lists of the
items of :mod:`gcs.log.flightlog`, ending with ``[("close",)]`` or the end of stdin.

Simulation logs:

Reads framed pickles from stdin — ``("open", path, kwargs)``, then per flight ``("begin",
SimFlightHeader)``, ``("block", SimBlock)``... ``("end", SimFlightEnd)``, and
``("metadata", name, dict)``, ``("attachment", name, media_type, bytes)``, ``("close",)`` — and
writes one framed result to stdout: ``("done", {"messages", "flights", "bytes"})`` or
``("error", text)``.  The end of stdin (the parent died) closes the log like ``close``.
Ctrl-C is ignored: the parent decides when the log ends.
"""

from __future__ import annotations

import os
import queue
import signal
import sys
import threading
import traceback

#: Items read ahead of the writer (blocks of ticks, about 0.3 MB each).
READ_AHEAD = 64


def main() -> int:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    from gcs.errors import LogError
    from gcs.log.simlog import SimFlightWriter, _recv, _send
    from gcs.log.writer import FlightLog

    inp, out = sys.stdin.buffer, sys.stdout.buffer
    first = _recv(inp)
    if first is None or first[0] != "open":
        return 2
    path, kwargs = first[1], dict(first[2])
    flight_mode = bool(kwargs.pop("flight", False))
    try:
        log = FlightLog(path, check=False, **kwargs)
    except LogError as exc:
        _send(out, ("error", str(exc)))
        return 1
    if flight_mode:
        return _flight(log, path, inp, out)
    # A reader thread keeps taking blocks from the pipe while this one formats and compresses
    # (both release the GIL for their I/O), so the simulation rarely waits on a full pipe.
    pending: queue.Queue = queue.Queue(maxsize=READ_AHEAD)

    def read_ahead() -> None:
        while True:
            try:
                item = _recv(inp)
            except Exception as exc:  # a garbled frame: hand the failure to the main loop, which stops
                pending.put(("failed", f"cannot read from the simulation: {type(exc).__name__}: {exc}"))
                return
            pending.put(item)
            if item is None or item[0] == "close":
                return

    threading.Thread(target=read_ahead, name="gcs-log-read-ahead", daemon=True).start()
    error = None
    flight = None
    try:
        while True:
            item = pending.get()
            if item is None or item[0] == "close":
                break
            if item[0] == "block":
                flight.block(item[1])  # type: ignore[union-attr]
            elif item[0] == "begin":
                flight = SimFlightWriter(log, item[1])
            elif item[0] == "end":
                flight.end(item[1])  # type: ignore[union-attr]
                flight = None
            elif item[0] == "metadata":
                log.metadata(item[1], item[2])
            elif item[0] == "attachment":
                log.attachment(item[1], item[2], item[3])
            elif item[0] == "failed":
                error = item[1]
                break
    except LogError as exc:
        error = str(exc)
    except Exception as exc:  # a process boundary: report any failure to the parent, then finish the file
        error = f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}"
    return _close(log, path, out, error, flights=log.flight_count)


def _close(log, path: str, out, error: str | None, **stats) -> int:
    """Finish the file and tell the parent: ("done", {"messages", "bytes", **stats}) or ("error", text)."""
    from gcs.errors import LogError
    from gcs.log.simlog import _send

    try:
        log.close()
    except LogError as exc:
        error = error or str(exc)
    try:
        if error is not None:
            _send(out, ("error", error))
            return 1
        _send(out, ("done", {"messages": log.message_count, "bytes": os.path.getsize(path), **stats}))
    except (BrokenPipeError, OSError):
        return 1  # nobody is listening any more; the file is finished anyway
    return 0


def _flight(log, path: str, inp, out) -> int:
    """Write a flight's items until ("close",) or the end of stdin (the ground station died)."""
    from gcs.errors import LogError
    from gcs.log.flightlog import FlightItemWriter
    from gcs.log.simlog import _recv

    writer = FlightItemWriter(log)
    try:
        os.nice(10)  # a background job: the flight loop (and a SITL beside it) come first
    except OSError:
        pass
    error = None
    try:
        while True:
            try:
                items = _recv(inp)
            except Exception as exc:  # a garbled frame (the parent died mid-write): keep what we have
                error = f"cannot read from the ground station: {type(exc).__name__}: {exc}"
                break
            if items is None:
                break
            if items and items[-1][0] == "close":
                for item in items[:-1]:
                    writer.apply(item)
                break
            for item in items:
                writer.apply(item)
    except LogError as exc:
        error = str(exc)
    except Exception as exc:  # a process boundary: report any failure, then finish the file
        error = f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}"
    return _close(log, path, out, error, undecodable=writer.undecodable)


if __name__ == "__main__":
    try:
        sys.exit(main())
    except OSError as exc:  # the disk failed under the writer: one line, no traceback (the parent warns)
        print(f"gcs log writer: {exc.strerror or exc}", file=sys.stderr)
        sys.exit(1)
