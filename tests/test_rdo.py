"""RDO (texcook.rdo): what it may change, what it must keep, and that it pays."""

import numpy as np
import pytest
import zstandard
from conftest import corpus_images
from decoders import t2d

from texcook import codecs, rdo
from texcook.container.ktx2 import read_ktx2
from texcook.errors import UsageError
from texcook.image import read_image
from texcook.pipeline import bake_file, load_texture
from texcook.plan import plan_bake
from texcook.recipe import SETTINGS, Recipe

# the channels each format stores, as a reader sees them
CHANNELS = {"bc1": [0, 1, 2], "bc1a": [0, 1, 2], "bc3": [0, 1, 2, 3], "bc4": [0], "bc5": [0, 1]}
SOURCES = {"bc1": "rgb", "bc1a": "rgba", "bc3": "rgba", "bc4": "rgb", "bc5": "normal"}


def rgba8(path, size=128):
    px = read_image(path).integer_values()[:size, :size]
    if px.shape[2] == 3:
        px = np.concatenate([px, np.full(px.shape[:2] + (1,), 255, np.uint8)], 2)
    return np.ascontiguousarray(px.astype(np.uint8))


def sse(fmt, data, px):
    """Squared error of a level against its texels, decoded by texture2ddecoder
    (an independent decoder), on the channels the format stores."""
    h, w = px.shape[:2]
    dec = t2d(fmt, data, w, h).astype(np.int64)
    ch = CHANNELS[fmt]
    return int(((dec[..., ch] - px[..., ch]) ** 2).sum())


def zstd(data):
    return len(zstandard.ZstdCompressor(level=19).compress(data))


@pytest.mark.parametrize("fmt", sorted(CHANNELS))
def test_added_error_is_within_lambda_times_the_bytes_saved_and_zstd_shrinks(corpus, fmt):
    codec = codecs.get(fmt)
    for path in corpus_images(SOURCES[fmt])[:2] + [corpus / "rgb" / "ldr-rgb-10.png"] * (fmt == "bc1"):
        px = rgba8(path)  # ldr-rgb-10 is 127 wide: partial blocks, whose padding counts nothing
        base = codec.encode(px, "fast")
        for lam in (30.0, 300.0):
            stats = {}
            out = rdo.optimise(fmt, base, px, lam, stats=stats)
            assert len(out) == len(base) and stats["halves"] > 0, (path.name, lam)
            added = sse(fmt, out, px) - sse(fmt, base, px)
            assert added == stats["added"], (path.name, lam)  # the stage measured what a reader decodes
            assert 0 <= added <= lam * stats["saved"], (path.name, lam)
            assert zstd(out) < zstd(base), (path.name, lam)
    # a larger lambda trades more error for more bytes
    small, large = ({} for _ in range(2))
    a, b = (zstd(rdo.optimise(fmt, base, px, lam, stats=s)) for lam, s in ((30.0, small), (300.0, large)))
    assert b < a and large["added"] > small["added"]


def test_lambda_zero_and_other_formats_leave_the_bytes(corpus):
    px = rgba8(corpus / "rgb" / "ldr-rgb-01.png", 32)
    data = codecs.get("bc1").encode(px, "fast")
    assert rdo.optimise("bc1", data, px, 0.0) is data
    assert not rdo.supports("bc7") and rdo.FORMATS == ("bc1", "bc1a", "bc3", "bc4", "bc5")


def test_rdo_off_bakes_the_same_file(corpus, tmp_path):
    src = corpus / "rgb" / "ldr-rgb-02.png"
    bake_file(src, tmp_path / "a.ktx2", Recipe.of(format="bc1", preset="fast", zstd=19))
    bake_file(src, tmp_path / "b.ktx2", Recipe.of(format="bc1", preset="fast", zstd=19, rdo=0))
    assert (tmp_path / "a.ktx2").read_bytes() == (tmp_path / "b.ktx2").read_bytes()
    assert Recipe.of(format="bc1", rdo=0).to_dict() == Recipe.of(format="bc1").to_dict()  # same digest
    assert plan_bake(src, Recipe.of(format="bc1")).step("rdo") == (False, "not asked for")


