"""Every file texcook reads or writes goes through here.

Reading: only regular files are read (a FIFO, a device such as /dev/zero or a
directory is refused before anything blocks), and a file larger than the memory
budget is refused before it is read.

Writing: one output path for every command. The bytes go to a temporary file
created exclusively in the target folder (O_EXCL, never through a symlink), named
`.NAME.texcook-XXXXXXXX.tmp` so a stale one left by a killed process is
recognisably texcook's. The writer holds an exclusive lock on its temporary
until the rename; the kernel drops the lock when a process dies, even by
SIGKILL, so the next write of NAME removes the temporaries nobody holds. The
write is checked (every byte, then the size on disk),
fsynced, given its final mode (the umask's, or the mode of the file it replaces)
and renamed over the target. On any failure, KeyboardInterrupt included, the
temporary is removed and an existing target is left as it was.

Writers that need a file name of their own (OpenImageIO) get a path inside a
private folder (mkdtemp, mode 0700) in the target folder: no other user can
plant anything at that name, and the folder is removed whatever happens.

The memory budget: decoders check what a header declares (texels x channels x 4
bytes, the float32 working size) against `max_memory()` before reading pixels or
decompressing. The default is an eighth of the machine's physical memory (see
`default_max_memory`); the TEXCOOK_MAX_MEMORY environment variable or
`texcook --max-memory SIZE` sets it.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import re
import secrets
import stat

from .errors import InputError, OutputError, UsageError

TEMP_MARK = ".texcook-"  # in every temporary name: `.NAME.texcook-XXXXXXXX.tmp`
TEMP_SUFFIX = ".tmp"
_NAME_MAX = 255  # bytes in one path component on the file systems we meet

# ------------------------------------------------------------------ memory budget

_SIZE_UNITS = {"": 1, "b": 1, "k": 1 << 10, "m": 1 << 20, "g": 1 << 30, "t": 1 << 40}
_max_memory = None  # bytes; None: not set, use the default


def parse_size(text) -> int:
    """'512M', '2G', '1.5g', '100000' (bytes) -> bytes. Units are powers of 1024."""
    m = re.fullmatch(r"\s*([0-9]+(?:\.[0-9]*)?)\s*([kmgt]?)i?b?\s*", str(text), re.IGNORECASE)
    if not m:
        raise UsageError(f"memory size {text!r} is not a number with an optional K, M, G or T unit")
    value = int(float(m.group(1)) * _SIZE_UNITS[m.group(2).lower()])
    if value < 1:
        raise UsageError(f"memory size {text!r} must be at least one byte")
    return value


def format_size(n: int) -> str:
    for unit, scale in (("G", 1 << 30), ("M", 1 << 20), ("K", 1 << 10)):
        if n >= scale:
            return f"{n / scale:.1f}{unit}"
    return f"{n}B"


def physical_memory() -> int | None:
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


# The stages make working copies: measured peaks are about 7x the declared size
# for a bake (2048x2048 RGBA with mips), 4.5x for compare and 3x for decode. An
# eighth of the memory keeps a bake at the limit within the machine.
DEFAULT_FRACTION = 8


def default_max_memory() -> int:
    """TEXCOOK_MAX_MEMORY when set, else physical memory / DEFAULT_FRACTION
    (1 GiB where it cannot be found)."""
    env = os.environ.get("TEXCOOK_MAX_MEMORY")
    if env:
        return parse_size(env)
    phys = physical_memory()
    return phys // DEFAULT_FRACTION if phys else 1 << 30


def max_memory() -> int:
    return _max_memory if _max_memory is not None else default_max_memory()


def set_max_memory(nbytes) -> None:
    """Set the budget (bytes, or a size string like '2G'); None restores the default."""
    global _max_memory
    _max_memory = None if nbytes is None else (parse_size(nbytes) if isinstance(nbytes, str) else int(nbytes))


def check_memory(nbytes: int, what: str, path=None, error=InputError) -> None:
    """Refuse work that would need more than the budget, before allocating it."""
    limit = max_memory()
    if nbytes > limit:
        raise error(f"{what} needs {format_size(nbytes)}, more than the {format_size(limit)} memory budget "
                         "(raise it with --max-memory)", path)


def texel_bytes(width: int, height: int, channels: int = 4) -> int:
    """The budget's measure of an image: texels x channels x 4 bytes (float32)."""
    return int(width) * int(height) * int(channels) * 4


