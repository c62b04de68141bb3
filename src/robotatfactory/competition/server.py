"""The factory-state server of the rules: UDP, plain ASCII, one request per datagram, one reply each.

| request | reply |
|---|---|
| ``IWP`` / ``OWP`` | incoming / outgoing warehouse, four letters, slot 1 (smallest x) first, e.g. ``BGGR`` |
| ``MAP`` / ``MBP`` | machine A / B, four letters in the server order 1 2 / 3 4, e.g. ``BXXG`` |
| ``CTL`` | ``Txxx``: whole seconds left in the round (rounded up, zero padded, 000..999) |
| ``PING`` | ``PONG`` (always, also before the start) |
| IWP/OWP/MAP/MBP/CTL before the run starts | ``STOP`` |
| anything else | ``ERR <reason>``, e.g. ``ERR unknown request 'XYZ' (known: IWP OWP MAP MBP CTL PING)`` |

Replies go to the sender's address and port, ASCII without a line end. Requests are case-sensitive;
surrounding blanks, CR, LF and NUL bytes are ignored. See docs/competition.md.
"""
from __future__ import annotations

import logging
import math
import socket
import threading
import time
from typing import Callable

from ..errors import ConfigError
from ..simtwo.ports import LOCALHOST, SERVER_UDP_PORT, bind_udp
from ..ratelog import RateLimitedLog
from .factory import Factory

log = logging.getLogger(__name__)

ZONE_OF = {"IWP": "incoming", "OWP": "outgoing", "MAP": "machine_A", "MBP": "machine_B"}
REQUESTS = ("IWP", "OWP", "MAP", "MBP", "CTL", "PING")
MAX_REQUEST = 64  # bytes after trimming; longer requests get an ERR reply
STRIP = b" \t\r\n\x00\x0b\x0c"
RECV_BUFFER = 65535


def ctl_reply(seconds_left: float) -> str:
    """``Txxx``: seconds left rounded up (a countdown shows 600 until a full second has passed), 0..999."""
    if not math.isfinite(seconds_left):
        seconds_left = 0.0
    return f"T{min(999, max(0, math.ceil(seconds_left - 1e-9))):03d}"


def _show(text: str, limit: int = 20) -> str:
    """A request as it appears in an error reply: printable ASCII, control bytes escaped, truncated."""
    shown = "".join(c if 32 <= ord(c) < 127 and c not in "'\\" else f"\\x{ord(c):02x}" for c in text[:limit])
    return shown + ("..." if len(text) > limit else "")


