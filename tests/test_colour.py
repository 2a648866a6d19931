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
