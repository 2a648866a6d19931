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
