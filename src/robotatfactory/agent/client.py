"""A client of the competition's factory-state server (UDP, plain ASCII; docs/competition.md).

The rules' sequence: PING until PONG, then IWP until the reply is not STOP (the part list: the robot may
move from then on), then OWP/MAP/MBP/CTL as needed. Every request is one datagram; a reply that does not
come within ``timeout`` seconds is retried ``retries`` times (UDP may drop datagrams). Replies are parsed
strictly: a malformed reply raises :class:`ServerReplyError` naming the request and the reply.

No ROS here: the agent's node and tests use it alike.
"""
from __future__ import annotations

import re
import socket
import time
from dataclasses import dataclass
from typing import Callable

from ..competition.parts import EMPTY, PartType
from ..errors import ConfigError
from ..simtwo.errors import ProtocolError
from ..simtwo.ports import LOCALHOST, SERVER_UDP_PORT
from .state import ZONE_REQUESTS, FactoryState, Letters

RECV_BUFFER = 512
STOP = "STOP"
PONG = "PONG"
_CTL = re.compile(r"^T(\d{3})$")


class ServerTimeout(TimeoutError):
    """The server did not answer (after every retry) or did not reach the awaited state in time."""


class ServerReplyError(ProtocolError):
    """The server answered something that is not a valid reply to the request (or answered ``ERR ...``)."""


def parse_letters(request: str, reply: str) -> Letters:
    """Four letters of ``R G B X`` (slot 1 first) -> a tuple of PartType / None (empty).

    Raises :class:`ServerReplyError` for ``STOP`` (use :meth:`FactoryClient.wait_start` first), ``ERR`` and
    anything that is not exactly four such letters.
    """
    if reply == STOP:
        raise ServerReplyError(f"{request} -> STOP: the run has not started (poll IWP until it is not STOP)")
    if reply.startswith("ERR"):
        raise ServerReplyError(f"{request} -> {reply!r}: the server refused the request")
    if len(reply) != 4 or any(c not in "RGB" + EMPTY for c in reply):
        raise ServerReplyError(f"{request} -> {reply!r}: expected four letters from R, G, B, X")
    return tuple(None if c == EMPTY else PartType(c) for c in reply)  # type: ignore[return-value]


def parse_ctl(reply: str) -> float:
    """``Txxx`` -> seconds left in the round (whole seconds, as the server rounds them up)."""
    if reply == STOP:
        raise ServerReplyError("CTL -> STOP: the run has not started")
    m = _CTL.match(reply)
    if not m:
        raise ServerReplyError(f"CTL -> {reply!r}: expected T followed by three digits (seconds left)")
    return float(m.group(1))


@dataclass
class ClientCounters:
    """What the client did: datagrams sent, replies received, timeouts (each retry counts), STOP replies."""

    sent: int = 0
    replies: int = 0
    timeouts: int = 0
    stops: int = 0
    stray: int = 0  # datagrams from another address, dropped


