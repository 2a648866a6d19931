"""BC7: decoder against texture2ddecoder (every mode, the reserved mode, our and
etcpak's streams), the symbolic block and its bits, encoder hard cases, exact
error bookkeeping, threads, weights, quality floors, and files through the CLI."""

import struct

import numpy as np
import pytest

from texcook import codecs
from texcook.codecs import bc7_kernels as k7
from texcook.codecs import bc7_search, bc7_tables
from texcook.codecs.bc7 import SEARCH, channel_weights
from texcook.metrics import psnr
from conftest import load_rgba8
from decoders import etcpak_encode, t2d
from reference import block_row

PRESETS = ("fastest", "fast", "medium", "thorough", "exhaustive")


@pytest.fixture
def rng():
    return np.random.default_rng(77)


def blocks_of_mode(rng, n, mode):
    """n random blocks whose first bits say `mode` (8: the reserved first byte 0)."""
    d = rng.integers(0, 256, (n, 16), dtype=np.uint8)
    if mode == 8:
        d[:, 0] = 0
    else:
        d[:, 0] = (d[:, 0] & ~np.uint8((2 << mode) - 1) & 0xFF) | np.uint8(1 << mode)
    return d


def decode_blocks(data):
    """Our decode of a row of blocks -> (n, 16, 4)."""
    d = np.frombuffer(bytes(data), np.uint8).reshape(-1, 16)
    out = np.zeros((len(d), 16, 4), np.uint8)
    k7.decode_run(d, out)
    return out


# ---------------------------------------------------------------- decoding


@pytest.mark.parametrize("mode", range(9))
def test_random_blocks_decode_like_texture2ddecoder(rng, mode):
    n = 2000
    d = blocks_of_mode(rng, n, mode)
    ours = codecs.get("bc7").decode(d.tobytes(), 4 * n, 4)
    assert np.array_equal(ours, t2d("bc7", d.tobytes(), 4 * n, 4))
    if mode == 8:
        # the specification's reserved mode: 0 in every channel, alpha too
        # (texture2ddecoder agrees; the spec lets hardware return alpha 1.0)
        assert not ours.any()


def test_mode_field_decides_the_layout(rng):
    """Every mode's fields fill exactly 128 bits, and unpacking then packing a
    block gives its bytes back (anchor indices carry one bit fewer)."""
    for mode in range(8):
        m = bc7_tables.MODES[mode]
        ns = m[bc7_tables.NS]
        nch = 4 if m[bc7_tables.AB] else 3
        bits = (mode + 1 + m[bc7_tables.PB] + m[bc7_tables.RB] + m[bc7_tables.ISB]
                + 2 * ns * (3 * m[bc7_tables.CB] + (nch - 3) * m[bc7_tables.AB])
                + 2 * ns * m[bc7_tables.EPB] + ns * m[bc7_tables.SPB]
                + 16 * m[bc7_tables.IB] - ns + (16 * m[bc7_tables.IB2] - 1 if m[bc7_tables.IB2] else 0))
        assert bits == 128, mode
        d = blocks_of_mode(rng, 500, mode)
        syms = np.zeros((500, k7.SYM_LEN), np.int64)
        k7.unpack_run(d, syms)
        assert (syms[:, k7.S_MODE] == mode).all()
        back = np.zeros_like(d)
        k7.pack_run(syms, back)
        assert np.array_equal(back, d)


def test_tables_are_consistent():
    t = bc7_tables
    for ns in (2, 3):
        for p in range(64):
            assert t.SUBSET[ns - 1, p, 0] == 0
            for s in range(1, ns):
                a = t.ANCHOR[ns - 1, p, s]
                assert t.SUBSET[ns - 1, p, a] == s
            assert sorted(set(t.SUBSET[ns - 1, p])) == list(range(ns))
    # the KDF's closed forms of the weight tables
    for i in range(4):
        assert t.WEIGHTS[2, i] == i * 21 + (i >> 1)
    for i in range(8):
        assert t.WEIGHTS[3, i] == i * 9 + (i >> 2)
    for i in range(16):
        assert t.WEIGHTS[4, i] == (i << 2) + (i >> 2) + ((i >> 1) & 1)
    # the first 32 two-subset partitions are BC6H's; one spot check of a
    # well-known shape: partition 13 is the top half against the bottom
    assert "".join(map(str, t.PARTITION2[13])) == "0000000011111111"


