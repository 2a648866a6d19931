"""The formats `texcook scene` writes per use: a mobile scene baked by a build
without an ASTC encoder holds its alpha in ETC2 (etc2a8: three.js's
KTX2Loader refuses the punch-through etc2a1 a two-level cut-out would fit), its normal map's X and
Y in EAC RG11 and a lone occlusion map in EAC R11; nothing stays rgba8 and no
normal map is ETC1 with Z. On desktop, blended alpha is BC7 and a soft
cut-out BC3. Each output is read back by texcook's reader and ktx-parse (or
OpenImageIO for DDS), and decoded by texture2ddecoder, as a glTF reader would."""

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import read_straight
from decoders import t2d
from test_scene import build, check_outputs, validate  # noqa: F401  (validate: the fixture)
from test_scene_normals import bumps, degrees, png, unit
from test_view_browser import browser  # noqa: F401  (the fixture: headless Chromium, or a skip)

from texcook import codecs, formats, scene
from texcook.container import table as containers
from texcook.container.ktx2 import read_ktx2
from texcook.mips import alpha_coverage

N = 64
PRESET = "fastest"
LEAF_CUTOFF = 0.4
NO_ASTC = [f for f in codecs.names() if not f.startswith("astc-")]  # a build without an ASTC encoder


def leaf(n=N):
    """A cut-out: a two-level alpha (a lobed disc) over a colour gradient."""
    y, x = (np.mgrid[0:n, 0:n] + 0.5) / n - 0.5
    r = np.hypot(x - 0.03, y + 0.05)  # off centre and turned: no mirror symmetry, whose ties
    inside = r < 0.32 + 0.08 * np.cos(5 * np.arctan2(y, x) + 0.7)  # would leave some counts unreachable
    px = np.empty((n, n, 4), np.uint8)
    px[..., 0] = np.rint(60 + 120 * (x + 0.5))
    px[..., 1] = np.rint(200 - 100 * (y + 0.5))
    px[..., 2] = 40
    px[..., 3] = np.where(inside, 255, 0)
    return px


def glass(n=N):
    """Blended alpha: a smooth ramp across the image."""
    y, x = (np.mgrid[0:n, 0:n] + 0.5) / n
    px = np.empty((n, n, 4), np.uint8)
    px[..., 0], px[..., 1], px[..., 2] = 90, np.rint(255 * y), 220
    px[..., 3] = np.rint(40 + 200 * x)
    return px


def occlusion(n=N):
    y, x = (np.mgrid[0:n, 0:n] + 0.5) / n
    v = np.rint(255 * (0.6 + 0.4 * np.sin(3 * np.pi * x) * np.cos(2 * np.pi * y))).clip(0, 255).astype(np.uint8)
    return np.stack([v, v, v], axis=-1)


@pytest.fixture(scope="module")
def mobile(tmp_path_factory, validate, ktx_parse):  # noqa: F811
    """A model with an alpha-tested leaf (base colour, normal map, occlusion)
    and a blended pane, baked for mobile by a build without ASTC: (folder,
    report, rewritten model JSON, source normals)."""
    folder = tmp_path_factory.mktemp("mobile")
    normal_px, normals = bumps(N)
    images = {"leaf": leaf(), "glass": glass(), "bumps": normal_px, "ao": occlusion()}
    textures = [("leaf", 0), ("glass", 0), ("bumps", 0), ("ao", 0)]
    materials = [
        {"name": "leaf", "alphaMode": "MASK", "alphaCutoff": LEAF_CUTOFF,
         "slots": {"baseColorTexture": 0, "normalTexture": 2, "occlusionTexture": 3}},
        {"name": "glass", "alphaMode": "BLEND", "slots": {"baseColorTexture": 1}},
    ]
    (folder / "src").mkdir()
    path = model(folder / "src" / "model.gltf", images, textures, materials)
    out = folder / "out"
    report = scene.bake_scene(path, out, target="mobile", preset=PRESET, available=NO_ASTC)
    check_outputs(out, report, validate, ktx_parse)  # gltf-validator: no errors; ktx-parse reads every file
    doc = json.loads((out / "model.gltf").read_text())
    return out, report, doc, normals


