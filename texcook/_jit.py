"""The one place numba options are set.

Kernels cache to disk so a warm start skips compilation. fastmath stays off:
codec paths must be bit-exact and reassociation would make results depend on
the compiler's choices.
"""

import sys


def _load_numba_without_blas_probe():
    """Import numba with its array maths loaded while scipy.linalg is hidden.

    numba probes for scipy's BLAS when its array maths module loads (at the
    first kernel call of a process), and importing scipy.linalg costs about
    0.2 s of every bake. texcook's kernels call no BLAS routine; without the
    probe numba's np.dot-style helpers fall back to plain loops. A process that
    imported scipy.linalg already keeps it.
    """
    hide = "scipy.linalg" not in sys.modules
    if hide:
        sys.modules["scipy.linalg"] = None  # makes `import scipy.linalg` fail fast
    try:
        import numba.np.arraymath  # noqa: F401
    finally:
        if hide:
            del sys.modules["scipy.linalg"]


_load_numba_without_blas_probe()

from numba import njit  # noqa: E402

# no_cfunc_wrapper: nothing takes a kernel's C address, and the wrapper costs
# compile time for every function
JIT_OPTIONS = dict(cache=True, nogil=True, fastmath=False, error_model="numpy", no_cfunc_wrapper=True)


def jit(fn=None, **overrides):
    """`@jit` or `@jit(...)`: numba.njit with the project's options."""
    opts = dict(JIT_OPTIONS, **overrides)
    if fn is None:
        return lambda f: njit(**opts)(f)
    return njit(**opts)(fn)


def jit_inner(fn=None, **overrides):
    """`jit` for helpers only ever called from other kernels: no wrapper for
    calls from Python, which numba would otherwise build and compile for each."""
    return jit(fn, no_cpython_wrapper=True, **overrides)


def jit_typed(signature, **overrides):
    """numba.njit with the project's options and an explicit signature: the
    function compiles once, at import (or loads from the cache), and callers
    passing literals or narrower ints convert to it instead of compiling
    another specialisation. Arrays must match exactly (layout, writability)."""
    return njit(signature, **dict(JIT_OPTIONS, **overrides))
