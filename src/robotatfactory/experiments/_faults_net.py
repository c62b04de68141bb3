"""``raf experiment faults``, the network side: the UDP proxy between the simulator and the bridge, and the fuzz.

No ROS here (plain sockets and :mod:`..simtwo`'s codec), so the fuzzer's own process (:func:`fuzzer`, started
by :func:`.faults.part_fuzz` with the ``spawn`` context) imports no middleware.

* :class:`Proxy`: simulator <-> bridge on loopback, in a thread of the part's process. It records every
  SensorFrame the simulator sent (the loss-free, fuzz-free truth: :meth:`Proxy.truth`) and every Command the
  bridge replied; it drops, duplicates and reorders datagrams both ways (:meth:`Proxy.set_faults`), sends the
  in-band fuzz from the simulator's own source address (``inject_queue``) and forges frames with impossible
  encoder totals (``forge_ticks_every``).
* :func:`fuzz_pool`: the fuzz datagrams of each kind (random bytes, mutated copies of a real SensorFrame,
  forged far-future Seq/Tms, oversized, non-ASCII; and the in-band kinds), built once from a real frame.
* :func:`fuzzer`: a separate process sending the out-of-band fuzz to the bridge's port, one kind after the
  other (:data:`FOREIGN_KINDS`, each in its own time segment, from several source ports; the second sender
  streams valid frames from one), reporting per kind the sends that succeeded and the bridge socket's
  kernel drops over the segment (:func:`udp_drops`).
* :func:`udp_drops`: a UDP socket's receive-buffer drop counter from ``/proc/net/udp``.
"""
from __future__ import annotations

import random
import select
import socket
import threading
import time
from collections import deque

import numpy as np

from ..simtwo import Command, ProtocolError
from ..simtwo.messages import encode_link_lost
from ._faults_observe import DELAYED, DROPPED, FORWARDED

LOCAL = "127.0.0.1"


# ------------------------------------------------------------------------------------------------ the proxy