# ------------------------------------------------------------------ reading


def _kind(mode) -> str:
    if stat.S_ISDIR(mode):
        return "is a directory"
    if stat.S_ISFIFO(mode):
        return "is a pipe (FIFO), not a regular file"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "is a device, not a regular file"
    if stat.S_ISSOCK(mode):
        return "is a socket, not a regular file"
    return "is not a regular file"


def check_regular(path) -> os.stat_result:
    """stat `path` (following symlinks, without opening it, so a FIFO cannot
    block) and refuse anything but a regular file."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise InputError("no such file", path) from None
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror})", path) from None
    if not stat.S_ISREG(st.st_mode):
        raise InputError(_kind(st.st_mode), path)
    return st


def read_bytes(path, what="file") -> bytes:
    """The whole of a regular file, refused when larger than the memory budget.
    O_NONBLOCK makes opening a FIFO return at once; fstat then refuses it."""
    return read_prefix(path, None, what)[0]


def read_prefix(path, limit, what="file"):
    """(the first `limit` bytes of a regular file, or all of it for None, and
    the file's size), with the checks of `read_bytes`."""
    path = os.fspath(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise InputError("no such file", path) from None
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror})", path) from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise InputError(_kind(st.st_mode), path)
        want = st.st_size if limit is None else min(int(limit), st.st_size)
        part = "" if want == st.st_size else f"{want} bytes of "
        check_memory(want, f"reading {part}this {st.st_size}-byte {what}", path)
        buf = bytearray(want)
        view = memoryview(buf)
        got = 0
        while got < want:
            n = os.readv(fd, [view[got:]])
            if n == 0:  # shrank while we read it
                break
            got += n
        del view
        if got < want:
            del buf[got:]
        return bytes(buf), st.st_size
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror})", path) from None
    except MemoryError:
        raise InputError("out of memory reading the file", path) from None
    finally:
        os.close(fd)


# ------------------------------------------------------------------ locks


def lock(path, exclusive=True, wait=True, create=False):
    """An open descriptor of `path` (a folder, or a file made when `create`)
    holding a flock on it; closing it releases the lock. The kernel drops a
    flock when its holder dies, even by SIGKILL, so a lock never outlives a
    killed run. None when `wait` is False and another process holds it;
    OSError when it cannot be opened or locked."""
    flags = getattr(os, "O_CLOEXEC", 0)
    if create:  # a symlink or FIFO planted at the lock's name is never followed or waited on
        flags |= os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | os.O_NONBLOCK
    else:
        flags |= os.O_RDONLY
    fd = os.open(path, flags, 0o666)
    try:
        fcntl.flock(fd, (fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH) | (0 if wait else fcntl.LOCK_NB))
    except BlockingIOError:
        os.close(fd)
        return None
    except BaseException:
        os.close(fd)
        raise
    return fd


# ------------------------------------------------------------------ writing


