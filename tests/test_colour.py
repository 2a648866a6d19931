import colour
import numpy as np

from texcook.colour import decode_colour, encode_colour, linear_to_srgb, quantize_unorm8, srgb_to_linear


def test_srgb_to_linear_matches_colour_science():
    x = np.linspace(-0.1, 1.5, 200001)
    ref = colour.models.eotf_sRGB(np.clip(x, 0, None))
    ours = srgb_to_linear(x)
    inside = x >= 0
    assert np.abs(ours[inside] - ref[inside]).max() < 1e-6
    # float32 path too
    assert np.abs(srgb_to_linear(x.astype(np.float32))[inside] - ref[inside]).max() < 1e-6


def test_linear_to_srgb_matches_colour_science():
    x = np.linspace(0.0, 1.0, 200001)
    ref = colour.models.eotf_inverse_sRGB(x)
    assert np.abs(linear_to_srgb(x) - ref).max() < 1e-6
    assert np.abs(linear_to_srgb(x.astype(np.float32)) - ref).max() < 1e-6


def test_every_8bit_value_round_trips_through_linear_float32():
    v = np.arange(256, dtype=np.uint8)
    lin = srgb_to_linear((v / 255.0).astype(np.float32))
    assert lin.dtype == np.float32
    back = quantize_unorm8(linear_to_srgb(lin))
    assert (back == v).all()


def test_piecewise_knee_is_continuous():
    knee = np.array([0.04045 - 1e-9, 0.04045 + 1e-9])
    lin = srgb_to_linear(knee)
    assert abs(lin[1] - lin[0]) < 1e-8


def test_alpha_channel_is_never_converted():
    px = np.full((2, 2, 4), 0.5, np.float32)
    lin = decode_colour(px, True, 3)
    assert np.all(lin[..., 3] == 0.5)
    assert np.allclose(lin[..., :3], colour.models.eotf_sRGB(0.5), atol=1e-6)
    assert np.allclose(encode_colour(lin, True, 3), px, atol=1e-6)
    assert decode_colour(px, False, 3) is px


# --- tables and the pipeline's kernels -------------------------------------------------

import os

import pytest

from texcook.colour import (
    linear_table, quantize, rgba8_from_stored, srgb8_code, srgb8_tables, to_linear_rgba, unit_table,
)

import reference


@pytest.mark.parametrize("bits", [8, 16])
def test_decode_tables_are_the_formula_bit_for_bit(bits):
    top = (1 << bits) - 1
    v = np.arange(top + 1)
    unit = (v / top).astype(np.float32)
    assert np.array_equal(unit_table(bits), unit)
    want = reference.srgb_to_linear(unit).astype(np.float32)
    assert np.array_equal(linear_table(bits).view(np.uint32), want.view(np.uint32))


@pytest.mark.parametrize("channels", [1, 2, 3, 4])
@pytest.mark.parametrize("srgb", [True, False])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_to_linear_rgba_matches_the_formula(channels, srgb, dtype):
    rng = np.random.default_rng(channels * 10 + srgb)
    h, w = 37, 23  # odd sizes, several row chunks
    if dtype == np.float32:
        stored = rng.uniform(-0.2, 1.5, (h, w, channels)).astype(np.float32)
        unit = stored
    else:
        top = np.iinfo(dtype).max
        stored = rng.integers(0, top + 1, (h, w, channels)).astype(dtype)
        stored[0, 0] = 0
        stored[0, 1] = top
        unit = (stored / top).astype(np.float32)
    for alpha in ([None, channels - 1] if channels in (2, 4) else [None]):
        want = reference.sampler_rgba(unit, srgb, alpha)
        for threads in (1, 2, 3):
            got = to_linear_rgba(stored, srgb, alpha, threads=threads)
            assert got.dtype == np.float32 and got.shape == (h, w, 4)
            assert np.array_equal(got.view(np.uint32), want.view(np.uint32))


def _special_floats():
    t, _ = srgb8_tables()
    # every threshold and its float32 neighbours, the knee, 0, 1, out-of-range values
    near = t[1:256].view(np.int32)[:, None] + np.arange(-3, 4)[None, :]
    vals = [near.ravel().astype(np.int32).view(np.float32),
            np.array([0.0, -0.0, 1.0, 0.0031308, 0.04045, 1e-30, -1e-30, -1.0, 2.0, 1e30, np.inf, -np.inf], np.float32),
            np.nextafter(np.float32(1.0), np.float32(0.0), dtype=np.float32)[None],
            (np.arange(256, dtype=np.float64) / 255).astype(np.float32),
            (np.arange(256, dtype=np.float64) / 255 + 0.5 / 255).astype(np.float32),
            linear_table(8)]
    return np.concatenate(vals)