def test_peer_streams_decode_like_texture2ddecoder():
    for name in ("rgb/ldr-rgb-03.png", "rgba/ldr-rgba-01.png"):
        img = load_rgba8(name)[:64, :64].copy()
        data = etcpak_encode("bc7", img)
        assert np.array_equal(codecs.get("bc7").decode(data, 64, 64), t2d("bc7", data, 64, 64))


# ---------------------------------------------------------------- encoding


@pytest.mark.parametrize("preset", PRESETS)
def test_our_streams_decode_like_texture2ddecoder(preset):
    img = load_rgba8("rgba/ldr-rgba-00.png")[96:128, 96:160].copy()
    c = codecs.get("bc7")
    data = c.encode(img, preset, threads=1)
    assert np.array_equal(c.decode(data, 64, 32), t2d("bc7", data, 64, 32))


def test_search_error_is_the_decoded_error(rng):
    """The error the search reports is the weighted error of the packed block
    as decoded (so anchors were normalised without changing a texel), and
    the symbolic block decodes to the same texels as its bits."""
    img = np.concatenate([load_rgba8("rgba/ldr-rgba-02.png")[:16, :64], load_rgba8("rgb/ldr-rgb-06.png")[:16, :64]])
    from reference import image_blocks

    blocks = np.ascontiguousarray(image_blocks(img, 4, 4))
    n = len(blocks)
    w, sw = channel_weights((1.0, 2.0, 0.5))
    for preset in ("fast", "exhaustive"):
        syms = np.zeros((n, k7.SYM_LEN), np.int64)
        errs = np.zeros(n)
        data = np.zeros((n, 16), np.uint8)
        bc7_search.encode_run(blocks, data, w, sw, SEARCH.record(preset), syms, errs)
        raw = np.zeros((n, 16, 4), np.uint8)
        k7.decode_sym_run(syms, raw)
        dec = decode_blocks(data)
        assert np.array_equal(dec, raw)
        k7.normalise_run(syms)
        again = np.zeros((n, 16), np.uint8)
        k7.pack_run(syms, again)
        assert np.array_equal(again, data)
        want = (((dec.astype(float) - blocks) ** 2) * w).sum(axis=(1, 2))
        assert np.allclose(errs, want, rtol=1e-12, atol=1e-9)
        assert len(set(syms[:, k7.S_MODE])) > 1, preset


@pytest.mark.parametrize("preset", ["fastest", "exhaustive"])
def test_constant_blocks_exact(rng, preset):
    greys = np.repeat(np.arange(256, dtype=np.uint8)[:, None], 4, axis=1)
    colours = np.concatenate([greys, rng.integers(0, 256, (512, 4), dtype=np.uint8)])
    colours[256:384, 3] = 255
    blocks = np.repeat(colours[:, None, :], 16, axis=1)
    img = block_row(blocks)
    c = codecs.get("bc7")
    assert np.array_equal(c.decode(c.encode(img, preset, threads=1), img.shape[1], 4), img)


@pytest.mark.parametrize("opaque", [True, False])
def test_two_colour_blocks_exact(rng, opaque):
    # colours with every channel odd: mode 6 holds both exactly (p-bit 1)
    n = 48
    cols = (rng.integers(0, 128, (n, 2, 4)) * 2 + 1).astype(np.uint8)
    if opaque:
        cols[..., 3] = 255
    pick = rng.integers(0, 2, (n, 16))
    img = block_row(cols[np.arange(n)[:, None], pick])
    c = codecs.get("bc7")
    for preset in PRESETS:
        assert np.array_equal(c.decode(c.encode(img, preset, threads=1), 4 * n, 4), img), preset


def test_alpha_kinds(rng):
    img = rng.integers(0, 256, (16, 16, 4), dtype=np.uint8)
    c = codecs.get("bc7")
    transparent = img.copy()
    transparent[..., 3] = 0
    opaque = img.copy()
    opaque[..., 3] = 255
    for preset in PRESETS:
        assert not c.decode(c.encode(transparent, preset, threads=1), 16, 16)[..., 3].any()
        assert (c.decode(c.encode(opaque, preset, threads=1), 16, 16)[..., 3] == 255).all()


