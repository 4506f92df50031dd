"""Taking MAVLink frames out of received bytes with pymavlink, never raising on hostile input.

A UDP datagram is parsed on its own: a frame cut at the datagram's end is dropped (the parser
is reset), never joined to the next datagram — a stray one-byte ``0xFD`` datagram would
otherwise swallow the next real frame.  A stream (TCP, serial) keeps its partial frame.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as mavlink

__all__ = ["reset_parser", "parse_bytes", "restore_unknown_header", "unknown_payload"]


def reset_parser(mav: mavlink.MAVLink) -> None:
    """Drop whatever partial frame a pymavlink parser holds."""
    mav.buf = bytearray()
    mav.buf_index = 0
    mav.expected_length = mavlink.HEADER_LEN_V1 + 2
    mav.have_prefix_error = False


def restore_unknown_header(msg) -> None:
    """Give a message of an id the dialect lacks (pymavlink's ``MAVLink_unknown``, e.g. PX4's EVENT 410)
    the header of its frame: pymavlink returns those before reading it (source system 0).  Its CRC
    cannot be checked (no CRC_EXTRA is known): it is for display, never for control."""
    if not isinstance(msg, mavlink.MAVLink_unknown):
        return
    data = bytes(msg.data)
    h = msg._header
    if len(data) >= 10 and data[0] == mavlink.PROTOCOL_MARKER_V2:
        h.mlen, h.incompat_flags, h.compat_flags, h.seq, h.srcSystem, h.srcComponent = data[1:7]
    elif len(data) >= 6 and data[0] == mavlink.PROTOCOL_MARKER_V1:
        h.mlen, h.seq, h.srcSystem, h.srcComponent = data[1:5]


def unknown_payload(msg) -> bytes:
    """The payload of a ``MAVLink_unknown`` message (its frame without header, CRC and signature)."""
    data = bytes(msg.data)
    if data and data[0] == mavlink.PROTOCOL_MARKER_V2:
        return data[10:10 + data[1]]
    return data[6:6 + data[1]] if len(data) > 1 else b""


def parse_bytes(mav: mavlink.MAVLink, data: bytes, *, datagram: bool) -> tuple[list, bool, bool]:
    """Every message in ``data`` (pymavlink's BAD_DATA included).

    Returns
    -------
    messages : list
    failed : bool
        pymavlink raised on these bytes (the parser was reset; the caller counts it).
    truncated : bool
        ``datagram`` and the datagram ended inside a frame (dropped, the parser reset).
    """
    try:
        msgs = mav.parse_buffer(data) or []
    except Exception:  # noqa: BLE001 - pymavlink raises anything (struct.error, IndexError, ...) on hostile bytes
        reset_parser(mav)
        return [], True, False
    if datagram and mav.buf_len() > 0:
        reset_parser(mav)
        return msgs, False, True
    return msgs, False, False
