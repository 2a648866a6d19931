"""The pipeline's decisions: colour encoding, channel expansion, which steps run."""

import os

import numpy as np
import pytest

from texcook import codecs
from texcook.errors import InputError, UsageError
from texcook.image import Image
from texcook.pipeline import Recipe, bake, build_levels
from texcook.plan import output_srgb


def _img(px, **kw):
    return Image.from_array(px, **kw)


def test_default_encoding_follows_source_and_format():
    ldr = _img(np.zeros((4, 4, 3), np.uint8))
    hdr = _img(np.zeros((4, 4, 3), np.float32))
    assert output_srgb(ldr, Recipe(), codecs.get("rgba8")) is True
    assert output_srgb(hdr, Recipe(), codecs.get("rgba8")) is False
    assert output_srgb(ldr, Recipe.of(normal_map=True), codecs.get("rgba8")) is False
    assert output_srgb(ldr, Recipe.of(format="rgba16f"), codecs.get("rgba16f")) is False
    assert output_srgb(ldr, Recipe.of(srgb=False), codecs.get("rgba8")) is False
    with pytest.raises(UsageError):
        output_srgb(ldr, Recipe.of(srgb=True, normal_map=True), codecs.get("rgba8"))
    with pytest.raises(UsageError):
        output_srgb(ldr, Recipe.of(format="rgba32f", srgb=True), codecs.get("rgba32f"))


def test_srgb_source_round_trips_through_linear_float():
    """Every 8-bit value, sRGB -> linear float32 -> sRGB 8-bit, comes back unchanged."""
    v = np.arange(256, dtype=np.uint8)
    px = np.stack([v, v[::-1], v, v], axis=-1).reshape(16, 16, 4)
    baked = bake(_img(px), Recipe.of(mips=False))
    assert baked.srgb
    back = codecs.get("rgba8").decode(baked.levels[0], 16, 16)
    assert np.array_equal(back, px)


def test_checkerboard_mip_is_gamma_correct():
    """Black/white texels average to linear 0.5, which is sRGB 188, not 128."""
    px = np.zeros((8, 8, 3), np.uint8)
    px[(np.indices((8, 8)).sum(0) % 2) == 1] = 255
    baked = bake(_img(px), Recipe())
    level1 = codecs.get("rgba8").decode(baked.levels[1], 4, 4)
    assert np.all(level1[..., :3] == 188), level1[..., 0]


def test_linear_output_keeps_8bit_values_as_data():
    """A mask baked to a linear format is not run through the sRGB curve."""
    px = np.arange(64, dtype=np.uint8).reshape(8, 8, 1) * 4
    baked = bake(_img(px), Recipe.of(format="r8", srgb=False, mips=False))
    assert np.array_equal(codecs.get("r8").decode(baked.levels[0], 8, 8)[..., 0], px[..., 0])
    (lv,) = build_levels(_img(px), Recipe.of(mips=False))  # planned: r8, sRGB
    assert lv[0, 1, 0] < 4 / 255.0  # decoded to linear light for sRGB output


def test_channel_expansion():
    grey = _img(np.full((2, 2, 1), 0.25, np.float32), colour_space="linear")
    (lv,) = build_levels(grey, Recipe.of(mips=False))
    assert np.allclose(lv[..., :3], 0.25) and np.all(lv[..., 3] == 1)
    ga = _img(np.array([[[0.5, 0.2]]], np.float32), colour_space="linear")
    (lv,) = build_levels(ga, Recipe.of(mips=False))
    assert np.allclose(lv[0, 0], [0.5, 0.5, 0.5, 0.2])


def test_two_channel_normal_map_rebuilds_z():
    xy = np.array([[[0.5, 0.5], [1.0, 0.5]]], np.float32)
    (lv,) = build_levels(_img(xy, alpha="none"), Recipe.of(mips=False, normal_map=True))
    assert np.allclose(lv[0, 0, :3], [0.5, 0.5, 1.0])
    assert np.allclose(lv[0, 1, :3], [1.0, 0.5, 0.5])


def test_alpha_is_linear_in_srgb_output():
    px = np.zeros((4, 4, 4), np.uint8)
    px[..., 3] = 128
    baked = bake(_img(px), Recipe.of(mips=False))
    assert np.all(codecs.get("rgba8").decode(baked.levels[0], 4, 4)[..., 3] == 128)