@pytest.mark.parametrize("shape", [(1, 1), (5, 3), (3, 5), (6, 10)])
def test_small_and_partial_images_edge_padded(rng, shape):
    h, w = shape
    img = rng.integers(0, 256, (h, w, 4), dtype=np.uint8)
    c = codecs.get("bc7")
    data = c.encode(img, "medium", threads=1)
    assert len(data) == c.level_size(w, h)
    padded = np.pad(img, ((0, -h % 4), (0, -w % 4), (0, 0)), mode="edge")
    assert data == c.encode(padded, "medium", threads=1)
    dec = c.decode(data, w, h)
    assert dec.shape == (h, w, 4)
    if shape == (1, 1):
        assert np.array_equal(dec, img)  # one texel is a constant block


def test_threads_same_bytes(many_chunks):
    img = load_rgba8("rgba/ldr-rgba-01.png")[:64, :64].copy()
    c = codecs.get("bc7")
    assert c.encode(img, "medium", threads=1) == c.encode(img, "medium", threads=2)


def test_weights_favour_a_channel():
    img = load_rgba8("rgb/ldr-rgb-05.png")[:64, :64].copy()
    c = codecs.get("bc7")
    plain = c.decode(c.encode(img, "fast", threads=1), 64, 64)
    green = c.decode(c.encode(img, "fast", threads=1, weights=(1, 8, 1)), 64, 64)
    assert psnr(img, green, channels=[1]) > psnr(img, plain, channels=[1])