class Proxy:
    """UDP proxy simulator <-> bridge on loopback, with loss, duplication, reordering and in-band injection.

    The simulator sends its frames to :attr:`port`; they go on to the bridge from the same socket, so the
    bridge sees one source. Replies from the bridge go back to the simulator's address (learned from its
    frames). Every frame the simulator sent is recorded (``frames``: wall time, Seq, Tms, totals, x, y, theta;
    ``fates``: what the proxy did with it, :data:`._faults_observe.FORWARDED` ...; ``ranges``: its LIDAR
    ranges when ``record_ranges``, for the observer's scan check: 360 floats a frame, off for long runs).
    """

    def __init__(self, bridge: tuple[str, int], seed: int = 0, record_ranges: bool = False,
                 notify_lost: bool = False):
        from ..simtwo.messages import SensorFrame

        self._decode = SensorFrame.decode
        self.bridge = bridge
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 21)
        self.sock.bind((LOCAL, 0))
        self.sock.setblocking(False)
        self.port = self.sock.getsockname()[1]
        # a draw per datagram, from one generator per direction: which of a reply and the next frame reaches the
        # proxy first depends on the machine's timing, and with one generator it would decide the fates of both
        self.rngs = (random.Random(seed), random.Random(f"{seed}-replies"))
        self.drop = self.dup = self.reorder = 0.0
        self.sim_addr = None
        self.lock = threading.Lock()
        self.frames: list[tuple] = []  # (wall, seq, tms, left, right, x, y, theta)
        self.replies: list[tuple] = []  # (wall, seq, v, w)
        self.fates: list[int] = []  # per frame: forwarded, dropped, delayed (behind the next), duplicated
        self.record_ranges = record_ranges
        self.ranges: list = []  # per frame (record_ranges): its ranges as float32
        self.template: bytes | None = None
        self.counts = {"frames": 0, "replies": 0, "dropped": 0, "duplicated": 0, "reordered": 0, "injected": 0,
                       "reply_errors": 0}
        self._held = {0: None, 1: None}  # a datagram held back per direction (reordering)
        self.inject_queue: deque = deque()
        self.forge_ticks_every = 0  # > 0: after every n-th frame, a copy of the next one with impossible ticks
        # a paced simulator waits for the reply to each frame: tell it (simtwo.messages.LINK_LOST) of every frame, and
        # every reply, dropped or held back, instead of letting it wait out its reply timeout
        self.notify_lost = notify_lost
        self._running = True
        self.thread = threading.Thread(target=self._loop, name="raf-faults-proxy", daemon=True)
        self.thread.start()

    def set_faults(self, drop=0.0, dup=0.0, reorder=0.0) -> None:
        self.drop, self.dup, self.reorder = drop, dup, reorder

    def _out(self, direction: int, data: bytes, addr) -> int:
        """Send (or drop, duplicate, hold back) one datagram; returns its fate."""
        r = self.rngs[direction].random()
        if r < self.drop:
            self.counts["dropped"] += 1
            return 1
        sends = [data]
        fate = 0
        if r < self.drop + self.dup:
            self.counts["duplicated"] += 1
            sends.append(data)
            fate = 3
        elif r < self.drop + self.dup + self.reorder and self._held[direction] is None:
            self.counts["reordered"] += 1
            self._held[direction] = data  # goes out after the next datagram of this direction
            return 2
        held, self._held[direction] = self._held[direction], None
        if held is not None:
            sends.append(held)
        for d in sends:
            try:
                self.sock.sendto(d, addr)
            except OSError:
                self.counts["reply_errors"] += 1
        return fate

    def _loop(self) -> None:
        sock = self.sock
        while self._running:
            r, _, _ = select.select([sock], [], [], 0.05)
            while self.inject_queue:
                try:
                    sock.sendto(self.inject_queue.popleft(), self.bridge)
                    self.counts["injected"] += 1
                except (IndexError, OSError):
                    break
            if not r:
                continue
            while True:
                try:
                    data, addr = sock.recvfrom(65535)
                except (BlockingIOError, InterruptedError):
                    break
                except OSError:
                    break
                now = time.monotonic()
                if addr == self.bridge:
                    self.counts["replies"] += 1
                    c = None
                    try:
                        c = Command.decode(data)
                        with self.lock:
                            self.replies.append((now, c.seq, c.v, c.w))
                    except ProtocolError:
                        pass
                    if self.sim_addr is not None and self._out(1, data, self.sim_addr) in (DROPPED, DELAYED) \
                            and c is not None:
                        self._notify_lost(c.seq)
                    continue
                self.sim_addr = addr
                try:
                    f = self._decode(data)
                except Exception:  # noqa: BLE001 - the simulator never sends garbage, but do not die on it
                    continue
                self.counts["frames"] += 1
                with self.lock:  # recorded before it goes out: whatever the bridge publishes from it is on record
                    self.frames.append((now, f.seq, f.time_ms, f.enc_total[0], f.enc_total[1], f.x, f.y, f.theta))
                    self.fates.append(FORWARDED)
                    k = len(self.fates) - 1
                    if self.record_ranges:
                        self.ranges.append(np.asarray(f.ranges, dtype=np.float32))
                    self.template = data
                fate = self._out(0, data, self.bridge)
                with self.lock:
                    self.fates[k] = fate
                if fate in (DROPPED, DELAYED):
                    self._notify_lost(f.seq)
                if self.forge_ticks_every and self.counts["frames"] % self.forge_ticks_every == 0:
                    self._forge_ticks(f)

    def _notify_lost(self, seq: int) -> None:
        if self.notify_lost and self.sim_addr is not None:
            try:
                self.sock.sendto(encode_link_lost(seq), self.sim_addr)
                self.counts["lost_notices"] = self.counts.get("lost_notices", 0) + 1
            except OSError:
                self.counts["reply_errors"] += 1

    def _forge_ticks(self, f) -> None:
        """The next frame before it comes, with encoder totals the wheels cannot reach in one cycle."""
        import dataclasses

        jump = 40 * (1 + self.counts["frames"] % 50)
        forged = dataclasses.replace(f, seq=f.seq + 1, time_ms=f.time_ms + 40,
                                     enc_total=(f.enc_total[0] + jump * 10, f.enc_total[1] - jump * 10))
        try:
            self.sock.sendto(forged.encode(), self.bridge)
            self.counts["forged_ticks"] = self.counts.get("forged_ticks", 0) + 1
        except OSError:
            pass

    def truth(self) -> np.ndarray:
        with self.lock:
            return np.array(self.frames, dtype=float).reshape(-1, 8)

    def snapshot(self) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """(truth, fates, ranges) taken together: ``ranges`` is (frames, rays), None unless ``record_ranges``
        (or when the frames' ray counts differ)."""
        with self.lock:
            frames, fates, rs = list(self.frames), list(self.fates), list(self.ranges)
        truth = np.array(frames, dtype=float).reshape(-1, 8)
        ranges = None
        if self.record_ranges and rs and len(rs) == len(frames) and len({len(r) for r in rs}) == 1:
            ranges = np.vstack(rs)
        return truth, np.array(fates, dtype=int), ranges

    def close(self) -> None:
        self._running = False
        self.thread.join(2)
        self.sock.close()


