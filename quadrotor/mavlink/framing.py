"""Taking MAVLink frames out of received bytes with pymavlink, never raising on hostile input.

A UDP datagram is parsed on its own: a frame cut at the datagram's end is dropped (the parser
is reset), never joined to the next datagram — a stray one-byte ``0xFD`` datagram would
otherwise swallow the next real frame.  A stream (TCP, serial) keeps its partial frame.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as mavlink

__all__ = ["reset_parser", "parse_bytes"]


def reset_parser(mav: mavlink.MAVLink) -> None:
    """Drop whatever partial frame a pymavlink parser holds."""
    mav.buf = bytearray()
    mav.buf_index = 0
    mav.expected_length = mavlink.HEADER_LEN_V1 + 2
    mav.have_prefix_error = False


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
