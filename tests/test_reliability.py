"""Every case of "every file in and out handled safely", through the command
line: each reproduces the problem and checks the message (one line, naming the
file), the exit code, the memory bound where one applies, that no output or
temporary is left and that an existing output survives."""

import json
import os
import resource
import signal
import struct
import subprocess
import sys
import time
import zlib

import numpy as np
import pytest

from texcook.container.ktx2 import write_ktx2
from texcook.image import read_image, write_image

from conftest import files_in, interruptible

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def one_line_error(result, code, *needles):
    exit_code, stdout, stderr = result
    assert exit_code == code, (stdout, stderr)
    lines = stderr.splitlines()
    assert len(lines) == 1, stderr
    for n in needles:
        assert str(n) in lines[0], lines[0]
    assert "Traceback" not in stderr and "Warning" not in stderr
    return lines[0]


def run(*args, limit_memory=None, timeout=60, env=None):
    """The real command in a subprocess: what a build script sees, OpenImageIO's
    exit-time output included. limit_memory caps the address space (bytes)."""

    def limit():
        if limit_memory:
            resource.setrlimit(resource.RLIMIT_AS, (limit_memory, limit_memory))

    r = subprocess.run([sys.executable, "-m", "texcook.cli", *map(str, args)], capture_output=True, text=True,
                       timeout=timeout, preexec_fn=limit, cwd=ROOT, env=env)
    return r.returncode, r.stdout, r.stderr


@pytest.fixture
def texture(tmp_path, cli_run, rng):
    src = tmp_path / "src.png"
    write_image(src, rng.integers(0, 256, (12, 20, 4)).astype(np.uint8))
    out = tmp_path / "tex.ktx2"
    assert cli_run("bake", src, "-o", out)[0] == 0
    return out


# ----------------------------------------------------------------------------- decode output


@pytest.mark.parametrize("ext", ["png", "tga", "tif", "jpg"])
def test_decode_on_a_full_disk(tmp_path, cli_run, full_disk, rng, ext):
    """Was: exit 0 with a 0-byte or truncated file (PNG, TGA, TIFF), or exit 1
    with no message and the temporary left (JPEG: libjpeg ends the process, so
    that case runs in a subprocess)."""
    src = tmp_path / "big.png"
    write_image(src, rng.integers(0, 256, (512, 512, 4)).astype(np.uint8))
    tex = tmp_path / "big.ktx2"
    assert cli_run("bake", src, "-o", tex, "--no-mips")[0] == 0
    out = full_disk / f"x.{ext}"
    out.write_bytes(b"previous")
    runner = run if ext == "jpg" else cli_run
    one_line_error(runner("decode", tex, "-o", out), 1, f"x.{ext}", "not")
    assert out.read_bytes() == b"previous" and files_in(full_disk) == [f"x.{ext}"]


def test_decode_to_an_unwritable_type_prints_one_line(tmp_path, texture):
    """Was: OpenImageIO's "pending error message" lines with the temporary path."""
    line = one_line_error(run("decode", texture, "-o", tmp_path / "x.xyz"), 1, "x.xyz", "cannot write this file type")
    assert "texcook-" not in line
    assert files_in(tmp_path) == ["src.png", "tex.ktx2"]


def test_decode_never_writes_through_a_planted_symlink(tmp_path, cli_run, texture):
    """Was: OpenImageIO wrote to a predictable temporary name beside the output,
    so a symlink planted there redirected the write. Now it writes inside a
    fresh private folder (test_fileio checks the exclusive names); and a symlink
    at the output's own name is replaced, not written through."""
    victim = tmp_path / "victim"
    victim.write_bytes(b"precious")
    os.symlink(victim, tmp_path / "out.png")
    code, stdout, stderr = cli_run("decode", texture, "-o", tmp_path / "out.png")
    assert code == 0, stderr
    assert victim.read_bytes() == b"precious"
    assert not os.path.islink(tmp_path / "out.png") and read_image(tmp_path / "out.png").width == 20
    assert files_in(tmp_path) == ["out.png", "src.png", "tex.ktx2", "victim"]


def test_decode_keeps_the_mode(tmp_path, cli_run, texture):
    out = tmp_path / "out.png"
    out.write_bytes(b"x")
    os.chmod(out, 0o640)
    assert cli_run("decode", texture, "-o", out)[0] == 0
    assert os.stat(out).st_mode & 0o777 == 0o640


