"""Error types. Every failure a user can cause is a TexcookError with a one-line
message that names the file (when there is one) and the problem.

File names and messages are made printable on one line: control characters
(a newline in a file name, an escape sequence) are shown as backslash escapes,
so a hostile name can neither split the error line nor drive the terminal."""

import unicodedata


def printable(text) -> str:
    """`text` on one line: control and format characters as backslash escapes."""
    text = str(text)
    if text.isprintable():
        return text
    out = []
    for ch in text:
        if ch.isprintable() or ch == " ":
            out.append(ch)
        elif ch in "\n\r\t":
            out.append({"\n": "\\n", "\r": "\\r", "\t": "\\t"}[ch])
        elif unicodedata.category(ch) == "Zs":  # odd spaces read as spaces
            out.append(" ")
        else:
            code = ord(ch)
            out.append(f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}" if code < 0x10000 else f"\\U{code:08x}")
    return "".join(out)


class TexcookError(Exception):
    """Base class: the CLI prints str(err) on one line and exits with `exit_code`."""

    exit_code = 1

    def __init__(self, message, path=None):
        self.path = None if path is None else str(path)
        self.message = str(message)
        text = printable(self.message)
        super().__init__(f"{printable(self.path)}: {text}" if self.path else text)

    def naming(self, path):
        """This error naming `path` when it names no file yet (the same error
        otherwise): for library checks that do not know the file they serve."""
        if self.path is not None or path is None:
            return self
        err = type(self)(self.message, path)
        err.__cause__ = self.__cause__
        return err


class InputError(TexcookError):
    """A source image or texture file that cannot be read or used."""


class ContainerError(InputError):
    """A KTX2 or DDS file that is corrupt, truncated or not of that kind."""


class OutputError(TexcookError):
    """An output that cannot be written."""


class UsageError(TexcookError):
    """Options that do not fit together or a value out of range."""

    exit_code = 2
