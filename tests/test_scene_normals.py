"""Normal maps baked by `texcook scene` are sampled right by a glTF reader, and
`bake --normal-map` keeps its two-plane ASTC layout unless asked for another.

A glTF reader follows the rewritten model to the baked image, decodes it
(here with decoders that are not texcook's), applies no KTXswizzle, and reads
the normal as RGB * 2 - 1. The reader of texcook's KTX2 extension rebuilds Z
from a two-channel format (docs/scene.md)."""

import json
import struct
from pathlib import Path

import numpy as np
import pytest

from conftest import CORPUS
from decoders import astcenc_decode, decode
from texcook import formats, scene
from texcook.container.ktx2 import read_ktx2
from texcook.errors import UsageError
from texcook.recipe import Recipe

N = 64


def bumps(n=N):
    """A tangent-space normal map of a smooth height field (two bumps across,
    one diagonal ridge) as RGB uint8, and its unit normals (float64)."""
    y, x = (np.mgrid[0:n, 0:n] + 0.5) / n
    # d(height)/dx and d(height)/dy of h = 0.05 sin(4 pi x) sin(4 pi y) + 0.02 sin(6 pi (x + y)):
    # tilts up to about 45 degrees
    k = 4 * np.pi
    hx = 0.05 * k * np.cos(k * x) * np.sin(k * y) + 0.02 * 6 * np.pi * np.cos(6 * np.pi * (x + y))
    hy = 0.05 * k * np.sin(k * x) * np.cos(k * y) + 0.02 * 6 * np.pi * np.cos(6 * np.pi * (x + y))
    v = np.stack([-hx, -hy, np.ones_like(hx)], axis=-1)
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    px = np.rint((v * 0.5 + 0.5) * 255).astype(np.uint8)
    return px, unit(px)


def unit(rgb):
    """glTF's reading of a normal texture: RGB * 2 - 1, normalised."""
    v = rgb[..., :3].astype(np.float64) / 255.0 * 2.0 - 1.0
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def degrees(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)))


def png(path, px):
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(str(path))
    spec = oiio.ImageSpec(px.shape[1], px.shape[0], px.shape[2], "uint8")
    spec.attribute("oiio:UnassociatedAlpha", 1)  # a two-channel X, Y image is written as it is
    out.open(str(path), spec)
    out.write_image(np.ascontiguousarray(px))
    out.close()