def test_options_that_need_what_the_source_lacks():
    with pytest.raises(UsageError, match="alpha"):
        build_levels(_img(np.zeros((4, 4, 3), np.uint8)), Recipe.of(alpha_cutoff=0.5))


def test_nan_is_refused_or_zeroed():
    px = np.ones((2, 2, 3), np.float32)
    px[0, 0, 0] = np.nan
    with pytest.raises(InputError, match="NaN"):
        build_levels(_img(px), Recipe())
    levels = build_levels(_img(px), Recipe.of(nan_to_zero=True))
    assert all(np.isfinite(lv).all() for lv in levels)


def test_recipe_validation():
    with pytest.raises(UsageError):
        Recipe.of(mip_filter="gauss")
    with pytest.raises(UsageError):
        Recipe.of(wrap="repeat,spiral")
    assert Recipe.of(wrap="repeat,clamp").mips.wrap == ("repeat", "clamp")
    with pytest.raises(UsageError):
        Recipe.of(preset="ludicrous")
    with pytest.raises(UsageError):
        Recipe.of(zstd=40)
    with pytest.raises(UsageError, match="weights"):
        Recipe.of(format="bc5", weights=(1, 1, 1))
    assert dict(Recipe.of(format="etc1", weights=(0.3, 0.6, 0.1)).codec.options)["weights"] == (0.3, 0.6, 0.1)


# --- the pipeline core: defaults, notes, transforms, outputs ------------------------

import json  # noqa: E402

from texcook.container.ktx2 import read_ktx2  # noqa: E402
from texcook.image import write_image  # noqa: E402
from texcook.pipeline import bake_file, load_texture  # noqa: E402


def _grey(tmp_path, channels, rng):
    p = tmp_path / f"grey{channels}.png"
    write_image(p, rng.integers(0, 256, (9, 14, channels)).astype(np.uint8))
    return p


@pytest.mark.parametrize("channels,flat,fmt,swizzle", [
    (1, {}, "r8", "rrr1"),
    (2, {"srgb": False}, "rg8", "rrrg"),
    (2, {}, "rgba8", None),  # sRGB grey+alpha: R8G8_SRGB would sRGB-encode the alpha
    (3, {}, "rgba8", None),
])
def test_default_format_keeps_the_source_channels(tmp_path, rng, channels, flat, fmt, swizzle):
    src = _grey(tmp_path, channels, rng)
    out = tmp_path / "o.ktx2"
    summary = bake_file(src, out, Recipe.of(**flat))
    assert summary["format"] == fmt
    ktx = read_ktx2(out.read_bytes(), str(out))
    assert ktx.text("KTXswizzle") == swizzle
    # read back through KTXswizzle, the texture is the source exactly
    from texcook.pipeline import compare

    assert compare(src, out, level=0)["psnr"] == float("inf")


def test_float_source_defaults_to_half_float(tmp_path, rng):
    src = tmp_path / "f.exr"
    write_image(src, (rng.random((4, 6, 3)) * 40).astype(np.float32))
    assert bake_file(src, tmp_path / "o.ktx2", Recipe())["format"] == "rgba16f"


def test_notes_say_when_channels_are_dropped(tmp_path, rng):
    rgb = tmp_path / "rgb.png"
    write_image(rgb, rng.integers(0, 256, (8, 8, 3)).astype(np.uint8))
    notes = bake_file(rgb, tmp_path / "a.ktx2", Recipe.of(format="bc4"))["notes"]
    assert notes == ["bc4 keeps only red of an RGB source"]
    cut = tmp_path / "cut.png"
    px = rng.integers(0, 256, (8, 8, 4)).astype(np.uint8)
    write_image(cut, px)
    assert bake_file(cut, tmp_path / "b.ktx2", Recipe.of(format="bc1"))["notes"] == [
        "bc1 has no alpha: the source's alpha is dropped"]
    assert bake_file(cut, tmp_path / "c.ktx2", Recipe.of(format="bc3"))["notes"] == []
    px[..., 3] = 255
    write_image(cut, px)
    assert bake_file(cut, tmp_path / "d.ktx2", Recipe.of(format="bc1"))["notes"] == []
    normal = tmp_path / "n.png"
    write_image(normal, rng.integers(0, 256, (8, 8, 3)).astype(np.uint8))
    assert bake_file(normal, tmp_path / "e.ktx2", Recipe.of(format="bc5", normal_map=True))["notes"] == []


