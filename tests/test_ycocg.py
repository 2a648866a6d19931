"""YCoCg: the colour transforms (lossy and YCoCg-R) and the bc3-ycocg format."""

import json

import numpy as np
import pytest

from texcook import codecs, formats, transforms
from texcook.colour import rgb_to_ycocg, rgb_to_ycocg_r, ycocg_r_to_rgb, ycocg_to_rgb
from texcook.image import read_image, write_image
from texcook.metrics import psnr

from decoders import t2d
from reference import ycocg, ycocg_r, ycocg_scaled_rgb

def test_ycocg_matches_reference_and_inverts(rng):
    rgb = rng.random((37, 41, 3))
    ours = rgb_to_ycocg(rgb)
    assert ours.dtype == np.float64 and ours.shape == rgb.shape
    np.testing.assert_allclose(ours, ycocg(rgb), atol=1e-15)
    np.testing.assert_allclose(ycocg_to_rgb(ours), rgb, atol=1e-12)
    f32 = rgb.astype(np.float32)
    assert rgb_to_ycocg(f32).dtype == np.float32
    np.testing.assert_allclose(ycocg_to_rgb(rgb_to_ycocg(f32)), f32, atol=1e-6)


def test_ycocg_ranges_at_the_corners():
    corners = np.array([[r, g, b] for r in (0, 1) for g in (0, 1) for b in (0, 1)], np.float64)
    y, co, cg = rgb_to_ycocg(corners).T
    assert y.min() == 0 and y.max() == 1
    assert co.min() == -0.5 and co.max() == 0.5
    assert cg.min() == -0.5 and cg.max() == 0.5
    # grey has no chroma
    grey = rgb_to_ycocg(np.full((5, 3), 0.3))
    np.testing.assert_allclose(grey[:, 1:], 0.0, atol=1e-15)
    np.testing.assert_allclose(grey[:, 0], 0.3)


def test_ycocg_r_matches_reference(rng):
    rgb = rng.integers(0, 256, (1000, 3))
    np.testing.assert_array_equal(rgb_to_ycocg_r(rgb), ycocg_r(rgb))
    # the integer form tracks the lossy one to within rounding (Co and Cg doubled)
    lossy = rgb_to_ycocg(rgb.astype(np.float64))
    r = rgb_to_ycocg_r(rgb)
    assert np.abs(r[:, 0] - lossy[:, 0]).max() <= 1
    np.testing.assert_array_equal(r[:, 1], 2 * lossy[:, 1])
    assert np.abs(r[:, 2] - 2 * lossy[:, 2]).max() <= 1


def test_ycocg_r_round_trips_every_8bit_triple():
    """All 2^24 RGB triples, in chunks of 2^20 to keep memory small."""
    lo = np.arange(1 << 20, dtype=np.int64)
    seen_min = np.full(3, 1 << 30)
    seen_max = np.full(3, -(1 << 30))
    for hi in range(16):
        v = (hi << 20) | lo
        rgb = np.stack([v >> 16, (v >> 8) & 255, v & 255], axis=-1).astype(np.uint8)
        ycocg = rgb_to_ycocg_r(rgb)
        back = ycocg_r_to_rgb(ycocg)
        assert np.array_equal(back, rgb), f"chunk {hi}"
        seen_min = np.minimum(seen_min, ycocg.min(axis=0))
        seen_max = np.maximum(seen_max, ycocg.max(axis=0))
    # Y keeps 8 bits; Co and Cg need the ninth
    assert seen_min.tolist() == [0, -255, -255]
    assert seen_max.tolist() == [255, 255, 255]


def test_ycocg_r_rejects_wrong_shapes():
    with pytest.raises(ValueError):
        rgb_to_ycocg_r(np.zeros((4, 4)))


# --- the scaled YCoCg layout and the bc3-ycocg format --------------------------------

def _rgba8(rgb):
    out = np.full(rgb.shape[:2] + (4,), 255, np.uint8)
    out[..., :3] = rgb
    return out


