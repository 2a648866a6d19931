"""ASTC encoder: every block size, hard cases, quality floors, determinism, and
astcenc's decompressor reading our streams. TEXCOOK_LONG=1 runs the full sweep
(every block size with every preset through astcenc)."""

import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT, corpus_images
from decoders import astcenc_decode
from reference import astc_decode_symbolic
from texcook import codecs
from texcook.codecs.astc import BLOCK_SIZES, normal_xy
from texcook.codecs.astc.symbolic import KIND_VOID, S_KIND
from texcook.errors import UsageError
from texcook.image import read_image
from texcook.metrics import normal_angular_error, psnr

LONG = bool(os.environ.get("TEXCOOK_LONG"))
NAMES = [f"astc-{w}x{h}" for w, h in BLOCK_SIZES]
SHORT = ["astc-4x4", "astc-6x6", "astc-12x12"]


def load(path):
    img = read_image(path)
    px = np.clip(np.rint(img.pixels * 255.0), 0, 255).astype(np.uint8)
    if px.shape[2] == 3:
        px = np.concatenate([px, np.full(px.shape[:2] + (1,), 255, np.uint8)], axis=2)
    return np.ascontiguousarray(px[..., :4])


def test_family_generated_from_block_sizes():
    assert codecs.names()[-14:] == NAMES
    for i, name in enumerate(NAMES):
        c = codecs.get(name)
        assert (c.vk_unorm, c.vk_srgb, c.bytes_per_block, c.channels) == (157 + 2 * i, 158 + 2 * i, 16, 4)
        assert codecs.by_vk_format(158 + 2 * i) == (c, True)


def test_options_are_checked(rng):
    c = codecs.get("astc-4x4")
    img = rng.integers(0, 256, (4, 4, 4), dtype=np.uint8)
    with pytest.raises(UsageError):
        c.encode(img, "fast", threads=1, colour="no")
    with pytest.raises(UsageError):
        c.encode(img, "fast", threads=1, weights=(1, 1, 1))
    with pytest.raises(UsageError):
        c.encode(img, "fast", threads=1, weights=(0, 0, 0, 0))
    with pytest.raises(UsageError):
        c.encode(img, "fastest-ever", threads=1)


def _roundtrip(name, img, preset="fast", srgb=False, **opt):
    c = codecs.get(name)
    data, sym = c.encode_symbolic(img, preset, threads=1, srgb=srgb, **opt)
    assert len(data) == c.level_size(img.shape[1], img.shape[0])
    return c.decode(data, img.shape[1], img.shape[0], srgb=srgb), sym


@pytest.mark.parametrize("name", NAMES)
def test_constant_blocks_are_void_extent_and_exact(name):
    img = np.empty((13, 7, 4), np.uint8)
    img[:] = (12, 200, 77, 255)
    for srgb in (False, True):
        dec, sym = _roundtrip(name, img, "fastest", srgb=srgb)
        assert np.all(sym[:, S_KIND] == KIND_VOID)
        assert np.array_equal(dec, img)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("srgb", [False, True])
def test_search_error_is_the_decoders(name, srgb, rng):
    """What the decoder makes of our stream equals an independent symbolic
    decode, and an encoded random image keeps a sane quality."""
    bw, bh = codecs.get(name).block_w, codecs.get(name).block_h
    base = rng.integers(0, 256, (2, 4), dtype=np.int64)
    yy, xx = np.mgrid[0:2 * bh, 0:2 * bw]
    t = ((xx + yy) / (2 * (bw + bh)))[..., None]
    img = np.clip(base[0] * (1 - t) + base[1] * t + rng.normal(0, 6, (2 * bh, 2 * bw, 4)), 0, 255)
    img = img.astype(np.uint8)
    dec, sym = _roundtrip(name, img, "fast", srgb=srgb)
    from texcook.codecs._base import image_to_blocks
    ref = np.stack([astc_decode_symbolic(r, bw, bh, srgb) for r in sym])
    assert np.array_equal(image_to_blocks(dec, bw, bh), ref)
    assert psnr(dec, img) > 24


