"""texcook.fileio: exclusive temporaries, checked writes, modes, cleanup on every
failure path, the memory budget and regular-file reads."""

import errno
import os
import stat
import threading
import time

import numpy as np
import pytest

from texcook import fileio
from texcook.errors import InputError, OutputError, UsageError
from texcook.image import write_image

from conftest import files_in


@pytest.fixture
def umask():
    """Set a umask for one test, restoring the old one after."""
    saved = []

    def set_(mask):
        saved.append(os.umask(mask))

    yield set_
    if saved:
        os.umask(saved[0])


# ----------------------------------------------------------------------------- atomic_write


def test_write_and_replace(tmp_path):
    out = tmp_path / "x.ktx2"
    fileio.atomic_write(out, b"one")
    fileio.atomic_write(out, memoryview(b"two two"))
    assert out.read_bytes() == b"two two"
    assert files_in(tmp_path) == ["x.ktx2"]


def test_mode_follows_umask(tmp_path, umask):
    umask(0o027)
    fileio.atomic_write(tmp_path / "a.ktx2", b"x")
    assert stat.S_IMODE(os.stat(tmp_path / "a.ktx2").st_mode) == 0o640
    umask(0o022)
    fileio.atomic_write(tmp_path / "b.ktx2", b"x")
    assert stat.S_IMODE(os.stat(tmp_path / "b.ktx2").st_mode) == 0o644


@pytest.mark.parametrize("mode", [0o644, 0o600, 0o664])
def test_replacing_keeps_the_mode(tmp_path, umask, mode):
    umask(0o077)
    out = tmp_path / "x.ktx2"
    out.write_bytes(b"old")
    os.chmod(out, mode)
    fileio.atomic_write(out, b"new")
    assert stat.S_IMODE(os.stat(out).st_mode) == mode and out.read_bytes() == b"new"


def test_temporary_is_named_as_texcooks_and_exclusive(tmp_path, monkeypatch):
    out = tmp_path / "x.ktx2"
    staged = fileio.stage_bytes(out, b"data")
    name = os.path.basename(staged.tmp)
    assert name.startswith(".x.ktx2.texcook-") and name.endswith(".tmp") and fileio.is_temp_name(name)
    assert not out.exists()
    staged.commit()
    assert out.read_bytes() == b"data" and files_in(tmp_path) == ["x.ktx2"]
    assert not fileio.is_temp_name("x.ktx2") and not fileio.is_temp_name("notes.texcook.txt")


def test_a_planted_symlink_is_never_followed(tmp_path, monkeypatch):
    """Even with a predictable name (the random part forced), a symlink planted
    at the temporary's name is not written through."""
    victim = tmp_path / "victim"
    victim.write_bytes(b"precious")
    monkeypatch.setattr(fileio.secrets, "token_hex", lambda n: "00000000")
    os.symlink(victim, tmp_path / ".x.ktx2.texcook-00000000.tmp")
    with pytest.raises(OutputError, match="x.ktx2: cannot create a temporary"):
        fileio.atomic_write(tmp_path / "x.ktx2", b"evil")
    assert victim.read_bytes() == b"precious" and not (tmp_path / "x.ktx2").exists()


def test_long_names_fit_one_component(tmp_path):
    out = tmp_path / ("n" * 250 + ".ktx2")
    fileio.atomic_write(out, b"x")
    assert out.read_bytes() == b"x" and files_in(tmp_path) == [out.name]


def test_output_symlink_is_replaced_not_followed(tmp_path):
    victim = tmp_path / "victim"
    victim.write_bytes(b"precious")
    link = tmp_path / "x.ktx2"
    os.symlink(victim, link)
    fileio.atomic_write(link, b"new")
    assert victim.read_bytes() == b"precious"
    assert not os.path.islink(link) and link.read_bytes() == b"new"


