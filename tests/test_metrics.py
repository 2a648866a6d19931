import math

import numpy as np
import pytest

from texcook import metrics


def test_psnr_known_value():
    a = np.zeros((4, 4, 3), np.uint8)
    b = a.copy()
    b[0, 0, 0] = 10  # mse = 100 / 48
    assert metrics.psnr(a, b) == pytest.approx(10 * math.log10(255**2 * 48 / 100))
    assert metrics.psnr(a, a) == math.inf
    assert metrics.psnr_per_channel(a, b)[1] == math.inf
    assert metrics.max_error(a, b) == 10


def test_psnr_levels_and_channels():
    a = np.zeros((2, 2, 2))
    b = a.copy()
    b[..., 1] = 1
    assert metrics.psnr(a, b, 255, [0]) == math.inf
    assert metrics.psnr_levels([a, a], [a, b], 255)[0] == math.inf
    with pytest.raises(ValueError):
        metrics.psnr_levels([a], [a, b])


def test_normal_angular_error():
    flat = np.zeros((2, 2, 2), np.uint8) + 128
    assert metrics.normal_angular_error(flat, flat)[0] == pytest.approx(0.0, abs=1e-6)
    tilted = flat.copy()
    tilted[..., 0] = 255  # x = 1 -> 90 degrees from +z
    mean, p99 = metrics.normal_angular_error(flat, tilted)
    assert 85 < mean < 91 and 85 < p99 < 91
