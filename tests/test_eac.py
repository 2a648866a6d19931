"""EAC (eac-r11, eac-rg11) and RGBA ETC2 (etc2a8): tables against the spec,
decoders against texture2ddecoder, encoder hard cases, quality floors against
our BC4/BC5 and etcpak, and bakes read back by ktx-parse and `texcook decode`."""

import numpy as np
import pytest

import texcook.codecs
from texcook.codecs.eac import SEARCH
from texcook.codecs.eac_tables import MODIFIERS
from texcook.metrics import normal_angular_error, psnr
from conftest import encoded_image, load_rgba8
from decoders import etcpak_encode, t2d, t2d_eac_signed

R11 = texcook.codecs.get("eac-r11")
RG11 = texcook.codecs.get("eac-rg11")
A8 = texcook.codecs.get("etc2a8")
BC4 = texcook.codecs.get("bc4")
BC5 = texcook.codecs.get("bc5")
PRESETS = list(SEARCH.presets)
QUICK = PRESETS[:4]  # exhaustive only on small crops


def _channel_image(img, ch):
    """One channel of img in red, the rest as a BC4/EAC R11 bake leaves them."""
    out = np.zeros_like(img)
    out[..., 0] = img[..., ch]
    out[..., 3] = 255
    return out


def _random_blocks(rng, n):
    """n random 8-byte EAC blocks with the edge cases forced into some: a
    multiplier of 0, base codewords 0, 255, 0x80 (-128 signed) and 0x7F, and
    the widest table at the largest multiplier (both clamps)."""
    b = rng.integers(0, 256, (n, 8), dtype=np.uint8)
    b[0::7, 1] &= 0x0F  # multiplier 0
    b[1::7, 0] = 0x80
    b[2::7, 0] = rng.choice([0, 255, 0x7F, 0x81], size=b[2::7].shape[0])
    b[3::7, 1] = 0xF0  # multiplier 15, table 0
    b[4::7, 0] = 0x80
    b[4::7, 1] &= 0x0F
    return b


# ---------------------------------------------------------------- interface


def test_format_rows():
    assert (R11.vk_unorm, R11.format.vk_snorm, R11.bytes_per_block, R11.channels) == (153, 154, 8, 1)
    assert (RG11.vk_unorm, RG11.format.vk_snorm, RG11.bytes_per_block, RG11.channels) == (155, 156, 16, 2)
    assert (A8.vk_unorm, A8.vk_srgb, A8.bytes_per_block, A8.channels) == (151, 152, 16, 4)
    assert R11.format.dfd_channels == (0,) and RG11.format.dfd_channels == (0, 1)
    assert A8.format.dfd_channels == (15, 2)
    assert R11.format.dxgi == RG11.format.dxgi == A8.format.dxgi == 0
    assert [o.name for o in RG11.options] == ["angular"] and [o.name for o in A8.options] == ["weights"]


def test_spec_examples():
    # KDF "RGBA ETC2" alpha: base 103, table 13, index 3, multiplier 2 -> 103 - 20 = 83
    blk = np.zeros(16, np.uint8)
    blk[0], blk[1] = 103, (2 << 4) | 13
    idx = 3 << 45  # texel a (0, 0)
    blk[2:8] = [(idx >> (40 - 8 * k)) & 255 for k in range(6)]
    blk[8:] = [0, 0, 0, 0, 0, 0, 0, 0]  # an ETC1 block of black
    dec = A8.decode(blk.tobytes(), 4, 4)
    assert dec[0, 0, 3] == 83 and dec[1, 0, 3] == 103 - 2 * 1  # texel b: index 0 -> -1
    assert np.array_equal(dec, t2d("etc2a8", blk.tobytes(), 4, 4))
    # every table holds its row of the spec (also checked on decodes below)
    assert MODIFIERS.shape == (16, 8) and MODIFIERS[13].tolist() == [-1, -2, -3, -10, 0, 1, 2, 9]
    assert (MODIFIERS[:, :4] < 0).all() and (MODIFIERS[:, 4:] >= 0).all()


