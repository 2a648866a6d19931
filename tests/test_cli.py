"""The command line: round trips through every uncompressed format, and every
kind of bad input (one-line message naming the file, exit code, no output)."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from texcook.container.ktx2 import read_ktx2
from texcook.image import read_image, write_image

from conftest import files_in


@pytest.fixture
def rgba_png(tmp_path, rng):
    p = tmp_path / "src.png"
    write_image(p, rng.integers(0, 256, (13, 21, 4)).astype(np.uint8))
    return p


def test_bake_info_decode_compare(tmp_path, cli_run, corpus):
    src = corpus / "rgb" / "ldr-rgb-01.png"
    out = tmp_path / "out.ktx2"
    code, stdout, _ = cli_run("bake", src, "-o", out, "--no-mips", "--json")
    assert code == 0, stdout
    summary = json.loads(stdout)
    assert summary["vk_format"] == 43 and summary["levels"] == 1
    code, stdout, _ = cli_run("info", out, "--json")
    assert code == 0
    desc = json.loads(stdout)
    assert desc["vkFormat"] == 43 and desc["colour_space"] == "srgb"
    assert desc["key_values"]["KTXwriter"].startswith("texcook")
    png = tmp_path / "back.png"
    assert cli_run("decode", out, "-o", png)[0] == 0
    assert np.array_equal(read_image(png).integer_values()[..., :3], read_image(src).integer_values())
    code, stdout, _ = cli_run("compare", src, out, "--json", "--min-psnr", "99")
    assert code == 0
    assert json.loads(stdout)["psnr"] == "inf"


@pytest.mark.parametrize("zstd", [None, 5])
@pytest.mark.parametrize("fmt,source", [
    ("rgba8", "rgba8"), ("rg8", "ga8"), ("r8", "g8"), ("rgba16f", "half"), ("rgba32f", "float"),
])
def test_uncompressed_formats_round_trip(tmp_path, cli_run, rng, fmt, source, zstd):
    """Level 0 comes back exactly; every level in the file is what the pipeline
    encoded, and the file has the full chain."""
    shape = {"rgba8": (6, 10, 4), "ga8": (6, 10, 2), "g8": (6, 10, 1), "half": (6, 10, 4), "float": (6, 10, 4)}[source]
    if source in ("half", "float"):
        px = (rng.standard_normal(shape) * 50).astype(np.float16 if source == "half" else np.float32)
        src = tmp_path / "src.exr"
    else:
        px = rng.integers(0, 256, shape).astype(np.uint8)
        src = tmp_path / "src.png"
    write_image(src, px)
    out = tmp_path / "out.ktx2"
    args = ["bake", src, "-o", out, "--format", fmt]
    if zstd:
        args += ["--zstd", zstd]
    code, stdout, stderr = cli_run(*args)
    assert code == 0, stderr
    ktx = read_ktx2(out.read_bytes(), str(out))
    assert len(ktx.levels) == 4 and (ktx.width, ktx.height) == (10, 6)
    assert ktx.supercompression == (2 if zstd else 0)
    code, stdout, _ = cli_run("compare", src, out, "--level", 0, "--json")
    assert code == 0 and json.loads(stdout)["psnr"] == "inf", stdout
    code, stdout, _ = cli_run("info", out, "--json")
    assert code == 0 and json.loads(stdout)["levels"] == 4


def test_compare_gate_fails_below_threshold(tmp_path, cli_run, corpus):
    src = corpus / "rgb" / "ldr-rgb-02.png"
    noisy = tmp_path / "noisy.png"
    px = read_image(src).integer_values().astype(int)
    px[::2, ::2] ^= 8
    write_image(noisy, px.astype(np.uint8))
    code, stdout, stderr = cli_run("compare", src, noisy, "--min-psnr", "40", "--json")
    result = json.loads(stdout)
    assert code == 1 and not result["passed"] and result["psnr"] < 40
    assert "below --min-psnr" in stderr
    assert cli_run("compare", src, noisy, "--min-psnr", "20")[0] == 0


def test_decode_all_levels(tmp_path, cli_run, rgba_png):
    out = tmp_path / "t.ktx2"
    assert cli_run("bake", rgba_png, "-o", out)[0] == 0
    code, stdout, _ = cli_run("decode", out, "-o", tmp_path / "d.png", "--all-levels")
    assert code == 0
    sizes = [read_image(tmp_path / f"d_mip{i}.png").pixels.shape[:2] for i in range(5)]
    assert sizes == [(13, 21), (6, 10), (3, 5), (1, 2), (1, 1)]


# --- bad input ---------------------------------------------------------------------


def _assert_failed(result, code, *needles, outdir=None, before=None):
    exit_code, stdout, stderr = result
    assert exit_code == code, (stdout, stderr)
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1, stderr
    for n in needles:
        assert str(n) in lines[0], lines[0]
    assert "Traceback" not in stderr
    if outdir is not None:
        assert files_in(outdir) == before, "output or temporary file left behind"


def test_missing_source(tmp_path, cli_run):
    out = tmp_path / "out"
    out.mkdir()
    r = cli_run("bake", tmp_path / "nope.png", "-o", out / "x.ktx2")
    _assert_failed(r, 1, "nope.png", "no such file", outdir=out, before=[])


def test_source_not_an_image(tmp_path, cli_run):
    src = tmp_path / "readme.png"
    src.write_text("hello")
    out = tmp_path / "out"
    out.mkdir()
    r = cli_run("bake", src, "-o", out / "x.ktx2")
    _assert_failed(r, 1, "readme.png", "not an image", outdir=out, before=[])


def test_truncated_png(tmp_path, cli_run, corpus):
    src = tmp_path / "cut.png"
    src.write_bytes((corpus / "rgb" / "ldr-rgb-03.png").read_bytes()[:5000])
    out = tmp_path / "out"
    out.mkdir()
    r = cli_run("bake", src, "-o", out / "x.ktx2")
    _assert_failed(r, 1, "cut.png", "truncated", outdir=out, before=[])


def test_unsupported_channel_count(tmp_path, cli_run):
    import OpenImageIO as oiio

    src = tmp_path / "six.tif"
    o = oiio.ImageOutput.create(str(src))
    o.open(str(src), oiio.ImageSpec(4, 4, 6, "uint8"))
    o.write_image(np.zeros((4, 4, 6), np.uint8))
    o.close()
    out = tmp_path / "out"
    out.mkdir()
    r = cli_run("bake", src, "-o", out / "x.ktx2")
    _assert_failed(r, 1, "six.tif", "channel count 6", outdir=out, before=[])


@pytest.mark.parametrize("damage", ["truncate", "identifier", "levels"])
def test_corrupt_ktx2(tmp_path, cli_run, rgba_png, damage):
    good = tmp_path / "good.ktx2"
    assert cli_run("bake", rgba_png, "-o", good)[0] == 0
    data = bytearray(good.read_bytes())
    if damage == "truncate":
        data = data[: len(data) - 7]
    elif damage == "identifier":
        data[1] = ord("X")
    else:
        data[40] = 30  # levelCount far beyond what 21x13 allows
    bad = tmp_path / "bad.ktx2"
    bad.write_bytes(bytes(data))
    for cmd in (["info", bad], ["decode", bad, "-o", tmp_path / "o" / "x.png"], ["compare", bad, good]):
        (tmp_path / "o").mkdir(exist_ok=True)
        _assert_failed(cli_run(*cmd), 1, "bad.ktx2", outdir=tmp_path / "o", before=[])


def test_unwritable_output(tmp_path, cli_run, rgba_png):
    r = cli_run("bake", rgba_png, "-o", tmp_path / "no" / "such" / "dir" / "x.ktx2")
    _assert_failed(r, 1, "x.ktx2", "directory")
    blocker = tmp_path / "file"
    blocker.write_text("")
    r = cli_run("bake", rgba_png, "-o", blocker / "x.ktx2")
    _assert_failed(r, 1, "x.ktx2")
    assert not (tmp_path / "no").exists()


def test_existing_output_survives_a_failed_bake(tmp_path, cli_run, rgba_png):
    out = tmp_path / "x.ktx2"
    out.write_bytes(b"previous")
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"\x89PNG\r\n\x1a\n" + b"\0" * 40)
    _assert_failed(cli_run("bake", bad, "-o", out), 1, "bad.png")
    assert out.read_bytes() == b"previous"
    assert files_in(tmp_path) == ["bad.png", "src.png", "x.ktx2"]


def test_usage_errors_exit_2(tmp_path, cli_run, rgba_png):
    out = tmp_path / "x.ktx2"
    assert cli_run("bake", rgba_png, "-o", out, "--format", "nope")[0] == 2
    assert cli_run("bake", rgba_png, "-o", out, "--wrap", "sideways")[0] == 2
    assert cli_run("bake", rgba_png, "-o", out, "--format", "rgba16f", "--srgb")[0] == 2
    assert cli_run("bake", rgba_png, "-o", tmp_path / "x.png")[0] == 2
    assert cli_run("bake", rgba_png, "-o", out, "--alpha-cutoff", "2")[0] == 2
    assert not out.exists()


def test_nan_in_float_source(tmp_path, cli_run):
    px = np.ones((4, 4, 3), np.float32)
    px[1, 2, 0] = np.nan
    px[3, 3, 1] = np.inf
    src = tmp_path / "nan.exr"
    write_image(src, px)
    out = tmp_path / "x.ktx2"
    _assert_failed(cli_run("bake", src, "-o", out, "--format", "rgba32f"), 1, "nan.exr", "NaN", "--nan-to-zero")
    assert not out.exists()
    assert cli_run("bake", src, "-o", out, "--format", "rgba32f", "--nan-to-zero", "--no-mips")[0] == 0
    level = read_ktx2(out.read_bytes()).levels[0]
    vals = np.frombuffer(level, np.float32).reshape(4, 4, 4)
    assert np.isfinite(vals).all() and vals[1, 2, 0] == 0 and vals[0, 0, 0] == 1


def test_debug_shows_traceback(tmp_path):
    r = subprocess.run([sys.executable, "-m", "texcook.cli", "--debug", "info", str(tmp_path / "none.ktx2")],
                       capture_output=True, text=True)
    assert r.returncode != 0 and "Traceback" in r.stderr


def test_console_script_runs(tmp_path, rgba_png):
    """The installed entry point, as a build script calls it."""
    out = tmp_path / "x.ktx2"
    r = subprocess.run(["texcook", "bake", str(rgba_png), "-o", str(out), "--no-mips"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    r = subprocess.run(["texcook", "info", str(tmp_path / "none.ktx2")], capture_output=True, text=True)
    assert r.returncode == 1 and r.stderr.count("\n") == 1 and "none.ktx2" in r.stderr


def test_closed_stdout_ends_quietly(tmp_path, rgba_png):
    """`texcook info x.ktx2 | head -1` must not print an internal error."""
    out = tmp_path / "x.ktx2"
    assert subprocess.run(["texcook", "bake", str(rgba_png), "-o", str(out)]).returncode == 0
    p = subprocess.Popen(["texcook", "info", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()
    err = p.stderr.read()
    p.wait()
    assert err == b"" and p.returncode == 141


def test_mip_and_sat_options_reach_the_library(tmp_path, cli_run, corpus):
    """The bake flags drive the chain: coverage is kept with --alpha-cutoff, the
    summed-area table written with --sat answers box means of the source."""
    from texcook.container.ktx2 import read_ktx2
    from texcook.sat import SummedAreaTable

    src = corpus / "rgba" / "ldr-rgba-01.png"
    out, sat = tmp_path / "cut.ktx2", tmp_path / "sat.ktx2"
    code, _, err = cli_run("bake", src, "-o", out, "--mip-filter", "kaiser", "--wrap", "repeat,clamp",
                           "--alpha-cutoff", "0.5", "--premultiply", "--sat", sat)
    assert code == 0, err
    alpha0 = read_image(src).integer_values()[..., 3]
    want = np.mean(alpha0 > 127)
    cut = tmp_path / "cut.png"
    assert cli_run("decode", out, "-o", cut, "--all-levels")[0] == 0
    for i in range(1, 6):  # down to 8x8
        a = read_image(tmp_path / f"cut_mip{i}.png").integer_values()[..., 3]
        assert abs(np.mean(a > 127) - want) <= 0.02, i
    table = SummedAreaTable.from_ktx2(read_ktx2(sat.read_bytes()))
    px = read_image(src).integer_values().astype(np.float64)
    assert np.array_equal(table.box_mean(3, 5, 40, 77), px[5:77, 3:40].mean(axis=(0, 1)))
    # a normal map keeps unit-length vectors down the chain
    nrm = tmp_path / "n.ktx2"
    assert cli_run("bake", corpus / "normal" / "ldr-xy-01.png", "-o", nrm, "--normal-map", "--format", "rgba8")[0] == 0
    lv = np.frombuffer(read_ktx2(nrm.read_bytes()).levels[2], np.uint8).reshape(64, 64, 4) / 255.0 * 2 - 1
    length = np.linalg.norm(lv[..., :3], axis=-1)
    assert np.all(np.abs(length - 1) < 0.02)


def test_float_texture_decodes_to_exr_exactly(tmp_path, cli_run, rng):
    px = (rng.standard_normal((9, 6, 4)) * 1e3).astype(np.float32)
    src, out, exr = tmp_path / "f.exr", tmp_path / "f.ktx2", tmp_path / "back.exr"
    write_image(src, px)
    assert cli_run("bake", src, "-o", out, "--format", "rgba32f")[0] == 0
    assert cli_run("decode", out, "-o", exr)[0] == 0
    assert np.array_equal(read_image(exr).pixels, px)
    # two textures compare level by level
    again = tmp_path / "g.ktx2"
    assert cli_run("bake", src, "-o", again, "--format", "rgba32f", "--zstd", "3")[0] == 0
    code, stdout, _ = cli_run("compare", out, again, "--json")
    result = json.loads(stdout)
    assert code == 0 and len(result["levels"]) == 4 and result["psnr"] == "inf"


# --- recipes and checks before any pixel is read -------------------------------------


@pytest.mark.parametrize("args,needle", [
    (["--format", "bc4", "--weights", "1,1,1"], "bc4 has no option weights"),
    (["--format", "bc5", "--srgb"], "no sRGB variant"),
    (["--format", "etc1", "-o", "x.dds"], "cannot be written to DDS"),
    (["--format", "bc1", "--zstd", "3", "-o", "x.dds"], "zstd"),
    (["--format", "bc1", "--weights", "1,2"], "weights"),
    (["--swizzle", "xyzw"], "swizzle"),
    (["-o", "x.png"], ".ktx2, .dds or .astc"),
    (["-o", "x.astc"], "holds ASTC blocks"),
    (["--sat", "s.png"], "summed-area table"),
])
def test_refused_before_the_image_is_read(tmp_path, cli_run, args, needle):
    """The source does not exist: a refusal naming the option proves nothing was read."""
    if "-o" not in args:
        args = args + ["-o", "x.ktx2"]
    args = [a if not a.startswith("x.") and a != "s.png" else tmp_path / a for a in args]
    code, stdout, stderr = cli_run("bake", tmp_path / "missing.png", *args)
    assert code == 2, stderr
    assert needle in stderr and stderr.count("\n") == 1 and "missing.png" not in stderr
    assert files_in(tmp_path) == []


def _options(command):
    return {p.name: p for p in command.params}


@pytest.mark.parametrize("command,names", [
    ("bake", None),  # every setting with a flag
    ("batch", ("format", "preset")),
    ("scene", ("preset",)),
])
def test_recipe_settings_are_options_made_from_their_declaration(command, names):
    """Each option of a recipe setting has the flags, help and default its one
    declaration gives; the option's own default is None, so a setting not given
    keeps the recipe's value (the default recipe's, or a loaded one's)."""
    from texcook import cli
    from texcook.recipe import SETTINGS

    options = _options(getattr(cli, command))
    settings = [s for s in SETTINGS.values() if s.flags] if names is None else [SETTINGS[n] for n in names]
    assert settings
    for s in settings:
        opt = options[s.name]
        assert tuple(opt.opts + opt.secondary_opts) == tuple(f for flag in s.flags for f in flag.split("/")), s.name
        assert opt.help.startswith(s.help) and opt.default is None, s.name
        if s.default not in (None, False, True):
            shown = s.shown or s.default
            assert f"[default: {shown}" in opt.help, s.name
        if s.choices:
            assert opt.type.get_metavar(opt, None) == f"[{'|'.join(s.choices)}]"
    if names is None:  # bake: every recipe field has an option, or says why not (--sat FILE names the path)
        flagless = {s.name for s in SETTINGS.values() if not s.flags}
        assert flagless == {"sat"} and "sat_path" in options


