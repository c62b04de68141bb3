"""The factory-state server over real UDP on loopback (a free port): every request type, STOP before the
start, the CTL countdown in simulation time, unknown requests and garbage never silence or crash it."""
import socket
import threading

import pytest
from hypothesis import given, settings, strategies as st

from robotatfactory.competition import (MAX_REQUEST, Factory, FactoryServer, KinematicWorld, RoundSetup, ctl_reply,
                                        query)
from robotatfactory.errors import ConfigError
from robotatfactory.field import load_field

FIELD = load_field()


class SimClock:
    """A settable simulation clock."""

    def __init__(self, t=0.0):
        self.t = t

    def __call__(self):
        return self.t


@pytest.fixture
def client():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(2.0)
    yield s
    s.close()


def ask(sock, server, payload):
    if isinstance(payload, str):
        payload = payload.encode("ascii")
    sock.sendto(payload, server.address)
    data, addr = sock.recvfrom(65535)
    assert addr == server.address  # the reply comes from the server's port
    return data.decode("ascii")


@pytest.fixture
def running():
    """A round-3 world with the server on a free port, its clock following the world's simulation time."""
    w = KinematicWorld(FIELD, RoundSetup.make(3, parts="RGBX", processing_delay=1.0, duration=120.0))
    server = FactoryServer(w.factory, port=0, clock=lambda: w.t)
    server.start()
    yield w, server
    server.stop()


def test_stop_before_the_start_pong_always(running, client):
    w, server = running
    for req in ("IWP", "OWP", "MAP", "MBP", "CTL"):
        assert ask(client, server, req) == "STOP"
    assert ask(client, server, "PING") == "PONG"
    c = server.counters
    assert c["stop_replies"] == 5 and c["PING"] == 1 and c["requests"] == 6 and c["errors"] == 0


def test_every_request_after_the_start(running, client):
    w, server = running
    w.advance(2.0)
    w.start()
    assert ask(client, server, "IWP") == "RGBX"
    assert ask(client, server, "OWP") == "XXXX"
    assert ask(client, server, "MAP") == "XXXX"
    assert ask(client, server, "MBP") == "XXXX"
    assert ask(client, server, "CTL") == "T120"
    assert ask(client, server, "PING") == "PONG"
    # the robot brings the red part to machine A slot 3, then the green one to machine B slot 1
    w.pick(1); w.place(1, "machine_A", 3)
    w.pick(2); w.place(2, "machine_B", 1)
    assert ask(client, server, "IWP") == "XXBX"
    assert ask(client, server, "MAP") == "XXRX"
    w.advance(1.2)  # both machines finish
    assert ask(client, server, "MAP") == "XXXG"
    assert ask(client, server, "MBP") == "XBXX"
    w.pick(3); w.place(3, "outgoing", 4)
    assert ask(client, server, "OWP") == "XXXB"
    w.pick(2); w.place(2, "outgoing", 1)
    assert ask(client, server, "OWP") == "BXXB"
    c = server.counters
    assert c["IWP"] == 2 and c["MAP"] == 3 and c["OWP"] == 3 and c["replies"] == c["requests"] == 12


def test_ctl_counts_down_in_simulation_time():
    f = Factory(FIELD, RoundSetup.make(1, duration=600))
    clock = SimClock(100.0)
    with FactoryServer(f, port=0, clock=clock) as server, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as c:
        c.settimeout(2.0)
        assert ask(c, server, "CTL") == "STOP"
        f.start(100.0)
        assert ask(c, server, "CTL") == "T600"
        clock.t = 100.5
        assert ask(c, server, "CTL") == "T600"  # rounded up: a full second has not passed
        clock.t = 101.0
        assert ask(c, server, "CTL") == "T599"
        clock.t = 100.0 + 590.2
        assert ask(c, server, "CTL") == "T010"
        clock.t = 100.0 + 599.99
        assert ask(c, server, "CTL") == "T001"
        clock.t = 100.0 + 600.0
        assert ask(c, server, "CTL") == "T000"
        clock.t = 5000.0
        assert ask(c, server, "CTL") == "T000"
        assert ask(c, server, "IWP") == "BBBB"  # after the end the state is still served


def test_ctl_reply_format():
    assert [ctl_reply(x) for x in (0, 0.2, 9, 9.5, 99.01, 600, 1000, 5000, -3, float("nan"))] == [
        "T000", "T001", "T009", "T010", "T100", "T600", "T999", "T999", "T000", "T000"]


