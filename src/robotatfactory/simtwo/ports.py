"""SimTwo's default addresses and ports (see docs/protocol.md), and binding a UDP port with a clear error."""
from __future__ import annotations

import socket

from ..errors import ConfigError

SIMTWO_UDP_PORT = 9808  # SimTwo (or raf sim) listens for Command datagrams
BRIDGE_UDP_PORT = 9810  # scripts send SensorFrame datagrams here (the bridge binds it)
CAMERA_ZMQ_PORT = 9899  # ZMQ PUB of raw camera frames
CAMERA_JPEG_UDP_PORT = 9898  # SimTwo's alternative JPEG-over-UDP camera mode (not used)
SERVER_UDP_PORT = 44832  # the competition's factory-state server
LOCALHOST = "127.0.0.1"


def bind_udp(sock: socket.socket, host: str, port: int, what: str, hint: str) -> socket.socket:
    """Bind ``sock`` to ``(host, port)``; on failure close it and raise a ConfigError that says what the port
    was for (``what``) and what to do (``hint``)."""
    try:
        sock.bind((host, port))
    except OSError as e:
        sock.close()
        raise ConfigError(f"{what} cannot bind udp {host}:{port}: {e.strerror or e} ({hint})") from None
    return sock
