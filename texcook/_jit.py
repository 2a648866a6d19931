"""The one place numba options are set.

Kernels cache to disk so a warm start skips compilation. fastmath stays off:
codec paths must be bit-exact and reassociation would make results depend on
the compiler's choices.

numba itself is loaded when the first kernel runs, not when a module that
defines kernels is imported: importing numba and initialising its compiler
costs about half a second, which commands that only check a recipe, list
formats or skip up-to-date files (a batch's second run) never need to pay.
Until then a kernel is a `_Pending` stand-in; the first call of any kernel
makes every defined kernel a numba dispatcher and puts the dispatchers where
the stand-ins were, so that numba sees dispatchers when it types a caller.
A kernel found in the cache is loaded without the rest of numba's compiler
(`_load_cached`), and `preload` lets a bake import numba while it reads its
source.
"""

import contextlib
import functools
import sys
import threading

# no_cfunc_wrapper: nothing takes a kernel's C address, and the wrapper costs
# compile time for every function
JIT_OPTIONS = dict(cache=True, nogil=True, fastmath=False, error_model="numpy", no_cfunc_wrapper=True)

_pending = []  # stand-ins not yet turned into dispatchers, in definition order
_njit = None  # numba.njit once numba is loaded
_loading = threading.RLock()  # kernels are first called from several threads at once
_preloader = None  # the thread preload() started
_preload_started = threading.Lock()


@contextlib.contextmanager
def _blas_probe_hidden():
    """Import numba's array maths, if it loads here, while scipy.linalg is hidden.

    numba probes for scipy's BLAS when its array maths module loads (at a
    compile, or when a cached kernel's environment names the module), and
    importing scipy.linalg costs about 0.2 s. texcook's kernels call no BLAS
    routine; without the probe numba's np.dot-style helpers fall back to plain
    loops. A process that imported scipy.linalg already keeps it.
    """
    hide = "scipy.linalg" not in sys.modules and "numba.np.arraymath" not in sys.modules
    if hide:
        sys.modules["scipy.linalg"] = None  # makes `import scipy.linalg` fail fast
    try:
        yield
    finally:
        if hide:
            del sys.modules["scipy.linalg"]


def _load_cached(cache, sig, target_context):
    """A dispatcher's cache lookup without numba's registry refresh.

    numba refreshes its typing and lowering registries before every cache
    lookup (about 0.2 s the first time, and all of numba's array, list and
    dict implementations imported), although a cached kernel is machine code
    that needs only numba's runtime. On a miss numba compiles, and its
    compiler refreshes the registries itself; the array maths is imported
    here first so that the refresh finds it loaded without scipy's probe, and
    numba's extensions are loaded then too (`_without_refresh`).
    """
    from numba.core import entrypoints
    from numba.core.runtime import rtsys

    rtsys.initialize(target_context)  # the allocator and refcounting cached code calls
    cres = None
    with _blas_probe_hidden(), cache._guard_against_spurious_io_errors():
        cres = cache._load_overload(sig, target_context)
    if cres is None:
        with _blas_probe_hidden():
            import numba.np.arraymath  # noqa: F401  (before extensions, which may import it)
        entrypoints.init_all()
    return cres


def _without_refresh(dispatcher):
    cache = getattr(dispatcher, "_cache", None)
    # numba's own path stays for any version whose cache is not laid out so
    if all(hasattr(cache, name) for name in ("_load_overload", "_guard_against_spurious_io_errors")):
        cache.load_overload = functools.partial(_load_cached, cache)
        # numba loads third-party extensions before it types a call's arguments,
        # scanning every installed package's entry points (about 0.04 s); our
        # arguments are arrays and scalars, so that waits for a compile
        dispatcher._compilation_chain_init_hook = _nothing
    return dispatcher


def _nothing():
    pass


def _make(fn, signature, opts):
    dispatcher = _njit(**opts)(fn)
    if not hasattr(dispatcher, "disable_compile"):
        return dispatcher  # NUMBA_DISABLE_JIT: the Python function itself
    _without_refresh(dispatcher)
    if signature:
        # what njit(signature) does, after the cache lookup is set up
        for sig in signature if isinstance(signature, list) else [signature]:
            dispatcher.compile(sig)
        dispatcher.disable_compile()
    return dispatcher


