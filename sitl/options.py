"""Checks and conversions of the ``sitl`` command's options, before anything is opened or started.

Every numeric option must be finite and within its range; a bad one raises
:class:`~sitl.errors.UsageError` with ``--NAME: reason`` (the command prints
``sitl: error: --NAME: reason`` and exits with 2).  Ranges:

==================  =========================================================
--period            > 0 and <= 1 s, a multiple of the inner-loop period (2.5 ms; 5 ms with --rig)
--seed              0 .. 2**63 - 1
--wind              speed 0..100 m/s, direction -360..360 deg, gust 0..50 m/s, tau > 0 and <= 3600 s
--start-altitude    0 .. 10000 m
--start-attitude    roll -180..180, pitch -90..90, yaw -360..360 deg
--param             a value the parameter accepts (finite, within its range)
--sysid             1 .. 255
--prearm-delay      0 .. 3600 s
--ekf-ready-s       0 .. 3600 s, only with --emulate
--baud              0 (no limit) or 50 .. 20000000
--loss              0 .. 1
--latency           0 .. 10 s
--bit-error-rate    0 .. <1
--parent-pid        >= 1
--motor-scale       4 factors (motors 1..4), each 0.3 .. 1.5
--com-offset        x,y,z [m, FRD], each -0.1 .. 0.1
--mass-scale        0.5 .. 2.0
--inertia-scale     0.5 .. 2.0
--clock-rate        0.9 .. 1.1
==================  =========================================================

The vehicle fault options (:func:`faults`, :mod:`sitl.copter.faults`) override the vehicle file's
``[faults]`` keys one by one; a combination that cannot hover the true vehicle with margin is refused
naming the fault options given (``--motor-scale: cannot hover: ...``).

Endpoints (:func:`open_endpoints`): ``--udp``, ``--udp-listen`` and ``--tcp``
may be given several times and combined with ``--pty``; each is opened in
command-line order.
"""

from __future__ import annotations

import argparse
import hashlib
import math
from collections.abc import Callable, Sequence
from dataclasses import replace

from quadrotor.errors import ConfigError
from quadrotor.wind import WindParams
from sitl.copter.ardupilot_emulation.vehicle import emulation_params
from sitl.copter.faults import FAULT_RANGES
from sitl.copter.params import ParamStore, ardupilot_params
from sitl.copter.simulation import InitialConditions
from sitl.copter.vehicle import VehicleParams
from sitl.copter.vehicle_file import with_faults
from sitl.errors import UsageError
from sitl.net.pty import PtyTransport
from sitl.net.tcp import TcpTransport
from sitl.net.transport import Transport, parse_host_port
from sitl.net.udp import UdpTransport

__all__ = ["EndpointAction", "check_common", "check_mavlink", "wind", "params", "signing_key", "initial",
           "faults", "FAULT_OPTIONS", "open_endpoints", "DEFAULT_ENDPOINT", "MAX_SEED"]

MAX_SEED = 2**63 - 1
DEFAULT_ENDPOINT = ("udp", "127.0.0.1:14550", "--udp")


class EndpointAction(argparse.Action):
    """Appends ``(kind, value, option)`` to ``namespace.endpoints``, keeping the command-line order."""

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        eps = list(getattr(namespace, self.dest, None) or [])
        eps.append((self.const, values, option_string))
        setattr(namespace, self.dest, eps)


def _in_range(option: str, value: float, low: float, high: float, unit: str = "") -> None:
    if not math.isfinite(value):
        raise UsageError(f"{option}: must be a finite number, got {value!r}")
    if not low <= value <= high:
        raise UsageError(f"{option}: must be in [{low:g}, {high:g}]{' ' + unit if unit else ''}, got {value:g}")