@pytest.mark.parametrize("where", ["write", "fsync", "replace"])
def test_disk_full_leaves_the_old_file(tmp_path, monkeypatch, where):
    out = tmp_path / "x.ktx2"
    out.write_bytes(b"previous")

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(fileio.os, where, full)
    with pytest.raises(OutputError, match="x.ktx2: (no space left on the device|cannot write)"):
        fileio.atomic_write(out, b"new data")
    monkeypatch.undo()
    assert out.read_bytes() == b"previous" and files_in(tmp_path) == ["x.ktx2"]


def test_short_write_is_caught(tmp_path, monkeypatch):
    """A writer that reports fewer bytes than it was given is written again
    from there; one that makes no progress is an error."""
    out = tmp_path / "x.ktx2"
    real = os.write
    monkeypatch.setattr(fileio.os, "write", lambda fd, b: real(fd, bytes(b)[:3]))
    fileio.atomic_write(out, b"0123456789")
    assert out.read_bytes() == b"0123456789"
    monkeypatch.setattr(fileio.os, "write", lambda fd, b: 0)
    with pytest.raises(OutputError, match="x.ktx2"):
        fileio.atomic_write(out, b"abc")
    assert out.read_bytes() == b"0123456789" and files_in(tmp_path) == ["x.ktx2"]


def test_interrupt_removes_the_temporary(tmp_path, monkeypatch):
    out = tmp_path / "x.ktx2"
    out.write_bytes(b"previous")

    def interrupt(fd):
        raise KeyboardInterrupt

    monkeypatch.setattr(fileio.os, "fsync", interrupt)
    with pytest.raises(KeyboardInterrupt):
        fileio.atomic_write(out, b"new")
    assert out.read_bytes() == b"previous" and files_in(tmp_path) == ["x.ktx2"]


def test_real_full_disk(full_disk):
    out = full_disk / "x.ktx2"
    out.write_bytes(b"previous")
    with pytest.raises(OutputError, match="x.ktx2: no space left"):
        fileio.atomic_write(out, bytes(1 << 20))
    assert out.read_bytes() == b"previous" and files_in(full_disk) == ["x.ktx2"]


def test_write_all_is_all_or_nothing(tmp_path, monkeypatch):
    a, b = tmp_path / "a.ktx2", tmp_path / "b.ktx2"
    a.write_bytes(b"old a")
    real = fileio.stage_bytes
    calls = []

    def second_fails(path, data):
        calls.append(path)
        if len(calls) == 2:
            raise OutputError("cannot write (No space left on device)", path)
        return real(path, data)

    monkeypatch.setattr(fileio, "stage_bytes", second_fails)
    with pytest.raises(OutputError):
        fileio.atomic_write_all([(a, b"new a"), (b, b"new b")])
    assert a.read_bytes() == b"old a" and files_in(tmp_path) == ["a.ktx2"]
    monkeypatch.undo()
    fileio.atomic_write_all([(a, b"new a"), (b, b"new b")])
    assert a.read_bytes() == b"new a" and b.read_bytes() == b"new b"
    with pytest.raises(UsageError, match="same file"):
        fileio.atomic_write_all([(a, b"1"), (tmp_path / "." / "a.ktx2", b"2")])


def test_missing_directory(tmp_path):
    with pytest.raises(OutputError, match="output directory does not exist"):
        fileio.atomic_write(tmp_path / "no" / "x.ktx2", b"x")
    with pytest.raises(OutputError, match="is a directory"):
        fileio.atomic_write(tmp_path, b"x")


# ----------------------------------------------------------------------------- staged_path (OpenImageIO)


def test_staged_path_is_private_and_cleaned(tmp_path):
    out = tmp_path / "x.png"
    with fileio.staged_path(out) as (staged, tmp):
        folder = os.path.dirname(tmp)
        assert os.path.basename(tmp) == "x.png" and os.path.dirname(folder) == str(tmp_path)
        assert stat.S_IMODE(os.stat(folder).st_mode) == 0o700 and fileio.is_temp_name(folder)
        with open(tmp, "wb") as fh:
            fh.write(b"partial")
    assert files_in(tmp_path) == []  # never committed: gone, folder and all
    with pytest.raises(RuntimeError):
        with fileio.staged_path(out) as (staged, tmp):
            open(tmp, "wb").close()
            raise RuntimeError
    assert files_in(tmp_path) == []