def test_bake_without_flags_bakes_the_default_recipe(tmp_path, monkeypatch, cli_run, rgba_png):
    from texcook import pipeline
    from texcook.recipe import Recipe

    seen = []
    monkeypatch.setattr(pipeline, "bake_file", lambda src, dst, recipe, **kw: seen.append(recipe) or 1 / 0)
    cli_run("bake", rgba_png, "-o", tmp_path / "o.ktx2")
    cli_run("bake", rgba_png, "-o", tmp_path / "o.ktx2", "--no-mips", "--wrap", "repeat,mirror", "--lanczos-a", "5",
            "--weights", "1,2,1", "-f", "bc1", "--linear", "--dx10")
    assert seen[0] == Recipe()
    assert seen[1] == Recipe.of(mips=False, wrap="repeat,mirror", lanczos_a=5, weights=(1, 2, 1), format="bc1",
                                srgb=False, dds_dx10=True)


@pytest.mark.parametrize("args,named", [
    (["--mip-filter", "gauss"], "--mip-filter"),
    (["--preset", "ludicrous"], "--preset"),
    (["--zstd", "0"], "--zstd"),
    (["--zstd", "three"], "--zstd"),
    (["--lanczos-a", "9"], "--lanczos-a"),  # the mip filter's own limit, known to the recipe
    (["--kaiser-width", "nan"], "--kaiser-width"),
    (["--alpha-cutoff", "half"], "--alpha-cutoff"),
    (["--weights", "1,two,1"], "--weights"),
    (["--colour-space", "cmyk"], "--colour-space"),
    (["--srgb", "--linear"], "--linear"),
    (["--renormalize-clip", "5"], "--renormalize"),
])
def test_a_bad_value_is_refused_once_when_the_recipe_is_made(tmp_path, cli_run, args, named):
    """One line naming the flag, exit 2, before the (missing) source is looked at."""
    code, stdout, stderr = cli_run("bake", tmp_path / "missing.png", "-o", tmp_path / "x.ktx2", *args)
    assert code == 2 and stdout == "", stderr
    assert stderr.startswith("texcook: error: ") and stderr.count("\n") == 1 and named in stderr, stderr
    assert "missing.png" not in stderr and files_in(tmp_path) == []