def test_swizzle_is_recorded_and_undone(tmp_path, rng):
    src = tmp_path / "s.png"
    px = rng.integers(0, 256, (6, 10, 4)).astype(np.uint8)
    write_image(src, px)
    out = tmp_path / "s.ktx2"
    bake_file(src, out, Recipe.of(format="rgba8", swizzle="bgra", srgb=False, mips=False))
    ktx = read_ktx2(out.read_bytes(), str(out))
    stored = np.frombuffer(ktx.levels[0], np.uint8).reshape(6, 10, 4)
    assert np.array_equal(stored, px[..., [2, 1, 0, 3]])
    assert json.loads(ktx.text("texcook.transforms")) == [{"map": "bgra", "name": "swizzle"}]
    assert np.array_equal(load_texture(out).levels[0], px)
    # in sRGB the swizzle runs in linear light and still comes back exactly
    bake_file(src, out, Recipe.of(format="rgba8", swizzle="gbra"))
    assert np.array_equal(load_texture(out).levels[0], px)
    # a channel no stored channel keeps reads as 0 (colour) or 1 (alpha)
    bake_file(src, out, Recipe.of(format="rgba8", swizzle="rrr1", srgb=False, mips=False))
    back = load_texture(out).levels[0]
    assert np.array_equal(back[..., 0], px[..., 0])
    assert (back[..., 1:3] == 0).all() and (back[..., 3] == 255).all()


def test_untransformed_files_carry_no_transform_key(tmp_path, rng):
    src = _grey(tmp_path, 3, rng)
    out = tmp_path / "p.ktx2"
    bake_file(src, out, Recipe.of(format="bc1"))
    assert read_ktx2(out.read_bytes(), str(out)).text("texcook.transforms") is None


def test_sat_is_written_with_the_texture_or_not_at_all(tmp_path, rng, monkeypatch):
    from texcook import pipeline
    from texcook.errors import OutputError

    src = _grey(tmp_path, 3, rng)
    out = tmp_path / "t.ktx2"
    with pytest.raises(OutputError, match="directory"):
        bake_file(src, out, Recipe(), sat_path=tmp_path / "missing" / "s.ktx2")
    assert not out.exists()
    with pytest.raises(UsageError, match="over the texture"):
        bake_file(src, out, Recipe(), sat_path=out)
    assert not out.exists()

    def broken(*a):
        raise OSError("disk on fire")

    monkeypatch.setattr(pipeline, "sat_bytes", broken)
    with pytest.raises(OSError):
        bake_file(src, out, Recipe.of(sat=True))
    monkeypatch.undo()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["grey3.png"]
    summary = bake_file(src, out, Recipe.of(sat=True))
    assert summary["sat"] == str(tmp_path / "t.sat.ktx2")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["grey3.png", "t.ktx2", "t.sat.ktx2"]


def test_cut_out_records_its_cutoff_for_viewers(tmp_path, rng):
    from texcook.pipeline import ALPHA_CUTOFF_KEY

    src = tmp_path / "cut.png"
    write_image(src, rng.integers(0, 256, (8, 8, 4)).astype(np.uint8))
    out = tmp_path / "c.ktx2"
    bake_file(src, out, Recipe.of(format="bc3", alpha_cutoff=0.3))
    assert float(read_ktx2(out.read_bytes(), str(out)).text(ALPHA_CUTOFF_KEY)) == 0.3