def test_bc1a_keeps_which_texels_are_transparent(corpus):
    for path in corpus_images("rgba"):
        px = rgba8(path)
        codec = codecs.get("bc1a")
        base = codec.encode(px, "fast")
        stats = {}
        out = rdo.optimise("bc1a", base, px, 1000.0, stats=stats)
        assert stats["halves"] > 0
        h, w = px.shape[:2]
        assert np.array_equal(codec.decode(out, w, h)[..., 3], codec.decode(base, w, h)[..., 3]), path.name


def three_colour_blacks(data):
    """Texels of BC1 blocks that read index 3 in the 3-colour mode (c0 <= c1)."""
    b = np.frombuffer(data, np.uint8).reshape(-1, 8).astype(np.int64)
    c0, c1 = b[:, 0] | b[:, 1] << 8, b[:, 2] | b[:, 3] << 8
    bits = b[:, 4] | b[:, 5] << 8 | b[:, 6] << 16 | b[:, 7] << 24
    idx = (bits[:, None] >> (2 * np.arange(16))) & 3
    return int(((idx == 3) & (c0 <= c1)[:, None]).sum())


def test_bc1_without_opaque_black_gains_no_three_colour_black(rng):
    # dark texels next to colour: 3-colour black is what a plain BC1 search would like
    px = rng.integers(0, 256, (64, 64, 4), dtype=np.uint8)
    px[::2, ::3, :3] = 0
    px[..., 3] = 255
    codec = codecs.get("bc1")
    base = codec.encode(px, "fast", opaque_black=False)
    assert three_colour_blacks(base) == 0
    out = rdo.optimise("bc1", base, px, 3000.0, {"opaque_black": False})
    assert out != base and three_colour_blacks(out) == 0


def bc3_order_broken(data):
    """BC3 colour halves that a D3D decoder (always 4 colours) and an
    order-reading one would decode differently."""
    b = np.frombuffer(data, np.uint8).reshape(-1, 16)[:, 8:].astype(np.int64)
    c0, c1 = b[:, 0] | b[:, 1] << 8, b[:, 2] | b[:, 3] << 8
    return int(((c0 < c1) | ((c0 == c1) & (b[:, 4:].sum(1) > 0))).sum())


def test_bc3_colour_keeps_c0_above_c1(rng):
    # flat blocks of a 565 colour (c0 == c1, indices 0) after two-colour
    # checkers (indices 0 and 1 only): a flat block taking a checker's indices
    # decodes the same to a reader that follows the endpoint order, and black
    # to one that reads every block as 4 colours (D3D)
    px = np.empty((16, 64, 4), np.uint8)
    px[..., :3] = (132, 134, 132)
    checker = (np.indices((16, 32)).sum(0) % 2).astype(bool)
    half = px[:, :32, :3]
    half[checker], half[~checker] = (33, 32, 33), (231, 227, 231)
    px[..., 3] = rng.integers(0, 256, (16, 64))
    codec = codecs.get("bc3")
    base = codec.encode(px, "fast")
    assert bc3_order_broken(base) == 0
    stats = {}
    out = rdo.optimise("bc3", base, px, 5000.0, stats=stats)
    assert bc3_order_broken(out) == 0
    assert sse("bc3", out, px) - sse("bc3", base, px) == stats["added"]


@pytest.mark.parametrize("shape", [(1, 1), (4, 4), (3, 5), (4, 8), (8, 8)])
@pytest.mark.parametrize("fmt", sorted(CHANNELS))
def test_small_and_constant_levels(rng, fmt, shape):
    codec = codecs.get(fmt)
    for px in (rng.integers(0, 256, shape + (4,), dtype=np.uint8), np.full(shape + (4,), 77, np.uint8)):
        base = codec.encode(px, "fast")
        stats = {}
        out = rdo.optimise(fmt, base, px, 1e5, stats=stats)
        assert len(out) == len(base)
        if len(base) == codec.bytes_per_block or px.min() == px.max():
            assert out == base  # nothing earlier to copy, or every block already the same
        assert sse(fmt, out, px) - sse(fmt, base, px) == stats.get("added", 0) <= 1e5 * stats.get("saved", 0)


def test_block_weights_mark_padding():
    w = rdo.block_weights(3, 5)  # two blocks: 3 rows of 4 columns, 3 rows of 1
    assert w.shape == (2, 16) and w[0].sum() == 12 and w[1].sum() == 3
    assert w[1].reshape(4, 4)[:3, 0].all() and not w[1].reshape(4, 4)[3].any()


