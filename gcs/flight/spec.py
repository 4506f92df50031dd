"""What to fly: :class:`FlightSpec`, the fields of ``gcs fly`` as one validated, frozen value (:func:`gcs.api.fly`)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

from gcs.config import Config, load_config
from gcs.link.endpoints import BadOutUrl, parse_out_url
from quadrotor.errors import ConfigError

__all__ = ["FlightSpec", "VEHICLES", "FIRMWARE_SITLS", "DEFAULT_CONFIG", "DEFAULT_RIG_CONFIG"]

DEFAULT_CONFIG = "outdoor-circle"
DEFAULT_RIG_CONFIG = "indoor-4dof"
#: ``mavlink``: an autopilot on ``port``/``connect``, or the built-in SITL without either; ``rig``: the 4-DOF rig.
VEHICLES = ("mavlink", "rig")
#: Real firmware that ``gcs fly --sitl NAME`` can start as its child vehicle.
FIRMWARE_SITLS = ("arducopter", "px4")
#: The option naming each firmware SITL's path.
FIRMWARE_PATH_OPTION = {"arducopter": "--arducopter", "px4": "--px4"}


@dataclass(frozen=True)
class FlightSpec:
    """Everything one flight needs (the fields of ``gcs fly``'s options).

    Attributes
    ----------
    controller : str
    config : str, Path or Config
        A bundled name, a TOML path or a loaded config (default ``outdoor-circle``; ``indoor-4dof``
        for the rig).
    vehicle : {"mavlink", "rig"}
    port, connect : str or None
        A serial device, or a pymavlink URL (``udpin:``, ``udpout:``, ``tcp:``); neither: the built-in
        SITL (or the rig emulator, or with ``firmware``, a firmware SITL) as a child process.
    firmware : {"arducopter", "px4"} or None
        Without port and URL: fly a real firmware's SITL as the child vehicle — ArduPilot's own
        ArduCopter SITL, or PX4 SITL with its simulator SIH — found at ``firmware_path`` or the
        ``GCS_ARDUCOPTER`` / ``GCS_PX4`` environment variable.
    firmware_path : str or None
    speedup : float or None
        The vehicle's simulated time runs this many times faster than the wall (``firmware`` started
        at that speed-up, or a firmware SITL at ``connect`` started so): the flight runs on the
        vehicle's clock (its telemetry time stamps).  None: real time.
    ready_timeout_s : float
        Vehicle seconds to wait for the vehicle to become ready (telemetry, EKF) and to accept arming.
    baud : int or None
        Serial baud rate (default 57600; 115200 for the rig).
    lockstep : bool
        The vehicle steps once per setpoint (the built-in SITL's lockstep; an external lockstep SITL).
    seed : int
        The child simulator's seed.
    sitl_args : tuple of str
        More options for the child simulator (``--wind=2,90,0.5,2``, ``--start-attitude=1,2,3``).
    target_system, target_component : int
    signing_key : bytes or None
    output, telemetry_rate_hz, stale_timeout_s : optional ``[flight]`` overrides
    duration_s : float or None
        Cut the mission at this time, then land.
    force_budget : bool
        Fly a serial link whose budget does not fit.
    log : bool
        Write an MCAP flight log; ``log_path`` where (default ``logs/<UTC>_<controller>_<experiment>.mcap``).
    live : str or None
        ``[HOST:]PORT``: the log's channels served live there too, on the Foxglove WebSocket protocol
        (:mod:`gcs.log.foxglove_live`; needs the log).
    out : tuple of str
        Other ground stations (``udpout:HOST:PORT``, ``udpin:``, ``tcpin:``, ``tcp:``): the vehicle's traffic
        forwarded to them and theirs to the vehicle, their setpoints dropped (:mod:`gcs.link.forward`).
    metadata : dict
        Added to the log's ``flight`` metadata (e.g. the command line).
    """

    controller: str = "nlsoc"
    config: str | Path | Config | None = None
    vehicle: str = "mavlink"
    port: str | None = None
    connect: str | None = None
    baud: int | None = None
    lockstep: bool = False
    seed: int = 0
    sitl_args: tuple[str, ...] = ()
    firmware: str | None = None
    firmware_path: str | None = None
    speedup: float | None = None
    ready_timeout_s: float = 60.0
    target_system: int = 1
    target_component: int = 1
    signing_key: bytes | None = None
    output: str | None = None
    telemetry_rate_hz: float | None = None
    stale_timeout_s: float | None = None
    duration_s: float | None = None
    force_budget: bool = False
    log: bool = True
    log_path: str | Path | None = None
    live: str | None = None
    out: tuple[str, ...] = ()
    metadata: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.vehicle not in VEHICLES:
            raise ConfigError("vehicle", "", f"must be one of {', '.join(VEHICLES)}, got {self.vehicle!r}")
        if self.firmware is not None:
            if self.firmware not in FIRMWARE_SITLS:
                raise ConfigError("--sitl", "", f"firmware SITL must be one of {', '.join(FIRMWARE_SITLS)}, "
                                                f"got {self.firmware!r}")
            if self.vehicle != "mavlink" or self.port is not None or self.connect is not None or self.lockstep:
                raise ConfigError("--sitl", self.firmware, "a firmware SITL is the child vehicle: not with --rig, "
                                                           "--port, --connect or --lockstep")
        if self.speedup is not None and not 0.1 <= self.speedup <= 50.0:
            raise ConfigError("--speedup", str(self.speedup), "must be in 0.1..50")
        if self.speedup is not None and self.firmware is None and self.connect is None:
            raise ConfigError("--speedup", str(self.speedup), "only for a firmware SITL (--sitl arducopter/px4, or "
                                                              "--connect to one started with that speed-up)")
        if not 1.0 <= self.ready_timeout_s <= 3600.0:
            raise ConfigError("--ready-timeout", str(self.ready_timeout_s), "must be in 1..3600 s")
        if self.port is not None and self.connect is not None:
            raise ConfigError("--port/--connect", "", "give one of them, not both")
        if self.live is not None and not self.log:
            raise ConfigError("--live", self.live, "serves the flight log's channels: not with --no-log")
        for url in self.out:
            try:
                parse_out_url(url)
            except BadOutUrl as exc:
                raise ConfigError("--out", url, exc.reason) from None
        if len(set(self.out)) != len(self.out):
            raise ConfigError("--out", "", "the same URL given twice")
        if self.vehicle == "rig" and self.out:
            raise ConfigError("--out", self.out[0], "forwards MAVLink: not with the rig")
        if self.vehicle == "rig" and (self.connect is not None or self.signing_key is not None or self.output):
            raise ConfigError("--connect/--signing-key/--output", "", "not used with the rig (it takes CONTROL frames "
                                                                      "on a serial port: --port)")

    @property
    def builtin(self) -> bool:
        """The vehicle is a child simulator (no port, no URL)."""
        return self.port is None and self.connect is None

    @property
    def paced(self) -> bool:
        """The flight runs on the vehicle's clock, the vehicle running by itself (a firmware SITL)."""
        return self.firmware is not None or self.speedup is not None

    def to_json(self) -> dict:
        """A JSON document of the spec (a loaded Config is given by its source path; the key in hex)."""
        doc = dataclasses.asdict(self)
        doc["config"] = self.config.source if isinstance(self.config, Config) else (
            None if self.config is None else str(self.config))
        doc["log_path"] = None if self.log_path is None else str(self.log_path)
        doc["signing_key"] = None if self.signing_key is None else self.signing_key.hex()
        doc["sitl_args"] = list(self.sitl_args)
        doc["out"] = list(self.out)
        return doc

    @classmethod
    def from_json(cls, doc: dict) -> FlightSpec:
        d = dict(doc)
        d["sitl_args"] = tuple(d.get("sitl_args", ()))
        d["out"] = tuple(d.get("out", ()))
        if d.get("signing_key") is not None:
            d["signing_key"] = bytes.fromhex(d["signing_key"])
        return cls(**d)

    def command_line(self, summary: str | None = None) -> list[str]:
        """The equivalent ``gcs fly`` command line (documentation: what a user types to fly the same)."""
        out = ["gcs", "fly"]
        if self.vehicle == "rig":
            out += ["--rig", "4dof"]
        if self.config is not None:
            out += ["--config", self.config.source if isinstance(self.config, Config) else str(self.config)]
        out += ["--controller", self.controller]
        opts = (("--port", self.port), ("--connect", self.connect), ("--baud", self.baud),
                ("--output", self.output), ("--telemetry-rate", self.telemetry_rate_hz),
                ("--stale-timeout", self.stale_timeout_s), ("--duration", self.duration_s),
                ("--speedup", self.speedup), ("--ready-timeout", None if self.ready_timeout_s == 60.0
                                              else self.ready_timeout_s))
        if self.firmware is not None:
            out += ["--sitl", self.firmware] + ([FIRMWARE_PATH_OPTION[self.firmware], self.firmware_path]
                                                if self.firmware_path else [])
        elif self.builtin:
            out += ["--sitl", "lockstep" if self.lockstep else "realtime", "--seed", str(self.seed)]
            out += [f"--sitl-arg={a}" for a in self.sitl_args]
        elif self.lockstep:
            out.append("--lockstep")
        for flag, value in opts:
            if value is not None:
                out += [flag, f"{value:g}" if isinstance(value, float) else str(value)]
        if self.force_budget:
            out.append("--force-budget")
        if summary:
            out += ["--summary", summary]
        out += ["--log", str(self.log_path)] if self.log and self.log_path else ([] if self.log else ["--no-log"])
        out += ["--live", self.live] if self.live else []
        for url in self.out:
            out += ["--out", url]
        return out

    def resolved_config(self) -> Config:
        """The config as flown: the file plus this spec's overrides (recorded in its raw document)."""
        base = self.config if self.config is not None else (DEFAULT_RIG_CONFIG if self.vehicle == "rig"
                                                            else DEFAULT_CONFIG)
        config = base if isinstance(base, Config) else load_config(base)
        changes = {k: v for k, v in (("telemetry_rate_hz", self.telemetry_rate_hz),
                                     ("telemetry_stale_s", self.stale_timeout_s), ("output", self.output))
                   if v is not None}
        if changes:
            config = config.with_changes("flight", **changes)
        if self.duration_s is not None:
            config = config.with_duration(self.duration_s)
        return config
