"""The bake plan: every decision made once, from the header, and read by the bake."""

import json

import numpy as np
import pytest

from texcook import codecs
from texcook import plan as planner
from texcook.image import Image, read_header, write_image
from texcook.pipeline import bake, plan_bake, settle
from texcook.recipe import Recipe


def _png(path, px):
    write_image(path, px)
    return path


@pytest.fixture
def rgba_png(tmp_path, rng):
    return _png(tmp_path / "rgba.png", rng.integers(0, 256, (24, 20, 4), dtype=np.uint8))


def test_header_says_what_read_image_says(tmp_path, rng):
    from texcook.image import header_of, read_image

    for name, px in (("g.png", rng.integers(0, 65535, (5, 7, 1), dtype=np.uint16)),
                     ("ga.png", rng.integers(0, 256, (5, 7, 2), dtype=np.uint8)),
                     ("f.exr", rng.random((5, 7, 3), dtype=np.float32))):
        path = _png(tmp_path / name, px)
        assert read_header(path) == header_of(read_image(path))


def test_plan_is_made_without_reading_pixels(tmp_path, rgba_png, cli_run, monkeypatch):
    import texcook.image

    def no_pixels(*args, **kwargs):
        raise AssertionError("pixels read")

    monkeypatch.setattr(texcook.image, "_read_image", no_pixels)
    code, out, err = cli_run("bake", rgba_png, "-o", tmp_path / "o.ktx2", "-f", "bc3", "--alpha-cutoff", "0.4",
                             "--plan", "--json")
    assert code == 0, err
    plan = json.loads(out)
    assert (plan["format"], plan["vk_format"], plan["colour_space"]["chosen"]) == ("bc3", 138, "srgb")
    assert plan["levels"] == [[20, 24], [10, 12], [5, 6], [2, 3], [1, 1]]
    assert plan["chain"]["alpha_cutoff"] == 0.4 and plan["steps"]["ran"]["coverage"]
    assert plan["key_values"] == {"texcook.alphaCutoff": "0.4"}
    assert not (tmp_path / "o.ktx2").exists()
    code, out, _ = cli_run("bake", rgba_png, "-o", tmp_path / "o.ktx2", "-f", "bc4", "--plan")
    assert code == 0 and "skipped    srgb: bc4 has no sRGB variant" in out
    assert "whether the alpha is opaque" in out and not (tmp_path / "o.ktx2").exists()


def test_an_image_over_the_memory_budget_still_plans(tmp_path, rgba_png, cli_run):
    out = tmp_path / "o.ktx2"
    code, text, err = cli_run("--max-memory", "1K", "bake", rgba_png, "-o", out, "--plan")
    assert code == 0, err
    assert "format     rgba8" in text and "levels     5: 20x24" in text
    code, _, err = cli_run("--max-memory", "1K", "bake", rgba_png, "-o", out)
    assert code == 1 and "memory budget" in err and not out.exists()


def test_plan_refuses_what_the_source_cannot_do(tmp_path, rng, cli_run):
    rgb = _png(tmp_path / "rgb.png", rng.integers(0, 256, (8, 8, 3), dtype=np.uint8))
    code, _, err = cli_run("bake", rgb, "-o", tmp_path / "o.ktx2", "--alpha-cutoff", "0.5", "--plan")
    assert code == 2 and "needs a source with an alpha channel" in err


def _settled_matches_bake(image, recipe, container="ktx2"):
    plan = settle(plan_bake(image, recipe, container=container), image)
    baked = bake(image, plan)
    assert baked.codec.name == plan.format and baked.srgb == plan.srgb
    assert len(baked.levels) == len(plan.levels)
    assert baked.notes == list(plan.notes) and baked.colour_reason == plan.colour_reason
    assert {k: v for k, v in baked.kv.items() if k != "texcook.transforms"} == {
        k: v for k, v in plan.kv if v is not None}
    return plan, baked


