"""Errors a user can cause (bad settings, unknown names); ``raf`` prints them without a traceback."""
from .field.loader import FieldError
from .simtwo.errors import ProtocolError
from .simtwo_linux.build import BuildError
from .simtwo_linux.run import SimTwoError
from .simtwo_linux.scene import SceneError


class ConfigError(ValueError):
    """A setting or parameter has a bad value; the message names the setting and what is allowed."""


UserError = (FieldError, ProtocolError, ConfigError, FileNotFoundError, BuildError, SceneError, SimTwoError)
