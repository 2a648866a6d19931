"""The format table and what derives from it: codecs, KTX2, DDS, the SAT, and
`texcook formats`."""

import json

import numpy as np
import pytest

from texcook import codecs, formats
from texcook.container import ktx2


def test_table_facts_are_consistent():
    vks = []
    for f in formats.FORMATS.values():
        if f.stored_as:  # shares the vkFormat of the format it is stored as
            stored = formats.get(f.stored_as)
            assert (f.vk_unorm, f.block_w, f.block_h, f.bytes_per_block, f.dfd_model) == (
                stored.vk_unorm, stored.block_w, stored.block_h, stored.bytes_per_block, stored.dfd_model)
            if not f.transform:  # blocks the stored format decodes as they are (etc1 in etc2)
                px = np.random.default_rng(1).integers(0, 256, (8, 8, 4), dtype=np.uint8)
                data = codecs.get(f.name).encode(px, "fastest")
                assert np.array_equal(codecs.get(f.name).decode(data, 8, 8), codecs.get(f.stored_as).decode(data, 8, 8))
            continue
        vks += [v for v in (f.vk_unorm, f.vk_srgb, f.vk_snorm) if v]
        assert f.sample in formats.SAMPLE_TYPES
        assert f.bytes_per_block % (1 if f.is_block_compressed else f.channels) == 0
        if f.dxgi_srgb:
            assert f.dxgi and f.vk_srgb
    assert len(vks) == len(set(vks)), "a vkFormat is listed twice"


def test_astc_family_is_generated():
    astc = [f for f in formats.FORMATS.values() if f.family == "astc"]
    assert len(astc) == 14
    assert [(f.vk_unorm, f.vk_srgb) for f in astc] == [(157 + 2 * i, 158 + 2 * i) for i in range(14)]
    assert formats.get("astc-12x12").bits_per_texel == pytest.approx(128 / 144)


def test_ktx2_derives_every_vkformat_from_the_table():
    for f in formats.FORMATS.values():
        for vk in (f.vk_unorm, f.vk_srgb, f.vk_snorm):
            if vk and not f.stored_as:
                info = ktx2.FORMATS[vk]
                assert (info.block_w, info.block_h, info.bytes_per_block) == (f.block_w, f.block_h, f.bytes_per_block)
                assert info.color_model == f.dfd_model
                assert info.srgb == (vk == f.vk_srgb)
    assert len(ktx2.FORMATS) == sum(bool(v) for f in formats.FORMATS.values() if not f.stored_as
                                    for v in (f.vk_unorm, f.vk_srgb, f.vk_snorm))


def test_codecs_take_their_facts_from_the_table():
    for name in codecs.names():
        c = codecs.get(name)
        f = formats.get(name)
        assert c.format is f
        assert (c.block_w, c.block_h, c.bytes_per_block, c.channels, c.vk_unorm, c.vk_srgb) == (
            f.block_w, f.block_h, f.bytes_per_block, f.channels, f.vk_unorm, f.vk_srgb)
        assert c.float_input == f.is_float
        if not f.vk_unorm:
            continue  # vkFormat 0 (ETC1S): KTX2 keys it by its DFD, not by a vkFormat
        back, srgb = codecs.by_vk_format(f.vk_unorm)
        assert back is (codecs.get(f.stored_as) if f.stored_as else c) and srgb is False


def test_lookups():
    assert formats.by_vk_format(132) == (formats.get("bc1"), "srgb")
    assert formats.by_vk_format(140) == (formats.get("bc4"), "snorm")
    assert formats.by_vk_format(12345) == (None, None)
    assert formats.by_dxgi(72) == (formats.get("bc1"), True)
    assert formats.by_dxgi(28) == (formats.get("rgba8"), False)
    assert formats.find("uint32", 3).vk_unorm == 104
    assert formats.find("float32", 4).name == "rgba32f"


# DXGI formats OpenImageIO's DDS reader decodes (it refuses R8, R8G8 and the float ones)
OIIO_DDS = ("rgba8", "bc1", "bc3", "bc4", "bc5")


@pytest.mark.parametrize("name", ["rgba8", "rg8", "r8", "rgba16f", "rgba32f", "bc1", "bc3", "bc4", "bc5"])
def test_dds_holds_every_format_with_a_dxgi_code(tmp_path, name):
    """DDS output of every such format is read back by our reader and, for the
    formats OpenImageIO decodes, by OpenImageIO."""
    import OpenImageIO as oiio

    from texcook.container.dds import read_dds, write_dds

    rng = np.random.default_rng(5)
    codec = codecs.get(name)
    if codec.float_input:
        px = rng.random((8, 12, 4)).astype(np.float32)
    else:
        px = rng.integers(0, 256, (8, 12, 4), dtype=np.uint8)
    data = write_dds(name, 12, 8, [codec.encode(px, "fast")], srgb=False)
    got_name, w, h, levels, srgb = read_dds(data, "x.dds")
    assert (got_name, w, h, srgb) == (name, 12, 8, False)
    want = codec.decode(codec.encode(px, "fast"), 12, 8)
    assert np.array_equal(codec.decode(levels[0], 12, 8), want)
    if name not in OIIO_DDS:
        return
    path = tmp_path / "t.dds"
    path.write_bytes(data)
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    theirs = inp.read_image(format="float")
    inp.close()
    assert theirs.shape[:2] == (8, 12)
    ours = want[..., : theirs.shape[2]].astype(np.float32)
    if not codec.float_input:
        ours /= 255.0
    # OpenImageIO expands missing channels its own way: compare what the format stores
    n = min(codec.channels, theirs.shape[2])
    assert np.allclose(theirs[..., :n], ours[..., :n], atol=1 / 255 + 1e-6)


def test_formats_command_lists_every_format(cli_run):
    code, stdout, _ = cli_run("formats", "--json")
    assert code == 0
    rows = json.loads(stdout)
    assert [r["name"] for r in rows] == list(formats.FORMATS)
    bc1 = next(r for r in rows if r["name"] == "bc1")
    assert bc1["vk_format"] == {"unorm": 131, "srgb": 132, "snorm": None}
    assert bc1["dxgi"] == {"unorm": 71, "srgb": 72} and bc1["fourcc"] == "DXT1"
    assert [o["name"] for o in bc1["options"]] == ["weights", "opaque_black"]
    assert bc1["presets"] == ["fastest", "fast", "medium", "thorough", "exhaustive"]
    code, stdout, _ = cli_run("formats")
    assert code == 0 and "bc5" in stdout and "astc-6x6" in stdout