def check_common(args: argparse.Namespace, inner_period_s: float) -> None:
    """Check the options both the vehicle and the rig take (UsageError naming the first bad one).

    Parameters
    ----------
    args : argparse.Namespace
    inner_period_s : float
        The onboard loop period ``--period`` must be a multiple of.
    """
    p = args.period
    _in_range("--period", p, 0.0, 1.0, "s")
    ticks = p / inner_period_s
    if p <= 0.0 or round(ticks) < 1 or abs(ticks - round(ticks)) > 1e-6:
        raise UsageError(f"--period: {p:g} s is not a multiple of the {inner_period_s * 1000:g} ms onboard period")
    if not 0 <= args.seed <= MAX_SEED:
        raise UsageError(f"--seed: must be in [0, 2**63 - 1], got {args.seed}")
    _in_range("--loss", args.loss, 0.0, 1.0)
    _in_range("--latency", args.latency, 0.0, 10.0, "s")
    if args.baud is not None and args.baud != 0 and not 50 <= args.baud <= 20_000_000:
        raise UsageError(f"--baud: must be 0 (no limit) or in [50, 20000000], got {args.baud}")
    if args.parent_pid is not None and args.parent_pid < 1:
        raise UsageError(f"--parent-pid: must be >= 1, got {args.parent_pid}")
    if args.bit_error_rate is not None:
        _in_range("--bit-error-rate", args.bit_error_rate, 0.0, 1.0)
        if args.bit_error_rate >= 1.0:
            raise UsageError(f"--bit-error-rate: must be in [0, 1), got {args.bit_error_rate:g}")


def check_mavlink(args: argparse.Namespace) -> None:
    """Check the options of the simulated ArduCopter (not the rig's)."""
    _in_range("--prearm-delay", args.prearm_delay, 0.0, 3600.0, "s")
    if args.ekf_ready_s is not None:
        if args.emulate is None:
            raise UsageError("--ekf-ready-s: only with --emulate")
        _in_range("--ekf-ready-s", args.ekf_ready_s, 0.0, 3600.0, "s")
    _in_range("--start-altitude", args.start_altitude, 0.0, 10000.0, "m")
    if args.sysid is not None and not 1 <= args.sysid <= 255:
        raise UsageError(f"--sysid: must be in [1, 255], got {args.sysid}")
    if args.signing_state is not None and args.signing_key is None:
        raise UsageError("--signing-state: only with --signing-key")


def _floats(text: str, option: str, count: tuple[int, int]) -> list[float]:
    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError:
        raise UsageError(f"{option}: expected comma-separated numbers, got {text!r}") from None
    if not count[0] <= len(vals) <= count[1]:
        n = f"{count[0]}" if count[0] == count[1] else f"{count[0]} to {count[1]}"
        raise UsageError(f"{option}: expected {n} numbers, got {text!r}")
    for v in vals:
        if not math.isfinite(v):
            raise UsageError(f"{option}: must be finite numbers, got {text!r}")
    return vals


def wind(text: str | None) -> WindParams | None:
    """``--wind SPEED[,DIR[,GUST[,TAU]]]`` as :class:`WindParams` (None if not given)."""
    if text is None:
        return None
    v = _floats(text, "--wind", (1, 4))
    names = ("speed", "direction", "gust", "tau")
    ranges = ((0, 100, "m/s"), (-360, 360, "deg"), (0, 50, "m/s"), (0, 3600, "s"))
    for value, name, (low, high, unit) in zip(v, names, ranges, strict=False):  # the values given, 1 to 4
        if not low <= value <= high:
            raise UsageError(f"--wind: {name} must be in [{low:g}, {high:g}] {unit}, got {value:g}")
    if len(v) > 3 and v[3] <= 0:
        raise UsageError(f"--wind: tau must be > 0 s, got {v[3]:g}")
    try:
        return WindParams(mean_speed_m_s=v[0], direction_deg=v[1] if len(v) > 1 else None,
                          gust_std_m_s=v[2] if len(v) > 2 else 0.0, gust_tau_s=v[3] if len(v) > 3 else 2.0)
    except ValueError as exc:
        raise UsageError(f"--wind: {exc}") from None


#: Vehicle fault options: (option, ``argparse`` attribute, ``FaultParams`` field, count of numbers).
FAULT_OPTIONS = (("--motor-scale", "motor_scale", "motor_scale", 4),
                 ("--com-offset", "com_offset", "com_offset_m", 3),
                 ("--mass-scale", "mass_scale", "mass_scale", 1),
                 ("--inertia-scale", "inertia_scale", "inertia_scale", 1),
                 ("--clock-rate", "clock_rate", "clock_rate", 1))


