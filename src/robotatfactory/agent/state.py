"""The factory as the server spells it: four zones of four slots, each a part type or empty.

``FactoryState`` is what the agent knows from IWP/OWP/MAP/MBP/CTL; the task logic plans on it and
compares it with what it expected. Slot numbers are the server's: warehouses 1-4 by increasing x;
machines 1 2 / 3 4 (1 and 3 inputs, 2 and 4 outputs; docs/competition.md).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Optional, Tuple

from ..competition.parts import PartType, letters_of
from ..competition.server import ZONE_OF

Letters = Tuple[Optional[PartType], Optional[PartType], Optional[PartType], Optional[PartType]]
ZONE_REQUESTS = {zone: req for req, zone in ZONE_OF.items()}  # the server's requests, by zone
ZONES = tuple(ZONE_REQUESTS)


@dataclass(frozen=True, order=True)
class SlotRef:
    """A slot by zone and server number (1-4)."""

    zone: str
    number: int

    def __str__(self) -> str:
        return f"{self.zone} {self.number}"


@dataclass(frozen=True)
class FactoryState:
    """Each zone's slots, slot 1 first (None: empty); ``time_left`` in seconds (CTL) or None if unknown."""

    incoming: Letters
    outgoing: Letters
    machine_A: Letters
    machine_B: Letters
    time_left: float | None = None

    @classmethod
    def from_letters(cls, incoming: str, outgoing: str = "XXXX", machine_A: str = "XXXX",
                     machine_B: str = "XXXX", time_left: float | None = None) -> FactoryState:
        """From server spellings, e.g. ``FactoryState.from_letters("RGBX")``."""
        def parse(s: str) -> Letters:
            if len(s) != 4:
                raise ValueError(f"expected four letters, got {s!r}")
            return tuple(None if c == "X" else PartType(c) for c in s)  # type: ignore[return-value]
        return cls(parse(incoming), parse(outgoing), parse(machine_A), parse(machine_B), time_left)

    def zone(self, zone: str) -> Letters:
        if zone not in ZONE_REQUESTS:
            raise KeyError(f"unknown zone {zone!r}")
        return getattr(self, zone)

    def at(self, ref: SlotRef) -> PartType | None:
        """The part in a slot (None: empty)."""
        return self.zone(ref.zone)[ref.number - 1]

    def with_slot(self, ref: SlotRef, part: PartType | None) -> FactoryState:
        """A copy with one slot changed."""
        z = list(self.zone(ref.zone))
        z[ref.number - 1] = part
        return replace(self, **{ref.zone: tuple(z)})

    def letters(self, zone: str) -> str:
        return letters_of(self.zone(zone))

    def same_slots(self, other: FactoryState) -> bool:
        """True when every slot agrees (time_left ignored)."""
        return all(self.zone(z) == other.zone(z) for z in ZONES)

    def __str__(self) -> str:
        t = "" if self.time_left is None else f" T{self.time_left:03.0f}"
        return " ".join(f"{ZONE_REQUESTS[z]}={self.letters(z)}" for z in ZONES) + t