def quad_model(folder, normal_px):
    """A one-quad glTF whose material reads `normal_px` as its normalTexture."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    png(folder / "bumps.png", normal_px)
    pos = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
    nrm = np.array([[0, 0, 1]] * 4, np.float32)
    tan = np.array([[1, 0, 0, 1]] * 4, np.float32)
    uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)
    idx = np.array([0, 1, 2, 0, 2, 3], np.uint16)
    blob, views, accessors = b"", [], []
    for arr, kind, comp, target in ((pos, "VEC3", 5126, 34962), (nrm, "VEC3", 5126, 34962),
                                    (tan, "VEC4", 5126, 34962), (uv, "VEC2", 5126, 34962),
                                    (idx, "SCALAR", 5123, 34963)):
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": arr.nbytes, "target": target})
        acc = {"bufferView": len(views) - 1, "componentType": comp, "count": len(arr), "type": kind}
        if arr is pos:
            acc.update(min=[0, 0, 0], max=[1, 1, 0])
        accessors.append(acc)
        blob += arr.tobytes() + b"\0" * (-arr.nbytes % 4)
    (folder / "quad.bin").write_bytes(blob)
    doc = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "TANGENT": 2, "TEXCOORD_0": 3},
                                    "indices": 4, "material": 0}]}],
        "materials": [{"name": "bumpy", "normalTexture": {"index": 0}}],
        "textures": [{"source": 0, "sampler": 0}],
        "samplers": [{"minFilter": 9987, "magFilter": 9729}],
        "images": [{"uri": "bumps.png"}],
        "accessors": accessors, "bufferViews": views,
        "buffers": [{"uri": "quad.bin", "byteLength": len(blob)}],
    }
    path = folder / "quad.gltf"
    path.write_text(json.dumps(doc))
    return path


def baked_normal_image(outdir):
    """The KTX2 file a reader of the rewritten model takes for the normal
    texture, and the extension that names it."""
    outdir = Path(outdir)
    doc = json.loads((outdir / "quad.gltf").read_text())
    texture = doc["textures"][doc["materials"][0]["normalTexture"]["index"]]
    (ext, ref), = texture["extensions"].items()
    return read_ktx2((outdir / doc["images"][ref["source"]]["uri"]).read_bytes()), ext


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    px, normals = bumps()
    return quad_model(tmp_path_factory.mktemp("src"), px), px, normals


# what each target's reader samples: (format, extension, decode level 0 -> RGBA), and the
# largest mean and 99th percentile angle (degrees) and mean blue difference (8-bit codes) allowed.
# Measured, preset medium: astc-4x4 0.76 / 3.0 / 1.9, bc5 0.96 / 3.2 / 0.7, eac-rg11 1.0 / 4.6; etc1
# with Z, what mobile without ASTC wrote before eac-rg11, 4.1 / 11.5 / 4.9 (ETC1 moves a block's
# colours along grey only). X in R, G and B with Y in alpha, read as RGB, is off by tens of degrees.
READERS = {
    "mobile": ("astc-4x4", scene.EXT_ASTC, lambda data: decode("astc-4x4", data, N, N), (1.5, 5.0, 3.0)),
    "mobile-etc": ("eac-rg11", scene.EXT_KTX2, lambda data: decode("eac-rg11", data, N, N), (1.5, 5.0, 2.0)),
    "desktop": ("bc5", scene.EXT_KTX2, lambda data: decode("bc5", data, N, N), (1.5, 5.0, 2.0)),
}


def test_a_dds_reader_samples_the_source_normals(model, tmp_path):
    """MSFT_texture_dds promises no rebuilt Z: a two-channel BC5 would be read
    with blue 0, so the normals are stored as X, Y, Z in BC1."""
    from texcook.container.dds import read_dds

    path, px, normals = model
    report = scene.bake_scene(path, tmp_path / "out", target="desktop", container="dds", preset="medium")
    doc = json.loads((tmp_path / "out" / "quad.gltf").read_text())
    texture = doc["textures"][doc["materials"][0]["normalTexture"]["index"]]
    (ext, ref), = texture["extensions"].items()
    assert ext == scene.EXT_DDS
    dds_path = tmp_path / "out" / doc["images"][ref["source"]]["uri"]
    fmt, width, height, levels = read_dds(dds_path.read_bytes(), dds_path)[:4]
    assert fmt == "bc1" and (width, height) == (N, N)
    rgba = decode("bc1", levels[0], N, N)
    angle = degrees(unit(rgba), normals)
    # BC1 holds four colours on a line per block: coarser than BC5 (measured 4.2 / 14.1 degrees), but
    # right in every channel
    assert angle.mean() < 5.0 and np.percentile(angle, 99) < 16.0, (angle.mean(), np.percentile(angle, 99))
    assert np.abs(rgba[..., 2].astype(int) - px[..., 2]).mean() < 6.0
    assert any("MSFT_texture_dds" in note for b in report["bakes"] for note in b.get("notes", []))


@pytest.mark.parametrize("target", sorted(READERS))
def test_a_gltf_reader_samples_the_source_normals(model, tmp_path, target):
    path, px, normals = model
    fmt, ext, decode, (mean, p99, blue) = READERS[target]
    available = ["etc2", "eac-rg11", "rgba8"] if target == "mobile-etc" else None
    scene.bake_scene(path, tmp_path / "out", target=target.split("-")[0], preset="medium", available=available)
    ktx, used = baked_normal_image(tmp_path / "out")
    assert (ktx.vk_format, used) == (formats.get(fmt).vk_unorm, ext)
    rgba = decode(ktx.levels[0])  # no KTXswizzle applied: a glTF reader reads RGB
    if formats.get(fmt).channels == 2:
        # two channels: the extension's reader rebuilds Z = sqrt(1 - X^2 - Y^2)
        xy = rgba[..., :2].astype(np.float64) / 255.0 * 2.0 - 1.0
        z = np.sqrt(np.clip(1.0 - np.sum(xy * xy, axis=-1), 0.0, 1.0))
        rgba = rgba.copy()
        rgba[..., 2] = np.rint((z * 0.5 + 0.5) * 255.0).astype(np.uint8)
    angle = degrees(unit(rgba), normals)
    assert angle.mean() < mean and np.percentile(angle, 99) < p99, (angle.mean(), np.percentile(angle, 99))
    # blue is the source's Z, not X or 0
    assert np.abs(rgba[..., 2].astype(int) - px[..., 2]).mean() < blue
    assert ktx.text("KTXswizzle") is None  # nothing a glTF reader would have to apply


@pytest.mark.parametrize("extra", [(), ("--normal-metric", "angular")])
def test_bake_normal_map_keeps_the_two_plane_astc_layout(cli_run, tmp_path, extra):
    """ASTC's default normal layout is still the one from before --normal-layout
    existed: X in RGB, Y in alpha (the same bytes as asking for xy), read as
    such by an independent decoder. Checked by layout, not by a pinned hash, so
    that the encoder's own improvements do not move it."""
    src = CORPUS / "normal" / "ldr-xy-00.png"
    levels = {}
    for name, layout in (("default", ()), ("xy", ("--normal-layout", "xy"))):
        out = tmp_path / f"{name}.ktx2"
        code, _, err = cli_run("bake", src, "--normal-map", "--format", "astc-4x4", "--preset", "fastest",
                               *layout, *extra, "-o", out)
        assert code == 0, err
        ktx = read_ktx2(out.read_bytes())
        assert ktx.text("KTXswizzle") == "ra01" and ktx.text("texcook.content") == "normal"
        levels[name] = ktx.levels
    assert levels["default"] == levels["xy"]
    import OpenImageIO as oiio

    px = oiio.ImageBuf(str(src)).get_pixels(oiio.UINT8)
    h, w = px.shape[:2]
    got = decode("astc-4x4", levels["default"][0], w, h).astype(int)
    assert np.array_equal(got[..., 0], got[..., 1]) and np.array_equal(got[..., 0], got[..., 2])
    assert np.abs(got[..., 0] - px[..., 0]).mean() < 2.0  # X
    assert np.abs(got[..., 3] - px[..., 1]).mean() < 2.0  # Y


