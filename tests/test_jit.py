"""Kernels load numba only when one first runs: checking recipes, listing
formats and skipping up-to-date files never pay for it, and the first call
(from any thread) makes every kernel a dispatcher in place."""

import subprocess
import sys
import textwrap
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
        from texcook.codecs import bc1, bc4, get
        from texcook import colour
        held = [bc4._palette]  # a list keeps the stand-in; module-level names are replaced
        data = get("bc1").encode(np.full((4, 4, 4), 90, np.uint8), "fast")
        from texcook.codecs import bc5_angular
        from numba.core.registry import CPUDispatcher
        print(type(bc1._RUN_PLAIN) is CPUDispatcher, type(bc4._palette) is CPUDispatcher,
              bc5_angular._palette is bc4._palette, held[0]._made is bc4._palette,
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


def test_cached_kernels_load_without_numba_registries():
    code = """
        import sys
        import numpy as np
        from texcook.codecs import get
        img = np.random.default_rng(5).integers(0, 256, (8, 8, 4), dtype=np.uint8)
        data = get("bc1").encode(img, "fast")
        print(data.hex(), "numba.np.arraymath" in sys.modules, "scipy.linalg" in sys.modules)
    """
    first = run_python(code).split()  # compiles on a cold cache, loads on a warm one
    second = run_python(code).split()
    assert second == [first[0], "False", "False"]


def test_a_compile_after_cached_loads_sees_the_whole_of_numba(tmp_path):
    # a kernel missing from the cache, compiled in a process whose kernels so far came from the cache,
    # then loaded from the cache in the next process
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


def test_preload_loads_numba_beside_the_caller():
    out = run_python("""
        import sys, threading
        import numpy as np
        from texcook import _jit
        from texcook.codecs import get
        bc1 = get("bc1")
        _jit.preload()
        _jit.preload()  # once
        loader = _jit._preloader
        data = bc1.encode(np.full((4, 4, 4), 9, np.uint8), "fast")  # waits for the load if it is under way
        loader.join()
        print(loader.name, len(data), "numba" in sys.modules, threading.active_count())
    """)
    assert out.split() == ["texcook-load-numba", "8", "True", "1"]
