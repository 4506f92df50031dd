"""The Python API: fly a vehicle and simulate experiments from a notebook, a script or the CLI.

::

    import gcs

    result = gcs.fly(gcs.FlightSpec(controller="loc", config="outdoor-circle", lockstep=True, duration_s=20))
    print(result.exit_reason, result.metrics["rms_error_m"])

    table = gcs.simulate("indoor-4dof", controllers=["nlsoc", "pd"], runs=3)
    print(table.summary["nlsoc"]["J_e"])

:func:`fly` does everything ``gcs fly`` does — the link budget, the log, the child simulator
or the link, preflight, the mission, the landing, the parameters restored — and returns a
:class:`~gcs.flight.result.FlightResult` (never raises for a flight that failed: its
``exit_reason`` says how it ended; a bad spec raises :class:`~quadrotor.errors.ConfigError`).
The command line (:mod:`gcs.cli`) and the campaign (:mod:`gcs.campaign`) build specs and call it.
"""

from __future__ import annotations

import dataclasses
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

from gcs.config import Config, load_config
from gcs.control import CONTROLLERS, make_controller
from gcs.errors import LogError, PreflightRefused
from gcs.flight.context import Interrupts
from gcs.flight.flight import Flight
from gcs.log.meta import default_log_path, run_attachments, run_metadata
from gcs.log.recorder import BYTES_PER_FLIGHT_TICK, FlightRecorder, utc_offset_ns
from gcs.flight.result import FlightResult
from gcs.flight.safety import envelope_for
from gcs.link.budget import compute_budget, control_streams, format_budget, suggest_fixes
from gcs.link.mavlink import LinkError, MavlinkLink
from gcs.link.rig import RigLink, rig_link_budget
from gcs.log.sink import BackgroundSink
from gcs.mission import Mission
from gcs.sim import ExperimentResult, SimOptions, run_experiment
from gcs.vehicles.embedded import EmbeddedRig, EmbeddedSitl
from gcs.vehicles.mavlink import MavlinkSession
from gcs.vehicles.rig import RigSession
from quadrotor.clock import MonotonicClock
from quadrotor.errors import ConfigError

__all__ = ["FlightSpec", "fly", "simulate", "VEHICLES", "DEFAULT_CONFIG", "DEFAULT_RIG_CONFIG"]

DEFAULT_CONFIG = "outdoor-circle"
DEFAULT_RIG_CONFIG = "indoor-4dof"
#: ``mavlink``: an autopilot on ``port``/``connect``, or the built-in SITL without either; ``rig``: the 4-DOF rig.
VEHICLES = ("mavlink", "rig")


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
        SITL (or the rig emulator) as a child process.
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
    metadata: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.vehicle not in VEHICLES:
            raise ConfigError("vehicle", "", f"must be one of {', '.join(VEHICLES)}, got {self.vehicle!r}")
        if self.port is not None and self.connect is not None:
            raise ConfigError("--port/--connect", "", "give one of them, not both")
        if self.vehicle == "rig" and (self.connect is not None or self.signing_key is not None or self.output):
            raise ConfigError("--connect/--signing-key/--output", "", "not used with the rig (it takes CONTROL frames "
                                                                      "on a serial port: --port)")

    @property
    def builtin(self) -> bool:
        """The vehicle is the child simulator (no port, no URL)."""
        return self.port is None and self.connect is None

    def to_json(self) -> dict:
        """A JSON document of the spec (a loaded Config is given by its source path; the key in hex)."""
        doc = dataclasses.asdict(self)
        doc["config"] = self.config.source if isinstance(self.config, Config) else (
            None if self.config is None else str(self.config))
        doc["log_path"] = None if self.log_path is None else str(self.log_path)
        doc["signing_key"] = None if self.signing_key is None else self.signing_key.hex()
        doc["sitl_args"] = list(self.sitl_args)
        return doc

    @classmethod
    def from_json(cls, doc: dict) -> "FlightSpec":
        d = dict(doc)
        d["sitl_args"] = tuple(d.get("sitl_args", ()))
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
                ("--stale-timeout", self.stale_timeout_s), ("--duration", self.duration_s))
        if self.builtin:
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


