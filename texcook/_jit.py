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
numba's compiler (its typing and lowering registries) is set up only when a
kernel is not in the cache and has to compile (`_cache_only_loader`), and
`loading_beside` lets a bake import numba while it reads its source.
"""

import contextlib
import os
import sys
import threading

from . import _compile_progress

# no_cfunc_wrapper: nothing takes a kernel's C address, and the wrapper costs
# compile time for every function
JIT_OPTIONS = dict(cache=True, nogil=True, fastmath=False, error_model="numpy", no_cfunc_wrapper=True)

_pending = []  # stand-ins not yet turned into dispatchers, in definition order
_njit = None  # numba.njit once numba is loaded
_loading = threading.RLock()  # kernels are first called from several threads at once
_preloader = None  # the thread loading_beside() started
_preload_started = threading.Lock()


@contextlib.contextmanager
def _blas_probe_hidden():
    """scipy.linalg hidden while numba's array maths may load.

    numba probes for scipy's BLAS when its array maths module loads (before a
    compilation, and when a cached kernel's environment names the module), and
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


def _cache_only_loader(dispatcher):
    """Make `dispatcher` load cached machine code without numba's compiler set-up.

    numba's cache calls `target_context.refresh()` before every load, which
    imports and installs every typing and lowering registry numba has (about
    0.2 s, and numba's array maths with its BLAS probe), and each call from
    Python first loads numba's extension entry points (importlib.metadata).
    A kernel loaded from the cache is machine code and needs neither. What it
    does need is numba's runtime (NRT) symbols, which the refresh would have
    registered first, so those are initialised here. On a cache miss the
    registries are prepared (with the BLAS probe hidden) and numba compiles as
    usual: its compiler refreshes the contexts and loads the entry points
    itself. If numba's internals are not what this expects, the dispatcher is
    left as numba made it.
    """
    cache = getattr(dispatcher, "_cache", None)
    try:
        from numba.core.caching import FunctionCache
        from numba.core.runtime import rtsys
    except ImportError:
        return
    if type(cache) is not FunctionCache or not all(
        callable(getattr(obj, name, None)) for obj, name in (
            (cache, "_load_overload"), (cache, "_guard_against_spurious_io_errors"), (rtsys, "initialize"),
            (dispatcher, "_compilation_chain_init_hook"))):
        return

    def load(sig, target_context):
        with _blas_probe_hidden(), cache._guard_against_spurious_io_errors():
            return cache._load_overload(sig, target_context)

    def load_overload(sig, target_context):
        rtsys.initialize(target_context)
        found = load(sig, target_context)
        if found is None and _compile_lock_taken(cache):  # another process may have saved it meanwhile
            found = load(sig, target_context)
        if found is None:  # numba compiles next, refreshing its contexts first
            with _blas_probe_hidden():
                import numba.np.arraymath  # noqa: F401
        return found

    cache.load_overload = load_overload
    dispatcher._compilation_chain_init_hook = lambda: None
    _lock_cache_file(cache)
    _compile_under_lock(dispatcher)


# --- one process compiles a kernel at a time ----------------------------------------------


_frames = threading.local()  # per thread: a list, one entry per compile() under way
_held = set()  # the compile locks this process holds (a kernel compiling itself must not wait on itself)


def _compile_under_lock(dispatcher):
    """A kernel not in the disk cache is compiled by one process at a time:
    another process that wants it meanwhile waits, then loads what the first
    saved, instead of compiling it again beside it (batch workers on a cold
    cache, `texcook prepare`'s processes, a bake and its helpers). The lock
    is a file beside the kernel's cache index, taken (by load_overload) only
    when the cache misses and held until compile() returns, after numba has
    saved the code. compile() runs under numba's compiler lock, so a process
    takes its file locks one thread at a time; a kernel's lock is taken
    before its callees' (they compile while it is typed) and calls never go
    round in a circle, so two processes never wait on each other."""
    plain = dispatcher.compile

    def compile(sig):
        frames = getattr(_frames, "stack", None)
        if frames is None:
            frames = _frames.stack = []
        frames.append(None)
        try:
            return plain(sig)
        finally:
            taken = frames.pop()
            if taken is not None:
                _held.discard(taken[0])
                os.close(taken[1])  # releases the lock

    dispatcher.compile = compile


