"""MCAP flight logs: the writer (:class:`FlightLog`), a robust reader and the review tools.

Every ``gcs fly`` and ``gcs sim`` run writes one MCAP file (``logs/<UTC>_<controller>_<experiment>.mcap``
by default).  Messages are JSON objects with ``jsonschema`` schemas (Foxglove Studio opens the
files as they are); times are integer nanoseconds: the loop's monotonic clock in flight, the
simulated time line in simulation.  The file is chunked and compressed (zstd) and flushed at
least every half second of wall time, so a killed process leaves a readable, truncated file
(every ``gcs log`` tool reads it and says it is truncated).

Topics (paper frame: x north, y east, z **up**; SI units; field names in the schemas)
---------------------------------------------------------------------------------------
``/flight``
    Start of a flight: ``flight`` (index in the file), ``controller``, ``experiment``, ``run``,
    ``seed``, ``ts_s`` (control period), ``steps`` (planned), ``source`` (``sim`` | ``flight``).
    Every message from it up to the next ``/flight`` message belongs to that flight.  A file
    without one is a single flight described by the ``flight`` metadata record.
``/control/state``
    State estimate fed to the controller: x, y, z [m], vx, vy, vz [m/s], roll, pitch, yaw [rad],
    roll_rate, pitch_rate, yaw_rate [rad/s] (Euler-angle rates).
``/control/reference``
    Reference, same fields.  In simulation it has one more message than the commands: the
    reference at the end of the flight.
``/control/error``
    reference - estimate, same fields (yaw wrapped to [-pi, pi)); the sign of ``J_e``.
``/control/command``
    Controller output before the safety envelope: thrust_n [N], roll_accel_rad_s2,
    pitch_accel_rad_s2, yaw_accel_rad_s2 [rad/s²].
``/control/command_limited``
    The same after the safety envelope (flight only; what the output adapter sent).
``/control/horizon``
    ``k`` (control step since the start of the flight), ``steps_to_go`` (j >= 1 of the
    finite-horizon law, 0 when another law flew) and ``mode``: ``horizon`` (within the
    horizon), ``terminal`` / ``restart`` (after it, per ``after_horizon``), ``fallback_pd``
    (PD after the horizon), ``pd`` (the PD controller).
``/control/cost``
    Stage terms of the controller's own cost J (eq. 5 LOC, eq. 17 NLSOC; absent for PD):
    ``state_cost`` = ½ xᵀQx, ``input_cost`` = ½ uᵀRu, ``stage_cost`` their sum (on the truth in
    simulation); J = Σ stage_cost over the horizon + ½ x(M)ᵀH x(M).
``/control/disturbance``
    Flight only, with the disturbance observer on (``[estimator] disturbance``): dx_m_s2, dy_m_s2,
    dz_m_s2 [m/s²], the acceleration eq. 1 misses as the laws are given it (before the reference's
    acceleration is taken off), and velocity_bias_x_m_s, _y_, _z_ [m/s], the offset taken off the
    velocity readings (:class:`gcs.estimate.DisturbanceObserver`).
``/sim/truth``
    Simulation only: the true plant state, same fields as the estimate, one message per tick
    plus the state after the last command (what ``gcs sim`` computes its metrics on).
``/sim/metrics``
    Simulation only: the metrics ``gcs sim`` computed in the run, with ``flight``.
``/flight/metrics``
    Flight only: the metrics ``gcs fly`` computed at the end of the flight (on the estimate and
    the limited commands), which ``gcs log metrics`` reproduces exactly.
``/loop/timing``
    Flight only: ``k``, ``jitter_s``, ``tick_s``, ``deadline_missed`` and per-stage ``*_s``.
``/events``
    ``kind`` and ``text`` plus any fields: ``flight_start``, ``phase`` (mission phase changes,
    with ``phase`` and ``index``), ``horizon_end``, ``flight_end``, and in flight mode changes,
    arming, failsafes, warnings.
``/mavlink/in/<TYPE>``, ``/mavlink/out/<TYPE>``
    Decoded MAVLink messages received / sent (pymavlink field names and units).
``/mavlink/raw``
    Every raw frame both ways: ``dir`` (``in`` | ``out``), ``type`` and ``data_b64`` (the frame
    bytes, base64), in order, for replay; frames of other systems (``type`` ``DROPPED`` when they
    did not decode) and garbled bytes (``BAD_DATA``) too.
``/rig/in/<NAME>``, ``/rig/out/<NAME>``, ``/rig/raw``
    The same for the 4-DOF rig's serial protocol (docs/rig-protocol.md): decoded messages and
    the escaped frames as on the wire; bytes that held no frame are ``GARBAGE``.
``/foxglove/*``: ``tf``, ``vehicle_pose``, ``reference_pose``, ``reference_path``, ``location``, ``log``
    Foxglove's well-known types (FrameTransform, PoseInFrame, PosesInFrame, LocationFix, Log) for its
    3D, Map and Log panels, beside the channels above: world ENU / body FLU frames, the map track of
    GLOBAL_POSITION_INT, the events and STATUSTEXT (:mod:`gcs.log.foxglove`; docs/foxglove-layout.json).

Metadata record ``flight``: controller(s), experiment, config (path), software_version
(``gcs.__version__``), start_time_utc, command line, and for simulations runs, seed, duration,
wind and sensors.  Attachments: ``config.json`` (the resolved config, what ``gcs log metrics``
rebuilds the config from), ``config.toml`` (the file as read, when there is one) and
``gains/<controller>.json`` (the designed gains: LOC Riccati gain tables by steps to go, NLSOC
weights, PD gains).

One file per ``gcs sim`` invocation: its flights (every controller, every run) are laid one after
the other on the file's time line (1 s apart), each announced on ``/flight``; ``gcs log metrics``
recomputes every flight's metrics from ``/sim/truth``, ``/control/reference``,
``/control/command`` and the attached config, equal to the figures ``gcs sim`` printed.

The pipeline (one for ``gcs fly`` and ``gcs sim``): a producer —
:class:`~gcs.log.recorder.FlightRecorder` in the flight loop,
:class:`~gcs.log.simrecorder.SimRecorder` in the simulation — builds typed records
(:mod:`~gcs.log.records`: numbers and bytes, nothing formatted) and hands lists of them to a
sink (:mod:`~gcs.log.sink`): :class:`~gcs.log.sink.BackgroundSink` frames them
(:mod:`~gcs.log.framing`) to the writer process ``python -m gcs.log.worker``
(:mod:`~gcs.log.worker`), :class:`~gcs.log.sink.InlineSink` writes them in this process.
Either way :class:`~gcs.log.foxglove_encoder.FoxgloveEncoder` (:class:`~gcs.log.encoder.RecordEncoder`
plus the ``/foxglove/*`` channels) turns each record into its messages
(:mod:`~gcs.log.jsonfmt`, :mod:`~gcs.log.linkframes`, stage costs by :mod:`gcs.control.cost`) on a
:class:`~gcs.log.writer.FlightLog`, an MCAP file of :mod:`gcs.log.mcap` (the format layer:
writer and robust reader, knowing nothing of flights).  The review tools (:mod:`gcs.log.review`)
read the files back with :mod:`gcs.log.mcap.reader` and :mod:`~gcs.log.topics` only.  Times are
the loop's clock in flight — the vehicle's time since boot in lockstep, UTC (the monotonic clock
plus a fixed offset) in real time — and the simulated time line in simulation.

Writing a log directly (one :class:`FlightLog` per flight, times from the loop's clock)::

    check_writable(path, expected_bytes)               # pre-flight: directory, free space
    with FlightLog(path) as log:                       # finished on exit, also on exceptions
        log.metadata("flight", run_metadata(config, [controller], source="flight"))
        for name, media, data in run_attachments(config, {controller: designed}):
            log.attachment(name, media, data)          # gcs.log.meta
        log.flight_start(t0_ns, controller=controller, experiment=config.experiment.name,
                         ts_s=config.experiment.ts_s)
        every tick:
            log.control_tick(t_ns, state=est, reference=ref, command=cmd, command_limited=sent,
                             k=k, steps_to_go=j, mode="horizon", cost=None)
            log.loop_timing(t_ns, k=k, jitter_s=..., tick_s=..., deadline_missed=False)
            log.mavlink(t_ns, "in", msg) / log.mavlink(t_ns, "out", msg)   # decoded + raw frame
        on a mode change, arming, failsafe, warning:
            log.event(t_ns, "failsafe", "link lost: landing", stale_s=0.4)

Modules: :mod:`~gcs.log.topics` (names, fields, schemas), :mod:`~gcs.log.records`,
:mod:`~gcs.log.recorder`, :mod:`~gcs.log.simrecorder`, :mod:`~gcs.log.sink`,
:mod:`~gcs.log.framing`, :mod:`~gcs.log.worker`, :mod:`~gcs.log.encoder`,
:mod:`~gcs.log.jsonfmt`, :mod:`~gcs.log.linkframes`,
:mod:`~gcs.log.writer` (:class:`FlightLog`), :mod:`~gcs.log.meta` (metadata, config and gains
attachments, log file names), :mod:`gcs.log.mcap` (the format layer), :mod:`gcs.log.review` (the
``gcs log`` tools).
"""
