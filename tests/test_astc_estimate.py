"""The mode estimate's weight-range error with refitted endpoints
(estimate.refit_wq_err, presets.py `wq_own` 2): per partition and plane it is
what a weighted least-squares affine map of the quantised weights leaves of
the ideal ones, and it is what lets the search pick coarse weight ranges for
noisy blocks."""

import numba
import numpy as np
import pytest
from test_astc_early_outs import _block_err, _encode

from texcook.codecs.astc.search.block_tables import kernel_tables
from texcook.codecs.astc.search.estimate import own_wq_err, refit_wq_err, wq_tables
from texcook.codecs.astc.symbolic import S_WQUANT


@numba.njit
def _errs(w1, s1, w2, s2, labels, nparts, dual, unq, quant):
    nr = unq.shape[0]
    vtab = np.zeros((65, nr))
    qtab = np.zeros((65, nr))
    wq_tables(unq, quant, qtab, vtab)
    refit = np.zeros(nr)
    fixed = np.zeros(nr)
    refit_wq_err(w1, s1, w2, s2, labels, nparts, w1.shape[0], dual, vtab, refit, np.zeros((4, 4, nr)))
    own_wq_err(w1, s1, w2, s2, w1.shape[0], dual, qtab, fixed)
    return refit, fixed, vtab


def _least_squares(w, s, q):
    """Weighted residual of the best a + b q for w."""
    a = np.stack([np.ones_like(q), q], axis=1) * np.sqrt(s)[:, None]
    coef = np.linalg.lstsq(a, w * np.sqrt(s), rcond=None)[0]
    r = w - (coef[0] + coef[1] * q)
    return float((s * r * r).sum())


@pytest.mark.parametrize("nparts,dual", [(1, 0), (2, 1), (3, 0), (4, 0)])
def test_refit_error_is_the_least_squares_residual(nparts, dual, rng):
    weight = kernel_tables(6, 6).weight
    nt = 36
    for _ in range(20):
        labels = rng.integers(0, nparts, nt)
        w1, w2 = rng.random(nt), rng.random(nt)
        s1 = rng.uniform(10, 900, nparts)[labels]  # one line length per partition
        s2 = rng.uniform(10, 900, nparts)[labels]
        refit, _, vtab = _errs(w1, s1, w2, s2, labels, nparts, dual, weight.unq, weight.quant)
        for wq in range(weight.unq.shape[0]):
            want = kept = 0.0
            for w, s in ((w1, s1), (w2, s2))[: 1 + dual]:
                q = vtab[np.clip((w * 64 + 0.5).astype(int), 0, 64), wq]
                kept += float((s * (w - q) ** 2).sum())
                for p in range(nparts):
                    on = labels == p
                    if on.any():
                        want += _least_squares(w[on], s[on], q[on])
            assert refit[wq] == pytest.approx(want, rel=1e-6, abs=1e-6)
            # refitting never loses: at worst it keeps the fit's endpoints
            assert refit[wq] <= kept * (1 + 1e-9)


def test_coarse_ranges_of_noise_and_two_colours(rng):
    weight = kernel_tables(6, 6).weight
    labels = np.zeros(36, np.int64)
    s = np.full(36, 100.0)
    # noise spread evenly: two levels keep about a quarter of the fixed-endpoint error
    w = rng.random(36)
    refit, fixed, _ = _errs(w, s, w, s, labels, 1, 0, weight.unq, weight.quant)
    assert 0.15 < refit[0] / fixed[0] < 0.4
    # two colours lose nothing at any range
    w = (rng.random(36) > 0.5).astype(np.float64)
    refit, _, _ = _errs(w, s, w, s, labels, 1, 0, weight.unq, weight.quant)
    assert np.abs(refit).max() < 1e-9


def test_noisy_blocks_gain_from_the_refit_estimate(rng, monkeypatch):
    """Blocks of one colour with noise in every channel (a PBR base colour's
    grain): exhaustive with the refit estimate ends below the fixed-endpoint
    one in total, and the coarse weight ranges it now ranks are used."""
    img = np.empty((24, 24, 4), np.uint8)
    base = rng.uniform(60, 190, (4, 4, 3)).repeat(6, 0).repeat(6, 1)
    img[..., :3] = np.clip(base + rng.normal(0, 9, (24, 24, 3)), 0, 255).round()
    img[..., 3] = 255
    dec_fixed, sym_fixed = _encode(monkeypatch, "astc-6x6", img, "exhaustive", wq_own=1)
    dec_refit, sym_refit = _encode(monkeypatch, "astc-6x6", img, "exhaustive", wq_own=2)
    assert _block_err(dec_refit, img, 6, 6).sum() < _block_err(dec_fixed, img, 6, 6).sum()
    # more blocks at the coarsest weight range (two levels)
    assert (sym_refit[:, S_WQUANT] == 0).sum() > (sym_fixed[:, S_WQUANT] == 0).sum()
