"""SimTwo's default addresses and ports (see docs/protocol.md)."""

SIMTWO_UDP_PORT = 9808  # SimTwo (or raf sim) listens for Command datagrams
BRIDGE_UDP_PORT = 9810  # scripts send SensorFrame datagrams here (the bridge binds it)
CAMERA_ZMQ_PORT = 9899  # ZMQ PUB of raw camera frames
CAMERA_JPEG_UDP_PORT = 9898  # SimTwo's alternative JPEG-over-UDP camera mode (not used)
SERVER_UDP_PORT = 44832  # the competition's factory-state server
LOCALHOST = "127.0.0.1"
