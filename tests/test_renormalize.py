"""Histogram renormalisation: the transform step, its recipe settings, what a
file records and how readers undo it."""

import json

import numpy as np
import pytest

from texcook import codecs, transforms
from texcook.container.ktx2 import read_ktx2
from texcook.errors import UsageError
from texcook.image import write_image
from texcook.pipeline import bake_file, load_texture
from texcook.recipe import Recipe, Transform

from reference import renormalise, renormalise_inverse


def _levels(rng, lo, hi, sizes=((16, 12), (8, 6), (4, 3))):
    return [(lo + (hi - lo) * rng.random((h, w, 4))).astype(np.float32) for h, w in sizes]


# --- the step ------------------------------------------------------------------------

def test_texture_mode_stretches_each_channel_and_inverts(rng):
    lo = np.array([0.3, 0.1, 0.6, 0.2], np.float32)
    hi = np.array([0.5, 0.2, 0.9, 0.25], np.float32)
    levels = _levels(rng, lo, hi)
    notes = []
    out, kv = transforms.forward(levels, Transform(renormalize="texture"), notes)
    assert notes == []
    allv = np.concatenate([px.reshape(-1, 4) for px in out])
    np.testing.assert_allclose(allv.min(axis=0), 0.0, atol=1e-6)
    np.testing.assert_allclose(allv.max(axis=0), 1.0, atol=1e-6)
    (step,) = json.loads(kv[transforms.KV_KEY])
    assert step["name"] == "renormalize" and step["mode"] == "texture"
    want, ((scale, bias),) = renormalise(levels, "texture")
    np.testing.assert_allclose(step["bias"], bias, atol=1e-7)
    np.testing.assert_allclose(step["scale"], scale, atol=1e-6)
    for a, b in zip(out, want):
        np.testing.assert_allclose(a, b, atol=1e-5)
    # the reconstruction a shader performs: value = stored * scale + bias
    back = transforms.inverse(out, kv[transforms.KV_KEY])
    for a, px, b in zip(back, out, levels):
        np.testing.assert_allclose(a, b, atol=1e-6)
        np.testing.assert_allclose(a, renormalise_inverse(px, step["scale"], step["bias"]), atol=1e-6)


def test_level_mode_has_a_scale_and_bias_per_level(rng):
    levels = _levels(rng, 0.4, 0.6)
    levels[2] = np.full_like(levels[2], 0.5)  # a constant level keeps the identity
    out, kv = transforms.forward(levels, Transform(renormalize="level"))
    (step,) = json.loads(kv[transforms.KV_KEY])
    assert len(step["scale"]) == 3 and len(step["bias"]) == 3
    assert step["scale"][2] == [1.0] * 4 and step["bias"][2] == [0.0] * 4
    want, params = renormalise(levels, "level")
    for k, (px, ref, (scale, bias)) in enumerate(zip(out, want, params)):
        np.testing.assert_allclose(px, ref, atol=1e-5)
        np.testing.assert_allclose(step["scale"][k], scale, atol=1e-6)
        np.testing.assert_allclose(step["bias"][k], bias, atol=1e-7)
    for px in out[:2]:
        np.testing.assert_allclose(px.reshape(-1, 4).min(axis=0), 0.0, atol=1e-6)
        np.testing.assert_allclose(px.reshape(-1, 4).max(axis=0), 1.0, atol=1e-6)
    np.testing.assert_array_equal(out[2], levels[2])
    for a, b in zip(transforms.inverse(out, kv[transforms.KV_KEY]), levels):
        np.testing.assert_allclose(a, b, atol=1e-6)


def test_full_range_and_constant_channels_are_left_alone(rng):
    px = rng.random((9, 7, 4)).astype(np.float32)
    px[0, 0] = 0.0
    px[0, 1] = 1.0
    px[..., 3] = 1.0  # opaque
    out, kv = transforms.forward([px], Transform(renormalize="texture"))
    (step,) = json.loads(kv[transforms.KV_KEY])
    assert step["scale"] == [1.0] * 4 and step["bias"] == [0.0] * 4
    np.testing.assert_array_equal(out[0], px)