@pytest.mark.parametrize("command", ["batch", "scene"])
def test_batch_and_scene_refuse_a_bad_preset_the_same_way(tmp_path, cli_run, command):
    code, _, stderr = cli_run(command, tmp_path / "missing.gltf", "-o", tmp_path / "out", "--preset", "ludicrous")
    assert code == 2 and stderr.count("\n") == 1, stderr
    assert stderr.startswith("texcook: error: codec.preset (--preset) must be one of fastest, fast, medium")
    assert files_in(tmp_path) == []


def test_recipe_saved_and_loaded(tmp_path, cli_run, rgba_png):
    a, b, c = tmp_path / "a.ktx2", tmp_path / "b.ktx2", tmp_path / "c.ktx2"
    saved = tmp_path / "r.json"
    code, _, stderr = cli_run("bake", rgba_png, "-o", a, "--format", "bc3", "--preset", "fast",
                              "--mip-filter", "kaiser", "--wrap", "repeat", "--save-recipe", saved)
    assert code == 0, stderr
    recipe = json.loads(saved.read_text())
    assert recipe["codec"] == {"format": "bc3", "preset": "fast"}
    assert cli_run("bake", rgba_png, "-o", b, "--recipe", saved)[0] == 0
    assert a.read_bytes() == b.read_bytes()
    toml = tmp_path / "r.toml"
    toml.write_text('version = 1\n[codec]\nformat = "bc3"\npreset = "fast"\n[mips]\nfilter = "kaiser"\n'
                    'wrap = ["repeat", "repeat"]\n')
    assert cli_run("bake", rgba_png, "-o", c, "--recipe", toml)[0] == 0
    assert c.read_bytes() == a.read_bytes()
    # a flag on the command line overrides the saved recipe
    assert cli_run("bake", rgba_png, "-o", c, "--recipe", toml, "--no-mips")[0] == 0
    assert len(read_ktx2(c.read_bytes(), str(c)).levels) == 1
    bad = tmp_path / "bad.json"
    bad.write_text('{"codec": {"format": "bc1", "speed": 3}}')
    code, _, stderr = cli_run("bake", rgba_png, "-o", c, "--recipe", bad)
    assert code == 2 and "bad.json" in stderr and "codec.speed" in stderr


