"""The log writer process of :class:`gcs.log.simlog.BackgroundSimLog`: ``python -m gcs.log.worker``.

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
    path, kwargs = first[1], first[2]
    try:
        log = FlightLog(path, check=False, **kwargs)
    except LogError as exc:
        _send(out, ("error", str(exc)))
        return 1
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
    try:
        log.close()
    except LogError as exc:
        error = error or str(exc)
    try:
        if error is not None:
            _send(out, ("error", error))
            return 1
        _send(out, ("done", {"messages": log.message_count, "flights": log.flight_count,
                             "bytes": os.path.getsize(path)}))
    except (BrokenPipeError, OSError):
        return 1  # nobody is listening any more; the file is finished anyway
    return 0


if __name__ == "__main__":
    sys.exit(main())