def _compile_lock_taken(cache):
    """Take the compile lock of `cache`'s kernel for the compile() under way
    on this thread (waiting while another process holds it). True when it
    was taken now, so the cache is worth reading again."""
    frames = getattr(_frames, "stack", None)
    path = getattr(getattr(cache, "_cache_file", None), "_index_path", None)
    if not frames or frames[-1] is not None or not isinstance(path, str):
        return False
    path += ".compiling"
    if path in _held:
        return False
    try:
        from .fileio import lock

        fd = lock(path, exclusive=True, create=True)
    except (ImportError, OSError):  # a cache folder that cannot be written: nobody saves there
        return False
    frames[-1] = (path, fd)
    _held.add(path)
    return True


def _lock_cache_file(cache):
    """numba's cache of one kernel read and written under a lock shared by processes.

    numba saves a kernel's machine code by reading its index, adding a key and
    writing the index back, then the code: two processes compiling different
    signatures of one kernel at once (a bake and its compile_beside helper,
    batch workers on a cold cache) can both take the same data file, leaving
    the index pairing one signature with the other's code, which would then be
    run on arguments of the wrong types. A save holds an exclusive lock on a
    file beside the index, a load a shared one. Without a lock file (a cache
    folder that cannot be written) both run unlocked: then nobody saves there.
    """
    file = getattr(cache, "_cache_file", None)
    path = getattr(file, "_index_path", None)
    if not isinstance(path, str) or not all(callable(getattr(file, n, None)) for n in ("save", "load")):
        return

    def locked(fn, exclusive):
        def call(*args):
            with _cache_lock(file, exclusive):
                return fn(*args)
        return call

    file.save = locked(file.save, True)
    file.load = locked(file.load, False)


@contextlib.contextmanager
def _cache_lock(file, exclusive):
    """The lock of one kernel's cache file (a numba IndexDataCacheFile); none
    where there is no flock or no lock file can be made."""
    try:
        from .fileio import lock

        fd = lock(file._index_path + ".lock", exclusive=exclusive, create=True)
    except (ImportError, OSError):
        yield
        return
    try:
        yield
    finally:
        os.close(fd)  # releases the lock


class _AnyTarget:
    """Stands in for numba's code generator where only a kernel's code hash is wanted."""

    @staticmethod
    def magic_tuple():
        return None


def cached(kernel):
    """True when numba's disk cache holds machine code of `kernel`'s current
    source for some signature, False when it holds none; None when that
    cannot be told (no cache, or numba's internals are not what this expects).
    Loads numba."""
    if type(kernel) is _Pending:
        kernel = kernel._dispatcher()
    cache = getattr(kernel, "_cache", None)
    try:
        # the key numba files an overload under: (signature, target, code hashes)
        code = cache._index_key(None, _AnyTarget())[2]
        with _cache_lock(cache._cache_file, False):
            return any(key[2] == code for key in cache._cache_file._load_index())
    except Exception:  # noqa: BLE001  (not numba's FunctionCache, or a changed layout)
        return None


def _import_njit():
    """numba.njit, imported while modules numba would load for nothing are
    hidden: SciPy, which numba imports only to check its version (about 8 ms),
    and PyYAML (about 12 ms), which numba needs only to read a
    `.numba_config.yaml` in the working folder, so it is hidden only when there
    is none. A module the process imported already is left alone, and nothing
    is hidden if numba is loaded already."""
    already = "numba" in sys.modules
    hide = [name for name in ("scipy", "yaml") if not already and name not in sys.modules]
    if os.path.exists(".numba_config.yaml") and "yaml" in hide:
        hide.remove("yaml")
    for name in hide:
        sys.modules[name] = None  # makes `import name` fail fast
    try:
        from numba import njit
    finally:
        for name in hide:
            del sys.modules[name]
    _link_large_callees_optimised()
    return njit


_LARGE = 300  # instructions: past what LLVM inlines (a cost threshold of 250 at -O3, some 5 an instruction)
_LINK_LATE = set()  # qualified names of the kernels jit(link_late=True) made