def slot_image(out, doc, material, slot):
    """What a reader of the rewritten model loads for a material slot: the
    parsed KTX2 file and the extension that points at it."""
    m = next(m for m in doc["materials"] if m["name"] == material)
    info = m["pbrMetallicRoughness"][slot] if slot == "baseColorTexture" else m[slot]
    (ext, ref), = doc["textures"][info["index"]]["extensions"].items()
    return read_ktx2((Path(out) / doc["images"][ref["source"]]["uri"]).read_bytes()), ext


def model(path, images, textures, materials):
    """test_scene.build's model, its PNGs rewritten with straight alpha as given
    (build's encoder takes colour as premultiplied and divides it by alpha)."""
    path = build(path, images, textures, materials, samplers=[{"minFilter": 9987, "magFilter": 9729}])
    for name, px in images.items():
        png(Path(path).parent / f"{name}.png", px)
    return path


def decode_level(fmt, data, w, h):
    """texture2ddecoder's decode of one level (blocks padded to 4x4), cropped."""
    pw, ph = -(-w // 4) * 4, -(-h // 4) * 4
    return t2d(fmt, data, pw, ph)[:h, :w]


# (material, slot) -> format, colour space
WANT = {("leaf", "baseColorTexture"): ("etc2a8", "srgb"), ("glass", "baseColorTexture"): ("etc2a8", "srgb"),
        ("leaf", "normalTexture"): ("eac-rg11", "linear"), ("leaf", "occlusionTexture"): ("eac-r11", "linear")}


def test_a_mobile_scene_without_astc_writes_etc2_and_eac(mobile, ktx_parse):
    """Was: rgba8 for both alpha uses and ETC1 (X, Y, Z) for the normal map."""
    out, report, doc, _ = mobile
    assert {(u["material_name"], u["slot"]): b["format"] for b in report["bakes"]
            for t in report["textures"] if t["bake"] == b["id"] for u in t["uses"]} == \
        {k: f for k, (f, _) in WANT.items()}
    for (material, slot), (fmt, space) in WANT.items():
        ktx, ext = slot_image(out, doc, material, slot)
        row = formats.get(fmt)
        assert ktx.vk_format == (row.vk_srgb if space == "srgb" else row.vk_unorm), (material, slot)
        # the extension the model names is the one the container table gives this format
        assert ext == containers.get("ktx2").gltf_extension(fmt) == scene.EXT_KTX2
    files = {b["output"]: b for b in report["bakes"]}
    for rec in ktx_parse([out / name for name in files]):
        b = files[Path(rec["file"]).name]
        row = formats.get(b["format"])
        assert rec["vkFormat"] == (row.vk_srgb if b["colour_space"] == "srgb" else row.vk_unorm)
        assert rec["levelCount"] == 7
    for b in report["bakes"]:
        assert not any("rgba8" in n or "ETC1" in n for n in b["notes"]), b["notes"]
    nrm = next(b for b in report["bakes"] if b["format"] == "eac-rg11")
    assert any("rebuilds Z" in n for n in nrm["notes"])
    assert report["extensionsUsed"] == [scene.EXT_KTX2] and report["extensionsRequired"] == []


def test_the_etc2a8_cutout_keeps_its_coverage_at_the_cutoff_in_every_level(mobile):
    out, report, doc, _ = mobile
    ktx, _ = slot_image(out, doc, "leaf", "baseColorTexture")
    assert ktx.vk_format == formats.get("etc2a8").vk_srgb
    src = leaf()[..., 3] / 255.0
    target = alpha_coverage(src, LEAF_CUTOFF)
    assert 0.2 < target < 0.6
    got = []
    for i, data in enumerate(ktx.levels):
        w, h = max(1, N >> i), max(1, N >> i)
        alpha = decode_level("etc2a8", data, w, h)[..., 3]
        got.append(alpha_coverage(alpha / 255.0, LEAF_CUTOFF))
        # as close as the level's texel count allows (a 2x2 level steps by a quarter)
        assert abs(got[-1] - target) <= max(0.03, 0.5 / (w * h)) + 1e-9, (i, target, got)
    assert len(got) == 7
    steps = next(b for b in report["bakes"] if b["name"].startswith("leaf"))["steps"]
    assert steps["ran"]["coverage"] == f"alphaMode MASK at cutoff {LEAF_CUTOFF} (leaf)"


def test_the_eac_rg11_normal_map_reads_back_as_the_source_normals(mobile):
    """The reader of the extension rebuilds Z from X and Y (its name is in the
    container table's gltf_rebuilds_z), as for BC5 on desktop."""
    out, _, doc, normals = mobile
    ktx, ext = slot_image(out, doc, "leaf", "normalTexture")
    assert ktx.vk_format == formats.get("eac-rg11").vk_unorm
    assert ext in containers.get("ktx2").gltf_rebuilds_z
    assert ktx.text("KTXswizzle") is None and ktx.text("texcook.content") == "normal"
    rg = decode_level("eac-rg11", ktx.levels[0], N, N)
    xy = rg[..., :2].astype(np.float64) / 255.0 * 2.0 - 1.0
    z = np.sqrt(np.clip(1.0 - np.sum(xy * xy, axis=-1), 0.0, 1.0))
    angle = degrees(unit(np.dstack([rg[..., :2], np.rint((z * 0.5 + 0.5) * 255.0)])), normals)
    # measured at preset fastest: 1.05 degrees mean, 3.7 at the 99th percentile (bc5 there: 1.18 / 3.9;
    # ETC1 with Z, what this scene wrote before, 4.1 / 11.5 at medium). The layout's own floor, Z
    # rebuilt from the source's X and Y, is 0.04 / 0.32: the rest is the codec's.
    mean, p99 = angle.mean(), np.percentile(angle, 99)
    assert mean < 1.5 and p99 < 5.0, (mean, p99)
    # every level is a unit normal map: the last one points near the bumps' mean normal (straight up)
    last = decode_level("eac-rg11", ktx.levels[-1], 1, 1)[0, 0, :2] / 255.0 * 2.0 - 1.0
    assert np.hypot(*last) < 0.2


# ----------------------------------------------------------------------------- desktop: BC7 for blended alpha


def fern(n=N):
    """A cut-out with soft edges: alpha ramps over a few texels around the outline."""
    px = leaf(n)
    y, x = (np.mgrid[0:n, 0:n] + 0.5) / n - 0.5
    r = np.hypot(x - 0.03, y + 0.05) - (0.32 + 0.08 * np.cos(5 * np.arctan2(y, x) + 0.7))
    px[..., 3] = np.rint(255 * np.clip(0.5 - r / 0.08, 0.0, 1.0))
    return px


@pytest.fixture(scope="module")
def desktop(tmp_path_factory):
    """A soft-edged cut-out and a blended pane, as a .gltf."""
    folder = tmp_path_factory.mktemp("desktop")
    images = {"fern": fern(), "glass": glass()}
    materials = [{"name": "fern", "alphaMode": "MASK", "slots": {"baseColorTexture": 0}},
                 {"name": "glass", "alphaMode": "BLEND", "slots": {"baseColorTexture": 1}}]
    return model(folder / "model.gltf", images, [("fern", 0), ("glass", 0)], materials)


def psnr(a, b):
    mse = np.mean((a.astype(np.float64) - b) ** 2)
    return 10 * np.log10(255.0 ** 2 / mse)


@pytest.mark.parametrize("container", ["ktx2", "dds"])
def test_a_desktop_scene_keeps_blended_alpha_in_bc7_and_a_soft_cutout_in_bc3(desktop, tmp_path, container,
                                                                             validate, ktx_parse):  # noqa: F811
    """Was: BC3 for both. BC7 at the same 8 bits per texel keeps colour that is
    not on one line per block: on the pane, 7.6 dB RGBA above BC3 of the same
    recipe (preset fastest). A soft cut-out stays BC3, whose alpha has a block
    of its own, and keeps its coverage at the cutoff in every level."""
    from texcook.container.dds import read_dds
    from texcook.pipeline import bake_file
    from texcook.recipe import Recipe

    out = tmp_path / "out"
    report = scene.bake_scene(desktop, out, container=container, preset=PRESET)
    check_outputs(out, report, validate, ktx_parse)  # gltf-validator, ktx-parse or OpenImageIO
    doc = json.loads((out / "model.gltf").read_text())
    want = {"fern": "bc3", "glass": "bc7"}
    for b in report["bakes"]:
        name = b["name"].split(".")[0]
        fmt, row = want[name], formats.get(want[name])
        assert (b["format"], b["colour_space"]) == (fmt, "srgb"), name
        data = (out / b["output"]).read_bytes()
        if container == "ktx2":
            ktx = read_ktx2(data)
            assert ktx.vk_format == row.vk_srgb
            levels = ktx.levels
        else:
            stored, _, _, levels = read_dds(data, b["output"])[:4]
            assert stored == fmt and int.from_bytes(data[128:132], "little") == row.dxgi_srgb
        assert doc["textures"][b["textures"][0]]["extensions"] == \
            {containers.get(container).gltf_extension(fmt): {"source": b["image"]}}
        source = Path(desktop).parent / f"{name}.png"
        src = np.rint(read_straight(source) * 255)
        if name == "glass":
            bc3 = tmp_path / "glass.bc3.ktx2"
            bake_file(source, bc3, Recipe.from_dict(b["recipe"]).replace(format="bc3", zstd=None))
            ours = psnr(decode_level("bc7", levels[0], N, N), src)
            theirs = psnr(decode_level("bc3", read_ktx2(bc3.read_bytes()).levels[0], N, N), src)
            assert ours > theirs + 3.0, (ours, theirs)
        else:  # the cut-out's coverage at glTF's default cutoff, in every level
            target = alpha_coverage(src[..., 3] / 255.0, 0.5)
            for i, level in enumerate(levels):
                w = max(1, N >> i)
                got = alpha_coverage(decode_level("bc3", level, w, w)[..., 3] / 255.0, 0.5)
                assert abs(got - target) <= max(0.03, 0.5 / (w * w)) + 1e-9, (i, target, got)


# ----------------------------------------------------------------------------- what three.js loads, per target


def roughness_metal(n=N):
    """A metallic-roughness map as painted: roughness (G) a smooth ramp with a
    ripple, metalness (B) two-level patches (as UV islands; 16-texel squares
    with a few edges inside blocks); R unread."""
    y, x = (np.mgrid[0:n, 0:n] + 0.5) / n
    px = np.empty((n, n, 3), np.uint8)
    px[..., 0] = 128
    px[..., 1] = np.rint(255 * np.clip(0.15 + 0.7 * x + 0.1 * np.sin(6 * np.pi * y), 0, 1))
    px[..., 2] = np.where((np.floor(n * x / 16 + 0.25) + np.floor(n * y / 16)) % 2 == 0, 255, 0)
    return px


@pytest.fixture(scope="module")
def every_use(tmp_path_factory):
    """The mobile fixture's model plus a metallic-roughness map on the leaf."""
    folder = tmp_path_factory.mktemp("targets")
    normal_px, _ = bumps(N)
    images = {"leaf": leaf(), "glass": glass(), "bumps": normal_px, "ao": occlusion(), "mr": roughness_metal()}
    textures = [("leaf", 0), ("glass", 0), ("bumps", 0), ("ao", 0), ("mr", 0)]
    materials = [
        {"name": "leaf", "alphaMode": "MASK", "alphaCutoff": LEAF_CUTOFF,
         "slots": {"baseColorTexture": 0, "normalTexture": 2, "occlusionTexture": 3,
                   "metallicRoughnessTexture": 4}},
        {"name": "glass", "alphaMode": "BLEND", "slots": {"baseColorTexture": 1}},
    ]
    (folder / "src").mkdir()
    return model(folder / "src" / "model.gltf", images, textures, materials)


def test_each_target_is_one_column_of_the_format_table(cli_run):
    from texcook.choices import SCENE_TARGETS

    assert tuple(scene.FORMAT_TABLE) == SCENE_TARGETS
    assert "mobile-etc" in SCENE_TARGETS
    _, out, _ = cli_run("scene", "--help")
    assert "[desktop|mobile|mobile-etc|universal]" in " ".join(out.split())


@pytest.mark.parametrize("target", ["desktop", "mobile", "mobile-etc"])
def test_every_target_writes_what_threejs_loads(every_use, tmp_path, target, validate, ktx_parse):  # noqa: F811
    """Was: mobile wrote occlusion and metallic-roughness in astc-8x8, and
    mobile-etc (no target then) would write metallic-roughness as linear
    ETC2 RGB (vkFormat 147): three.js's KTX2Loader refuses both."""
    from texcook.view.three import THREE_KTX2_VK_FORMATS

    out = tmp_path / "out"
    report = scene.bake_scene(every_use, out, target=target, preset=PRESET)
    check_outputs(out, report, validate, ktx_parse)  # gltf-validator: no errors; ktx-parse reads every file
    for b in report["bakes"]:
        vk = read_ktx2((out / b["output"]).read_bytes()).vk_format
        assert vk in THREE_KTX2_VK_FORMATS, (b["name"], b["format"], vk)
    if target == "mobile-etc":
        mr = next(b for b in report["bakes"] if b["name"].startswith("mr"))
        assert (mr["format"], mr["colour_space"]) == ("etc2", "srgb")
        assert any("refuses linear etc2 (vkFormat 147)" in n for n in mr["notes"]), mr["notes"]
        assert mr["steps"]["ran"]["srgb"].startswith("metallic-roughness is linear data, stored through")
        formats_by_name = {b["name"].split(".")[0]: b["format"] for b in report["bakes"]}
        assert formats_by_name == {"leaf": "etc2a8", "glass": "etc2a8", "bumps": "eac-rg11", "ao": "eac-r11",
                                   "mr": "etc2"}


# The error of metallic-roughness through the sRGB curve, level 0, on the map
# above at preset fastest, G and B: measured 49.6 dB and at most 4.2 codes off
# (linear etc2, which three.js refuses: 51.4 dB, 3 codes); the curve alone at
# 8 bits costs at most 1.02 codes (near 1, where one sRGB code spans 2.3
# linear codes), 58.2 dB.
DATA_PSNR_FLOOR = 47.0
DATA_MAX_CODES = 6.0


def test_mobile_etc_data_decodes_to_its_linear_values(every_use, tmp_path, cli_run):
    """The metallic-roughness file holds sRGB-encoded data (vkFormat 148): a
    sampler's sRGB decode, here texture2ddecoder's bytes through the sRGB
    curve, returns the source's linear values; texcook's reader (the
    texcook.colour_space record) decodes it the same way."""
    from texcook.colour import srgb_to_linear
    from texcook.pipeline import load_texture

    out = tmp_path / "out"
    code, _, err = cli_run("scene", every_use, "-o", out, "--target", "mobile-etc", "--preset", PRESET)
    assert code == 0, err
    # stderr says which format three.js refuses, and what was done instead
    assert "KTX2Loader refuses linear etc2 (vkFormat 147)" in err
    report = json.loads((out / "scene.json").read_text())
    mr = next(b for b in report["bakes"] if b["name"].startswith("mr"))
    path = out / mr["output"]
    ktx = read_ktx2(path.read_bytes())
    assert ktx.vk_format == formats.get("etc2").vk_srgb == 148
    assert json.loads(ktx.text("texcook.colour_space"))["source"] == "linear"
    src = roughness_metal().astype(np.float64) / 255.0
    sampled = srgb_to_linear(decode_level("etc2", ktx.levels[0], N, N)[..., :3] / 255.0)
    err_gb = sampled[..., 1:3] - src[..., 1:3]
    db = 10 * np.log10(1.0 / np.mean(err_gb ** 2))
    assert db >= DATA_PSNR_FLOOR and np.abs(err_gb).max() * 255 <= DATA_MAX_CODES, (db, np.abs(err_gb).max() * 255)
    assert abs(mr["psnr"] - db) < 0.05, (mr["psnr"], db)  # scene.json's figure is the data's, in linear units
    ours = load_texture(path)
    assert not ours.srgb
    np.testing.assert_allclose(ours.levels[0][..., :3], sampled, atol=1e-5)
    # metalness's two levels, 0 and 1, come back exact: the curve keeps its ends
    b = sampled[..., 2][(src[..., 2] == 0) | (src[..., 2] == 1)]
    assert np.mean(np.abs(b - np.rint(b)) < 1.5 / 255) > 0.9


def test_a_mobile_etc_scene_loads_in_threejs_as_compressed_textures(every_use, tmp_path, browser):  # noqa: F811
    """In headless Chromium with three.js (skipped where either is missing, as
    tests/test_view_browser.py does): every texture of a mobile-etc scene,
    the sRGB-stored metallic-roughness included, is a compressed texture."""
    from texcook import view

    out = tmp_path / "out"
    scene.bake_scene(every_use, out, target="mobile-etc", preset=PRESET)
    _, records = view.render(view.open_site(out), query={"layout": "baked"}, browser=browser)
    assert sorted(r["vk"] for r in records) == [148, 152, 152, 153, 155]
    for r in records:
        assert r["ok"] and r["compressed"], r