class FactoryClient:
    """One UDP socket talking to the factory-state server at (``host``, ``port``).

    ``timeout`` is the wait for one reply (s), ``retries`` the number of re-sends after a timeout.
    ``sleep`` and ``clock`` (monotonic seconds) are injectable for tests. Use as a context manager or
    call :meth:`close`.
    """

    def __init__(self, host: str = LOCALHOST, port: int = SERVER_UDP_PORT, *, timeout: float = 0.2,
                 retries: int = 4, sleep: Callable[[float], None] = time.sleep,
                 clock: Callable[[], float] = time.monotonic):
        if not (timeout > 0):
            raise ConfigError(f"server timeout must be > 0 s, got {timeout!r}")
        if not isinstance(retries, int) or retries < 0:
            raise ConfigError(f"server retries must be a non-negative integer, got {retries!r}")
        try:
            self.address = (socket.gethostbyname(host), int(port))
        except socket.gaierror as e:
            raise ConfigError(f"cannot resolve the factory-state server's host {host!r}: {e.strerror}") from None
        self.timeout = float(timeout)
        self.retries = retries
        self._sleep = sleep
        self._clock = clock
        self.counters = ClientCounters()
        self.started_at: float | None = None  # clock() when the first part list arrived
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.settimeout(self.timeout)

    # ------------------------------------------------------------------------------------------ raw
    def request(self, req: str) -> str:
        """Send ``req`` and return the reply (ASCII, stripped). Retries on timeout; raises ServerTimeout."""
        data = req.encode("ascii")
        self._drain()  # a late reply to an earlier request must not answer this one
        for _ in range(self.retries + 1):
            self._sock.sendto(data, self.address)
            self.counters.sent += 1
            deadline = self._clock() + self.timeout
            while True:
                left = deadline - self._clock()
                if left <= 0:
                    break
                self._sock.settimeout(left)
                try:
                    reply, addr = self._sock.recvfrom(RECV_BUFFER)
                except (socket.timeout, TimeoutError):
                    break
                except ConnectionRefusedError:  # ICMP port unreachable: nothing listens (yet)
                    self._sleep(min(self.timeout, max(0.0, deadline - self._clock())))
                    break
                if addr[1] != self.address[1]:
                    self.counters.stray += 1
                    continue
                self.counters.replies += 1
                return reply.decode("ascii", "replace").strip()
            self.counters.timeouts += 1
        raise ServerTimeout(f"no reply from the factory-state server at udp {self.address[0]}:{self.address[1]} "
                            f"to {req!r} after {self.retries + 1} tries of {self.timeout:g} s")

    def _drain(self) -> None:
        """Discard whatever is waiting in the socket (counted as stray)."""
        self._sock.setblocking(False)
        try:
            while True:
                self._sock.recvfrom(RECV_BUFFER)
                self.counters.stray += 1
        except (BlockingIOError, ConnectionRefusedError):
            pass
        finally:
            self._sock.settimeout(self.timeout)

    # ------------------------------------------------------------------------------------------ sequence
    def wait_pong(self, limit: float = 10.0) -> None:
        """PING until PONG, for at most ``limit`` seconds; raises ServerTimeout (or ServerReplyError)."""
        end = self._clock() + limit
        while True:
            try:
                reply = self.request("PING")
            except ServerTimeout:
                if self._clock() >= end:
                    raise ServerTimeout(f"the factory-state server at udp {self.address[0]}:{self.address[1]} "
                                        f"did not answer PING within {limit:g} s") from None
                continue
            if reply == PONG:
                return
            raise ServerReplyError(f"PING -> {reply!r}: expected PONG")

    def wait_start(self, poll: float = 0.05, limit: float | None = None) -> Letters:
        """IWP until the reply is not STOP; returns the part list (incoming warehouse, slot 1 first).

        Polls every ``poll`` seconds, for at most ``limit`` seconds (None: forever); the robot must not
        move before this returns.
        """
        end = None if limit is None else self._clock() + limit
        while True:
            reply = self.request("IWP")
            if reply != STOP:
                letters = parse_letters("IWP", reply)
                self.started_at = self._clock()
                return letters
            self.counters.stops += 1
            if end is not None and self._clock() >= end:
                raise ServerTimeout(f"the run did not start within {limit:g} s (IWP still answers STOP)")
            self._sleep(poll)

    # ------------------------------------------------------------------------------------------ state
    def zone(self, zone: str) -> Letters:
        """One zone's four slots: ``incoming``, ``outgoing``, ``machine_A`` or ``machine_B``."""
        try:
            req = ZONE_REQUESTS[zone]
        except KeyError:
            raise ConfigError(f"unknown zone {zone!r} (known: {', '.join(ZONE_REQUESTS)})") from None
        return parse_letters(req, self.request(req))

    def time_left(self) -> float:
        """Seconds left in the round (CTL)."""
        return parse_ctl(self.request("CTL"))

    def poll_state(self) -> FactoryState | None:
        """One look without blocking on the start: None while IWP answers STOP (the run has not
        started), else the whole state (:meth:`state`). For callers that run their own loop."""
        reply = self.request("IWP")
        if reply == STOP:
            self.counters.stops += 1
            return None
        incoming = parse_letters("IWP", reply)
        if self.started_at is None:
            self.started_at = self._clock()
        rest = {z: self.zone(z) for z in ("outgoing", "machine_A", "machine_B")}
        return FactoryState(incoming, rest["outgoing"], rest["machine_A"], rest["machine_B"], self.time_left())

    def state(self) -> FactoryState:
        """Every zone and the time left: five requests (IWP, OWP, MAP, MBP, CTL)."""
        zones = {z: self.zone(z) for z in ZONE_REQUESTS}
        return FactoryState(zones["incoming"], zones["outgoing"], zones["machine_A"], zones["machine_B"],
                            self.time_left())

    # ------------------------------------------------------------------------------------------ life
    def close(self) -> None:
        self._sock.close()

    def __enter__(self) -> FactoryClient:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