class FactoryServer:
    """Serves ``factory``'s state over UDP from a background thread.

    ``clock`` returns the current simulation time in seconds (the same clock the factory is stepped and
    started with), so ``CTL`` follows simulation time. ``port=0`` binds a free port (see :attr:`address`).
    """

    def __init__(self, factory: Factory, host: str = LOCALHOST, port: int = SERVER_UDP_PORT,
                 clock: Callable[[], float] = time.monotonic, *, log_requests: bool = False):
        if not isinstance(port, int) or isinstance(port, bool) or not 0 <= port <= 65535:
            raise ConfigError(f"server port must be an integer 0..65535, got {port!r}")
        self.factory = factory
        self.host = host
        self.port = port
        self.clock = clock
        self.log_requests = log_requests
        self._sock: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._stopping = threading.Event()
        self._lock = threading.Lock()
        self._counters = dict(requests=0, replies=0, stop_replies=0, errors=0, internal_errors=0,
                              send_errors=0, recv_errors=0, **{r: 0 for r in REQUESTS})
        self._rlog = RateLimitedLog(log)

    # --------------------------------------------------------------------------------------- the protocol
    def answer(self, data: bytes, now: float | None = None) -> str:
        """The reply to one request datagram (counts it). Never raises."""
        try:
            reply, kind = self._answer(data, now)
        except Exception as e:  # a bug must not silence the server: answer, count, log
            self._rlog.warn("internal", "internal error answering %r: %r", data[:40], e)
            reply, kind = "ERR internal error", "internal_errors"
        with self._lock:
            self._counters["requests"] += 1
            if kind in ("errors", "internal_errors"):
                self._counters["errors"] += 1
            if kind != "errors":
                self._counters[kind] = self._counters.get(kind, 0) + 1
            if reply == "STOP":
                self._counters["stop_replies"] += 1
        return reply

    def _answer(self, data: bytes, now: float | None) -> tuple[str, str]:
        if isinstance(data, str):
            data = data.encode("utf-8", "replace")
        req_bytes = bytes(data).strip(STRIP)
        if not req_bytes:
            return "ERR empty request", "errors"
        if len(req_bytes) > MAX_REQUEST:
            return f"ERR request too long ({len(req_bytes)} bytes, at most {MAX_REQUEST})", "errors"
        try:
            req = req_bytes.decode("ascii")
        except UnicodeDecodeError:
            return "ERR request is not ASCII", "errors"
        if req == "PING":
            return "PONG", "PING"
        if req not in ZONE_OF and req != "CTL":
            hint = ""
            if req.upper() in REQUESTS:
                hint = f"; requests are case-sensitive: did you mean '{req.upper()}'?"
            return f"ERR unknown request '{_show(req)}' (known: {' '.join(REQUESTS)}{hint})", "errors"
        if not self.factory.started:
            return "STOP", req
        if req == "CTL":
            t = self.clock() if now is None else now
            return ctl_reply(self.factory.time_left(t)), req
        return self.factory.letters(ZONE_OF[req]), req

    # ------------------------------------------------------------------------------------------ the loop
    def start(self) -> FactoryServer:
        """Bind the socket and serve from a daemon thread. Raises ConfigError if the address is taken."""
        if self._thread is not None:
            return self
        sock = bind_udp(socket.socket(socket.AF_INET, socket.SOCK_DGRAM), self.host, self.port,
                        "the factory-state server", "another server, e.g. raf sim, already there? choose another port")
        sock.settimeout(0.1)
        self._sock = sock
        self._stopping.clear()
        self._thread = threading.Thread(target=self._serve, name="factory-server", daemon=True)
        self._thread.start()
        log.info("factory-state server on udp %s:%d", *self.address)
        return self

    def stop(self) -> None:
        """Stop serving and close the socket (idempotent)."""
        self._stopping.set()
        if self._thread is not None and self._sock is not None:
            try:  # wake the receive call at once instead of waiting for its timeout
                host, port = self._sock.getsockname()[:2]
                with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
                    s.sendto(b"", ("127.0.0.1" if host == "0.0.0.0" else host, port))
            except OSError:
                pass
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def __enter__(self) -> FactoryServer:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    @property
    def address(self) -> tuple[str, int]:
        """(host, port) actually bound (the real port when constructed with port 0)."""
        if self._sock is not None:
            return self._sock.getsockname()[:2]
        return self.host, self.port

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    @property
    def counters(self) -> dict[str, int]:
        """requests, replies, stop_replies, errors (ERR replies), internal_errors, send_errors,
        recv_errors, and one count per known request name (IWP ... PING)."""
        with self._lock:
            return dict(self._counters)

    def _serve(self) -> None:
        sock = self._sock
        while not self._stopping.is_set():
            try:
                data, addr = sock.recvfrom(RECV_BUFFER)
            except socket.timeout:
                continue
            except OSError as e:
                if self._stopping.is_set():
                    break
                with self._lock:
                    self._counters["recv_errors"] += 1
                self._rlog.warn("recv", "factory-state server receive error: %s", e)
                time.sleep(0.01)
                continue
            if self._stopping.is_set():
                break
            reply = self.answer(data)
            if self.log_requests:
                log.info("%s:%d %r -> %r", addr[0], addr[1], data[:MAX_REQUEST], reply)
            elif reply.startswith("ERR"):
                self._rlog.warn("bad_request", "factory-state server: %s:%d sent %r -> %s", addr[0], addr[1],
                                data[:40], reply)
            with self._lock:  # counted before sending, so a client that got its reply sees it counted
                self._counters["replies"] += 1
            try:
                sock.sendto(reply.encode("ascii"), addr)
            except OSError as e:
                with self._lock:
                    self._counters["replies"] -= 1
                    self._counters["send_errors"] += 1
                self._rlog.warn("send", "factory-state server cannot reply to %s: %s", addr, e)


def query(request: str, host: str = LOCALHOST, port: int = SERVER_UDP_PORT, timeout: float = 1.0) -> str:
    """Send one request to a factory-state server and return its reply (ASCII, decoded).

    Raises TimeoutError with a clear message when nothing answers within ``timeout`` seconds.
    """
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.settimeout(timeout)
        try:
            s.sendto(request.encode("ascii", "replace"), (host, port))
            data, _ = s.recvfrom(RECV_BUFFER)
        except (socket.timeout, TimeoutError):
            raise TimeoutError(f"no reply from the factory-state server at udp {host}:{port} within {timeout:g} s "
                               f"to {request!r} (is raf server or raf sim running there?)") from None
        except ConnectionRefusedError:
            raise TimeoutError(f"nothing listens on udp {host}:{port} (is raf server or raf sim running?)") from None
        except socket.gaierror as e:
            raise ConfigError(f"cannot resolve host {host!r}: {e.strerror}") from None
    return data.decode("ascii", "replace")
