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
from pathlib import Path
from collections.abc import Callable, Sequence

from gcs.config import Config, load_config
from gcs.control import CONTROLLERS, make_controller
from gcs.errors import LogError, PreflightRefused
from gcs.flight.context import Interrupts
from gcs.flight.flight import Flight
from gcs.flight.spec import DEFAULT_CONFIG, DEFAULT_RIG_CONFIG, FIRMWARE_SITLS, VEHICLES, FlightSpec
from gcs.log.meta import default_log_path, run_attachments, run_metadata
from gcs.log.recorder import BYTES_PER_FLIGHT_TICK, FlightRecorder, utc_offset_ns
from gcs.flight.result import FlightResult
from gcs.flight.safety import envelope_for
from gcs.link.forward import Forwarder
from gcs.link.budget import compute_budget, control_streams, format_budget, suggest_fixes
from gcs.link.mavlink import LinkError, MavlinkLink
from gcs.link.rig import RigLink, rig_link_budget
from gcs.log.sink import BackgroundSink
from gcs.mission import Mission
from gcs.sim import ExperimentResult, SimOptions, run_experiment
from gcs.vehicles.arducopter_sitl import ArduCopterSitl
from gcs.vehicles.embedded import EmbeddedRig, EmbeddedSitl
from gcs.vehicles.px4_events import EventMetadata, find_event_metadata
from gcs.vehicles.px4_sitl import Px4Sitl
from gcs.vehicles.mavlink import STREAM_IDS, MavlinkSession
from gcs.vehicles.rig import RigSession
from quadrotor.clock import MonotonicClock

__all__ = ["FlightSpec", "fly", "simulate", "VEHICLES", "FIRMWARE_SITLS", "DEFAULT_CONFIG", "DEFAULT_RIG_CONFIG"]

#: Speed-up at which a firmware SITL started by ``gcs fly`` boots (then SIM_SPEEDUP = the flight's).
BOOT_SPEEDUP = 10.0


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
        log = BackgroundSink(path, expected_bytes=ticks * BYTES_PER_FLIGHT_TICK,
                             **({"live": spec.live} if spec.live else {}))  # gcs fly --live: the writer serves it
    except LogError as exc:
        raise PreflightRefused(f"{exc} (--log PATH writes elsewhere, --no-log writes none)") from None
    rec = FlightRecorder(log)
    md = dict(spec.metadata)
    md.update(vehicle=f"rig {spec.vehicle}" if spec.vehicle == "rig" else "mavlink",
              time_base="vehicle time since boot (lockstep)" if spec.lockstep
              else "vehicle time since boot (its telemetry time stamps)" if spec.paced
              else "UTC (the loop's monotonic clock plus a fixed offset)")
    rec.header(run_metadata(config, [spec.controller], source="flight", **md),
               run_attachments(config, {spec.controller: make_controller(spec.controller, config)}))
    return rec


