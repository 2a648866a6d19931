"""ASTC presets: the ranked block modes and the masks the fast presets search."""

import numpy as np
import pytest

from texcook.codecs import PRESETS
from texcook.codecs.astc import BLOCK_SIZES, presets, search
from texcook.codecs.astc.mode_ranks import RANKS


def _table_modes(bw, bh):
    tb = search.tables(bw, bh)
    dims = tb["g_dims"]
    return [(int(dims[g, 0]), int(dims[g, 1]), int(wq), int(dual)) for g, wq, dual, _ in tb["modes"]]


@pytest.mark.parametrize("size", BLOCK_SIZES)
def test_ranks_name_legal_modes_in_order(size):
    rows = RANKS[size]
    legal = set(_table_modes(*size))
    assert len({r[:4] for r in rows}) == len(rows)
    for r in rows:
        assert r[:4] in legal
    shares = [r[4] for r in rows]
    assert shares == sorted(shares)  # how far they reach: test_astc_mode_ranks.py


@pytest.mark.parametrize("size", BLOCK_SIZES)
def test_masks(size):
    bw, bh = size
    modes = _table_modes(bw, bh)
    for name in PRESETS:
        mask = presets.mode_mask(bw, bh, name)
        assert mask.shape == (len(modes),) and mask.dtype == np.int64
        # a single-plane mode is always there to fall back on
        assert any(m and not mode[3] for m, mode in zip(mask, modes))
    assert presets.share_mask(bw, bh, 1000).all()
    small, large = presets.share_mask(bw, bh, 500), presets.share_mask(bw, bh, 900)
    assert 0 < small.sum() < large.sum() < len(modes)
    assert np.all(large >= small)
    # the most frequent winner is in every mask
    top = modes.index(RANKS[size][0][:4])
    assert small[top] == 1


def test_share_one_keeps_a_single_plane_mode():
    for size in BLOCK_SIZES:
        mask = presets.share_mask(*size, 1)
        assert 1 <= mask.sum() <= 1 + sum(1 for r in RANKS[size] if r[3])