def test_seal_refuses_an_empty_file(tmp_path):
    out = tmp_path / "x.png"
    out.write_bytes(b"previous")
    with fileio.staged_path(out) as (staged, tmp):
        open(tmp, "wb").close()
        with pytest.raises(OutputError, match="x.png: the writer left 0 bytes"):
            fileio.seal(staged)
    assert out.read_bytes() == b"previous" and files_in(tmp_path) == ["x.png"]


@pytest.mark.parametrize("ext", [".png", ".tga", ".tif", ".jpg", ".exr"])
def test_image_on_a_full_disk(full_disk, rng, ext):
    """Each writer meets a full disk: an error naming the file, the old file
    intact, nothing left behind."""
    out = full_disk / f"x{ext}"
    out.write_bytes(b"previous")
    px = rng.random((700, 700, 4)).astype(np.float32)
    with pytest.raises(OutputError, match=f"x\\{ext}: "):
        write_image(out, px if ext == ".exr" else (px * 255).astype(np.uint8))
    assert out.read_bytes() == b"previous" and files_in(full_disk) == [out.name]


def test_image_writer_failing_midway(tmp_path, rng, monkeypatch):
    """A writer whose output does not read back (the faked truncation) is caught
    before the rename."""
    import texcook.image as image

    out = tmp_path / "x.png"
    out.write_bytes(b"previous")
    real_seal = image.seal

    def truncate_then_seal(staged, min_size=1):
        with open(staged.tmp, "r+b") as fh:
            fh.truncate(100)
        real_seal(staged, min_size)

    monkeypatch.setattr(image, "seal", truncate_then_seal)
    with pytest.raises(OutputError, match="x.png: the written image does not read back"):
        write_image(out, rng.integers(0, 256, (64, 64, 3)).astype(np.uint8))
    assert out.read_bytes() == b"previous" and files_in(tmp_path) == ["x.png"]


def test_image_mode_follows_umask_and_replaced_file(tmp_path, umask):
    umask(0o022)
    write_image(tmp_path / "a.png", np.zeros((2, 2, 3), np.uint8))
    assert stat.S_IMODE(os.stat(tmp_path / "a.png").st_mode) == 0o644
    os.chmod(tmp_path / "a.png", 0o600)
    write_image(tmp_path / "a.png", np.zeros((2, 2, 3), np.uint8))
    assert stat.S_IMODE(os.stat(tmp_path / "a.png").st_mode) == 0o600


# ----------------------------------------------------------------------------- reading


def test_only_regular_files_are_read(tmp_path):
    fifo = tmp_path / "x.ktx2"
    os.mkfifo(fifo)
    t0 = time.monotonic()
    with pytest.raises(InputError, match="x.ktx2: is a pipe"):
        fileio.read_bytes(fifo)
    with pytest.raises(InputError, match="is a device"):
        fileio.read_bytes("/dev/zero")
    with pytest.raises(InputError, match="is a directory"):
        fileio.read_bytes(tmp_path)
    with pytest.raises(InputError, match="is a pipe"):
        fileio.check_regular(fifo)
    with pytest.raises(InputError, match="no such file"):
        fileio.read_bytes(tmp_path / "none")
    assert time.monotonic() - t0 < 2


def test_a_fifo_with_a_writer_waiting_is_not_read(tmp_path):
    """Even with a writer at the other end, nothing is read from a FIFO."""
    fifo = tmp_path / "x.png"
    os.mkfifo(fifo)
    writer = threading.Thread(target=lambda: open(fifo, "wb").close(), daemon=True)
    writer.start()
    with pytest.raises(InputError, match="is a pipe"):
        fileio.read_bytes(fifo)
    os.close(os.open(fifo, os.O_RDONLY | os.O_NONBLOCK))  # let the writer go
    writer.join(5)


