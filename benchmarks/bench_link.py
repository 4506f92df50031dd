"""MAVLink link overhead: ``gcs.link.mavlink.MavlinkLink`` beside raw pymavlink (issue 7).

Run: ``python benchmarks/bench_link.py [--quick] [--json]``.

What a ``gcs fly`` tick pays to the link, per message, over a UDP loopback pair
(our link on ``udpin:127.0.0.1:<port>``, a plain socket as the vehicle):

* up: ``MavlinkLink.send(mav.set_attitude_target_encode(...))`` (what the output
  adapter and ``gcs fly`` do each tick: encode, pack, ``sendto``, counters);
* down: ``MavlinkLink.drain()`` of ATTITUDE and LOCAL_POSITION_NED frames, one
  datagram each as the SITL sends them (``recv_msg`` until empty: ``recvfrom``,
  parse, pymavlink's bookkeeping, our system filter and counters).

Baselines, the same messages through raw pymavlink (``mavlink.MAVLink``):
``set_attitude_target_encode(...).pack()`` and ``parse_buffer(frame)`` alone (the
codec), and the codec plus the bare socket call (``sendto`` / ``recvfrom``), so the
difference splits into socket and wrapper.  Batches of 50 frame pairs are sent, then
drained (the socket buffer holds them all); the figures are the median over batches
of the time per message.  The rig's XBee protocol (``quadrotor.rig_protocol`` encode and
``RigDecoder.feed``) is measured by ``bench_rig.py`` (frames/s); it is not repeated here.
"""

from __future__ import annotations

import argparse
import socket
import statistics
import sys
import time

from benchlib import document, emit, row
from gcs.link.mavlink import MavlinkLink, mavlink

PAIRS = 50  # frame pairs per batch: 100 datagrams, well inside the default receive buffer


def _setpoints(n: int) -> list[tuple]:
    """Varied SET_ATTITUDE_TARGET fields (quaternion, rates, thrust) as the adapter produces them."""
    out = []
    for i in range(n):
        s = 1e-3 * (i % 17)
        out.append(((1.0 - s * s, s, -s, 0.5 * s), 0.01 * s, -0.02 * s, 0.0, 0.39 + s))
    return out


def _vehicle_frames(pairs: int) -> list[bytes]:
    """ATTITUDE and LOCAL_POSITION_NED frames of system 1, alternating, as packed bytes."""
    vmav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    frames = []
    for i in range(pairs):
        t = 10 * i
        frames.append(vmav.attitude_encode(t, 0.01, -0.02, 1.5 + 1e-4 * i, 0.001, 0.002, 0.0).pack(vmav))
        frames.append(vmav.local_position_ned_encode(t, 1.0, 2.0, -1.5 - 1e-4 * i, 0.1, 0.0, -0.01).pack(vmav))
    return frames


def _empty(sock: socket.socket) -> int:
    n = 0
    while True:
        try:
            sock.recvfrom(65535)
        except BlockingIOError:
            return n
        n += 1


class Pair:
    """Our link on udpin plus a plain UDP socket standing for the vehicle (and a second plain pair)."""

    def __init__(self) -> None:
        self.link = MavlinkLink("udpin:127.0.0.1:0", target_system=1, target_component=1)
        self.link_addr = self.link.conn.port.getsockname()
        self.vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.vehicle.bind(("127.0.0.1", 0))
        self.vehicle.setblocking(False)
        # The link learns the vehicle's address from its first frame.
        hb = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        self.vehicle.sendto(hb.heartbeat_encode(2, 3, 0, 0, 0).pack(hb), self.link_addr)
        end = time.monotonic() + 2.0
        while self.link.vehicle_addr is None and time.monotonic() < end:
            self.link.drain()
        if self.link.vehicle_addr is None:
            raise RuntimeError("the link did not see the vehicle's heartbeat")
        # Raw baseline pair: plain sockets both ends.
        self.raw_rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.raw_rx.bind(("127.0.0.1", 0))
        self.raw_rx.setblocking(False)
        self.raw_rx_addr = self.raw_rx.getsockname()

    def close(self) -> None:
        self.link.close()
        self.vehicle.close()
        self.raw_rx.close()


def bench_send_link(pair: Pair, batches: int) -> float:
    """Median us per SET_ATTITUDE_TARGET through MavlinkLink (encode + send)."""
    link, sps = pair.link, _setpoints(PAIRS)
    mav, ts, tc = link.mav, link.target_system, link.target_component
    times = []
    for _ in range(batches):
        t0 = time.perf_counter()
        for i, (q, rr, pr, yr, th) in enumerate(sps):
            link.send(mav.set_attitude_target_encode(i, ts, tc, 0, q, rr, pr, yr, th))
        times.append((time.perf_counter() - t0) / PAIRS * 1e6)
        _empty(pair.vehicle)
    return statistics.median(times)


def bench_send_raw(pair: Pair, batches: int, with_socket: bool) -> float:
    """Median us per SET_ATTITUDE_TARGET through raw pymavlink (encode + pack [+ sendto])."""
    mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    sps, sock, dest = _setpoints(PAIRS), pair.vehicle, pair.raw_rx_addr
    times = []
    for _ in range(batches):
        t0 = time.perf_counter()
        if with_socket:
            for i, (q, rr, pr, yr, th) in enumerate(sps):
                sock.sendto(mav.set_attitude_target_encode(i, 1, 1, 0, q, rr, pr, yr, th).pack(mav), dest)
        else:
            for i, (q, rr, pr, yr, th) in enumerate(sps):
                mav.set_attitude_target_encode(i, 1, 1, 0, q, rr, pr, yr, th).pack(mav)
        times.append((time.perf_counter() - t0) / PAIRS * 1e6)
        _empty(pair.raw_rx)
    return statistics.median(times)


