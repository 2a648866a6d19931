"""Which components the ASTC search gives a weight plane of their own
(presets.py `dual`): 1 the one whose leaving the line fit leaves the others
closest to one line (the most of the block's distance from its line taken
off it), 2 every one that varies, 3 the two best by that rule; a component
whose correlation with another is over the preset's limit gets none."""

import numba
import numpy as np
import pytest

from texcook.codecs.astc.search.fit import dual_channels, texel_moments


@numba.njit
def _planes(x, chw, mode, max_corr, opaque):
    tot = np.zeros(16)
    texel_moments(x, chw, x.shape[0], tot)
    out = np.full(4, -1, np.int64)
    n = dual_channels(tot, opaque, mode, max_corr, out, np.zeros((8, 4)))
    return out[:n].copy()


def _block(rng):
    """36 texels: red its own noise, green and blue one ramp (correlated 1),
    alpha noise of its own, half as strong as red's."""
    t = np.arange(36, dtype=np.float64)
    x = np.empty((36, 4))
    x[:, 0] = 120 + rng.normal(0, 30, 36)
    x[:, 1] = 40 + 4 * t
    x[:, 2] = 200 - 3 * t
    x[:, 3] = 180 + rng.normal(0, 15, 36)
    return x


@pytest.mark.parametrize("opaque", [1, 0])
def test_modes(rng, opaque):
    x = _block(rng)
    if opaque:
        x[:, 3] = 255
    chw = np.ones(4)
    alone = [0] if opaque else [0, 3]  # red (and alpha) vary apart from the rest
    assert _planes(x, chw, 1, 2.0, opaque)[0] in alone
    assert list(_planes(x, chw, 2, 2.0, opaque)) == ([0, 1, 2] if opaque else [0, 1, 2, 3])
    two = list(_planes(x, chw, 3, 2.0, opaque))
    assert len(two) == 2 and two[0] == _planes(x, chw, 1, 2.0, opaque)[0]
    if opaque:
        assert two[1] in (1, 2)  # green and blue tie: either one is as good
    else:
        assert sorted(two) == [0, 3]


def _resid_without(x, chw, c):
    """numpy's: the weighted texels' distance from their principal line with
    component c left out (the covariance's trace less its top eigenvalue)."""
    keep = [k for k in range(4) if k != c]
    v = x[:, keep] * np.sqrt(chw[keep])
    cov = np.cov(v.T, bias=True) * len(v)
    return np.trace(cov) - np.linalg.eigvalsh(cov)[-1]


def test_plane_for_what_leaves_the_line(rng):
    """Red and green on one ramp, blue partly on it with a strong variation
    of its own, alpha a faint noise of its own: alpha is the least correlated
    with anything, but a plane for blue takes far more of the block off its
    line, and mode 1 gives blue the plane (mode 3 blue, then alpha)."""
    t = np.arange(36, dtype=np.float64)
    x = np.empty((36, 4))
    x[:, 0] = 40 + 4 * t
    x[:, 1] = 200 - 3 * t
    x[:, 2] = 60 + 2 * t + rng.normal(0, 20, 36)
    x[:, 3] = 200 + rng.normal(0, 2, 36)
    chw = np.ones(4)
    corr = np.abs(np.corrcoef(x.T))
    np.fill_diagonal(corr, 0)
    assert corr[3].max() < corr[2].max()  # the old rule, least correlated first, gave alpha the plane
    resid = [_resid_without(x, chw, c) for c in range(4)]
    assert int(np.argmin(resid)) == 2
    assert list(_planes(x, chw, 1, 2.0, 0)) == [2]
    assert list(_planes(x, chw, 3, 2.0, 0))[0] == 2


def test_correlation_limit(rng):
    """With mode 3 the second component also has to be under the limit:
    green and blue move together, so only red gets a plane."""
    x = _block(rng)
    x[:, 3] = 255
    chw = np.ones(4)
    assert list(_planes(x, chw, 3, 0.5, 1)) == [0]
    x[:, 0] = 120 + 2 * np.arange(36)  # red on the ramp too: nothing varies apart
    assert len(_planes(x, chw, 3, 0.5, 1)) == 0
    assert len(_planes(x, chw, 1, 0.5, 1)) == 0


def test_flat_and_weightless_components(rng):
    """A constant component, or one without weight, varies nowhere."""
    x = _block(rng)
    x[:, 0] = 77
    x[:, 3] = 255
    chw = np.ones(4)
    assert list(_planes(x, chw, 2, 2.0, 1)) == [1, 2]
    chw[1] = 0.0
    assert list(_planes(x, chw, 2, 2.0, 1)) == [2]
    assert list(_planes(x, chw, 3, 2.0, 1)) == [2]


@pytest.mark.parametrize("alpha", [False, True])
def test_grey_stays_grey(alpha, rng, monkeypatch):
    """A grey texture decodes grey (R = G = B in every texel) whatever the
    preset asks of planes (here every component, `dual` 2): an opaque grey
    block gets no plane (R, G and B move together, and the search no longer
    tries one), and with alpha of its own only alpha's plane wins."""
    from texcook import codecs
    from texcook.codecs.astc import presets
    from texcook.codecs.astc.symbolic import S_CCS, S_DUAL

    real = presets.record

    def every_component(bw, bh, preset):
        rec = real(bw, bh, preset)
        rec["dual"] = 2
        rec["plane_early"] = 0
        return rec

    monkeypatch.setattr(presets, "record", every_component)
    yy, xx = np.mgrid[0:16, 0:32]
    lum = np.clip(90 + 3 * xx + rng.normal(0, 6, xx.shape), 0, 255)
    img = np.empty((16, 32, 4), np.uint8)
    img[..., :3] = np.rint(lum)[..., None]
    img[..., 3] = np.clip(np.rint(200 - 5 * yy + rng.normal(0, 20, yy.shape)), 0, 255) if alpha else 255
    c = codecs.get("astc-4x4")
    data, sym = c.encode_symbolic(img, "medium", threads=1)
    dec = c.decode(data, 32, 16)
    assert np.array_equal(dec[..., 0], dec[..., 1]) and np.array_equal(dec[..., 1], dec[..., 2])
    planes = sym[sym[:, S_DUAL] != 0]
    assert (len(planes) > 0) == alpha
    assert np.all(planes[:, S_CCS] == 3)
