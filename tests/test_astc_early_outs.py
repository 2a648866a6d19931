"""The search's early-outs (presets.py `done_err` of `medium` and `fast`,
`part_gain` of `medium` and `thorough`, `grey_early` of 4x4 `medium` and
`thorough`): each may only end a block's search
where its rule says so, and otherwise leaves the block's encoding exactly as
the full search makes it. Checked per block on tiles of the hard kinds:
constant, two colours, a border between two materials, six shades on a
three-partition pattern, a noisy gradient."""

import numba
import numpy as np
import pytest

from texcook import codecs
from texcook.codecs._base import image_to_blocks
from texcook.codecs.astc import presets
from texcook.codecs.astc.search import more_parts, tables
from texcook.codecs.astc.symbolic import KIND_VOID, S_KIND, S_PARTS


def _tiles(bw, bh, rng):
    """Eight block columns by two block rows of test content (uint8 RGBA)."""
    h, w = 2 * bh, 8 * bw
    img = np.zeros((h, w, 4))
    img[..., 3] = 255
    img[:, :bw, :3] = (30, 140, 220)  # constant
    pick = rng.integers(0, 2, (h, bw))
    pick[0, 0], pick[-1, -1] = 0, 1
    img[:, bw:2 * bw, :3] = np.where(pick[..., None], (200, 40, 90), (20, 180, 60))  # two colours
    yy, xx = np.mgrid[0:h, 0:bw]
    inside = (yy - h / 2 + 0.5) ** 2 + (xx + 0.3 * bw) ** 2 < (0.9 * bw) ** 2  # a curved material border
    img[:, 2 * bw:3 * bw, :3] = np.where(inside[..., None], (192, 53, 84), (40, 130, 185))
    img[:, 2 * bw:3 * bw, :3] += rng.normal(0, 1.5, (h, bw, 3))
    # on one of the size's three-partition patterns, three colours each split
    # into two close shades by texel parity: three partitions hold two shades
    # each (on a line), two put four shades off one line
    labels = _pattern(bw, bh, tables(bw, bh)["ptab"])
    parity = np.add.outer(np.arange(bh), np.arange(bw)) % 2
    for row, cols in ((0, [(250, 20, 20), (20, 250, 20), (20, 20, 250)]),
                      (1, [(200, 160, 30), (30, 90, 200), (120, 230, 180)])):
        shade = np.array([(14, -10, 6), (-8, 12, 10), (10, 8, -14)], np.float64)
        img[row * bh:(row + 1) * bh, 3 * bw:4 * bw, :3] = (np.array(cols, np.float64)[labels]
                                                           + shade[labels] * parity[..., None])
    # a gradient, three columns with a little noise (where the early-out can
    # stop) and one with more
    yy, xx = np.mgrid[0:h, 0:4 * bw]
    grad = np.stack([60 + 0.8 * xx + 0.5 * yy, 90 + 0.3 * xx, 150 - 0.6 * yy], axis=-1)
    img[:, 4 * bw:, :3] = grad + rng.normal(0, 1.0, grad.shape)
    img[:, 7 * bw:, :3] += rng.normal(0, 3.0, (h, bw, 3))
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def _pattern(bw, bh, ptab):
    """The first three-partition pattern of the size with every partition at
    least a quarter of the block, as (bh, bw) labels."""
    for labels in ptab[1]:
        counts = np.bincount(labels[:bw * bh], minlength=3)
        if counts.min() * 4 >= bw * bh:
            return labels[:bw * bh].reshape(bh, bw)
    raise AssertionError("no balanced three-partition pattern")


def _encode(monkeypatch, name, img, preset="medium", **fields):
    """`preset` with some of its record's fields replaced: (decoded, sym)."""
    real = presets.record

    def patched(bw, bh, preset):
        rec = real(bw, bh, preset)
        for k, v in fields.items():
            rec[k] = v
        return rec

    monkeypatch.setattr(presets, "record", patched)
    try:
        c = codecs.get(name)
        data, sym = c.encode_symbolic(img, preset, threads=1)
    finally:
        monkeypatch.setattr(presets, "record", real)
    return c.decode(data, img.shape[1], img.shape[0]), sym


def _block_err(dec, img, bw, bh):
    d = image_to_blocks(dec, bw, bh).astype(np.float64) - image_to_blocks(img, bw, bh)
    return (d * d).sum(axis=(1, 2))


def _hard_cases(sym_on, dec_on, img, bw, bh):
    on = image_to_blocks(dec_on, bw, bh)
    ref = image_to_blocks(img, bw, bh)
    for b in (0, 8):  # the constant column: void extent, exact
        assert sym_on[b, S_KIND] == KIND_VOID and np.array_equal(on[b], ref[b])
    for b in (1, 9):  # the two-colour column: exact up to 36 texels (a full grid of
        # 1-bit weights fits), within one level per channel above
        diff = np.abs(on[b].astype(int) - ref[b])
        assert diff.max() <= (0 if bw * bh <= 36 else 1), b


@pytest.mark.parametrize("name,preset", [("astc-6x6", "medium"), ("astc-8x8", "medium"), ("astc-6x6", "fast"),
                                         ("astc-8x8", "fast")])