def test_bakes_with_rdo_read_back_everywhere(corpus, tmp_path, ktx_parse, cli_run):
    src = corpus / "rgba" / "ldr-rgba-00.png"
    plain, done = tmp_path / "plain.ktx2", tmp_path / "rdo.ktx2"
    bake_file(src, plain, Recipe.of(format="bc3", preset="fast", zstd=19))
    summary = bake_file(src, done, Recipe.of(format="bc3", preset="fast", zstd=19, rdo=200), threads=1)
    assert summary["bytes"] < plain.stat().st_size
    # thread count does not change the bytes
    bake_file(src, tmp_path / "t2.ktx2", Recipe.of(format="bc3", preset="fast", zstd=19, rdo=200), threads=2)
    assert (tmp_path / "t2.ktx2").read_bytes() == done.read_bytes()
    (rec,) = ktx_parse([done])
    ours = read_ktx2(done.read_bytes(), str(done))
    assert "error" not in rec and rec["supercompressionScheme"] == 2 and rec["levelCount"] == len(ours.levels)
    dctx = zstandard.ZstdDecompressor()
    import base64

    for level, theirs in zip(ours.levels, rec["levels"]):
        assert dctx.decompress(base64.b64decode(theirs["data"]), max_output_size=1 << 24) == bytes(level)
    code, _, err = cli_run("decode", done, "-o", tmp_path / "d.png")
    assert code == 0, err
    back = read_image(tmp_path / "d.png").integer_values()
    assert np.array_equal(back, load_texture(done).levels[0])
    assert np.array_equal(back, t2d("bc3", ours.levels[0], ours.width, ours.height))


def test_the_plan_says_when_rdo_runs_and_refuses_other_formats(corpus, tmp_path, cli_run):
    src = corpus / "rgb" / "ldr-rgb-01.png"
    plan = plan_bake(src, Recipe.of(format="bc5", rdo=50, zstd=19))
    ran, why = plan.step("rdo")
    assert ran and "lambda 50" in why and not plan.notes
    assert any("--rdo without Zstandard" in n for n in plan_bake(src, Recipe.of(format="bc4", rdo=50)).notes)
    with pytest.raises(UsageError, match="--rdo works on bc1, bc1a, bc3, bc4, bc5, not bc7"):
        plan_bake(src, Recipe.of(format="bc7", rdo=50))
    code, out, err = cli_run("bake", src, "-o", tmp_path / "x.ktx2", "-f", "astc-4x4", "--rdo", "10")
    assert code == 2 and err.count("\n") == 1 and "--rdo works on" in err and not (tmp_path / "x.ktx2").exists()
    code, out, err = cli_run("bake", src, "-o", tmp_path / "x.ktx2", "-f", "bc1", "--rdo", "-1")
    assert code == 2 and "codec.rdo (--rdo) must be within 0..1e+06" in err


def test_bake_batch_and_scene_take_the_flag(cli_run):
    assert SETTINGS["rdo"].part == "codec" and SETTINGS["rdo"].default == 0.0
    for command in ("bake", "batch", "scene"):
        code, out, _ = cli_run(command, "--help")
        assert code == 0 and "--rdo LAMBDA" in out, command


def test_scene_reworks_only_the_formats_rdo_knows(tmp_path, corpus):
    import json

    from test_scene import build

    from texcook import scene

    photo = rgba8(corpus / "rgb" / "ldr-rgb-03.png", 32)
    normal = rgba8(corpus / "normal" / "ldr-xy-00.png", 32)[..., :3]
    path = build(tmp_path / "m.gltf", {"c": photo, "n": normal}, [("c", None), ("n", None)],
                 [{"name": "a", "slots": {"baseColorTexture": 0, "normalTexture": 1}},
                  {"name": "b", "slots": {"baseColorTexture": 0}, "alphaMode": "BLEND"}])
    report = scene.bake_scene(path, tmp_path / "out", preset="fastest", rdo=100)
    lams = {b["format"]: b["recipe"]["codec"].get("rdo") for b in report["bakes"]}
    assert lams == {"bc1": 100.0, "bc5": 100.0, "bc7": None} and report["rdo"] == 100.0
    assert json.loads((tmp_path / "out" / "scene.json").read_text())["rdo"] == 100.0