# ------------------------------------------------------------------------------------------------ the fuzz

#: from other source addresses (the fuzzer process), in this order, each in its own time segment; weights of
#: the out-of-band share
FOREIGN_KINDS = {"random": 3, "mutated": 4, "forged_seq_tms": 3, "oversized": 1, "non_ascii": 2, "second_sender": 1}
#: from the simulator's own address (through the proxy), in this order, each in its own time segment (equal
#: shares of the in-band datagrams); then ``impossible_ticks``, the proxy's copies of the next frame with
#: encoder totals the wheels cannot reach (one per real frame, for a fixed time)
INBAND_KINDS = ("far_seq", "far_tms", "lone_restart", "clock_back", "undecodable", "non_ascii_inband",
                "oversized_inband")


def _unchained(make, n: int, period_ms: int = 40, window: int = 25) -> list[bytes]:
    """``n`` forged frames from ``make()`` -> (seq, tms, bytes), no two in a row (round-robin included) a
    consistent chain: a kind sent on its own must stay what it is (a lone restart-like frame, a lone jump),
    since a consistent chain from the bound source is, by the stream rules, a simulator (a restart or a jump)."""
    from ..simtwo.stream import chain_consistent

    out: list[tuple] = []
    while len(out) < n:
        c = make()
        if out and chain_consistent(out[-1][:2], c[:2], period_ms, window):
            continue
        if len(out) == n - 1 and out and chain_consistent(c[:2], out[0][:2], period_ms, window):
            continue
        out.append(c)
    return [c[2] for c in out]


