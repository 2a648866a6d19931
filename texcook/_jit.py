"""The one place numba options are set.

Kernels cache to disk so a warm start skips compilation. fastmath stays off:
codec paths must be bit-exact and reassociation would make results depend on
the compiler's choices.
"""

from numba import njit

JIT_OPTIONS = dict(cache=True, nogil=True, fastmath=False, error_model="numpy")


def jit(fn=None, **overrides):
    """`@jit` or `@jit(...)`: numba.njit with the project's options."""
    opts = dict(JIT_OPTIONS, **overrides)
    if fn is None:
        return lambda f: njit(**opts)(f)
    return njit(**opts)(fn)


def jit_typed(signature, **overrides):
    """numba.njit with the project's options and an explicit signature: the
    function compiles once, at import (or loads from the cache), and callers
    passing literals or narrower ints convert to it instead of compiling
    another specialisation. Arrays must match exactly (layout, writability)."""
    return njit(signature, **dict(JIT_OPTIONS, **overrides))
