"""Kernels load numba only when one first runs: checking recipes, listing
formats and skipping up-to-date files never pay for it, and the first call
(from any thread) makes every kernel a dispatcher in place."""

import os
import re
import subprocess
import sys
import textwrap
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def run_python(code):
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=ROOT, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def test_recipes_and_codec_options_are_checked_without_numba():
    out = run_python("""
        import sys
        from texcook import cli, codecs, formats
        from texcook.recipe import Recipe
        Recipe.of(format="bc1", preset="fast", mips=True, weights=(1, 2, 1))
        Recipe.of(format="astc-6x6", preset="medium", normal_map=True)
        for name in codecs.names():
            codecs.get(name).check_options({})
        print("numba" in sys.modules, "scipy.linalg" in sys.modules)
    """)
    assert out.split() == ["False", "False"]


def test_first_call_makes_every_kernel_a_dispatcher_and_skips_scipy():
    out = run_python("""
        import sys
        import numpy as np
        from texcook.codecs import bc1_kernels, bc4, get
        from texcook import colour
        held = [bc4.palette]  # a list keeps the stand-in; module-level names are replaced
        data = get("bc1").encode(np.full((4, 4, 4), 90, np.uint8), "fast")
        from texcook.codecs import bc5_angular
        from numba.core.registry import CPUDispatcher
        print(type(bc1_kernels._RUN_PLAIN) is CPUDispatcher, type(bc4.palette) is CPUDispatcher,
              bc5_angular.palette is bc4.palette, held[0]._made is bc4.palette,
              type(colour._quantize_rows) is CPUDispatcher, len(data), "scipy.linalg" in sys.modules)
    """)
    assert out.split() == ["True", "True", "True", "True", "True", "8", "False"]


def test_first_calls_from_many_threads_at_once():
    out = run_python("""
        import numpy as np
        from concurrent.futures import ThreadPoolExecutor
        from texcook.codecs import get
        bc1 = get("bc1")
        img = np.random.default_rng(3).integers(0, 256, (8, 8, 4), dtype=np.uint8)
        with ThreadPoolExecutor(8) as pool:
            outs = list(pool.map(lambda _: bc1.encode(img, "fast", threads=1), range(16)))
        print(len(set(outs)), len(outs[0]))
    """)
    assert out.split() == ["1", "32"]


def test_py_func_is_reachable_before_numba_loads():
    out = run_python("""
        import sys
        import importlib
        resample = importlib.import_module("texcook.mips.resample")  # the package re-exports a function of that name
        f = resample._box2x2.py_func
        print(f.__name__, "numba" in sys.modules)
    """)
    assert out.split()[0] == "_box2x2"


# modules numba's compiler set-up imports (its typing and lowering registries)
_COMPILER_ONLY = ("numba.np.arraymath", "numba.np.linalg", "numba.typed.typeddict", "numba.cpython.unicode")


def test_warm_bake_loads_kernels_without_numba_compiler_setup(tmp_path):
    bake = f"""
        import sys
        from texcook import pipeline
        from texcook.recipe import Recipe
        from texcook.codecs import bc1_kernels as bc1
        for fmt in ("bc1", "rgba8"):
            pipeline.bake_file("corpus/rgb/ldr-rgb-01.png", {str(tmp_path)!r} + "/a." + fmt + ".ktx2",
                               Recipe.of(format=fmt, mips=True))
        hits = sum(bc1._RUN_PLAIN.stats.cache_hits.values())
        print(hits, *(name in sys.modules for name in {_COMPILER_ONLY!r} + ("scipy", "yaml")))
    """
    run_python(bake)  # warms the cache if a kernel was edited or never compiled
    out = run_python(bake).split()
    assert int(out[0]) >= 1  # loaded from the cache, not compiled
    assert out[1:] == ["False"] * (len(_COMPILER_ONLY) + 2)


