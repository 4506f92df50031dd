"""MAVLink 2 signing keys as users keep them in files."""

from __future__ import annotations

import hashlib

from quadrotor.errors import ConfigError

__all__ = ["read_signing_key"]


def read_signing_key(path: str) -> bytes:
    """A 32-byte key from a file: raw 32 bytes, or 64 hex characters, or a passphrase (SHA-256 of it).

    Raises
    ------
    ConfigError
        The file cannot be read or is empty (a bad option: exit 2).
    """
    try:
        with open(path, "rb") as fh:
            data = fh.read(4096)
    except OSError as exc:
        raise ConfigError("--signing-key", "", f"cannot read {path!r}: {exc.strerror or exc}") from None
    if len(data) == 32:
        return data
    text = data.strip()
    try:
        if len(text) == 64:
            return bytes.fromhex(text.decode())
    except ValueError:
        pass
    if not text:
        raise ConfigError("--signing-key", "", f"{path!r} is empty")
    return hashlib.sha256(text).digest()