def fly(spec: FlightSpec, *, console: Callable[[str], None] | None = None, interrupts: Interrupts | None = None,
        report: Callable[[str], None] | None = None) -> FlightResult:
    """Fly ``spec`` end to end (see the module docstring).

    Parameters
    ----------
    spec : FlightSpec
    console : callable (str) or None
        The pilot's lines (events, the live line).
    interrupts : Interrupts or None
        Ctrl-C / SIGTERM handling (installed for the flight when the caller is the main thread).
    report : callable (str) or None
        Where refusals explain themselves at length (the link budget and the settings that fit).

    Raises
    ------
    ConfigError
        The spec or its config is invalid (nothing was opened).
    """
    config = spec.resolved_config()
    say = report or (lambda text: None)
    refusal = _budget_refusal(spec, config, say)
    if refusal is not None:
        return FlightResult.refused(spec.controller, config.source, "preflight_refused", refusal)
    try:
        recorder = _open_log(spec, config)
    except PreflightRefused as exc:
        return FlightResult.refused(spec.controller, config.source, "preflight_refused", str(exc))
    try:
        return _fly_logged(spec, config, recorder, console, interrupts or Interrupts())
    finally:
        recorder.close()


def _budget_refusal(spec: FlightSpec, config: Config, say: Callable[[str], None]) -> str | None:
    """Why the serial link cannot carry the exchange (None: it can, or it is not a serial link)."""
    if spec.port is None:
        return None
    rate = 1.0 / config.experiment.ts_s
    if spec.vehicle == "rig":
        baud = spec.baud or 115200
        b = rig_link_budget(baud, rate)
        if max(b["down_share"], b["up_share"]) <= 0.8:
            return None
        say(f"rig link at {baud} baud: telemetry {b['down_b_s']:.0f} B/s ({b['down_share']:.0%}), control "
            f"{b['up_b_s']:.0f} B/s ({b['up_share']:.0%}) of {b['capacity_b_s']:.0f} B/s; 115200 baud fits")
    else:
        fc = config.flight
        budget = compute_budget(control_streams(rate, fc.telemetry_rate_hz, fc.output), spec.baud or 57600,
                                signed=spec.signing_key is not None)
        if budget.fits:
            return None
        say(format_budget(budget))
        say("the 100 Hz exchange does not fit this link; configurations that fit:")
        for fix in suggest_fixes(budget, rate, fc.output):
            say(f"  {fix}")
    if spec.force_budget:
        say("link budget exceeded; flying anyway (--force-budget)")
        return None
    say("refusing to fly (--force-budget overrides)")
    return "link budget exceeded"


def _open_log(spec: FlightSpec, config: Config) -> FlightRecorder:
    """The flight's recorder: the log path and the free space are checked before anything flies."""
    if not spec.log:
        return FlightRecorder(None)
    path = Path(spec.log_path) if spec.log_path else default_log_path(spec.controller, config.experiment.name)
    ticks = int(Mission(config.mission).duration_s / config.experiment.ts_s) + 6000  # + preflight and landing
    try:
        log = BackgroundSink(path, expected_bytes=ticks * BYTES_PER_FLIGHT_TICK)
    except LogError as exc:
        raise PreflightRefused(f"{exc} (--log PATH writes elsewhere, --no-log writes none)") from None
    rec = FlightRecorder(log)
    md = dict(spec.metadata)
    md.update(vehicle=f"rig {spec.vehicle}" if spec.vehicle == "rig" else "mavlink",
              time_base="vehicle time since boot (lockstep)" if spec.lockstep
              else "UTC (the loop's monotonic clock plus a fixed offset)")
    rec.header(run_metadata(config, [spec.controller], source="flight", **md),
               run_attachments(config, {spec.controller: make_controller(spec.controller, config)}))
    return rec


def _open_vehicle(spec: FlightSpec, config: Config, console: Callable[[str], None]):
    """``(session, link, child)``: the link to the vehicle (and the child simulator behind it, stopped again
    should anything after its start fail)."""
    child = None
    try:
        if spec.vehicle == "rig":
            baud = spec.baud or 115200
            if spec.builtin:
                # Lockstep runs without the emulated baud limit (as fast as it computes) unless asked.
                child = EmbeddedRig(lockstep=spec.lockstep, seed=spec.seed, baud=0 if spec.lockstep else baud,
                                    extra_args=spec.sitl_args).start()
                console(f"[link] rig emulator ({'lockstep' if spec.lockstep else 'real time'}) on {child.device}")
            link = RigLink(child.device if child is not None else spec.port, baud)
            session = RigSession(config, link, envelope_for(config),
                                 vehicle_alive=child.exit_reason if child is not None else None)
            return session, link, child
        if spec.builtin:
            link = MavlinkLink("udpin:127.0.0.1:0", target_system=spec.target_system,
                               target_component=spec.target_component, signing_key=spec.signing_key)
            port = link.conn.port.getsockname()[1]
            child = EmbeddedSitl(port, lockstep=spec.lockstep, seed=spec.seed, extra_args=spec.sitl_args).start()
            link.alive_check = child.check_alive
            console(f"[link] built-in SITL ({'lockstep' if spec.lockstep else 'real time'}) on udp 127.0.0.1:{port}")
        else:
            link = MavlinkLink(spec.port or spec.connect, baud=spec.baud or 57600, target_system=spec.target_system,
                               target_component=spec.target_component, signing_key=spec.signing_key)
        session = MavlinkSession(config, link, output=spec.output,
                                 vehicle_alive=child.exit_reason if child is not None else None)
        return session, link, child
    except BaseException:
        if child is not None:
            child.stop()
        raise