@pytest.mark.parametrize("shape", [(8, 8), (7, 9), (1, 1), (5, 3)])
def test_layout_and_reconstruction_invert(rng, shape):
    px = np.ones(shape + (4,), np.float32)
    px[..., :3] = rng.random(shape + (3,))
    px[: shape[0] // 2, : shape[1] // 2, :3] = 0.5 + 0.05 * rng.random((shape[0] // 2, shape[1] // 2, 3))
    lay = transforms.ycocg_layout(px)
    assert lay.min() >= -0.5 / 255 and lay.max() <= 1.0 + 0.5 / 255
    np.testing.assert_allclose(transforms.ycocg_rgb(lay), px, atol=1e-5)
    # the layout is the one the shader formula reads
    np.testing.assert_allclose(ycocg_scaled_rgb(lay * 255) / 255, px[..., :3], atol=1e-5)


def test_layout_scale_follows_the_block_chroma():
    px = np.ones((4, 12, 4), np.float32)
    px[:, 0:4, :3] = 0.5  # grey: no chroma, largest scale
    px[:, 4:8, :3] = (0.6, 0.5, 0.45)  # faint colour: still 4
    px[:, 8:12, :3] = (1.0, 0.0, 0.0)  # saturated red: Co = 0.5, scale 1
    lay = transforms.ycocg_layout(px)
    codes = np.rint(lay[0, ::4, 2] * 255).tolist()
    assert codes == [24.0, 24.0, 0.0]  # (s - 1) << 3 for s = 4, 4, 1
    mid = np.ones((4, 4, 4), np.float32)
    mid[..., :3] = (0.76, 0.5, 0.5)  # Co = 0.13: twice fits, four times (0.52 > 127.5/255) does not
    assert round(transforms.ycocg_layout(mid)[0, 0, 2] * 255) == 8


def _hard_images(rng):
    yield "random", rng.integers(0, 256, (13, 11, 3))
    yield "constant", np.full((8, 8, 3), (200, 30, 90))
    two = np.zeros((8, 8, 3), np.int64)
    two[::2] = (255, 255, 255)
    yield "two-colour", two
    yield "1x1", np.array([[[12, 250, 3]]])
    yield "primaries", np.array([[[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 0]]] * 4)
    yield "black-white", np.array([[[0, 0, 0]] * 4, [[255, 255, 255]] * 4] * 2)
    y, x = np.mgrid[0:16, 0:16]
    yield "smooth", np.stack([x * 16, y * 16, (x + y) * 8], axis=-1)


def test_codec_round_trip_on_hard_cases(rng):
    codec = codecs.get("bc3-ycocg")
    bc3 = codecs.get("bc3")
    for name, rgb in _hard_images(rng):
        src = _rgba8(rgb.astype(np.uint8))
        h, w = src.shape[:2]
        for preset in ("fastest", "medium"):
            data = codec.encode(src, preset)
            assert len(data) == codec.level_size(w, h)
            layout = codec.decode_layout(data, w, h)
            blue = layout[..., 2]
            # blue holds the block's scale code exactly, one value per block
            assert set(np.unique(blue).tolist()) <= {0, 8, 24}, name
            for by in range(0, h, 4):
                for bx in range(0, w, 4):
                    assert len(np.unique(blue[by:by + 4, bx:bx + 4])) == 1, name
            back = codec.decode(data, w, h)
            assert back.dtype == np.uint8 and (back[..., 3] == 255).all()
            err = np.abs(back[..., :3].astype(int) - src[..., :3]).max()
            # against BC3 on the same texels: never much worse (blocks of colours on no
            # line defeat both), exact up to the transform's rounding where BC3 is exact
            plain = bc3.decode(bc3.encode(src, preset), w, h)
            plain_err = np.abs(plain[..., :3].astype(int) - src[..., :3]).max()
            assert err <= max(plain_err + 20, 2), (name, preset, err, plain_err)
            assert psnr(src, back, 255, [0, 1, 2]) >= min(psnr(src, plain, 255, [0, 1, 2]), 45.0) - 0.5, name
    # a constant block is exact up to the transform's rounding
    const = _rgba8(np.full((4, 4, 3), (200, 30, 90), np.uint8))
    assert np.abs(codec.decode(codec.encode(const), 4, 4).astype(int) - const).max() <= 2


def test_encoded_blocks_decode_the_same_as_bc3(corpus):
    """A reader that only knows BC3 (texture2ddecoder) sees the layout, and the
    shader's reconstruction from it is the codec's decode, to the nearest code."""
    img = _rgba8(np.rint(read_image(corpus / "rgb" / "ldr-rgb-03.png").pixels[..., :3] * 255).astype(np.uint8))
    codec = codecs.get("bc3-ycocg")
    data = codec.encode(img, "fast")
    h, w = img.shape[:2]
    layout = t2d("bc3", data, w, h)
    np.testing.assert_array_equal(codec.decode_layout(data, w, h), layout)
    assert set(np.unique(layout[..., 2]).tolist()) <= {0, 8, 24}  # only the three scale codes
    want = np.clip(ycocg_scaled_rgb(layout), 0, 255)
    got = codec.decode(data, w, h)
    assert (got[..., 3] == 255).all()
    # the exact value can sit on a half code (scale 2 and 4 halve Co and Cg): either neighbour
    assert np.abs(got[..., :3] - want).max() <= 0.5 + 1e-6


def test_beats_bc1_and_bc3_on_a_corpus_image(corpus):
    img = read_image(corpus / "rgb" / "ldr-rgb-06.png")
    src = _rgba8(np.rint(img.pixels[..., :3] * 255).astype(np.uint8))
    h, w = src.shape[:2]
    scores = {}
    for name in ("bc1", "bc3", "bc3-ycocg"):
        codec = codecs.get(name)
        scores[name] = psnr(src, codec.decode(codec.encode(src, "fast"), w, h), 255, [0, 1, 2])
    assert scores["bc3-ycocg"] > scores["bc3"] + 2.0
    assert scores["bc3-ycocg"] > scores["bc1"] + 2.0


def test_formats_command_says_how_it_is_written(cli_run):
    code, stdout, _ = cli_run("formats")
    assert code == 0
    line = next(x for x in stdout.splitlines() if x.startswith("bc3-ycocg"))
    assert "vk 137 " in line and "written as bc3 with a recorded ycocg step" in line
    code, stdout, _ = cli_run("formats", "--json")
    assert code == 0
    row = next(r for r in json.loads(stdout) if r["name"] == "bc3-ycocg")
    assert (row["stored_as"], row["transform"], row["vk_format"]["srgb"]) == ("bc3", "ycocg", None)


def test_format_row_reads_back_as_bc3():
    row = formats.get("bc3-ycocg")
    assert row.stored_as == "bc3" and row.transform == "ycocg"
    assert row.vk_unorm == formats.get("bc3").vk_unorm and not row.vk_srgb and not row.dxgi
    assert formats.by_vk_format(137) == (formats.get("bc3"), "linear")
    assert formats.get("bc3-ycocg").facts()["stored_as"] == "bc3"


def test_bake_records_the_step_and_readers_reconstruct_rgb(tmp_path, rng, ktx_parse, cli_run):
    from texcook.container.ktx2 import read_ktx2
    from texcook.errors import UsageError
    from texcook.pipeline import bake_file, compare, load_texture
    from texcook.recipe import Recipe

    y, x = np.mgrid[0:24, 0:20]
    rgb = np.stack([x * 12, y * 10, 255 - x * 6 - y * 4], axis=-1).astype(np.uint8)
    src = tmp_path / "s.png"
    write_image(src, rgb)
    out = tmp_path / "s.ktx2"
    summary = bake_file(src, out, Recipe.of(format="bc3-ycocg"))
    assert summary["format"] == "bc3-ycocg" and summary["vk_format"] == 137
    assert summary["colour_space"] == "linear"
    ktx = read_ktx2(out.read_bytes(), str(out))
    (step,) = json.loads(ktx.text(transforms.KV_KEY))
    assert step["name"] == "ycocg" and step["shader"] == transforms.YCOCG_SHADER
    assert step["rgb"] == "srgb"  # the PNG's encoding: a shader decodes sRGB after rebuilding RGB
    (theirs,) = ktx_parse([out])
    assert theirs["vkFormat"] == 137 and theirs["keyValue"][transforms.KV_KEY] == ktx.text(transforms.KV_KEY)
    tex = load_texture(out)
    assert tex.channels == 3 and len(tex.levels) == summary["levels"] and tex.srgb
    # the reader's RGB is the codec's own decoding of the stored blocks
    codec = codecs.get("bc3-ycocg")
    np.testing.assert_array_equal(tex.levels[0], codec.decode(ktx.levels[0], 20, 24))
    # within the codec's error: a 2-D colour ramp is as hard for it as for BC3
    plain = tmp_path / "plain.ktx2"
    bake_file(src, plain, Recipe.of(format="bc3", srgb=False))
    assert compare(src, out, level=0)["psnr"] > compare(src, plain, level=0)["psnr"] - 0.5 > 25
    # with a renormalisation first, both are undone, last first
    bake_file(src, out, Recipe.of(format="bc3-ycocg", renormalize="texture"))
    names = [s["name"] for s in json.loads(read_ktx2(out.read_bytes(), str(out)).text(transforms.KV_KEY))]
    assert names == ["renormalize", "ycocg"]
    assert compare(src, out, level=0)["psnr"] > compare(src, plain, level=0)["psnr"] - 0.5
    # no sRGB twin, no DDS
    with pytest.raises(UsageError):
        Recipe.of(format="bc3-ycocg", srgb=True)
    with pytest.raises(UsageError):
        bake_file(src, tmp_path / "s.dds", Recipe.of(format="bc3-ycocg"))
    code, stdout, _ = cli_run("decode", out, "-o", tmp_path / "d.png")
    assert code == 0
    back = np.rint(read_image(tmp_path / "d.png").pixels[..., :3] * 255)
    np.testing.assert_array_equal(back, np.rint(load_texture(out).levels[0][..., :3] * 255))
