"""One exception tree for reckon. Messages name the value, the limit and where."""


class ReckonError(Exception):
    """Base of every error reckon raises on purpose; the CLI prints it without a traceback."""


class ConfigError(ReckonError):
    """A configuration file or option is wrong (unknown key, bad value, missing field)."""


class InputError(ReckonError):
    """An input file (CSV, MCAP, folder) cannot be used as given."""