def test_kernel_compiled_after_kernels_loaded_from_cache(tmp_path):
    # a kernel in a fresh module has no cache entry: it compiles, calling a
    # kernel that was loaded from the cache, and needs numba's array maths
    (tmp_path / "fresh_kernels.py").write_text(textwrap.dedent("""
        import numpy as np
        from texcook._jit import jit
        from texcook import colour

        @jit
        def decode_and_reduce(x):
            out = np.empty(x.size, np.float64)
            colour._srgb_to_linear_flat(x, out)
            return np.sum(np.sqrt(out)), out.max()
    """))
    code = f"""
        import sys
        import numpy as np
        sys.path.insert(0, {str(tmp_path)!r})
        from texcook import colour
        x = np.random.default_rng(5).random(1000).astype(np.float32)
        ref = colour.srgb_to_linear(x)
        hits = sum(colour._srgb_to_linear_flat.stats.cache_hits.values())
        before = [name in sys.modules for name in {_COMPILER_ONLY!r}]
        import fresh_kernels
        total, top = fresh_kernels.decode_and_reduce(x)
        misses = sum(fresh_kernels.decode_and_reduce.stats.cache_misses.values())
        exact = np.array_equal(colour.srgb_to_linear(x), ref)
        ref64 = colour.srgb_to_linear(x.astype(np.float64))  # may be another compilation
        ycocg = colour.rgb_to_ycocg(np.full((2, 2, 3), 0.5, np.float32))
        print(hits >= 1, any(before), misses, np.isclose(total, np.sqrt(ref64).sum(), rtol=1e-12),
              top == ref64.max(), exact, np.allclose(ycocg[..., 0], 0.5), "scipy.linalg" in sys.modules)
    """
    run_python(f"import sys; sys.path.insert(0, {str(tmp_path)!r}); from texcook import colour; import numpy as np; "
               "colour.srgb_to_linear(np.zeros(4, np.float32))")  # warm colour's cache
    out = run_python(code).split()
    assert out == ["True", "False", "1", "True", "True", "True", "True", "False"]


def test_kernels_in_a_process_that_compiled_with_numba_already():
    out = run_python("""
        import numpy as np
        import numba

        @numba.njit
        def user_kernel(a):
            return np.sum(a) * 2.0

        x = np.linspace(0.0, 1.0, 9, dtype=np.float32)
        first = user_kernel(x)  # numba's compiler is set up before texcook loads a kernel
        from texcook import colour
        ours = colour.srgb_to_linear(x)
        v = x.astype(np.float64)
        formula = np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4).astype(np.float32)
        print(first == user_kernel(x) == np.sum(x) * 2.0, np.allclose(ours, formula, rtol=1e-6, atol=0))
    """)
    assert out.split() == ["True", "True"]


def test_numba_config_file_is_still_read(tmp_path):
    # PyYAML is hidden from numba's import only when there is no config file to read
    (tmp_path / ".numba_config.yaml").write_text("disable_performance_warnings: 1\n")
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent("""
        import numpy as np
        from texcook import colour
        colour.srgb_to_linear(np.zeros(4, np.float32))
        from numba.core import config
        print(config.DISABLE_PERFORMANCE_WARNINGS)
    """)], cwd=tmp_path, env=dict(os.environ, PYTHONPATH=str(ROOT)), capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["1"]

def test_kernel_loaded_from_cache_in_the_next_process(tmp_path):
    # a kernel missing from the cache, compiled in a process whose kernels so far came from the cache,
    # then loaded from the cache in the next process: its environment imports numba's array maths,
    # which must not probe scipy's BLAS
    (tmp_path / "fresh_kernel.py").write_text(textwrap.dedent("""
        import numpy as np
        from texcook._jit import jit

        @jit
        def norms(a):
            out = np.empty(a.shape[0])
            for i in range(a.shape[0]):
                out[i] = np.sqrt(np.sum(a[i] * a[i]))
            return out
    """))
    warm = """
        import numpy as np
        from texcook.codecs import get
        get("bc1").encode(np.full((4, 4, 4), 7, np.uint8), "fast")
    """
    code = warm + f"""
        import sys
        before = "numba.np.arraymath" in sys.modules
        sys.path.insert(0, {str(tmp_path)!r})
        from fresh_kernel import norms
        a = np.random.default_rng(1).random((5, 3))
        print(before, np.allclose(norms(a), np.linalg.norm(a, axis=1)), "scipy.linalg" in sys.modules)
    """
    run_python(warm)  # compiles texcook's kernels if the cache is cold
    assert run_python(code).split() == ["False", "True", "False"]  # norms compiles
    assert run_python(code).split() == ["False", "True", "False"]  # norms loads from the cache


