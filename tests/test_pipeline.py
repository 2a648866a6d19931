"""The pipeline's decisions: colour encoding, channel expansion, which steps run."""

import numpy as np
import pytest

from texcook import codecs
from texcook.errors import InputError, UsageError
from texcook.image import Image
from texcook.pipeline import Recipe, bake, build_levels, output_srgb


def _img(px, **kw):
    return Image.from_array(px, **kw)


def test_default_encoding_follows_source_and_format():
    ldr = _img(np.zeros((4, 4, 3), np.uint8))
    hdr = _img(np.zeros((4, 4, 3), np.float32))
    assert output_srgb(ldr, Recipe(), codecs.get("rgba8")) is True
    assert output_srgb(hdr, Recipe(), codecs.get("rgba8")) is False
    assert output_srgb(ldr, Recipe(normal_map=True), codecs.get("rgba8")) is False
    assert output_srgb(ldr, Recipe(format="rgba16f"), codecs.get("rgba16f")) is False
    assert output_srgb(ldr, Recipe(srgb=False), codecs.get("rgba8")) is False
    with pytest.raises(UsageError):
        output_srgb(ldr, Recipe(srgb=True, normal_map=True), codecs.get("rgba8"))
    with pytest.raises(UsageError):
        output_srgb(ldr, Recipe(format="rgba32f", srgb=True), codecs.get("rgba32f"))


def test_srgb_source_round_trips_through_linear_float():
    """Every 8-bit value, sRGB -> linear float32 -> sRGB 8-bit, comes back unchanged."""
    v = np.arange(256, dtype=np.uint8)
    px = np.stack([v, v[::-1], v, v], axis=-1).reshape(16, 16, 4)
    baked = bake(_img(px), Recipe(mips=False))
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
    baked = bake(_img(px), Recipe(format="r8", srgb=False, mips=False))
    assert np.array_equal(codecs.get("r8").decode(baked.levels[0], 8, 8)[..., 0], px[..., 0])
    (lv,) = build_levels(_img(px), Recipe(mips=False), srgb_out=True)
    assert lv[0, 1, 0] < 4 / 255.0  # decoded to linear light for sRGB output


def test_channel_expansion():
    grey = _img(np.full((2, 2, 1), 0.25, np.float32), colour_space="linear")
    (lv,) = build_levels(grey, Recipe(mips=False))
    assert np.allclose(lv[..., :3], 0.25) and np.all(lv[..., 3] == 1)
    ga = _img(np.array([[[0.5, 0.2]]], np.float32), colour_space="linear")
    (lv,) = build_levels(ga, Recipe(mips=False))
    assert np.allclose(lv[0, 0], [0.5, 0.5, 0.5, 0.2])


def test_two_channel_normal_map_rebuilds_z():
    xy = np.array([[[0.5, 0.5], [1.0, 0.5]]], np.float32)
    (lv,) = build_levels(_img(xy, alpha="none"), Recipe(mips=False, normal_map=True))
    assert np.allclose(lv[0, 0, :3], [0.5, 0.5, 1.0])
    assert np.allclose(lv[0, 1, :3], [1.0, 0.5, 0.5])


def test_alpha_is_linear_in_srgb_output():
    px = np.zeros((4, 4, 4), np.uint8)
    px[..., 3] = 128
    baked = bake(_img(px), Recipe(mips=False))
    assert np.all(codecs.get("rgba8").decode(baked.levels[0], 4, 4)[..., 3] == 128)


def test_options_that_need_what_the_source_lacks():
    with pytest.raises(UsageError, match="alpha"):
        build_levels(_img(np.zeros((4, 4, 3), np.uint8)), Recipe(alpha_cutoff=0.5))


def test_nan_is_refused_or_zeroed():
    px = np.ones((2, 2, 3), np.float32)
    px[0, 0, 0] = np.nan
    with pytest.raises(InputError, match="NaN"):
        build_levels(_img(px), Recipe())
    levels = build_levels(_img(px), Recipe(nan_to_zero=True))
    assert all(np.isfinite(lv).all() for lv in levels)


def test_recipe_validation():
    with pytest.raises(UsageError):
        Recipe(mip_filter="gauss")
    with pytest.raises(UsageError):
        Recipe(wrap="repeat,spiral")
    assert Recipe(wrap="repeat,clamp").wrap == ("repeat", "clamp")
    with pytest.raises(UsageError):
        Recipe(preset="ludicrous")
    with pytest.raises(UsageError):
        Recipe(zstd=40)
    with pytest.raises(UsageError, match="weights"):
        Recipe(format="bc5", weights=(1, 1, 1))
    assert Recipe(format="etc1", weights=(0.3, 0.6, 0.1)).weights == (0.3, 0.6, 0.1)
