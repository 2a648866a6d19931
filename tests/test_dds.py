"""DDS writer/reader: header fields, both header styles, mips, errors, and
OpenImageIO reading what we write with a decode that matches ours."""

import struct
from pathlib import Path

import numpy as np
import pytest

from texcook import codecs
from texcook.container.dds import read_dds, write_dds
from texcook.errors import ContainerError, UsageError

CORPUS = Path(__file__).resolve().parent.parent / "corpus"
FORMATS = ("bc1", "bc1a", "bc3", "bc4", "bc5")


@pytest.fixture
def rng():
    return np.random.default_rng(99)


def image(rng, h=40, w=24):
    import OpenImageIO as oiio

    px = oiio.ImageBuf(str(CORPUS / "rgba/ldr-rgba-00.png")).get_pixels(oiio.UINT8)
    return np.ascontiguousarray(px[100:100 + h, 80:80 + w, :4])


def chain(fmt, img, n):
    c = codecs.get(fmt)
    levels = []
    for i in range(n):
        sub = np.ascontiguousarray(img[:: 1 << i, :: 1 << i][: max(1, img.shape[0] >> i), : max(1, img.shape[1] >> i)])
        levels.append(c.encode(sub, "fast", threads=1))
    return levels


@pytest.mark.parametrize("dx10", [False, True])
@pytest.mark.parametrize("fmt", FORMATS)
def test_round_trip_and_header(rng, fmt, dx10):
    img = image(rng)
    levels = chain(fmt, img, 6)
    data = write_dds(fmt, 24, 40, levels, srgb=False, dx10=dx10)
    assert data[:4] == b"DDS "
    size, flags, h, w, linear, depth, mips = struct.unpack_from("<7I", data, 4)
    assert (size, h, w, linear, mips) == (124, 40, 24, len(levels[0]), 6)
    assert flags & 0x20000 and flags & 0x80000
    fourcc = data[84:88]
    caps = struct.unpack_from("<I", data, 108)[0]
    assert caps & 0x401008 == 0x401008  # texture, complex, mipmap
    if dx10:
        assert fourcc == b"DX10"
        dxgi = struct.unpack_from("<I", data, 128)[0]
        assert dxgi == {"bc1": 71, "bc1a": 71, "bc3": 77, "bc4": 80, "bc5": 83}[fmt]
        head = 148
    else:
        assert fourcc == {"bc1": b"DXT1", "bc1a": b"DXT1", "bc3": b"DXT5", "bc4": b"ATI1", "bc5": b"ATI2"}[fmt]
        head = 128
    assert len(data) == head + sum(len(x) for x in levels)
    name, w2, h2, lv2, srgb = read_dds(data, "t.dds")
    assert (name, w2, h2, srgb) == (fmt, 24, 40, False)
    assert lv2 == levels


def test_srgb_uses_dx10(rng):
    img = image(rng)
    for fmt, dxgi in (("bc1", 72), ("bc3", 78)):
        data = write_dds(fmt, 24, 40, chain(fmt, img, 1), srgb=True)
        assert data[84:88] == b"DX10" and struct.unpack_from("<I", data, 128)[0] == dxgi
        assert read_dds(data)[4] is True
        size_flags = struct.unpack_from("<I", data, 8)[0]
        assert not size_flags & 0x20000  # one level: no mip count flag
    with pytest.raises(UsageError):
        write_dds("bc4", 24, 40, chain("bc4", img, 1), srgb=True)


def test_write_errors(rng):
    img = image(rng)
    lv = chain("bc1", img, 2)
    with pytest.raises(UsageError):
        write_dds("rgba8", 24, 40, lv, False)
    with pytest.raises(UsageError):
        write_dds("bc1", 24, 40, [lv[0][:-8]], False)
    with pytest.raises(UsageError):
        write_dds("bc1", 24, 40, [], False)
    with pytest.raises(UsageError):
        write_dds("bc1", 1, 1, [bytes(8), bytes(8)], False)