@pytest.mark.parametrize("srgb", [True, False])
def test_quantize_matches_the_formula_and_rounding(srgb):
    rng = np.random.default_rng(7)
    special = _special_floats()
    rand = np.concatenate([rng.uniform(-0.1, 1.1, 200000), rng.uniform(0, 0.01, 50000)]).astype(np.float32)
    x = np.concatenate([special, rand])
    x = np.concatenate([x, np.zeros((-x.size) % 28, np.float32)]).reshape(-1, 7, 4)
    want = quantize_unorm8(encode_colour(x, srgb, 3))
    for threads in (1, 2):
        assert np.array_equal(quantize(x, srgb, threads=threads), want)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_colour_stages_are_the_same_bytes_on_any_thread_count(dtype, many_chunks):
    from texcook._threads import split

    rng = np.random.default_rng(11)
    h, w = 45, 19
    assert len(split(h, 2, 16384)) > 4  # several chunks per thread, whatever the stage asks
    top = 1.0 if dtype == np.float32 else np.iinfo(dtype).max
    for channels in (1, 2, 3, 4):
        if dtype == np.float32:
            stored = rng.uniform(-0.2, 1.5, (h, w, channels)).astype(np.float32)
        else:
            stored = rng.integers(0, top + 1, (h, w, channels)).astype(dtype)
        for srgb in (True, False):
            for alpha in ([None, channels - 1] if channels in (2, 4) else [None]):
                want = to_linear_rgba(stored, srgb, alpha, threads=1)
                for threads in (2, 3):
                    got = to_linear_rgba(stored, srgb, alpha, threads=threads)
                    assert np.array_equal(got.view(np.uint32), want.view(np.uint32))
                codes = quantize(want, srgb, threads=1)
                for threads in (2, 3):
                    assert np.array_equal(quantize(want, srgb, threads=threads), codes)


@pytest.mark.parametrize("channels", [1, 2, 3, 4])
@pytest.mark.parametrize("srgb", [True, False])
@pytest.mark.parametrize("kernel", [False, True])
def test_every_8bit_code_survives_the_table_round_trip(channels, srgb, kernel, many_chunks, monkeypatch):
    # what lets the pipeline store level 0 of an 8-bit source as it is; laid
    # out as RGBA by NumPy for small images and by the kernel for large ones
    import texcook.colour

    monkeypatch.setattr(texcook.colour, "_LAYOUT_KERNEL_TEXELS", 0 if kernel else 1 << 40)
    v = np.arange(256, dtype=np.uint8)
    stored = np.stack([np.roll(v, 37 * k + 5 * y) for y in range(7) for k in range(channels)], axis=-1)
    stored = stored.reshape(256, 7, channels).transpose(1, 0, 2)  # 7 rows, each code in each channel
    for alpha in [None, channels - 1]:
        # the stored values laid out as RGBA where the round trip gives them back;
        # decoded and quantised where it does not (sRGB, with colour landing in alpha)
        want = quantize(to_linear_rgba(stored, srgb, alpha), srgb)
        for threads in (1, 2):
            assert np.array_equal(rgba8_from_stored(stored, srgb, alpha, threads=threads), want)


@pytest.mark.parametrize("channels", [1, 2, 3, 4])
@pytest.mark.parametrize("srgb", [True, False])
def test_16bit_values_are_quantised_without_a_float_image(channels, srgb, many_chunks):
    rng = np.random.default_rng(channels)
    stored = rng.integers(0, 65536, (9, 300, channels)).astype(np.uint16)
    stored[0, 0], stored[0, 1] = 0, 65535  # the ends of the range
    for alpha in [None, channels - 1]:
        want = quantize(to_linear_rgba(stored, srgb, alpha), srgb)
        for threads in (1, 2):
            assert np.array_equal(rgba8_from_stored(stored, srgb, alpha, threads=threads), want)


@pytest.mark.skipif(not os.environ.get("TEXCOOK_EXHAUSTIVE"), reason="set TEXCOOK_EXHAUSTIVE=1 (about a minute)")
def test_srgb8_code_is_monotonic_over_every_float32_in_0_1():
    # the threshold search is exact only if the code never steps down as x grows
    prev = 0
    step = 1 << 24
    for start in range(0, 0x3F800001, step):
        bits = np.arange(start, min(start + step, 0x3F800001), dtype=np.uint32)
        q = srgb8_code(bits.view(np.float32)).astype(np.int16)
        assert q[0] >= prev and np.all(np.diff(q) >= 0)
        prev = q[-1]