def test_bake_output_mode_follows_umask(tmp_path, cli_run, texture):
    """Was: 0600 whatever the umask, and 0600 after replacing a 0644 file."""
    src = tmp_path / "src.png"
    old = os.umask(0o022)
    try:
        out = tmp_path / "new.ktx2"
        assert cli_run("bake", src, "-o", out)[0] == 0
        assert os.stat(out).st_mode & 0o777 == 0o644
        os.chmod(texture, 0o664)
        assert cli_run("bake", src, "-o", texture)[0] == 0
        assert os.stat(texture).st_mode & 0o777 == 0o664
    finally:
        os.umask(old)


def test_decode_all_levels_is_all_or_nothing(tmp_path, cli_run, texture, monkeypatch):
    import texcook.image as image

    real = image.seal
    calls = []

    def fail_third(staged, min_size=1):
        calls.append(staged.path)
        if len(calls) == 3:
            raise image.OutputError("cannot write (No space left on device)", staged.path)
        real(staged, min_size)

    monkeypatch.setattr(image, "seal", fail_third)
    before = files_in(tmp_path)
    one_line_error(cli_run("decode", texture, "-o", tmp_path / "d.png", "--all-levels"), 1, "d_mip2.png")
    assert files_in(tmp_path) == before


@pytest.mark.parametrize("cmd", ["decode", "bake"])
@pytest.mark.parametrize("how", ["same name", "hard link"])
def test_output_is_the_input(tmp_path, cli_run, cmd, how):
    """Was: `bake same.dds -o same.dds` and `decode a.png -o a.png` overwrote their input."""
    src = tmp_path / "s.png"
    write_image(src, np.zeros((8, 8, 4), np.uint8))
    dds = tmp_path / "same.dds"
    assert cli_run("bake", src, "-o", dds, "--format", "bc3")[0] == 0
    out = dds
    if how == "hard link":
        out = tmp_path / "other.dds"
        os.link(dds, out)
    before = dds.read_bytes()
    one_line_error(cli_run(cmd, dds, "-o", out), 2, out.name, "the output is")
    assert dds.read_bytes() == before


def test_decode_of_an_image_onto_itself(tmp_path, cli_run):
    a = tmp_path / "a.png"
    write_image(a, np.zeros((4, 4, 3), np.uint8))
    before = a.read_bytes()
    one_line_error(cli_run("decode", a, "-o", a), 2, "a.png", "the output is the input")
    assert a.read_bytes() == before


# ----------------------------------------------------------------------------- memory


def _declared_huge_ktx2(path, side=16384):
    """A few hundred bytes claiming one side x side rgba32f level (4 GiB at
    16384), zstd-supercompressed: the stream itself is a tiny real frame."""
    data = bytearray(write_ktx2(109, 1, 1, [bytes(16)], zstd_level=3))
    struct.pack_into("<II", data, 20, side, side)
    struct.pack_into("<Q", data, 96, side * side * 16)  # uncompressedByteLength of level 0
    path.write_bytes(bytes(data))
    return path


LIMIT = 1536 << 20  # address space for the child: numba and OpenImageIO fit, 4 GiB does not


def test_info_never_decompresses(tmp_path):
    """Was: 8 GB to describe a 131 KB file. Under a 1.5 GiB address-space cap."""
    bomb = _declared_huge_ktx2(tmp_path / "bomb.ktx2")
    code, stdout, stderr = run("info", "--json", bomb, limit_memory=LIMIT)
    assert code == 0, stderr
    desc = json.loads(stdout)
    assert desc["width"] == 16384 and desc["mips"][0]["uncompressed_bytes"] == 16384 * 16384 * 16


def test_decode_of_a_declared_huge_texture_is_refused_before_decompressing(tmp_path):
    bomb = _declared_huge_ktx2(tmp_path / "bomb.ktx2")
    out = tmp_path / "out"
    out.mkdir()
    r = run("--max-memory", "1G", "decode", bomb, "-o", out / "x.exr", limit_memory=LIMIT)
    one_line_error(r, 1, "bomb.ktx2", "16384x16384", "more than the 1.0G memory budget", "--max-memory")
    assert files_in(out) == []
    r = run("--max-memory", "1G", "compare", bomb, bomb, limit_memory=LIMIT)
    one_line_error(r, 1, "bomb.ktx2", "memory budget")