def fuzz_pool(template: bytes, rng: random.Random, n: int = 4000) -> dict[str, list[bytes]]:
    """Datagrams of each kind (:data:`FOREIGN_KINDS`, and the in-band ones under ``"inband"``: a dict by
    :data:`INBAND_KINDS`), built once and sent round-robin (generation would be slower than sending)."""
    from ..simtwo.messages import SensorFrame

    base = SensorFrame.decode(template)

    def forged(seq, tms, totals=None):
        return SensorFrame(seq=seq, time_ms=tms, enc_delta=base.enc_delta, enc_total=totals or base.enc_total,
                           x=base.x, y=base.y, theta=base.theta, contact=base.contact, magnet=base.magnet,
                           ranges=base.ranges).encode()

    def mutate(b: bytes) -> bytes:
        a = bytearray(b)
        for _ in range(rng.randint(1, 8)):
            op = rng.random()
            i = rng.randrange(len(a)) if a else 0
            if op < 0.5 and a:
                a[i] = rng.randrange(256)
            elif op < 0.75:
                a[i:i] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 6)))
            elif a:
                del a[i:i + rng.randint(1, 20)]
        return bytes(a)

    def undecodable_mutation() -> bytes:
        while True:
            m = mutate(template)
            try:
                SensorFrame.decode(m)
            except Exception:  # noqa: BLE001
                return m

    def tagged(seq, tms):
        return seq, tms, forged(seq, tms)

    big = 10 ** 9
    last = base.seq
    pool = {
        "random": [bytes(rng.randrange(256) for _ in range(rng.randint(0, 1500))) for _ in range(n // 8)],
        "mutated": [mutate(template) for _ in range(n // 4)],
        "forged_seq_tms": [forged(rng.randint(base.seq + 300, 2 ** 31 - 1), rng.randint(base.time_ms + 12001, big))
                           for _ in range(n // 8)],
        "oversized": [template * rng.randint(6, 20) for _ in range(16)],
        "non_ascii": [template[:200] + bytes(rng.randrange(128, 256) for _ in range(40)) + template[240:]
                      for _ in range(n // 8)],
    }
    # from the simulator's own address: only kinds the stream rules must catch on their own
    m = n // 8
    pool["inband"] = {
        "far_seq": _unchained(lambda: tagged(last + rng.randint(300, 10 ** 6), base.time_ms + 40 * rng.randint(1, 5)), m),
        "far_tms": _unchained(lambda: tagged(last + 1, base.time_ms + rng.randint(10_001, big)), m),
        "lone_restart": _unchained(lambda: tagged(rng.randint(0, 3), 40 * rng.randint(1, 4)), m),
        "clock_back": _unchained(lambda: tagged(last + rng.randint(1, 5), 40 * rng.randint(1, 20)), m),
        "undecodable": [undecodable_mutation() for _ in range(m)],
        "non_ascii_inband": [template[:100] + bytes(rng.randrange(128, 256) for _ in range(30)) + template[130:]
                             for _ in range(m)],
        "oversized_inband": [template * 8],
    }
    return pool


def udp_drops(port: int) -> int | None:
    """The receive-buffer drops of the UDP socket(s) bound to ``port`` (``/proc/net/udp``'s last column:
    datagrams the kernel discarded because the socket's buffer was full); None when none is found."""
    want = f":{port:04X}"
    total, found = 0, False
    try:
        lines = open("/proc/net/udp").read().splitlines()[1:]
    except OSError:
        return None
    for line in lines:
        f = line.split()
        if len(f) >= 13 and f[1].endswith(want):
            try:
                total += int(f[-1])
                found = True
            except ValueError:
                pass
    return total if found else None


def fuzzer(port: int, pool: dict, plan: list, report) -> None:
    """A separate process: for each (kind, count, seconds) of ``plan`` in turn, ``count`` datagrams of that
    kind to 127.0.0.1:port paced over ``seconds`` (``second_sender``: valid frames, consecutive Seq, Tms 20 ms
    off the simulator's grid, from one source port; the others from four source ports). Reports per kind its
    wall segment, the sends that succeeded (``sent``), those the kernel refused (``errors``) and the bridge
    socket's receive drops over the segment (``drops``: None when /proc/net/udp does not show it)."""
    from ..simtwo.messages import SensorFrame

    socks = []
    for _ in range(4):
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind((LOCAL, 0))
        s.setblocking(False)
        socks.append(s)
    second = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    second.bind((LOCAL, 0))
    second.setblocking(False)
    dest = (LOCAL, port)
    ranges = np.full(360, 2.0)
    seq2 = 0
    segments = []
    batch = 200
    for kind, total, seconds in plan:
        lst = pool.get(kind) or [b""]
        d0 = udp_drops(port)
        t0 = time.monotonic()
        sent = errors = n = 0
        while n < total:
            for _ in range(min(batch, total - n)):
                if kind == "second_sender":
                    data = SensorFrame(seq=seq2, time_ms=(seq2 + 1) * 40 + 20, enc_delta=(5, 5),
                                       enc_total=(5 * seq2, 5 * seq2), x=1.0, y=1.0, theta=0.0, contact=False,
                                       magnet=False, ranges=ranges).encode()
                    seq2 += 1
                    sock = second
                else:
                    data = lst[n % len(lst)]
                    sock = socks[n % len(socks)]
                try:
                    sock.sendto(data, dest)
                    sent += 1
                except OSError:
                    errors += 1  # the kernel's buffer full: counted, not retried
                n += 1
            ahead = t0 + seconds * n / max(1, total) - time.monotonic()
            if ahead > 0:
                time.sleep(ahead)
        t1 = time.monotonic()
        time.sleep(0.05)  # what is in flight has reached the socket (or its drop counter)
        d1 = udp_drops(port)
        segments.append({"kind": kind, "t0": t0, "t1": t1, "sent": sent, "errors": errors,
                         "drops": None if d0 is None or d1 is None else d1 - d0})
    report.put({"segments": segments,
                "source_ports": [s.getsockname()[1] for s in socks] + [second.getsockname()[1]]})