def _open_vehicle(spec: FlightSpec, config: Config, console: Callable[[str], None]):
    """``(session, link, child)``: the link to the vehicle (and the child simulator behind it, stopped again
    should anything after its start fail)."""
    child = None
    events = None
    forwarder = _open_forwarder(spec)
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
        if spec.firmware == "arducopter":
            # It boots (EKF alignment: ~40 s of its time) at BOOT_SPEEDUP, then flies at the spec's speed-up.
            child = ArduCopterSitl(spec.firmware_path, speedup=max(BOOT_SPEEDUP, spec.speedup or 1.0)).start()
            link = MavlinkLink(child.url, target_system=spec.target_system, target_component=spec.target_component,
                               signing_key=spec.signing_key)
            link.alive_check = child.check_alive
            console(f"[link] ArduCopter SITL {child.binary} on {child.url} (booting at speed-up {child.speedup:g}), "
                    f"its log {child.log_path}")
        elif spec.firmware == "px4":
            # SIH runs at PX4_SIM_SPEED_FACTOR from boot (PX4 is ready within seconds).
            child = Px4Sitl(spec.firmware_path, speedup=spec.speedup or 1.0).start()
            link = MavlinkLink(child.url, target_system=child.instance + 1, target_component=spec.target_component,
                               signing_key=spec.signing_key)
            link.alive_check = child.check_alive
            events = _px4_events(child.events_path, console)
            console(f"[link] PX4 SITL + SIH {child.build} instance {child.instance} on {child.url} "
                    f"(speed factor {child.speedup:g}), its log {child.log_path}")
        elif spec.builtin:
            link = MavlinkLink("udpin:127.0.0.1:0", target_system=spec.target_system,
                               target_component=spec.target_component, signing_key=spec.signing_key)
            port = link.conn.port.getsockname()[1]
            child = EmbeddedSitl(port, lockstep=spec.lockstep, seed=spec.seed, extra_args=spec.sitl_args).start()
            link.alive_check = child.check_alive
            console(f"[link] built-in SITL ({'lockstep' if spec.lockstep else 'real time'}) on udp 127.0.0.1:{port}")
        else:
            link = MavlinkLink(spec.port or spec.connect, baud=spec.baud or 57600, target_system=spec.target_system,
                               target_component=spec.target_component, signing_key=spec.signing_key)
        if events is None and spec.firmware != "px4":
            found = find_event_metadata()
            events = _px4_events(found, console) if found is not None else None
        session = MavlinkSession(config, link, output=spec.output,
                                 vehicle_alive=child.exit_reason if child is not None else None,
                                 speedup=(spec.speedup or 1.0) if spec.paced else None,
                                 ready_timeout_s=spec.ready_timeout_s,
                                 boot_speedup=child.speedup if spec.firmware == "arducopter" else None,
                                 event_metadata=events)
        if forwarder is not None:
            forwarder.own_ids = (link.source_system, link.source_component)
            forwarder.on_streams = lambda: _reassert_streams(session)
            forwarder.protected = lambda: session.params.changed if session.params is not None else ()
            link.forwarder = forwarder
        return session, link, child
    except BaseException:
        if forwarder is not None:
            forwarder.close(quiet=True)
        if child is not None:
            child.stop()
        raise


def _open_forwarder(spec: FlightSpec) -> Forwarder | None:
    """``--out``'s endpoints, opened before the vehicle (a port in use: a link error, nothing started)."""
    if not spec.out:
        return None
    try:
        return Forwarder(spec.out)
    except OSError as exc:
        raise LinkError(str(exc)) from None


def _reassert_streams(session: MavlinkSession) -> None:
    """A client's stream request went to the vehicle: ask for the rates the controller flies on again, at once."""
    link = session.link
    for name, rate in session.streams.requested_hz.items():
        session.io.quietly(lambda name=name, rate=rate: link.send_message_interval(STREAM_IDS[name], rate))


def _close_forwarder(link, flight: Flight | None) -> dict | None:
    """Close ``--out``'s endpoints (their summary said as an event); the summary (None: no --out)."""
    forwarder = getattr(link, "forwarder", None)
    if forwarder is None:
        return None
    if flight is not None and not forwarder.closed:
        forwarder.attach(flight.event)
    return forwarder.close()


def _px4_events(path, console: Callable[[str], None]) -> EventMetadata | None:
    """PX4's event metadata from ``path`` (None, said, when it cannot be read: refusals then say "an event")."""
    try:
        meta = EventMetadata.load(path)
    except (OSError, ValueError, EOFError) as exc:
        console(f"[link] PX4 event metadata not read ({exc}): arming refusals will name event ids only")
        return None
    console(f"[link] PX4 event metadata: {len(meta)} events from {path}")
    return meta


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
    clock = None if spec.lockstep or spec.paced else MonotonicClock()
    if clock is not None:
        recorder.offset_ns = utc_offset_ns(clock.now_ns())
    flight = None
    try:
        with interrupts:
            flight = Flight(config, spec.controller, session, clock=clock, recorder=recorder, console=console,
                            interrupts=interrupts)
            if getattr(link, "forwarder", None) is not None:
                link.forwarder.attach(flight.event)
            return _fly_flight(flight, config, spec, child, link)
    except Exception as exc:  # noqa: BLE001 - outside the mission loop's own net: land, restore, report
        why = f"{type(exc).__name__}: {exc}"
        if flight is None:
            return FlightResult.refused(spec.controller, config.source, "internal_error", why)
        _last_resort(flight, why)
        return FlightResult.refused(spec.controller, config.source, "internal_error", why, flight.events)
    finally:
        _close_forwarder(link, flight)
        link.close()
        if child is not None:
            child.stop()


def _fly_flight(flight: Flight, config: Config, spec: FlightSpec, child, link) -> FlightResult:
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
    forwarded = _close_forwarder(link, flight)
    if failure is not None:
        result = FlightResult.refused(spec.controller, config.source, failure[0], failure[1], flight.events)
    if forwarded is not None:
        result.link["forward"] = forwarded
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
