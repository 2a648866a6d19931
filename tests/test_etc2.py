"""ETC2 RGB and punch-through: the T, H and planar bit layouts, decoders
against texture2ddecoder, never worse than ETC1, planar on gradients,
punch-through coverage, hard cases, quality floors and the CLI."""

import base64

import numpy as np
import pytest

import texcook.codecs
from texcook.codecs import etc2_kernels as K
from texcook.codecs._base import image_to_blocks
from texcook.codecs.etc2 import SEARCH, encode_colour_blocks
from texcook.codecs.etc2_tables import E_A, E_B, E_C, E_DIST, E_LEN, E_MODE, E_OPAQUE, E_SEL, MODE_H, \
    MODE_PLANAR, MODE_T
from texcook.image import write_image
from texcook.metrics import psnr
from conftest import load_rgba8
from decoders import etcpak_encode, t2d

ETC1 = texcook.codecs.get("etc1")
ETC2 = texcook.codecs.get("etc2")
A1 = texcook.codecs.get("etc2a1")
ALL_PRESETS = list(SEARCH.presets)


@pytest.fixture
def rng():
    return np.random.default_rng(20250301)


def block_sse(img, dec):
    a = image_to_blocks(img, 4, 4)[:, :, :3].astype(np.int64)
    b = image_to_blocks(dec, 4, 4)[:, :, :3].astype(np.int64)
    return ((a - b) ** 2).sum(axis=(1, 2))


def random_e(rng, mode, opaque=1):
    e = np.zeros(E_LEN, np.int64)
    e[E_MODE] = mode
    e[E_OPAQUE] = opaque
    if mode == MODE_PLANAR:
        for slot in (E_A, E_B, E_C):
            e[slot:slot + 3] = rng.integers(0, [64, 128, 64])
        e[E_OPAQUE] = 1
        return e
    e[E_A:E_A + 3] = rng.integers(0, 16, 3)
    e[E_B:E_B + 3] = rng.integers(0, 16, 3)
    e[E_DIST] = rng.integers(0, 8)
    if mode == MODE_H:
        a = (e[E_A] << 8) | (e[E_A + 1] << 4) | e[E_A + 2]
        b = (e[E_B] << 8) | (e[E_B + 1] << 4) | e[E_B + 2]
        e[E_DIST] = (e[E_DIST] & 6) | int(a >= b)  # the stored order sets the lowest bit
    e[E_SEL:] = rng.integers(0, 4, 16)
    return e


def legal_blocks(rng, n, punch):
    """n random blocks of every mode, packed by pack_e (T, H, planar) or as
    random ETC1 differential/individual words whose sums stay in range."""
    out = np.zeros((n, 8), np.uint8)
    modes = []
    for i in range(n):
        mode = (MODE_T, MODE_H, MODE_PLANAR, 0)[i % 4]
        if mode:
            K.pack_e(random_e(rng, mode, int(rng.integers(2)) if punch else 1), out[i])
        else:
            while True:
                out[i] = rng.integers(0, 256, 8)
                if K.mode_of_bytes(out[i], punch) == 0:
                    break
        modes.append(mode)
    return out, modes


# ---------------------------------------------------------------- interface


def test_registry_and_format_fields():
    assert (ETC2.vk_unorm, ETC2.vk_srgb, A1.vk_unorm, A1.vk_srgb) == (147, 148, 149, 150)
    assert (ETC2.bytes_per_block, ETC2.channels, A1.bytes_per_block, A1.channels) == (8, 3, 8, 4)
    # an ETC1 file is an ETC2 RGB file: read back with the ETC2 decoder
    assert texcook.codecs.by_vk_format(147) == (ETC2, False)
    assert [o.name for o in A1.options] == ["weights", "alpha_threshold"]


# ---------------------------------------------------------------- bit layout


@pytest.mark.parametrize("mode", [MODE_T, MODE_H, MODE_PLANAR])
def test_pack_unpack_round_trip_sets_the_overflow(mode, rng):
    for _ in range(300):
        e = random_e(rng, mode)
        out = np.zeros(8, np.uint8)
        K.pack_e(e, out)
        # the mode is read from which sum overflows: red T, green H, blue planar
        assert K.mode_of_bytes(out, False) == mode
        back = np.zeros(E_LEN, np.int64)
        K.unpack_e(out, mode, back)
        assert np.array_equal(back, e)


