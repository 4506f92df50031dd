"""MAVLink 2 signing for pymavlink parsers: signature checked before timestamps, state kept across restarts.

pymavlink's ``MAVLink.check_signature`` stores a stream's timestamp *before*
it compares the signature, so a single forged frame (valid framing and CRC,
any signature, a timestamp far in the future) makes every later genuine frame
of that stream look old: the real sender is locked out.  And a process that
starts with the local timestamp at 0 and no memory of its streams accepts a
frame captured before a restart.

This module (pymavlink and the standard library only, so that the vehicle and
the ground station can both use it) implements the rules of the MAVLink 2
signing specification in the right order:

1. the 48-bit SHA-256 signature (``sha256(key + frame[:-6])[:6]``) must match,
   else the frame is refused (``bad_signature``) and nothing is stored;
2. a frame of a known stream ``(link_id, system_id, component_id)`` must carry a
   timestamp greater than the stream's last accepted one (else ``replayed``);
3. the first frame of a new stream may be at most one minute
   (:data:`NEW_STREAM_WINDOW`) behind the local timestamp (else ``stale_timestamp``);
4. then the stream's timestamp is stored and the local timestamp (the one
   outgoing frames carry) is raised to it if it is newer.

Timestamps are in 10 us units since 2015-01-01 00:00 UTC; the local timestamp
starts at the wall clock (as pymavlink's ``mavfile.setup_signing`` does).

:class:`SigningStateFile` persists the local timestamp and the streams' last
timestamps, as ArduPilot keeps its signing timestamp in storage: written
atomically, at most once per ``min_interval_s`` while it changes, and at exit;
loaded at start so that frames captured before a restart are refused.

Usage (either side)::

    from quadrotor.mavlink.signing import setup_signing
    check = setup_signing(conn.mav, key, link_id=0)    # conn = mavutil.mavlink_connection(...)
    ...
    check.bad_signature, check.replayed, check.stale_timestamp
"""

from __future__ import annotations

import hashlib
import hmac
import json
import logging
import os
import struct
import tempfile
import time
from pathlib import Path
from collections.abc import Callable

from pymavlink.dialects.v20 import ardupilotmega as mavlink

__all__ = ["SignatureCheck", "SigningStateFile", "setup_signing", "install_signature_check",
           "wall_clock_timestamp", "default_state_path", "EPOCH_2015_S", "TIMESTAMP_UNITS_PER_S",
           "NEW_STREAM_WINDOW", "REJECT_BAD_SIGNATURE", "REJECT_REPLAYED", "REJECT_STALE"]

log = logging.getLogger(__name__)

EPOCH_2015_S = 1_420_070_400            # 2015-01-01 00:00:00 UTC in Unix seconds
TIMESTAMP_UNITS_PER_S = 100_000         # 10 us units
NEW_STREAM_WINDOW = 60 * TIMESTAMP_UNITS_PER_S
_TIMESTAMP_MAX = (1 << 48) - 1
_MAX_SAVED_STREAMS = 1024
_FORMAT = "quadrotor-sitl-signing-state"

REJECT_BAD_SIGNATURE = "bad_signature"
REJECT_REPLAYED = "replayed"
REJECT_STALE = "stale_timestamp"

StreamKey = tuple[int, int, int]  # (link_id, system_id, component_id), pymavlink's order
_TS = struct.Struct("<IH")


def wall_clock_timestamp(now_s: float | None = None) -> int:
    """Signing timestamp of the wall clock: 10 us units since 2015-01-01 UTC (0 for earlier clocks)."""
    t = time.time() if now_s is None else now_s
    return max(0, int((t - EPOCH_2015_S) * TIMESTAMP_UNITS_PER_S))