@pytest.mark.parametrize("shape,dtype,recipe", [
    ((9, 7, 1), np.uint8, Recipe()),
    ((9, 7, 2), np.uint8, Recipe.of(srgb=False)),
    ((9, 7, 2), np.uint16, Recipe()),
    ((8, 8, 3), np.float32, Recipe()),
    ((8, 8, 4), np.uint8, Recipe.of(format="bc1", colour_space="auto")),
    ((8, 8, 4), np.uint8, Recipe.of(format="bc4")),
    ((8, 8, 3), np.uint8, Recipe.of(normal_map=True, normal_layout="xy")),
    ((8, 8, 4), np.uint8, Recipe.of(format="bc1a", alpha_cutoff=0.5, premultiply=True)),
    ((8, 8, 4), np.uint8, Recipe.of(swizzle="bgra", mips=False)),
])
def test_the_bake_does_what_its_plan_says(rng, shape, dtype, recipe):
    hi = 1.0 if dtype == np.float32 else np.iinfo(dtype).max
    px = (rng.random(shape) * hi).astype(dtype)
    _settled_matches_bake(Image.from_array(px), recipe)


def test_settling_makes_the_pixel_decisions_once(rng):
    bright = Image.from_array(np.full((8, 8, 3), 250, np.uint8))
    plan = plan_bake(bright, Recipe.of(format="bc1", colour_space="auto"))
    assert plan.srgb is None and plan.vk_format is None and not plan.settled
    assert plan.decode  # an sRGB source is filtered in linear light whichever encoding auto chooses
    done = settle(plan, bright)
    assert done.srgb is False and done.to_light and done.decode and done.settled
    assert json.loads(done.key_values[planner.COLOUR_KEY])["chosen"] == "linear"
    assert settle(done, bright) is done
    with pytest.raises(Exception, match="not the one the bake was planned for"):
        settle(plan, Image.from_array(np.zeros((4, 8, 3), np.uint8)))


def test_an_astc_file_plans_one_level(rng):
    image = Image.from_array(rng.integers(0, 256, (16, 16, 4), dtype=np.uint8))
    plan = plan_bake(image, Recipe.of(format="astc-4x4"), container="astc")
    assert len(plan.levels) == 1 and plan.step("mips") == (False, "a .astc file holds one level")
    assert plan.notes == ("a .astc file holds one level: no mips were built",)
    assert plan.to_dict()["key_values"] == {}  # .astc holds no key/values


def test_the_bake_takes_the_format_and_decoding_from_the_plan(rng, monkeypatch):
    """A planner rule changed is what the bake does: the pipeline re-derives nothing."""
    px = np.arange(64, dtype=np.uint8).reshape(4, 4, 4) * 4
    image = Image.from_array(px)
    kept = codecs.get("rgba8").decode(bake(image, Recipe.of(mips=False)).levels[0], 4, 4)
    assert np.array_equal(kept, px)  # decoded to linear light and encoded back
    monkeypatch.setattr(planner, "decodes", lambda srgb, to_light, space: False)
    plan = plan_bake(image, Recipe.of(mips=False))
    assert plan.srgb and not plan.decode
    encoded = codecs.get("rgba8").decode(bake(image, plan).levels[0], 4, 4)
    assert not np.array_equal(encoded[..., :3], px[..., :3])  # sRGB-encoded once more: the plan's word
    monkeypatch.setattr(planner, "resolve_format", lambda header, recipe, container="ktx2": ("rgba16f", None))
    assert bake(image, Recipe.of(mips=False)).codec.name == "rgba16f"


def test_the_codec_gets_the_plan_s_options(rng, monkeypatch):
    image = Image.from_array(rng.integers(0, 256, (8, 8, 3), dtype=np.uint8))
    seen = {}
    bc1 = type(codecs.get("bc1"))
    real = bc1._encode

    def encode(self, rgba, preset, threads, options):
        seen.update(options)
        return real(self, rgba, preset, threads, options)

    monkeypatch.setattr(bc1, "_encode", encode)
    bake(image, Recipe.of(format="bc1", mips=False, preset="fastest"), container="dds")
    assert seen.get("opaque_black") is False  # DDS's default for BC1
    seen.clear()
    monkeypatch.setattr(planner, "codec_options", lambda codec, recipe, container, srgb=False: {})
    bake(image, Recipe.of(format="bc1", mips=False, preset="fastest"), container="dds")
    assert seen.get("opaque_black") is not False


