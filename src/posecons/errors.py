"""One exception type for bad user input, so the CLI can print it without a traceback."""


class PoseconsError(Exception):
    """A problem with the user's input (file, config, data); the message names what and where."""