class SignatureCheck:
    """A replacement for ``MAVLink.check_signature`` that verifies the signature before any timestamp rule.

    One instance may be installed on several parsers (one per peer); they then
    share ``signing`` (key, local timestamp, stream timestamps) and the counts.

    Parameters
    ----------
    signing : MAVLinkSigning
        pymavlink's signing state (``secret_key`` must be set before frames arrive).
    new_stream_window : int
        How far behind the local timestamp the first frame of a new stream may be [10 us].

    Attributes
    ----------
    accepted, bad_signature, replayed, stale_timestamp : int
        Signed frames accepted; refused for a wrong signature; refused for a
        timestamp not after their stream's last; refused as a new stream too far
        behind the local timestamp.
    last_rejection : str
        Why the last refused frame was refused (one of the ``REJECT_*`` names), "" after an accepted one.
    version : int
        Incremented whenever a stream timestamp or the local timestamp was raised by
        an accepted frame (what :class:`SigningStateFile` watches).
    """

    def __init__(self, signing: mavlink.MAVLinkSigning, new_stream_window: int = NEW_STREAM_WINDOW) -> None:
        self.signing = signing
        self.new_stream_window = int(new_stream_window)
        self.accepted = 0
        self.bad_signature = 0
        self.replayed = 0
        self.stale_timestamp = 0
        self.last_rejection = ""
        self.version = 0

    def signature_ok(self, msgbuf: bytes | bytearray) -> bool:
        """True when the 6-byte signature at the end of ``msgbuf`` matches the key (constant time)."""
        key = self.signing.secret_key
        if key is None or len(msgbuf) < mavlink.MAVLINK_SIGNATURE_BLOCK_LEN + 1:
            return False
        digest = hashlib.sha256(bytes(key) + bytes(msgbuf[:-6])).digest()[:6]
        return hmac.compare_digest(digest, bytes(msgbuf[-6:]))

    def _reject(self, reason: str) -> bool:
        self.last_rejection = reason
        if reason == REJECT_BAD_SIGNATURE:
            self.bad_signature += 1
        elif reason == REJECT_REPLAYED:
            self.replayed += 1
        else:
            self.stale_timestamp += 1
        return False

    def __call__(self, msgbuf: bytes | bytearray, src_system: int, src_component: int) -> bool:
        """Accept or refuse one signed frame (pymavlink calls this from ``MAVLink.decode``)."""
        if not self.signature_ok(msgbuf):
            return self._reject(REJECT_BAD_SIGNATURE)
        link_id = msgbuf[-13]
        low, high = _TS.unpack(bytes(msgbuf[-12:-6]))
        timestamp = low | (high << 32)
        key: StreamKey = (int(link_id), int(src_system), int(src_component))
        s = self.signing
        last = s.stream_timestamps.get(key)
        if last is not None:
            if timestamp <= last:
                return self._reject(REJECT_REPLAYED)
        elif timestamp + self.new_stream_window < s.timestamp:
            return self._reject(REJECT_STALE)
        s.stream_timestamps[key] = timestamp
        if timestamp > s.timestamp:
            s.timestamp = timestamp
        self.accepted += 1
        self.version += 1
        self.last_rejection = ""
        return True


def install_signature_check(mav: mavlink.MAVLink, check: SignatureCheck | None = None) -> SignatureCheck:
    """Make ``mav`` verify incoming signatures with ``check`` (a new one on ``mav.signing`` if None).

    With a shared ``check``, ``mav.signing`` becomes ``check.signing``: every
    parser it is installed on shares the key, timestamps and counts.
    """
    if check is None:
        check = SignatureCheck(mav.signing)
    else:
        mav.signing = check.signing
    mav.check_signature = check  # type: ignore[method-assign]
    return check


def setup_signing(mav: mavlink.MAVLink, secret_key: bytes, *, sign_outgoing: bool = True, link_id: int = 0,
                  allow_unsigned_callback: Callable[[mavlink.MAVLink, int], bool] | None = None,
                  initial_timestamp: int | None = None) -> SignatureCheck:
    """Configure MAVLink 2 signing on a pymavlink ``MAVLink`` object with the corrected check.

    The local timestamp becomes the larger of its current value and
    ``initial_timestamp`` (default: :func:`wall_clock_timestamp`).

    Returns
    -------
    SignatureCheck
        The installed check (counts of accepted and refused frames).
    """
    key = bytes(secret_key)
    if len(key) != 32:
        raise ValueError(f"signing key must be 32 bytes, got {len(key)}")
    if not 0 <= link_id <= 255:
        raise ValueError(f"link_id must be in 0..255, got {link_id}")
    s = mav.signing
    s.secret_key = key
    s.sign_outgoing = sign_outgoing
    s.link_id = int(link_id)
    s.allow_unsigned_callback = allow_unsigned_callback
    start = wall_clock_timestamp() if initial_timestamp is None else int(initial_timestamp)
    s.timestamp = max(int(s.timestamp), start)
    return install_signature_check(mav)


def default_state_path(secret_key: bytes, system_id: int) -> Path:
    """``${XDG_CACHE_HOME:-~/.cache}/quadrotor-sitl/signing-<hash>.json``; the hash names key and system id.

    The name is a digest, never the key: a different key or system id has its own file.
    """
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    h = hashlib.sha256(b"quadrotor-sitl signing state\0" + bytes(secret_key) + int(system_id).to_bytes(2, "big"))
    return Path(base) / "quadrotor-sitl" / f"signing-{h.hexdigest()[:24]}.json"


