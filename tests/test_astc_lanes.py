"""ASTC search: the first fits made for a run of blocks at once
(texcook.codecs.astc.search.lanes) are, bit for bit, what the per-block
functions they stand in for make: texel_moments's sums, fit_partitions's
fit of one partition and one plane, and sep_errs's grid estimates; for runs
shorter than a pass, longer than a run, and blocks that are flat, two-coloured,
noisy, or have a channel without weight."""

import numba
import numpy as np
import pytest

from texcook.codecs.astc.search import _fit_work
from texcook.codecs.astc.search.block_tables import kernel_tables
from texcook.codecs.astc.search.fit import fit_partitions, texel_moments
from texcook.codecs.astc.search.grid import sep_errs
from texcook.codecs.astc.search.lanes import (
    O_E0,
    O_E1,
    O_GE,
    O_RES,
    O_SP,
    O_SS,
    O_TOT,
    TILE,
    first_tile,
    grid_row,
    lanes_work,
)


@numba.njit
def _per_block(blocks, chw, fw, bw, bh, sep, used, out):
    """Per block: the sums, the fit and the estimates, in lanes.Lanes.out's
    row layout."""
    nb, nt = blocks.shape[0], blocks.shape[1]
    ux, uoff, qyp = sep
    x = np.zeros((nt, 4))
    labels = np.zeros(nt, np.int64)
    errs = np.zeros((13, 13))
    sc = np.zeros(nt + bh * ux.shape[1] + bh * bh)
    for i in range(nb):
        for t in range(nt):
            for c in range(4):
                x[t, c] = blocks[i, t, c]
        texel_moments(x, chw, nt, fw.tot)
        res = fit_partitions(x, chw, labels, np.int64(1), nt, np.int64(0), np.int64(0), fw, np.int64(0))
        errs[:] = 0.0
        sep_errs(fw.w1, fw.s1, bw, bh, ux, uoff, qyp, errs, sc, used, np.int64(-1), fw.runs)
        o = out[i]
        for t in range(nt):
            o[t] = fw.w1[t]
        for j in range(16):
            o[nt + O_TOT + j] = fw.tot[j]
        for c in range(4):
            o[nt + O_E0 + c] = fw.e0f[0, c]
            o[nt + O_E1 + c] = fw.e1f[0, c]
        o[nt + O_RES] = res
        o[nt + O_SS] = fw.fsc[20, 0]
        # the importance of every texel is the span's square
        o[nt + O_SP] = fw.s1[0]
        for gw in range(2, bw + 1):
            for gh in range(2, bh + 1):
                if used[gw, gh] and gw * gh < nt:
                    o[nt + O_GE + grid_row(gw, gh, bh)] = errs[gw, gh]


@numba.njit
def _by_runs(blocks, chw, lw, bw, bh, sep, used, out):
    """The same through first_tile, run by run (the span squared, as the
    search copies it)."""
    nb, nt = blocks.shape[0], blocks.shape[1]
    for i0 in range(0, nb, TILE):
        first_tile(blocks, np.int64(i0), chw, lw, bw, bh, sep, used)
        for k in range(min(TILE, nb - i0)):
            out[i0 + k] = lw.out[k]
            sp = lw.out[k, nt + O_SP]
            out[i0 + k, nt + O_SP] = sp * sp


def _blocks(rng, n, nt):
    """n blocks of nt texels: noise, flat, two colours, a ramp, alpha apart."""
    b = rng.integers(0, 256, (n, nt, 4)).astype(np.uint8)
    for i in range(n):
        kind = i % 5
        if kind == 1:
            b[i] = rng.integers(0, 256, 4)
        elif kind == 2:
            two = rng.integers(0, 256, (2, 4))
            b[i] = two[rng.integers(0, 2, nt)]
        elif kind == 3:
            ramp = np.linspace(0, 1, nt)[:, None]
            a, c = rng.integers(0, 256, (2, 4))
            b[i] = np.round(a + (c - a) * ramp).astype(np.uint8)
        elif kind == 4:
            b[i, :, :3] = rng.integers(0, 256, 3)
    return b


@pytest.mark.parametrize("bw,bh,n", [(4, 4, 1), (5, 4, 300), (8, 8, 65), (12, 12, 70)])
@pytest.mark.parametrize("chw", [(1.0, 1.0, 1.0, 1.0), (1.0, 2.0, 0.5, 0.0)])
def test_first_fits_are_the_per_block_fits(bw, bh, n, chw):
    tab = kernel_tables(bw, bh)
    nt = bw * bh
    lw = lanes_work(bw, bh, tab.sep.ux.shape[1])
    fw = _fit_work(nt)
    used = np.zeros((13, 13), np.int64)
    used[2:bw + 1, 2:bh + 1] = 1
    blocks = _blocks(np.random.default_rng(bw * 100 + n), n, nt)
    chw = np.array(chw)
    want = np.zeros((n, lw.out.shape[1]))
    got = np.ones_like(want)
    _per_block(blocks, chw, fw, bw, bh, tab.sep, used, want)
    _by_runs(blocks, chw, lw, bw, bh, tab.sep, used, got)
    bad = np.nonzero((want.view(np.int64) != got.view(np.int64)).any(axis=1))[0]
    assert bad.size == 0, f"blocks {bad[:5]} differ"
