"""BC4 / BC5 / BC3: decoders against texture2ddecoder and a readable reference,
both BC4 modes, search optimality on small cases, normal maps, quality floors."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from texcook import codecs
from texcook.metrics import normal_angular_error, psnr
from conftest import load_rgba8
from decoders import etcpak_encode, quicktex_encode, t2d
from reference import bc4_best_error, bc4_decode_block, bc4_palette

CORPUS = Path(__file__).resolve().parent.parent / "corpus"
PRESETS = ("fastest", "fast", "medium", "thorough", "exhaustive")


@pytest.fixture
def rng():
    return np.random.default_rng(4321)


def test_decoders_match_reference_and_texture2ddecoder(rng):
    n = 512
    raw = rng.integers(0, 256, (n, 16), dtype=np.uint8)
    raw[:40, 1] = raw[:40, 0]  # r0 == r1
    for fmt, bpb in (("bc4", 8), ("bc5", 16), ("bc3", 16)):
        data = np.ascontiguousarray(raw[:, :bpb]).tobytes()
        ours = codecs.get(fmt).decode(data, 4 * n, 4)
        assert np.array_equal(ours, t2d(fmt, data, 4 * n, 4)), fmt
    ours = codecs.get("bc4").decode(np.ascontiguousarray(raw[:, :8]).tobytes(), 4 * n, 4)
    assert np.all(ours[..., 1:3] == 0) and np.all(ours[..., 3] == 255)
    for k in range(0, n, 29):
        assert ours[:, 4 * k:4 * k + 4, 0].reshape(16).tolist() == bc4_decode_block(raw[k, :8])


def test_peer_bitstreams_decode_like_texture2ddecoder():
    img = load_rgba8("rgba/ldr-rgba-01.png")[:64, :64].copy()
    streams = [("bc3", quicktex_encode("bc3", img, 5)), ("bc4", quicktex_encode("bc4", img, 0)),
               ("bc5", quicktex_encode("bc5", img, 0, 1))]
    streams += [(fmt, etcpak_encode(fmt, img)) for fmt in ("bc3", "bc4", "bc5")]
    for fmt, s in streams:
        assert np.array_equal(codecs.get(fmt).decode(s, 64, 64), t2d(fmt, s, 64, 64)), fmt


@pytest.mark.parametrize("preset", PRESETS)
def test_our_streams_decode_like_texture2ddecoder(preset):
    img = load_rgba8("rgba/ldr-rgba-00.png")[100:132, 90:154].copy()
    for fmt in ("bc3", "bc4", "bc5"):
        c = codecs.get(fmt)
        data = c.encode(img, preset, threads=1)
        assert np.array_equal(c.decode(data, 64, 32), t2d(fmt, data, 64, 32)), fmt


def test_exhaustive_reaches_the_optimum(rng):
    c = codecs.get("bc4")
    cases = [rng.integers(0, 256, 16), rng.normal(128, 20, 16).clip(0, 255), rng.integers(100, 140, 16),
             np.r_[rng.integers(0, 256, 14), 0, 255], rng.integers(0, 256, 16) // 32 * 32]
    for vals in cases:
        vals = np.asarray(vals, np.uint8)
        blk = np.zeros((4, 4, 4), np.uint8)
        blk[..., 0] = vals.reshape(4, 4)
        dec = c.decode(c.encode(blk, "exhaustive", threads=1), 4, 4)[..., 0].reshape(16)
        got = int(((dec.astype(int) - vals) ** 2).sum())
        assert got == bc4_best_error(vals)


def test_index_choice_is_a_palette_scan_for_every_pair_and_value():
    """The encoder's index choice (midpoint counting) equals a scan of the
    palette in index order keeping the first smallest error, for all 65536
    endpoint pairs and all 256 values, duplicates and ties included."""
    import numba

    from texcook.codecs import bc4

    @numba.njit
    def choose_all(out):
        v, pal, idx = np.empty(16, np.int64), np.zeros((4, 8), np.int64), np.empty(16, np.int64)
        for r0 in range(256):
            for r1 in range(256):
                for start in range(0, 256, 16):
                    for i in range(16):
                        v[i] = start + i
                    bc4._eval(v, r0, r1, pal, idx)
                    out[r0 * 256 + r1, start:start + 16] = idx

    got = np.empty((65536, 256), np.int64)
    choose_all(got)
    x = np.arange(256)
    for r0 in range(256):
        pal = np.array([bc4_palette(r0, r1) for r1 in range(256)])  # (256 pairs, 8)
        want = np.argmin((pal[:, None, :] - x[None, :, None]) ** 2, axis=2)  # first of equal errors
        assert np.array_equal(got[r0 * 256:(r0 + 1) * 256], want), f"r0={r0}"


def test_whole_image_index_choice_is_a_palette_scan():
    """The vectorised path's thresholds (a sum and a tie bit between every two
    neighbouring palette entries, equal ones too) pick what a scan of the
    palette in index order keeping the first smallest error picks, and its
    errors are that scan's, for every endpoint pair of both modes (the
    6-value mode's endpoints lie within 1..254) and every value."""
    import numba

    from texcook.codecs import bc4_quick as q

    @numba.njit
    def indices(T, W, n, six):
        # the helpers have no wrapper for calls from Python
        q._thresholds8(W, n)
        q._count8(T, W, n)
        if six:
            q._thresholds6(W, n)
        q._errors(T, W, n)

    G = q.GROUP
    x = np.arange(256)
    texels = x.reshape(16, 16).T  # block j holds values 16 j .. 16 j + 15: texel i of block j at [i, j]
    for six in (False, True):
        pairs = [(a, b) for a in range(1, 255) for b in range(a, 255)] if six else \
            [(b, a) for a in range(256) for b in range(a + 1, 256)]  # (r0, r1), r0 > r1
        pairs = np.array(pairs)
        lanes = np.repeat(pairs, 16, axis=0)  # 16 blocks a pair
        T = np.empty(16 * G, np.uint8)
        T.reshape(16, G)[:] = np.tile(texels, (1, G // 16))
        W = np.zeros(q._W_ROWS * G, np.int64)
        Wr = W.reshape(q._W_ROWS, G)
        bits = np.empty(len(lanes), np.int64)
        errs = np.empty(len(lanes), np.int64)
        for a in range(0, len(lanes), G):
            n = min(G, len(lanes) - a)
            if six:
                Wr[q._LO6, :n], Wr[q._HI6, :n] = lanes[a:a + n, 0], lanes[a:a + n, 1]
                Wr[q._LO, :n], Wr[q._HI, :n] = 0, 255
                indices(T, W, n, True)
                bits[a:a + n], errs[a:a + n] = Wr[q._BITS6, :n], Wr[q._E6, :n]
            else:
                Wr[q._HI, :n], Wr[q._LO, :n] = lanes[a:a + n, 0], lanes[a:a + n, 1]
                indices(T, W, n, False)
                bits[a:a + n], errs[a:a + n] = Wr[q._BITS8, :n], Wr[q._E8, :n]
        got = ((bits[:, None] >> (3 * np.arange(16))) & 7).reshape(len(pairs), 256)  # [pair, value]
        for k in range(0, len(pairs), 4096):
            pal = np.array([bc4_palette(r0, r1) for r0, r1 in pairs[k:k + 4096]])
            err = (pal[:, None, :] - x[None, :, None]) ** 2
            want = np.argmin(err, axis=2)  # the first of equal errors
            assert np.array_equal(got[k:k + 4096], want), ("6-value" if six else "8-value", k)
            best = err.min(axis=2).reshape(-1, 16, 16).sum(axis=2).reshape(-1)
            assert np.array_equal(errs.reshape(len(pairs), 16)[k:k + 4096].reshape(-1), best)


def test_fastest_takes_the_better_of_the_extremes_in_either_mode(rng):
    """fastest measures one pair per mode: the block's min and max in the
    8-value mode, and where the block holds 0 or 255 the min and max of the
    other values in the 6-value mode (exact 0 and 255); it keeps the better."""
    c = codecs.get("bc4")

    def best(pal, vals):
        return int(np.min((np.asarray(pal)[None, :] - vals[:, None]) ** 2, axis=1).sum())

    for k in range(300):
        vals = rng.integers(0, 256, 16)
        if k % 3 == 0:
            vals[rng.integers(0, 16, 4)] = 0
        elif k % 3 == 1:
            vals[rng.integers(0, 16, 3)] = 255
        blk = np.zeros((4, 4, 4), np.uint8)
        blk[..., 0] = vals.reshape(4, 4)
        dec = c.decode(c.encode(blk, "fastest", threads=1), 4, 4)[..., 0].reshape(16).astype(int)
        lo, hi = int(vals.min()), int(vals.max())
        want = best(bc4_palette(hi, lo), vals) if lo < hi else 0
        inner = vals[(vals != 0) & (vals != 255)]
        if lo == 0 or hi == 255:
            lo6, hi6 = (int(inner.min()), int(inner.max())) if inner.size else (0, 0)
            want = min(want, best(bc4_palette(lo6, hi6), vals))
        assert int(((dec - vals) ** 2).sum()) == want, vals


def test_both_modes(rng):
    c = codecs.get("bc4")
    # 0, 255 and the six values 100..160 decode to: exact only with the 6-value mode
    vals = np.array(bc4_palette(100, 160) * 2, np.uint8)
    blk = np.zeros((4, 4, 4), np.uint8)
    blk[..., 0] = vals.reshape(4, 4)
    for preset in ("fast", "thorough"):
        data = c.encode(blk, preset, threads=1)
        assert data[0] <= data[1]
        assert np.array_equal(c.decode(data, 4, 4)[..., 0].reshape(16), vals)
    # eight evenly spread values: exact in the 8-value mode
    vals = np.array([((7 - i) * 210 + i * 14) // 7 for i in range(8)] * 2, np.uint8)
    blk[..., 0] = vals.reshape(4, 4)
    data = c.encode(blk, "fast", threads=1)
    assert data[0] > data[1]
    assert np.array_equal(c.decode(data, 4, 4)[..., 0].reshape(16), vals)


def test_constant_and_alpha_zero_blocks():
    vals = np.arange(256, dtype=np.uint8)
    img = np.zeros((4, 4 * 256, 4), np.uint8)
    img[..., 0] = np.repeat(vals, 4)[None]
    img[..., 1] = 255 - img[..., 0]
    img[..., 3] = img[..., 0]
    for fmt in ("bc4", "bc5", "bc3"):
        c = codecs.get(fmt)
        dec = c.decode(c.encode(img, "fastest", threads=1), 4 * 256, 4)
        ch = {"bc4": [0], "bc5": [0, 1], "bc3": [3]}[fmt]
        assert np.array_equal(dec[..., ch], img[..., ch]), fmt
    # BC3 with alpha 0 everywhere keeps the colour
    img = load_rgba8("rgb/ldr-rgb-04.png")[:32, :32].copy()
    img[..., 3] = 0
    c = codecs.get("bc3")
    dec = c.decode(c.encode(img, "medium", threads=1), 32, 32)
    assert np.all(dec[..., 3] == 0)
    assert psnr(img[..., :3], dec[..., :3]) > 30


def test_bc3_colour_block_always_four_colour():
    img = load_rgba8("rgba/ldr-rgba-02.png")[:64, :64].copy()
    img[:8, :8, :3] = 77  # flat blocks
    for preset in PRESETS:
        blocks = np.frombuffer(codecs.get("bc3").encode(img, preset, threads=1), np.uint8).reshape(-1, 16)
        c0 = blocks[:, 8].astype(int) | blocks[:, 9].astype(int) << 8
        c1 = blocks[:, 10].astype(int) | blocks[:, 11].astype(int) << 8
        idx = blocks[:, 12:16].astype(int)
        assert np.all((c0 > c1) | ((c0 == c1) & np.all(idx == 0, axis=1))), preset


def test_flat_normal_map():
    img = np.zeros((16, 16, 4), np.uint8)
    img[..., 0] = 128
    img[..., 1] = 128
    img[..., 2] = 255
    img[..., 3] = 255
    c = codecs.get("bc5")
    for preset in PRESETS:
        dec = c.decode(c.encode(img, preset, threads=1), 16, 16)
        assert np.all(dec[..., :2] == 128) and np.all(dec[..., 2] == 0) and np.all(dec[..., 3] == 255)
        assert normal_angular_error(img, dec) == (0.0, 0.0)


def test_bc5_normal_quality_against_quicktex():
    c = codecs.get("bc5")
    for name in ("normal/ldr-xy-00.png", "normal/ldr-xy-02.png"):
        img = load_rgba8(name)[:64, :64].copy()
        ours = t2d("bc5", c.encode(img, "thorough", threads=1), 64, 64)
        theirs = t2d("bc5", quicktex_encode("bc5", img, 0, 1), 64, 64)
        assert psnr(img[..., :2], ours[..., :2]) >= psnr(img[..., :2], theirs[..., :2])
        assert normal_angular_error(img, ours)[0] <= normal_angular_error(img, theirs)[0]


def test_alpha_quality_against_quicktex():
    img = load_rgba8("rgba/ldr-rgba-00.png")[64:128, 64:128].copy()
    theirs = t2d("bc3", quicktex_encode("bc3", img, 5), 64, 64)
    for preset in ("fastest", "medium"):
        ours = t2d("bc3", codecs.get("bc3").encode(img, preset, threads=1), 64, 64)
        assert psnr(img, ours, channels=[3]) >= psnr(img, theirs, channels=[3])


@pytest.mark.parametrize("shape", [(1, 1), (10, 6), (6, 10)])
def test_small_and_partial_images_edge_padded(rng, shape):
    h, w = shape
    img = rng.integers(0, 256, (h, w, 4), dtype=np.uint8)
    padded = np.pad(img, ((0, -h % 4), (0, -w % 4), (0, 0)), mode="edge")
    for fmt in ("bc3", "bc4", "bc5"):
        c = codecs.get(fmt)
        data = c.encode(img, "medium", threads=1)
        assert len(data) == c.level_size(w, h)
        assert data == c.encode(padded, "medium", threads=1)
        assert c.decode(data, w, h).shape == (h, w, 4)
    one = codecs.get("bc5").decode(codecs.get("bc5").encode(img[:1, :1].copy(), "fast", threads=1), 1, 1)
    assert one[0, 0, :2].tolist() == img[0, 0, :2].tolist()


def _single_block_path(img, fmt, preset="fastest"):
    """The blocks of a gathered image through the one-block search (the path
    every preset but the whole-image one takes)."""
    from texcook.codecs import bc4
    from texcook.codecs._base import image_to_blocks

    nch = {"bc4": 1, "bc5": 2}[fmt]
    blocks = image_to_blocks(img, 4, 4, 1)
    out = np.zeros((blocks.shape[0], 8 * nch), np.uint8)
    bc4.encode_single_run(blocks, out, bc4.SEARCH.record(preset), np.int64(0), np.int64(nch))
    return out.tobytes()


def _hard_blocks(rng):
    """Blocks as an image four texels high: for every endpoint pair (lo, hi) a
    block holding both and values between (all palette duplicates and ties
    of the 8-value mode), with 0 and/or 255 added where the range is small
    (the 6-value mode's), constant blocks, two-value blocks and 0/255 ones."""
    blocks = []
    for lo in range(256):
        for hi in range(lo, 256, 1 if lo % 3 == 0 else 7):
            v = rng.integers(lo, hi + 1, 16)
            v[0], v[1] = lo, hi
            blocks.append(v)
            if hi - lo < 24:
                for extra in ((0,), (255,), (0, 255)):
                    w = v.copy()
                    w[2:2 + len(extra)] = extra
                    blocks.append(rng.permutation(w))
    for a, b in ((0, 255), (0, 1), (254, 255), (0, 0), (255, 255), (7, 200), (1, 254)):
        blocks.append(rng.choice([a, b], 16))
    blocks.append(np.r_[[0] * 8, [255] * 8])
    b = np.array(blocks, np.uint8)
    b = np.concatenate([b, np.zeros((-len(b) % 64, 16), np.uint8)])
    return b.reshape(-1, 64, 4, 4).transpose(0, 2, 1, 3).reshape(-1, 256)


def test_whole_image_fastest_is_the_single_block_search(rng):
    """fastest runs on the image itself, vectorised across blocks, with the
    palette's equal values and ties settled by the thresholds' tie bits: the
    same bytes as the one-block search on gathered blocks, on endpoint pairs
    of both modes from every low end (with 0 and 255 beside small ranges),
    in channel 0 (BC4) and channels 0 and 1 (BC5)."""
    from texcook.codecs import bc4

    assert bc4.reads_image("fastest") and not bc4.reads_image("fast")
    plane = _hard_blocks(rng)
    img = np.stack([plane, plane[:, ::-1], 255 - plane, plane], axis=2).copy()
    for fmt in ("bc4", "bc5"):
        assert codecs.get(fmt).encode(img, "fastest", threads=1) == _single_block_path(img, fmt), fmt
    # noise, smooth ramps and cut-out alpha with 0s and 255s
    for k in range(6):
        h, w = 32, 4 * 70
        noisy = rng.integers(0, 256, (h, w, 4))
        ramp = (np.arange(w)[None, :, None] * (k + 1) // 7 + rng.integers(-3, 4, (h, w, 4)))
        cut = np.where(rng.random((h, w, 4)) < 0.3, 0, np.where(rng.random((h, w, 4)) < 0.3, 255, ramp))
        for src in (noisy, ramp, cut):
            im = np.clip(src, 0, 255).astype(np.uint8)
            for fmt in ("bc4", "bc5"):
                assert codecs.get(fmt).encode(im, "fastest", threads=1) == _single_block_path(im, fmt), (fmt, k)


@pytest.mark.parametrize("shape", [(1, 1), (1, 7), (7, 1), (3, 5), (9, 13), (5, 4 * 65 + 3), (4 * 65 + 1, 6)])
def test_whole_image_fastest_odd_sizes(rng, shape):
    """Blocks past the right and bottom edges repeat the last column and row;
    rows of more blocks than a group; 1-texel levels."""
    h, w = shape
    img = rng.integers(0, 256, (h, w, 4), dtype=np.uint8)
    img[: h // 2, : w // 2, :2] = 0
    img[h // 2:, w // 2:, :2] = 255
    for fmt in ("bc4", "bc5"):
        c = codecs.get(fmt)
        data = c.encode(img, "fastest", threads=1)
        assert len(data) == c.level_size(w, h)
        assert data == _single_block_path(img, fmt), fmt
        assert np.array_equal(c.decode(data, w, h), t2d(fmt, data, w, h)), fmt
    one = codecs.get("bc5").decode(codecs.get("bc5").encode(img[:1, :1].copy(), "fastest", threads=1), 1, 1)
    assert one[0, 0, :2].tolist() == img[0, 0, :2].tolist()


def test_whole_image_fastest_threads_same_bytes(rng):
    """Runs split for threads start and end inside block rows."""
    img = rng.integers(0, 256, (4 * 70, 4 * 67 + 2, 4), dtype=np.uint8)
    img[::3] = 0
    for fmt in ("bc4", "bc5"):
        c = codecs.get(fmt)
        assert c.encode(img, "fastest", threads=1) == c.encode(img, "fastest", threads=2), fmt


@pytest.mark.parametrize("shape", [(1, 1), (7, 5), (4 * 70, 4 * 67 + 2)])
def test_bc3_fastest_on_the_image_is_the_gathered_blocks_runs(rng, shape):
    """BC3 `fastest` runs BC1's and BC4's image kernels (alpha: the hard
    endpoint pairs of _hard_blocks, cut-out 0s and 255s): the bytes of its
    two runs over gathered blocks, with and without weights, on 1 and 2
    threads."""
    from texcook.codecs import bc1, bc3
    from texcook.codecs._base import image_to_blocks

    assert bc3.reads_image("fastest") and not bc3.reads_image("fast")
    plane = _hard_blocks(rng) if shape[0] > 64 else None
    h, w = shape if plane is None else (plane.shape[0], shape[1])
    img = rng.integers(0, 256, (h, w, 4), dtype=np.uint8)
    img[::3, :, 3] = 0
    img[1::5, :, 3] = 255
    if plane is not None:
        img[:, :256, 3] = plane
        img[h // 2:, :, :3] = img[h // 2, :, :3]  # flat colour blocks
    c = codecs.get("bc3")
    for weights in (None, (1.0, 2.0, 0.5)):
        ww, sw = bc1.colour_weights(weights)
        blocks = image_to_blocks(img, 4, 4, 1)
        out = np.zeros((blocks.shape[0], 16), np.uint8)
        bc3.encode_runs(blocks, out, 1, "fastest", ww, sw)
        opts = {} if weights is None else {"weights": weights}
        for threads in (1, 2):
            assert c.encode(img, "fastest", threads=threads, **opts) == out.tobytes(), (weights, threads)


def test_threads_same_bytes():
    img = load_rgba8("rgba/ldr-rgba-01.png")[:128, :128].copy()
    for fmt in ("bc3", "bc4", "bc5"):
        c = codecs.get(fmt)
        assert c.encode(img, "fast", threads=1) == c.encode(img, "fast", threads=2), fmt


def test_python_kernels_without_jit():
    code = (
        "import numpy as np; from texcook import codecs;"
        "r = np.random.default_rng(5); im = r.integers(0, 256, (4, 8, 4), dtype=np.uint8);"
        "print(codecs.get('bc5').encode(im, 'medium', threads=1).hex(),"
        " codecs.get('bc3').encode(im, 'fast', threads=1).hex(),"
        " codecs.get('bc5').encode(im, 'fastest', threads=1).hex())"
    )
    env = dict(os.environ, NUMBA_DISABLE_JIT="1")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    im = np.random.default_rng(5).integers(0, 256, (4, 8, 4), dtype=np.uint8)
    want = [codecs.get("bc5").encode(im, "medium", threads=1).hex(),
            codecs.get("bc3").encode(im, "fast", threads=1).hex(),
            codecs.get("bc5").encode(im, "fastest", threads=1).hex()]
    assert out.stdout.split() == want