def test_done_err_ends_a_search_only_below_its_error(name, preset, rng, monkeypatch):
    """A block's encoding is the full search's, or its error per texel is at
    most `done_err` (the search stopped there)."""
    c = codecs.get(name)
    bw, bh, nt = c.block_w, c.block_h, c.block_w * c.block_h
    done = presets.record(bw, bh, preset)[0]["done_err"] / 100.0
    assert done > 0
    img = _tiles(bw, bh, rng)
    dec_on, sym_on = _encode(monkeypatch, name, img, preset, part_gain=0)
    dec_off, sym_off = _encode(monkeypatch, name, img, preset, part_gain=0, done_err=0)
    err_on, err_off = _block_err(dec_on, img, bw, bh), _block_err(dec_off, img, bw, bh)
    same = np.all(sym_on == sym_off, axis=1)
    assert np.all(same | (err_on <= done * nt + 1e-9))
    assert not np.all(same), "the test's blocks never reach the early-out"
    _hard_cases(sym_on, dec_on, img, bw, bh)
    # the border and the three colours stay close to the full search
    for b in (2, 3, 10, 11):
        assert err_on[b] <= max(done * nt, err_off[b] * 1.5), b


@pytest.mark.parametrize("name,preset", [("astc-4x4", "medium"), ("astc-6x6", "medium"), ("astc-4x4", "thorough"),
                                         ("astc-6x6", "thorough")])
def test_part_gain_skips_only_three_partitions(name, preset, rng, monkeypatch):
    """`part_gain` only drops a third (or fourth) partition: a block comes out
    as the full search makes it unless that search's best has more than two
    partitions; where two partitions gained much over one (shades on a
    three-partition pattern) three are still tried and win. `medium` compares
    the running best, `thorough` (above 100) each count's own."""
    c = codecs.get(name)
    bw, bh = c.block_w, c.block_h
    gain = presets.record(bw, bh, preset)[0]["part_gain"]
    assert (gain > 100) == (preset == "thorough") and gain > 0
    img = _tiles(bw, bh, rng)
    dec_on, sym_on = _encode(monkeypatch, name, img, preset, done_err=0)
    dec_off, sym_off = _encode(monkeypatch, name, img, preset, done_err=0, part_gain=0)
    same = np.all(sym_on == sym_off, axis=1)
    assert np.all(same | (sym_off[:, S_PARTS] >= 3))
    _hard_cases(sym_on, dec_on, img, bw, bh)
    # the shades on a three-partition pattern: as the full search, which takes
    # three partitions for at least one of them
    assert same[3] and same[11]
    assert 3 in (sym_on[3, S_PARTS], sym_on[11, S_PARTS])


@numba.njit
def _more_parts(part_gain, best, cbest, prev):
    return more_parts(part_gain, best, cbest, prev)


def test_more_parts_rule():
    """Up to 100 the running best must have come under the share of what one
    partition fewer left; above, the last count's own best, so a count that
    did worse than the one below ends the search while a small gain does not."""
    assert _more_parts(0.0, 10.0, 50.0, 10.0)  # 0: always
    assert not _more_parts(0.95, 9.6, 9.6, 10.0)
    assert _more_parts(0.95, 9.4, 9.4, 10.0)
    assert not _more_parts(0.95, 10.0, 30.0, 10.0)  # did worse: the running best did not move
    assert _more_parts(1.15, 10.0, 11.0, 10.0)  # a little worse than one partition fewer: still tried
    assert not _more_parts(1.15, 10.0, 12.0, 10.0)
    assert not _more_parts(1.15, 10.0, np.inf, 10.0)  # nothing of that count came near
    assert _more_parts(1.15, 5.0, 5.0, 10.0)


@pytest.mark.parametrize("name,preset", [("astc-4x4", "medium"), ("astc-4x4", "thorough")])
def test_grey_early_searches_grey_blocks_further(name, preset, rng, monkeypatch):
    """`grey_early` lowers the early-outs of wholly grey blocks only: a colour
    block comes out as with the row's own early-outs, a grey block goes on
    searching past them (every candidate the row's search encodes, and then
    more), so its error is never larger, and on nearly lossless grey tiles
    smaller."""
    c = codecs.get(name)
    bw, bh = c.block_w, c.block_h
    assert presets.record(bw, bh, preset)[0]["grey_early"] < 100
    colour = _tiles(bw, bh, rng)
    # grey tiles as a height or roughness map has them: three bands of one
    # level each with a level's noise, which one partition holds within the
    # early-out and three hold nearly exactly
    band = np.minimum(np.arange(8 * bw) % bw * 3 // bw, 2)
    levels = rng.integers(40, 220, (2, 8, 3))
    lum = levels[np.arange(2 * bh)[:, None] // bh, np.arange(8 * bw)[None, :] // bw, band[None, :]]
    lum = np.clip(lum + rng.integers(-2, 3, lum.shape), 0, 255)
    grey = np.empty_like(colour)
    grey[..., :3] = lum[..., None]
    grey[..., 3] = 255
    img = np.concatenate([colour, grey], axis=1)
    dec_on, sym_on = _encode(monkeypatch, name, img, preset)
    dec_off, sym_off = _encode(monkeypatch, name, img, preset, grey_early=100)
    err_on, err_off = _block_err(dec_on, img, bw, bh), _block_err(dec_off, img, bw, bh)
    blocks = image_to_blocks(img, bw, bh)
    is_grey = np.all((blocks[..., 0] == blocks[..., 1]) & (blocks[..., 1] == blocks[..., 2]), axis=1)
    assert is_grey.sum() == 16 and not is_grey[:8].any()  # the right half, by block order
    assert np.all(sym_on[~is_grey] == sym_off[~is_grey])
    assert np.all(err_on[is_grey] <= err_off[is_grey] + 1e-9)
    assert np.any(err_on[is_grey] < err_off[is_grey])
