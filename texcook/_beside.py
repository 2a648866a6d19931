"""Compiling kernels in a second process while this one compiles others.

numba compiles one function at a time per process (its compiler holds a
global lock). On a cold kernel cache a bake spends most of its time compiling:
first its codec's kernels (seconds), then the mip chain's. A helper process
given a small sample of the same work compiles the chain's kernels into the
shared disk cache meanwhile, on the second core, and the bake loads them from
there when it gets to them. What the helper has not finished by then the bake
compiles itself, as without it; the helper is stopped when the bake is done.

`start` runs fn(*args) in the helper: fn and its arguments are pickled to the
helper's standard input, so they must be small (a sample, a recipe). The
helper's output is discarded and its failure ignored: it only fills a cache.
Set TEXCOOK_COMPILE_BESIDE=0 to never start one.
"""

import importlib
import os
import pickle
import subprocess
import sys

# a payload that fits a pipe's buffer is written without waiting for the
# helper to start reading (Linux: 64 KiB)
_MAX_PAYLOAD = 60_000
_NICE = 10  # the helper yields the core to the bake and to other work


def start(fn, *args):
    """A helper process running fn(*args), or None when none was started."""
    if os.environ.get("TEXCOOK_COMPILE_BESIDE", "1") == "0":
        return None
    if getattr(sys, "frozen", False):  # a frozen program cannot run `-m`
        return None
    # the interpreter multiprocessing would start: embedding programs point it
    # at their Python when sys.executable is the program itself
    from multiprocessing.spawn import get_executable

    payload = pickle.dumps((fn.__module__, fn.__qualname__, args), protocol=pickle.HIGHEST_PROTOCOL)
    if len(payload) > _MAX_PAYLOAD:
        return None
    env = dict(os.environ)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    if root not in _site_dirs():
        # the helper imports this copy of the package, however this process
        # found it (a site folder on PYTHONPATH would come before the standard
        # library: an installed copy is found there anyway)
        env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH")) if p)
    try:
        # -P: the working folder is not put on sys.path (a folder named like
        # the package there must not be what the helper imports)
        proc = subprocess.Popen([get_executable(), "-P", "-m", __name__], stdin=subprocess.PIPE,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    except OSError:
        return None
    try:
        proc.stdin.write(payload)
        proc.stdin.close()
    except OSError:  # it died already
        stop(proc)
        return None
    return proc


def _site_dirs():
    import site

    dirs = list(getattr(site, "getsitepackages", lambda: [])())
    dirs.append(getattr(site, "getusersitepackages", lambda: "")())
    return {os.path.abspath(d) for d in dirs if d}


def stop(proc):
    """End the helper (if it is still compiling, its work is no longer
    wanted). numba writes each cache file whole (to a temporary name, then
    renamed), so stopping it midway leaves no half-written entry."""
    if proc is None:
        return
    if proc.poll() is None:
        proc.terminate()
    proc.wait()


def _main():
    try:
        os.nice(_NICE)
    except (AttributeError, OSError):
        pass
    module, name, args = pickle.loads(sys.stdin.buffer.read())
    fn = importlib.import_module(module)
    for part in name.split("."):
        fn = getattr(fn, part)
    fn(*args)


if __name__ == "__main__":
    _main()
