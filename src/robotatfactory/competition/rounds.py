"""A round's setup: which parts start in the incoming warehouse, the machines' delay, the round's length.

The rules fix what each round asks for but not the colours; :meth:`RoundSetup.make` draws them like an
organiser would (seeded, so the same seed gives the same layout on every machine), or takes them given as
four letters. See docs/competition.md for the decisions.
"""
from __future__ import annotations

import math
import random
from dataclasses import dataclass

from ..errors import ConfigError
from .parts import EMPTY, PartType, letters_of

ROUNDS = (1, 2, 3)
SLOTS = 4  # slots per warehouse
DEFAULT_PROCESSING_DELAY = 10.0  # s, the machines' processing time (announced before a competition)
DEFAULT_DURATION = 600.0  # s, a team's slot per round in the rules

_DRAW = {
    # round: (types a slot may hold, a type at least one slot must hold)
    1: ((PartType.BLUE,), PartType.BLUE),
    2: ((PartType.BLUE, PartType.GREEN), PartType.GREEN),
    3: ((PartType.RED, PartType.GREEN, PartType.BLUE), PartType.RED),
}

ROUND_RULES = {
    1: "move the four parts from the incoming to the outgoing warehouse",
    2: "some parts go through one machine (B) before the outgoing warehouse",
    3: "Red -> machine A, Green -> machine B, Blue -> outgoing warehouse",
}


@dataclass(frozen=True)
class RoundSetup:
    """One round: ``incoming[i]`` is the part in incoming slot i+1 (x increasing), None for an empty slot.

    ``processing_delay`` and ``duration`` are seconds of simulation time; ``seed`` is None when the parts
    were given explicitly (``custom`` is then True).
    """

    round_no: int
    incoming: tuple[PartType | None, PartType | None, PartType | None, PartType | None]
    seed: int | None = 0
    processing_delay: float = DEFAULT_PROCESSING_DELAY
    duration: float = DEFAULT_DURATION
    custom: bool = False

    @classmethod
    def make(cls, round_no: int, seed: int = 0, parts: str | None = None,
             processing_delay: float = DEFAULT_PROCESSING_DELAY, duration: float = DEFAULT_DURATION) -> RoundSetup:
        """A validated setup. ``parts`` (e.g. ``"RGBX"``) overrides the seeded draw; raises ConfigError."""
        round_no = _check_round(round_no)
        processing_delay = _check_seconds("processing delay", processing_delay, allow_zero=True)
        duration = _check_seconds("round duration", duration, allow_zero=False)
        if parts is not None:
            incoming = parse_parts(parts)
            return cls(round_no, incoming, None, processing_delay, duration, custom=True)
        seed = _check_seed(seed)
        return cls(round_no, draw_parts(round_no, seed), seed, processing_delay, duration, custom=False)

    @property
    def letters(self) -> str:
        """The incoming warehouse as the server spells it, e.g. ``"BGGR"``."""
        return letters_of(self.incoming)

    @property
    def rule(self) -> str:
        return ROUND_RULES[self.round_no]

    @property
    def max_points(self) -> int:
        """The best score this layout allows (red 3, green 2, blue 1 per part)."""
        return sum(p.max_points for p in self.incoming if p is not None)

    def describe(self) -> str:
        origin = "given" if self.custom else f"seed {self.seed}"
        return (f"round {self.round_no} ({self.rule}): incoming {self.letters} ({origin}), "
                f"processing delay {self.processing_delay:g} s, duration {self.duration:g} s, "
                f"at most {self.max_points} points")


def draw_parts(round_no: int, seed: int) -> tuple:
    """The organiser's draw for a round: four parts, each type uniform among the round's types, redrawn
    until the round's required type is present (round 1: all blue; round 2: blue/green, at least one green;
    round 3: red/green/blue, at least one red). Deterministic in (round_no, seed) across platforms."""
    round_no = _check_round(round_no)
    seed = _check_seed(seed)
    choices, required = _DRAW[round_no]
    # a string seed goes through SHA-512 in random.Random: stable across Python versions and platforms,
    # and different rounds with the same seed get independent draws
    rng = random.Random(f"robotatfactory/round{round_no}/seed{seed}")
    while True:
        parts = tuple(choices[rng.randrange(len(choices))] for _ in range(SLOTS))
        if required in parts:
            return parts


def parse_parts(text) -> tuple:
    """Four letters from R, G, B, X (case and surrounding blanks ignored) -> a tuple of PartType/None."""
    if not isinstance(text, str):
        raise ConfigError(f"parts must be a string of {SLOTS} letters from R, G, B, X, got {text!r}")
    s = text.strip().upper()
    if len(s) != SLOTS:
        raise ConfigError(f"parts {text!r}: expected exactly {SLOTS} letters (incoming slots 1-4, x increasing) "
                          f"from R (red), G (green), B (blue), X (empty), got {len(s)}")
    bad = sorted({c for c in s if c not in "RGB" + EMPTY})
    if bad:
        raise ConfigError(f"parts {text!r}: unknown letter(s) {', '.join(repr(c) for c in bad)}; "
                          "use R (red), G (green), B (blue) or X (empty slot)")
    if set(s) == {EMPTY}:
        raise ConfigError(f"parts {text!r}: at least one slot must hold a part")
    return tuple(None if c == EMPTY else PartType(c) for c in s)


def _check_round(round_no) -> int:
    if isinstance(round_no, bool) or not isinstance(round_no, int) or round_no not in ROUNDS:
        raise ConfigError(f"round must be 1, 2 or 3, got {round_no!r}")
    return round_no


def _check_seed(seed) -> int:
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError(f"seed must be a non-negative integer, got {seed!r}")
    return seed


def _check_seconds(what: str, value, *, allow_zero: bool) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{what} must be a number of seconds, got {value!r}") from None
    if isinstance(value, bool) or not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        limit = ">= 0" if allow_zero else "> 0"
        raise ConfigError(f"{what} must be a finite number of seconds {limit}, got {value!r}")
    return v