def test_dropped_channels_are_noted_once(tmp_path, cli_run, rgba_png):
    code, stdout, stderr = cli_run("bake", rgba_png, "-o", tmp_path / "x.ktx2", "--format", "bc1")
    assert code == 0
    assert stderr.count("note:") == 1 and "alpha is dropped" in stderr


def test_formats_has_column_headers(cli_run):
    code, stdout, _ = cli_run("formats")
    head, first = stdout.splitlines()[:2]
    assert code == 0 and head.split() == ["format", "vkFormat", "block", "bits/texel", "channels", "sample", "options"]
    assert first.split()[:6] == ["r8", "vk", "9/15", "1x1", "8", "1"]
    # each value sits under its header
    bc1 = next(line for line in stdout.splitlines() if line.startswith("bc1 "))
    assert bc1[head.index("block"):].startswith("4x4") and bc1[head.index("options"):].startswith("weights")


def test_an_astc_file_summary_does_not_claim_a_colour_space(tmp_path, cli_run, corpus):
    src = corpus / "rgb" / "ldr-rgb-01.png"
    code, stdout, _ = cli_run("bake", src, "-o", tmp_path / "t.astc", "-f", "astc-8x8", "--preset", "fastest")
    assert code == 0 and "colour space not recorded" in stdout and " srgb " not in stdout
    code, stdout, _ = cli_run("bake", src, "-o", tmp_path / "t.astc", "-f", "astc-8x8", "--preset", "fastest",
                              "--json")
    summary = json.loads(stdout)
    assert summary["colour_space_recorded"] is False and summary["colour_space"] == "srgb"  # how values are encoded
    code, stdout, _ = cli_run("bake", src, "-o", tmp_path / "t.ktx2", "-f", "astc-8x8", "--preset", "fastest")
    assert " srgb " in stdout and "not recorded" not in stdout  # a KTX2 file records it


