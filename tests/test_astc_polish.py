"""Polishing a block's best encoding (presets.py `polish`): once the search
ends, the winner's weights are re-derived from its decoded endpoints and its
endpoints refitted. It only ever replaces the winner with a closer encoding,
keeps hard blocks exact, reaches real blocks, and what it writes decodes the
same in astcenc as in texcook."""

import numpy as np
import pytest
from conftest import load_rgba8
from decoders import astcenc_decode
from test_astc_early_outs import _block_err, _encode, _hard_cases, _tiles

from texcook import codecs
from texcook.codecs.astc import presets
from texcook.codecs.astc.pack import pack


@pytest.mark.parametrize("name,preset", [("astc-4x4", "thorough"), ("astc-6x6", "thorough"),
                                         ("astc-8x8", "thorough"), ("astc-6x6", "fast")])
def test_polish_never_loses_and_reaches_blocks(name, preset, rng, monkeypatch):
    c = codecs.get(name)
    bw, bh = c.block_w, c.block_h
    img = _tiles(bw, bh, rng)
    dec, sym = _encode(monkeypatch, name, img, preset, polish=2)
    _hard_cases(sym, dec, img, bw, bh)
    photo = load_rgba8("rgb/ldr-rgb-02.png", (48, 48))
    dec_on, sym_on = _encode(monkeypatch, name, photo, preset, polish=1)
    dec_off, sym_off = _encode(monkeypatch, name, photo, preset, polish=0)
    err_on, err_off = _block_err(dec_on, photo, bw, bh), _block_err(dec_off, photo, bw, bh)
    # the search before the polish is the same, and a polished block is kept
    # only when it is closer (the kernel's error is the decoded one: no
    # channel weights here)
    assert np.all(err_on <= err_off)
    assert np.sum(err_on < err_off) >= len(err_on) // 10, "polish improved under a tenth of the blocks"
    changed = np.any(sym_on != sym_off, axis=1)
    assert np.array_equal(changed, err_on < err_off)
    assert np.array_equal(dec_on, astcenc_decode(pack(sym_on), bw, bh, photo.shape[1], photo.shape[0],
                                                 unorm8=True))


def test_thorough_rows_polish():
    """Every `thorough` row polishes its blocks' winners (docs/astc.md,
    "Polishing the winner")."""
    from texcook.codecs.astc import BLOCK_SIZES
    for bw, bh in BLOCK_SIZES:
        assert presets.table_for(bw, bh).row("thorough").polish == 1, (bw, bh)