def faults(args: argparse.Namespace, vehicle: VehicleParams) -> VehicleParams:
    """``vehicle`` with the fault options given (``--motor-scale A,B,C,D``, ``--com-offset X,Y,Z`` [m],
    ``--mass-scale S``, ``--inertia-scale S``, ``--clock-rate R``) over its file's ``[faults]``.

    Raises
    ------
    UsageError
        A value not a number, the wrong count, out of its range (``--NAME: must be in [lo, hi] ...``),
        or a combination that cannot hover (``--NAME[/--NAME...]: cannot hover: ...``).
    """
    changes: dict[str, object] = {}
    for option, attr, field_name, count in FAULT_OPTIONS:
        value = getattr(args, attr, None)
        if value is None:
            continue
        low, high, unit = FAULT_RANGES[field_name]
        if count == 1:
            _in_range(option, float(value), low, high, unit)
            changes[field_name] = float(value)
            continue
        vals = _floats(str(value), option, (count, count))
        names = ("motor 1", "motor 2", "motor 3", "motor 4") if count == 4 else ("x", "y", "z")
        for name, v in zip(names, vals, strict=True):
            if not low <= v <= high:
                raise UsageError(f"{option}: {name} must be in [{low:g}, {high:g}]{' ' + unit if unit else ''}, "
                                 f"got {v:g}")
        changes[field_name] = tuple(vals)
    if not changes:
        return vehicle
    given = "/".join(o for o, attr, _, _ in FAULT_OPTIONS if getattr(args, attr, None) is not None)
    try:
        return with_faults(vehicle, replace(vehicle.faults, **changes))
    except (ConfigError, ValueError) as exc:
        raise UsageError(f"{given}: {getattr(exc, 'reason', exc)}") from None


def initial(altitude_m: float, attitude: str | None) -> InitialConditions:
    """``--start-altitude`` and ``--start-attitude ROLL,PITCH,YAW`` [deg] as :class:`InitialConditions`."""
    if attitude is None:
        return InitialConditions(altitude_m)
    r, pch, y = _floats(attitude, "--start-attitude", (3, 3))
    for value, name, lim in ((r, "roll", 180.0), (pch, "pitch", 90.0), (y, "yaw", 360.0)):
        if not -lim <= value <= lim:
            raise UsageError(f"--start-attitude: {name} must be in [{-lim:g}, {lim:g}] deg, got {value:g}")
    return InitialConditions(altitude_m, r, pch, y)


def params(items: Sequence[str], sysid: int | None, vehicle: VehicleParams,
           emulate: str | None = None) -> dict[str, float]:
    """``--param NAME=VALUE`` overrides (and ``--sysid``), each checked against the parameter table
    (the emulation's with ``emulate``)."""
    out: dict[str, float] = {}
    store = ParamStore(emulation_params(vehicle) if emulate else ardupilot_params(vehicle))
    for item in items:
        name, sep, value = item.partition("=")
        name = name.strip().upper()
        if not sep or not name:
            raise UsageError(f"--param: expected NAME=VALUE, got {item!r}")
        try:
            v = float(value)
        except ValueError:
            raise UsageError(f"--param {name}: not a number: {value!r}") from None
        ok, reason = store.set(name, v, force=True)
        if not ok:
            raise UsageError(f"--param {name}: {reason}")
        out[name] = v
    if sysid is not None:
        out["SYSID_THISMAV"] = float(sysid)
    return out


def signing_key(text: str | None) -> bytes | None:
    """``--signing-key``: 64 hex digits, or a passphrase whose SHA-256 is the key (as MAVProxy)."""
    if text is None:
        return None
    t = text.strip()
    if len(t) == 64:
        try:
            return bytes.fromhex(t)
        except ValueError:
            pass
    if not t:
        raise UsageError("--signing-key: empty")
    return hashlib.sha256(t.encode("utf-8")).digest()


def open_endpoints(endpoints: Sequence[tuple[str, object, str]] | None,
                   clock_ns: Callable[[], int]) -> list[Transport]:
    """Open the transports of ``(kind, value, option)`` in order (default: ``--udp 127.0.0.1:14550``).

    Raises UsageError for a malformed address and TransportError when one cannot
    be opened (the ones already opened are closed).
    """
    out: list[Transport] = []
    try:
        for kind, value, option in endpoints or [DEFAULT_ENDPOINT]:
            try:
                if kind == "pty":
                    out.append(PtyTransport(clock_ns))
                elif kind == "tcp":
                    out.append(TcpTransport(parse_host_port(str(value))))
                elif kind == "udp-listen":
                    out.append(UdpTransport(parse_host_port(str(value))))
                else:
                    remote = parse_host_port(str(value))
                    local = "127.0.0.1" if remote[0].startswith("127.") or remote[0] == "localhost" else "0.0.0.0"
                    out.append(UdpTransport((local, 0), remote))
            except ValueError as exc:
                raise UsageError(f"{option}: {exc}") from None
    except BaseException:
        for t in out:
            t.close()
        raise
    return out
