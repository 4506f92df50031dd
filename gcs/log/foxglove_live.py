"""``gcs fly --live [HOST:]PORT``: the log's channels served live on the Foxglove WebSocket protocol.

:class:`LiveServer` runs a Foxglove WebSocket server (the ``foxglove-sdk`` package, its own threads) in
the log writer process (:mod:`gcs.log.worker`) and publishes every message the log gets, as the log
gets it: the same topics, schemas (:mod:`gcs.log.topics`, the Foxglove well-known ones of
:mod:`gcs.log.foxglove` included) and bytes.  :func:`tee` hooks it to a
:class:`~gcs.log.writer.FlightLog`.  The control loop pays nothing more: the records reach the writer
process as before, and a slow or vanished viewer costs the writer a dropped message, never the flight.
Open it in Foxglove with *Open connection* → *Foxglove WebSocket* → ``ws://HOST:PORT`` (the layout in
docs/foxglove-layout.json applies).  Message times are the log's (``log_time_ns``).
"""

from __future__ import annotations

import sys
from collections.abc import Iterable
from typing import Any

from gcs.log import topics as T

__all__ = ["DEFAULT_HOST", "LIVE_TOPICS", "LiveServer", "live_argument", "parse_address", "start_for", "tee"]

#: Topics every flight's log carries, advertised as the server starts: a viewer connecting early subscribes
#: to them at once.  (A channel created with its first message can race a viewer's subscription, which
#: the SDK then refuses as "unknown channel" without a word to the viewer.)
LIVE_TOPICS = (T.STATE, T.REFERENCE, T.COMMAND, T.EVENTS, T.FOXGLOVE_TF, T.FOXGLOVE_VEHICLE_POSE,
               T.FOXGLOVE_REFERENCE_POSE, T.FOXGLOVE_LOG)

#: Host served when ``--live`` names a port only (this machine; ``0.0.0.0`` serves every interface).
DEFAULT_HOST = "127.0.0.1"


def parse_address(text: str) -> tuple[str, int]:
    """``(host, port)`` of ``[HOST:]PORT`` (port 0: any free one).

    Raises
    ------
    ValueError
        A port that is not an integer in 0 .. 65535, or an empty host.
    """
    host, sep, port = str(text).rpartition(":")
    if not sep:
        host = DEFAULT_HOST
    host = host.strip("[]")  # [::1]:8765
    try:
        number = int(port)
    except ValueError:
        raise ValueError(f"--live: {text!r} is not [HOST:]PORT (a port number 0 .. 65535)") from None
    if not 0 <= number <= 65535 or not host:
        raise ValueError(f"--live: {text!r} is not [HOST:]PORT (a port number 0 .. 65535)")
    return host, number


class LiveServer:
    """A Foxglove WebSocket server publishing log messages (``foxglove-sdk``).

    Parameters
    ----------
    host : str
    port : int
        0: a free port (see :attr:`port`).
    name : str
        The server name viewers show.
    topics : iterable of str
        Channels advertised at once (others appear with their first message).

    Raises
    ------
    RuntimeError
        The server could not start (the port is taken, foxglove-sdk is not installed).
    """

    def __init__(self, host: str = DEFAULT_HOST, port: int = 8765, name: str = "gcs",
                 topics: Iterable[str] = ()) -> None:
        try:
            import foxglove
        except ImportError:
            raise RuntimeError("--live needs the foxglove-sdk package: pip install 'quadrotor-gcs[live]' "
                               "(or pip install foxglove-sdk)") from None
        self._fox = foxglove
        self.context = foxglove.Context()
        try:
            self.server = foxglove.start_server(name=name, host=host, port=port, context=self.context)
        except Exception as exc:  # noqa: BLE001  the SDK raises its own errors (a taken port, a bad host)
            raise RuntimeError(f"--live {host}:{port}: cannot serve: {exc}") from None
        self.host = host
        self._channels: dict[str, Any] = {}
        self.published = 0
        #: Messages the SDK refused (counted; the log has them all the same).
        self.failed = 0
        for topic in topics:
            self._channel(topic)

    @property
    def port(self) -> int:
        """The port served."""
        return int(self.server.port)

    def _channel(self, topic: str) -> Any:
        ch = self._channels.get(topic)
        if ch is None:
            name, schema = T.schema_json(topic)
            ch = self._channels[topic] = self._fox.Channel(
                topic, schema=self._fox.Schema(name=name, encoding="jsonschema", data=schema), message_encoding="json",
                context=self.context)
        return ch

    def publish(self, items: Iterable[tuple[str, bytes]], log_time_ns: int) -> None:
        """``(topic, JSON bytes)`` pairs at one log time [ns], to every viewer subscribed."""
        for topic, data in items:
            try:
                self._channel(topic).log(bytes(data), log_time=int(log_time_ns))
            except Exception:  # noqa: BLE001  a viewer never stops the log: the SDK's errors are counted
                self.failed += 1
            else:
                self.published += 1

    def close(self) -> None:
        """Stop serving (idempotent)."""
        server, self.server = self.server, None
        if server is not None:
            server.stop()


def tee(log: Any, live: LiveServer) -> None:
    """Publish every message ``log`` (a :class:`~gcs.log.writer.FlightLog`) writes on ``live`` too, after
    the file has it (every write method of the log goes through its ``add``)."""
    write = log.add

    def add(items: Iterable[tuple[str, bytes]], log_time_ns: int, publish_time_ns: int | None = None) -> None:
        items = items if isinstance(items, (list, tuple)) else list(items)
        write(items, log_time_ns, publish_time_ns)
        live.publish(items, log_time_ns)

    log.add = add


def start_for(log: Any, address: str) -> LiveServer | None:
    """Serve ``log`` live on ``address`` ([HOST:]PORT); None (and a line on stderr) when it cannot be served:
    the flight and its log go on without it."""
    try:
        host, port = parse_address(address)
        live = LiveServer(host, port, topics=LIVE_TOPICS)
    except (ValueError, RuntimeError) as exc:
        print(f"gcs: warning: {exc}; flying without the live view", file=sys.stderr)
        return None
    tee(log, live)
    print(f"gcs: live on ws://{live.host}:{live.port} (Foxglove: Open connection, Foxglove WebSocket)",
          file=sys.stderr)
    return live


def live_argument(text: str) -> str:
    """The ``argparse`` type of ``--live``: ``[HOST:]PORT`` checked (a usage error otherwise), as given."""
    import argparse

    try:
        parse_address(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("--live: ")) from None
    return text
