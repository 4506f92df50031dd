"""MAVFTP (FILE_TRANSFER_PROTOCOL) of the emulated ArduCopter: the parameter file ``@PARAM/param.pck``.

As ArduPilot's ``GCS_FTP.cpp`` and ``AP_Filesystem_Param.cpp``: one session; OpenFileRO of
``@PARAM/param.pck`` (options ``?withdefaults=1``, ``start=``, ``count=``) answers ACK with a size
estimate (12 bytes a parameter); ReadFile and BurstReadFile serve the packed parameter file (a burst
sends the file from the offset to its end, then NACK EndOfFile); TerminateSession / ResetSessions
close; None is ACKed.  Every other file is FileNotFound, every write, directory or CRC operation a
NACK (FailErrno EROFS / FileNotFound), so a client that wants something else falls back at once.

Packed format (little endian)::

    header   uint16 magic 0x671b (0x671c with defaults), uint16 num_params, uint16 total_params
    entry    uint8 type | flags << 4  (AP_Param type: 1 int8, 2 int16, 3 int32, 4 float;
                                      flag 1: a default follows the value)
             uint8 common_len | (name_len - 1) << 4   (name bytes shared with the previous entry)
             name[name_len], value, [default]

Zero pad bytes keep a value from crossing a read-size boundary (the size of the first read), so
that a block read again gives the same bytes.  The values are those at the first read.
"""

from __future__ import annotations

import errno
import struct

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sitl.copter.params import ParamStore

__all__ = ["FtpServer", "pack_params", "OP", "ERR"]

M = mavlink


class OP:
    """FTP opcodes."""

    NONE, TERMINATE, RESET, LIST, OPEN_RO, READ, CREATE, WRITE, REMOVE, MKDIR, RMDIR, OPEN_WO, TRUNCATE, \
        RENAME, CRC32, BURST = range(16)
    ACK, NACK = 128, 129


class ERR:
    """FTP NACK error codes (first data byte)."""

    NONE, FAIL, FAIL_ERRNO, INVALID_SIZE, INVALID_SESSION, NO_SESSIONS, EOF, UNKNOWN, EXISTS, PROTECTED, \
        NOT_FOUND = range(11)


_DATA = 239  # payload data bytes
_HEADER = struct.Struct("<HBBBBBxI")
_MAGIC, _MAGIC_DEFAULTS = 0x671B, 0x671C
# MAV_PARAM_TYPE -> (AP_Param type, struct format)
_TYPES = {1: (1, "b"), 2: (1, "b"), 3: (2, "h"), 4: (2, "h"), 5: (3, "i"), 6: (3, "i"), 9: (4, "f")}
_NAME = "param.pck"


def _pack_value(fmt: str, value: float) -> bytes:
    return struct.pack("<" + fmt, int(round(value)) if fmt != "f" else value)


def pack_params(params: ParamStore, read_size: int, with_defaults: bool = False, start: int = 0,
                count: int = 0) -> bytes:
    """The ``param.pck`` file for reads of ``read_size`` bytes (see the module docstring)."""
    names = list(params)
    total = len(names)
    chosen = names[start:start + count] if count else names[start:]
    out = bytearray(struct.pack("<HHH", _MAGIC_DEFAULTS if with_defaults else _MAGIC, len(chosen), total))
    last = b""
    for name in chosen:
        spec = params.spec(name)
        ap_type, fmt = _TYPES.get(spec.ptype, (4, "f"))
        raw = name.encode("ascii")
        common = 0
        while common < min(len(raw), len(last), 15) and raw[common] == last[common]:
            common += 1
        if common == len(raw):  # at least one name byte
            common -= 1
        rest = raw[common:][:16]
        value = params[name]
        add_default = with_defaults and float(spec.default) != value
        data = _pack_value(fmt, value) + (_pack_value(fmt, float(spec.default)) if add_default else b"")
        entry = bytes([ap_type | (int(add_default) << 4), common | ((len(rest) - 1) << 4)]) + rest + data
        size = struct.calcsize(fmt)
        if size > 1:
            mod = (len(out) + len(entry)) % read_size
            if 0 < mod < size:
                out += bytes(size - mod)
        out += entry
        last = raw
    return bytes(out)


def _parse_name(data: bytes) -> tuple[str, dict[str, int]] | None:
    """``("param.pck", options)`` for ``@PARAM/param.pck[?k=v&...]``, None for any other file."""
    path = data.split(b"\x00", 1)[0].decode("ascii", errors="replace")
    if not path.startswith("@PARAM/"):
        return None
    name, _, query = path[len("@PARAM/"):].partition("?")
    if name != _NAME:
        return None
    opts: dict[str, int] = {}
    for part in filter(None, query.split("&")):
        key, _, val = part.partition("=")
        if key not in ("start", "count", "withdefaults") or not val.isdigit():
            return None
        opts[key] = int(val)
    if opts.get("withdefaults", 0) > 1 or opts.get("start", 0) >= 65535 or opts.get("count", 0) >= 65535:
        return None
    return name, opts


