"""The one exception type every SimTwo wire-format decoder raises."""


class ProtocolError(ValueError):
    """Malformed, foreign or unsupported input on one of SimTwo's streams.

    The message names what was wrong: which label, which line, what was expected.
    """
