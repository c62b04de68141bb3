"""Part types of RobotAtFactory 4.0 and their one-letter codes (the factory-state server's alphabet).

Raw = Red goes to machine A, Intermediate = Green goes to machine B, Final = Blue goes to the outgoing
warehouse. A machine turns a part into the next type: RED -> GREEN -> BLUE. ``X`` marks an empty slot.
"""
from __future__ import annotations

from enum import Enum

EMPTY = "X"
"""The letter of an empty slot in every server reply (IWP, OWP, MAP, MBP)."""


class PartType(Enum):
    """A part's type. The value is the server letter (``PartType("R") is PartType.RED``)."""

    RED = "R"
    GREEN = "G"
    BLUE = "B"

    @property
    def letter(self) -> str:
        """``R``, ``G`` or ``B``."""
        return self.value

    @property
    def label(self) -> str:
        """Lower-case colour name for messages: ``red``, ``green``, ``blue``."""
        return self.name.lower()

    @property
    def is_final(self) -> bool:
        """True for BLUE: no machine processes it; it belongs in the outgoing warehouse."""
        return self is PartType.BLUE

    def next(self) -> PartType:
        """The type a machine turns this part into: RED -> GREEN -> BLUE.

        Raises ValueError for BLUE (a final part is never processed).
        """
        if self is PartType.RED:
            return PartType.GREEN
        if self is PartType.GREEN:
            return PartType.BLUE
        raise ValueError("a blue (final) part has no next type: no machine processes it")

    @property
    def target_zone(self) -> str:
        """Where the rules send this type: ``machine_A`` (red), ``machine_B`` (green), ``outgoing`` (blue)."""
        return _TARGET[self]

    @property
    def max_points(self) -> int:
        """Most points one part of this type can earn: red 3 (A, B, outgoing), green 2, blue 1."""
        return _MAX_POINTS[self]

    @property
    def rgba(self) -> tuple[float, float, float, float]:
        """A display colour (linear 0..1 RGBA) for renderers and plots."""
        return _RGBA[self]

    @classmethod
    def from_letter(cls, letter: str) -> PartType:
        """``"R"`` -> RED, ... Raises ValueError on anything else (``X`` included: it is no part)."""
        try:
            return cls(letter)
        except ValueError:
            raise ValueError(f"not a part letter: {letter!r} (expected R, G or B)") from None


_TARGET = {PartType.RED: "machine_A", PartType.GREEN: "machine_B", PartType.BLUE: "outgoing"}
_MAX_POINTS = {PartType.RED: 3, PartType.GREEN: 2, PartType.BLUE: 1}
_RGBA = {PartType.RED: (0.85, 0.1, 0.1, 1.0), PartType.GREEN: (0.1, 0.7, 0.15, 1.0),
         PartType.BLUE: (0.1, 0.25, 0.85, 1.0)}


def letter_of(part: PartType | None) -> str:
    """The server letter of a slot's content: R, G, B, or X when it is empty (None)."""
    return EMPTY if part is None else part.letter


def letters_of(parts) -> str:
    """``letters_of([RED, None, BLUE, BLUE]) == "RXBB"``."""
    return "".join(letter_of(p) for p in parts)