class FtpServer:
    """The MAVFTP session of one vehicle."""

    def __init__(self, params: ParamStore) -> None:
        self.params = params
        self._open: dict[str, int] | None = None
        self._file: bytes | None = None
        self._read_size = 0
        self.requests = 0

    def handle(self, payload: bytes | list[int]) -> list[bytes]:
        """Replies (payloads, 251 bytes each) to one request payload."""
        self.requests += 1
        p = bytes(payload)[:251].ljust(251, b"\x00")
        seq, session, opcode, size, _req, _burst, offset = _HEADER.unpack_from(p)
        data = p[12:12 + min(size, _DATA)]
        head = (seq, session, opcode)
        if size > _DATA:
            return [self._nack(head, ERR.INVALID_SIZE)]
        if opcode in (OP.ACK, OP.NACK):
            return []
        if opcode == OP.NONE:
            return [self._reply(head, 1, OP.ACK, b"")]
        if opcode in (OP.TERMINATE, OP.RESET):
            self._close()
            return [self._reply(head, 1, OP.ACK, b"")]
        if opcode == OP.OPEN_RO:
            return [self._open_ro(head, data)]
        if opcode in (OP.READ, OP.BURST):
            return self._read(head, offset, size, opcode == OP.BURST)
        if opcode in (OP.LIST, OP.REMOVE, OP.RMDIR, OP.CRC32, OP.TRUNCATE, OP.RENAME):
            return [self._nack(head, ERR.NOT_FOUND)]
        if opcode in (OP.CREATE, OP.WRITE, OP.MKDIR, OP.OPEN_WO):
            return [self._nack(head, ERR.FAIL_ERRNO, errno.EROFS)]
        return [self._nack(head, ERR.UNKNOWN)]

    # ------------------------------------------------------------------ helpers
    def _close(self) -> None:
        self._open, self._file, self._read_size = None, None, 0

    @staticmethod
    def _reply(head, seq_inc: int, opcode: int, data: bytes, offset: int = 0, burst_complete: bool = False) -> bytes:
        seq, session, req = head
        return (_HEADER.pack((seq + seq_inc) & 0xFFFF, session, opcode, len(data), req, int(burst_complete), offset)
                + data).ljust(251, b"\x00")

    def _nack(self, head, error: int, err_no: int | None = None, seq_inc: int = 1, offset: int = 0) -> bytes:
        data = bytes([error]) if err_no is None else bytes([error, err_no])
        return self._reply(head, seq_inc, OP.NACK, data, offset, burst_complete=True)

    def _open_ro(self, head, data: bytes) -> bytes:
        if self._open is not None:
            return self._nack(head, ERR.FAIL)
        parsed = _parse_name(data)
        if parsed is None:
            return self._nack(head, ERR.NOT_FOUND)
        self._open = parsed[1]
        return self._reply(head, 1, OP.ACK, struct.pack("<I", len(self.params) * 12))

    def _read(self, head, offset: int, size: int, burst: bool) -> list[bytes]:
        if self._open is None:
            return [self._nack(head, ERR.NOT_FOUND)]
        want = size if size else _DATA
        if self._file is None:
            o = self._open
            self._read_size = want
            self._file = pack_params(self.params, want, bool(o.get("withdefaults", 0)), o.get("start", 0),
                                     o.get("count", 0))
        elif want != self._read_size:
            return [self._nack(head, ERR.FAIL_ERRNO, errno.EINVAL)]
        f = self._file
        if not burst:
            chunk = f[offset:offset + min(want, _DATA)]
            if not chunk:
                return [self._nack(head, ERR.EOF, offset=offset)]
            return [self._reply(head, 1, OP.ACK, chunk, offset)]
        out = []
        i = 0
        pos = offset
        while True:
            chunk = f[pos:pos + min(want, _DATA)]
            if not chunk:
                out.append(self._nack(head, ERR.EOF, seq_inc=i + 1, offset=pos))
                return out
            out.append(self._reply(head, i + 1, OP.ACK, chunk, pos, burst_complete=len(chunk) < want))
            pos += len(chunk)
            i += 1


def ftp_message(reply: bytes, target_system: int, target_component: int) -> mavlink.MAVLink_message:
    """The FILE_TRANSFER_PROTOCOL carrying ``reply``."""
    return M.MAVLink_file_transfer_protocol_message(0, target_system, target_component, list(reply))