def test_bake_normal_layout_xyz_stores_x_y_z(cli_run, tmp_path):
    px, normals = bumps()
    png(tmp_path / "n.png", px)
    out = tmp_path / "n.ktx2"
    code, _, err = cli_run("bake", tmp_path / "n.png", "--normal-map", "--normal-layout", "xyz",
                           "--format", "astc-4x4", "--preset", "fastest", "-o", out)
    assert code == 0, err
    ktx = read_ktx2(out.read_bytes())
    assert ktx.text("KTXswizzle") is None and ktx.text("texcook.content") == "normal"
    rgba = astcenc_decode(ktx.levels[0], 4, 4, N, N)
    assert degrees(unit(rgba), normals).mean() < 1.5
    assert np.abs(rgba[..., 2].astype(int) - px[..., 2]).mean() < 3.0
    # the smallest level is still a unit vector: mips are renormalised with Z kept
    last = astcenc_decode(ktx.levels[-1], 4, 4, 1, 1)[0, 0, :3] / 255.0 * 2.0 - 1.0
    assert abs(np.linalg.norm(last) - 1.0) < 0.03


def test_the_recipe_says_which_layouts_a_format_holds(tmp_path):
    r = Recipe.of(format="astc-6x6", normal_map=True, normal_layout="xyz")
    assert r.to_dict()["output"] == {"normal_layout": "xyz"}
    assert Recipe.from_dict(r.to_dict()) == r
    assert "output" not in Recipe.of(format="astc-6x6", normal_map=True).to_dict()  # today's recipes unchanged
    Recipe.of(format="etc1", normal_map=True, normal_layout="xyz")
    Recipe.of(format="bc5", normal_map=True, normal_layout="xy")
    for bad, words in [(dict(format="bc5", normal_layout="xyz"), "bc5 stores a normal map as xy only"),
                       (dict(format="etc1", normal_layout="xy"), "etc1 stores a normal map as xyz only"),
                       (dict(format="astc-4x4", normal_layout="xyz", normal_metric="angular"), "needs --normal-layout xy"),
                       (dict(format="astc-4x4", normal_layout="zyx"), "must be one of xy, xyz")]:
        with pytest.raises(UsageError, match=words):
            Recipe.of(normal_map=True, **bad)
    with pytest.raises(UsageError, match="needs --normal-map"):
        Recipe.of(format="astc-4x4", normal_layout="xyz")
    with pytest.raises(UsageError, match="contradicts"):
        Recipe.from_dict({"source": {"normal_map": True}, "output": {"normal_layout": "xyz"},
                          "codec": {"format": "astc-4x4", "options": {"normal_layout": "xy"}}})


def test_uncompressed_output_follows_the_layout(cli_run, tmp_path):
    """Without --format, xy keeps X, Y (rg8) and xyz X, Y, Z (rgba8), also from a two-channel source."""
    px, _ = bumps(16)
    png(tmp_path / "n.png", px)
    png(tmp_path / "xy.png", px[..., :2])
    for src, layout, want in [("n.png", "xy", "rg8"), ("xy.png", "xyz", "rgba8")]:
        out = tmp_path / f"{layout}.ktx2"
        code, stdout, err = cli_run("bake", tmp_path / src, "--normal-map", "--normal-layout", layout, "-o", out,
                                    "--json")
        assert code == 0, err
        assert json.loads(stdout)["format"] == want
    rgba = np.frombuffer(read_ktx2((tmp_path / "xyz.ktx2").read_bytes()).levels[0], np.uint8).reshape(16, 16, 4)
    assert np.abs(rgba[..., 2].astype(int) - px[..., 2]).max() <= 2  # Z rebuilt from X and Y
    assert struct.unpack("<I", (tmp_path / "xy.ktx2").read_bytes()[12:16])[0] == 16  # VK_FORMAT_R8G8_UNORM