def _png_claiming(path, width, height, payload):
    """A PNG whose IHDR (valid CRC) claims width x height, followed by `payload`
    bytes of IDAT: what a hostile or broken upload looks like."""
    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0)
    idat = np.random.default_rng(3).integers(0, 256, payload, dtype=np.uint8).tobytes()
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", idat) + chunk(b"IEND", b""))
    return path


def test_png_declaring_30000x30000_is_refused_from_its_header(tmp_path):
    """Was: the bake was killed by the OOM killer with no message. A 2.6 MB PNG
    claiming 30000x30000 RGBA needs 14.4 GB as float: refused by the budget
    before a pixel is read, under a 1.5 GiB cap."""
    src = _png_claiming(tmp_path / "huge.png", 30000, 30000, 2_600_000)
    out = tmp_path / "out"
    out.mkdir()
    (out / "x.ktx2").write_bytes(b"previous")
    t0 = time.monotonic()
    r = run("--max-memory", "1G", "bake", src, "-o", out / "x.ktx2", limit_memory=LIMIT)
    one_line_error(r, 1, "huge.png", "30000x30000", "memory budget")
    assert time.monotonic() - t0 < 30
    assert (out / "x.ktx2").read_bytes() == b"previous" and files_in(out) == ["x.ktx2"]


def test_default_budget_refuses_it_too(tmp_path):
    """Without --max-memory the same PNG is refused by the default budget (an
    eighth of the memory) on any machine with less than 115 GB."""
    from texcook.fileio import default_max_memory

    if default_max_memory() > 14_400_000_000:
        pytest.skip("this machine's default budget admits 14.4 GB")
    src = _png_claiming(tmp_path / "huge.png", 30000, 30000, 2_600_000)
    env = {k: v for k, v in os.environ.items() if k != "TEXCOOK_MAX_MEMORY"}
    one_line_error(run("bake", src, "-o", tmp_path / "x.ktx2", limit_memory=LIMIT, env=env), 1, "huge.png", "budget")


def test_memory_error_names_the_file(tmp_path, cli_run, monkeypatch, texture):
    """Was: "internal error: MemoryError" without the file."""
    import texcook.pipeline as pipeline

    def out_of_memory(*a, **k):
        raise MemoryError

    monkeypatch.setattr(pipeline, "load_texture", out_of_memory)
    one_line_error(cli_run("decode", texture, "-o", tmp_path / "x.png"), 1, "tex.ktx2", "out of memory")
    monkeypatch.setattr(pipeline, "read_image", out_of_memory)
    one_line_error(cli_run("bake", tmp_path / "src.png", "-o", tmp_path / "y.ktx2"), 1, "src.png", "out of memory")
    assert "x.png" not in files_in(tmp_path) and "y.ktx2" not in files_in(tmp_path)


@pytest.mark.parametrize("name", ["x.ktx2", "x.png", "x.dds"])
def test_fifo_dev_zero_and_directories_are_refused_at_once(tmp_path, cli_run, name):
    """Was: a FIFO named x.ktx2 or x.png hung info and bake; info /dev/zero read
    without end."""
    fifo = tmp_path / name
    os.mkfifo(fifo)
    t0 = time.monotonic()
    for cmd in (["info", fifo], ["bake", fifo, "-o", tmp_path / "o.ktx2"], ["decode", fifo, "-o", tmp_path / "o.png"],
                ["compare", fifo, fifo]):
        one_line_error(cli_run(*cmd), 1, name, "is a pipe (FIFO), not a regular file")
    one_line_error(cli_run("info", "/dev/zero"), 1, "/dev/zero", "is a device")
    one_line_error(cli_run("bake", tmp_path, "-o", tmp_path / "o.ktx2"), 1, "is a directory")
    assert time.monotonic() - t0 < 20
    assert files_in(tmp_path) == [name]


# ----------------------------------------------------------------------------- float hygiene


def _float_texture(tmp_path, cli_run, values, name="f.ktx2"):
    src = tmp_path / "f.exr"
    write_image(src, values)
    out = tmp_path / name
    code, stdout, stderr = cli_run("bake", src, "-o", out, "--format", "rgba32f", "--no-mips", "--nan-to-zero")
    assert code == 0, stderr
    return out