def _link_large_callees_optimised():
    """numba links every callee's module into its caller's and runs LLVM's
    whole module pipeline again over the lot, callees included, each already
    optimised in its own compile: for the ASTC search kernel 4 s of the last,
    serial step of a first use, 80% of it its callees' code. For a kernel
    made with jit(link_late=True), callee libraries whose functions it calls
    are all too large to inline are linked after its module is optimised
    (their code still goes into its machine code, which the cache needs
    whole); smaller ones link first, as numba does, and may be inlined.
    Only for kernels measured with it: the callees' code then misses the
    extra round, which elsewhere could cost speed. Nothing changes where
    numba's internals are not what this expects."""
    try:
        from numba.core.codegen import CPUCodeLibrary
    except ImportError:
        return
    finalize = getattr(CPUCodeLibrary, "finalize", None)
    optimise = getattr(CPUCodeLibrary, "_optimize_final_module", None)
    if (finalize is None or optimise is None or getattr(finalize, "_texcook", False)
            or not hasattr(CPUCodeLibrary, "_get_module_for_linking")):
        return

    def size(library, name):
        """Instructions in function `name` of library's module for linking (None: not defined there)."""
        known = library.__dict__.setdefault("_texcook_sizes", {})
        if name not in known:
            try:
                fn = library._get_module_for_linking().get_function(name)
            except NameError:  # llvmlite's answer for a name the module lacks
                fn = None
            known[name] = None if fn is None or fn.is_declaration else sum(
                1 for b in fn.blocks for _ in b.instructions)
        return known[name]

    def finalize_large_last(self):
        libraries = getattr(self, "_linking_libraries", None)
        # the library numba makes for a kernel is named by its qualified name
        if (getattr(self, "name", None) not in _LINK_LATE or not isinstance(libraries, list)
                or not hasattr(self, "_reload_init") or not hasattr(self, "_final_module")):
            return finalize(self)
        # numba's runtime functions (NRT_*), tiny, are linked into every library counting references
        called = [f.name for f in self._final_module.functions if f.is_declaration and not f.name.startswith("NRT_")]
        later = []
        for lib in dict.fromkeys(libraries):
            sizes = [n for n in (size(lib, name) for name in called) if n is not None]
            if sizes and min(sizes) >= _LARGE:
                later.append(lib)
        self._linking_libraries = [lib for lib in libraries if lib not in later]
        self._texcook_later = later
        try:
            return finalize(self)
        finally:
            self._linking_libraries = libraries

    def optimise_then_link(self):
        optimise(self)
        for lib in getattr(self, "_texcook_later", ()):
            self._reload_init.update(lib._reload_init)
            self._final_module.link_in(lib._get_module_for_linking(), preserve=True)

    finalize_large_last._texcook = True
    CPUCodeLibrary.finalize = finalize_large_last
    CPUCodeLibrary._optimize_final_module = optimise_then_link


def _make(fn, signature, opts):
    dispatcher = _njit(**opts)(fn)
    _cache_only_loader(dispatcher)
    if signature is None or not hasattr(dispatcher, "compile"):  # NUMBA_DISABLE_JIT gives the function back
        return dispatcher if signature is None else _njit(signature, **opts)(fn)
    # what njit(signature) does, on the dispatcher whose cache loads cheaply
    try:
        from numba.core.typeinfer import register_dispatcher
    except ImportError:
        return _njit(signature, **opts)(fn)
    with register_dispatcher(dispatcher):
        dispatcher.compile(signature)
    dispatcher.disable_compile()
    return dispatcher


@contextlib.contextmanager
def loading_beside():
    """numba loads on a thread of its own while the block runs, once per
    process. A bake reads its source in the block: the import (Python, holding
    the interpreter) then overlaps the image decode (which releases it), about
    0.15 s of a 2048x2048 PNG bake. A kernel called meanwhile waits for the
    load (if it failed, that call loads again and raises). The thread is done
    when the block is left, also when the block raised, so that a caller which
    forks next does not copy a half-made import."""
    global _preloader
    with _preload_started:
        if _njit is None and _preloader is None:
            _preloader = threading.Thread(target=_load_quietly, name="texcook-load-numba")
            _preloader.start()
        loader = _preloader
    try:
        yield
    finally:
        if loader is not None:
            loader.join()


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
        _njit = _import_njit()
    pending, _pending[:] = list(_pending), []
    places = _places()
    for stand_in in pending:
        if stand_in._opts is _EXTENSION:
            stand_in._made = stand_in._fn()
        elif stand_in._signature is None:
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


_EXTENSION = {}  # the options of a stand-in for an extension, not a kernel
_defined = []  # the Python function of every kernel defined, for first_use()


def extension(factory):
    """A numba extension (an intrinsic) that factory() makes once numba is
    loaded; modules name it at import, before numba is."""
    with _loading:
        if _njit is not None:
            return factory()
        stand_in = _Pending(factory, None, _EXTENSION)
        _pending.append(stand_in)
        return stand_in