def test_percentile_clip_cuts_and_reports(rng):
    px = (0.45 + 0.1 * rng.random((64, 64, 4))).astype(np.float32)
    px[0, :8] = 0.0  # a few outliers a min/max stretch would keep
    px[1, :8] = 1.0
    notes = []
    out, kv = transforms.forward([px], Transform(renormalize="texture", renormalize_clip=1.0), notes)
    (step,) = json.loads(kv[transforms.KV_KEY])
    assert step["clip"] == 1.0
    assert all(0.44 < b < 0.47 for b in step["bias"])
    assert all(0.07 < s < 0.11 for s in step["scale"])
    assert len(notes) == 1 and "1.0%" in notes[0] and "r 1.00%/1.00%" in notes[0]
    assert out[0].min() == 0.0 and out[0].max() == 1.0  # the outliers land on the ends
    # without the clip the outliers decide the range
    _, kv = transforms.forward([px], Transform(renormalize="texture"))
    assert json.loads(kv[transforms.KV_KEY])[0]["scale"] == [1.0] * 4


@pytest.mark.parametrize("meta", [
    {"mode": "texture", "scale": [1, 1, 1], "bias": [0, 0, 0, 0]},
    {"mode": "level", "scale": [[1, 1, 1, 1]], "bias": [[0, 0, 0, 0]]},  # too few levels for two
    {"mode": "texture", "scale": [1, 1, 1, "x"], "bias": [0, 0, 0, 0]},
    {"mode": "sideways", "scale": [1, 1, 1, 1], "bias": [0, 0, 0, 0]},
])
def test_bad_records_are_container_errors(meta):
    from texcook.errors import ContainerError

    text = json.dumps([dict(meta, name="renormalize")])
    with pytest.raises(ContainerError):
        transforms.inverse([np.zeros((2, 2, 4), np.float32)] * 2, text)


# --- the recipe ------------------------------------------------------------------------

def test_recipe_settings_are_validated_and_saved():
    r = Recipe.of(renormalize="level", renormalize_clip=0.5)
    assert r.transform.steps == [("renormalize", {"mode": "level", "clip": 0.5})]
    assert Recipe.from_dict(r.to_dict()) == r
    assert r.to_dict()["transform"] == {"renormalize": "level", "renormalize_clip": 0.5}
    assert Recipe.of(renormalize="texture", renormalize_clip=0).transform.renormalize_clip is None
    for bad in ({"renormalize": "image"}, {"renormalize_clip": 1.0},
                {"renormalize": "texture", "renormalize_clip": 30.0},
                {"renormalize": "texture", "renormalize_clip": -1.0},
                {"renormalize": "texture", "renormalize_clip": "1"}):
        with pytest.raises(UsageError):
            Recipe.of(**bad)


# --- baked files -----------------------------------------------------------------------

def _ramp16(tmp_path, lo=0.4, hi=0.6, name="low16.png"):
    """A 16-bit RGB image using only lo..hi of the range."""
    y, x = np.mgrid[0:32, 0:32]
    px = np.stack([x / 31, y / 31, (x + y) / 62], axis=-1)
    px = lo + (hi - lo) * px
    path = tmp_path / name
    write_image(path, np.rint(px * 65535).astype(np.uint16))
    return path, px


def test_16bit_source_is_stretched_before_it_is_quantised(tmp_path):
    src, px = _ramp16(tmp_path)
    out = tmp_path / "r.ktx2"
    bake_file(src, out, Recipe.of(format="rgba8", srgb=False, mips=False, renormalize="texture"))
    back = load_texture(out).levels[0]
    assert back.dtype == np.float32  # restored values fall between 8-bit codes
    err = np.abs(back[..., :3] - px).max()
    # 8-bit codes of the stretched range: a fifth of a code's rounding, not a whole one
    assert err <= 0.2 * 0.5 / 255 + 2e-5
    plain = tmp_path / "p.ktx2"
    bake_file(src, plain, Recipe.of(format="rgba8", srgb=False, mips=False))
    assert np.abs(load_texture(plain).levels[0][..., :3] / 255.0 - px).max() > 3 * err
    # in sRGB the stretch runs in linear light and still comes back
    bake_file(src, out, Recipe.of(format="rgba8", mips=False, renormalize="texture"))
    assert np.abs(load_texture(out).levels[0][..., :3] - px).max() < 0.6 / 255


def test_full_range_image_bakes_the_same_bytes(tmp_path, rng):
    px = rng.integers(0, 256, (12, 20, 4)).astype(np.uint8)
    px[0, 0] = 0
    px[0, 1] = 255
    src = tmp_path / "full.png"
    write_image(src, px)
    a, b = tmp_path / "a.ktx2", tmp_path / "b.ktx2"
    for fmt in ("rgba8", "bc1"):
        bake_file(src, a, Recipe.of(format=fmt, mips=False))
        bake_file(src, b, Recipe.of(format=fmt, mips=False, renormalize="texture"))
        ka, kb = read_ktx2(a.read_bytes(), str(a)), read_ktx2(b.read_bytes(), str(b))
        assert ka.levels == kb.levels, fmt
        step = json.loads(kb.text(transforms.KV_KEY))[0]
        assert step["scale"] == [1.0] * 4 and step["bias"] == [0.0] * 4


