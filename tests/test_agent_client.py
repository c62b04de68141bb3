"""The agent's factory-state client against the real competition.FactoryServer on loopback."""
import socket
import threading
import time

import pytest

from robotatfactory.agent.client import (FactoryClient, ServerReplyError, ServerTimeout, parse_ctl,
                                         parse_letters)
from robotatfactory.agent.state import FactoryState, SlotRef
from robotatfactory.competition import Factory, FactoryServer, PartType, RoundSetup


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


@pytest.fixture
def served(field):
    clock = Clock()
    factory = Factory(field, RoundSetup.make(3, parts="RGBX", duration=120.0))
    server = FactoryServer(factory, port=0, clock=clock).start()
    yield factory, server, clock
    server.stop()


def test_sequence_ping_wait_start_and_state(served):
    factory, server, clock = served
    host, port = server.address
    polls = []

    def sleep(s):  # the organiser starts the run after the robot's third STOP
        polls.append(s)
        if len(polls) == 3:
            factory.start(0.0)
            clock.t = 1.2

    with FactoryClient(host, port, timeout=0.5, sleep=sleep) as c:
        c.wait_pong()
        assert c.wait_start(poll=0.01) == (PartType.RED, PartType.GREEN, PartType.BLUE, None)
        assert c.counters.stops == 3 and polls == [0.01] * 3
        st = c.state()
    assert st.letters("incoming") == "RGBX" and st.letters("outgoing") == "XXXX"
    assert st.letters("machine_A") == "XXXX" and st.time_left == 119.0
    assert st.at(SlotRef("incoming", 2)) is PartType.GREEN
    assert server.counters["PING"] == 1 and server.counters["IWP"] == 5


def test_retries_a_lost_datagram_then_gives_up_clearly(served):
    _, server, _ = served
    host, port = server.address
    # a relay that drops the first datagram and forwards the rest to the real server
    relay = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    relay.bind(("127.0.0.1", 0))
    relay.settimeout(2.0)
    seen = []

    def run():
        up = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        up.settimeout(2.0)
        for _ in range(2):
            data, addr = relay.recvfrom(512)
            seen.append(data)
            if len(seen) == 1:
                continue  # lost
            up.sendto(data, (host, port))
            relay.sendto(up.recvfrom(512)[0], addr)
        up.close()

    th = threading.Thread(target=run)
    th.start()
    with FactoryClient("127.0.0.1", relay.getsockname()[1], timeout=1.0, retries=2) as c:  # 1 s: a stalled
        assert c.request("PING") == "PONG"                                                  # relay is no loss
        assert c.counters.sent == 2 and c.counters.timeouts == 1
    th.join()
    relay.close()
    # nothing listens: a clear timeout after every retry
    dead = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    dead.bind(("127.0.0.1", 0))
    with FactoryClient("127.0.0.1", dead.getsockname()[1], timeout=0.05, retries=1) as c:
        with pytest.raises(ServerTimeout, match="after 2 tries"):
            c.request("IWP")
        with pytest.raises(ServerTimeout, match="did not answer PING within 0.1 s"):
            c.wait_pong(limit=0.1)
    dead.close()


def test_before_the_start_state_requests_fail_clearly(served):
    _, server, _ = served
    with FactoryClient(*server.address, timeout=0.5) as c:
        with pytest.raises(ServerReplyError, match="not started"):
            c.zone("machine_A")
        with pytest.raises(ServerTimeout, match="did not start within 0 s"):
            c.wait_start(limit=0.0)


def test_parsing_is_strict():
    assert parse_letters("OWP", "XXXB") == (None, None, None, PartType.BLUE)
    assert parse_ctl("T007") == 7.0
    for bad in ("XXB", "XXXBB", "xxxb", "XXQB", "ERR unknown request"):
        with pytest.raises(ServerReplyError, match="OWP"):
            parse_letters("OWP", bad)
    for bad in ("T12", "600", "T1234", "STOP"):
        with pytest.raises(ServerReplyError, match="CTL"):
            parse_ctl(bad)
    s = FactoryState.from_letters("RGBX", machine_A="XXRX")
    assert s.with_slot(SlotRef("machine_A", 3), None).letters("machine_A") == "XXXX"
    assert not s.same_slots(FactoryState.from_letters("RGBX")) and s.same_slots(s)


def test_a_late_reply_to_an_earlier_request_does_not_answer_the_next_one():
    """The server answers PING late (after the client gave up on it); the next request must get its own
    answer, not the stale PONG."""
    srv = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    srv.bind(("127.0.0.1", 0))
    with FactoryClient("127.0.0.1", srv.getsockname()[1], timeout=0.2, retries=0) as c:
        with pytest.raises(ServerTimeout):
            c.request("PING")
        data, addr = srv.recvfrom(512)
        srv.sendto(b"PONG", addr)  # the late answer to PING
        time.sleep(0.1)

        def answer():
            d, a = srv.recvfrom(512)
            srv.sendto(b"XXXX" if d == b"IWP" else b"?", a)

        th = threading.Thread(target=answer)
        th.start()
        assert c.request("IWP") == "XXXX"
        th.join()
        assert c.counters.stray == 1
    srv.close()
