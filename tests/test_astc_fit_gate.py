"""The search's fit gate (presets.py `fit_gate`): a candidate whose refit
endpoints, before quantisation, already miss by more than the gate's share of
the best error so far is not encoded further. The float error it reads
(endpoints.fit_err) must be the error of those endpoints at the candidate's
weights, and the gate must leave hard blocks exact and the rest close to the
full search."""

import numba
import numpy as np
import pytest
from conftest import load_rgba8
from test_astc_early_outs import _block_err, _encode, _hard_cases, _tiles

from texcook import codecs
from texcook.codecs.astc import presets
from texcook.codecs.astc.search.endpoints import fit_err
from texcook.codecs.astc.search.fit import refit


@numba.njit
def _refit_err(x, labels, nparts, wt1, wt2, dual, ccs, chw, sxx):
    e0 = np.zeros((4, 4))
    e1 = np.zeros((4, 4))
    acc = np.zeros((4, 4, 5))
    refit(x, labels, nparts, x.shape[0], wt1, wt2, dual, ccs, e0, e1, acc)
    return fit_err(acc, nparts, chw, e0, e1, sxx), e0, e1


@pytest.mark.parametrize("nparts,dual", [(1, 0), (1, 1), (2, 0), (3, 1)])
def test_fit_err_is_the_error_of_the_float_endpoints(nparts, dual, rng):
    nt = 36
    x = rng.uniform(0, 255, (nt, 4))
    labels = rng.integers(0, nparts, nt)
    wt1 = rng.integers(0, 65, nt)
    wt2 = rng.integers(0, 65, nt)
    ccs = 2
    chw = np.array([1.0, 2.0, 0.5, 1.5])
    sxx = float((x * x * chw).sum())
    err, e0, e1 = _refit_err(x, labels, nparts, wt1, wt2, dual, ccs, chw, sxx)
    want = 0.0
    for t in range(nt):
        p = labels[t]
        for c in range(4):
            u = (wt2[t] if dual and c == ccs else wt1[t]) / 64.0
            d = (1 - u) * e0[p, c] + u * e1[p, c] - x[t, c]
            want += chw[c] * d * d
    assert err == pytest.approx(want, rel=1e-9, abs=1e-6)


@pytest.mark.parametrize("name,preset", [("astc-4x4", "medium"), ("astc-6x6", "medium"), ("astc-8x8", "thorough")])
def test_fit_gate_keeps_hard_blocks_and_stays_close(name, preset, rng, monkeypatch):
    """With the preset's gate, constant and two-colour blocks stay exact and
    a photograph's blocks stay within a fifth of the full search's error (a
    percent overall); a gate far below the best error changes
    blocks, so the gate is reached."""
    c = codecs.get(name)
    bw, bh = c.block_w, c.block_h
    assert presets.record(bw, bh, preset)[0]["fit_gate"] > 0
    img = _tiles(bw, bh, rng)
    dec_on, sym_on = _encode(monkeypatch, name, img, preset)
    _hard_cases(sym_on, dec_on, img, bw, bh)
    photo = load_rgba8("rgb/ldr-rgb-01.png", (48, 48))
    dec_on, sym_on = _encode(monkeypatch, name, photo, preset)
    dec_off, sym_off = _encode(monkeypatch, name, photo, preset, fit_gate=0)
    _, sym_low = _encode(monkeypatch, name, photo, preset, fit_gate=50)
    err_on, err_off = _block_err(dec_on, photo, bw, bh), _block_err(dec_off, photo, bw, bh)
    assert np.all(err_on <= err_off * 1.2 + bw * bh)  # or one level per texel
    assert err_on.sum() <= err_off.sum() * 1.01
    assert np.any(np.any(sym_low != sym_off, axis=1)), "a gate of half the best error changed nothing"