def test_golden_planar_block():
    # O = (32, 64, 0), H = (63, 127, 63), V = (0, 0, 63): a ramp per channel
    e = np.zeros(E_LEN, np.int64)
    e[E_MODE], e[E_OPAQUE] = MODE_PLANAR, 1
    e[E_A:E_A + 3] = (32, 64, 0)
    e[E_B:E_B + 3] = (63, 127, 63)
    e[E_C:E_C + 3] = (0, 0, 63)
    out = np.zeros(8, np.uint8)
    K.pack_e(e, out)
    for dec in (ETC2.decode(out.tobytes(), 4, 4), t2d("etc2", out.tobytes(), 4, 4)):
        o, h, v = 130, 255, 0  # red: 6-bit 32 -> 130, 63 -> 255, 0 -> 0
        for y in range(4):
            for x in range(4):
                assert dec[y, x, 0] == min(255, max(0, (x * (h - o) + y * (v - o) + 4 * o + 2) >> 2))
        assert dec[0, 0, :3].tolist() == [130, 129, 0] and (dec[..., 3] == 255).all()


# ---------------------------------------------------------------- decoders


def test_decoder_matches_texture2ddecoder_on_random_words(rng):
    data = rng.integers(0, 256, 64 * 64 // 16 * 8, dtype=np.uint8).tobytes()
    assert np.array_equal(ETC2.decode(data, 64, 64), t2d("etc2", data, 64, 64))
    ours = A1.decode(data, 64, 64)
    ref = t2d("etc2a1", data, 64, 64)
    assert np.array_equal(ours[..., 3], ref[..., 3])
    opaque = ours[..., 3] == 255
    assert np.array_equal(ours[opaque], ref[opaque])
    # transparent texels are black (the specification); texture2ddecoder keeps their colour
    assert (ours[~opaque] == 0).all() and (~opaque).sum() > 100


@pytest.mark.parametrize("punch", [False, True])
def test_decoder_matches_texture2ddecoder_on_legal_blocks_of_every_mode(punch, rng):
    blocks, modes = legal_blocks(rng, 1024, punch)
    data = blocks.tobytes()
    fmt, codec = ("etc2a1", A1) if punch else ("etc2", ETC2)
    ours = codec.decode(data, 128, 128)
    ref = t2d(fmt, data, 128, 128)
    assert np.array_equal(ours[..., 3], ref[..., 3])
    opaque = ours[..., 3] == 255
    assert np.array_equal(ours[opaque], ref[opaque])
    ob = image_to_blocks(ours, 4, 4)
    for n, mode in enumerate(modes):
        if mode == MODE_PLANAR:
            assert (ob[n, :, 3] == 255).all()  # planar is opaque whatever the opaque bit


@pytest.mark.parametrize("fmt", ["etc2", "etc2a1"])
def test_decoders_agree_on_our_bitstreams(fmt, rng):
    codec = texcook.codecs.get(fmt)
    img = load_rgba8("rgba/ldr-rgba-00.png", (48, 64))
    noise = rng.integers(0, 256, (12, 20, 4), dtype=np.uint8)
    for preset in ALL_PRESETS:
        for src in (img, noise):
            h, w = src.shape[:2]
            data = codec.encode(src, preset, threads=1)
            ours, ref = codec.decode(data, w, h), t2d(fmt, data, w, h)
            assert np.array_equal(ours[..., 3], ref[..., 3]), preset
            opaque = ours[..., 3] == 255
            assert np.array_equal(ours[opaque], ref[opaque]), preset


def test_decoder_agrees_on_etcpak_bitstreams(rng):
    y, x = np.mgrid[0:32, 0:32]
    ramp = np.stack([x * 8, y * 8, (x + y) * 4, x * 0 + 255], -1).astype(np.uint8)
    modes = set()
    for src in (load_rgba8("rgb/ldr-rgb-05.png", (96, 96)), rng.integers(0, 256, (32, 32, 4), dtype=np.uint8),
                ramp):
        h, w = src.shape[:2]
        data = etcpak_encode("etc2", src)
        modes |= {K.mode_of_bytes(b, False) for b in np.frombuffer(data, np.uint8).reshape(-1, 8)}
        assert np.array_equal(ETC2.decode(data, w, h), t2d("etc2", data, w, h))
    assert MODE_PLANAR in modes and len(modes) >= 3, modes


# ---------------------------------------------------------------- never worse than ETC1


@pytest.mark.parametrize("preset", ALL_PRESETS)
def test_never_worse_than_etc1_block_by_block(preset):
    img = load_rgba8("rgb/ldr-rgb-02.png", (64, 64))
    e1 = ETC1.decode(ETC1.encode(img, preset, threads=1), 64, 64)
    data = ETC2.encode(img, preset, threads=1)
    e2 = ETC2.decode(data, 64, 64)
    assert (block_sse(img, e2) <= block_sse(img, e1)).all()
    if preset != "fastest":
        modes = [K.mode_of_bytes(b, False) for b in np.frombuffer(data, np.uint8).reshape(-1, 8)]
        assert {MODE_T, MODE_H, MODE_PLANAR} & set(modes)


@pytest.mark.parametrize("weights", [None, (0.299, 0.587, 0.114), (0.0, 1.0, 0.5)])
def test_fastest_one_pass_equals_etc1_then_the_planar_pass(weights, rng):
    # the one pass measures planar blocks only until they have lost (per
    # channel, from the ETC1 error left); the two passes measure them fully
    from texcook.codecs import etc1, etc1_kernels as K1
    from texcook.codecs.etc2 import scratch

    y, x = np.mgrid[0:32, 0:32]
    ramp = np.stack([x * 7, y * 3 + 40, 255 - x * 4 - y * 3, x * 0 + 255], -1)
    dark = np.clip(ramp // 12 + rng.normal(0, 2, ramp.shape), 0, 255)
    imgs = [load_rgba8("rgb/ldr-rgb-03.png", (64, 64)), rng.integers(0, 256, (32, 32, 4)), ramp, dark,
            np.clip(ramp + 200, 0, 255)]
    w = etc1.integer_weights(weights)
    modes = set()
    for img in imgs:
        blocks = image_to_blocks(np.ascontiguousarray(img, np.uint8), 4, 4)
        one = np.zeros((blocks.shape[0], 8), np.uint8)
        K.fast_blocks(blocks, one, SEARCH.record("fastest"), w, K1.fast_scratch(), scratch())
        two = np.zeros_like(one)
        K1.fast_blocks(blocks, two, w, K1.fast_scratch())
        K.improve_blocks(blocks, two, SEARCH.record("fastest"), w, np.int64(0), np.bool_(False), scratch())
        assert np.array_equal(one, two)
        modes |= {K.mode_of_bytes(b, False) for b in one}
    assert {0, MODE_PLANAR} <= modes


def test_planar_gains_on_a_gradient():
    y, x = np.mgrid[0:64, 0:64]
    img = np.zeros((64, 64, 4), np.uint8)
    img[..., 0] = x * 255 // 63
    img[..., 1] = (x + y) * 255 // 126
    img[..., 2] = 255 - y * 4
    img[..., 3] = 255
    for preset in ("fastest", "medium"):
        p1 = psnr(ETC1.decode(ETC1.encode(img, preset, threads=1), 64, 64)[..., :3], img[..., :3])
        p2 = psnr(t2d("etc2", ETC2.encode(img, preset, threads=1), 64, 64)[..., :3], img[..., :3])
        assert p2 >= p1 + 6.0, (preset, p1, p2)


# ---------------------------------------------------------------- punch-through


@pytest.mark.parametrize("preset", ["fastest", "medium", "exhaustive"])
def test_punch_through_keeps_coverage_at_the_cutoff(preset, rng):
    img = load_rgba8("rgba/ldr-rgba-01.png", (40, 44)).copy()
    img[:4, :4, 3] = 0  # one block all transparent
    img[4:8, :4, 3] = 255  # one all opaque
    for thr in (128, 1, 200):
        data = A1.encode(img, preset, threads=1, alpha_threshold=thr)
        dec = A1.decode(data, 44, 40)
        assert np.array_equal(dec[..., 3] == 255, img[..., 3] >= thr), thr
        assert (dec[..., 3] % 255 == 0).all()
        assert np.array_equal(dec[..., 3], t2d("etc2a1", data, 44, 40)[..., 3])
    # where every texel is opaque, the RGB quality stays near etc2's
    opaque = np.full_like(img, 255)
    opaque[..., :3] = img[..., :3]
    pa = psnr(A1.decode(A1.encode(opaque, preset, threads=1), 44, 40)[..., :3], img[..., :3])
    pb = psnr(ETC2.decode(ETC2.encode(opaque, preset, threads=1), 44, 40)[..., :3], img[..., :3])
    assert pa >= pb - 0.5, (pa, pb)


def test_punch_through_all_transparent_and_all_opaque(rng):
    img = rng.integers(0, 256, (8, 8, 4), dtype=np.uint8)
    img[..., 3] = 0
    dec = A1.decode(A1.encode(img, "fast", threads=1), 8, 8)
    assert (dec == 0).all()
    img[..., 3] = 255
    img[..., :3] = (10, 200, 90)
    dec = A1.decode(A1.encode(img, "fast", threads=1), 8, 8)
    assert (dec[..., 3] == 255).all()
    assert int(block_sse(img, dec).max()) <= 16 * 3 * 4  # a flat colour held within 2 levels a channel


def test_punch_through_colour_of_the_opaque_texels(rng):
    # half of each block cut out: the opaque half's colour still fits closely
    img = load_rgba8("rgb/ldr-rgb-03.png", (32, 32)).copy()
    img[:, 0::4, 3] = 0
    img[:, 1::4, 3] = 0
    dec = A1.decode(A1.encode(img, "medium", threads=1), 32, 32)
    keep = img[..., 3] == 255
    d = dec[keep][:, :3].astype(float) - img[keep][:, :3]
    assert 10 * np.log10(255.0 ** 2 / np.mean(d * d)) > 30.0


# ---------------------------------------------------------------- hard cases


@pytest.mark.parametrize("preset", ["fastest", "thorough"])
def test_constant_and_two_colour_blocks(preset, rng):
    colours = rng.integers(0, 256, (24, 3))
    img = np.full((4, 4 * 24, 4), 255, np.uint8)
    for i, c in enumerate(colours):
        img[:, 4 * i:4 * i + 4, :3] = c
    e1 = block_sse(img, ETC1.decode(ETC1.encode(img, preset, threads=1), img.shape[1], 4))
    e2 = block_sse(img, ETC2.decode(ETC2.encode(img, preset, threads=1), img.shape[1], 4))
    assert (e2 <= e1).all()
    # two colours in a diagonal pattern no ETC1 split follows: T or H holds them
    two = np.full((4, 4 * 12, 4), 255, np.uint8)
    for i in range(12):
        a, b = rng.integers(0, 256, (2, 3))
        blk = two[:, 4 * i:4 * i + 4]
        for y in range(4):
            for x in range(4):
                blk[y, x, :3] = a if (x + y) % 2 else b
    d1 = block_sse(two, ETC1.decode(ETC1.encode(two, preset, threads=1), two.shape[1], 4))
    data = ETC2.encode(two, preset, threads=1)
    d2 = block_sse(two, ETC2.decode(data, two.shape[1], 4))
    assert (d2 <= d1).all()
    if preset == "thorough":
        assert d2.sum() < 0.5 * d1.sum()


@pytest.mark.parametrize("shape", [(1, 1), (6, 10), (5, 4)])
@pytest.mark.parametrize("fmt", ["etc2", "etc2a1"])
def test_small_and_partial_images(shape, fmt, rng):
    codec = texcook.codecs.get(fmt)
    h, w = shape
    img = rng.integers(0, 256, (h, w, 4), dtype=np.uint8)
    data = codec.encode(img, "medium", threads=1)
    assert len(data) == codec.level_size(w, h)
    dec = codec.decode(data, w, h)
    assert dec.shape == (h, w, 4)
    ph, pw = -(-h // 4) * 4, -(-w // 4) * 4
    padded = np.pad(img, ((0, ph - h), (0, pw - w), (0, 0)), mode="edge")
    assert codec.encode(padded, "medium", threads=1) == data


def test_same_bytes_whatever_the_thread_count():
    img = load_rgba8("rgba/ldr-rgba-02.png", (64, 96))
    for fmt in ("etc2", "etc2a1"):
        codec = texcook.codecs.get(fmt)
        one = codec.encode(img, "fast", threads=1)
        assert codec.encode(img, "fast", threads=2) == one == codec.encode(img, "fast", threads=3)


def test_colour_blocks_entry_point_is_the_codecs():
    img = load_rgba8("rgb/ldr-rgb-04.png", (32, 32))
    blocks = image_to_blocks(img, 4, 4)
    out = np.zeros((blocks.shape[0], 8), np.uint8)
    encode_colour_blocks(blocks, out, "fast", 2, weights=(0.3, 0.6, 0.1))
    assert out.tobytes() == ETC2.encode(img, "fast", threads=1, weights=(0.3, 0.6, 0.1))


def test_weights_lower_the_weighted_error():
    img = load_rgba8("rgb/ldr-rgb-04.png", (64, 64))
    wts = np.array([0.299, 0.587, 0.114])

    def werr(dec):
        d = dec[:, :, :3].astype(np.float64) - img[:, :, :3]
        return float((d * d * wts).sum())

    plain = ETC2.decode(ETC2.encode(img, "fast", threads=1), 64, 64)
    weighted = ETC2.decode(ETC2.encode(img, "fast", threads=1, weights=tuple(wts)), 64, 64)
    assert werr(weighted) < werr(plain)


# ---------------------------------------------------------------- quality


def test_quality_floors_against_etcpak():
    img = load_rgba8("rgb/ldr-rgb-01.png", (96, 96))
    ref = psnr(t2d("etc2", etcpak_encode("etc2", img), 96, 96)[..., :3], img[..., :3])
    scores = {p: psnr(t2d("etc2", ETC2.encode(img, p, threads=1), 96, 96)[..., :3], img[..., :3])
              for p in ALL_PRESETS}
    assert scores["fastest"] >= ref
    assert scores["medium"] >= ref + 1.0
    assert scores["exhaustive"] >= ref + 1.5
    for lo, hi in zip(ALL_PRESETS, ALL_PRESETS[1:]):
        assert scores[hi] >= scores[lo] - 0.05, scores


# ---------------------------------------------------------------- files


@pytest.mark.parametrize("fmt", ["etc2", "etc2a1"])
def test_bake_to_ktx2_read_by_ktx_parse_and_decoded(fmt, tmp_path, cli_run, ktx_parse):
    src = tmp_path / "s.png"
    img = load_rgba8("rgba/ldr-rgba-00.png", (20, 28))
    write_image(src, img)
    out = tmp_path / "o.ktx2"
    code, _, err = cli_run("bake", src, "-o", out, "--format", fmt, "--preset", "fast")
    assert code == 0, err
    (rec,) = ktx_parse([out])
    assert "error" not in rec, rec
    assert rec["vkFormat"] in ((147, 148) if fmt == "etc2" else (149, 150))
    assert rec["colorModel"] == 161
    channels = [s["channelType"] & 15 for s in rec["samples"]]
    assert channels == ([2] if fmt == "etc2" else [2, 15])
    assert [s["bitOffset"] for s in rec["samples"]] == [0] * len(channels)
    base = base64.b64decode(rec["levels"][0]["data"])
    png = tmp_path / "d.png"
    code, _, err = cli_run("decode", out, "-o", png)
    assert code == 0, err
    from texcook.pipeline import load_texture

    back = load_texture(png).levels[0]
    codec = texcook.codecs.get(fmt)
    assert np.array_equal(back, codec.decode(base, 28, 20))


def test_dds_is_refused_in_one_line(tmp_path, cli_run):
    src = tmp_path / "s.png"
    write_image(src, np.zeros((8, 8, 3), np.uint8))
    for fmt in ("etc2", "etc2a1"):
        code, _, err = cli_run("bake", src, "-o", tmp_path / "x.dds", "--format", fmt)
        assert code == 2 and len(err.strip().splitlines()) == 1 and "DDS" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.png"]


def test_punch_through_coverage_held_at_the_cutoff_down_the_chain():
    """An etc2a1 bake with --alpha-cutoff: in every level the share of opaque
    texels is level 0's share of texels at or above the cutoff (the chain's
    coverage scaling, then the 1-bit threshold at the same cutoff)."""
    from texcook.image import read_image
    from texcook.pipeline import bake
    from texcook.recipe import Recipe

    from conftest import CORPUS

    image = read_image(CORPUS / "rgba" / "ldr-rgba-01.png")
    baked = bake(image, Recipe.of(format="etc2a1", preset="fast", alpha_cutoff=0.5), threads=1)
    want = float((np.asarray(image.pixels)[..., 3] >= 0.5).mean())
    w, h = baked.width, baked.height
    for level, data in enumerate(baked.levels):
        lw, lh = max(1, w >> level), max(1, h >> level)
        if lw * lh < 64:
            break  # a few texels cannot hold a share to within a few percent
        got = float((A1.decode(data, lw, lh)[..., 3] == 255).mean())
        assert abs(got - want) <= max(0.03, 1.5 / (lw * lh)), (level, got, want)