@pytest.mark.filterwarnings("error::RuntimeWarning")  # any numpy warning fails the test
def test_beyond_half_float_is_refused_or_clamped(tmp_path, cli_run):
    """Was: values beyond 65504 became Inf in rgba16f, with RuntimeWarnings."""
    px = np.ones((4, 6, 4), np.float32)
    px[0, 0, 0] = 1e6
    px[2, 3, 1] = -70000.0
    src = tmp_path / "hot.exr"
    write_image(src, px)
    out = tmp_path / "x.ktx2"
    out.write_bytes(b"previous")
    r = cli_run("bake", src, "-o", out, "--format", "rgba16f", "--no-mips")
    one_line_error(r, 1, "hot.exr", "2 value(s) beyond the rgba16f range", "--clamp")
    assert out.read_bytes() == b"previous" and files_in(tmp_path) == ["hot.exr", "x.ktx2"]
    code, stdout, stderr = cli_run("bake", src, "-o", out, "--format", "rgba16f", "--no-mips", "--clamp", "--json")
    assert code == 0 and stderr == ""
    assert json.loads(stdout)["clamped"] == 2
    code, stdout, stderr = cli_run("bake", src, "-o", out, "--format", "rgba16f", "--clamp")
    assert code == 0 and "clamped" in stdout and stderr == ""
    from texcook.pipeline import load_texture

    level = load_texture(out).levels[0]
    assert np.isfinite(level).all() and level[0, 0, 0] == 65504 and level[2, 3, 1] == -65504


@pytest.mark.filterwarnings("error::RuntimeWarning")  # any numpy warning fails the test
def test_compare_with_nan_and_inf_is_valid_json(tmp_path, cli_run):
    """Was: bare NaN in --json and "math domain error" comparing a file with itself."""
    px = np.full((4, 4, 4), 0.5, np.float32)
    a = _float_texture(tmp_path, cli_run, px, "a.ktx2")
    import texcook.container.ktx2 as ktx2

    def with_values(name, values):
        raw = np.full((4, 4, 4), 0.5, np.float32)
        for (y, x, c), v in values.items():
            raw[y, x, c] = v
        p = tmp_path / name
        p.write_bytes(ktx2.write_ktx2(109, 4, 4, [raw.tobytes()]))
        return p

    nan = with_values("nan.ktx2", {(1, 1, 0): np.nan, (2, 2, 1): np.inf})
    for x, y, want in ((nan, nan, "inf"), (nan, a, "-inf"), (a, nan, "-inf"), (a, a, "inf")):
        code, stdout, stderr = cli_run("compare", x, y, "--json")
        assert code == 0 and "Warning" not in stderr and stderr == "", stderr
        result = json.loads(stdout)  # strict: NaN or Infinity would not parse as they are not JSON
        assert result["psnr"] == want, result
        assert "NaN" not in stdout and "Infinity" not in stdout
    rows = json.loads(cli_run("compare", nan, a, "--json")[1])["levels"]
    assert rows[0]["nonfinite"] == 2 and rows[0]["channels"]["B"] == "inf" and rows[0]["channels"]["R"] == "-inf"
    code, stdout, stderr = cli_run("compare", nan, a, "--min-psnr", "10")
    assert code == 1 and "2 NaN/Inf" in stdout and "-inf dB is below" in stderr and "Warning" not in stderr


@pytest.mark.filterwarnings("error::RuntimeWarning")  # any numpy warning fails the test
def test_decode_nan_texture(tmp_path, cli_run):
    import texcook.container.ktx2 as ktx2

    raw = np.full((2, 3, 4), 0.25, np.float32)
    raw[0, 0, 0] = np.nan
    raw[1, 2, 2] = -np.inf
    tex = tmp_path / "n.ktx2"
    tex.write_bytes(ktx2.write_ktx2(109, 3, 2, [raw.tobytes()]))
    code, stdout, stderr = cli_run("decode", tex, "-o", tmp_path / "n.png")
    assert code == 0 and "Warning" not in stderr
    assert stderr.count("\n") == 1 and "2 NaN or Inf value(s)" in stderr and "n.ktx2" in stderr
    png = read_image(tmp_path / "n.png").integer_values()
    assert png[0, 0, 0] == 0 and png[1, 2, 2] == 0
    code, stdout, stderr = cli_run("decode", tex, "-o", tmp_path / "n.exr")
    assert code == 0 and stderr == ""
    back = read_image(tmp_path / "n.exr").pixels
    assert np.isnan(back[0, 0, 0]) and back[1, 2, 2] == -np.inf


