"""ETC1S (etc1s, etc1s-rgba): every block a legal ETC1S block that
texture2ddecoder decodes as texcook does, vocabulary within the budget, hard
cases, quality floors and the quality option's effect."""

import numpy as np
import pytest

import texcook.codecs
from texcook.codecs import etc1s
from texcook.codecs._base import image_to_blocks
from texcook.codecs.etc1_tables import EXPAND5, MODS, SINGLE_ERR
from texcook.errors import UsageError
from texcook.metrics import psnr
from conftest import load_rgba8
from decoders import t2d

ETC1S = texcook.codecs.get("etc1s")
RGBA = texcook.codecs.get("etc1s-rgba")


@pytest.fixture
def rng():
    return np.random.default_rng(20261127)


def halves(codec, data):
    """The ETC1S blocks of a level: (n, 8) for etc1s; colour and alpha halves for etc1s-rgba."""
    b = np.frombuffer(data, np.uint8).reshape(-1, codec.bytes_per_block)
    return [b[:, i:i + 8] for i in range(0, codec.bytes_per_block, 8)]


def assert_legal(blocks):
    """Differential, zero deltas, equal tables, flip 0: the contract's ETC1S block."""
    assert ((blocks[:, 3] >> 1) & 1 == 1).all(), "not differential"
    assert (blocks[:, 3] & 1 == 0).all(), "flip set"
    assert (blocks[:, :3] & 7 == 0).all(), "non-zero delta"
    assert ((blocks[:, 3] >> 5) & 7 == (blocks[:, 3] >> 2) & 7).all(), "tables differ"


def vocabulary(blocks):
    """(distinct endpoints, distinct selector patterns) of ETC1S blocks."""
    return len(np.unique(blocks[:, :4], axis=0)), len(np.unique(blocks[:, 4:], axis=0))


