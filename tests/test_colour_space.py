"""--colour-space auto: Kaplanyan's rule for storing colour as sRGB or linear."""

import json

import numpy as np
import pytest

from texcook import codecs
from texcook.colour import AUTO_THRESHOLD, auto_colour_space, bright_share
from texcook.container.ktx2 import read_ktx2
from texcook.errors import UsageError
from texcook.image import Image, read_image, write_image
from texcook.pipeline import COLOUR_KEY, bake_file, colour_choice, compare, load_texture, output_srgb
from texcook.recipe import Recipe


def test_rule_counts_values_strictly_above_116():
    assert bright_share(np.full(10, AUTO_THRESHOLD)) == 0.0
    assert bright_share(np.full(10, 117 / 255)) == 1.0
    v = np.array([117, 117, 117, 116]) / 255
    assert auto_colour_space(v) == ("linear", 0.75)  # at least 75% is enough
    v = np.array([117, 116, 116, 116, 200, 200, 200, 200]) / 255
    assert auto_colour_space(v) == ("srgb", 5 / 8)


def _image(tmp_path, rng, lo, hi, name, channels=3):
    px = rng.integers(lo, hi + 1, (16, 16, channels)).astype(np.uint8)
    path = tmp_path / name
    write_image(path, px)
    return path, px


def test_auto_picks_linear_for_bright_and_srgb_for_dark(tmp_path, rng):
    bright, _ = _image(tmp_path, rng, 130, 255, "bright.png")
    dark, _ = _image(tmp_path, rng, 0, 150, "dark.png")
    recipe = Recipe.of(format="bc1", colour_space="auto")
    out = tmp_path / "t.ktx2"
    s = bake_file(bright, out, recipe)
    assert s["colour_space"] == "linear" and s["vk_format"] == 131
    assert s["colour_space_reason"].startswith("auto: 100.0% of the colour values are above 116/255")
    record = json.loads(read_ktx2(out.read_bytes(), str(out)).text(COLOUR_KEY))
    assert record == {"chosen": "linear", "reason": s["colour_space_reason"][6:], "source": "srgb", "to_light": True}
    s = bake_file(dark, out, recipe)
    assert s["colour_space"] == "srgb" and s["vk_format"] == 132
    record = json.loads(read_ktx2(out.read_bytes(), str(out)).text(COLOUR_KEY))
    assert record["chosen"] == "srgb" and not record["to_light"]
    # without auto nothing is recorded
    bake_file(dark, out, Recipe.of(format="bc1"))
    assert read_ktx2(out.read_bytes(), str(out)).text(COLOUR_KEY) is None


def test_linear_choice_stores_linear_light_and_reads_back_in_srgb(tmp_path, rng):
    bright, px = _image(tmp_path, rng, 130, 255, "bright.png")
    out = tmp_path / "t.ktx2"
    bake_file(bright, out, Recipe.of(format="rgba8", colour_space="auto", mips=False))
    ktx = read_ktx2(out.read_bytes(), str(out))
    stored = np.frombuffer(ktx.levels[0], np.uint8).reshape(16, 16, 4)[..., :3] / 255.0
    from texcook.colour import srgb_to_linear

    # colour, stored as linear light (not the sRGB values kept as data)
    assert np.abs(stored - srgb_to_linear(px / 255.0)).max() <= 0.5 / 255 + 1e-6
    tex = load_texture(out)
    assert tex.srgb and tex.levels[0].dtype == np.float32
    # read back in the source's encoding: the only loss is linear 8-bit's own step
    assert np.abs(tex.levels[0][..., :3] * 255 - px).max() < 1.0
    assert compare(bright, out)["psnr"] > 55


def test_fallbacks_and_their_reasons(tmp_path, rng):
    img = Image.from_array(rng.integers(200, 256, (8, 8, 3)).astype(np.uint8))
    auto = Recipe.of(colour_space="auto")
    assert colour_choice(img, auto, codecs.get("bc4")) == (False, "bc4 has no sRGB variant", False)
    assert colour_choice(img, auto.replace(normal_map=True), codecs.get("bc5")) == (
        False, "a normal map holds vectors", False)
    assert colour_choice(img, auto, codecs.get("rgba16f"))[0] is False
    assert output_srgb(img, auto, codecs.get("bc1")) is False  # bright: linear
    assert colour_choice(img, Recipe.of(srgb=True), codecs.get("bc1")) == (True, None, False)
    # a linear float source is judged by its values in sRGB encoding
    dim = Image.from_array(np.full((4, 4, 3), 0.1, np.float32))  # 0.1 linear is 89/255 in sRGB
    assert colour_choice(dim, auto, codecs.get("bc1"))[:2] == (True, "0.0% of the colour values are above "
                                                                    "116/255; linear from 75%")
    # alpha does not count
    rgba = rng.integers(0, 100, (8, 8, 4)).astype(np.uint8)
    rgba[..., 3] = 255
    assert colour_choice(Image.from_array(rgba), auto, codecs.get("bc3"))[0] is True


def test_recipe_and_cli(tmp_path, rng, cli_run, ktx_parse):
    r = Recipe.of(colour_space="auto", normal_map=True)
    assert Recipe.from_dict(r.to_dict()) == r
    with pytest.raises(UsageError):
        Recipe.of(colour_space="gamma")
    bright, _ = _image(tmp_path, rng, 130, 255, "bright.png")
    out = tmp_path / "c.ktx2"
    code, stdout, _ = cli_run("bake", bright, "-o", out, "-f", "bc1", "--colour-space", "auto")
    assert code == 0 and "bc1 linear (auto: 100.0% of the colour values" in stdout
    code, stdout, _ = cli_run("info", out)
    assert code == 0 and COLOUR_KEY in stdout and '"chosen": "linear"' in stdout
    (theirs,) = ktx_parse([out])
    assert json.loads(theirs["keyValue"][COLOUR_KEY])["chosen"] == "linear"
    code, _, stderr = cli_run("bake", bright, "-o", out, "--srgb", "--colour-space", "auto")
    assert code == 2 and "not both" in stderr
    code, stdout, _ = cli_run("bake", bright, "-o", out, "-f", "bc1", "--colour-space", "srgb")
    assert code == 0 and "bc1 srgb 16x16" in stdout
    png = tmp_path / "d.png"
    code, _, _ = cli_run("bake", bright, "-o", out, "-f", "bc1", "--colour-space", "auto")
    code, _, _ = cli_run("decode", out, "-o", png)
    assert code == 0 and read_image(png).colour_space == "srgb"


def test_grey_alpha_with_auto_keeps_rgba(tmp_path, rng):
    path, _ = _image(tmp_path, rng, 150, 255, "ga.png", channels=2)
    s = bake_file(path, tmp_path / "ga.ktx2", Recipe.of(colour_space="auto"))
    assert s["format"] == "rgba8"