def bench_drain_link(pair: Pair, batches: int) -> tuple[float, int]:
    """Median us per ATTITUDE / LOCAL_POSITION_NED message of MavlinkLink.drain(); messages lost."""
    frames = _vehicle_frames(PAIRS)
    link, sock, dest = pair.link, pair.vehicle, pair.link_addr
    times, lost = [], 0
    for _ in range(batches):
        for f in frames:
            sock.sendto(f, dest)
        t0 = time.perf_counter()
        got = link.drain()
        dt = time.perf_counter() - t0
        n = sum(1 for m in got if m.get_type() in ("ATTITUDE", "LOCAL_POSITION_NED"))
        lost += len(frames) - n
        times.append(dt / max(n, 1) * 1e6)
    return statistics.median(times), lost


def bench_decode_raw(pair: Pair, batches: int, with_socket: bool) -> float:
    """Median us per message of raw pymavlink ``parse_buffer`` [+ ``recvfrom``] on the same frames."""
    frames = _vehicle_frames(PAIRS)
    mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    mav.robust_parsing = True  # as the link parses
    sock, rx, dest = pair.vehicle, pair.raw_rx, pair.raw_rx_addr
    times = []
    for _ in range(batches):
        n = 0
        if with_socket:
            for f in frames:
                sock.sendto(f, dest)
            t0 = time.perf_counter()
            while True:
                try:
                    data = rx.recv(65535)
                except BlockingIOError:
                    break
                n += len(mav.parse_buffer(data) or ())
        else:
            t0 = time.perf_counter()
            for f in frames:
                n += len(mav.parse_buffer(f) or ())
        dt = time.perf_counter() - t0
        times.append(dt / max(n, 1) * 1e6)
    return statistics.median(times)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer batches")
    ap.add_argument("--json", action="store_true", help="text on stderr, one JSON document on stdout")
    args = ap.parse_args(argv)
    batches = 15 if args.quick else 61
    pair = Pair()
    try:
        bench_send_link(pair, 2)  # warm-up
        d = {"pairs_per_batch": PAIRS, "batches": batches}
        d["send_link_us"] = bench_send_link(pair, batches)
        d["send_raw_codec_us"] = bench_send_raw(pair, batches, with_socket=False)
        d["send_raw_socket_us"] = bench_send_raw(pair, batches, with_socket=True)
        d["drain_link_us"], d["drain_lost"] = bench_drain_link(pair, batches)
        d["decode_raw_codec_us"] = bench_decode_raw(pair, batches, with_socket=False)
        d["decode_raw_socket_us"] = bench_decode_raw(pair, batches, with_socket=True)
    finally:
        pair.close()
    # One 100 Hz tick: 1 message up, 2 down.
    d["tick_link_us"] = d["send_link_us"] + 2 * d["drain_link_us"]
    d["tick_raw_socket_us"] = d["send_raw_socket_us"] + 2 * d["decode_raw_socket_us"]
    d["tick_raw_codec_us"] = d["send_raw_codec_us"] + 2 * d["decode_raw_codec_us"]
    rows = [
        row("up: SET_ATTITUDE_TARGET, MavlinkLink encode+send", d["send_link_us"], "us/msg",
            baseline="raw pymavlink encode+pack", baseline_value=d["send_raw_codec_us"]),
        row("up: raw pymavlink encode+pack+sendto", d["send_raw_socket_us"], "us/msg",
            baseline="raw pymavlink encode+pack", baseline_value=d["send_raw_codec_us"]),
        row("down: ATTITUDE/LOCAL_POSITION_NED, MavlinkLink.drain", d["drain_link_us"], "us/msg",
            baseline="raw pymavlink parse_buffer", baseline_value=d["decode_raw_codec_us"],
            note=f"{d['drain_lost']} lost" if d["drain_lost"] else ""),
        row("down: raw pymavlink recv+parse_buffer", d["decode_raw_socket_us"], "us/msg",
            baseline="raw pymavlink parse_buffer", baseline_value=d["decode_raw_codec_us"]),
        row("one tick (1 up, 2 down), MavlinkLink", d["tick_link_us"], "us",
            baseline="raw pymavlink + socket", baseline_value=d["tick_raw_socket_us"]),
    ]
    text = "\n".join([
        f"MAVLink 2 over UDP loopback, per message; median of {batches} batches of {PAIRS} frame pairs",
        f"{'':<44} {'MavlinkLink':>12} {'raw+socket':>11} {'raw codec':>10} {'link/raw':>9}",
        f"{'up:   SET_ATTITUDE_TARGET (encode+send)':<44} {d['send_link_us']:>10.1f}us "
        f"{d['send_raw_socket_us']:>9.1f}us "
        f"{d['send_raw_codec_us']:>8.1f}us {d['send_link_us'] / d['send_raw_codec_us']:>8.2f}x",
        f"{'down: ATTITUDE + LOCAL_POSITION_NED (drain)':<44} {d['drain_link_us']:>10.1f}us "
        f"{d['decode_raw_socket_us']:>9.1f}us "
        f"{d['decode_raw_codec_us']:>8.1f}us {d['drain_link_us'] / d['decode_raw_codec_us']:>8.2f}x",
        f"{'one 100 Hz tick (1 up + 2 down)':<44} {d['tick_link_us']:>10.1f}us {d['tick_raw_socket_us']:>9.1f}us "
        f"{d['tick_raw_codec_us']:>8.1f}us {d['tick_link_us'] / d['tick_raw_codec_us']:>8.2f}x",
        f"messages lost in the loopback: {d['drain_lost']}",
        "rig protocol (XBee frames): encode / RigDecoder.feed throughput in bench_rig.py",
    ])
    emit(document("link", args.quick, d, rows), text, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