def preload():
    """Start loading numba on a thread of its own, once. A bake calls this
    before it reads its source: the import (Python, holding the interpreter)
    then overlaps the image decode (which releases it), about 0.15 s of a
    2048x2048 PNG bake. The first kernel call waits for the load; if it
    failed, that call loads again and raises."""
    global _preloader
    with _preload_started:
        if _njit is not None or _preloader is not None:
            return
        # not a daemon: the interpreter must not stop while numba is half imported
        _preloader = threading.Thread(target=_load_quietly, name="texcook-load-numba")
        _preloader.start()


def _load_quietly():
    try:
        with _loading:
            if _njit is None:
                _load()
    except Exception:  # noqa: BLE001  (raised again at the first kernel call)
        pass


def _load():
    """Load numba, make every pending kernel a dispatcher and replace the
    stand-ins in the namespaces of loaded modules. Typed kernels compile (or
    load from the cache) as they are made, so they are made last, when their
    callees are dispatchers already."""
    global _njit
    if _njit is None:
        from numba import njit

        _njit = njit
    pending, _pending[:] = list(_pending), []
    places = _places()
    for stand_in in pending:
        if stand_in._signature is None:
            stand_in._made = _make(stand_in._fn, None, stand_in._opts)
    _replace(places)
    for stand_in in pending:  # in definition order: callees before callers
        if stand_in._signature is not None:
            stand_in._made = _make(stand_in._fn, stand_in._signature, stand_in._opts)
            _replace(places)


def _places():
    """(namespace, name) of every stand-in held by a loaded module."""
    found = []
    for module in list(sys.modules.values()):
        try:
            space = vars(module)
        except TypeError:  # None (a failed import) or an object without a namespace
            continue
        if isinstance(space, dict):
            found.extend((space, name) for name, value in list(space.items()) if type(value) is _Pending)
    return found


def _replace(places):
    for space, name in places:
        value = space.get(name)
        if type(value) is _Pending and value._made is not None:
            space[name] = value._made


class _Pending:
    """A kernel whose numba dispatcher is not made yet. Calling it, or asking
    it for a dispatcher attribute (`py_func`, `signatures`), loads numba."""

    def __init__(self, fn, signature, opts):
        self._fn, self._signature, self._opts, self._made = fn, signature, opts, None
        self.__wrapped__ = fn
        self.__name__, self.__qualname__, self.__module__ = fn.__name__, fn.__qualname__, fn.__module__
        self.__doc__ = fn.__doc__

    def _dispatcher(self):
        if self._made is None:
            with _loading:
                if self._made is None:
                    _load()
        return self._made

    def __call__(self, *args, **kwargs):
        return self._dispatcher()(*args, **kwargs)

    def __getattr__(self, name):
        if name.startswith("__") or name in ("_fn", "_signature", "_opts", "_made"):
            raise AttributeError(name)  # copy/pickle probing a half-made object
        return getattr(self._dispatcher(), name)

    def __repr__(self):
        return f"<kernel {self.__module__}.{self.__qualname__} (numba not loaded yet)>"


def _define(fn, signature, opts):
    with _loading:
        if _njit is not None:
            return _make(fn, signature, opts)
        stand_in = _Pending(fn, signature, opts)
        _pending.append(stand_in)
        return stand_in


def jit(fn=None, **overrides):
    """`@jit` or `@jit(...)`: numba.njit with the project's options."""
    opts = dict(JIT_OPTIONS, **overrides)
    if fn is None:
        return lambda f: _define(f, None, opts)
    return _define(fn, None, opts)


def jit_inner(fn=None, **overrides):
    """`jit` for helpers only ever called from other kernels: no wrapper for
    calls from Python, which numba would otherwise build and compile for each."""
    return jit(fn, no_cpython_wrapper=True, **overrides)


def jit_typed(signature, **overrides):
    """numba.njit with the project's options and an explicit signature: the
    function compiles once (or loads from the cache) when numba is loaded, and
    callers passing literals or narrower ints convert to it instead of
    compiling another specialisation. Arrays must match exactly (layout,
    writability)."""
    opts = dict(JIT_OPTIONS, **overrides)
    return lambda f: _define(f, signature, opts)
