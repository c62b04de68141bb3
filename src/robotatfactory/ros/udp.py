"""A UDP socket that reports when the kernel received each datagram (Linux SO_TIMESTAMPNS).

The bridge compares the arrival of SensorFrames with the arrival of camera frames to stamp the camera
(see ``simtwo.timing``). Measuring a datagram's arrival only when a Python thread gets round to it would
add the thread's scheduling delay (GIL, a previous frame still being published); the kernel's receive
timestamp does not. Times are returned on ``time.monotonic()``'s clock. Where the option is missing the
socket falls back to the time ``recvmsg`` returned. A port that cannot be bound raises ConfigError.
"""
from __future__ import annotations

import socket
import struct
import time

from ..simtwo.ports import bind_udp

SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)  # Linux (asm-generic and x86)
SCM_TIMESTAMPNS = SO_TIMESTAMPNS
_TIMESPEC = struct.Struct("@qq")  # struct timespec on 64-bit Linux


class TimestampedUDP:
    def __init__(self, host: str, port: int, rcvbuf: int = 1 << 20, timeout: float = 0.2):
        self.sock = s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        try:
            s.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
            self.kernel_timestamps = True
        except OSError:
            self.kernel_timestamps = False
        bind_udp(s, host, port, "the bridge", "~udp/bind_host, ~udp/port")
        s.settimeout(timeout)
        self._anc = socket.CMSG_SPACE(_TIMESPEC.size)

    @property
    def port(self) -> int:
        return self.sock.getsockname()[1]

    def recv(self, bufsize: int = 65536) -> tuple[bytes, tuple, float]:
        """(data, source address, arrival on the monotonic clock); raises socket.timeout."""
        data, anc, _flags, addr = self.sock.recvmsg(bufsize, self._anc)
        now_mono, now_real = time.monotonic(), time.time()
        for level, kind, payload in anc:
            if level == socket.SOL_SOCKET and kind == SCM_TIMESTAMPNS and len(payload) >= _TIMESPEC.size:
                sec, nsec = _TIMESPEC.unpack_from(payload)
                arrival = now_mono - (now_real - (sec + nsec * 1e-9))
                return data, addr, min(arrival, now_mono)
        return data, addr, now_mono

    def sendto(self, data: bytes, addr) -> int:
        return self.sock.sendto(data, addr)

    def close(self) -> None:
        self.sock.close()
