"""In a real browser (headless Chromium, WebGL 2 on SwiftShader) with
three.js: every format texcook writes to KTX2 that three.js's KTX2Loader
takes reads back, every texel of every level, as texcook decodes it; every
format it does not take is refused; a baked scene renders as its source."""

import base64
import io
import json

import numpy as np
import pytest
from click.testing import CliRunner

from texcook import formats, view
from texcook.cli import cli
from texcook.container.ktx2 import write_ktx2
from texcook.pipeline import bake_file, load_texture
from texcook.recipe import Recipe
from texcook.view import three
from texcook.view.server import Server
from texcook.view.site import Site

from conftest import CORPUS, encoded_image

SIZE = 64  # a full chain 64 .. 1: levels narrower than a block, and ASTC 6x6's partial blocks
ZSTD = 19
# dB over the drawn pixels, the baked render against the source render: 41.4
# measured on this scene (desktop: bc1, bc5, bc1; mobile 41.9), 640x400;
# universal 34.1 (ETC1S at its default quality, a JPEG-like size, normal map as
# its source)
SCENE_PSNR_FLOOR = {"desktop": 35.0, "universal": 32.0}
BACKGROUND = np.array([48.0, 51.0, 58.0])  # the page's clear colour, #30333a

# The GPU's sRGB-to-linear conversion is itself rounded: re-encoded, exact
# texels of rgba8, bc1..bc7 and etc come back within 0.025 of their code
# (SwiftShader), so a one-code difference can read as 1.01 codes.
SRGB_SLACK = 1.05 / 255

VARIANTS = three.written_variants()
TAKEN = [(f, s) for f, s, taken in VARIANTS if taken]
REFUSED = [(f, s) for f, s, taken in VARIANTS if not taken]


def _id(case):
    fmt, srgb = case
    return f"{fmt.name}-{'srgb' if srgb else 'linear'}"


@pytest.fixture(scope="module")
def browser():
    if view.find_chromium() is None:
        pytest.skip(f"Chromium is not installed ({view.browser.INSTALL})")
    if three.three_version() is None:
        import os

        if os.environ.get("CI"):
            pytest.fail(f"three.js is not installed: run `{three.INSTALL}`")
        pytest.skip(f"three.js is not installed ({three.INSTALL})")
    with view.Browser(640, 400) as b:
        yield b


def _corpus_crop():
    from PIL import Image

    px = np.asarray(Image.open(CORPUS / "rgba" / "ldr-rgba-00.png").convert("RGBA"))
    return np.ascontiguousarray(px[40:40 + SIZE, 70:70 + SIZE])


@pytest.fixture(scope="module")
def readback(browser, tmp_path_factory):
    """name -> (the file, what the page read back), all in one page."""
    folder = tmp_path_factory.mktemp("conformance")
    src = folder / "src.png"
    src.write_bytes(encoded_image(_corpus_crop()))
    files = {}
    for fmt, srgb in TAKEN:
        out = folder / f"{_id((fmt, srgb))}.ktx2"
        bake_file(src, out, Recipe.of(format=fmt.name, preset="fastest", zstd=ZSTD,
                                      colour_space="srgb" if srgb else "linear"))
        files[_id((fmt, srgb))] = out
    for fmt, srgb in REFUSED:
        # refused on its vkFormat alone: one level of zero blocks is enough
        out = folder / f"{_id((fmt, srgb))}.ktx2"
        out.write_bytes(write_ktx2(fmt.vk_format(srgb), 8, 8, [bytes(fmt.level_size(8, 8))]))
        files[_id((fmt, srgb))] = out
    site = Site("probe", folder, {})
    with Server(site, three.THREE_DIR).start() as server:
        browser.goto(server.url)
        browser.wait_for(f"location.href === {json.dumps(server.url)} && window.texcook "
                         "&& texcook.state === 'ready'")
        names = json.dumps(sorted(files))
        results = browser.evaluate(
            f"(async () => {{ const out = {{}}; for (const n of {names}) "
            f"out[n] = await texcook.readLevels('/files/' + n + '.ktx2'); return out; }})()")
    return files, results


