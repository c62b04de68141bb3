"""``raf server``: the standalone server as a process (STOP before the timed start, the static layout,
CTL, exit at the end) and the client mode (replies, a clear error when nothing answers)."""
import socket
import subprocess
import sys
import time

import pytest

from robotatfactory.competition import Factory, FactoryServer, RoundSetup, query
from robotatfactory.field import load_field

RAF = [sys.executable, "-m", "robotatfactory"]


def free_udp_port():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for_pong(port, deadline=10.0):
    end = time.monotonic() + deadline
    while time.monotonic() < end:
        try:
            return query("PING", "127.0.0.1", port, timeout=0.2)
        except TimeoutError:
            pass
    raise AssertionError("raf server did not answer PING")


def test_standalone_server_process():
    port = free_udp_port()
    proc = subprocess.Popen(RAF + ["server", "--port", str(port), "--round", "3", "--parts", "RGBX",
                                       "--start-after", "1.5", "--duration", "2", "--exit-at-end"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert wait_for_pong(port) == "PONG"
        assert query("IWP", "127.0.0.1", port) == "STOP"
        assert query("CTL", "127.0.0.1", port) == "STOP"
        end = time.monotonic() + 10
        while query("IWP", "127.0.0.1", port) == "STOP":
            assert time.monotonic() < end, "the run never started"
            time.sleep(0.05)
        assert query("IWP", "127.0.0.1", port) == "RGBX"
        assert query("OWP", "127.0.0.1", port) == "XXXX"
        assert query("MAP", "127.0.0.1", port) == "XXXX"
        assert query("MBP", "127.0.0.1", port) == "XXXX"
        assert query("CTL", "127.0.0.1", port) in ("T002", "T001")
        assert query("nope", "127.0.0.1", port).startswith("ERR unknown request 'nope'")
        out, err = proc.communicate(timeout=15)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    assert "incoming RGBX (given)" in out and "run started" in out and "round over" in out
    assert "STOP" in out and "1 errors" in out


def test_sigterm_stops_it_cleanly():
    port = free_udp_port()
    proc = subprocess.Popen(RAF + ["server", "--port", str(port)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        wait_for_pong(port)
        assert query("IWP", "127.0.0.1", port) == "BBBB"  # round 1, started at once
        proc.terminate()
        out, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    assert "server stopped: 2 requests, 2 replies" in out


def test_query_mode_prints_replies(capsys):
    from robotatfactory.cli import main

    f = Factory(load_field(), RoundSetup.make(2, seed=5))
    f.start(0.0)
    with FactoryServer(f, port=0, clock=lambda: 30.0) as server:
        port = str(server.address[1])
        assert main(["server", "--port", port, "--query", "IWP"]) == 0
        assert capsys.readouterr().out == f.letters("incoming") + "\n"
        assert main(["server", "--port", port, "--query", "CTL", "--query", "PING"]) == 0
        assert capsys.readouterr().out == "CTL -> T570\nPING -> PONG\n"


def test_query_mode_reports_silence(capsys):
    from robotatfactory.cli import main

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as silent:
        silent.bind(("127.0.0.1", 0))
        rc = main(["server", "--port", str(silent.getsockname()[1]), "--query", "PING", "--timeout", "0.2"])
    assert rc == 1
    assert "no reply from the factory-state server" in capsys.readouterr().err


@pytest.mark.parametrize("argv, message", [
    (["server", "--parts", "RGB"], "exactly 4 letters"),
    (["server", "--duration", "0"], "duration"),
    (["server", "--start-after", "-1"], "--start-after"),
])
def test_bad_options_are_clear_errors(capsys, argv, message):
    from robotatfactory.cli import main

    assert main(argv) == 2
    assert message in capsys.readouterr().err