def _fly_logged(spec: FlightSpec, config: Config, recorder: FlightRecorder, console, interrupts: Interrupts
                ) -> FlightResult:
    console = console or (lambda s: None)
    try:
        session, link, child = _open_vehicle(spec, config, console)
    except LinkError as exc:
        recorder.event(0, "failsafe", f"link error: {exc}")
        return FlightResult.refused(spec.controller, config.source, "link_error", str(exc))
    except Exception as exc:  # noqa: BLE001 - nothing flies yet: one line and an exit code, never a traceback
        why = f"{type(exc).__name__}: {exc}"
        recorder.event(0, "failsafe", f"internal error: {why}", traceback=traceback.format_exc())
        return FlightResult.refused(spec.controller, config.source, "internal_error", why)
    clock = None if spec.lockstep else MonotonicClock()
    if clock is not None:
        recorder.offset_ns = utc_offset_ns(clock.now_ns())
    flight = None
    try:
        with interrupts:
            flight = Flight(config, spec.controller, session, clock=clock, recorder=recorder, console=console,
                            interrupts=interrupts)
            return _fly_flight(flight, config, spec, child)
    except Exception as exc:  # noqa: BLE001 - outside the mission loop's own net: land, restore, report
        why = f"{type(exc).__name__}: {exc}"
        if flight is None:
            return FlightResult.refused(spec.controller, config.source, "internal_error", why)
        _last_resort(flight, why)
        return FlightResult.refused(spec.controller, config.source, "internal_error", why, flight.events)
    finally:
        link.close()
        if child is not None:
            child.stop()


def _fly_flight(flight: Flight, config: Config, spec: FlightSpec, child) -> FlightResult:
    """Preflight, mission, landing, parameters restored; a refusal disarms again on the ground."""
    failure: tuple[str, str] | None = None
    result = None
    try:
        flight.preflight()
    except PreflightRefused as exc:
        flight.event("failsafe", f"preflight refused: {exc}")
        flight.session.disarm_on_ground()
        failure = ("preflight_refused", str(exc))
    except LinkError as exc:
        why = (child.exit_reason() if child is not None else None) or str(exc)
        flight.event("failsafe", f"link error: {why}")
        flight.session.disarm_on_ground()
        failure = ("link_error", why)
    else:
        result = flight.fly()
    flight.restore()
    if failure is not None:
        return FlightResult.refused(spec.controller, config.source, failure[0], failure[1], flight.events)
    return result  # type: ignore[return-value]


def _last_resort(flight: Flight, why: str) -> None:
    """An exception escaped the flight: land (or disarm on the ground) and restore, each step on its own."""
    flight.event("failsafe", f"internal error ({why}): landing", traceback=traceback.format_exc())
    for step in (flight.emergency_land, flight.restore):
        try:
            step()
        except Exception as exc:  # noqa: BLE001 - each last-resort step is tried whatever the others did
            flight.event("failsafe", f"{step.__name__} failed: {type(exc).__name__}: {exc}")


def simulate(config: str | Path | Config, controllers: Sequence[str] | str = CONTROLLERS,
             *, runs: int | None = None, seed: int | None = None, duration_s: float | None = None,
             wind: bool | None = None, noise: bool = True, matrices: str | None = None, log=None,
             progress: Callable[[str, int, int], None] | None = None) -> ExperimentResult:
    """Fly ``controllers`` on the in-process plant ``runs`` times each (``gcs sim``); the metrics per run.

    ``config``: a bundled name, a path or a Config; ``matrices`` "corrected" or "printed";
    ``log``: a log sink of :mod:`gcs.log` (None: no log).  See :func:`gcs.sim.run_experiment`.
    """
    cfg = config if isinstance(config, Config) else load_config(config)
    if matrices is not None and matrices != cfg.experiment.matrices:
        cfg = cfg.with_matrices(matrices)
    names = [controllers] if isinstance(controllers, str) else list(controllers)
    options = SimOptions(duration_s=duration_s, wind=wind, noise=noise)
    return run_experiment(cfg, names, runs=runs, seed=seed, options=options, progress=progress, log=log)


def replace(spec: FlightSpec, **changes) -> FlightSpec:
    """A copy of ``spec`` with ``changes`` (validated again)."""
    return dataclasses.replace(spec, **changes)