def limits(codec, w, h, quality):
    """The budget one level encoded on its own gets: (endpoints, patterns, bits)."""
    share = etc1s._Chain(4, 4).share(w, h)
    return etc1s.budget(codec.blocks_x(w) * codec.blocks_y(h), quality, share, codec.bytes_per_block // 8)


def cost(counts):
    """What a vocabulary costs in the budget's bits."""
    return etc1s.ENTRY_BITS[0] * counts[0] + etc1s.ENTRY_BITS[1] * counts[1]


def decode_t2d(codec, data, w, h):
    """texture2ddecoder's ETC1 decode of each half; alpha from the alpha half's G."""
    parts = [t2d("etc1", np.ascontiguousarray(p).tobytes(), w, h) for p in halves(codec, data)]
    out = parts[0].copy()
    if len(parts) == 2:
        out[:, :, 3] = parts[1][:, :, 1]
    return out


def own_fit(img):
    """Each block's unconstrained ETC1S fit, as bytes, by the kernels' own fit."""
    blocks = np.ascontiguousarray(image_to_blocks(img, 4, 4)[:, :, :3])
    eps, pats, _ = etc1s.fit(blocks, etc1s.SEARCH.record("medium"), 1)
    return etc1s.pack((eps, pats, np.arange(len(eps)), np.arange(len(eps)))).tobytes()


# ---------------------------------------------------------------- interface


def test_registry_options_and_bad_values(rng):
    assert (ETC1S.bytes_per_block, RGBA.bytes_per_block) == (8, 16)
    assert [o.name for o in ETC1S.options] == ["quality"] and ETC1S.options[0].default == 128
    img = rng.integers(0, 256, (8, 8, 4), dtype=np.uint8)
    for bad in (0, 256, 1.5, "high"):
        with pytest.raises(UsageError, match="quality"):
            ETC1S.encode(img, "fast", quality=bad)
    with pytest.raises(UsageError, match="has no option weights"):
        ETC1S.encode(img, "fast", weights=(1, 1, 1))


@pytest.mark.parametrize("name", ["etc1s", "etc1s-rgba"])
def test_blocks_legal_and_decoders_agree(name, rng):
    codec = texcook.codecs.get(name)
    img = load_rgba8("rgba/ldr-rgba-00.png", (48, 64))
    noise = rng.integers(0, 256, (20, 12, 4), dtype=np.uint8)
    for px in (img, noise):
        h, w = px.shape[:2]
        for preset, q in (("fastest", 1), ("medium", 128), ("exhaustive", 255)):
            data = codec.encode(px, preset, threads=1, quality=q)
            for part in halves(codec, data):
                assert_legal(part)
            dec = codec.decode(data, w, h)
            assert np.array_equal(dec, decode_t2d(codec, data, w, h))


def test_same_bytes_whatever_the_thread_count():
    img = load_rgba8("rgb/ldr-rgb-07.png", (96, 128))
    for preset in ("fastest", "medium"):
        one = ETC1S.encode(img, preset, threads=1, quality=64)
        assert ETC1S.encode(img, preset, threads=2, quality=64) == one
        assert ETC1S.encode(img, preset, threads=3, quality=64) == one


# ---------------------------------------------------------------- vocabulary


@pytest.mark.parametrize("quality", [1, 40, 128])
def test_vocabulary_within_budget(quality):
    img = load_rgba8("rgba/ldr-rgba-01.png", (64, 96))
    for codec in (ETC1S, RGBA):
        data = codec.encode(img, "fast", threads=1, quality=quality)
        ep, sel, bits = limits(codec, 96, 64, quality)
        got = [vocabulary(p) for p in halves(codec, data)]
        total = (sum(g[0] for g in got), sum(g[1] for g in got))
        assert total[0] <= ep and total[1] <= sel and cost(total) <= bits, (got, ep, sel, bits)
        if quality == 40:  # more distinct blocks than the budget: it is used, not undershot by far
            assert cost(total) >= bits / 2, (got, bits)


def test_budget_rises_with_quality_and_shares_the_file_limit():
    seen = [etc1s.budget(4096, q, 10 ** 6) for q in (1, 64, 128, 200, 255)]
    assert all(a[2] < b[2] for a, b in zip(seen, seen[1:]))
    assert seen[-1][:2] == (4096, 4096) and seen[-1][2] >= cost((4096, 4096))
    # a full chain of a large texture: the levels' caps sum within the file's limit
    chain = etc1s._Chain(4, 4)
    for size in (8192, 4000):
        total = np.zeros(2, np.int64)
        for lv in range(14):
            w, h = max(1, size >> lv), max(1, (size // 2) >> lv)
            n = -(-w // 4) * -(-h // 4)
            total += etc1s.budget(n, 255, chain.share(w, h), 2)[:2]
        assert (total <= etc1s.MAX_CODEBOOK).all(), total


def test_the_split_follows_the_image():
    """Within one budget, a smooth image gets more endpoints than patterns
    and a busy one more patterns than endpoints."""
    smooth = np.zeros((64, 64, 4), np.uint8)
    smooth[..., 0] = np.linspace(0, 255, 64)[None, :]
    smooth[..., 1] = np.linspace(0, 255, 64)[:, None]
    smooth[..., 2] = 90
    busy = np.zeros((64, 64, 4), np.uint8)
    busy[..., :3] = (np.random.default_rng(5).random((64, 64, 1)) * 60 + 100).astype(np.uint8)
    counts = {}
    for name, px in (("smooth", smooth), ("busy", busy)):
        counts[name] = vocabulary(halves(ETC1S, ETC1S.encode(px, "fast", threads=1, quality=96))[0])
    assert counts["smooth"][0] > counts["smooth"][1], counts
    assert counts["busy"][1] > counts["busy"][0], counts


def test_a_chain_through_one_encoder_stays_within_the_limit(monkeypatch):
    """With the file limit made small, a mip chain encoded level by level
    through one encoder uses no more distinct endpoints and patterns in total."""
    monkeypatch.setattr(etc1s, "MAX_CODEBOOK", 60)
    img = load_rgba8("rgb/ldr-rgb-03.png", (64, 64))
    encode = ETC1S.encoder("fast", threads=1, quality=255)
    eps, sels = set(), set()
    for lv in range(7):
        s = 64 >> lv
        level = np.ascontiguousarray(img[::1 << lv, ::1 << lv][:s, :s])
        b = halves(ETC1S, encode(level))[0]
        eps |= {bytes(r) for r in b[:, :4]}
        sels |= {bytes(r) for r in b[:, 4:]}
    assert len(eps) <= 60 and len(sels) <= 60, (len(eps), len(sels))


def test_fewer_distinct_blocks_than_the_budget_is_the_unconstrained_fit(rng):
    tiles = rng.integers(0, 256, (3, 4, 4, 4), dtype=np.uint8)
    pick = rng.integers(0, 3, (8, 8))
    img = np.ascontiguousarray(tiles[pick].transpose(0, 2, 1, 3, 4).reshape(32, 32, 4))
    data = ETC1S.encode(img, "medium", threads=1, quality=128)
    assert data == own_fit(img)
    assert vocabulary(halves(ETC1S, data)[0]) == (3, 3)
    # each tile alone gives the same block
    blocks = halves(ETC1S, data)[0]
    for y in range(8):
        for x in range(8):
            alone = ETC1S.encode(np.ascontiguousarray(tiles[pick[y, x]]), "medium", threads=1)
            assert alone == blocks[y * 8 + x].tobytes()


def test_quality_255_is_the_unconstrained_fit():
    img = load_rgba8("rgb/ldr-rgb-02.png", (32, 48))
    assert ETC1S.encode(img, "medium", threads=1, quality=255) == own_fit(img)


def test_more_distinct_blocks_than_the_budget_still_fit_well(rng):
    img = rng.integers(0, 256, (64, 64, 4), dtype=np.uint8)
    smooth = load_rgba8("rgb/ldr-rgb-04.png", (64, 64))
    for px in (img, smooth):
        data = ETC1S.encode(px, "medium", threads=1, quality=1)
        ep, sel, bits = limits(ETC1S, 64, 64, 1)
        got = vocabulary(halves(ETC1S, data)[0])
        assert got[0] <= ep and got[1] <= sel and cost(got) <= bits
        # no worse than every block the image's mean colour
        mean = np.broadcast_to(px[:, :, :3].reshape(-1, 3).mean(0), px[:, :, :3].shape)
        assert psnr(ETC1S.decode(data, 64, 64)[:, :, :3], px[:, :, :3]) > psnr(mean, px[:, :, :3])


# ---------------------------------------------------------------- hard cases


def best_flat_error(rgb):
    """Least squared error of one texel of colour rgb in an ETC1S block (5-bit base, any table)."""
    return min(sum(int(SINGLE_ERR[1, t, k, v]) for v in rgb) for t in range(8) for k in range(4))


@pytest.mark.parametrize("colour", [(0, 0, 0), (255, 255, 255), (200, 30, 90), (13, 128, 251)])
def test_constant_image_is_one_optimal_block(colour):
    img = np.zeros((20, 24, 4), np.uint8)
    img[:, :] = colour + (255,)
    data = ETC1S.encode(img, "fast", threads=1)
    b = halves(ETC1S, data)[0]
    assert vocabulary(b) == (1, 1)
    err = ((ETC1S.decode(data, 24, 20)[0, 0, :3].astype(int) - colour) ** 2).sum()
    assert err == best_flat_error(colour)


def test_two_colours():
    # two colours in separate blocks: two endpoints, each block exact where ETC1S can be
    img = np.zeros((16, 16, 4), np.uint8)
    img[:, :8] = (255, 0, 0, 255)
    img[:, 8:] = (20, 40, 200, 255)
    dec = ETC1S.decode(ETC1S.encode(img, "fast", threads=1, quality=1), 16, 16)
    for x, c in ((0, (255, 0, 0)), (15, (20, 40, 200))):
        assert ((dec[:, x, :3].astype(int) - c) ** 2).sum(axis=1).max() == best_flat_error(c)
    # two greys inside every block (a checkerboard): one table spans them
    g = np.indices((16, 16)).sum(0) % 2
    img = np.zeros((16, 16, 4), np.uint8)
    img[..., :3] = np.where(g[..., None], 170, 60)
    img[..., 3] = 255
    data = ETC1S.encode(img, "medium", threads=1, quality=1)
    assert vocabulary(halves(ETC1S, data)[0]) == (1, 1)  # every block the same checkerboard
    # the least error of any grey base and table (each texel its best modifier), by brute force
    lv = np.clip(EXPAND5[:, None, None] + MODS[None, :, :], 0, 255)  # (code, table, selector)
    best = min(int((np.abs(lv - 60).min(2) ** 2 + np.abs(lv - 170).min(2) ** 2).min()), 10 ** 9)
    dec = ETC1S.decode(data, 16, 16)[:, :, :3].astype(int)
    assert ((dec - img[:, :, :3]) ** 2).sum() == 3 * best * 128


@pytest.mark.parametrize("shape", [(1, 1), (5, 3), (6, 10), (10, 6), (127, 9)])
def test_small_odd_and_partial_sizes(shape, rng):
    h, w = shape
    img = rng.integers(0, 256, (h, w, 4), dtype=np.uint8)
    for codec in (ETC1S, RGBA):
        data = codec.encode(img, "medium", threads=1)
        assert len(data) == codec.level_size(w, h)
        dec = codec.decode(data, w, h)
        assert dec.shape == (h, w, 4)
        assert np.array_equal(dec, decode_t2d(codec, data, w, h))
        ph, pw = -(-h // 4) * 4, -(-w // 4) * 4
        padded = np.pad(img, ((0, ph - h), (0, pw - w), (0, 0)), mode="edge")
        assert codec.encode(padded, "medium", threads=1) == data
    if shape == (1, 1):
        err = ((ETC1S.decode(ETC1S.encode(img, "fast"), 1, 1)[0, 0, :3].astype(int) - img[0, 0, :3]) ** 2).sum()
        assert err == best_flat_error(img[0, 0, :3])


def test_alpha_all_opaque_all_transparent_and_cut_out(rng):
    img = rng.integers(0, 256, (24, 20, 4), dtype=np.uint8)
    for a in (255, 0):
        img[..., 3] = a
        data = RGBA.encode(img, "fast", threads=1, quality=1)
        dec = RGBA.decode(data, 20, 24)
        assert (dec[..., 3] == a).all()
        alpha = halves(RGBA, data)[1]
        assert_legal(alpha)
        assert vocabulary(alpha) == (1, 1)
        # the colour is what etc1s makes of it with the budget the alpha left
        assert psnr(dec[..., :3], img[..., :3]) > 10
    cut = load_rgba8("rgba/ldr-rgba-02.png", (64, 64))
    dec = RGBA.decode(RGBA.encode(cut, "medium", threads=1), 64, 64)
    assert psnr(dec[..., 3], cut[..., 3]) > 25
    # alpha blocks are grey: R = G = B in every decoded alpha texel
    alpha = np.zeros((16 * 16, 16, 4), np.uint8)
    texcook.codecs.get("etc1")._decode_blocks(np.ascontiguousarray(halves(RGBA, RGBA.encode(cut, "medium"))[1]), alpha)
    assert (alpha[..., 0] == alpha[..., 1]).all() and (alpha[..., 2] == alpha[..., 1]).all()


# ---------------------------------------------------------------- quality


# RGB PSNR at the default quality and preset on 128x128 crops (measured: 29.93, 25.47, 32.35
# and 23.06 dB); the floors are 0.3 dB under
FLOORS = {"rgb/ldr-rgb-01.png": 29.63, "rgb/ldr-rgb-04.png": 25.17, "rgb/ldr-rgb-08.png": 32.05,
          "rgba/ldr-rgba-00.png": 22.76}


@pytest.mark.parametrize("path", sorted(FLOORS))
def test_quality_floors_on_the_corpus(path):
    img = load_rgba8(path, (128, 128))
    data = ETC1S.encode(img, "medium", threads=1)
    assert psnr(ETC1S.decode(data, 128, 128)[:, :, :3], img[:, :, :3]) >= FLOORS[path]


def test_quality_rises_with_the_quality_option():
    img = load_rgba8("rgb/ldr-rgb-06.png", (96, 96))
    scores = [psnr(ETC1S.decode(ETC1S.encode(img, "fast", threads=1, quality=q), 96, 96)[:, :, :3],
                   img[:, :, :3]) for q in (1, 64, 128, 192, 255)]
    assert all(b > a + 0.2 for a, b in zip(scores, scores[1:])), scores


def test_search_effort_helps():
    img = load_rgba8("rgb/ldr-rgb-09.png", (96, 96))
    scores = {p: psnr(ETC1S.decode(ETC1S.encode(img, p, threads=1), 96, 96)[:, :, :3], img[:, :, :3])
              for p in etc1s.SEARCH.presets}
    assert scores["exhaustive"] >= scores["fastest"] + 0.1, scores
    assert scores["medium"] >= scores["fastest"], scores