@extension
def borrow():
    """borrow(a) in a kernel: a view of array a, or a tuple of views of a
    tuple's arrays (nested tuples too), that is not reference-counted.

    numba counts references to an array atomically: every array passed to a
    function that is not inlined costs two atomic updates, about 40 cycles,
    and more when threads share the array. A kernel that calls helpers with
    many arrays many times per block spends much of its time there. Borrowed
    views skip the counting (and so do views sliced from them); the kernel
    must keep the arrays themselves alive (arguments, or a local still used
    at the end) for as long as the views are used."""
    from numba.core import cgutils, config, types
    from numba.extending import intrinsic

    if config.DISABLE_JIT:
        return lambda a: a

    def view(context, builder, typ, value):
        # in registers only: a view built through the stack (an array
        # structure per array) left LLVM's SROA some 2 s of a kernel whose
        # scratch holds 119 arrays
        if isinstance(typ, types.Array):
            at = context.data_model_manager[typ].get_field_position("meminfo")
            return builder.insert_value(value, cgutils.get_null_value(value.type.elements[at]), at)
        for i, t in enumerate(typ):
            value = builder.insert_value(value, view(context, builder, t, builder.extract_value(value, i)), i)
        return value

    def borrowable(typ):
        if isinstance(typ, types.Array):
            return True
        return isinstance(typ, types.BaseTuple) and all(borrowable(t) for t in typ)

    @intrinsic
    def borrow(typingctx, a):
        if not borrowable(a):
            return None
        return a(a), lambda context, builder, sig, args: view(context, builder, a, args[0])

    return borrow


def _define(fn, signature, opts):
    if opts is not _EXTENSION:
        _defined.append(fn)
    with _loading:
        if _njit is not None:
            return _make(fn, signature, opts)
        stand_in = _Pending(fn, signature, opts)
        _pending.append(stand_in)
        return stand_in


def jit(fn=None, link_late=False, **overrides):
    """`@jit` or `@jit(...)`: numba.njit with the project's options.
    link_late: its large callees linked after its own code is optimised
    (_link_large_callees_optimised)."""
    opts = dict(JIT_OPTIONS, **overrides)

    def define(f):
        if link_late:
            _LINK_LATE.add(f.__qualname__)
        return _define(f, None, opts)

    return define if fn is None else define(fn)


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


# --- first use ---------------------------------------------------------------------------


def _function_cached(fn):
    """cached() for a kernel's Python function, without making its dispatcher
    (making one would load numba's compiler and compile the typed kernels)."""
    global _njit
    with _loading:  # after a loading_beside() thread's import: never two imports of numba at once
        if _njit is None:
            _njit = _import_njit()
    try:
        from numba.core.caching import FunctionCache

        cache = FunctionCache(fn)
        code = cache._index_key(None, _AnyTarget())[2]
        with _cache_lock(cache._cache_file, False):
            return any(key[2] == code for key in cache._cache_file._load_index()), cache._cache_path
    except Exception:  # noqa: BLE001  (numba's internals are not what this expects)
        return None, None


def _cold(modules):
    """(True, cache folder) when kernels are defined in `modules` (module
    names; a package's name covers its modules) and none of them is in the
    disk cache: the code was never compiled with this cache (or this version
    of its source). (False, None) when one is, or nothing can be told. One
    cached kernel answers for all: which kernels a call compiles depends on
    its options."""
    prefixes = tuple(m + "." for m in modules)
    folder = None
    for fn in list(_defined):
        if fn.__module__ in modules or fn.__module__.startswith(prefixes):
            found, folder = _function_cached(fn)
            if found is not False:
                return False, None
    return (True, folder) if folder is not None else (False, None)


def _announcer(folder, what):
    """(speaks, descriptor): whether this process is the one to announce
    compiling `what`, and the descriptor holding its lock (None when there is
    no lock). The others compiling it at the same moment (batch workers on one
    cold cache) find the lock held and stay quiet; it is held until
    first_use()'s block ends."""
    try:
        from .fileio import lock

        os.makedirs(folder, exist_ok=True)  # numba makes it when it saves the first kernel
        fd = lock(os.path.join(folder, f"texcook-first-use-{what}.lock"), wait=False, create=True)
    except (ImportError, OSError):
        return True, None  # no lock to share: this process speaks for itself
    return fd is not None, fd


NOTICE_MODES = ("progress", "line", "off")