@pytest.mark.parametrize("name", SHORT)
def test_hard_cases(name):
    c = codecs.get(name)
    bw, bh = c.block_w, c.block_h
    # two colours, one per half
    img = np.zeros((bh, bw, 4), np.uint8)
    img[:, : bw // 2] = (255, 0, 0, 255)
    img[:, bw // 2:] = (0, 0, 255, 255)
    dec, _ = _roundtrip(name, img, "medium")
    assert psnr(dec, img) > 30
    # alpha 0 and alpha 255 blocks side by side, colour noise under both
    rng = np.random.default_rng(7)
    img = rng.integers(0, 256, (bh, 2 * bw, 4), dtype=np.uint8)
    img[:, :bw, 3] = 0
    img[:, bw:, 3] = 255
    dec, _ = _roundtrip(name, img, "fast")
    assert np.all(dec[:, :bw, 3] == 0) and np.all(dec[:, bw:, 3] == 255)
    # saturated primaries in one block
    img = np.zeros((bh, bw, 4), np.uint8)
    prim = np.array([(255, 0, 0, 255), (0, 255, 0, 255), (0, 0, 255, 255), (255, 255, 255, 255)])
    for y in range(bh):
        for x in range(bw):
            img[y, x] = prim[(2 * (y * 2 >= bh) + (x * 2 >= bw))]
    dec, _ = _roundtrip(name, img, "thorough")
    assert psnr(dec, img) > (30 if bw * bh == 16 else 19)


@pytest.mark.parametrize("name", ["astc-4x4", "astc-5x5", "astc-6x6"])
def test_two_colour_blocks_are_exact(name, rng):
    """Any two RGBA colours in any pattern fit a full grid of 1-bit weights with
    8-bit endpoints at these sizes; the slow presets must find that mode (its
    two weight levels lose nothing on weights that are exactly 0 or 1)."""
    c = codecs.get(name)
    bw, bh = c.block_w, c.block_h
    img = np.zeros((bh, 4 * bw, 4), np.uint8)
    for k in range(4):
        pair = rng.integers(0, 256, (2, 4), dtype=np.uint8)
        pick = rng.integers(0, 2, (bh, bw))
        pick[0, 0], pick[-1, -1] = 0, 1  # both colours present
        img[:, k * bw:(k + 1) * bw] = pair[pick]
    for preset in ("medium", "thorough"):
        dec, _ = _roundtrip(name, img, preset)
        assert np.array_equal(dec, img), preset


@pytest.mark.parametrize("name, floor", [("astc-6x6", 46), ("astc-8x8", 44)])
def test_hard_material_border_at_fast(name, floor, rng):
    """Two flat colours (with a little noise) split by a curved border, as
    base-colour textures have: the border's blocks lie on one line, and a fine
    grid of two weight levels keeps the edge. `fast` ranks modes with a weight
    range's error from the fit's own weights; the range's average (worst at
    two levels) picked coarse grids that blur the border (8x8: 36.7 dB, 6x6:
    44.1)."""
    n = 96
    yy, xx = np.mgrid[0:n, 0:n]
    inside = (yy - 40.0) ** 2 + (xx - 52.0) ** 2 < 30.0 ** 2
    img = np.where(inside[..., None], np.array([192.0, 53, 84, 255]), np.array([40.0, 130, 185, 255]))
    img[..., :3] += rng.normal(0, 1.5, (n, n, 3))
    img = img.clip(0, 255).round().astype(np.uint8)
    dec, _ = _roundtrip(name, img, "fast")
    assert psnr(dec, img) > floor


def test_smooth_gradient_12x12():
    yy, xx = np.mgrid[0:48, 0:48]
    img = np.stack([xx * 5, yy * 5, (xx + yy) * 2, 255 - xx], axis=-1).clip(0, 255).astype(np.uint8)
    dec, _ = _roundtrip("astc-12x12", img, "medium")
    assert psnr(dec, img) > 36


@pytest.mark.parametrize("shape", [(1, 1), (7, 13), (128, 127)])
def test_odd_sizes(shape, rng):
    h, w = shape
    img = load(corpus_images("rgb")[3])[:h, :w].copy()
    for name in ("astc-4x4", "astc-10x6"):
        dec, _ = _roundtrip(name, img, "fastest")
        assert dec.shape == img.shape
        assert psnr(dec, img) > (40 if h * w == 1 else 20)


# PSNR floors (RGB, `fast`) on two corpus photographs, a little under what the
# encoder reaches, per block-size class
FLOORS = {"astc-4x4": 36.5, "astc-6x6": 30.0, "astc-8x8": 26.0, "astc-12x12": 23.0}


@pytest.mark.parametrize("name", list(FLOORS))
def test_quality_floor(name):
    img = load(corpus_images("rgb")[0])[:96, :96].copy()
    dec, _ = _roundtrip(name, img, "fast")
    assert psnr(dec[..., :3], img[..., :3]) > FLOORS[name]


def test_rgba_alpha_weight():
    img = load(corpus_images("rgba")[0])[:64, :64].copy()
    dec_a, _ = _roundtrip("astc-6x6", img, "fast", weights=(1, 1, 1, 4))
    dec_c, _ = _roundtrip("astc-6x6", img, "fast", weights=(4, 4, 4, 1))
    assert psnr(dec_a[..., 3], img[..., 3]) > psnr(dec_c[..., 3], img[..., 3])


def test_threads_give_the_same_bytes():
    img = load(corpus_images("rgba")[1])[:64, :96].copy()
    c = codecs.get("astc-5x5")
    assert c.encode(img, "fast", threads=1) == c.encode(img, "fast", threads=3)


def test_normal_map_rrrg():
    img = load(sorted((ROOT / "corpus" / "normal").glob("*.png"))[0])[:64, :64].copy()
    c = codecs.get("astc-6x6")
    data = c.encode(img, "fast", threads=1, normal_map=True)
    dec = c.decode(data, 64, 64)
    assert np.array_equal(dec[..., 0], dec[..., 1]) and np.array_equal(dec[..., 0], dec[..., 2])
    mean, p99 = normal_angular_error(img, normal_xy(dec))
    assert mean < 3.0 and p99 < 20.0


# X/Y PSNR floors of each corpus normal map at `fast`: X (in RGB) and Y (in
# alpha) vary apart, so Y gets a plane of its own whatever the early-out; when
# the early-out skipped that plane these were 45.3 / 43.5 / 43.1 dB at 4x4
# and 38.6 / 36.9 / 40.5 dB at 6x6
NORMAL_FLOORS = {"astc-4x4": (47.0, 44.3, 51.0), "astc-6x6": (39.0, 36.6, 45.5)}


@pytest.mark.parametrize("name", sorted(NORMAL_FLOORS))
def test_a_normal_map_keeps_y_on_a_plane_of_its_own(name):
    c = codecs.get(name)
    paths = sorted((ROOT / "corpus" / "normal").glob("*.png"))
    assert len(paths) == len(NORMAL_FLOORS[name])
    for path, floor in zip(paths, NORMAL_FLOORS[name]):
        img = load(path)
        h, w = img.shape[0] // c.block_h * c.block_h, img.shape[1] // c.block_w * c.block_w
        img = np.ascontiguousarray(img[:h, :w])
        dec = normal_xy(c.decode(c.encode(img, "fast", normal_map=True), w, h))
        assert psnr(dec[..., :2], img[..., :2]) >= floor, path.name


def test_no_jit_matches_jit(tmp_path):
    """The kernels' Python runs (NUMBA_DISABLE_JIT=1) give the same bytes."""
    rng = np.random.default_rng(3)
    img = rng.integers(0, 256, (5, 4, 4), dtype=np.uint8)
    img[:, :, 3] = 255
    np.save(tmp_path / "img.npy", img)
    code = (
        "import numpy as np, sys; from texcook import codecs;"
        f"img = np.load(r'{tmp_path / 'img.npy'}');"
        "sys.stdout.write(codecs.get('astc-4x4').encode(img, 'fast', threads=1).hex())"
    )
    env = dict(os.environ, NUMBA_DISABLE_JIT="1", PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, check=True, timeout=600).stdout
    assert out == codecs.get("astc-4x4").encode(img, "fast", threads=1).hex()


@pytest.mark.parametrize("name", NAMES)
def test_astcenc_decodes_our_streams(name):
    c = codecs.get(name)
    img = load(corpus_images("rgba")[2])[:2 * c.block_h + 3, :3 * c.block_w + 1].copy()
    presets = c.presets if LONG else ("fast",)
    for preset in presets:
        for srgb in (False, True):
            data = c.encode(img, preset, threads=1, srgb=srgb)
            ours = c.decode(data, img.shape[1], img.shape[0], srgb=srgb)
            theirs = astcenc_decode(data, c.block_w, c.block_h, img.shape[1], img.shape[0], srgb)
            if not srgb:
                assert np.array_equal(ours, theirs), preset
            else:
                # colour identical; astcenc's 8-bit sRGB output can round alpha
                # one level differently from the spec's C >> 8 (decoder's note)
                assert np.array_equal(ours[..., :3], theirs[..., :3]), preset
                assert np.abs(ours[..., 3].astype(int) - theirs[..., 3]).max() <= 1, preset


@pytest.mark.parametrize("size,grid", [((8, 8), (5, 4)), ((6, 5), (3, 5)), ((4, 4), (2, 2)),
                                       ((12, 10), (7, 9))])
def test_separable_grid_estimate(rng, size, grid):
    """The ranking's separable estimate is the least-squares error of a
    bilinear grid fit to the weights scaled by the root of their importance:
    0 for weights a grid makes, the brute-force optimum otherwise."""
    from texcook.codecs.astc.search import grid as G
    from texcook.codecs.astc.search import block_tables as T

    (bw, bh), (gw, gh) = size, grid
    tb = T.tables(bw, bh)
    ax = T.infill_1d(bw, gw)
    ay = T.infill_1d(bh, gh)
    op = np.kron(ay, ax)  # texel (y, x) from grid (j, i)

    def est(w, s):  # the helpers compile only inside the kernel: run their Python
        errs = np.zeros((13, 13))
        sc = np.zeros(bw * bh + bh * tb["ux"].shape[1] + bh * bh)
        G.sep_errs.py_func(w, s, bw, bh, tb["ux"], tb["uoff"], tb["qyp"], errs, sc,
                            np.ones((13, 13), np.int64), -1, None)
        return errs[gw, gh]

    flat = np.full(bw * bh, 3.0)
    made = op @ rng.random(gw * gh)
    assert abs(est(made, flat)) < 1e-9
    w = rng.random(bw * bh)
    g = np.linalg.lstsq(op, w, rcond=None)[0]
    assert est(w, flat) == pytest.approx(3.0 * np.sum((op @ g - w) ** 2), rel=1e-9)
    s = rng.random(bw * bh) * 5
    v = np.sqrt(s) * w
    g = np.linalg.lstsq(op, v, rcond=None)[0]
    assert est(w, s) == pytest.approx(np.sum((op @ g - v) ** 2), rel=1e-9)


def test_a_threads_scratch_serves_every_call(rng):
    """search() keeps one Scratch per thread and block size: a search after
    others with other presets and mode masks (thorough's many modes, then
    fastest's few, then a normal map's every plane) writes what a fresh
    Scratch writes."""
    from texcook.codecs.astc import presets, search

    bw, bh = 5, 4
    tab = search.kernel_tables(bw, bh)
    blocks = rng.integers(0, 256, (40, bw * bh, 4)).astype(np.uint8)
    blocks[:10, :, 3] = 255
    blocks[10:20, :, :3] = blocks[10:20, :, :1]  # grey
    out = {}
    for preset in ("thorough", "fastest", "medium", "fast"):
        rec = presets.record(bw, bh, preset)
        mask = presets.mode_mask(bw, bh, preset)
        args = (rec, mask, np.ones(4), np.int64(0), tab)
        kept = np.zeros((blocks.shape[0], search.SYM_LEN), np.int32)
        search.search(blocks, kept, *args)
        alone = np.zeros_like(kept)
        search.search_kernel(blocks, alone, *args, search.scratch(tab, bw * bh))
        assert np.array_equal(kept, alone), preset
        out[preset] = kept
    assert not np.array_equal(out["thorough"], out["fastest"])