# --- first-use compile notices ------------------------------------------------------------------


class _Terminal:
    """A stand-in for stderr on a terminal."""

    def __init__(self, tty=True):
        self.text, self.tty = "", tty

    def isatty(self):
        return self.tty

    def write(self, s):
        self.text += s

    def flush(self):
        pass


def _run_python(code, env):
    import textwrap

    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                          timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def test_first_use_is_announced_once_on_a_terminal(tmp_path):
    """A kernel module with nothing in a fresh cache is announced (on a
    terminal, never elsewhere), once among processes compiling it at once, and
    not again once compiled."""
    from pathlib import Path

    (tmp_path / "fresh_kernels.py").write_text(
        "from texcook._jit import jit\n\n@jit\ndef total(a):\n    s = 0.0\n    for v in a:\n        s += v\n"
        "    return s\n")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"),
               PYTHONPATH=os.pathsep.join([str(tmp_path), str(Path(__file__).parent)]))
    code = """
        import numpy as np
        import fresh_kernels
        from test_cli import _Terminal
        from texcook._jit import first_use

        term, other, piped = _Terminal(), _Terminal(), _Terminal(tty=False)
        with first_use("the test kernel", ["fresh_kernels"], 7, term):
            with first_use("the test kernel", ["fresh_kernels"], 7, other):  # a second compiler at once
                pass
            with first_use("the test kernel", ["fresh_kernels"], 7, piped):
                pass
            fresh_kernels.total(np.ones(3))
        print(term.text + "|" + other.text + "|" + piped.text)
    """
    first = _run_python(code, env).rstrip("\n").split("|")
    assert first == ["texcook: compiling the test kernel for first use (about 7 s; cached afterwards)\n", "", ""]
    assert _run_python(code, env).rstrip("\n").split("|") == ["", "", ""]  # the cache holds it now


