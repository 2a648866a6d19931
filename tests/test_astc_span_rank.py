"""Partitions of unequal spans (presets.py `span_rank`): a fit whose
partitions' spans differ more than the row says ranks its grids decimated for
real instead of by the separable estimate, which counts a narrow partition's
nearly free weights as fixed beside a wide one's. On flat patches with noise
beside hard borders (a PBR base colour) that finds coarse grids the estimate
ranked out, and what it writes decodes the same in astcenc."""

import numpy as np
import pytest
from decoders import astcenc_decode
from test_astc_early_outs import _block_err, _encode

from texcook.codecs.astc import BLOCK_SIZES, presets
from texcook.codecs.astc.pack import pack


def _patches(rng, n):
    """Flat materials with a little noise and hard, irregular borders: discs
    of their own colour over a base, and a texel here and there of the
    neighbour's colour (a pattern's label off by one)."""
    yy, xx = np.mgrid[0:n, 0:n]
    img = np.empty((n, n, 3))
    img[:] = rng.uniform(40, 220, 3)
    for _ in range(10):
        cy, cx, r = rng.uniform(0, n), rng.uniform(0, n), rng.uniform(4, 14)
        img[(yy - cy) ** 2 + (xx - cx) ** 2 < r * r] = rng.uniform(20, 235, 3)
    img += rng.normal(0, 1.5, img.shape)
    rgba = np.concatenate([img, np.full((n, n, 1), 255.0)], axis=2)
    return np.clip(np.rint(rgba), 0, 255).astype(np.uint8)


# (at 6x6 and 8x8 this content gains under 1%: larger blocks' coarse grids
# are where the estimate went most wrong)
@pytest.mark.parametrize("name", ["astc-10x8", "astc-10x10", "astc-12x12"])
def test_unequal_spans_ranked_for_real(name, rng, monkeypatch):
    bw, bh = (int(v) for v in name.split("-")[1].split("x"))
    img = _patches(rng, 120 if bw == 12 else 80)
    dec_on, sym_on = _encode(monkeypatch, name, img, "thorough", span_rank=80)
    dec_off, _ = _encode(monkeypatch, name, img, "thorough", span_rank=0)
    err_on, err_off = _block_err(dec_on, img, bw, bh), _block_err(dec_off, img, bw, bh)
    # the other fits rank as before, so most blocks keep their error; where
    # the edge's fit was ranked for real the block comes out closer
    assert err_on.sum() < 0.97 * err_off.sum(), (err_on.sum(), err_off.sum())
    assert np.sum(err_on < 0.5 * err_off) >= 2, "no block much closer"
    assert np.array_equal(dec_on, astcenc_decode(pack(sym_on), bw, bh, img.shape[1], img.shape[0], unorm8=True))


def test_flat_and_two_colour_blocks_unchanged(monkeypatch):
    """A block of one colour, or of two colours split by a partition pattern
    (both partitions' spans 0): nothing to rank differently, the same bytes."""
    img = np.zeros((20, 20, 4), np.uint8)
    img[..., 3] = 255
    img[:10, :10, :3] = 90
    img[10:, :, :3] = (200, 30, 60)
    img[:10, 10:, 0] = 255
    on, _ = _encode(monkeypatch, "astc-10x10", img, "thorough", span_rank=80)
    off, _ = _encode(monkeypatch, "astc-10x10", img, "thorough", span_rank=0)
    assert np.array_equal(on, off)
    assert np.abs(on.astype(int) - img).max() <= 1


def test_thorough_rows_rank_unequal_spans():
    """Every `thorough` row ranks unequal partitions for real; the faster
    presets keep the separable estimate (docs/astc.md, "Partitions of unequal
    spans")."""
    for bw, bh in BLOCK_SIZES:
        table = presets.table_for(bw, bh)
        assert table.row("thorough").span_rank == 80, (bw, bh)
        for p in ("fastest", "fast", "medium"):
            assert table.row(p).span_rank == 0, (bw, bh, p)
