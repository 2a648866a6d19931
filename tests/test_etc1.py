"""ETC1: bit layout, decoder against texture2ddecoder and a readable reference,
encoder hard cases and quality floors."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import texcook.codecs
from texcook.codecs import etc1_kernels as K
from texcook.codecs._base import image_to_blocks
from texcook.codecs.etc1 import SEARCH
from texcook.errors import UsageError
from texcook.metrics import psnr
from conftest import load_rgba8
from decoders import etcpak_encode, t2d
from reference import etc1_best_flat_error, etc1_best_flat_error_4bit, etc1_decode_block

ETC1 = texcook.codecs.get("etc1")

CORPUS = Path(__file__).resolve().parent.parent / "corpus"
ALL_PRESETS = list(SEARCH.presets)

@pytest.fixture
def rng():
    return np.random.default_rng(20240611)


def block_sse(img, dec):
    """Squared RGB error of each 4x4 block."""
    a = image_to_blocks(img, 4, 4)[:, :, :3].astype(np.int64)
    b = image_to_blocks(dec, 4, 4)[:, :, :3].astype(np.int64)
    return ((a - b) ** 2).sum(axis=(1, 2))


# ---------------------------------------------------------------- interface


def test_registry_and_format_fields():
    codec = texcook.codecs.get("etc1")
    assert codec is ETC1
    assert (codec.block_w, codec.block_h, codec.bytes_per_block, codec.channels) == (4, 4, 8, 3)
    assert (codec.vk_unorm, codec.vk_srgb) == (147, 148)
    assert codec.vk_format(True) == 148 and codec.vk_format(False) == 147


def test_bad_options_raise_clear_errors(rng):
    img = rng.integers(0, 256, (8, 8, 4), dtype=np.uint8)
    with pytest.raises(UsageError, match="preset"):
        ETC1.encode(img, "slowest")
    with pytest.raises(UsageError, match="weights"):
        ETC1.encode(img, "fastest", weights=(1, 2))
    with pytest.raises(UsageError, match="weights"):
        ETC1.encode(img, "fastest", weights=(0, 0, 0))
    with pytest.raises(UsageError, match="weights"):
        ETC1.encode(img, "fastest", weights=(1, -1, 1))
    with pytest.raises(UsageError, match="has no option dither"):
        ETC1.encode(img, "fastest", dither=True)
    with pytest.raises(UsageError, match="bytes"):
        ETC1.decode(b"\0" * 7, 4, 4)


# ---------------------------------------------------------------- bit layout


def test_golden_individual_block():
    # individual, flip 1 (top/bottom halves), tables 3 and 6,
    # colours (A, 5, 3) and (1, F, 7), selector of texel (x, y) = (x + 2y) % 4
    sym = np.zeros(K.SYM_LEN, np.int64)
    sym[:10] = [0, 1, 0xA, 0x5, 0x3, 0x1, 0xF, 0x7, 3, 6]
    for y in range(4):
        for x in range(4):
            sym[10 + 4 * y + x] = (x + 2 * y) % 4
    out = np.zeros(8, np.uint8)
    K.pack_sym(sym, out)
    assert out.tobytes().hex() == "a15f377955aaf0f0"
    back = np.zeros(K.SYM_LEN, np.int64)
    K.unpack_sym(out, back)
    assert np.array_equal(back, sym)
    for dec in (ETC1.decode(out.tobytes(), 4, 4), t2d("etc1", out.tobytes(), 4, 4)):
        assert dec[0, 0, :3].tolist() == [170 + 13, 85 + 13, 51 + 13]  # top, +a
        assert dec[1, 0, :3].tolist() == [170 - 13, 85 - 13, 51 - 13]  # top, -a
        assert dec[3, 3, :3].tolist() == [17 + 106, 255, 119 + 106]  # bottom, +b, clamped
        assert dec[2, 1, :3].tolist() == [17 + 106, 255, 119 + 106]
        assert (dec[:, :, 3] == 255).all()


def test_golden_differential_block():
    # differential, flip 0 (left/right), base (20, 3, 31), delta (-4, +3, 0),
    # tables 0 and 7, every selector -b
    sym = np.zeros(K.SYM_LEN, np.int64)
    sym[:10] = [1, 0, 20, 3, 31, 16, 6, 31, 0, 7]
    sym[10:] = 3
    out = np.zeros(8, np.uint8)
    K.pack_sym(sym, out)
    assert out.tobytes().hex() == "a41bf81effffffff"
    for dec in (ETC1.decode(out.tobytes(), 4, 4), t2d("etc1", out.tobytes(), 4, 4)):
        assert (dec[:, :2, :3] == [165 - 8, 24 - 8, 255 - 8]).all()
        assert (dec[:, 2:, :3] == [0, 0, 255 - 183]).all()


def test_pack_unpack_round_trip(rng):
    for _ in range(300):
        sym = np.zeros(K.SYM_LEN, np.int64)
        diff = int(rng.integers(2))
        sym[0], sym[1] = diff, rng.integers(2)
        if diff:
            a = rng.integers(4, 28, 3)
            sym[2:5] = a
            sym[5:8] = a + rng.integers(-4, 4, 3)
        else:
            sym[2:8] = rng.integers(0, 16, 6)
        sym[8:10] = rng.integers(0, 8, 2)
        sym[10:] = rng.integers(0, 4, 16)
        out = np.zeros(8, np.uint8)
        K.pack_sym(sym, out)
        back = np.zeros(K.SYM_LEN, np.int64)
        K.unpack_sym(out, back)
        assert np.array_equal(back, sym)


# ---------------------------------------------------------------- decoder


def test_decoder_matches_references_on_random_bitstreams(rng):
    # every 64-bit pattern is a block; random ones cover both modes, both flips,
    # every table and 5-bit sums that leave 0..31
    data = rng.integers(0, 256, 64 * 64 // 16 * 8, dtype=np.uint8).tobytes()
    ours = ETC1.decode(data, 64, 64)
    assert np.array_equal(ours, t2d("etc1", data, 64, 64))
    blocks = np.frombuffer(data, np.uint8).reshape(-1, 8)
    ob = image_to_blocks(ours, 4, 4)
    for n in range(0, len(blocks), 7):
        ref = etc1_decode_block(blocks[n]).reshape(16, 3)
        assert np.array_equal(ob[n, :, :3], ref)


def test_decoders_agree_on_our_bitstreams(rng):
    img = load_rgba8("rgb/ldr-rgb-03.png", (64, 64))
    noise = rng.integers(0, 256, (16, 24, 4), dtype=np.uint8)
    for preset in ALL_PRESETS:
        for src in (img, noise):
            h, w = src.shape[:2]
            data = ETC1.encode(src, preset, threads=1)
            assert np.array_equal(ETC1.decode(data, w, h), t2d("etc1", data, w, h)), preset


def test_decoders_agree_on_etcpak_bitstreams(rng):
    for src in (load_rgba8("rgb/ldr-rgb-05.png", (128, 128)),
                rng.integers(0, 256, (32, 32, 4), dtype=np.uint8)):
        h, w = src.shape[:2]
        data = etcpak_encode("etc1", src)
        assert np.array_equal(ETC1.decode(data, w, h), t2d("etc1", data, w, h))


# ---------------------------------------------------------------- hard cases


def _constant_blocks(colours):
    """One 4x4 block per colour, side by side."""
    n = len(colours)
    img = np.full((4, 4 * n, 4), 255, np.uint8)
    for i, c in enumerate(colours):
        img[:, 4 * i: 4 * i + 4, :3] = c
    return img


@pytest.mark.parametrize("preset", ["fastest", "medium", "exhaustive"])
def test_every_constant_grey_is_encoded_optimally(preset):
    colours = [(v, v, v) for v in range(256)]
    img = _constant_blocks(colours)
    dec = ETC1.decode(ETC1.encode(img, preset, threads=1), img.shape[1], img.shape[0])
    sse = block_sse(img, dec)
    for v, e in zip(range(256), sse):
        assert e == 16 * etc1_best_flat_error((v, v, v)), v
        assert (dec[:, 4 * v: 4 * v + 4] == dec[0, 4 * v]).all()  # stays constant


@pytest.mark.parametrize("preset", ALL_PRESETS)
def test_random_constant_colours_and_primaries(preset, rng):
    primaries = [(255, 0, 0), (0, 255, 0), (0, 0, 255), (0, 255, 255), (255, 0, 255),
                 (255, 255, 0), (255, 255, 255), (0, 0, 0), (255, 128, 0), (1, 254, 3)]
    colours = primaries + [tuple(c) for c in rng.integers(0, 256, (60, 3))]
    img = _constant_blocks(colours)
    dec = ETC1.decode(ETC1.encode(img, preset, threads=1), img.shape[1], img.shape[0])
    for c, e in zip(colours, block_sse(img, dec)):
        assert e == 16 * etc1_best_flat_error(c), c
    # extremes that ETC1 holds exactly
    assert (dec[:, 24:28, :3] == 255).all() and (dec[:, 28:32, :3] == 0).all()


@pytest.mark.parametrize("preset", ALL_PRESETS)
def test_two_colour_blocks_split_along_and_across_flip(preset, rng):
    pairs = [((255, 0, 0), (0, 0, 255)), ((0, 255, 0), (255, 0, 255)),
             ((10, 10, 10), (250, 250, 250))]
    pairs += [(tuple(a), tuple(b)) for a, b in rng.integers(0, 256, (20, 2, 3))]
    for vertical in (True, False):  # left|right halves (flip 0) or top/bottom (flip 1)
        img = np.full((4, 4 * len(pairs), 4), 255, np.uint8)
        for i, (a, b) in enumerate(pairs):
            blk = img[:, 4 * i: 4 * i + 4]
            if vertical:
                blk[:, :2, :3], blk[:, 2:, :3] = a, b
            else:
                blk[:2, :, :3], blk[2:, :, :3] = a, b
        data = ETC1.encode(img, preset, threads=1)
        dec = ETC1.decode(data, img.shape[1], img.shape[0])
        assert np.array_equal(dec, t2d("etc1", data, img.shape[1], img.shape[0]))
        raw = np.frombuffer(data, np.uint8).reshape(-1, 8)
        for i, ((a, b), e) in enumerate(zip(pairs, block_sse(img, dec))):
            # individual mode holds any two colours independently, so the error
            # is at most the sum of the halves' best 4-bit single-colour errors
            limit = 8 * (etc1_best_flat_error_4bit(a) + etc1_best_flat_error_4bit(b))
            assert e <= limit, (a, b, vertical)
            if e > 0 and a != b:
                assert raw[i, 3] & 1 == (0 if vertical else 1)  # sub-blocks follow the split


def _fastest_reference(blk, w):
    """The `fastest` preset written out plainly from its description
    (docs/etc1.md): blk int (16, 3) row-major texels, w 3 int weights -> 8 bytes."""
    from texcook.codecs.etc1_tables import (
        EXPAND4,
        EXPAND5,
        MODS,
        QUANT4,
        QUANT5,
        SUB_IDX,
        TABLES,
    )

    expand = {5: EXPAND5, 4: EXPAND4}
    quant = {5: QUANT5, 4: QUANT4}
    w = [int(x) for x in w]

    def err(p, q):
        return sum(w[c] * (int(p[c]) - int(q[c])) ** 2 for c in range(3))

    def one_colour(v, prec):  # best (error per texel, code, table), first best in table, selector order
        best = None
        for t in range(8):
            for k in range(4):
                code, e = [], 0
                for c in range(3):
                    d = [(min(255, max(0, int(x) + MODS[t, k])) - int(v[c])) ** 2 for x in expand[prec]]
                    code.append(int(np.argmin(d)))
                    e += w[c] * min(d)
                if best is None or e < best[0]:
                    best = (e, code, t)
        return best

    def code_of(half, prec):
        if (half == half[0]).all():
            return one_colour(half[0], prec)[1]
        return [int(quant[prec][(int(half[:, c].sum()) + 4) >> 3]) for c in range(3)]

    def table_of(half, base):  # closed form, clamping ignored; the first best, stop once one is worse
        best, bt = None, 0
        if (half == half[0]).all():  # one colour: measured exactly
            for t in range(8):
                e = 8 * min(err(np.clip(base + MODS[t, k], 0, 255), half[0]) for k in range(4))
                if best is None or e < best:
                    best, bt = e, t
            return best, bt
        for t in range(8):
            a, b = TABLES[t]
            e = 0
            for p in half:
                e += min(err(base + m, p) for m in (a, -a, b, -b))
            if best is None or e < best:
                best, bt = e, t
            elif e > best:
                break
        return best, bt

    def selectors(half, base, t):
        out = []
        for p in half:
            es = [err(np.clip(base + MODS[t, k], 0, 255), p) for k in range(4)]
            out.append(int(np.argmin(es)))
        return out

    if (blk == blk[0]).all():
        e5, c5, t5 = one_colour(blk[0], 5)
        e4, c4, t4 = one_colour(blk[0], 4)
        flip, diff = 0, int(e5 <= e4)
        ca, ta = (c5, t5) if diff else (c4, t4)
        cb, tb = ca, ta
    else:
        def var(s):
            h = blk[SUB_IDX[s]].astype(float)
            return sum(w[c] * ((h[:, c] - h[:, c].mean()) ** 2).sum() for c in range(3))
        flip = int(var(2) + var(3) < var(0) + var(1))
        ha, hb = blk[SUB_IDX[2 * flip]], blk[SUB_IDX[2 * flip + 1]]
        ca, cb = code_of(ha, 5), code_of(hb, 5)
        fits = all(-4 <= cb[c] - ca[c] <= 3 for c in range(3))
        if not fits:
            cb = [min(ca[c] + 3, max(ca[c] - 4, cb[c])) for c in range(3)]
        ea, ta = table_of(ha, EXPAND5[ca])
        eb, tb = table_of(hb, EXPAND5[cb])
        diff = 1
        if not fits:
            ia, ib = code_of(ha, 4), code_of(hb, 4)
            ea4, ta4 = table_of(ha, EXPAND4[ia])
            eb4, tb4 = table_of(hb, EXPAND4[ib])
            if ea4 + eb4 < ea + eb:
                diff, ca, cb, ta, tb = 0, ia, ib, ta4, tb4
    prec = 5 if diff else 4
    sel = [0] * 16
    for half, code, t in ((0, ca, ta), (1, cb, tb)):
        idx = SUB_IDX[2 * flip + half]
        for i, k in zip(idx, selectors(blk[idx], expand[prec][code], t)):
            sel[i] = k
    out = bytearray(8)
    for c in range(3):
        out[c] = ((ca[c] << 3) | ((cb[c] - ca[c]) & 7)) if diff else ((ca[c] << 4) | cb[c])
    out[3] = (ta << 5) | (tb << 2) | (diff << 1) | flip
    msb = lsb = 0
    for i, k in enumerate(sel):
        bit = (i % 4) * 4 + i // 4  # selector planes run down the columns
        msb |= (k >> 1) << bit
        lsb |= (k & 1) << bit
    out[4:8] = bytes([msb >> 8, msb & 255, lsb >> 8, lsb & 255])
    return bytes(out)


@pytest.mark.parametrize("weights", [None, (0.299, 0.587, 0.114), (0, 1, 1)])
def test_fastest_kernel_equals_its_plain_reference(weights, rng):
    """The one-pass `fastest` kernel gives, block for block, what the preset's
    description computed plainly gives: random blocks, blocks near 0 and 255
    (tables that clamp), few-level blocks (ties), one-colour halves and blocks."""
    from texcook.codecs.etc1 import integer_weights

    n = 96
    kinds = [
        rng.integers(0, 256, (n, 16, 3)),
        rng.integers(0, 24, (n, 16, 3)),
        rng.integers(232, 256, (n, 16, 3)),
        rng.choice(np.array([0, 3, 60, 128, 129, 200, 252, 255]), (n, 16, 3)),
        np.clip(rng.normal(128, 4, (n, 16, 3)), 0, 255).astype(np.int64),
    ]
    halves = rng.integers(0, 256, (n, 2, 3))
    split = np.repeat(halves, 8, axis=1)[:, [0, 1, 8, 9, 2, 3, 10, 11, 4, 5, 12, 13, 6, 7, 14, 15]]
    split[: n // 2] = np.repeat(halves[: n // 2, :1], 16, axis=1)  # whole blocks of one colour
    kinds.append(split)
    blk = np.concatenate(kinds)
    blocks = np.concatenate([blk, np.full(blk.shape[:2] + (1,), 255)], axis=2).astype(np.uint8)
    w = integer_weights(weights)
    out = np.zeros((len(blocks), 8), np.uint8)
    K.encode_blocks(blocks, out, SEARCH.record("fastest"), w)
    for b, got in zip(blk, out):
        assert got.tobytes() == _fastest_reference(b, w), b.tolist()


@pytest.mark.parametrize("shape", [(1, 1), (6, 10), (10, 6), (5, 4)])
def test_small_and_partial_images_pad_by_edge_replication(shape, rng):
    h, w = shape
    img = rng.integers(0, 256, (h, w, 4), dtype=np.uint8)
    data = ETC1.encode(img, "medium", threads=1)
    assert len(data) == ETC1.level_size(w, h) == 8 * (-(-w // 4)) * (-(-h // 4))
    dec = ETC1.decode(data, w, h)
    assert dec.shape == (h, w, 4) and (dec[:, :, 3] == 255).all()
    assert np.array_equal(dec, t2d("etc1", data, w, h))
    ph, pw = -(-h // 4) * 4, -(-w // 4) * 4
    padded = np.pad(img, ((0, ph - h), (0, pw - w), (0, 0)), mode="edge")
    assert ETC1.encode(padded, "medium", threads=1) == data
    if shape == (1, 1):
        assert int(((dec[0, 0, :3].astype(int) - img[0, 0, :3]) ** 2).sum()) == \
            etc1_best_flat_error(img[0, 0, :3])


def test_same_bytes_whatever_the_thread_count():
    img = load_rgba8("rgb/ldr-rgb-07.png", (96, 128))
    for preset in ("fastest", "fast"):
        one = ETC1.encode(img, preset, threads=1)
        assert ETC1.encode(img, preset, threads=2) == one
        assert ETC1.encode(img, preset, threads=3) == one


# ---------------------------------------------------------------- quality


def test_quality_floors_against_etcpak():
    img = load_rgba8("rgb/ldr-rgb-01.png", (96, 96))
    h, w = img.shape[:2]
    ref = psnr(t2d("etc1", etcpak_encode("etc1", img), w, h)[:, :, :3],
               img[:, :, :3])
    scores = {}
    for preset in ALL_PRESETS:
        data = ETC1.encode(img, preset, threads=1)
        scores[preset] = psnr(t2d("etc1", data, w, h)[:, :, :3], img[:, :, :3])
    assert scores["fastest"] >= ref
    assert scores["medium"] >= ref + 1.0
    assert scores["exhaustive"] >= ref + 1.5
    # a wider search never does worse on the whole image
    order = ALL_PRESETS
    for lo, hi in zip(order, order[1:]):
        assert scores[hi] >= scores[lo] - 0.05, (lo, hi, scores)


def test_perceptual_weights_lower_the_weighted_error():
    img = load_rgba8("rgb/ldr-rgb-04.png", (64, 64))
    wts = np.array([0.299, 0.587, 0.114])

    def werr(dec):
        d = dec[:, :, :3].astype(np.float64) - img[:, :, :3]
        return float((d * d * wts).sum())

    plain = ETC1.decode(ETC1.encode(img, "fast", threads=1), 64, 64)
    weighted = ETC1.decode(ETC1.encode(img, "fast", threads=1, weights=tuple(wts)), 64, 64)
    assert werr(weighted) < werr(plain)
    assert ETC1.encode(img, "fast", threads=1, weights=(1, 1, 1)) == \
        ETC1.encode(img, "fast", threads=1)


def test_kernels_run_as_plain_python(tmp_path):
    """The kernels' Python (NUMBA_DISABLE_JIT) gives the same bytes as the
    compiled code on tiny inputs."""
    rng = np.random.default_rng(7)
    img = rng.integers(0, 256, (4, 8, 4), dtype=np.uint8)
    img[:, 4:, :3] = (200, 30, 90)  # one constant block
    np.save(tmp_path / "img.npy", img)
    script = (
        "import sys, numpy as np\n"
        "from texcook.codecs import get; ETC1 = get('etc1')\n"
        f"img = np.load({str(tmp_path / 'img.npy')!r})\n"
        "for p in ('fastest', 'medium', 'exhaustive'):\n"
        "    d = ETC1.encode(img, p, threads=1)\n"
        "    print(p, d.hex(), ETC1.decode(d, 8, 4).tobytes().hex())\n"
    )
    root = str(Path(__file__).resolve().parent.parent)
    env = dict(os.environ, NUMBA_DISABLE_JIT="1",
               PYTHONPATH=os.pathsep.join([root, os.environ.get("PYTHONPATH", "")]))
    res = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                         text=True, timeout=600, cwd=str(tmp_path))
    assert res.returncode == 0, res.stderr
    for line in res.stdout.splitlines():
        p, hexdata, hexdec = line.split()
        d = ETC1.encode(img, p, threads=1)
        assert d.hex() == hexdata, p
        assert ETC1.decode(d, 8, 4).tobytes().hex() == hexdec
