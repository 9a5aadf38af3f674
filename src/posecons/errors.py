"""The exceptions the CLI prints as one line without a traceback: bad user input (exit 2), an
interrupt (128 + the signal) and a collapsed run (1)."""


class PoseconsError(Exception):
    """A problem with the user's input (file, config, data); the message names what and where."""


class Interrupted(PoseconsError):
    """SIGINT or SIGTERM stopped a command; it exits with 128 + the signal number, as shells report it."""

    def __init__(self, message: str, signum: int):
        super().__init__(message)
        self.exit_code = 128 + signum


class Collapsed(PoseconsError):
    """A run whose depth collapsed in training (:mod:`posecons.training.collapse`): no bad input, but a
    result not to be used; it exits with 1."""

    exit_code = 1