def test_bake_announces_the_encoder_it_is_about_to_use(tmp_path, monkeypatch, rgba_png):
    import contextlib

    from texcook import pipeline
    from texcook.recipe import Recipe

    seen = []

    @contextlib.contextmanager
    def record(codec, stream=None):
        seen.append(codec.name)
        yield

    monkeypatch.setattr(pipeline, "encoder_first_use", record)
    pipeline.bake_file(rgba_png, tmp_path / "o.ktx2", Recipe.of(format="bc3", preset="fastest"))
    assert seen == ["bc3"]


@pytest.mark.skipif(not os.environ.get("TEXCOOK_LONG"), reason="a cold compile (TEXCOOK_LONG=1)")
def test_a_cold_bake_announces_its_encoder(tmp_path, corpus):
    """End to end: bake into an empty kernel cache with stderr on a terminal."""
    import pty

    src = tmp_path / "s.png"
    write_image(src, np.full((8, 8, 3), 90, np.uint8))
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))

    def bake(*extra):
        leader, follower = pty.openpty()
        proc = subprocess.run([sys.executable, "-m", "texcook.cli", "bake", str(src), "-o", str(tmp_path / "o.ktx2"),
                               "-f", "bc4", *extra], stdout=subprocess.PIPE, stderr=follower, env=env, timeout=300)
        os.close(follower)
        err = b""
        try:
            while chunk := os.read(leader, 4096):
                err += chunk
        except OSError:  # the terminal closed
            pass
        os.close(leader)
        assert proc.returncode == 0, err
        return proc.stdout.decode(), err.decode()

    out, err = bake("--json")
    assert "texcook: compiling the bc4 encoder for first use (about" in err and json.loads(out)["format"] == "bc4"
    _, err = bake()
    assert "compiling" not in err
