"""Error types of the core. Each also inherits the matching built-in, as python-can does."""


class TransparencyError(Exception):
    """Base class of every error raised on purpose by transparency_ros."""


class ConfigError(TransparencyError, ValueError):
    """A configuration file or value is missing, malformed or out of range.

    The message names the file and the key path (``actuators.EC60.mass_kg``) that is wrong.
    """


class UnknownActuatorError(ConfigError, LookupError):
    """An actuator name that the configuration does not define."""


class ModelError(TransparencyError, ValueError):
    """Inputs to a physics model are outside its domain (negative energy, NaN, ...)."""


def shown(value: object) -> str:
    """A value in an error message as the user typed it: a numpy scalar as its number (``-1.0``,
    not ``np.float64(-1.0)``), anything else as its repr."""
    try:
        return repr(float(value))  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return repr(value)
