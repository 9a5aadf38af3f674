"""One exception type for bad user input, so the CLI can print it without a traceback."""


class PoseconsError(Exception):
    """A problem with the user's input (file, config, data); the message names what and where."""


class Interrupted(PoseconsError):
    """SIGINT or SIGTERM stopped a command; it exits with 128 + the signal number, as shells report it."""

    def __init__(self, message: str, signum: int):
        super().__init__(message)
        self.exit_code = 128 + signum