@pytest.mark.parametrize("payload, reply", [
    (b"IWP\r\n", "RGBX"), (b"  OWP ", "XXXX"), (b"PING\n", "PONG"), (b"CTL\x00\x00\x00", "T120"),
    (b"iwp", "ERR unknown request 'iwp' (known: IWP OWP MAP MBP CTL PING; requests are case-sensitive: "
             "did you mean 'IWP'?)"),
    (b"XYZ", "ERR unknown request 'XYZ' (known: IWP OWP MAP MBP CTL PING)"),
    (b"IWP OWP", "ERR unknown request 'IWP OWP' (known: IWP OWP MAP MBP CTL PING)"),
    (b"IWP\nOWP", "ERR unknown request 'IWP\\x0aOWP' (known: IWP OWP MAP MBP CTL PING)"),
    (b"", "ERR empty request"), (b" \r\n", "ERR empty request"),
    (b"\xff\xfeIWP", "ERR request is not ASCII"), ("PİNG".encode(), "ERR request is not ASCII"),
    (b"A" * (MAX_REQUEST + 1), f"ERR request too long ({MAX_REQUEST + 1} bytes, at most {MAX_REQUEST})"),
    (b"X" * 60000, f"ERR request too long (60000 bytes, at most {MAX_REQUEST})"),
])
def test_trimming_and_error_replies(running, client, payload, reply):
    w, server = running
    w.start()
    assert ask(client, server, payload) == reply
    assert server.running


def test_unknown_requests_before_the_start_are_errors_not_stop(running, client):
    w, server = running
    assert ask(client, server, "HELLO").startswith("ERR unknown request 'HELLO'")
    assert server.counters["errors"] == 1 and server.counters["stop_replies"] == 0


def test_garbage_storm_then_still_answers(running, client):
    w, server = running
    w.start()
    import random

    rng = random.Random(1)
    n = 200
    for _ in range(n):
        blob = bytes(rng.randrange(256) for _ in range(rng.randrange(0, 300)))
        reply = ask(client, server, blob)
        assert reply  # never silence
    assert ask(client, server, "PING") == "PONG"
    c = server.counters
    assert c["requests"] == n + 1 and c["replies"] == n + 1 and c["internal_errors"] == 0


@settings(max_examples=300, deadline=None)
@given(data=st.binary(max_size=200))
def test_answer_never_raises_and_is_ascii(data):
    f = Factory(FIELD, RoundSetup.make(2, seed=3))
    f.start(0.0)
    server = FactoryServer(f, port=0, clock=lambda: 1.0)
    reply = server.answer(data)
    assert reply and reply.isascii() and "\n" not in reply
    assert reply in ("PONG", "T599", f.letters("incoming"), "XXXX") or reply.startswith("ERR ")
    assert server.counters["requests"] == 1


def test_many_clients_each_get_their_own_answer(running):
    w, server = running
    w.start()
    results = {}

    def worker(i):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.settimeout(2.0)
            results[i] = [ask(s, server, req) for req in ("IWP", "PING", "OWP")]

    threads = [threading.Thread(target=worker, args=(i,)) for i in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert all(r == ["RGBX", "PONG", "XXXX"] for r in results.values()) and len(results) == 8


def test_state_updates_while_serving_are_consistent(running, client):
    """The simulator steps in its thread while clients query: every reply is a valid state."""
    w, server = running
    w.start()
    stop = threading.Event()

    def simulate():
        while not stop.is_set():
            w.pick(1); w.place(1, "outgoing", 1)
            w.pick(1); w.place(1, "incoming", 1)

    th = threading.Thread(target=simulate)
    th.start()
    try:
        seen = {ask(client, server, "IWP") for _ in range(100)}
    finally:
        stop.set()
        th.join()
    assert seen <= {"RGBX", "XGBX"}


def test_query_client_and_timeout(running):
    w, server = running
    host, port = server.address
    assert query("PING", host, port, timeout=1.0) == "PONG"
    assert query("IWP", host, port) == "STOP"
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as silent:
        silent.bind(("127.0.0.1", 0))  # bound but never answers
        with pytest.raises(TimeoutError, match="no reply from the factory-state server"):
            query("PING", "127.0.0.1", silent.getsockname()[1], timeout=0.2)


def test_bind_conflict_is_a_config_error(running):
    w, server = running
    with pytest.raises(ConfigError, match="cannot bind"):
        FactoryServer(w.factory, port=server.address[1]).start()
    with pytest.raises(ConfigError, match="port"):
        FactoryServer(w.factory, port=70000)


def test_stop_is_idempotent_and_releases_the_port():
    f = Factory(FIELD, RoundSetup.make(1))
    server = FactoryServer(f, port=0).start()
    port = server.address[1]
    server.stop()
    server.stop()
    assert not server.running
    again = FactoryServer(f, port=port).start()  # the port is free again
    assert again.address[1] == port
    again.stop()