def test_numba_loads_beside_a_block_and_is_done_when_it_ends():
    out = run_python("""
        import sys, threading
        import numpy as np
        from texcook import _jit
        from texcook.codecs import get
        bc1 = get("bc1")
        try:
            with _jit.loading_beside():
                loader = _jit._preloader
                raise ValueError  # a bake whose source cannot be read
        except ValueError:
            pass
        print(loader.name, loader.is_alive(), "numba" in sys.modules)
        with _jit.loading_beside():  # once per process
            same = _jit._preloader is loader
            data = bc1.encode(np.full((4, 4, 4), 9, np.uint8), "fast")
        print(same, len(data), threading.active_count())
    """)
    assert out.split() == ["texcook-load-numba", "False", "True", "True", "8", "1"]


def test_borrowed_views_share_data(tmp_path):
    """borrow() gives views (of an array, or of every array in nested tuples)
    that write through to the arrays the kernel keeps; with
    NUMBA_DISABLE_JIT it gives its argument back."""
    script = tmp_path / "borrowing.py"
    script.write_text(textwrap.dedent("""
        import numpy as np
        from collections import namedtuple
        from texcook._jit import borrow, jit, jit_inner
        Pair = namedtuple("Pair", "a b")

        @jit_inner
        def bump(a, b, pair):
            a[0] += 1
            b[1, 1] += 2
            pair.b[2] += 3

        @jit
        def kernel(a, b):
            pair = Pair(np.zeros(2), np.zeros(3))
            own = (a, b, pair)
            (a, b, pair) = borrow(own)
            for _ in range(5):
                bump(a, b[:, :], pair)
            return pair.b[2] + len(own)

        a, b = np.zeros(3), np.zeros((2, 2))
        print(kernel(a, b), a[0], b[1, 1])
        """))
    for jit_off in ("0", "1"):
        env = dict(os.environ, NUMBA_DISABLE_JIT=jit_off, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
        proc = subprocess.run([sys.executable, str(script)], cwd=ROOT, capture_output=True, text=True,
                              timeout=300, env=env)
        assert proc.returncode == 0, proc.stderr
        assert proc.stdout.split() == ["18.0", "5.0", "10.0"], jit_off


def test_a_link_late_kernel_links_its_large_callees_after_its_own_optimisation(tmp_path):
    """jit(link_late=True): a callee too large to inline is linked after the
    kernel's own module is optimised, a small one before, as numba does
    (and as it does everything for a kernel without link_late); both
    kernels compute the same."""
    steps = "\n".join(f"    s = s * 0.5 + a[{k} % n] * {k + 1}.25\n    if s > {k}.5:\n        s -= a[{k * 7} % n]"
                       for k in range(60))
    script = tmp_path / "late.py"
    script.write_text(textwrap.dedent("""
        import numpy as np
        from texcook._jit import _LARGE, jit, jit_inner

        @jit_inner
        def small(x):
            return x * 2.0

        @jit_inner
        def large(a):
            n = a.shape[0]
            s = 0.0
        {STEPS}
            return s

        @jit(link_late=True, cache=False)
        def late(a):
            return large(a) + small(a[0])

        @jit(cache=False)
        def plain(a):
            return large(a) + small(a[0])

        a = np.linspace(0.0, 9.0, 7)
        print(late(a) == plain(a))
        for kernel in (late, plain, large):
            kernel = kernel._dispatcher() if hasattr(kernel, "_dispatcher") else kernel
            library = kernel.overloads[kernel.signatures[0]].library
            print(sorted(lib.name for lib in getattr(library, "_texcook_later", ())) or "-")
        fn = next(f for f in library._final_module.functions if not f.is_declaration)
        print(sum(1 for b in fn.blocks for _ in b.instructions) >= _LARGE)
        """).replace("{STEPS}", steps))
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    proc = subprocess.run([sys.executable, str(script)], cwd=ROOT, capture_output=True, text=True, timeout=300,
                          env=env)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["True", "['large']", "-", "-", "True"]


def test_cached_tells_whether_the_disk_cache_holds_a_kernel(tmp_path):
    (tmp_path / "fresh_sum.py").write_text(textwrap.dedent("""
        from texcook._jit import jit

        @jit
        def total(a):
            s = 0.0
            for v in a:
                s += v
            return s
    """))
    code = f"""
        import sys
        import numpy as np
        sys.path.insert(0, {str(tmp_path)!r})
        from texcook._jit import cached
        import fresh_sum
        before = cached(fresh_sum.total)
        fresh_sum.total(np.ones(3))
        print(before, cached(fresh_sum.total))
    """
    assert run_python(code).split() == ["False", "True"]
    assert run_python(code).split() == ["True", "True"]  # the next process finds it


def test_cache_saves_hold_an_exclusive_lock_and_loads_a_shared_one(tmp_path):
    # two processes compiling different signatures of one kernel must not both
    # take the same data file (the index would pair one's key with the other's code)
    import fcntl

    from texcook._jit import _lock_cache_file

    index = tmp_path / "k.nbi"
    seen = []

    def try_lock(mode):
        fd = os.open(str(index) + ".lock", os.O_RDWR)
        try:
            fcntl.flock(fd, mode | fcntl.LOCK_NB)
            return True
        except BlockingIOError:
            return False
        finally:
            os.close(fd)

    class File:
        _index_path = str(index)

        def save(self, key, data):
            seen.append(("save", try_lock(fcntl.LOCK_SH)))

        def load(self, key):
            seen.append(("load", try_lock(fcntl.LOCK_SH), try_lock(fcntl.LOCK_EX)))

    class Cache:
        _cache_file = File()

    cache = Cache()
    _lock_cache_file(cache)
    cache._cache_file.save("k", b"")
    cache._cache_file.load("k")
    assert seen == [("save", False), ("load", True, False)]
    assert try_lock(fcntl.LOCK_EX)  # released after each


# --- the live line of a first-use compile ---------------------------------------------------------

_FRESH_KERNELS = """
from texcook._jit import jit

@jit
def total(a):
    s = 0.0
    for v in a:
        s += v
    return s

@jit
def biggest(a):
    m = a[0]
    for v in a:
        m = max(m, v)
    return m
"""

# a terminal on stderr that keeps what was written, with the moments the
# status line showed something and the threads drawing it
_TERMINAL = """
import os, pty, threading, time
import numpy as np
import fresh_kernels
from texcook import _compile_progress as progress
from texcook._jit import first_use, set_first_use_notice

progress.FIRST_DRAW, progress.INTERVAL, progress.IDLE = 0.05, 0.02, 0.3
from texcook._jit import _defined
for fn in _defined:  # each kernel a module of its own, as two codecs' kernels are
    if fn.__module__ == "fresh_kernels":
        fn.__module__ = "fresh_kernels." + fn.__name__

class Terminal:
    # stderr on a terminal (a pseudo-terminal's descriptor) that keeps what is written
    def __init__(self, tty=True):
        self.text, self.tty, self.drawers = "", tty, set()
        self.leader, self.follower = pty.openpty()
    def isatty(self):
        return self.tty
    def fileno(self):
        return self.follower
    def write(self, s):
        self.text += s
        if s.startswith("\\r") and s.strip():
            self.drawers.add(threading.current_thread().name)
    def flush(self):
        pass
    def screen(self):
        # what the terminal shows: a carriage return writes over its line
        rows = []
        for line in self.text.split("\\n"):
            shown = ""
            for part in line.split("\\r"):
                shown = part + shown[len(part):]
            rows.append(shown.rstrip())
        return rows

def drawing():
    return any(t.name == "texcook-compile-progress" for t in threading.enumerate())
"""


def _terminal_run(tmp_path, code):
    (tmp_path / "fresh_kernels.py").write_text(_FRESH_KERNELS)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=str(tmp_path))
    env.pop("TEXCOOK_FIRST_USE", None)
    proc = subprocess.run([sys.executable, "-c", _TERMINAL + textwrap.dedent(code)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout.splitlines()


def test_a_first_use_compile_shows_its_seconds_on_a_terminal_and_clears_them(tmp_path):
    """On a terminal the one line is followed by a live line of the seconds
    elapsed against those expected, redrawn while the block runs and cleared
    when it ends; nothing off a terminal."""
    out = _terminal_run(tmp_path, """
        term, piped = Terminal(), Terminal(tty=False)
        with first_use("the test kernels", ["fresh_kernels"], 7, term):
            with first_use("the test kernels", ["fresh_kernels"], 7, piped):
                time.sleep(0.2)
                live = term.screen()
                fresh_kernels.total(np.ones(3))
        print(repr(live))
        print(repr(term.screen()), repr(piped.text), drawing(), "\\r" in term.text)
    """)
    live = eval(out[0])
    assert live[0] == "texcook: compiling the test kernels for first use (about 7 s; cached afterwards)"
    assert re.fullmatch(r"  \d+ s of about 7 s [|/\\-]", live[1]), live[1]
    assert out[1] == "['texcook: compiling the test kernels for first use (about 7 s; cached afterwards)', ''] '' " \
                     "False True"


def test_the_live_line_is_cleared_when_numba_is_done_or_the_block_raises(tmp_path):
    """A block that runs on after its kernels compiled (encoding a large
    image) does not keep saying so; Ctrl-C clears the line and stops its
    thread; --json and --quiet's modes draw none, nor does a stream that only
    says it is a terminal."""
    out = _terminal_run(tmp_path, """
        term = Terminal()
        with first_use("the test kernels", ["fresh_kernels.total"], 7, term):
            fresh_kernels.total(np.ones(3))  # compiled: numba is idle from here
            time.sleep(1.0)
            print(repr(term.screen()[-1]), drawing())
        term = Terminal()
        try:
            with first_use("the test kernels", ["fresh_kernels.biggest"], 7, term):  # still cold
                time.sleep(0.2)
                raise KeyboardInterrupt
        except KeyboardInterrupt:
            print(repr(term.screen()[-1]), drawing(), "\\r" in term.text)
        class Claims(Terminal):  # says isatty, with no terminal behind it (a progress bar's writer)
            def fileno(self):
                raise OSError("no descriptor")
        for mode, term in (("claims", Claims()), ("line", Terminal()), ("off", Terminal())):
            if mode != "claims":
                set_first_use_notice(mode)
            with first_use("the test kernels", ["fresh_kernels.biggest"], 7, term):
                time.sleep(0.2)
            print(mode, repr(term.text))
    """)
    assert out[:2] == ["'' False", "'' False True"]
    line = "'texcook: compiling the test kernels for first use (about 7 s; cached afterwards)\\n'"
    assert out[2:] == ["claims " + line, "line " + line, "off ''"]


def test_threads_compiling_at_once_share_one_live_line(tmp_path):
    """Two codecs first used by two threads at once: each is announced once,
    one thread draws one status line for both (the later one's end counted
    from the earlier one's start), and it is cleared when both are done."""
    out = _terminal_run(tmp_path, """
        term = Terminal()
        both = threading.Barrier(2)
        def bake(module, kernel, seconds):
            with first_use(f"the {kernel} kernel", [module], seconds, term):
                both.wait()
                time.sleep(0.2)
                getattr(fresh_kernels, kernel)(np.ones(3))
                both.wait()
        threads = [threading.Thread(target=bake, args=("fresh_kernels.total", "total", 5)),
                   threading.Thread(target=bake, args=("fresh_kernels.biggest", "biggest", 9))]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        print(repr(term.screen()))
        print(sorted(term.drawers), drawing())
        print(repr([row for row in term.text.split("\\r") if "of about" in row][-1]))
    """)
    assert sorted(eval(out[0])) == ["", "texcook: compiling the biggest kernel for first use (about 9 s; cached afterwards)",
                                    "texcook: compiling the total kernel for first use (about 5 s; cached afterwards)"]
    assert out[1] == "['texcook-compile-progress'] False"
    assert out[2].strip("'").split()[3:5] == ["about", "9"]


def test_processes_wanting_one_cold_kernel_at_once_compile_it_once(tmp_path):
    """Two processes call a kernel none of them has in the cache at the same
    moment: one compiles it, the other waits for it and loads what was saved
    (without the lock both would compile it)."""
    (tmp_path / "slow_kernels.py").write_text(_FRESH_KERNELS)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=str(tmp_path))
    go = tmp_path / "go"
    code = textwrap.dedent(f"""
        import os, time
        import numpy as np
        import slow_kernels
        from texcook import _jit
        _jit.cached(slow_kernels.total)  # numba loaded: the processes start compiling together
        open({str(tmp_path)!r} + "/ready-" + str(os.getpid()), "w").close()
        while not os.path.exists({str(go)!r}):
            time.sleep(0.005)
        slow_kernels.total(np.ones(3))
        stats = slow_kernels.total.stats
        print(sum(stats.cache_misses.values()), sum(stats.cache_hits.values()))
    """)
    procs = [subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(2)]
    deadline = time.monotonic() + 120
    while len(list(tmp_path.glob("ready-*"))) < 2 and time.monotonic() < deadline:
        time.sleep(0.01)
    go.touch()
    outs = [p.communicate(timeout=300) for p in procs]
    assert all(p.returncode == 0 for p in procs), [err for _, err in outs]
    assert sorted(out.strip() for out, _ in outs) == ["0 1", "1 0"]