class SigningStateFile:
    """The local signing timestamp and the streams' last timestamps, in a small JSON file.

    Parameters
    ----------
    path : str or PathLike
        The state file (its directory is created, mode 0700).
    min_interval_s : float
        :meth:`maybe_save` writes at most this often.
    clock_s : callable
        Monotonic clock [s] for the throttle.

    Attributes
    ----------
    saves : int
        Files written.
    load_error : str
        Why the file could not be used at :meth:`load` ("" if it was, or was absent).
    """

    def __init__(self, path: str | os.PathLike, min_interval_s: float = 1.0,
                 clock_s: Callable[[], float] = time.monotonic) -> None:
        self.path = Path(path)
        self.min_interval_s = float(min_interval_s)
        self._clock_s = clock_s
        self._last_save_s: float | None = None
        self._saved: tuple[int, int, int] | None = None
        self.saves = 0
        self.load_error = ""

    def load(self, signing: mavlink.MAVLinkSigning) -> bool:
        """Merge the file into ``signing``: stream timestamps (the larger wins) and the local timestamp.

        Returns True if a valid file was read.  An unreadable or corrupt file is
        logged and ignored (the wall clock and the new-stream window still apply).
        """
        try:
            doc = json.loads(self.path.read_text(encoding="utf-8"))
            if not isinstance(doc, dict) or doc.get("format") != _FORMAT or doc.get("version") != 1:
                raise ValueError("not a signing state file")
            local = _timestamp(doc["timestamp"])
            streams = [(_byte(a), _byte(b), _byte(c), _timestamp(t)) for a, b, c, t in doc["streams"]]
        except FileNotFoundError:
            return False
        except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError) as exc:
            self.load_error = f"{self.path}: {exc}"
            log.warning("signing state ignored: %s", self.load_error)
            return False
        st = signing.stream_timestamps
        for link_id, sysid, compid, ts in streams:
            key = (link_id, sysid, compid)
            if ts > st.get(key, -1):
                st[key] = ts
        newest = max([local, *(s[3] for s in streams)])
        signing.timestamp = max(int(signing.timestamp), newest)
        return True

    @staticmethod
    def _fingerprint(signing: mavlink.MAVLinkSigning) -> tuple[int, int, int]:
        # A stream's timestamp only ever grows, so the sum changes whenever one is stored.
        st = signing.stream_timestamps
        return int(signing.timestamp), len(st), sum(st.values())

    def save(self, signing: mavlink.MAVLinkSigning) -> None:
        """Write the state now, atomically (temporary file in the same directory, fsync, rename)."""
        streams = sorted(signing.stream_timestamps.items(), key=lambda kv: kv[1], reverse=True)[:_MAX_SAVED_STREAMS]
        doc = {"format": _FORMAT, "version": 1, "timestamp": int(signing.timestamp),
               "streams": [[k[0], k[1], k[2], int(t)] for k, t in streams]}
        self.path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".signing-", suffix=".tmp", dir=self.path.parent)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                json.dump(doc, f, separators=(",", ":"))
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, self.path)
        except BaseException:
            try:
                os.unlink(tmp)
            except FileNotFoundError:
                pass
            raise
        self.saves += 1
        self._saved = self._fingerprint(signing)
        self._last_save_s = self._clock_s()

    def maybe_save(self, signing: mavlink.MAVLinkSigning, force: bool = False) -> bool:
        """Save if the state changed and ``min_interval_s`` passed since the last save (or ``force``).

        Returns True if the file was written.  A failed write is logged, not raised
        (the vehicle keeps flying; the next attempt comes after the interval).
        """
        if not force and self._last_save_s is not None and self._clock_s() - self._last_save_s < self.min_interval_s:
            return False
        if self._saved is not None and self._fingerprint(signing) == self._saved:
            return False
        try:
            self.save(signing)
        except OSError as exc:
            self._last_save_s = self._clock_s()
            log.warning("cannot write the signing state %s: %s", self.path, exc.strerror or exc)
            return False
        return True


def _timestamp(value: object) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value <= _TIMESTAMP_MAX:
        raise ValueError(f"bad timestamp {value!r}")
    return value


def _byte(value: object) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value <= 255:
        raise ValueError(f"bad stream id {value!r}")
    return value