def test_read_errors(rng):
    good = write_dds("bc3", 24, 40, chain("bc3", image(rng), 3), False)
    bad = [
        (b"PNG " + good[4:], "magic"),
        (good[:100], "truncated DDS header"),
        (good[:-1], "truncated DDS data"),
        (good[:84] + b"XYZW" + good[88:], "FourCC"),
        (good[:4] + struct.pack("<I", 100) + good[8:], "header size"),
    ]
    for data, words in bad:
        with pytest.raises(ContainerError) as exc:
            read_dds(data, "x.dds")
        msg = str(exc.value)
        assert words in msg and "\n" not in msg and msg.startswith("x.dds: ")


@pytest.mark.parametrize("dx10", [False, True])
@pytest.mark.parametrize("fmt", FORMATS)
def test_openimageio_reads_what_we_write(tmp_path, rng, fmt, dx10):
    """OpenImageIO's DDS reader decodes our files; its BC interpolation rounds to
    nearest where ours truncates, so texels may differ by at most 1."""
    import OpenImageIO as oiio
    img = image(rng)
    levels = chain(fmt, img, 3)
    path = tmp_path / f"t_{fmt}.dds"
    path.write_bytes(write_dds(fmt, 24, 40, levels, srgb=False, dx10=dx10))
    buf = oiio.ImageBuf(str(path))
    assert not buf.has_error, buf.geterror()
    assert (buf.spec().width, buf.spec().height, buf.nmiplevels) == (24, 40, 3)
    px = buf.get_pixels(oiio.UINT8)
    c = codecs.get(fmt)
    ours = c.decode(levels[0], 24, 40)
    nch = {"bc4": 1, "bc5": 2}.get(fmt, 4)
    assert px.shape == (40, 24, nch)
    diff = np.abs(px.astype(int) - ours[:, :, :nch].astype(int))
    assert diff.max() <= 1
    # a mip level reads back too
    mip = oiio.ImageBuf(str(path), 0, 1)
    assert (mip.spec().width, mip.spec().height) == (12, 20)
    m = np.abs(mip.get_pixels(oiio.UINT8).astype(int) - c.decode(levels[1], 12, 20)[:, :, :nch].astype(int))
    assert m.max() <= 1


def test_bc1_dds_never_decodes_transparent(tmp_path):
    """Direct3D (and OpenImageIO) read BC1's 3-colour black as transparent; a
    plain bc1 .dds from the pipeline must stay opaque, while KTX2 output may use
    that entry (Vulkan's BC1_RGB reads it opaque)."""
    import OpenImageIO as oiio

    from texcook.image import write_image
    from texcook.pipeline import Recipe, bake_file

    # black beside two colours off the line through black: the 3-colour black
    # entry fits these blocks exactly
    k = (np.arange(32)[:, None] + np.arange(32)[None, :]) % 3
    palette = np.array([[0, 0, 0], [200, 40, 40], [40, 200, 40]], np.uint8)
    px = palette[k]
    src = tmp_path / "dark.png"
    write_image(src, px)
    recipe = Recipe.of(format="bc1", preset="thorough", mips=False, srgb=False)
    bake_file(src, tmp_path / "t.dds", recipe)
    alpha = oiio.ImageBuf(str(tmp_path / "t.dds")).get_pixels(oiio.UINT8)[..., 3]
    assert alpha.min() == 255
    bake_file(src, tmp_path / "t.ktx2", recipe)
    from texcook.container.ktx2 import read_ktx2

    from reference import bc1_decode_block

    blocks = np.frombuffer(read_ktx2((tmp_path / "t.ktx2").read_bytes()).levels[0], np.uint8).reshape(-1, 8)
    uses_black = []
    for b in blocks:
        _, four_colour, bits = bc1_decode_block(b)
        uses_black.append(not four_colour and any((bits >> (2 * k)) & 3 == 3 for k in range(16)))
    assert any(uses_black), "the test image no longer exercises the black entry"
