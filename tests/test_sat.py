"""Summed-area tables: exact integer sums, stable float sums, KTX2 storage."""

import numpy as np
import pytest

from reference import box_mean, box_sum, summed_area
from texcook.errors import ContainerError, UsageError
from texcook.sat import SummedAreaTable


def random_rects(rng, w, h, n):
    x0 = rng.integers(0, w, n)
    y0 = rng.integers(0, h, n)
    x1 = np.array([rng.integers(a + 1, w + 1) for a in x0])
    y1 = np.array([rng.integers(a + 1, h + 1) for a in y0])
    return x0, y0, x1, y1


def special_rects(w, h):
    """The whole image, the four corner texels, full rows and columns, thin strips."""
    return [
        (0, 0, w, h),
        (0, 0, 1, 1),
        (w - 1, 0, w, 1),
        (0, h - 1, 1, h),
        (w - 1, h - 1, w, h),
        (0, 0, w, 1),
        (0, h - 1, w, h),
        (0, 0, 1, h),
        (w - 1, 0, w, h),
        (1, 1, w - 1, h - 1),
        (w // 2, 0, w // 2 + 1, h),
    ]


def test_uint8_4096_exact_means(rng):
    img = rng.integers(0, 256, (4096, 4096), dtype=np.uint8)
    sat = SummedAreaTable.build(img)
    assert sat.table.dtype == np.uint32
    rects = special_rects(4096, 4096)
    x0, y0, x1, y1 = random_rects(rng, 4096, 4096, 150)
    rects += list(zip(x0, y0, x1, y1))
    # Small rectangles, where a float table would be at its worst (tiny differences of huge sums).
    sx, sy = rng.integers(0, 4090, 100), rng.integers(0, 4090, 100)
    rects += [(a, b, a + 1 + (a % 5), b + 1 + (b % 3)) for a, b in zip(sx, sy)]
    for rx0, ry0, rx1, ry1 in rects:
        true_sum = int(box_sum(img, rx0, ry0, rx1, ry1))
        assert int(sat.box_sum(rx0, ry0, rx1, ry1)) == true_sum
        assert sat.box_mean(rx0, ry0, rx1, ry1) == box_mean(img, rx0, ry0, rx1, ry1)  # exactly, not approximately


def test_uint8_whole_image_at_the_uint32_edge():
    # 255 * 4096 * 4096 = 4,278,190,080 is just below 2^32: still exact.
    sat = SummedAreaTable.build(np.full((4096, 4096), 255, np.uint8))
    assert int(sat.box_sum(0, 0, 4096, 4096)) == 255 * 4096 * 4096
    assert sat.box_mean(0, 0, 4096, 4096) == 255.0
    assert sat.box_mean(4095, 4095, 4096, 4096) == 255.0


def test_vectorised_queries_and_channels(rng):
    img = rng.integers(0, 256, (33, 47, 4), dtype=np.uint8)
    sat = SummedAreaTable.build(img)
    x0, y0, x1, y1 = random_rects(rng, 47, 33, 64)
    sums = sat.box_sum(x0, y0, x1, y1)
    means = sat.box_mean(x0, y0, x1, y1)
    assert sums.shape == (64, 4) and means.shape == (64, 4)
    for i in range(64):
        np.testing.assert_array_equal(sums[i], box_sum(img, x0[i], y0[i], x1[i], y1[i]))
        np.testing.assert_array_equal(means[i], box_mean(img, x0[i], y0[i], x1[i], y1[i]))


def test_uint16_exact_beyond_32_bits(rng):
    img = rng.integers(60000, 65536, (300, 301, 2), dtype=np.uint16)
    sat = SummedAreaTable.build(img)
    total = img.reshape(-1, 2).astype(np.int64).sum(axis=0)
    assert total.max() > 2**32
    np.testing.assert_array_equal(sat.box_sum(0, 0, 301, 300).astype(np.int64), total)
    x0, y0, x1, y1 = random_rects(rng, 301, 300, 50)
    for i in range(50):
        np.testing.assert_array_equal(sat.box_sum(x0[i], y0[i], x1[i], y1[i]).astype(np.int64),
                                      box_sum(img, x0[i], y0[i], x1[i], y1[i]))


def test_float_means_within_1e_minus_6_of_the_largest_value(rng):
    img = (rng.random((2048, 2048, 2)) * 1e4).astype(np.float32)
    img[:, :, 1] += 5e3  # a channel far from zero: the offset matters
    sat = SummedAreaTable.build(img)
    limit = 1e-6 * float(img.max())
    rects = special_rects(2048, 2048) + list(zip(*random_rects(rng, 2048, 2048, 120)))
    worst = 0.0
    for rx0, ry0, rx1, ry1 in rects:
        ref = box_mean(img, rx0, ry0, rx1, ry1)
        worst = max(worst, float(np.abs(sat.box_mean(rx0, ry0, rx1, ry1) - ref).max()))
    assert worst <= limit


def test_float_extremes_side_by_side():
    img = np.zeros((64, 64), np.float32)
    img[:, :32] = 1e6
    img[:, 32:] = 1e-6
    sat = SummedAreaTable.build(img)
    assert sat.box_mean(40, 3, 41, 4) == pytest.approx(1e-6, abs=1e-6 * 1e6 * 1e-6)
    assert sat.box_mean(0, 0, 32, 64) == pytest.approx(1e6, rel=1e-12)
    assert sat.box_mean(0, 0, 64, 64) == pytest.approx(0.5e6 + 0.5e-6, rel=1e-12)


def test_float_offset_beats_plain_float32(rng):
    # Why the offset and float64: a plain float32 table is far off on small boxes.
    img = (rng.random((1024, 1024)) * 1e4).astype(np.float32)
    plain = np.cumsum(np.cumsum(img, axis=0, dtype=np.float32), axis=1, dtype=np.float32)
    x, y = 1000, 1000
    naive = plain[y, x] - plain[y - 1, x] - plain[y, x - 1] + plain[y - 1, x - 1]
    sat = SummedAreaTable.build(img)
    assert abs(naive - img[y, x]) > 1.0
    assert abs(sat.box_mean(x, y, x + 1, y + 1) - img[y, x]) < 1e-6


def test_bad_inputs_and_queries():
    with pytest.raises(UsageError):
        SummedAreaTable.build(np.array([[np.nan]], np.float32))
    with pytest.raises(UsageError):
        SummedAreaTable.build(np.zeros((4, 4), np.int8))
    with pytest.raises(UsageError):
        SummedAreaTable.build(np.zeros((4, 4, 5), np.uint8))
    sat = SummedAreaTable.build(np.ones((4, 5), np.uint8))
    with pytest.raises(UsageError):
        sat.box_sum(0, 0, 6, 4)
    with pytest.raises(UsageError):
        sat.box_sum(2, 0, 2, 4)
    with pytest.raises(UsageError):
        sat.box_mean(-1, 0, 2, 2)
    assert sat.box_sum(0, 0, 5, 4) == 20 and sat.box_mean(1, 1, 3, 2) == 1.0


# ---------------------------------------------------------------- KTX2


def _round_trip(sat):
    import texcook.container.ktx2 as ktx2
    vk, levels, kv = sat.to_ktx2()
    data = ktx2.write_ktx2(vk, sat.width, sat.height, levels, kv=kv)
    return ktx2.read_ktx2(data, "sat.ktx2"), vk


@pytest.mark.parametrize("channels, vk", [(1, 98), (2, 101), (3, 104), (4, 107)])
def test_ktx2_round_trip_uint8(channels, vk, rng):
    img = rng.integers(0, 256, (37, 29, channels), dtype=np.uint8)
    sat = SummedAreaTable.build(img)
    ktx, got_vk = _round_trip(sat)
    assert got_vk == vk and ktx.vk_format == vk
    back = SummedAreaTable.from_ktx2(ktx)
    np.testing.assert_array_equal(back.table, sat.table)
    x0, y0, x1, y1 = random_rects(rng, 29, 37, 40)
    np.testing.assert_array_equal(back.box_mean(x0, y0, x1, y1), sat.box_mean(x0, y0, x1, y1))


def test_ktx2_round_trip_uint16_is_modular(rng):
    img = rng.integers(0, 65536, (200, 300), dtype=np.uint16)
    sat = SummedAreaTable.build(img)
    ktx, vk = _round_trip(sat)
    back = SummedAreaTable.from_ktx2(ktx)
    assert vk == 98
    # Stored sums are mod 2^32: exact for every rectangle whose sum is below 2^32 ...
    x0, y0, x1, y1 = random_rects(rng, 300, 200, 60)
    for i in range(60):
        true = int(img[y0[i]: y1[i], x0[i]: x1[i]].sum(dtype=np.int64))
        if true < 2**32:
            assert int(back.box_sum(x0[i], y0[i], x1[i], y1[i])) == true
    # ... such as any 256x256 box (at most 65535 * 65536 < 2^32).
    assert int(back.box_sum(10, 10, 266, 200)) == int(img[10:200, 10:266].sum(dtype=np.int64))


def test_ktx2_round_trip_float(rng):
    img = (rng.random((64, 80, 3)) * 100.0).astype(np.float32)
    sat = SummedAreaTable.build(img)
    ktx, vk = _round_trip(sat)
    assert vk == 106
    back = SummedAreaTable.from_ktx2(ktx)
    np.testing.assert_array_equal(back.offset, sat.offset)  # float64 offset survives exactly
    x0, y0, x1, y1 = random_rects(rng, 80, 64, 100)
    # float32 storage of the centred sums: documented error, small against the values.
    err = np.abs(back.box_mean(x0, y0, x1, y1) - sat.box_mean(x0, y0, x1, y1)).max()
    assert err < 1e-3 * 100.0


def test_from_ktx2_rejects_other_textures():
    import texcook.container.ktx2 as ktx2
    data = ktx2.write_ktx2(37, 2, 2, [bytes(16)])
    with pytest.raises(ContainerError):
        SummedAreaTable.from_ktx2(ktx2.read_ktx2(data, "plain.ktx2"))


def test_sat_kernels_match_their_python(rng):
    import texcook.sat as S

    img = rng.integers(0, 256, (5, 7, 2), dtype=np.uint8)
    a = S._sat_int(img, np.empty((5, 7, 2), np.uint32))
    b = S._sat_int.py_func(img, np.empty((5, 7, 2), np.uint32))
    np.testing.assert_array_equal(a, summed_area(img))
    np.testing.assert_array_equal(b, a)
    f = rng.random((4, 6, 3)).astype(np.float32)
    off = np.array([0.5, 0.25, 0.0])
    c = S._sat_float(f, off, np.empty((4, 6, 3)))
    d = S._sat_float.py_func(f, off, np.empty((4, 6, 3)))
    np.testing.assert_allclose(c, summed_area(f.astype(np.float64) - off), atol=1e-12)
    np.testing.assert_array_equal(d, c)
