"""The ``sitl`` command: the simulated ArduCopter (:mod:`sitl.copter`) or, with ``--rig``, the 4-DOF rig.

The first lines on stdout are what the ground station connects to, one per endpoint in
command-line order (``mavutil.mavlink_connection`` strings; for ``--pty`` and ``--rig`` the device
path): ``gcs fly`` and the tests read them.  Bad options are refused before anything starts
(``sitl: error: --NAME: reason``, exit 2; ranges in :mod:`sitl.options`).  Ctrl-C, SIGTERM or the
end of ``--parent-pid`` stop it cleanly (exit 0).
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import re
import signal
import sys
import threading
import time
from collections.abc import Sequence
from typing import NoReturn

from quadrotor.clock import MonotonicClock, ScaledClock
from quadrotor.errors import QuadrotorError
from quadrotor.mavlink.signing import default_state_path
from sitl import options
from sitl.copter.ardupilot_emulation import EMULATIONS
from sitl.copter.ardupilot_emulation.status import EKF_READY_S
from sitl.copter.ardupilot_emulation.vehicle import INITIAL_YAW_DEG, arducopter_sitl_vehicle
from sitl.copter.server import SitlServer
from sitl.copter.vehicle import MODELS, VehicleParams
from sitl.copter.vehicle_file import bundled_vehicles, load_vehicle
from sitl.errors import UsageError
from sitl.net.pty import PtyTransport
from sitl.net.radio import RadioParams
from sitl.rig.dynamics import RigParams
from sitl.rig.firmware import TICK_NS, RigSafetyParams
from sitl.rig.sensors import RigSensorParams
from sitl.rig.server import RIG_KINDS, RigServer

__all__ = ["main", "build_parser"]

_EPILOG = """\
conventions (ArduCopter; see sitl/copter/):
  modes            STABILIZE 0, GUIDED 4, LAND 9, GUIDED_NOGPS 20 (MAV_CMD_DO_SET_MODE or SET_MODE)
  arming           MAV_CMD_COMPONENT_ARM_DISARM; refused (STATUSTEXT "Arm: ...") when leaning more
                   than ATC_ANGLE_MAX, not landed, battery low, or in LAND; param2=21196 forces
  streams          none but HEARTBEAT until requested: MAV_CMD_SET_MESSAGE_INTERVAL or REQUEST_DATA_STREAM
  SET_ATTITUDE_TARGET (GUIDED/GUIDED_NOGPS)
                   GUID_OPTIONS=0: thrust is a climb rate (0.5 hold, 1.0 = +WP_SPD_UP, 0.0 = -WP_SPD_DN)
                   GUID_OPTIONS=8: thrust = throttle 0..1 of 4 x rotors.max_thrust_n, divided by
                   cos(tilt) while ATC_ANGLE_BOOST=1 (ArduPilot's default; set 0 for raw thrust)
  SET_ACTUATOR_CONTROL_TARGET (group 0)
                   controls[0..2] in -1..1 = torque / (sqrt(2) L T_max, sqrt(2) L T_max, 2 k T_max),
                   controls[3] in 0..1 = thrust / (4 T_max); `sitl --describe` prints the numbers
  failsafe         no new target for GUID_TIMEOUT s: level, LAND, STATUSTEXT; LAND disarms on landing;
                   DISARM_DELAY s landed while armed disarms
  lockstep         each SET_ATTITUDE_TARGET / SET_ACTUATOR_CONTROL_TARGET advances --period seconds,
                   then every stream message due is sent; no command, no time
  signing          with --signing-key, unsigned, badly signed and replayed frames are rejected and
                   counted (SYS_STATUS errors_count3); outgoing frames are signed; the timestamps
                   are kept in --signing-state, so frames captured before a restart stay refused
  links            every UDP sender, TCP connection and the serial line has its own stream rates

4-DOF rig (--rig 4dof; frames and payloads: quadrotor/rig_protocol.py, docs/rig-protocol.md):
  link             XBee API-mode-2 frames on a pseudo-terminal, 115200 baud unless --baud;
                   send a HEARTBEAT first (answered by STATUS)
  control          CONTROL (thrust N, roll/pitch/yaw angular accelerations rad/s^2) or CONTROL_PWM
                   (four 10-bit values) at 100 Hz; the rig applies the latest at 200 Hz and sends
                   TELEMETRY at 200 Hz; roll stops at +-15 deg, pitch at +-60 deg, no y, no yaw
  arming           ARM only when landed; DISARM at any time (kill) also clears a cut-off
  cut-off          |vz|, |vx|, roll/pitch rate, altitude or a CONTROL demand beyond the limits
                   (`sitl --rig 4dof --describe`): motors off, latched until DISARM
  watchdog         armed without a control frame for 0.5 s: level, descend at 0.3 m/s, disarm landed
  lockstep         each CONTROL / CONTROL_PWM advances --period (10 ms = two 5 ms ticks), then
                   the ticks' TELEMETRY frames are sent

vehicles: {vehicles} (or a TOML file; see configs/vehicles/)
"""


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line, without the usage text."""

    def error(self, message: str) -> NoReturn:
        message = re.sub(r"^argument (?:-\w/)?(--[\w-]+): ", r"\1: ", message.splitlines()[0] if message else "")
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    """The ``sitl`` argument parser."""
    p = _Parser(prog="sitl", description="Simulated ArduCopter quadrotor (6-DOF physics, sensors, autopilot) "
                "behind a MAVLink endpoint.", epilog=_EPILOG.format(vehicles=", ".join(bundled_vehicles())),
                formatter_class=argparse.RawDescriptionHelpFormatter)
    _endpoint_options(p.add_argument_group("endpoints (any number, combined; default --udp 127.0.0.1:14550)"))
    _simulation_options(p.add_argument_group("simulation"))
    _fault_options(p.add_argument_group("vehicle faults (override the vehicle file's [faults]; the autopilot "
                                        "is not told)"))
    _link_options(p.add_argument_group("link emulation (both directions)"))
    rig = p.add_argument_group("4-DOF rig")
    rig.add_argument("--rig", choices=RIG_KINDS, default=None,
                     help="emulate the paper's indoor 4-DOF rig and its XBee serial protocol instead of "
                          "an ArduCopter; served on a pseudo-terminal (implies --pty)")
    rig.add_argument("--bit-error-rate", metavar="P", type=float, default=None,
                     help="with --rig: flip each bit on the link with probability P, both directions")
    other = p.add_argument_group("other")
    other.add_argument("--describe", action="store_true",
                       help="print the vehicle's derived values (hover thrust, torque normalisation) and exit")
    other.add_argument("-v", "--verbose", action="count", default=0, help="log to stderr (-vv: debug)")
    other.add_argument("--parent-pid", type=int, metavar="PID",
                       help="stop when process PID (the ground station that started this SITL) is gone, "
                            "even if it was killed without a word")
    return p


def _endpoint_options(ep: argparse._ArgumentGroup) -> None:
    ep.add_argument("--udp", metavar="HOST:PORT", dest="endpoints", action=options.EndpointAction, const="udp",
                    help="send to a ground station listening there (it uses udpin:HOST:PORT)")
    ep.add_argument("--udp-listen", metavar="[HOST:]PORT", dest="endpoints", action=options.EndpointAction,
                    const="udp-listen",
                    help="listen there and answer the senders (ground station: udpout:HOST:PORT; it must send first)")
    ep.add_argument("--tcp", metavar="[HOST:]PORT", dest="endpoints", action=options.EndpointAction, const="tcp",
                    help="TCP server (ground station: tcp:HOST:PORT); HOST 127.0.0.1")
    ep.add_argument("--pty", dest="endpoints", action=options.EndpointAction, const="pty", nargs=0,
                    help="serial port on a pseudo-terminal; prints its path (open it like /dev/ttyUSB0)")


def _simulation_options(sim: argparse._ArgumentGroup) -> None:
    sim.add_argument("--vehicle", metavar="NAME|FILE", default=None,
                     help="bundled vehicle name or TOML file (default: quad-1kg)")
    sim.add_argument("--model", choices=MODELS, default=None,
                     help="plant: 6-DOF rigid body or the paper's reduced model (default: the vehicle file's)")
    sim.add_argument("--lockstep", action="store_true",
                     help="advance simulated time one period per received target instead of in real time")
    sim.add_argument("--speedup", metavar="X", type=float, default=1.0,
                     help="real time X times faster (0 < X <= 100; not with --lockstep; default: 1)")
    sim.add_argument("--period", metavar="S", type=float, default=0.01,
                     help="lockstep step, a multiple of 0.0025 s (default: 0.01)")
    sim.add_argument("--seed", metavar="S", type=int, default=0,
                     help="seed of wind, sensor noise and loss (default: 0)")
    sim.add_argument("--wind", metavar="SPEED[,DIR[,GUST[,TAU]]]", default=None,
                     help="steady wind [m/s] towards DIR [deg from north, default: random from the seed], "
                          "gust standard deviation [m/s], gust correlation time [s] (default 2)")
    sim.add_argument("--start-altitude", metavar="M", type=float, default=0.0,
                     help="start at rest this high above home (default: on the ground)")
    sim.add_argument("--start-attitude", metavar="ROLL,PITCH,YAW", default=None,
                     help="initial Euler angles [deg]; tilted on the ground = resting on a slope")
    sim.add_argument("--param", metavar="NAME=VALUE", action="append", default=[],
                     help="ArduPilot parameter override, repeatable (e.g. GUID_OPTIONS=8)")
    sim.add_argument("--sysid", metavar="N", type=int, default=None, help="MAVLink system id (SYSID_THISMAV)")
    sim.add_argument("--prearm-delay", metavar="S", type=float, default=0.0,
                     help="refuse arming for S simulated seconds after boot (a real autopilot's EKF takes ~20 s)")
    sim.add_argument("--emulate", choices=EMULATIONS, default=None,
                     help="fly ArduCopter's own inner loop, motors, spool-up, EKF start-up, GUID_TIMEOUT and "
                          "status (sitl/copter/ardupilot_emulation) on ArduPilot SITL's X quad (unless --vehicle)")
    sim.add_argument("--ekf-ready-s", metavar="S", type=float, default=None,
                     help=f"with --emulate: the EKF is ready (position, arming) S s after boot "
                          f"(default {EKF_READY_S:g}, as measured on the firmware)")


def _fault_options(f: argparse._ArgumentGroup) -> None:
    f.add_argument("--motor-scale", metavar="A,B,C,D", default=None,
                   help="thrust produced per thrust commanded, motors 1..4, each 0.3..1.5 (a weak motor: "
                        "0.85,1,1,1; as ArduPilot SIM_ENGINE_MUL)")
    f.add_argument("--com-offset", metavar="X,Y,Z", default=None,
                   help="centre of mass moved by X,Y,Z m (FRD, each within 0.1 m): the rotor arms about it")
    f.add_argument("--mass-scale", metavar="S", type=float, default=None,
                   help="true mass = S x the vehicle file's (0.5..2); MOT_THST_HOVER stays nominal")
    f.add_argument("--inertia-scale", metavar="S", type=float, default=None,
                   help="true inertia = S x the vehicle file's (0.5..2)")
    f.add_argument("--clock-rate", metavar="R", type=float, default=None,
                   help="the vehicle clock (time_boot_ms, time_usec) runs R times simulated time (0.9..1.1; "
                        "PX4 SITL ~0.988); the physics does not change")


def _link_options(link: argparse._ArgumentGroup) -> None:
    link.add_argument("--baud", metavar="N", type=int, default=None,
                      help="byte rate limit as a serial line, 10 bits/byte (default: 115200 with --rig, 57600 with "
                           "--pty, else none; 0 = none)")
    link.add_argument("--loss", metavar="P", type=float, default=0.0, help="probability of losing a frame (0..1)")
    link.add_argument("--latency", metavar="S", type=float, default=0.0, help="one-way latency [s]")
    link.add_argument("--signing-key", metavar="KEY", default=None,
                      help="MAVLink 2 signing: 64 hex digits, or a passphrase (key = SHA-256 of it, as MAVProxy)")
    link.add_argument("--signing-state", metavar="PATH", default=None,
                      help="with --signing-key: file keeping the signing timestamps across restarts (default: "
                           "${XDG_CACHE_HOME:-~/.cache}/quadrotor-sitl/signing-<hash of key and sysid>.json)")


def _describe(v: VehicleParams) -> str:
    tq = v.max_torque_nm
    ix = v.inertia_diagonal
    return "\n".join([
        f"vehicle          {v.name} ({v.source}), plant {v.model}",
        f"mass             {v.mass_kg:g} kg, inertia diag {ix[0]:g} {ix[1]:g} {ix[2]:g} kg m^2",
        f"full thrust      {v.max_total_thrust_n:g} N (4 x {v.rotors.max_thrust_n:g} N) = thrust 1.0",
        f"hover thrust     {v.hover_thrust_fraction:.4f} (MOT_THST_HOVER)",
        f"max torque       roll {tq[0]:.4f}  pitch {tq[1]:.4f}  yaw {tq[2]:.4f} N m = controls 1.0",
        f"max ang. accel   roll {tq[0] / ix[0]:.1f}  pitch {tq[1] / ix[1]:.1f}  yaw {tq[2] / ix[2]:.2f} rad/s^2",
        *([] if v.faults.nominal else [f"faults           {v.faults.describe()} (the autopilot flies the nominal "
                                       "values above)"]),
    ])


def _describe_rig() -> str:
    p, s, n = RigParams(), RigSafetyParams(), RigSensorParams()
    return "\n".join([
        f"rig              4dof: x, z, roll, pitch (y and yaw locked), mass {p.mass_kg:g} kg",
        f"stops            roll +-{math.degrees(p.roll_stop_rad):g} deg, "
        f"pitch +-{math.degrees(p.pitch_stop_rad):g} deg",
        f"motors           4 x {p.max_motor_thrust_n:g} N (PWM 1023), arm {p.arm_length_m:g} m, inertia roll "
        f"{p.inertia_roll_kg_m2:g} pitch {p.inertia_pitch_kg_m2:g} kg m^2; hover {p.hover_thrust_n:g} N",
        f"command limits   thrust 0..{s.max_thrust_n:g} N, |angular accel| <= {s.max_angular_accel_rad_s2:g} rad/s^2",
        f"cut-off          |vz| > {s.max_vz_m_s:g} m/s, |vx| > {s.max_vx_m_s:g} m/s, "
        f"rate > {s.max_angular_rate_rad_s:g} rad/s, z > {s.max_altitude_m:g} m",
        f"watchdog         {s.watchdog_timeout_s:g} s without control: descend at {s.descent_rate_m_s:g} m/s",
        f"ultrasonic       {n.altitude_resolution_m * 100:g} cm steps, mounted {n.mount_height_m * 100:g} cm up, "
        f"range {n.min_range_m * 100:g}..{n.max_range_m * 100:g} cm",
    ])


_MAVLINK_ONLY = (("vehicle", None, "--vehicle"), ("model", None, "--model"), ("wind", None, "--wind"),
                 ("param", [], "--param"), ("sysid", None, "--sysid"), ("prearm_delay", 0.0, "--prearm-delay"),
                 ("signing_key", None, "--signing-key"), ("signing_state", None, "--signing-state"),
                 ("start_attitude", None, "--start-attitude"), ("start_altitude", 0.0, "--start-altitude"),
                 ("emulate", None, "--emulate"), ("ekf_ready_s", None, "--ekf-ready-s"),
                 *((attr, None, option) for option, attr, _, _ in options.FAULT_OPTIONS))


def _run_rig(args: argparse.Namespace) -> int:
    for attr, default, option in _MAVLINK_ONLY:
        if getattr(args, attr) != default:
            raise UsageError(f"{option}: not available with --rig (the rig is served on a pseudo-terminal)")
    for kind, _, option in args.endpoints or []:
        if kind != "pty":
            raise UsageError(f"{option}: not available with --rig (the rig is served on a pseudo-terminal)")
    options.check_common(args, TICK_NS * 1e-9)
    if args.describe:
        print(_describe_rig(), flush=True)
        return 0
    ber = 0.0 if args.bit_error_rate is None else args.bit_error_rate
    baud = args.baud if args.baud is not None else 115200
    clock = MonotonicClock()
    server = RigServer(PtyTransport(clock.now_ns), lockstep=args.lockstep, control_period_s=args.period,
                       seed=args.seed, radio=RadioParams(baud=baud, loss=args.loss, latency_s=args.latency),
                       bit_error_rate=ber, clock=clock)
    return _serve(server, f"rig {args.rig}", args)


def _watch_parent(pid: int, stop) -> None:
    """Call ``stop`` once ``pid`` is no longer this process's parent (it died; we were re-parented)."""

    def watch() -> None:
        while os.getppid() == pid:
            time.sleep(0.2)
        stop()

    threading.Thread(target=watch, name="sitl-parent-watch", daemon=True).start()


def _serve(server: SitlServer | RigServer, what: str, args: argparse.Namespace) -> int:
    def on_signal(signum, frame) -> None:
        server.request_stop()

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    if getattr(args, "parent_pid", None) is not None:
        _watch_parent(args.parent_pid, server.request_stop)
    try:
        strings = getattr(server, "connection_strings", None) or [server.connection_string]
        print("\n".join(strings), flush=True)
        timing = f"lockstep {args.period:g} s" if args.lockstep else "real time"
        print(f"sitl: {what}, {timing}, seed {args.seed}; "
              f"ground station: {', '.join(strings)}", file=sys.stderr, flush=True)
        server.run()
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        server.close()
    return 0


def _run(args: argparse.Namespace) -> int:
    if args.rig is not None:
        return _run_rig(args)
    if args.bit_error_rate is not None:
        raise UsageError("--bit-error-rate: only with --rig")
    options.check_common(args, 0.0025)
    options.check_mavlink(args)
    vehicle = arducopter_sitl_vehicle() if args.emulate and args.vehicle is None else load_vehicle(args.vehicle)
    if args.model is not None:
        vehicle = vehicle.with_model(args.model)
    vehicle = options.faults(args, vehicle)
    if args.describe:
        print(_describe(vehicle), flush=True)
        return 0
    pty = any(kind == "pty" for kind, _, _ in args.endpoints or [])
    baud = args.baud if args.baud is not None else (57600 if pty else 0)
    attitude = args.start_attitude
    if args.emulate and attitude is None:
        attitude = f"0,0,{INITIAL_YAW_DEG}"  # the firmware SITL's heading at boot
    initial = options.initial(args.start_altitude, attitude)
    wind = options.wind(args.wind)
    params = options.params(args.param, args.sysid, vehicle, args.emulate)
    key = options.signing_key(args.signing_key)
    state = None
    if key is not None:
        sysid = int(params.get("SYSID_THISMAV", 1))
        state = args.signing_state if args.signing_state is not None else default_state_path(key, sysid)
    radio = RadioParams(baud=baud, loss=args.loss, latency_s=args.latency)
    clock = _clock(args)
    transports = options.open_endpoints(args.endpoints, clock.now_ns)
    server = SitlServer(transports, vehicle=vehicle, lockstep=args.lockstep, control_period_s=args.period,
                        seed=args.seed, wind=wind, initial=initial, params=params, signing_key=key,
                        signing_state=state, radio=radio, clock=clock, prearm_delay_s=args.prearm_delay,
                        emulate=args.emulate, ekf_ready_s=args.ekf_ready_s)
    what = f"{vehicle.name} ({vehicle.model}{', emulating ' + args.emulate if args.emulate else ''})"
    if not vehicle.faults.nominal:
        what += f", faults: {vehicle.faults.describe()}"
    return _serve(server, what, args)


def _clock(args: argparse.Namespace) -> MonotonicClock:
    """Real time, or ``--speedup`` times faster."""
    if args.speedup == 1.0:
        return MonotonicClock()
    if args.lockstep:
        raise UsageError("--speedup: not with --lockstep (lockstep runs as fast as the ground station)")
    try:
        return ScaledClock(args.speedup)
    except ValueError as exc:
        raise UsageError(f"--speedup: {exc}") from None


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``sitl`` command; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING - 10 * min(args.verbose, 2), stream=sys.stderr,
                        format="sitl: %(levelname)s: %(message)s")
    try:
        return _run(args)
    except QuadrotorError as exc:  # SitlError and the vehicle file's ConfigError
        print(f"sitl: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        return 0
    except BrokenPipeError:
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