def current_umask() -> int:
    """The process umask, read without changing it where the system allows."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def final_mode(path) -> int:
    """The mode an output gets: that of the regular file it replaces, otherwise
    0666 less the umask (what `open(path, "w")` would give)."""
    try:
        st = os.lstat(path)
        if stat.S_ISREG(st.st_mode):
            return stat.S_IMODE(st.st_mode)
    except OSError:
        pass
    return 0o666 & ~current_umask()


def _target_dir(path) -> str:
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise OutputError("output directory does not exist", path)
    if os.path.isdir(path):
        raise OutputError("is a directory", path)
    return directory


def temp_name(path) -> str:
    """`.NAME.texcook-XXXXXXXX.tmp` in the target folder, NAME shortened to fit
    one path component."""
    base = os.path.basename(path)
    tail = f"{TEMP_MARK}{secrets.token_hex(4)}{TEMP_SUFFIX}"
    room = _NAME_MAX - len(tail.encode()) - 1
    raw = os.fsencode(base)[:room]
    return "." + os.fsdecode(raw) + tail


def is_temp_name(name) -> bool:
    """True for the names texcook gives its temporaries (stale ones included)."""
    name = os.path.basename(name)
    return name.startswith(".") and bool(re.search(r"\.texcook-[0-9a-z_]+(\.tmp)?$", name))


def _write_all(fd, data, path):
    view = memoryview(data).cast("B")
    done = 0
    while done < len(view):
        n = os.write(fd, view[done:done + (1 << 26)])
        if n <= 0:
            raise OSError(errno.EIO, "short write")
        done += n
    return done


def _fsync_dir(directory):
    try:
        fd = os.open(directory, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass  # some file systems refuse fsync on a directory; the rename stands
    finally:
        os.close(fd)


def _write_error(exc, path):
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        return OutputError("no space left on the device; the output was not written", path)
    return OutputError(f"cannot write ({exc.strerror or exc})", path)


class Staged:
    """A complete, fsynced temporary waiting to be renamed over its target.
    `commit()` renames it; `discard()` removes it (idempotent)."""

    def __init__(self, path, tmp, cleanup_dir=None, mode=None, lock_fd=None):
        self.path = os.fspath(path)
        self.tmp = tmp
        self.mode = mode  # final mode, for `seal`
        self._dir = cleanup_dir
        self._lock_fd = lock_fd  # held until the temporary is renamed or removed
        self.done = False

    def _unlock(self):
        if self._lock_fd is not None:
            with contextlib.suppress(OSError):
                os.close(self._lock_fd)
            self._lock_fd = None

    def commit(self):
        if self.done:
            return
        try:
            os.replace(self.tmp, self.path)
        except OSError as exc:
            self.discard()
            raise _write_error(exc, self.path) from None
        except BaseException:
            self.discard()
            raise
        self.done = True
        self._unlock()
        self._remove_dir()
        _fsync_dir(os.path.dirname(os.path.abspath(self.path)))

    def discard(self):
        if not self.done:
            _unlink_quietly(self.tmp)
        self.done = True
        self._unlock()
        self._remove_dir()

    def _remove_dir(self):
        if self._dir is not None:
            with contextlib.suppress(OSError):
                for name in os.listdir(self._dir):
                    _unlink_quietly(os.path.join(self._dir, name))
                os.rmdir(self._dir)
            self._dir = None


def stage_bytes(path, data) -> Staged:
    """Write `data` to an exclusive temporary beside `path` (see the module
    docstring); the caller commits or discards it."""
    path = os.fspath(path)
    directory = _target_dir(path)
    mode = final_mode(path)
    sweep_stale(path)
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    for _ in range(16):
        tmp = os.path.join(directory, temp_name(path))
        try:
            fd = os.open(tmp, flags, 0o600)
            fcntl.flock(fd, fcntl.LOCK_EX)  # ours alone: nobody else has opened it yet
            break
        except FileExistsError:
            continue
        except OSError as exc:
            raise OutputError(f"cannot write here ({exc.strerror})", path) from None
    else:
        raise OutputError("cannot create a temporary file beside the output", path)
    try:
        n = _write_all(fd, data, path)
        os.fsync(fd)
        if os.fstat(fd).st_size != n:
            raise OSError(errno.EIO, f"{os.fstat(fd).st_size} bytes on disk, {n} written")
        os.fchmod(fd, mode)
    except OSError as exc:
        _unlink_quietly(tmp)
        os.close(fd)
        raise _write_error(exc, path) from None
    except BaseException:
        _unlink_quietly(tmp)
        os.close(fd)
        raise
    return Staged(path, tmp, lock_fd=fd)


def sweep_stale(path) -> list:
    """Remove the temporaries of `path` (`.NAME.texcook-*.tmp` beside it) that
    no live writer holds: what a killed texcook left. Returns their names."""
    directory = os.path.dirname(os.path.abspath(path))
    prefix = "." + os.path.basename(path)
    removed = []
    try:
        names = os.listdir(directory)
    except OSError:
        return removed
    for name in names:
        if not (name.startswith(prefix + TEMP_MARK) and is_temp_name(name) and name.endswith(TEMP_SUFFIX)):
            continue
        full = os.path.join(directory, name)
        try:
            fd = os.open(full, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0))
        except OSError:
            continue
        try:
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                continue
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            continue  # a live writer holds it
        else:
            _unlink_quietly(full)
            removed.append(name)
        finally:
            os.close(fd)
    return removed


def atomic_write(path, data) -> None:
    """Replace `path` with `data` all at once, or not at all."""
    stage_bytes(path, data).commit()


def atomic_write_all(items) -> None:
    """Write several (path, data) outputs all or nothing: every one is staged
    before any is renamed into place, so a failure while writing leaves every
    target as it was."""
    items = list(items)
    paths = [os.path.abspath(p) for p, _ in items]
    if len(set(paths)) != len(paths):
        dup = next(p for p in paths if paths.count(p) > 1)
        raise UsageError("the same file is named for two outputs", dup)
    staged = []
    try:
        for path, data in items:
            staged.append(stage_bytes(path, data))
        for s in staged:
            s.commit()
    except BaseException:
        for s in staged:
            s.discard()
        raise


@contextlib.contextmanager
def staged_path(path):
    """For writers that need a file name: yields (staged, tmp_path) where tmp_path
    sits in a fresh private folder in the target folder and keeps the target's
    name (writers pick the file type from its extension). The writer writes
    tmp_path; the caller checks it and calls `staged.commit()`. Whatever is not
    committed when the block ends is removed, the folder with it."""
    import tempfile

    path = os.fspath(path)
    directory = _target_dir(path)
    mode = final_mode(path)
    base = os.path.basename(path)
    try:
        private = tempfile.mkdtemp(prefix="." + os.fsdecode(os.fsencode(base)[:200]) + TEMP_MARK, dir=directory)
    except OSError as exc:
        raise OutputError(f"cannot write here ({exc.strerror})", path) from None
    staged = Staged(path, os.path.join(private, base), cleanup_dir=private, mode=mode)
    try:
        yield staged, staged.tmp
    finally:
        staged.discard()


def seal(staged: Staged, min_size=1):
    """Check, fsync and set the final mode of a file a writer left at
    `staged.tmp` (see `staged_path`); OutputError when it is missing or short."""
    try:
        fd = os.open(staged.tmp, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise _write_error(exc, staged.path) from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode) or st.st_size < min_size:
            raise OutputError(f"the writer left {st.st_size} bytes; the output was not written", staged.path)
        os.fsync(fd)
        os.fchmod(fd, staged.mode if staged.mode is not None else 0o666 & ~current_umask())
    except OSError as exc:
        raise _write_error(exc, staged.path) from None
    finally:
        os.close(fd)


def refuse_same_file(src, dst) -> None:
    """UsageError when `dst` is `src` (the same file by device and inode, hard
    links and symlinks included): writing it would destroy the input."""
    try:
        same = os.path.samefile(src, dst)
    except OSError:  # either does not exist (yet): they cannot be one file
        return
    if same:
        what = "the input file" if os.path.abspath(src) == os.path.abspath(dst) else f"the same file as the input {src}"
        raise UsageError(f"the output is {what}; choose another output", dst)


def _unlink_quietly(p):
    try:
        os.unlink(p)
    except OSError:
        pass