# ---------------------------------------------------------------- decoders


@pytest.mark.parametrize("codec", [R11, RG11], ids=["r11", "rg11"])
def test_decoder_matches_texture2ddecoder_on_random_blocks(codec, rng):
    n = 48 * 40 // 16
    data = _random_blocks(rng, n * codec.bytes_per_block // 8).tobytes()
    assert np.array_equal(codec.decode(data, 48, 40), t2d(codec.name, data, 48, 40))


@pytest.mark.parametrize("codec", [R11, RG11], ids=["r11", "rg11"])
def test_signed_decoder_against_texture2ddecoder(codec, rng):
    n = 64 * 64 // 16
    raw = _random_blocks(rng, n * codec.bytes_per_block // 8)
    ours = codec.decode(raw.tobytes(), 64, 64, signed=True)
    # texture2ddecoder reads the base codeword -128 as -128, the spec as -127:
    # with every -128 written as -127 the two agree texel for texel
    legal = raw.copy()
    legal[legal[:, 0] == 0x80, 0] = 0x81
    assert np.array_equal(ours, t2d_eac_signed(codec.name, legal.tobytes(), 64, 64))
    assert np.array_equal(codec.decode(legal.tobytes(), 64, 64, signed=True), ours)
    theirs = t2d_eac_signed(codec.name, raw.tobytes(), 64, 64)
    assert not np.array_equal(ours, theirs)  # the -128 blocks are there and differ
    # the clamps: base 127, modifier +14 (index 7) at multiplier 15 -> 1023 -> 255
    blk = bytes([0x7F, 0xF0, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF]) * (codec.bytes_per_block // 8)
    assert (codec.decode(blk, 4, 4, signed=True)[..., 0] == 255).all()
    # base -127, modifier -15 (index 3) at multiplier 15 -> -1023 -> 0
    blk = bytes([0x81, 0xF0, 0x6D, 0xB6, 0xDB, 0x6D, 0xB6, 0xDB]) * (codec.bytes_per_block // 8)
    assert (codec.decode(blk, 4, 4, signed=True)[..., 0] == 0).all()


def test_decoders_agree_on_our_and_etcpaks_streams(rng):
    img = load_rgba8("rgb/ldr-rgb-03.png", (32, 48))
    noise = rng.integers(0, 256, (12, 20, 4), dtype=np.uint8)
    for src in (img, noise):
        h, w = src.shape[:2]
        for codec in (R11, RG11, A8):
            for preset in PRESETS if src is noise else QUICK:
                data = codec.encode(src, preset, threads=1)
                assert np.array_equal(codec.decode(data, w, h), t2d(codec.name, data, w, h)), (codec.name, preset)
        for name, codec in (("eac-r11", R11), ("eac-rg11", RG11)):
            data = etcpak_encode(name, src)
            assert np.array_equal(codec.decode(data, w, h), t2d(name, data, w, h)), name
        data = etcpak_encode("etc2a8", src)  # colour blocks in every ETC2 mode
        assert np.array_equal(A8.decode(data, w, h), t2d("etc2a8", data, w, h))


def test_etc2a8_decoder_on_random_blocks(rng):
    # random colour halves cover every ETC2 mode, random alpha halves every table
    data = rng.integers(0, 256, (32 * 32 // 16, 16), dtype=np.uint8)
    data[0::5, 1] &= 0x0F  # multiplier 0: every texel is the base
    assert np.array_equal(A8.decode(data.tobytes(), 32, 32), t2d("etc2a8", data.tobytes(), 32, 32))


# ---------------------------------------------------------------- hard cases


@pytest.mark.parametrize("preset", ["fastest", "exhaustive"])
def test_every_constant_value_decodes_exactly(preset):
    img = np.zeros((4, 4 * 256, 4), np.uint8)
    img[..., :] = np.repeat(np.arange(256, dtype=np.uint8), 4)[None, :, None]
    for codec in (R11, RG11, A8):
        dec = codec.decode(codec.encode(img, preset, threads=1), img.shape[1], img.shape[0])
        for c in range(codec.channels if codec is not A8 else 0):
            assert np.array_equal(dec[..., c], img[..., c]), codec.name
        if codec is A8:
            assert np.array_equal(dec[..., 3], img[..., 3])
            raw = np.frombuffer(codec.encode(img, preset, threads=1), np.uint8).reshape(-1, 16)
            assert (raw[:, 1] >> 4 > 0).all()  # RGBA ETC2 encoders must not write multiplier 0


@pytest.mark.parametrize("preset", PRESETS)
def test_two_values_and_extremes(preset, rng):
    pairs = [(0, 255), (0, 1), (254, 255), (10, 200), (128, 129)] + \
        [tuple(p) for p in rng.integers(0, 256, (11, 2))]
    img = np.zeros((4, 4 * len(pairs), 4), np.uint8)
    for i, (a, b) in enumerate(pairs):
        img[:, 4 * i: 4 * i + 4, :] = a
        img[::2, 4 * i: 4 * i + 4, :] = b
    for codec, ch in ((R11, 0), (A8, 3)):
        dec = codec.decode(codec.encode(img, preset, threads=1), img.shape[1], img.shape[0])
        err = np.abs(dec[..., ch].astype(int) - img[..., ch])
        # two values a modifier pair of some table spans within the clamps: exact
        # for 0/255 and neighbours; no pair costs more than a few levels
        for i, (a, b) in enumerate(pairs):
            e = err[:, 4 * i: 4 * i + 4]
            if abs(a - b) <= 1 or {a, b} == {0, 255}:
                assert e.max() == 0, (codec.name, a, b)
            assert e.max() <= 8, (codec.name, a, b)


@pytest.mark.parametrize("shape", [(1, 1), (5, 7), (6, 10), (3, 4)])
def test_small_and_partial_images(shape, rng):
    h, w = shape
    img = rng.integers(0, 256, (h, w, 4), dtype=np.uint8)
    for codec in (R11, RG11, A8):
        data = codec.encode(img, "medium", threads=1)
        assert len(data) == codec.level_size(w, h)
        dec = codec.decode(data, w, h)
        assert dec.shape == (h, w, 4)
        assert np.array_equal(dec, t2d(codec.name, data, w, h))
        if shape == (1, 1):
            chans = [3] if codec is A8 else list(range(codec.channels))
            assert (dec[0, 0, chans] == img[0, 0, chans]).all(), codec.name  # one value: exact


def test_all_transparent_etc2a8():
    img = np.zeros((8, 12, 4), np.uint8)
    img[..., :3] = (200, 40, 90)
    dec = A8.decode(A8.encode(img, "fast", threads=1), 12, 8)
    assert (dec[..., 3] == 0).all()


def test_same_bytes_whatever_the_thread_count():
    img = load_rgba8("rgba/ldr-rgba-01.png", (64, 96))
    for codec, opts in ((R11, {}), (RG11, {"angular": True}), (A8, {})):
        one = codec.encode(img, "fast", threads=1, **opts)
        assert codec.encode(img, "fast", threads=2, **opts) == one
        assert codec.encode(img, "fast", threads=3, **opts) == one


# ---------------------------------------------------------------- quality


def test_r11_at_or_above_bc4_and_etcpak():
    # a crop with texture and smooth parts (on smooth ones alone BC4's free
    # endpoints can do better than EAC's fixed tables: docs/etc.md)
    img = load_rgba8("rgb/ldr-rgb-01.png", (128, 128))
    for ch in (0, 1):
        src = _channel_image(img, ch)
        etcpak = psnr(t2d("eac-r11", etcpak_encode("eac-r11", src), 128, 128)[..., 0], src[..., 0])
        scores = []
        for preset in PRESETS:
            crop = src if preset != "exhaustive" else src[64:96, 64:96].copy()
            h, w = crop.shape[:2]
            ours = psnr(R11.decode(R11.encode(crop, preset, threads=1), w, h)[..., 0], crop[..., 0])
            bc4 = psnr(BC4.decode(BC4.encode(crop, preset, threads=1), w, h)[..., 0], crop[..., 0])
            assert ours >= bc4, (ch, preset, ours, bc4)
            if preset != "exhaustive":
                assert ours >= etcpak + 0.5, (ch, preset, ours, etcpak)
                scores.append(ours)
        assert scores == sorted(scores), scores  # a wider search never does worse


@pytest.mark.parametrize("name,angular", [("normal/ldr-xy-00.png", False), ("normal/ldr-xy-00.png", True),
                                          ("normal/ldr-xy-01.png", True)])
def test_rg11_normal_maps_angular_error_at_most_bc5(name, angular):
    # normal maps with detail; on smooth ones (ldr-xy-02) BC5 is ahead: docs/etc.md
    img = load_rgba8(name, (48, 64))
    h, w = img.shape[:2]
    for preset in ("fastest", "medium", "thorough"):
        ours = RG11.decode(RG11.encode(img, preset, threads=1, angular=angular), w, h)
        bc5 = BC5.decode(BC5.encode(img, preset, threads=1, angular=angular), w, h)
        mine, theirs = normal_angular_error(ours, img)[0], normal_angular_error(bc5, img)[0]
        assert mine <= theirs, (preset, angular, mine, theirs)
    if angular:
        plain = RG11.decode(RG11.encode(img, "thorough", threads=1), w, h)
        assert normal_angular_error(ours, img)[0] < normal_angular_error(plain, img)[0]


def test_etc2a8_alpha_at_or_above_etcpak():
    for name in ("rgba/ldr-rgba-00.png", "rgba/ldr-rgba-01.png", "rgba/ldr-rgba-02.png"):
        img = load_rgba8(name, (64, 64))
        theirs = psnr(t2d("etc2a8", etcpak_encode("etc2a8", img), 64, 64)[..., 3], img[..., 3])
        for preset in QUICK:
            dec = A8.decode(A8.encode(img, preset, threads=1), 64, 64)
            assert psnr(dec[..., 3], img[..., 3]) >= theirs, (name, preset)


# ---------------------------------------------------------------- files


@pytest.mark.parametrize("fmt", ["eac-r11", "eac-rg11", "etc2a8"])
def test_bake_to_ktx2_read_by_ktx_parse_and_decoded(fmt, tmp_path, cli_run, ktx_parse):
    from texcook.container.ktx2 import read_ktx2
    from texcook.image import read_image

    img = load_rgba8("rgba/ldr-rgba-01.png", (20, 28))
    src, out, back = tmp_path / "src.png", tmp_path / "t.ktx2", tmp_path / "back.png"
    src.write_bytes(encoded_image(img))
    code, _, err = cli_run("bake", src, "-o", out, "--format", fmt, "--linear", "--preset", "fast")
    assert code == 0, err
    (rec,) = ktx_parse([out])
    assert "error" not in rec and rec["vkFormat"] == texcook.codecs.get(fmt).vk_unorm
    assert rec["colorModel"] == 161
    assert cli_run("decode", out, "-o", back)[0] == 0
    got = np.rint(read_image(back).pixels * 255).astype(np.uint8)
    # texcook's decode of the file is texture2ddecoder's of its first level
    level0 = t2d(fmt, read_ktx2(out.read_bytes(), str(out)).levels[0], 28, 20)
    channels = texcook.codecs.get(fmt).channels
    assert got.shape[:2] == (20, 28)
    assert np.array_equal(got[..., :channels], level0[..., :channels])


@pytest.mark.parametrize("fmt", ["eac-r11", "eac-rg11", "etc2a8"])
def test_dds_refused_with_one_line(fmt, tmp_path, cli_run):
    code, _, stderr = cli_run("bake", tmp_path / "missing.png", "-o", tmp_path / "x.dds", "--format", fmt)
    assert code == 2 and "cannot be written to DDS" in stderr and stderr.count("\n") == 1
    assert not (tmp_path / "x.dds").exists()