def test_file_larger_than_the_budget(tmp_path):
    p = tmp_path / "x.ktx2"
    p.write_bytes(bytes(5000))
    fileio.set_max_memory(4096)
    try:
        with pytest.raises(InputError, match="x.ktx2: reading this 5000-byte texture needs 4.9K, more than the "
                                             "4.0K memory budget"):
            fileio.read_bytes(p, "texture")
    finally:
        fileio.set_max_memory(None)
    assert fileio.read_bytes(p) == bytes(5000)


def test_sizes_and_default_budget(monkeypatch):
    assert fileio.parse_size("512M") == 512 << 20
    assert fileio.parse_size("1.5g") == 3 << 29
    assert fileio.parse_size("2GiB") == 2 << 30
    assert fileio.parse_size("100000") == 100000
    for bad in ("", "lots", "-1G", "0", "1Q"):
        with pytest.raises(UsageError):
            fileio.parse_size(bad)
    monkeypatch.delenv("TEXCOOK_MAX_MEMORY", raising=False)
    phys = fileio.physical_memory()
    assert fileio.default_max_memory() == (phys // 8 if phys else 1 << 30)
    monkeypatch.setenv("TEXCOOK_MAX_MEMORY", "3G")
    assert fileio.max_memory() == 3 << 30


def test_refuse_same_file(tmp_path):
    a = tmp_path / "a.dds"
    a.write_bytes(b"x")
    with pytest.raises(UsageError, match="a.dds: the output is the input file"):
        fileio.refuse_same_file(a, a)
    os.link(a, tmp_path / "hard.dds")
    os.symlink(a, tmp_path / "soft.dds")
    for other in ("hard.dds", "soft.dds", "./a.dds"):
        with pytest.raises(UsageError, match="the output is"):
            fileio.refuse_same_file(a, tmp_path / other)
    fileio.refuse_same_file(a, tmp_path / "new.dds")  # not there yet: fine
    (tmp_path / "b.dds").write_bytes(b"x")
    fileio.refuse_same_file(a, tmp_path / "b.dds")  # equal bytes, different file: fine


def test_a_killed_writers_temporary_is_removed_by_the_next_write(tmp_path):
    """Was: a SIGKILL left a 200 MB temporary that nothing cleaned. The writer
    holds a lock on its temporary; the kernel drops it with the process, and
    the next write of the same output removes what nobody holds."""
    import subprocess
    import sys

    out = tmp_path / "t.ktx2"
    script = ("import os, signal\nfrom texcook.fileio import stage_bytes\n"
              f"stage_bytes({str(out)!r}, b'x' * 100000)\nos.kill(os.getpid(), signal.SIGKILL)\n")
    p = subprocess.run([sys.executable, "-c", script])
    assert p.returncode == -9
    stale = [n for n in os.listdir(tmp_path) if n.startswith(".t.ktx2.texcook-")]
    assert len(stale) == 1
    from texcook.fileio import atomic_write, stage_bytes, sweep_stale

    live = stage_bytes(out, b"live")  # the next writer sweeps the dead one's temporary
    assert not os.path.exists(tmp_path / stale[0])
    assert sweep_stale(out) == [] and os.path.exists(live.tmp)  # a live writer's is left alone
    live.discard()
    atomic_write(out, b"new")
    assert out.read_bytes() == b"new" and os.listdir(tmp_path) == ["t.ktx2"]


# ----------------------------------------------------------------------------- locks


def test_a_lock_is_held_until_closed(tmp_path):
    path = tmp_path / "x.lock"
    fd = fileio.lock(path, create=True)
    assert fileio.lock(path, wait=False) is None  # another open file description: refused
    assert fileio.lock(path, exclusive=False, wait=False) is None
    os.close(fd)
    again = fileio.lock(path, wait=False)
    assert again is not None
    os.close(again)


def test_a_folder_can_be_locked_and_shared_locks_coexist(tmp_path):
    a = fileio.lock(tmp_path, exclusive=False)
    b = fileio.lock(tmp_path, exclusive=False, wait=False)
    assert b is not None and fileio.lock(tmp_path, wait=False) is None
    os.close(a)
    os.close(b)


def test_a_lock_never_follows_a_planted_symlink(tmp_path):
    target = tmp_path / "victim"
    target.write_bytes(b"keep")
    os.symlink(target, tmp_path / "x.lock")
    with pytest.raises(OSError):
        fileio.lock(tmp_path / "x.lock", create=True)
    assert target.read_bytes() == b"keep"


# ----------------------------------------------------------------------------- one reader, one writer

# Opens outside fileio that read or write no user file, each with its reason.
NOT_USER_FILES = {
    ("cli.py", "wrapper"): "os.devnull, standing in for a closed stdout",
    ("image.py", "_quiet_stderr"): "os.devnull, muting the image library's own diagnostics",
    ("image.py", "_stage_image"): "the image writer writes the temporary fileio.staged_path gives it",
    ("image.py", "_check_written"): "reads back that temporary before it is renamed into place",
    ("_jit.py", "_cache_lock"): "the lock file beside numba's kernel cache",
    ("cli.py", "view"): "webbrowser.open of the page's http://127.0.0.1 address, not a file",
}
_FILE_LOADERS = {"json", "tomllib", "pickle", "marshal"}  # their load() reads an open file


def _opens(tree):
    """(function name, line, call) for every call in `tree` that opens a file by
    name or reads one: open and os.open, pathlib's readers and writers, json and
    TOML loads of an open file, glTF's and NumPy's file loaders. OpenImageIO's
    ImageInput.open is the image reader's own, behind fileio.check_regular."""
    import ast

    found = []

    def opens(call):
        f = call.func
        if isinstance(f, ast.Name):
            return f.id == "open"
        if not isinstance(f, ast.Attribute):
            return False
        owner = ast.unparse(f.value)
        if f.attr == "open":
            return not owner.endswith("ImageInput")
        if f.attr == "read_bytes":  # pathlib's takes no argument; fileio's takes the path
            return not call.args
        if f.attr == "load":
            return owner in _FILE_LOADERS
        return f.attr in ("read_text", "write_text", "write_bytes", "load_json", "load_binary", "fromfile",
                          "tofile", "loadtxt", "savetxt")

    def visit(node, func):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            func = node.name
        if isinstance(node, ast.Call) and opens(node):
            found.append((func, node.lineno, ast.unparse(node)[:80]))
        for child in ast.iter_child_nodes(node):
            visit(child, func)

    visit(tree, "<module>")
    return found


def test_every_user_file_goes_through_fileio():
    """Reads and writes of user files go through texcook.fileio (regular files
    only, the memory budget, atomic writes): a new bare open elsewhere fails here."""
    import ast

    import texcook

    root = os.path.dirname(texcook.__file__)
    stray = []
    for dirpath, _, names in os.walk(root):
        for name in sorted(names):
            if not name.endswith(".py") or name == "fileio.py":
                continue
            path = os.path.join(dirpath, name)
            rel = os.path.relpath(path, root)
            with open(path, encoding="utf-8") as fh:
                tree = ast.parse(fh.read(), path)
            for func, line, call in _opens(tree):
                if (rel, func) not in NOT_USER_FILES:
                    stray.append(f"{rel}:{line} in {func}: {call}")
    assert not stray, "files opened outside texcook.fileio:\n" + "\n".join(stray)


def test_the_open_walker_finds_opens():
    import ast

    tree = ast.parse("def f(p):\n    with open(p) as fh:\n        return json.load(fh)\n"
                     "def g(p):\n    return Path(p).read_bytes(), os.open(p, 0), read_bytes(p), np.load(p)\n"
                     "def h(p):\n    return oiio.ImageInput.open(p), load(p)\n")
    assert [(f, line) for f, line, _ in _opens(tree)] == [("f", 2), ("f", 3), ("g", 5), ("g", 5)]