def _levels(result):
    return [np.frombuffer(base64.b64decode(lv["data"]), "<f4").reshape(lv["height"], lv["width"], 4)
            for lv in result["levels"]]


def _srgb_encode(linear):
    """The sRGB curve (IEC 61966-2-1), written here rather than taken from texcook."""
    x = np.clip(linear.astype(np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def mismatch(gpu_levels, expected_levels, fmt, srgb):
    """The first disagreement beyond 1/255 between what the GPU fetched and
    texcook's decode, or None. Channels the format does not store must read as
    GL defines them: 0 for green and blue, 1 for alpha."""
    if len(gpu_levels) != len(expected_levels):
        return f"{len(gpu_levels)} levels read, {len(expected_levels)} decoded"
    for i, (gpu, want) in enumerate(zip(gpu_levels, expected_levels)):
        if gpu.shape[:2] != want.shape[:2]:
            return f"level {i}: {gpu.shape[:2]} read, {want.shape[:2]} decoded"
        stored = fmt.channels
        got = gpu[..., :stored].astype(np.float64)
        if srgb:
            got[..., :3] = _srgb_encode(got[..., :3])  # the GPU returns linear light; alpha is never sRGB
        ref = want[..., :stored].astype(np.float64)
        ref = ref / 255.0 if want.dtype == np.uint8 else ref
        err = np.abs(got - ref)
        if err.max() > (SRGB_SLACK if srgb else 1 / 255 + 1e-5):
            y, x, c = np.unravel_index(int(err.argmax()), err.shape)
            return (f"level {i} texel ({x}, {y}) channel {c}: GPU {got[y, x, c] * 255:.2f}/255, "
                    f"texcook {ref[y, x, c] * 255:.2f}/255")
        defaults = np.array([0.0, 0.0, 0.0, 1.0])
        for c in range(stored, 4):
            if not np.all(gpu[..., c] == defaults[c]) and not (c < 3 and stored >= 3):
                return f"level {i}: channel {c}, which {fmt.name} does not store, reads {gpu[..., c].max()}"
    return None


@pytest.mark.parametrize("case", TAKEN, ids=[_id(c) for c in TAKEN])
def test_three_reads_every_texel_of_every_level_as_texcook_decodes(readback, case):
    files, results = readback
    fmt, srgb = case
    result = results[_id(case)]
    assert result["loaded"], result.get("why")
    assert result["glError"] == 0
    assert result["compressed"] == fmt.is_block_compressed
    decoded = load_texture(files[_id(case)])
    assert decoded.srgb == srgb
    assert len(decoded.levels) == formats.max_levels(SIZE, SIZE)
    # where three.js drops the sRGB curve, the shader reads the stored values as they are
    curve = srgb and fmt.vk_format(srgb) not in three.THREE_IGNORES_SRGB
    problem = mismatch(_levels(result), decoded.levels, fmt, curve)
    assert problem is None, problem


@pytest.mark.parametrize("case", REFUSED, ids=[_id(c) for c in REFUSED])
def test_three_refuses_the_formats_it_does_not_list(readback, case):
    result = readback[1][_id(case)]
    assert not result["loaded"] and "Unsupported vkFormat" in result["why"]


def test_the_comparison_sees_one_step_off(readback):
    """A decode one code off in one texel of one level is caught (so that a
    broken decoder or writer cannot pass)."""
    files, results = readback
    fmt, srgb = TAKEN[0]
    decoded = load_texture(files[_id(TAKEN[0])]).levels
    assert mismatch(_levels(results[_id(TAKEN[0])]), decoded, fmt, srgb) is None
    for level in (0, len(decoded) - 1):
        off = [lv.copy() for lv in decoded]
        off[level][0, 0, 0] = off[level][0, 0, 0] + 2 if off[level][0, 0, 0] < 128 else off[level][0, 0, 0] - 2
        assert mismatch(_levels(results[_id(TAKEN[0])]), off, fmt, srgb).startswith(f"level {level} ")


# ----------------------------------------------------------------------------- scenes


def _png(data):
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB")).astype(np.float64)


def _psnr(a, b, drawn_only=False):
    if drawn_only:
        mask = np.any(np.abs(a - BACKGROUND) > 2, axis=-1) | np.any(np.abs(b - BACKGROUND) > 2, axis=-1)
        assert mask.mean() > 0.1  # the models are in view
        a, b = a[mask], b[mask]
    mse = np.mean((a - b) ** 2)
    return float("inf") if mse == 0 else 10 * np.log10(255.0 ** 2 / mse)


@pytest.fixture(scope="module")
def scene_out(tmp_path_factory):
    """A model of three quads (base colour, normal map, occlusion-roughness-
    metalness) baked by `texcook scene` for desktop, mobile and universal."""
    from PIL import Image
    from test_scene import build

    from texcook.scene import bake_scene

    folder = tmp_path_factory.mktemp("scene")
    model = folder / "src" / "model.gltf"
    model.parent.mkdir()

    def crop(rel):
        return np.ascontiguousarray(np.asarray(Image.open(CORPUS / rel).convert("RGB"))[:128, :128])

    images = {"colour": crop("rgb/ldr-rgb-01.png"), "normal": crop("normal/ldr-xy-00.png"),
              "orm": crop("rgb/ldr-rgb-03.png")}
    build(model, images, [("colour", 0), ("normal", 0), ("orm", 0)],
          [{"name": "painted", "slots": {"baseColorTexture": 0}},
           {"name": "bumpy", "slots": {"baseColorTexture": 0, "normalTexture": 1}},
           {"name": "rough", "slots": {"baseColorTexture": 0, "metallicRoughnessTexture": 2,
                                       "occlusionTexture": 2}}],
          samplers=[{"minFilter": 9987, "magFilter": 9729}])
    doc = json.loads(model.read_text())  # the quads side by side, not on top of each other
    for i, node in enumerate(doc["nodes"]):
        node["translation"] = [1.15 * i, 0.0, 0.0]
    model.write_text(json.dumps(doc))
    outs = {}
    for target in ("desktop", "mobile", "universal"):
        outs[target] = folder / target
        bake_scene(str(model), str(outs[target]), target, "ktx2", "fastest", 2)
    return outs


def _canvas(png, size):
    """The rendered part of a screenshot: left of the panel, below the labels."""
    return png[40:, : size[0] - 380]


@pytest.mark.parametrize("target", ["desktop", "universal"])
def test_a_baked_scene_renders_as_its_source_with_compressed_textures(browser, scene_out, target):
    """universal: KHR_texture_basisu, transcoded by three.js's Basis transcoder."""
    site = view.open_site(scene_out[target])
    baked, records = view.render(site, query={"layout": "baked"}, browser=browser)
    original, _ = view.render(site, query={"layout": "original"}, browser=browser)
    assert sorted(r["image"] for r in records) == sorted(t["image"] for t in site.manifest["textures"])
    for r in records:
        assert r["ok"] and r["compressed"], r  # KTX2 compressed textures, not the fallback images
    a, b = _png(baked), _png(original)
    assert a.std() > 5  # something was drawn
    psnr = _psnr(_canvas(a, (640, 400)), _canvas(b, (640, 400)), drawn_only=True)
    assert psnr >= SCENE_PSNR_FLOOR[target], psnr


def test_formats_three_refuses_show_their_fallback_labelled(browser, scene_out):
    site = view.open_site(scene_out["mobile"])
    _, records = view.render(site, query={"layout": "baked"}, browser=browser)
    table = three.vk_table()
    assert records
    for r in records:
        assert r["ok"] == table[r["vk"]]["three"], r
        if not r["ok"]:
            assert "KTX2Loader refuses" in r["why"] and r["shown"].startswith("fallback: ")


def test_screenshot_command_writes_the_page(scene_out, browser, tmp_path):
    out = tmp_path / "shot.png"
    result = CliRunner().invoke(cli, ["view", str(scene_out["desktop"]), "--screenshot", str(out),
                                      "--size", "800x450"])
    assert result.exit_code == 0, result.output
    assert result.output.startswith(f"{out}: 3 texture(s) shown as KTX2")
    png = _png(out.read_bytes())
    assert png.shape == (450, 800, 3)
    left, right = png[40:, :210], png[40:, 210:420]  # the two halves of the canvas: baked, source
    assert left.std() > 5 and right.std() > 5
    assert _psnr(left, right) >= 30  # 44 dB measured: the same picture twice


def test_a_texture_on_planes_with_its_difference_view(browser, scene_out):
    site = view.open_site(scene_out["desktop"] / "colour.ktx2")  # its source found through scene.json
    assert site.manifest["source"]["name"] == "colour.png"
    shown, records = view.render(site, query={"filter": "anisotropic"}, browser=browser)
    diff, _ = view.render(site, query={"filter": "anisotropic", "diff": "1"}, browser=browser)
    assert records == [{"name": "colour.ktx2", "vk": 132, "ok": True, "why": None, "compressed": True}]
    shown, diff = _canvas(_png(shown), (640, 400)), _canvas(_png(diff), (640, 400))
    drawn = np.any(np.abs(shown - BACKGROUND) > 2, axis=-1)
    assert drawn.mean() > 0.2  # both planes are in view
    # BC1 against its source, 8 times amplified: darker than the picture, not black
    assert 2 < diff[drawn].mean() < shown[drawn].mean() / 2


def test_a_texture_three_refuses_shows_its_source_labelled(browser, scene_out, tmp_path):
    from texcook import pipeline
    from texcook.recipe import Recipe

    # the scene's mobile textures are all ones three.js takes: an astc-8x8 bake of its source beside it
    src = scene_out["mobile"] / "orm.png"
    out = tmp_path / "orm.ktx2"
    pipeline.bake_file(str(src), str(out), Recipe.of(format="astc-8x8", preset="fastest"))
    (tmp_path / "orm.png").write_bytes(src.read_bytes())
    site = view.open_site(out, source=tmp_path / "orm.png")
    png, records = view.render(site, browser=browser)
    assert records[0]["ok"] is False and "KTX2Loader refuses vkFormat 172 (astc-8x8 sRGB)" in records[0]["why"]
    assert _canvas(_png(png), (640, 400)).std() > 5  # the source image is drawn instead


def test_the_bundled_example_scene_side_by_side(tmp_path, cli_run, browser):
    """The user's first run (examples/scene/README.md): the example model baked
    by `texcook scene` and shown by `texcook view --screenshot`, baked and
    source halves alike; the example itself validates."""
    from conftest import ROOT, node_tool

    example = ROOT / "examples" / "scene" / "model.gltf"
    report = node_tool("validate.mjs", "gltf-validator")([example])[0]
    assert report["issues"]["numErrors"] == 0
    code, _, err = cli_run("scene", example, "-o", tmp_path / "baked", "--preset", "fastest", "-q")
    assert code == 0, err
    shot = tmp_path / "shot.png"
    code, _, err = cli_run("view", tmp_path / "baked", "--screenshot", shot, "--size", "1280x720")
    assert code == 0, err
    canvas = _canvas(_png(shot.read_bytes()), (1280, 720))
    half = canvas.shape[1] // 2
    baked, source = canvas[:, :half], canvas[:, half:2 * half]
    drawn = np.any(np.abs(baked - BACKGROUND) > 2, axis=-1)
    assert 0.05 < drawn.mean() < 0.9  # the whole model in view, not filling the half
    assert _psnr(baked, source, drawn_only=True) >= SCENE_PSNR_FLOOR["desktop"]
