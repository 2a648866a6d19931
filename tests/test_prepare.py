"""`texcook prepare`: kernels compiled ahead of time into the disk cache, and
the compile time each codec declares for its first-use notice."""

import os
import subprocess
import sys
import textwrap

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