# ----------------------------------------------------------------------------- interrupt


def test_sigint_stops_a_thorough_bake_within_a_second(tmp_path, rng):
    """Was: 30 s to stop a thorough 4096x4096 bake. A 2048x2048 thorough BC1
    bake takes several seconds even on an idle machine; interrupted in the
    middle it stops in under a second, exits 130 and leaves the old output and
    nothing else."""
    warm = tmp_path / "warm.png"
    write_image(warm, rng.integers(0, 256, (8, 8, 4)).astype(np.uint8))
    assert run("bake", warm, "-o", tmp_path / "warm.ktx2", "--format", "bc1", "--preset", "thorough")[0] == 0
    y, x = np.mgrid[0:2048, 0:2048]
    px = np.stack([(x * 7 + y * 3) % 256, (x * y) % 256, (x ^ y) % 256, 255 - x % 256], -1)
    src = tmp_path / "big.png"
    write_image(src, np.clip(px + rng.integers(0, 20, px.shape), 0, 255).astype(np.uint8))
    out = tmp_path / "out"
    out.mkdir()
    (out / "x.ktx2").write_bytes(b"previous")
    p = subprocess.Popen([sys.executable, "-m", "texcook.cli", "bake", str(src), "-o", str(out / "x.ktx2"),
                          "--format", "bc1", "--preset", "thorough"], stderr=subprocess.PIPE, text=True, cwd=ROOT,
                         preexec_fn=interruptible)
    time.sleep(2.5)
    assert p.poll() is None, "the bake ended before it could be interrupted"
    t0 = time.monotonic()
    p.send_signal(signal.SIGINT)
    line = p.stderr.readline()
    said = time.monotonic() - t0
    p.wait(10)
    ended = time.monotonic() - t0
    assert p.returncode == 130 and line == "texcook: interrupted\n" and p.stderr.read() == ""
    assert said < 1.0, f"took {said:.2f} s to stop"
    assert ended < 2.0, f"took {ended:.2f} s to exit"
    assert (out / "x.ktx2").read_bytes() == b"previous" and files_in(out) == ["x.ktx2"]


def test_run_chunked_stops_between_runs():
    """A KeyboardInterrupt raised while runs are under way stops the rest: the
    blocks after the interrupted run are never encoded."""
    from texcook.codecs._base import run_chunked

    done = []

    def kernel(inp, out, _):
        time.sleep(0.002)  # a slow kernel keeps the runs short (sized to about 50 ms)
        done.append(len(inp))
        out[:] = 1
        if len(done) == 3:
            raise KeyboardInterrupt

    for threads in (1, 2):
        done.clear()
        out = np.zeros((100000, 1), np.uint8)
        with pytest.raises(KeyboardInterrupt):
            run_chunked(kernel, np.zeros((100000, 1), np.uint8), out, threads, 0)
        assert sum(done) == out.sum() < 20000 and len(done) <= 3 + threads


# ----------------------------------------------------------------------------- info and messages


def test_info_reads_dds(tmp_path, cli_run):
    """Was: "not a KTX2 file"."""
    src = tmp_path / "s.png"
    write_image(src, np.zeros((8, 12, 4), np.uint8))
    dds = tmp_path / "s.dds"
    assert cli_run("bake", src, "-o", dds, "--format", "bc3")[0] == 0
    code, stdout, _ = cli_run("info", dds, "--json")
    desc = json.loads(stdout)
    assert code == 0 and desc["container"] == "dds" and desc["format"] == "bc3" and desc["levels"] == 4
    assert [m["width"] for m in desc["mips"]] == [12, 6, 3, 1] and desc["colour_space"] == "srgb"
    code, stdout, _ = cli_run("info", dds)
    assert code == 0 and "format: bc3" in stdout
    junk = tmp_path / "junk.dds"
    junk.write_bytes(b"JUNK" * 40)
    one_line_error(cli_run("info", junk), 1, "junk.dds", "not a KTX2, DDS or .astc file")


def test_control_characters_in_names_stay_on_one_line(tmp_path, cli_run):
    """Was: a file name holding a newline split the error line."""
    name = tmp_path / "evil\nname\x1b[31m.png"
    line = one_line_error(cli_run("bake", name, "-o", tmp_path / "x.ktx2"), 1, "evil\\nname\\x1b[31m.png",
                          "no such file")
    assert "\x1b" not in line
    name.write_bytes(b"not an image")
    one_line_error(cli_run("info", name), 1, "evil\\nname")