def test_every_codec_round_trips_a_renormalised_texture(tmp_path):
    src, px = _ramp16(tmp_path, 0.3, 0.5)
    # every codec, one ASTC block size standing for its family
    names = [n for n in codecs.names() if not n.startswith("astc-")]
    names += [n for n in codecs.names() if n.startswith("astc-")][:1]
    for name in names:
        codec = codecs.get(name)
        out = tmp_path / f"{name}.ktx2"
        bake_file(src, out, Recipe.of(format=name, mips=False, srgb=False, renormalize="texture",
                                      preset="fastest"))
        back = load_texture(out).levels[0]
        assert back.dtype == np.float32, name
        n = min(codec.channels, 3)
        err = np.abs(back[..., :n] - px[..., :n]).max()
        # within a block codec's worst error on a 2-D colour ramp (about 17 codes for
        # BC1's fastest preset; ETC1S, one base colour per block from a small file-wide
        # vocabulary, about 38), scaled down by the stretch
        worst = 48 if codec.format.basislz else 24
        assert err < 0.2 * worst / 255, (name, err)


def test_bc1_gains_on_a_low_contrast_16bit_source(tmp_path):
    """Where BC1's error is its endpoints' 5:6:5 quantisation (colours on a line
    in each block), the stretch wins back most of the fifth of the range."""
    from texcook.pipeline import compare

    y, x = np.mgrid[0:32, 0:32]
    t = np.sin(x / 5.0) * np.cos(y / 7.0) * 0.5 + 0.5
    px = 0.4 + 0.2 * t[..., None] * np.array([1.0, 0.8, 0.6])
    src = tmp_path / "line16.png"
    write_image(src, np.rint(px * 65535).astype(np.uint16))
    a, b = tmp_path / "a.ktx2", tmp_path / "b.ktx2"
    bake_file(src, a, Recipe.of(format="bc1", mips=False))
    bake_file(src, b, Recipe.of(format="bc1", mips=False, renormalize="texture"))
    assert compare(src, b)["psnr"] > compare(src, a)["psnr"] + 6.0


def test_key_values_read_back_by_ktx_parse(tmp_path, ktx_parse):
    src, _ = _ramp16(tmp_path)
    out = tmp_path / "k.ktx2"
    summary = bake_file(src, out, Recipe.of(format="bc1", renormalize="level", renormalize_clip=2.0))
    assert any("renormalize clipped" in n for n in summary["notes"])
    ours = read_ktx2(out.read_bytes(), str(out)).text(transforms.KV_KEY)
    (theirs,) = ktx_parse([out])
    assert theirs["keyValue"][transforms.KV_KEY] == ours
    step = json.loads(ours)[0]
    assert step["mode"] == "level" and len(step["scale"]) == summary["levels"]


def test_containers_without_key_values_are_refused(tmp_path):
    src, _ = _ramp16(tmp_path)
    with pytest.raises(UsageError, match="DDS"):
        bake_file(src, tmp_path / "r.dds", Recipe.of(format="bc1", renormalize="texture"))
    assert not (tmp_path / "r.dds").exists()
    with pytest.raises(UsageError, match="astc"):
        bake_file(src, tmp_path / "r.astc", Recipe.of(format="astc-6x6", renormalize="texture"))


def test_cli_flags(tmp_path, cli_run):
    src, px = _ramp16(tmp_path)
    out = tmp_path / "c.ktx2"
    code, stdout, stderr = cli_run("bake", src, "-o", out, "-f", "bc4", "--renormalize", "texture",
                                   "--renormalize-clip", "0.5")
    assert code == 0 and "renormalize clipped 0.5%" in stderr
    code, _, stderr = cli_run("bake", src, "-o", out, "--renormalize-clip", "0.5")
    assert code == 2 and "--renormalize" in stderr
    png = tmp_path / "d.png"
    code, _, _ = cli_run("decode", out, "-o", png)
    assert code == 0 and png.exists()
    # decoded to a float file the restored values keep their precision: the source's
    # red within BC4's error on the stretched ramp, a fifth of it in source units
    exr = tmp_path / "d.exr"
    code, _, _ = cli_run("decode", out, "-o", exr)
    assert code == 0
    from texcook.image import read_image

    back = read_image(exr).pixels[..., 0]
    assert np.abs(back - px[..., 0]).max() < 0.2 * 4 / 255