def test_a_helper_compiles_the_chain_into_a_cold_cache(tmp_path):
    # what a cold bake of an 8-bit source to a block format starts beside its
    # codec's compilation; it is only a helper, so the bake itself must not
    # depend on it: this checks that it runs and fills the cache
    import subprocess
    import sys
    import textwrap

    code = textwrap.dedent("""
        import numpy as np
        from texcook import pipeline, colour
        from texcook._jit import cached
        from texcook.image import read_image
        from texcook.mips.resample import _box2x2_ints
        from texcook.recipe import Recipe

        image = read_image("corpus/rgb/ldr-rgb-01.png")
        plan = pipeline.plan_bake(image, Recipe.of(format="bc1", mips=True))
        before = cached(colour._quantize_rows), cached(_box2x2_ints)
        def helper(plan, threads, stored0=True):
            with pipeline._chain_compiled_beside(image, pipeline.settle(plan, image), threads, stored0) as proc:
                return proc if proc is None else proc.wait(timeout=240)

        none = [helper(plan, 1), helper(pipeline.plan_bake(image, Recipe.of(format="bc1", mips=False)), 2),
                helper(pipeline.plan_bake(image, Recipe.of(format="rgba8", mips=True)), 2),
                helper(plan, 2, stored0=False)]
        code = helper(plan, 2)
        after = cached(colour._quantize_rows), cached(_box2x2_ints)
        again = helper(plan, 2)
        print(*before, none == [None] * 4, code, *after, again)
    """)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    env.pop("TEXCOOK_COMPILE_BESIDE", None)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    proc = subprocess.run([sys.executable, "-c", code], cwd=root, env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["False", "False", "True", "0", "True", "True", "None"]


def test_a_bake_stops_its_helper(tmp_path, rng, monkeypatch):
    # on a cold cache (as `cached` says here), for block formats only, and also
    # when the bake fails
    from texcook import _beside, pipeline

    started = []

    class Helper:
        stopped = False

    def stop(proc):
        if proc is not None:
            proc.stopped = True

    monkeypatch.setattr(_beside, "start", lambda fn, *args: started.append(Helper()) or started[-1])
    monkeypatch.setattr(_beside, "stop", stop)
    monkeypatch.setattr(pipeline, "quantize_kernels_cached", lambda: False)
    src = tmp_path / "a.png"
    write_image(src, (rng.random((40, 36, 3)) * 255).astype(np.uint8))
    for fmt, expect in (("bc1", 1), ("rgba8", 0)):
        started.clear()
        bake_file(src, tmp_path / f"a.{fmt}.ktx2", Recipe.of(format=fmt, mips=True), threads=2)
        assert len(started) == expect and all(h.stopped for h in started)

    def fail(*args, **kwargs):
        raise RuntimeError("encoder failed")

    monkeypatch.setattr(type(codecs.get("bc1")), "_encode", fail)
    started.clear()
    with pytest.raises(RuntimeError):
        bake_file(src, tmp_path / "b.ktx2", Recipe.of(format="bc1", mips=True), threads=2)
    assert len(started) == 1 and started[0].stopped and not (tmp_path / "b.ktx2").exists()


@pytest.mark.skipif(not os.environ.get("TEXCOOK_LONG"), reason="set TEXCOOK_LONG=1 (cold compiles, about a minute)")
def test_concurrent_cold_bakes_share_one_kernel_cache(tmp_path, rng):
    # twelve processes (and their compile helpers) compiling into one empty
    # cache at once, with sources whose kernels differ in type (8 and 16 bits,
    # grey and colour): every file equals the one a warm process bakes
    import subprocess
    import sys

    sources = []
    for name, shape, dtype in (("rgb8", (70, 64, 3), np.uint8), ("rgba16", (64, 50, 4), np.uint16),
                               ("grey16", (40, 33, 1), np.uint16), ("ga8", (32, 32, 2), np.uint8)):
        path = tmp_path / f"{name}.png"
        write_image(path, rng.integers(0, np.iinfo(dtype).max, shape, dtype=dtype))
        sources.append(path)
    jobs = [(src, fmt) for src in sources for fmt in ("bc1", "etc1", "rgba8")]
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    env.pop("TEXCOOK_COMPILE_BESIDE", None)
    bake = ("import sys; from texcook.pipeline import bake_file; from texcook.recipe import Recipe; "
            "bake_file(sys.argv[1], sys.argv[2], Recipe.of(format=sys.argv[3], mip_filter='lanczos', mips=True))")
    procs = [subprocess.Popen([sys.executable, "-c", bake, str(src), str(tmp_path / f"cold-{src.stem}.{fmt}.ktx2"), fmt],
                              env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE) for src, fmt in jobs]
    for proc in procs:
        _, err = proc.communicate(timeout=600)
        assert proc.returncode == 0, err
    for src, fmt in jobs:
        warm = tmp_path / f"warm-{src.stem}.{fmt}.ktx2"
        bake_file(src, warm, Recipe.of(format=fmt, mip_filter="lanczos", mips=True))
        assert (tmp_path / f"cold-{src.stem}.{fmt}.ktx2").read_bytes() == warm.read_bytes(), (src.name, fmt)