def test_sizes_differ_names_both_files(tmp_path, cli_run):
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    write_image(a, np.zeros((4, 4, 3), np.uint8))
    write_image(b, np.zeros((8, 4, 3), np.uint8))
    one_line_error(cli_run("compare", a, b), 2, "a.png", "level 0 sizes differ", "b.png")


def test_dds_refusal_names_the_output(tmp_path, cli_run):
    src = tmp_path / "s.png"
    write_image(src, np.zeros((8, 8, 3), np.uint8))
    one_line_error(cli_run("bake", src, "-o", tmp_path / "x.dds", "--format", "etc1", "--preset", "fastest"), 2,
                   "x.dds", "DDS")
    assert files_in(tmp_path) == ["s.png"]


def test_conflicting_and_meaningless_options_are_usage_errors(tmp_path, cli_run, texture):
    """Was: --min-psnr nan exited 1; --srgb --linear was accepted (last wins)."""
    assert cli_run("compare", texture, texture, "--min-psnr", "nan")[0] == 2
    assert cli_run("compare", texture, texture, "--min-psnr", "inf")[0] == 0
    src = tmp_path / "src.png"
    one_line_error(cli_run("bake", src, "-o", tmp_path / "x.ktx2", "--srgb", "--linear"), 2, "--srgb and --linear")
    assert not (tmp_path / "x.ktx2").exists()
    assert cli_run("--max-memory", "lots", "info", texture)[0] == 2


def test_uint32_tiff_is_not_baked_to_black(tmp_path, cli_run):
    """Was: a uint32 TIFF holding 0..255 baked to black without a word."""
    import OpenImageIO as oiio

    src = tmp_path / "wide.tif"
    o = oiio.ImageOutput.create(str(src))
    o.open(str(src), oiio.ImageSpec(4, 4, 3, oiio.UINT32))
    o.write_image(np.full((4, 4, 3), 200, np.uint32))
    o.close()
    one_line_error(cli_run("bake", src, "-o", tmp_path / "x.ktx2"), 1, "wide.tif", "uint",
                   "8-bit, 16-bit or float")
    assert not (tmp_path / "x.ktx2").exists()


def test_numeric_overflow_is_one_note_not_numpy_warnings(tmp_path, cli_run, monkeypatch):
    """A normal map holding 3.4e38 once overflowed when renormalised; it now
    bakes without a word (tests/test_extremes.py). An overflow that still
    happens is one line naming the file instead of numpy's warnings; the bake
    still completes."""
    import texcook.plan as plan

    px = np.ones((9, 13, 4), np.float32)
    px[1, 1] = [3.4e38, -3.4e38, 0, 1]
    src = tmp_path / "wild.exr"
    write_image(src, px)
    bake = ("bake", src, "-o", tmp_path / "n.ktx2", "--format", "bc5", "--normal-map", "--preset", "fastest")
    assert cli_run(*bake)[::2] == (0, "")
    notes = plan.dropped_channels

    def overflowing(*args):
        np.float32(3e38) * np.float32(10)  # a step that overflows, as one might
        return notes(*args)

    monkeypatch.setattr(plan, "dropped_channels", overflowing)
    code, stdout, stderr = cli_run(*bake)
    assert code == 0 and stderr.count("\n") == 1
    assert stderr.startswith("texcook: note: ") and "wild.exr" in stderr and "overflow" in stderr


def test_info_reads_only_the_metadata(tmp_path, cli_run, monkeypatch):
    """`info` of a texture reads its header and metadata, not its levels."""
    import texcook.fileio as fileio

    raw = np.zeros((256, 256, 4), np.float32).tobytes()
    tex = tmp_path / "t.ktx2"
    tex.write_bytes(write_ktx2(109, 256, 256, [raw]))
    asked = []
    real = fileio.read_prefix
    monkeypatch.setattr(fileio, "read_prefix", lambda p, n, what="file": asked.append(n) or real(p, n, what))
    code, stdout, _ = cli_run("info", tex, "--json")
    assert code == 0 and json.loads(stdout)["mips"][0]["uncompressed_bytes"] == len(raw)
    assert asked and all(n is not None and n < 4096 for n in asked), asked
