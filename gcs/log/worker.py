"""The log writer process of :class:`gcs.log.sink.BackgroundSink`: ``python -m gcs.log.worker``.

Reads frames of records (:mod:`gcs.log.framing`) from stdin — an
:class:`~gcs.log.records.OpenLog` first, then any records of :mod:`gcs.log.records`, up to a
:class:`~gcs.log.records.CloseLog` or the end of stdin (the producer died: the file is
finished just the same) — writes them with :class:`gcs.log.foxglove_encoder.FoxgloveEncoder` and answers
with one frame on stdout: :class:`~gcs.log.records.LogDone` (``{"messages", "bytes",
"flights", "undecodable"}``) or :class:`~gcs.log.records.LogFailed`.  Ctrl-C is ignored: the
producer decides when the log ends.
"""

from __future__ import annotations

import contextlib
import os
import queue
import signal
import sys
import threading
import traceback
from typing import Any

#: Frames read ahead of the writer (blocks of simulated ticks are about 0.3 MB each).
READ_AHEAD = 64


def _read_ahead(inp: Any, pending: queue.Queue) -> None:
    """Keep taking frames from the pipe while the main thread formats and compresses (both release
    the GIL for their I/O), so the producer rarely waits on a full pipe."""
    from gcs.log.framing import read_frame
    from gcs.log.records import CloseLog

    while True:
        try:
            records = read_frame(inp)
        except Exception as exc:  # noqa: BLE001  a garbled frame (the producer died mid-write): keep what we have
            pending.put(f"cannot read the log records: {type(exc).__name__}: {exc}")
            return
        pending.put(records)
        if records is None or any(type(r) is CloseLog for r in records):
            return


def _write(encoder: Any, inp: Any) -> str | None:
    """Write every record until CloseLog or the end of the input; the error, or None."""
    from gcs.errors import LogError
    from gcs.log.records import CloseLog

    pending: queue.Queue = queue.Queue(maxsize=READ_AHEAD)
    threading.Thread(target=_read_ahead, args=(inp, pending), name="gcs-log-read-ahead", daemon=True).start()
    try:
        while True:
            records = pending.get()
            if records is None:
                return None
            if isinstance(records, str):
                return records
            for r in records:
                if type(r) is CloseLog:
                    return None
                encoder.write(r)
    except LogError as exc:
        return str(exc)
    except Exception as exc:  # noqa: BLE001  process boundary: report any failure to the producer, then finish the file
        return f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}"


def main() -> int:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    from gcs.errors import LogError
    from gcs.log.foxglove_encoder import FoxgloveEncoder
    from gcs.log.framing import read_frame, write_frame
    from gcs.log.records import LogDone, LogFailed, OpenLog
    from gcs.log.writer import FlightLog

    inp, out = sys.stdin.buffer, sys.stdout.buffer
    first = read_frame(inp)
    if not first or type(first[0]) is not OpenLog:
        return 2
    opened = first[0]
    options = dict(opened.options)
    live = options.pop("live", None)  # gcs fly --live [HOST:]PORT: served from here (gcs.log.foxglove_live)
    try:
        log = FlightLog(opened.path, check=False, **options)
    except LogError as exc:
        write_frame(out, [LogFailed(str(exc))])
        return 1
    if opened.nice:
        with contextlib.suppress(OSError):
            os.nice(opened.nice)  # a background job: a real-time loop (and a SITL beside it) come first
    encoder = FoxgloveEncoder(log, live=live)
    error = _write(encoder, inp)
    try:
        log.close()
    except LogError as exc:
        error = error or str(exc)
    encoder.close()
    try:
        if error is not None:
            write_frame(out, [LogFailed(error)])
            return 1
        write_frame(out, [LogDone({"messages": log.message_count, "bytes": os.path.getsize(opened.path),
                                   "flights": log.flight_count, "undecodable": encoder.undecodable})])
    except OSError:
        return 1  # nobody is listening any more; the file is finished anyway
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except OSError as exc:  # the disk failed under the writer: one line, no traceback (the producer warns)
        print(f"gcs log writer: {exc.strerror or exc}", file=sys.stderr)
        sys.exit(1)
