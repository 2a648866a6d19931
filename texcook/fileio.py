"""Atomic output: write to a temporary name beside the target, then rename, so a
failure never leaves a partial file where the output should be."""

import os
import tempfile

from .errors import OutputError


def atomic_write(path, data: bytes) -> None:
    atomic_write_all([(path, data)])


def atomic_write_all(outputs) -> None:
    """Write several (path, bytes) outputs all-or-nothing: every one goes to a
    temporary file first, and only when all are written are they renamed into
    place. A failure before the renames leaves no output and no temporary."""
    temps = []
    try:
        for path, data in outputs:
            path = os.fspath(path)
            directory = os.path.dirname(os.path.abspath(path))
            if not os.path.isdir(directory):
                raise OutputError("output directory does not exist", path)
            try:
                fd, tmp = tempfile.mkstemp(prefix=".texcook-", suffix=".tmp", dir=directory)
            except OSError as exc:
                raise OutputError(f"cannot write here ({exc.strerror})", path) from None
            temps.append((tmp, path))
            try:
                with os.fdopen(fd, "wb") as fh:
                    fh.write(data)
            except OSError as exc:
                raise OutputError(f"cannot write ({exc.strerror})", path) from None
        for tmp, path in temps:
            try:
                os.replace(tmp, path)
            except OSError as exc:
                raise OutputError(f"cannot write ({exc.strerror})", path) from None
    finally:
        for tmp, _ in temps:
            _unlink_quietly(tmp)


def atomic_output_path(path):
    """A temporary path beside `path` for writers (like OpenImageIO) that need a
    file name; the caller renames it with `commit_output` or removes it."""
    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise OutputError("output directory does not exist", path)
    if not os.access(directory, os.W_OK):
        raise OutputError("output directory is not writable", path)
    base = os.path.basename(path)
    # keep the extension: OpenImageIO picks the format from it
    return os.path.join(directory, f".texcook-{os.getpid()}-{base}")


def commit_output(tmp, path):
    try:
        os.replace(tmp, path)
    except OSError as exc:
        _unlink_quietly(tmp)
        raise OutputError(f"cannot write ({exc.strerror})", path) from None


def _unlink_quietly(p):
    try:
        os.unlink(p)
    except OSError:
        pass