def set_first_use_notice(mode):
    """How a first-use compile shows on a terminal, for this process and the
    processes it starts (batch workers): "progress" (the default: a live line
    with the seconds elapsed, texcook._compile_progress), "line" (one line as
    the compile starts: for commands that draw their own progress bar, or
    print JSON) or "off" (--quiet)."""
    if mode not in NOTICE_MODES:
        raise ValueError(f"first-use notice: {mode!r} is not one of {', '.join(NOTICE_MODES)}")
    os.environ["TEXCOOK_FIRST_USE"] = mode


def _notice_mode():
    mode = os.environ.get("TEXCOOK_FIRST_USE", "progress")
    return mode if mode in NOTICE_MODES else "progress"


def _speaks(stream):
    """A notice goes to a terminal only, and only where kernels compile."""
    isatty = getattr(stream, "isatty", None)
    try:
        return (callable(isatty) and bool(isatty()) and os.environ.get("NUMBA_DISABLE_JIT", "0") in ("", "0")
                and _notice_mode() != "off")
    except (OSError, ValueError):  # a closed stream
        return False


def _redrawable(stream):
    """A stream whose descriptor is a terminal, where a line redrawn after
    carriage returns shows as one line (an object that only says isatty, such
    as a progress bar's writer, gets the first line alone)."""
    try:
        return os.isatty(stream.fileno())
    except (AttributeError, OSError, ValueError):
        return False


@contextlib.contextmanager
def first_use(what, modules, seconds, stream=None):
    """While the block runs (the work that compiles `what`, whose kernels live
    in `modules`), a cold kernel cache is announced on `stream` (stderr), and
    only on a terminal: a first run is otherwise silent for `seconds` while
    numba compiles, and logs stay the same from run to run. The announcement
    is a live line with the seconds elapsed against `seconds`, finished when
    the compile is (texcook._compile_progress), or one line in the "line"
    mode (set_first_use_notice). Among processes compiling the same kernels at
    once, only one speaks."""
    stream = sys.stderr if stream is None else stream
    fd = token = None
    try:
        if _speaks(stream):
            cold, folder = _cold(modules)
            if cold:
                speak, fd = _announcer(folder, modules[0])
                if speak:
                    stream.write(f"texcook: compiling {what} for first use (about {seconds:.0f} s; "
                                 "cached afterwards)\n")
                    stream.flush()
                    if _notice_mode() == "progress" and _redrawable(stream):
                        token = _compile_progress.begin(stream, seconds)
    except Exception:  # noqa: BLE001  (a notice must never stop the work)
        pass
    try:
        yield
    finally:
        try:
            if token is not None:
                _compile_progress.end(token)  # also when an exception (Ctrl-C) ends the block
        finally:
            if fd is not None:
                os.close(fd)  # releases the lock


def _encoder_modules(codec):
    """The modules holding the kernels of a codec's own: its module (with every
    module of a package, imported here as some codecs import theirs at the
    first encode), else the modules whose kernels, codecs or names it imports."""
    import importlib
    import pkgutil
    import types

    name = codec.format.codec_module
    module = importlib.import_module(name)
    for info in pkgutil.walk_packages(getattr(module, "__path__", []), name + "."):
        importlib.import_module(info.name)
    if any(fn.__module__ == name or fn.__module__.startswith(name + ".") for fn in list(_defined)):
        return [name]
    package = name.rsplit(".", 1)[0] + "."
    used = {v.__name__ if isinstance(v, types.ModuleType) else v.__module__ for v in vars(module).values()
            if isinstance(v, (types.ModuleType, type)) or type(v) is _Pending or hasattr(v, "py_func")}
    # the package's private modules (shared helpers) are not one encoder's
    return sorted(m for m in used if m.startswith(package) and not m.rsplit(".", 1)[1].startswith("_"))


def encoder_first_use(codec, stream=None):
    """first_use() for a codec's encoder: `with encoder_first_use(codec): encode...`.
    Off a terminal nothing is looked up (no module imported, no cache read)."""
    if not _speaks(sys.stderr if stream is None else stream):
        return contextlib.nullcontext()
    try:
        modules = _encoder_modules(codec)
    except Exception:  # noqa: BLE001  (a notice must never stop the work; the encode reports it)
        modules = []
    # each codec declares its figure (Codec.compile_seconds: cold minus warm bake
    # of a 256x256 PNG, docs/performance.md)
    return first_use(f"the {codec.name} encoder", modules, codec.compile_seconds, stream)
