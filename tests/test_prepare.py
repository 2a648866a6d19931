"""`texcook prepare`: kernels compiled ahead of time into the disk cache, and
the compile time each codec declares for its first-use notice."""

import os
import subprocess
import sys
import textwrap

import pytest

from texcook import codecs


def _python(code, cache):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, env=env,
                          timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


# cold: True when none of a module's kernels is in the cache
COLD = """
    import texcook.codecs.bc4, texcook.mips
    from texcook import _jit
    print(_jit._cold(["texcook.codecs.bc4"])[0], _jit._cold(["texcook.mips"])[0])
"""


def test_prepare_fills_the_cache_for_the_formats_named(tmp_path):
    cache = tmp_path / "cache"
    assert _python(COLD, cache).split() == ["True", "True"]
    proc = subprocess.run([sys.executable, "-m", "texcook.cli", "prepare", "bc4"], capture_output=True, text=True,
                          env=dict(os.environ, NUMBA_CACHE_DIR=str(cache)), timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert sorted(line.split(":")[0] for line in lines) == ["a bake's colour and mip kernels", "bc4 (bc4)", "total"]
    assert all(line.split(": ")[1].endswith(" s)") or line.startswith("total") for line in lines)
    assert _python(COLD, cache).split() == ["False", "False"]  # a first bake now finds them


def test_prepare_refuses_an_unknown_format_before_starting(cli_run):
    code, stdout, stderr = cli_run("prepare", "bc4,bc9")
    assert code == 2 and "bc9" in stderr and not stdout


def test_jobs_are_one_per_codec_module_slowest_first():
    from texcook.prepare import jobs

    found = jobs(["bc1", "astc-4x4", "bc1a", "astc-8x8", "bc4"])
    assert found == {"texcook.codecs.astc": ["astc-4x4", "astc-8x8"], "texcook.codecs.bc1": ["bc1", "bc1a"],
                     "texcook.codecs.bc4": ["bc4"]}
    assert set(jobs(["all"])) == {codecs.get(n).format.codec_module for n in codecs.names()}


def test_a_codec_with_a_beside_job_gets_it_right_after_its_own():
    """prepare's jobs in the order submitted: ASTC's compile_beside follows
    its module's job, so that a second process compiles the search's callees
    meanwhile; a codec without one gets none; the bake's own job last."""
    from texcook.codecs import astc
    from texcook.prepare import BAKE, job_list

    found = job_list(["bc4", "astc-8x8", "astc-4x4"])
    assert [(m.rsplit(".", 1)[-1], names, beside) for m, names, beside in found] == [
        ("astc", ["astc-8x8", "astc-4x4"], None), ("astc", ["astc-8x8", "astc-4x4"], (astc.compile_beside, (8, 8))),
        ("bc4", ["bc4"], None), (BAKE.rsplit(".", 1)[-1], [], None)]


def test_every_codec_declares_its_compile_time():
    """Each codec module states its own figure, not the default of codecs._base."""
    from texcook.codecs import Codec

    for name in codecs.names():
        codec = codecs.get(name)
        declared = [k for k in type(codec).__mro__ if "compile_seconds" in vars(k)]
        assert declared[0] is not Codec, name
        assert 0 < codec.compile_seconds < Codec.compile_seconds * 30, name


def test_the_first_use_notice_names_the_codec_and_its_declared_time(tmp_path):
    """bc7 on an empty cache, stderr a terminal: the notice says the codec and
    the figure BC7's module declares (nothing is compiled here)."""
    out = _python("""
        from texcook import codecs
        from texcook._jit import encoder_first_use

        class Terminal:
            text = ""
            def isatty(self): return True
            def write(self, s): self.text += s
            def flush(self): pass

        term = Terminal()
        with encoder_first_use(codecs.get("bc7"), term):
            pass
        print(term.text, end="")
    """, tmp_path / "cache")
    seconds = codecs.get("bc7").compile_seconds
    assert out == f"texcook: compiling the bc7 encoder for first use (about {seconds:.0f} s; cached afterwards)\n"


# --- ASTC's first use: what the search compiles, and the packing compiled beside it --------------


def test_the_astc_search_imports_neither_the_block_decoder_nor_the_packing(tmp_path):
    """A first encode compiles the kernels of every module it imports (typed
    kernels compile as their module loads): the search measures through the
    endpoint decoding alone, so the block decoder's kernels (about 4 s cold)
    are not compiled, and the packing's are left to the helper."""
    out = _python("""
        import sys
        import texcook.codecs.astc.search
        print(*(f"texcook.codecs.astc.{m}" in sys.modules for m in ("decode", "unpack", "pack", "bise",
                                                                     "endpoint_decode")))
    """, tmp_path / "cache")
    assert out.split() == ["False", "False", "False", "False", "True"]


def test_a_first_astc_encode_compiles_beside_in_a_helper():
    """On a cold search kernel with two threads the first encode starts the
    helper and stops it when the encode is done; later encodes, and
    a first encode on one thread, on a warm cache or on a busy machine, start
    none."""
    code = """
        import numpy as np
        from texcook import _beside, _jit, codecs

        calls = []
        _beside.start = lambda fn, *args: calls.append(("start", fn.__name__)) or "helper"
        _beside.stop = lambda helper: calls.append(("stop", helper))
        _jit.cached = lambda kernel: {CACHED}  # False: nothing of the search in the disk cache
        astc = __import__("texcook.codecs.astc").codecs.astc
        astc.os.getloadavg = lambda: ({LOAD}, 0.0, 0.0)
        astc.os.cpu_count = lambda: 2
        img = np.random.default_rng(1).integers(0, 256, (8, 8, 4), dtype=np.uint8)
        for _ in range(2):
            codecs.get("astc-4x4").encode(img, "fastest", threads={THREADS})
        print(calls)
    """

    def run(cached, threads, load=0.2):  # in the suite's (warm) kernel cache, on an idle 2-core machine
        proc = subprocess.run([sys.executable, "-c", textwrap.dedent(code.format(CACHED=cached, THREADS=threads,
                                                                               LOAD=load))],
                              capture_output=True, text=True, timeout=600, check=False)
        assert proc.returncode == 0, proc.stderr
        return proc.stdout.strip()

    assert run(False, 2) == "[('start', 'compile_beside'), ('stop', 'helper'), ('stop', None)]"
    assert run(False, 1) == "[('stop', None), ('stop', None)]"
    assert run(True, 2) == "[('stop', None), ('stop', None)]"
    assert run(False, 2, load=1.6) == "[('stop', None), ('stop', None)]"  # no core to spare


def test_the_helper_compiles_what_the_encode_loads():
    """compile_beside() compiles what the search's kernel calls for the types
    it calls them with, and the packing kernel for those an encode passes: in
    a warm cache every one is found there (a type that differed would compile
    anew: a miss)."""
    code = """
        import numpy as np
        from texcook import codecs
        from texcook.codecs import astc

        codecs.get("astc-6x6").encode(np.zeros((6, 6, 4), np.uint8), "fastest", threads=1)  # warms the cache
        if {HELPER}:
            from texcook.codecs.astc import pack, search

            astc.compile_beside(6, 6)
            kernels = dict.fromkeys([k for k, _ in search.beside_kernels(6, 6)] + [pack.encode_symbolic_blocks])
            for kernel in kernels:
                print(kernel.py_func.__name__, sum(kernel.stats.cache_hits.values()),
                      sum(kernel.stats.cache_misses.values()), len(kernel.overloads))
    """

    def run(helper):  # in the suite's kernel cache
        proc = subprocess.run([sys.executable, "-c", textwrap.dedent(code.format(HELPER=helper))],
                              capture_output=True, text=True, timeout=600, check=False)
        assert proc.returncode == 0, proc.stderr
        return [line.split() for line in proc.stdout.splitlines()]

    run(False)
    rows = run(True)
    names = [r[0] for r in rows]
    assert {"_encode_mode", "fit_partitions", "rank_partitions", "encode_symbolic_blocks"} <= set(names)
    for name, hits, misses, overloads in rows:
        want = "2" if name == "decimate" else "1"  # decimate: a grid index from a range and from the mode table
        assert (name, hits, misses, overloads) == (name, want, "0", want)


@pytest.mark.skipif(not os.environ.get("TEXCOOK_LONG"), reason="a cold ASTC compile (TEXCOOK_LONG=1)")
def test_a_cold_astc_encode_loads_what_its_helper_compiled(tmp_path):
    out = _python("""
        import numpy as np
        from texcook import _beside
        from texcook.codecs import astc, get

        astc._core_idle = lambda: True  # as on an idle machine: this one may be busy
        start = _beside.start
        def start_and_wait(*args):  # the helper done first, as where it wins the race: no timing in the test
            helper = start(*args)
            helper.wait()
            return helper
        _beside.start = start_and_wait
        get("astc-6x6").encode(np.random.default_rng(2).integers(0, 256, (64, 64, 4), dtype=np.uint8),
                               "medium", threads=2)
        from texcook.codecs.astc import pack, search
        kernels = dict.fromkeys([k for k, _ in search.beside_kernels(6, 6)] + [pack.encode_symbolic_blocks])
        print(len(kernels))
        for kernel in kernels:
            stats = kernel.stats
            print(sum(stats.cache_hits.values()) > 0, sum(stats.cache_misses.values()))
    """, tmp_path / "cache")
    count, *rest = out.split()
    assert int(count) >= 18 and rest == ["True", "0"] * int(count)  # every one loaded from what the helper saved
