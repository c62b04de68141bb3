"""The error for a bad setting or an unknown name, at the bottom of the package: every layer may raise it
(``raf`` prints it, and the other errors users cause, without a traceback: ``cli.user_errors``)."""


class ConfigError(ValueError):
    """A setting or parameter has a bad value; the message names the setting and what is allowed."""
