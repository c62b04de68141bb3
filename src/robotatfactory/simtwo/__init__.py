"""SimTwo's wire formats: the labelled-string UDP codec, the RobotAtFactory datagrams and camera frames.

Plain Python, no ROS. Every decoder raises :class:`ProtocolError` on malformed input.
"""
from .camera import FRAME_BYTES, HEIGHT, WIDTH, decode_frame, encode_frame
from .errors import ProtocolError
from .labels import MAX_DATAGRAM, LabelledValues, decode_labels, encode_labels, format_int, format_real, split_lines
from .messages import NO_RETURN, PROTOCOL_VERSION, Command, SensorFrame
from .ports import (BRIDGE_UDP_PORT, CAMERA_ZMQ_PORT, LOCALHOST, SERVER_UDP_PORT, SIMTWO_UDP_PORT)

__all__ = ["FRAME_BYTES", "HEIGHT", "WIDTH", "decode_frame", "encode_frame", "ProtocolError", "MAX_DATAGRAM",
           "LabelledValues", "decode_labels", "encode_labels", "format_int", "format_real", "split_lines",
           "NO_RETURN", "PROTOCOL_VERSION", "Command", "SensorFrame", "BRIDGE_UDP_PORT", "CAMERA_ZMQ_PORT",
           "LOCALHOST", "SERVER_UDP_PORT", "SIMTWO_UDP_PORT"]
