"""YCoCg: the colour transforms (lossy and YCoCg-R) and the bc3-ycocg format."""

import numpy as np
import pytest

from texcook.colour import rgb_to_ycocg, rgb_to_ycocg_r, ycocg_r_to_rgb, ycocg_to_rgb


# --- readable references, written from the formulas -------------------------------

def ref_ycocg(rgb):
    r, g, b = (rgb[..., i].astype(np.float64) for i in range(3))
    return np.stack([r / 4 + g / 2 + b / 4, r / 2 - b / 2, -r / 4 + g / 2 - b / 4], axis=-1)


def ref_ycocg_r(rgb):
    r, g, b = (rgb[..., i].astype(np.int64) for i in range(3))
    co = r - b
    t = b + np.floor_divide(co, 2)  # >> 1 on a negative number rounds down
    cg = g - t
    y = t + np.floor_divide(cg, 2)
    return np.stack([y, co, cg], axis=-1)


def test_ycocg_matches_reference_and_inverts(rng):
    rgb = rng.random((37, 41, 3))
    ours = rgb_to_ycocg(rgb)
    assert ours.dtype == np.float64 and ours.shape == rgb.shape
    np.testing.assert_allclose(ours, ref_ycocg(rgb), atol=1e-15)
    np.testing.assert_allclose(ycocg_to_rgb(ours), rgb, atol=1e-12)
    f32 = rgb.astype(np.float32)
    assert rgb_to_ycocg(f32).dtype == np.float32
    np.testing.assert_allclose(ycocg_to_rgb(rgb_to_ycocg(f32)), f32, atol=1e-6)


def test_ycocg_ranges_at_the_corners():
    corners = np.array([[r, g, b] for r in (0, 1) for g in (0, 1) for b in (0, 1)], np.float64)
    y, co, cg = rgb_to_ycocg(corners).T
    assert y.min() == 0 and y.max() == 1
    assert co.min() == -0.5 and co.max() == 0.5
    assert cg.min() == -0.5 and cg.max() == 0.5
    # grey has no chroma
    grey = rgb_to_ycocg(np.full((5, 3), 0.3))
    np.testing.assert_allclose(grey[:, 1:], 0.0, atol=1e-15)
    np.testing.assert_allclose(grey[:, 0], 0.3)


def test_ycocg_r_matches_reference(rng):
    rgb = rng.integers(0, 256, (1000, 3))
    np.testing.assert_array_equal(rgb_to_ycocg_r(rgb), ref_ycocg_r(rgb))
    # the integer form tracks the lossy one to within rounding (Co and Cg doubled)
    lossy = rgb_to_ycocg(rgb.astype(np.float64))
    r = rgb_to_ycocg_r(rgb)
    assert np.abs(r[:, 0] - lossy[:, 0]).max() <= 1
    np.testing.assert_array_equal(r[:, 1], 2 * lossy[:, 1])
    assert np.abs(r[:, 2] - 2 * lossy[:, 2]).max() <= 1


def test_ycocg_r_round_trips_every_8bit_triple():
    """All 2^24 RGB triples, in chunks of 2^20 to keep memory small."""
    lo = np.arange(1 << 20, dtype=np.int64)
    seen_min = np.full(3, 1 << 30)
    seen_max = np.full(3, -(1 << 30))
    for hi in range(16):
        v = (hi << 20) | lo
        rgb = np.stack([v >> 16, (v >> 8) & 255, v & 255], axis=-1).astype(np.uint8)
        ycocg = rgb_to_ycocg_r(rgb)
        back = ycocg_r_to_rgb(ycocg)
        assert np.array_equal(back, rgb), f"chunk {hi}"
        seen_min = np.minimum(seen_min, ycocg.min(axis=0))
        seen_max = np.maximum(seen_max, ycocg.max(axis=0))
    # Y keeps 8 bits; Co and Cg need the ninth
    assert seen_min.tolist() == [0, -255, -255]
    assert seen_max.tolist() == [255, 255, 255]


def test_ycocg_r_rejects_wrong_shapes():
    with pytest.raises(ValueError):
        rgb_to_ycocg_r(np.zeros((4, 4)))
