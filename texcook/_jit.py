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