def test_preview_builds_the_chain_its_plan_says(tmp_path, rng, monkeypatch):
    from texcook.preview.source import load

    path = _png(tmp_path / "p.png", rng.integers(0, 256, (16, 12, 3), dtype=np.uint8))
    tex = load(path, mips=False)
    assert tex.level_count == 5 and tex.srgb and len(tex.levels) == 1
    monkeypatch.setattr(planner, "colour_choice", lambda *a, **k: (False, None, False))
    assert not load(path, mips=True).srgb  # the plan's answer, not a rule of preview's own


def test_scene_json_steps_follow_the_planner(tmp_path, rng, monkeypatch):
    """scene.json's "steps" are the bake plans': a planner rule changed (no
    premultiplied chains) is what scene.json says."""
    from test_scene import build, colour_rgba

    from texcook import scene

    soft = np.rint(rng.random((16, 16)) * 255).astype(np.uint8)
    path = build(tmp_path / "glass.gltf", {"glass": colour_rgba(rng, alpha=soft)}, [("glass", None)],
                 [{"name": "glass", "alphaMode": "BLEND", "slots": {"baseColorTexture": 0}}])

    def steps(out):
        scene.bake_scene(path, tmp_path / out, preset="fastest")
        (entry,) = json.loads((tmp_path / out / "scene.json").read_text())["bakes"]
        return entry["steps"]

    assert steps("before")["ran"]["premultiply"] == "alphaMode BLEND: colour filtered weighted by alpha"
    real = planner._mip_steps

    def never_premultiply(*args):
        chain, found = real(*args)
        chain = tuple((k, False if k == "premultiply" else v) for k, v in chain)
        return chain, [(s, False, "premultiplying is off") if s == "premultiply" else (s, r, w) for s, r, w in found]

    monkeypatch.setattr(planner, "_mip_steps", never_premultiply)
    after = steps("after")
    assert "premultiply" not in after["ran"] and after["skipped"]["premultiply"] == "premultiplying is off"
    assert after["ran"]["mips"] and after["ran"]["srgb"]  # the rest as before


def test_bench_stages_bakes_its_plan(tmp_path, rng, monkeypatch):
    from texcook import bench

    src = _png(tmp_path / "s.png", rng.integers(0, 256, (16, 8, 3), dtype=np.uint8))
    (row,) = bench.stages(src, ["rgba8"], ["fast"], repeat=1)["rows"]
    assert row["levels"] == 5 and row["skipped"] == {"transform": "none asked for"}
    monkeypatch.setattr(planner, "max_levels", lambda w, h: 2)
    (row,) = bench.stages(src, ["rgba8"], ["fast"], repeat=1)["rows"]
    assert row["levels"] == 2


def test_the_chain_is_as_long_as_the_plan_says(rng, monkeypatch):
    image = Image.from_array(rng.integers(0, 256, (16, 8, 3), dtype=np.uint8))
    assert len(bake(image, Recipe()).levels) == 5
    monkeypatch.setattr(planner, "max_levels", lambda w, h: 2)
    assert len(bake(image, Recipe()).levels) == 2


def test_the_range_check_is_the_plan_s(monkeypatch):
    px = np.full((4, 4, 3), 7e4, np.float32)
    image = Image.from_array(px)
    half = plan_bake(image, Recipe.of(format="rgba16f", mips=False))
    assert half.range_limit == 65504.0 and half.step("range")[0]
    with pytest.raises(Exception, match="beyond the rgba16f range"):
        bake(image, half)
    full = plan_bake(image, Recipe.of(format="rgba32f", mips=False, clamp=True))
    assert full.range_limit is None and not full.step("range")[0]
    monkeypatch.setattr(planner, "_range_limit", lambda fmt: 1.0)
    baked = bake(image, Recipe.of(format="rgba32f", mips=False, clamp=True))
    assert baked.clamped == 48 and np.frombuffer(baked.levels[0], np.float32).max() == 1.0
