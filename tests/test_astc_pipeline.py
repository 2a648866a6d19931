"""ASTC end to end: bake_file and the CLI with mip options and colour spaces,
.astc files in and out, normal maps, refusals before any work."""

import json

import numpy as np
import pytest

from texcook.container.ktx2 import read_ktx2
from texcook.pipeline import bake_file, compare, load_texture
from texcook.recipe import Recipe

from conftest import CORPUS, files_in


@pytest.mark.parametrize("flat", [
    dict(),
    dict(srgb=False, mip_filter="kaiser", wrap="repeat"),
    dict(alpha_cutoff=0.5, premultiply=True, mip_filter="lanczos"),
    dict(mips=False, zstd=5),
])
def test_astc_6x6_bakes_with_every_mip_option(tmp_path, flat):
    src = CORPUS / "rgba" / "ldr-rgba-00.png"
    out = tmp_path / "t.ktx2"
    summary = bake_file(src, out, Recipe.of(format="astc-6x6", preset="fastest", **flat))
    ktx = read_ktx2(out.read_bytes(), str(out))
    assert ktx.vk_format == (166 if summary["colour_space"] == "srgb" else 165)
    assert len(ktx.levels) == (1 if flat.get("mips") is False else 9)
    assert summary["colour_space"] == ("linear" if flat.get("srgb") is False else "srgb")
    level0 = compare(src, out, level=0)
    assert level0["psnr"] > 25.0, level0


def test_astc_file_out_and_in(tmp_path, cli_run):
    src = CORPUS / "rgb" / "ldr-rgb-10.png"  # 127x128: partial blocks
    out = tmp_path / "t.astc"
    code, stdout, stderr = cli_run("bake", src, "-o", out, "--format", "astc-8x8", "--preset", "fastest", "--linear",
                                   "--json")
    assert code == 0, stderr
    summary = json.loads(stdout)
    assert summary["levels"] == 1 and "one level" in stderr
    data = out.read_bytes()
    assert data[:4] == b"\x13\xab\xa1\x5c" and len(data) == 16 + 16 * 16 * 16
    tex = load_texture(out)
    assert tex.levels[0].shape == (128, 127, 4)
    code, stdout, _ = cli_run("compare", src, out, "--json")
    assert code == 0 and json.loads(stdout)["psnr"] > 24.0
    code, _, _ = cli_run("decode", out, "-o", tmp_path / "back.png")
    assert code == 0 and (tmp_path / "back.png").exists()


def test_astc_normal_map_stores_x_in_rgb_and_y_in_alpha(tmp_path):
    src = CORPUS / "normal" / "ldr-xy-00.png"
    out = tmp_path / "n.ktx2"
    bake_file(src, out, Recipe.of(format="astc-5x5", normal_map=True, preset="fastest", mips=False))
    ktx = read_ktx2(out.read_bytes(), str(out))
    assert ktx.text("KTXswizzle") == "ra01" and ktx.vk_format == 161  # linear: vectors are never sRGB
    from texcook import codecs

    raw = codecs.get("astc-5x5").decode(ktx.levels[0], ktx.width, ktx.height)
    # X sits in R, G and B, Y in alpha
    assert np.abs(raw[..., 0].astype(int) - raw[..., 1]).max() <= 2
    tex = load_texture(out)
    assert tex.channels == 2
    assert compare(src, out)["psnr"] > 35.0


def test_refused_before_any_work(tmp_path, cli_run):
    for args, needle in [(["-o", tmp_path / "x.dds", "-f", "astc-4x4"], "cannot be written to DDS"),
                         (["-o", tmp_path / "x.astc", "-f", "bc1"], "holds ASTC blocks"),
                         (["-o", tmp_path / "x.ktx2", "-f", "astc-4x4", "--weights", "1,1,1"], "weights")]:
        code, _, stderr = cli_run("bake", tmp_path / "missing.png", *args)
        assert code == 2 and needle in stderr, stderr
    assert files_in(tmp_path) == []


def test_info_describes_an_astc_file_from_its_header(tmp_path, cli_run):
    from texcook.container.astcfile import write_astc
    from texcook.fileio import set_max_memory

    path = tmp_path / "big.astc"
    # 4096x4096 in 12x12 blocks: 1.9 MB of blocks that decode to 268 MB of float texels
    path.write_bytes(write_astc(12, 12, 4096, 4096, bytes(16 * 342 * 342)))
    code, stdout, stderr = cli_run("info", path, "--json")
    assert code == 0, stderr
    desc = json.loads(stdout)
    assert (desc["format"], desc["width"], desc["height"], desc["levels"]) == ("astc-12x12", 4096, 4096, 1)
    code, _, stderr = cli_run("--max-memory", "64M", "decode", path, "-o", tmp_path / "x.png")
    assert code == 1 and "memory budget" in stderr and "big.astc" in stderr
    set_max_memory(None)
    assert not (tmp_path / "x.png").exists()
