"""SimTwo's labelled-string codec, exactly as SimTwo scripts build and read it.

A datagram is a Windows ``TStringList.Text``: for every value three lines, the label, the value and
an empty line, each ended by CR LF. Integers are written ``%d``, reals ``%.6g`` with a '.' decimal
point. A reader splits on CR, LF or CR LF and takes the FIRST line equal to a label, the value being
the next line. ``ReadUDPData`` concatenates every datagram received since the previous call, so
decoding copes with several datagrams glued together (the first one wins).
"""
from __future__ import annotations

import math
import re
from typing import Iterable, Mapping

from .errors import ProtocolError

#: The largest UDP payload over IPv4; anything larger cannot be one datagram.
MAX_DATAGRAM = 65507
EOL = "\r\n"

_LINE_SPLIT = re.compile(r"\r\n|\r|\n")
# characters str.splitlines() would also break on, but SimTwo's TStringList does not
_OTHER_BREAKS = ("\x0b", "\x0c", "\x1c", "\x1d", "\x1e", "\x85", "\u2028", "\u2029")


def format_int(v: int) -> str:
    return "%d" % v


def format_real(v: float) -> str:
    """``%.6g`` as SimTwo's ``Format`` writes it (Python and C agree on this)."""
    if not math.isfinite(v):
        raise ProtocolError(f"cannot encode non-finite real {v!r}")
    s = "%.6g" % v
    return "0" if s == "-0" else s


def encode_labels(items: Iterable[tuple[str, str]] | Mapping[str, str]) -> bytes:
    """Label/value pairs (already formatted) to one datagram: label, value, empty line, CR LF."""
    if isinstance(items, Mapping):
        items = items.items()
    parts = []
    for label, value in items:
        if not label or any(c in label for c in "\r\n") or any(c in value for c in "\r\n"):
            raise ProtocolError(f"label {label!r} or its value contains a line break or is empty")
        parts.append(f"{label}{EOL}{value}{EOL}{EOL}")
    return "".join(parts).encode("ascii")


def split_lines(data: bytes | str) -> list[str]:
    """Bytes (or text) to lines the way SimTwo's ``TStringList.Text := s`` splits them."""
    if isinstance(data, (bytes, bytearray, memoryview)):
        if len(data) > MAX_DATAGRAM:
            raise ProtocolError(f"datagram of {len(data)} bytes exceeds the {MAX_DATAGRAM}-byte UDP limit")
        try:
            text = bytes(data).decode("ascii")
        except UnicodeDecodeError as e:
            raise ProtocolError(f"byte 0x{data[e.start]:02x} at offset {e.start} is not ASCII text") from None
    else:
        text = data
    if not any(c in text for c in _OTHER_BREAKS):
        return text.splitlines()  # fast path: for ASCII without these, exactly CR, LF, CR LF
    lines = _LINE_SPLIT.split(text)
    if lines and lines[-1] == "":
        lines.pop()  # the final line end does not start a new line
    return lines


class LabelledValues:
    """The decoded view of one (or several concatenated) labelled-string datagrams.

    ``values[label]`` is the value line after the FIRST line equal to ``label``, as SimTwo's
    ``IndexOf`` lookup finds it. Typed getters raise :class:`ProtocolError` naming the label and line.
    """

    __slots__ = ("lines", "_index")

    def __init__(self, data: bytes | str):
        self.lines = split_lines(data)
        index: dict[str, int] = {}
        for i, line in enumerate(self.lines):
            if line not in index:
                index[line] = i
        self._index = index

    def __contains__(self, label: str) -> bool:
        i = self._index.get(label)
        return i is not None and i + 1 < len(self.lines)

    def line_of(self, label: str) -> int:
        """1-based line number of the value of ``label``."""
        return self._index[label] + 2

    def raw(self, label: str) -> str:
        i = self._index.get(label)
        if i is None:
            raise ProtocolError(f"label {label!r} is missing")
        if i + 1 >= len(self.lines):
            raise ProtocolError(f"label {label!r} on line {i + 1} has no value line after it")
        return self.lines[i + 1]

    def get_int(self, label: str) -> int:
        s = self.raw(label)
        try:
            return int(s.strip())
        except ValueError:
            raise ProtocolError(f"label {label!r} (line {self.line_of(label)}): expected an integer, "
                                f"got {s[:40]!r}") from None

    def get_real(self, label: str) -> float:
        s = self.raw(label)
        try:
            v = float(s.strip())
        except ValueError:
            raise ProtocolError(f"label {label!r} (line {self.line_of(label)}): expected a real number, "
                                f"got {s[:40]!r}") from None
        if not math.isfinite(v):
            raise ProtocolError(f"label {label!r} (line {self.line_of(label)}): {s.strip()!r} is not a finite number")
        return v

    def get_bool(self, label: str) -> bool:
        v = self.get_int(label)
        if v not in (0, 1):
            raise ProtocolError(f"label {label!r} (line {self.line_of(label)}): expected 0 or 1, got {v}")
        return bool(v)

    def as_dict(self) -> dict[str, str]:
        """Every label with its value, first occurrence winning (labels on lines 1, 4, 7, ...)."""
        out: dict[str, str] = {}
        for i in range(0, len(self.lines) - 1, 3):
            out.setdefault(self.lines[i], self.lines[i + 1])
        return out


def decode_labels(data: bytes | str) -> dict[str, str]:
    """Datagram(s) to ``{label: value}``, the first occurrence of a label winning."""
    return LabelledValues(data).as_dict()