def _trivial_fit_error(block):
    """Squared error of the trivial single-subset fit, written out plainly:
    mode 6 with the per-channel minimum and maximum as endpoints (7 bits and
    a p-bit, nearest stored value, the lower on ties), each endpoint's p-bit
    by its rounding error (0 on ties; a flat alpha's low bit when alpha is
    one value, which the encoder keeps exactly), each texel its nearest entry."""
    x = block.astype(np.int64)
    ends = [x.min(axis=0), x.max(axis=0)]

    def stored(v, p):
        q = np.clip((v - p) // 2, 0, 127)
        lower, upper = 2 * q + p, 2 * np.minimum(q + 1, 127) + p
        return np.where(np.abs(upper - v) < np.abs(lower - v), upper, lower)

    flat = (x[:, 3] == x[0, 3]).all()
    pal_ends = []
    for v in ends:
        if flat:
            p = x[0, 3] & 1
        else:
            p = 0 if ((stored(v, 0) - v) ** 2).sum() <= ((stored(v, 1) - v) ** 2).sum() else 1
        pal_ends.append(stored(v, p))
    wt = bc7_tables.WEIGHTS[4][:, None]
    pal = ((64 - wt) * pal_ends[0] + wt * pal_ends[1] + 32) >> 6
    return ((x[:, None, :] - pal[None]) ** 2).sum(axis=2).min(axis=1).sum()


@pytest.mark.parametrize("preset", ["fastest", "medium"])
def test_never_worse_than_the_trivial_fit(preset):
    from reference import image_blocks

    c = codecs.get("bc7")
    for name in ("rgb/ldr-rgb-02.png", "rgb/ldr-rgb-06.png", "rgba/ldr-rgba-00.png", "rgba/ldr-rgba-02.png"):
        img = load_rgba8(name)[:32, :64].copy()
        dec = image_blocks(c.decode(c.encode(img, preset, threads=1), 64, 32), 4, 4)
        for block, got in zip(image_blocks(img, 4, 4), dec):
            ours = ((block.astype(np.int64) - got) ** 2).sum()
            assert ours <= _trivial_fit_error(block), (name, block.tolist())


# ---------------------------------------------------------------- quality floors


def _rgba_psnr(img, dec):
    return psnr(img, dec, channels=[0, 1, 2, 3])


def test_quality_beats_bc3_and_bc1():
    bc7, bc3, bc1 = codecs.get("bc7"), codecs.get("bc3"), codecs.get("bc1")
    for name in ("rgba/ldr-rgba-00.png", "rgba/ldr-rgba-01.png", "rgba/ldr-rgba-02.png"):
        img = load_rgba8(name)[:64, :64].copy()
        s7 = _rgba_psnr(img, bc7.decode(bc7.encode(img, "medium", threads=1), 64, 64))
        s3 = _rgba_psnr(img, bc3.decode(bc3.encode(img, "medium", threads=1), 64, 64))
        assert s7 >= s3 + 3.0, (name, s7, s3)
    for name in ("rgb/ldr-rgb-00.png", "rgb/ldr-rgb-04.png", "rgb/ldr-rgb-08.png"):
        img = load_rgba8(name)[:64, :64].copy()
        s7 = psnr(img, bc7.decode(bc7.encode(img, "medium", threads=1), 64, 64), channels=[0, 1, 2])
        s1 = psnr(img, bc1.decode(bc1.encode(img, "medium", threads=1), 64, 64), channels=[0, 1, 2])
        assert s7 > s1, (name, s7, s1)


def test_quality_against_etcpak_and_across_presets():
    c = codecs.get("bc7")
    for name in ("rgb/ldr-rgb-02.png", "rgba/ldr-rgba-00.png"):
        img = load_rgba8(name)[:32, :64].copy()
        peer = _rgba_psnr(img, c.decode(etcpak_encode("bc7", img), 64, 32))
        scores = {p: _rgba_psnr(img, c.decode(c.encode(img, p, threads=1), 64, 32)) for p in PRESETS}
        assert scores["fast"] >= peer, (name, scores, peer)
        assert scores["exhaustive"] >= scores["medium"] >= scores["fastest"], (name, scores)


# ---------------------------------------------------------------- files


@pytest.mark.parametrize("srgb", [False, True])
def test_ktx2_bake_read_by_ktx_parse_and_decoded(tmp_path, cli_run, ktx_parse, srgb):
    src = tmp_path / "src.png"
    from texcook.image import read_image, write_image

    img = load_rgba8("rgba/ldr-rgba-01.png")[:36, :44].copy()
    write_image(src, img)
    out = tmp_path / "out.ktx2"
    flag = "--srgb" if srgb else "--linear"
    code, stdout, _ = cli_run("bake", src, "-o", out, "--format", "bc7", flag, "--preset", "fast", "--json")
    assert code == 0, stdout
    (rec,) = ktx_parse([out])
    assert "error" not in rec, rec
    assert rec["vkFormat"] == (146 if srgb else 145)
    assert rec["colorModel"] == 134 and rec["transferFunction"] == (2 if srgb else 1)
    assert rec["texelBlockDimension"] == [3, 3, 0, 0] and rec["bytesPlane"][0] == 16
    back = tmp_path / "back.png"
    assert cli_run("decode", out, "-o", back)[0] == 0
    got = read_image(back).integer_values()
    # the base level as our decoder (checked above against texture2ddecoder) reads it
    import base64

    level0 = base64.b64decode(rec["levels"][0]["data"])
    assert np.array_equal(got, codecs.get("bc7").decode(level0, 44, 36))
    assert _rgba_psnr(img, got) > 35


def test_dds_uses_the_dx10_header(tmp_path, cli_run):
    from texcook.container.dds import read_dds
    from texcook.image import write_image

    src = tmp_path / "src.png"
    write_image(src, load_rgba8("rgba/ldr-rgba-02.png")[:20, :24].copy())
    for flag, dxgi in (("--linear", 98), ("--srgb", 99)):
        out = tmp_path / "out.dds"
        code, stdout, _ = cli_run("bake", src, "-o", out, "--format", "bc7", flag, "--preset", "fastest")
        assert code == 0, stdout
        data = out.read_bytes()
        assert data[84:88] == b"DX10" and struct.unpack_from("<I", data, 128)[0] == dxgi
        name, w, h, levels, srgb = read_dds(data, "out.dds")
        assert (name, w, h, srgb) == ("bc7", 24, 20, flag == "--srgb")
        assert len(levels[0]) == 6 * 5 * 16


def test_openimageio_reads_our_dds_as_we_decode_it(tmp_path, cli_run):
    oiio = pytest.importorskip("OpenImageIO")
    from texcook.container.dds import read_dds
    from texcook.image import write_image

    src = tmp_path / "src.png"
    write_image(src, load_rgba8("rgba/ldr-rgba-00.png")[40:76, 60:104].copy())
    out = tmp_path / "out.dds"
    assert cli_run("bake", src, "-o", out, "--format", "bc7", "--linear", "--no-mips", "--preset", "fast")[0] == 0
    theirs = oiio.ImageBuf(str(out)).get_pixels(oiio.UINT8)
    _, w, h, levels, _ = read_dds(out.read_bytes(), "out.dds")
    assert np.array_equal(theirs, codecs.get("bc7").decode(levels[0], w, h))
