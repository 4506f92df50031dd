"""The reader: truncated files at any byte, damaged chunks, and input that is not MCAP at all."""

import os

import pytest

from gcs.cli import main
from gcs.errors import LogError
from gcs.log.writer import FlightLog
from gcs.log import topics as T
from gcs.log.mcap.reader import MAGIC, read_log
from quadrotor.state import Command, State


@pytest.fixture(scope="module")
def small_log(tmp_path_factory):
    path = tmp_path_factory.mktemp("reader") / "small.mcap"
    with FlightLog(path, chunk_size_bytes=3000) as log:
        log.metadata("flight", {"controller": "pd"})
        log.attachment("config.json", "application/json", "{}")
        log.flight_start(0, controller="pd", ts_s=0.01)
        for k in range(300):
            log.control_tick(k * 10_000_000, state=State(z=k * 0.01), reference=State(z=1.0),
                             command=Command(9.81, 0, 0, 0), k=k)
            if k % 100 == 0:
                log.event(k * 10_000_000, "note", f"tick {k}")
    return path


def test_complete_log(small_log):
    log = read_log(small_log)
    assert not log.truncated and log.counts[T.STATE] == 300 and log.counts[T.EVENTS] == 3
    assert log.summary_message_count == log.message_count
    assert log.start_ns == 0 and log.end_ns == 299 * 10_000_000
    assert [m["z"] for _, m in log.decoded(T.STATE)] == [k * 0.01 for k in range(300)]


def test_cut_anywhere_reads_what_is_there(small_log, tmp_path):
    data = small_log.read_bytes()
    cut_path = tmp_path / "cut.mcap"
    last = -1
    for cut in list(range(8, 200, 7)) + list(range(200, len(data), max(1, len(data) // 60))) + [len(data) - 1]:
        cut_path.write_bytes(data[:cut])
        log = read_log(cut_path)
        assert log.truncated and log.problem, cut
        n = log.counts.get(T.STATE, 0)
        assert n >= last, "a longer prefix must not read fewer messages"
        last = n
        # What is read is right: a prefix of the ticks, in order.
        assert [m["z"] for _, m in log.decoded(T.STATE)] == [k * 0.01 for k in range(n)]
    assert last > 250  # only the last chunk and the summary are lost at the end


def test_damaged_chunk_stops_there(small_log, tmp_path):
    data = bytearray(small_log.read_bytes())
    full = read_log(small_log, None).message_count
    data[len(data) // 2] ^= 0xFF
    p = tmp_path / "damaged.mcap"
    p.write_bytes(bytes(data))
    log = read_log(p, None)
    assert log.truncated and 0 < log.message_count < full
    assert "byte" in log.problem


@pytest.mark.parametrize("content, message", [
    (b"", "empty file"),
    (b"hello, I am a CSV file\n1,2,3\n", "not an MCAP log"),
    (b"\x89PNG\r\n\x1a\n" + bytes(100), "not an MCAP log"),
])
def test_not_mcap_is_a_clear_error(tmp_path, content, message):
    p = tmp_path / "x.mcap"
    p.write_bytes(content)
    with pytest.raises(LogError, match=message):
        read_log(p)


def test_missing_and_directory(tmp_path):
    with pytest.raises(LogError, match="no such file"):
        read_log(tmp_path / "nope.mcap")
    with pytest.raises(LogError, match="is a directory"):
        read_log(tmp_path)


def test_magic_then_garbage_is_an_empty_truncated_log(tmp_path):
    p = tmp_path / "g.mcap"
    p.write_bytes(MAGIC + os.urandom(3000))
    log = read_log(p)
    assert log.truncated and log.message_count == 0


@pytest.mark.parametrize("action", [["info"], ["metrics"], ["metrics", "--json"], ["export", "--csv", "OUT"],
                                    ["plot", "-o", "OUT/x.png"], ["compare"]])
@pytest.mark.parametrize("content", [b"not an mcap file at all", b"", None, "dir"])
def test_cli_garbage_gives_one_line_error(tmp_path, capsys, action, content):
    p = tmp_path / "in.mcap"
    if content == "dir":
        p = tmp_path
    elif content is not None:
        p.write_bytes(content)
    args = ["log", action[0], str(p)] + [str(tmp_path / a[4:]) if a.startswith("OUT/") else
                                         (str(tmp_path / "out") if a == "OUT" else a) for a in action[1:]]
    code = main(args)
    err = capsys.readouterr().err
    assert code != 0
    assert err.startswith("gcs: error: ") and err.count("\n") == 1 and "Traceback" not in err, err


def test_cli_garbage_in_a_subprocess_has_no_traceback(tmp_path):
    import subprocess
    import sys

    p = tmp_path / "g.mcap"
    p.write_bytes(b"\x00" * 64)
    r = subprocess.run([sys.executable, "-m", "gcs.cli", "log", "info", str(p)], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 1 and r.stdout == ""
    assert r.stderr.strip().startswith("gcs: error:") and "Traceback" not in r.stderr
