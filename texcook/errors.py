"""Error types. Every failure a user can cause is a TexcookError with a one-line
message that names the file (when there is one) and the problem."""


class TexcookError(Exception):
    """Base class: the CLI prints str(err) on one line and exits with `exit_code`."""

    exit_code = 1

    def __init__(self, message, path=None):
        self.path = None if path is None else str(path)
        super().__init__(f"{self.path}: {message}" if self.path else message)


class InputError(TexcookError):
    """A source image or texture file that cannot be read or used."""


class ContainerError(InputError):
    """A KTX2 or DDS file that is corrupt, truncated or not of that kind."""


class OutputError(TexcookError):
    """An output that cannot be written."""


class UsageError(TexcookError):
    """Options that do not fit together or a value out of range."""

    exit_code = 2
