"""texcook.scene: glTF materials and samplers -> recipes, bakes, scene.json and
a rewritten model that the Khronos validator accepts."""

import json
import os
import tempfile
from pathlib import Path

import numpy as np
import pygltflib as gl
import pytest
from conftest import encoded_image, node_tool

from texcook import colour, scene
from texcook.errors import InputError, OutputError, UsageError
from texcook.mips import alpha_coverage
from texcook.pipeline import load_texture

PRESET = "fastest"


# ----------------------------------------------------------------------------- building scenes



def build(path, images, textures, materials, samplers=(), storage="external", jpeg=None):
    """A one-quad-per-material glTF (.gltf or .glb by `path`'s extension).

    images: name -> uint8 pixels; textures: (image name, sampler index or None);
    materials: dicts with name, slots {slot: texture index}, and optionally
    alphaMode, alphaCutoff, baseColorFactor, extensions. storage: "external"
    (files beside the model), "data" (data URIs) or "bufferView". jpeg: a
    JPEG quality, to store the images as JPEGs (RGB) as most models do."""
    path = Path(path)
    glb = path.suffix == ".glb"
    pos = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
    nrm = np.array([[0, 0, 1]] * 4, np.float32)
    tan = np.array([[1, 0, 0, 1]] * 4, np.float32)
    uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)
    idx = np.array([0, 1, 2, 0, 2, 3], np.uint16)
    blob = bytearray()
    views = []

    def add(data, target=None):
        blob.extend(b"\0" * (-len(blob) % 4))
        views.append(gl.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data), target=target))
        blob.extend(data)
        return len(views) - 1

    accessors = [
        gl.Accessor(bufferView=add(pos.tobytes(), 34962), componentType=5126, count=4, type="VEC3",
                    min=[0, 0, 0], max=[1, 1, 0]),
        gl.Accessor(bufferView=add(nrm.tobytes(), 34962), componentType=5126, count=4, type="VEC3"),
        gl.Accessor(bufferView=add(tan.tobytes(), 34962), componentType=5126, count=4, type="VEC4"),
        gl.Accessor(bufferView=add(uv.tobytes(), 34962), componentType=5126, count=4, type="VEC2"),
        gl.Accessor(bufferView=add(idx.tobytes(), 34963), componentType=5123, count=6, type="SCALAR"),
    ]
    gl_images = []
    for name, px in images.items():
        ext, mime = (".png", "image/png") if jpeg is None else (".jpg", "image/jpeg")
        data = encoded_image(px, ext, jpeg)
        if storage == "external":
            (path.parent / f"{name}{ext}").write_bytes(data)
            gl_images.append(gl.Image(uri=f"{name}{ext}"))
        elif storage == "data":
            import base64

            gl_images.append(gl.Image(uri=f"data:{mime};base64," + base64.b64encode(data).decode()))
        else:
            gl_images.append(gl.Image(bufferView=add(data), mimeType=mime, name=name))
    names = list(images)
    gl_textures = [gl.Texture(source=names.index(img), sampler=s) for img, s in textures]
    gl_materials = []
    for m in materials:
        slots = m.get("slots", {})
        pbr = gl.PbrMetallicRoughness(baseColorFactor=m.get("baseColorFactor", [1.0, 1.0, 1.0, 1.0]))
        mat = gl.Material(name=m["name"], alphaMode=m.get("alphaMode", "OPAQUE"), alphaCutoff=m.get("alphaCutoff"),
                          pbrMetallicRoughness=pbr, extensions=m.get("extensions", {}))
        for slot, t in slots.items():
            if slot == "baseColorTexture":
                pbr.baseColorTexture = gl.TextureInfo(index=t)
            elif slot == "metallicRoughnessTexture":
                pbr.metallicRoughnessTexture = gl.TextureInfo(index=t)
            elif slot == "normalTexture":
                mat.normalTexture = gl.NormalMaterialTexture(index=t)
            elif slot == "occlusionTexture":
                mat.occlusionTexture = gl.OcclusionTextureInfo(index=t)
            elif slot == "emissiveTexture":
                mat.emissiveTexture = gl.TextureInfo(index=t)
                mat.emissiveFactor = [1.0, 1.0, 1.0]
        gl_materials.append(mat)
    prims = [gl.Mesh(primitives=[gl.Primitive(attributes=gl.Attributes(POSITION=0, NORMAL=1, TANGENT=2,
                                                                        TEXCOORD_0=3), indices=4, material=i)])
             for i in range(len(materials))]
    model = gl.GLTF2(
        asset=gl.Asset(version="2.0"), scene=0, scenes=[gl.Scene(nodes=list(range(len(prims))))],
        nodes=[gl.Node(mesh=i) for i in range(len(prims))], meshes=prims, accessors=accessors,
        bufferViews=views, materials=gl_materials, textures=gl_textures, images=gl_images,
        samplers=[gl.Sampler(**s) for s in samplers],
        buffers=[gl.Buffer(byteLength=len(blob), uri=None if glb else path.stem + ".bin")],
    )
    if any(m.get("extensions") for m in materials):
        model.extensionsUsed = sorted({e for m in materials for e in m.get("extensions", {})})
    text = model.gltf_to_json()
    if glb:
        path.write_bytes(scene._glb_bytes(text, blob))
    else:
        (path.parent / (path.stem + ".bin")).write_bytes(bytes(blob))
        path.write_text(text)
    return path


def colour_rgba(rng, n=16, alpha=None):
    px = rng.integers(0, 256, (n, n, 4), dtype=np.uint8)
    px[..., 3] = 255 if alpha is None else alpha
    return px


def rgb(rng, n=16):
    return rng.integers(0, 256, (n, n, 3), dtype=np.uint8)


def normal_map(rng, n=16):
    v = rng.normal(size=(n, n, 3))
    v[..., 2] = np.abs(v[..., 2]) + 1.0
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    return np.rint((v * 0.5 + 0.5) * 255).astype(np.uint8)


def plan_of(path, target="desktop", container="ktx2", available=None):
    """(bakes, not baked) for a model, without baking."""
    model = scene.load_model(path)
    uses = scene.collect_uses(model.gltf)
    images = {model.gltf.textures[u.texture].source for u in uses}
    with tempfile.TemporaryDirectory() as work:
        sources = scene.extract_images(model, work, images)
        return scene.plan(model, target, container, PRESET, sources, available)


def bake_for(bakes, material, slot):
    found = [b for b in bakes if any(u.material_name == material and u.slot == slot for u in b.uses)]
    assert len(found) == 1, (material, slot)
    return found[0]


# ----------------------------------------------------------------------------- outside checks


@pytest.fixture(scope="module")
def validate():
    run = node_tool("validate.mjs", "gltf-validator")

    def check(path):
        report = run([path])[0]
        errors = [m for m in report["issues"]["messages"] if m["severity"] == 0]
        assert report["issues"]["numErrors"] == 0, errors
        return report

    return check


def check_outputs(outdir, report, validate, ktx_parse):
    """The rewritten model validates, every baked texture (a file beside a
    .gltf, a bufferView inside a .glb) is readable by an independent reader,
    and scene.json matches them."""
    outdir = Path(outdir)
    model = outdir / report["output_model"]
    validate(model)
    assert json.loads((outdir / "scene.json").read_text()) == json.loads(json.dumps(scene._finite(report)))
    assert not (outdir / scene.INCOMPLETE).exists()
    assert not [n for n in os.listdir(outdir) if n.startswith(".")]  # no staging folder left
    doc = model_json(model)
    data = {}
    for b in report["bakes"]:
        image = doc["images"][b["image"]]
        if model.suffix == ".glb":
            assert "output" not in b and "uri" not in image
            data[b["name"]] = glb_view(model, image["bufferView"])
        else:
            assert image["uri"] == b["output"]
            data[b["name"]] = (outdir / b["output"]).read_bytes()
        assert len(data[b["name"]]) == b["bytes"]
    by_name = {b["name"]: b for b in report["bakes"]}
    assert len(by_name) == len(report["bakes"])
    for e in report["textures"]:  # each texture names its bake, whose image its texture reads
        b = report["bakes"][[x["id"] for x in report["bakes"]].index(e["bake"])]
        assert e["texture"] in b["textures"]
        assert b["image"] in [ext["source"] for ext in doc["textures"][e["output_texture"]]["extensions"].values()]
    with tempfile.TemporaryDirectory() as d:
        for name, payload in data.items():
            Path(d, name).write_bytes(payload)
        ktx = [Path(d, n) for n in data if n.endswith(".ktx2")]
        if ktx:
            for rec in ktx_parse(ktx):
                assert "error" not in rec, rec
                entry = by_name[Path(rec["file"]).name]
                assert rec["levelCount"] == entry["levels"]
                assert (rec["pixelWidth"], rec["pixelHeight"]) == (entry["width"], entry["height"])
                assert rec["transferFunction"] == (2 if entry["colour_space"] == "srgb" else 1)
        import OpenImageIO as oiio

        for name in data:
            if name.endswith(".dds"):
                buf = oiio.ImageBuf(str(Path(d, name)))
                assert not buf.has_error, buf.geterror()
                assert buf.spec().width == by_name[name]["width"]
                assert buf.nmiplevels == by_name[name]["levels"]
    return model


def glb_view(path, view):
    glb = gl.GLTF2.load_from_bytes(Path(path).read_bytes())
    v = glb.bufferViews[view]
    return glb.binary_blob()[v.byteOffset or 0: (v.byteOffset or 0) + v.byteLength]


def model_json(path):
    """The JSON as written (a GLB's JSON chunk read directly, not through pygltflib)."""
    path = Path(path)
    if path.suffix == ".glb":
        data = path.read_bytes()
        (size,) = np.frombuffer(data[12:16], "<u4")
        return json.loads(data[20:20 + int(size)])
    return json.loads(path.read_text())


# ----------------------------------------------------------------------------- recipes


@pytest.fixture
def every_slot(tmp_path, rng):
    soft = rng.random((16, 16)) ** 2
    images = {
        "opaque": colour_rgba(rng, alpha=rng.integers(0, 256, (16, 16))),  # alpha OPAQUE must drop
        "cutout": colour_rgba(rng, alpha=np.rint(soft * 255).astype(np.uint8)),
        "binary": colour_rgba(rng, alpha=np.where(soft > 0.3, 255, 0).astype(np.uint8)),
        "glass": colour_rgba(rng, alpha=rng.integers(0, 256, (16, 16))),
        "emissive": rgb(rng),
        "occlusion": rgb(rng),
        "mr": rgb(rng),
        "normal": normal_map(rng),
    }
    textures = [(name, None) for name in images]
    t = {name: i for i, name in enumerate(images)}
    materials = [
        {"name": "opaque", "slots": {"baseColorTexture": t["opaque"], "emissiveTexture": t["emissive"],
                                     "occlusionTexture": t["occlusion"], "metallicRoughnessTexture": t["mr"],
                                     "normalTexture": t["normal"]}},
        {"name": "cutout", "alphaMode": "MASK", "alphaCutoff": 0.3, "slots": {"baseColorTexture": t["cutout"]}},
        {"name": "binary", "alphaMode": "MASK", "slots": {"baseColorTexture": t["binary"]}},
        {"name": "glass", "alphaMode": "BLEND", "slots": {"baseColorTexture": t["glass"]}},
    ]
    return build(tmp_path / "every.gltf", images, textures, materials)


def test_every_slot_and_alpha_mode_gets_its_recipe_on_desktop(every_slot):
    bakes, skipped = plan_of(every_slot)
    assert not skipped and len(bakes) == 8

    def r(material, slot):
        return bake_for(bakes, material, slot).recipe

    base = r("opaque", "baseColorTexture")
    assert (base.codec.format, base.output.colour_space) == ("bc1", "srgb")
    assert base.source.alpha_cutoff is None and not base.mips.premultiply
    emissive = r("opaque", "emissiveTexture")
    assert (emissive.codec.format, emissive.output.colour_space) == ("bc1", "srgb")
    occ = r("opaque", "occlusionTexture")
    assert (occ.codec.format, occ.output.colour_space) == ("bc4", "linear")
    mr = r("opaque", "metallicRoughnessTexture")
    assert (mr.codec.format, mr.output.colour_space) == ("bc1", "linear")
    assert dict(mr.codec.options)["weights"] == (0.0, 1.0, 1.0)  # R is read by no use
    nrm = r("opaque", "normalTexture")
    assert (nrm.codec.format, nrm.output.colour_space, nrm.source.normal_map) == ("bc5", "linear", True)
    assert any("rebuilds Z" in n for n in bake_for(bakes, "opaque", "normalTexture").notes)
    cut = r("cutout", "baseColorTexture")
    assert (cut.codec.format, cut.source.alpha_cutoff, cut.mips.premultiply) == ("bc3", 0.3, False)
    binary = r("binary", "baseColorTexture")
    assert (binary.codec.format, binary.source.alpha_cutoff) == ("bc1a", 0.5)  # glTF's default cutoff
    glass = r("glass", "baseColorTexture")
    assert (glass.codec.format, glass.mips.premultiply, glass.source.alpha_cutoff) == ("bc7", True, None)
    for b in bakes:  # no sampler: mips, repeat
        assert b.recipe.mips.enabled and b.recipe.mips.wrap == ("repeat", "repeat")
        assert b.recipe.codec.preset == PRESET


def test_steps_say_what_runs_and_why_not(every_slot):
    bakes, _ = plan_of(every_slot)
    occ = bake_for(bakes, "opaque", "occlusionTexture").steps
    assert occ["skipped"]["srgb"] == "occlusion is linear data"
    assert set(occ["ran"]) == {"mips"} and set(occ["skipped"]) == set(scene.STEPS) - {"mips"}
    base = bake_for(bakes, "opaque", "baseColorTexture").steps
    assert base["skipped"]["coverage"] == "alphaMode OPAQUE" and base["skipped"]["alpha"] == "alphaMode OPAQUE"
    assert set(base["ran"]) == {"srgb", "mips"}
    cut = bake_for(bakes, "cutout", "baseColorTexture").steps
    assert cut["ran"]["coverage"] == "alphaMode MASK at cutoff 0.3 (cutout)"
    assert set(cut["ran"]) == {"srgb", "alpha", "mips", "coverage"}
    glass = bake_for(bakes, "glass", "baseColorTexture").steps
    assert set(glass["ran"]) == {"srgb", "alpha", "mips", "premultiply"}
    nrm = bake_for(bakes, "opaque", "normalTexture").steps
    assert set(nrm["ran"]) == {"mips", "renormalise"}
    for b in bakes:  # every step is accounted for, once
        assert set(b.steps["ran"]) | set(b.steps["skipped"]) == set(scene.STEPS)
        assert not set(b.steps["ran"]) & set(b.steps["skipped"])


def test_mobile_without_astc_takes_etc2_and_eac(every_slot):
    """Was: ETC1 for opaque uses, data and normals, rgba8 for every alpha use.
    A two-level cut-out is etc2a8: three.js refuses punch-through etc2a1."""
    bakes, _ = plan_of(every_slot, target="mobile", available=["etc2", "rgba8", "bc1"])
    fmt = {(b.uses[0].material_name, b.uses[0].slot): b.recipe.codec.format for b in bakes}
    assert fmt == {("opaque", "baseColorTexture"): "etc2", ("opaque", "emissiveTexture"): "etc2",
                   ("opaque", "normalTexture"): "eac-rg11", ("opaque", "occlusionTexture"): "eac-r11",
                   ("opaque", "metallicRoughnessTexture"): "etc2", ("cutout", "baseColorTexture"): "etc2a8",
                   ("binary", "baseColorTexture"): "etc2a8", ("glass", "baseColorTexture"): "etc2a8"}
    mr = bake_for(bakes, "opaque", "metallicRoughnessTexture").recipe
    assert dict(mr.codec.options)["weights"] == (0.0, 1.0, 1.0)  # R is read by no use
    # three.js takes ETC2 RGB as sRGB only: the data goes through the sRGB curve (test_scene_formats)
    assert (mr.source.data, mr.output.colour_space) == (True, "srgb")
    binary = bake_for(bakes, "binary", "baseColorTexture").recipe
    assert (binary.source.alpha_cutoff, binary.output.colour_space) == (0.5, "srgb")
    nrm = bake_for(bakes, "opaque", "normalTexture")
    assert nrm.recipe.output.normal_layout == "xy" and any("rebuilds Z" in n for n in nrm.notes)


def test_mobile_takes_astc_block_sizes_by_use_when_the_build_has_astc():
    from texcook.formats import ASTC_BLOCK_SIZES

    astc = [f"astc-{w}x{h}" for w, h in ASTC_BLOCK_SIZES]
    available = ["etc1", "rgba8"] + astc
    assert scene.choose_format("mobile", "normal", available) == "astc-4x4"
    assert scene.choose_format("mobile", "colour", available) == "astc-6x6"
    assert scene.choose_format("mobile", "mask", available) == "astc-6x6"
    # was astc-8x8, which three.js's KTX2Loader refuses (it takes ASTC 4x4 and 6x6 only)
    assert scene.choose_format("mobile", "data", available) == "astc-6x6"
    assert scene.choose_format("mobile", "occlusion", available) == "astc-6x6"
    assert scene.choose_format("mobile", "colour", ["etc2", "rgba8"]) == "etc2"
    assert scene.choose_format("mobile-etc", "colour", available) == "etc2"  # whatever the build has
    assert scene.extension_for("ktx2", "astc-6x6") == scene.EXT_ASTC
    assert scene.extension_for("ktx2", "bc1") == scene.EXT_KTX2
    assert scene.extension_for("dds", "bc1") == scene.EXT_DDS


def test_shared_images_bake_once_per_way(tmp_path, rng):
    images = {"orm": rgb(rng), "albedo": rgb(rng)}
    textures = [("orm", None), ("orm", None), ("albedo", 0), ("albedo", 1), ("albedo", 2)]
    samplers = [{"minFilter": 9987}, {"minFilter": 9985, "magFilter": 9728}, {"wrapS": 33071}]
    materials = [
        # occlusion and metallic-roughness of one image, through two textures: one bake holding R, G, B
        {"name": "a", "slots": {"occlusionTexture": 0, "metallicRoughnessTexture": 1,
                                "baseColorTexture": 2}},
        # same image, sampler settings that bake the same: shared; a clamped wrap: a bake of its own
        {"name": "b", "slots": {"baseColorTexture": 3, "emissiveTexture": 4}},
        # the albedo as data: an incompatible way
        {"name": "c", "slots": {"occlusionTexture": 2}},
    ]
    bakes, _ = plan_of(build(tmp_path / "shared.gltf", images, textures, materials, samplers))
    orm = bake_for(bakes, "a", "occlusionTexture")
    assert orm is bake_for(bakes, "a", "metallicRoughnessTexture")
    assert (orm.recipe.codec.format, orm.channels) == ("bc1", "rgb") and not orm.recipe.codec.options
    albedo = bake_for(bakes, "a", "baseColorTexture")
    assert albedo is bake_for(bakes, "b", "baseColorTexture")
    clamped = bake_for(bakes, "b", "emissiveTexture")
    assert clamped is not albedo and clamped.recipe.mips.wrap == ("clamp", "repeat")
    data = bake_for(bakes, "c", "occlusionTexture")
    assert data.recipe.output.colour_space == "linear" and albedo.recipe.output.colour_space == "srgb"
    assert len(bakes) == 4
    ways = [n for b in bakes for n in b.notes if "incompatible ways" in n]
    assert len(ways) == 1 and "image 1 is used 3" in ways[0]  # one fact, said once
    assert not orm.notes


def test_samplers_wrap_modes_and_mips(tmp_path, rng):
    samplers = [
        {"minFilter": 9728},  # NEAREST: no mips
        {"minFilter": 9729, "wrapS": 33071, "wrapT": 33071},  # LINEAR: no mips
        {"minFilter": 9984, "wrapS": 33648, "wrapT": 10497},
        {"minFilter": 9987, "wrapS": 33071, "wrapT": 33648},
        {"magFilter": 9728},  # minFilter unset: mips
    ]
    images = {f"i{k}": rgb(rng, 8) for k in range(6)}
    textures = [(f"i{k}", k) for k in range(5)] + [("i5", None)]
    materials = [{"name": f"m{k}", "slots": {"baseColorTexture": k}} for k in range(6)]
    bakes, _ = plan_of(build(tmp_path / "samplers.gltf", images, textures, materials, samplers))
    got = [(b.recipe.mips.enabled, b.recipe.mips.wrap) for b in (bake_for(bakes, f"m{k}", "baseColorTexture")
                                                                  for k in range(6))]
    assert got == [(False, ("clamp", "clamp")), (False, ("clamp", "clamp")), (True, ("mirror", "repeat")),
                   (True, ("clamp", "mirror")), (True, ("repeat", "repeat")), (True, ("repeat", "repeat"))]
    nearest = bake_for(bakes, "m0", "baseColorTexture").steps["skipped"]
    assert nearest["mips"] == "minFilter NEAREST (9728) uses no mipmaps"


def test_cutoff_follows_the_base_colour_factor_alpha():
    m = gl.Material(alphaMode="MASK", alphaCutoff=0.25, pbrMetallicRoughness=gl.PbrMetallicRoughness(
        baseColorFactor=[1, 1, 1, 0.5]))
    assert scene.texture_cutoff(m) == 0.5
    m.pbrMetallicRoughness.baseColorFactor = [1, 1, 1, 0.2]
    assert scene.texture_cutoff(m) == 1.0
    assert scene.texture_cutoff(gl.Material(alphaMode="MASK")) == 0.5


def test_a_scene_refuses_the_astc_file_container(every_slot, tmp_path):
    """A model points at KTX2 or DDS images; an .astc file holds one level and
    glTF has no way to point at it. Was: for --target mobile, accepted from
    Python, each texture baked without mips to a .astc file."""
    for target in ("desktop", "mobile"):
        with pytest.raises(UsageError, match="ktx2, dds"):
            scene.bake_scene(every_slot, tmp_path / "out", target=target, container="astc")
        assert not (tmp_path / "out").exists()


def test_dds_and_mobile_do_not_mix(every_slot, tmp_path):
    with pytest.raises(UsageError, match="DDS"):
        scene.bake_scene(every_slot, tmp_path / "out", target="mobile", container="dds")
    with pytest.raises(UsageError, match="model's own"):
        scene.bake_scene(every_slot, every_slot.parent)


# ----------------------------------------------------------------------------- bakes


def test_every_slot_bakes_and_validates_as_gltf(every_slot, tmp_path, validate, ktx_parse):
    out = tmp_path / "out"
    report = scene.bake_scene(every_slot, out, preset=PRESET)
    model = check_outputs(out, report, validate, ktx_parse)
    doc = model_json(model)
    assert doc["extensionsUsed"] == [scene.EXT_KTX2] and "extensionsRequired" not in doc
    by_texture = {e["texture"]: e for e in report["textures"]}
    bakes = {b["id"]: b for b in report["bakes"]}
    for t, tex in enumerate(doc["textures"][:8]):
        entry = by_texture[t]
        assert tex["source"] == t  # .gltf default: the original image stays as the fallback
        baked = doc["images"][tex["extensions"][scene.EXT_KTX2]["source"]]
        assert baked["uri"] == entry["output"] == bakes[entry["bake"]]["output"]
        assert (out / doc["images"][t]["uri"]).exists()
        assert entry["sampler"] == {"index": None, "minFilter": None, "magFilter": None,
                                    "wrapS": 10497, "wrapT": 10497}
    psnr = {e["uses"][0]["slot"] + ":" + e["uses"][0]["material_name"]: bakes[e["bake"]]["psnr"]
            for e in report["textures"]}
    assert psnr["occlusionTexture:opaque"] > 25 and psnr["normalTexture:opaque"] > 25
    assert (out / "every.bin").exists()


def test_glb_with_embedded_images_bakes_to_dds(tmp_path, rng, validate, ktx_parse):
    images = {"base": colour_rgba(rng), "nrm": normal_map(rng), "occ": rgb(rng)}
    textures = [("base", 0), ("nrm", 1), ("occ", 0)]
    samplers = [{"minFilter": 9987, "wrapS": 33648}, {"minFilter": 9729}]
    materials = [{"name": "m", "slots": {"baseColorTexture": 0, "normalTexture": 1, "occlusionTexture": 2}}]
    path = build(tmp_path / "embedded.glb", images, textures, materials, samplers, storage="bufferView")
    # the GLB default drops the source images: the baked ones replace them, and are required
    out = tmp_path / "out"
    report = scene.bake_scene(path, out, container="dds", preset=PRESET)
    assert report["fallback"] == "drop"
    model = check_outputs(out, report, validate, ktx_parse)
    doc = model_json(model)
    assert doc["extensionsUsed"] == doc["extensionsRequired"] == [scene.EXT_DDS]
    assert sorted(os.listdir(out)) == ["embedded.glb", "scene.json"]  # no loose copies beside a GLB
    assert len(doc["images"]) == 3 and len(doc["bufferViews"]) == 5 + 3  # geometry, then the three DDS
    for tex in doc["textures"]:
        assert "source" not in tex
        baked = doc["images"][tex["extensions"][scene.EXT_DDS]["source"]]
        assert baked["mimeType"] == "image/vnd-ms.dds" and "bufferView" in baked
    nrm = next(e for e in report["textures"] if e["uses"][0]["slot"] == "normalTexture")
    bake = report["bakes"][nrm["bake"]]
    assert bake["levels"] == 1 and nrm["sampler"]["minFilter"] == 9729
    assert bake["source"] == {"image": 1, "name": "nrm", "bufferView": 6, "mimeType": "image/png"}
    # kept: each texture still reads its PNG, the DDS files are inside the GLB as well
    report = scene.bake_scene(path, tmp_path / "keep", container="dds", preset=PRESET, fallback="keep")
    model = check_outputs(tmp_path / "keep", report, validate, ktx_parse)
    doc = model_json(model)
    assert "extensionsRequired" not in doc and len(doc["images"]) == 6
    for tex in doc["textures"]:
        assert doc["images"][tex["source"]]["mimeType"] == "image/png"
    assert sorted(os.listdir(tmp_path / "keep")) == ["embedded.glb", "scene.json"]


def test_data_uri_images_bake_and_stay_inline(tmp_path, rng, validate, ktx_parse):
    images = {"base": colour_rgba(rng, 8), "mr": rgb(rng, 8)}
    materials = [{"name": "m", "slots": {"baseColorTexture": 0, "metallicRoughnessTexture": 1}}]
    path = build(tmp_path / "inline.gltf", images, [("base", None), ("mr", None)], materials, storage="data")
    out = tmp_path / "out"
    report = scene.bake_scene(path, out, preset=PRESET)
    model = check_outputs(out, report, validate, ktx_parse)
    doc = model_json(model)
    assert doc["images"][0]["uri"].startswith("data:image/png;base64,")
    assert report["bakes"][0]["source"] == {"image": 0, "data_uri": True}
    assert sorted(os.listdir(out)) == ["image0.ktx2", "image1.ktx2", "inline.bin", "inline.gltf", "scene.json"]


def test_one_image_two_ways_is_two_textures_in_the_model(tmp_path, rng, validate, ktx_parse):
    images = {"shared": rgb(rng)}
    materials = [{"name": "paint", "slots": {"baseColorTexture": 0}},
                 {"name": "rock", "slots": {"occlusionTexture": 0}}]
    path = build(tmp_path / "twoways.gltf", images, [("shared", None)], materials)
    out = tmp_path / "out"
    report = scene.bake_scene(path, out, preset=PRESET)
    check_outputs(out, report, validate, ktx_parse)
    doc = model_json(out / "twoways.gltf")
    assert len(doc["textures"]) == 2 and len(doc["images"]) == 3
    paint = doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["index"]
    rock = doc["materials"][1]["occlusionTexture"]["index"]
    assert paint != rock
    files = {t: doc["images"][doc["textures"][t]["extensions"][scene.EXT_KTX2]["source"]]["uri"]
             for t in (paint, rock)}
    assert files == {paint: "shared.colour.ktx2", rock: "shared.data.ktx2"}
    assert load_texture(out / files[paint]).srgb and not load_texture(out / files[rock]).srgb
    assert sum("incompatible ways" in n for b in report["bakes"] for n in b["notes"]) == 1


def test_textures_read_by_material_extensions_are_left_alone(tmp_path, rng, validate, ktx_parse):
    images = {"coat": rgb(rng, 8)}
    materials = [{"name": "m", "slots": {"baseColorTexture": 0},
                  "extensions": {"KHR_materials_clearcoat": {"clearcoatTexture": {"index": 0}}}}]
    path = build(tmp_path / "ext.gltf", images, [("coat", None)], materials)
    out = tmp_path / "out"
    report = scene.bake_scene(path, out, preset=PRESET)
    check_outputs(out, report, validate, ktx_parse)
    doc = model_json(out / "ext.gltf")
    assert "extensions" not in doc["textures"][0]
    base = doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["index"]
    assert base == 1 and scene.EXT_KTX2 in doc["textures"][1]["extensions"]
    assert doc["materials"][0]["extensions"]["KHR_materials_clearcoat"]["clearcoatTexture"]["index"] == 0


# ----------------------------------------------------------------------------- steps not called for


@pytest.fixture
def spies(monkeypatch):
    """Count the sRGB curves and coverage searches, and record every mip chain's settings."""
    import texcook.mips
    import texcook.mips.chain

    calls = {"srgb": 0, "coverage": 0, "chains": []}

    def counted(name, fn):
        def wrapper(*a, **k):
            calls[name] += 1
            return fn(*a, **k)
        return wrapper

    monkeypatch.setattr(colour, "srgb_to_linear", counted("srgb", colour.srgb_to_linear))
    monkeypatch.setattr(colour, "linear_to_srgb", counted("srgb", colour.linear_to_srgb))

    def srgb_flag(fn):  # the pipeline's table paths: the flag says whether the curve is applied
        def wrapper(values, srgb, *a, **k):
            calls["srgb"] += bool(srgb)
            return fn(values, srgb, *a, **k)
        return wrapper

    import texcook.pipeline

    for name in ("to_linear_rgba", "StoredRGBA", "quantize", "rgba8_from_stored"):
        monkeypatch.setattr(texcook.pipeline, name, srgb_flag(getattr(texcook.pipeline, name)))
    monkeypatch.setattr(texcook.mips.chain, "scale_alpha_to_coverage",
                        counted("coverage", texcook.mips.chain.scale_alpha_to_coverage))
    real_chain = texcook.mips.iter_chain

    def chain(pixels, **kw):
        calls["chains"].append(kw)
        return real_chain(pixels, **kw)

    monkeypatch.setattr(texcook.mips, "iter_chain", chain)
    return calls


def test_an_occlusion_texture_never_meets_the_srgb_curve_or_the_coverage_search(tmp_path, rng, spies, validate):
    images = {"occ": colour_rgba(rng, alpha=rng.integers(0, 256, (16, 16)))}
    path = build(tmp_path / "occ.gltf", images, [("occ", None)],
                 [{"name": "m", "alphaMode": "MASK", "slots": {"occlusionTexture": 0}}])
    scene.bake_scene(path, tmp_path / "out", preset=PRESET)
    validate(tmp_path / "out" / "occ.gltf")
    assert spies["srgb"] == 0 and spies["coverage"] == 0
    (chain,) = spies["chains"]
    assert chain["alpha_cutoff"] is None and not chain["premultiply"] and not chain["normal_map"]


def test_steps_called_for_do_run(tmp_path, rng, spies, validate):
    """The same counters see the steps when a use calls for them."""
    soft = np.rint(rng.random((16, 16)) ** 2 * 255).astype(np.uint8)
    images = {"cut": colour_rgba(rng, alpha=soft), "glass": colour_rgba(rng, alpha=soft), "nrm": normal_map(rng)}
    materials = [{"name": "cut", "alphaMode": "MASK", "alphaCutoff": 0.3, "slots": {"baseColorTexture": 0}},
                 {"name": "glass", "alphaMode": "BLEND", "slots": {"baseColorTexture": 1, "normalTexture": 2}}]
    path = build(tmp_path / "steps.gltf", images, [("cut", 0), ("glass", None), ("nrm", 1)], materials,
                 [{"wrapS": 33648, "wrapT": 33071}, {"wrapS": 33071}])
    scene.bake_scene(path, tmp_path / "out", preset=PRESET)
    validate(tmp_path / "out" / "steps.gltf")
    assert spies["srgb"] >= 2 and spies["coverage"] == 4  # levels 1..4 of a 16x16 chain
    cut, glass, nrm = spies["chains"]
    assert (cut["alpha_cutoff"], cut["premultiply"], cut["wrap"]) == (0.3, False, ("mirror", "clamp"))
    assert glass["wrap"] == ("repeat", "repeat") and nrm["wrap"] == ("clamp", "repeat")
    assert (glass["alpha_cutoff"], glass["premultiply"]) == (None, True)
    assert nrm["normal_map"] and not nrm["premultiply"]


def test_no_mipmaps_no_chain(tmp_path, rng, spies, validate):
    images = {"cut": colour_rgba(rng, alpha=rng.integers(0, 256, (16, 16)))}
    path = build(tmp_path / "flat.gltf", images, [("cut", 0)],
                 [{"name": "m", "alphaMode": "MASK", "slots": {"baseColorTexture": 0}}], [{"minFilter": 9729}])
    report = scene.bake_scene(path, tmp_path / "out", preset=PRESET)
    validate(tmp_path / "out" / "flat.gltf")
    assert spies["chains"] == [] and spies["coverage"] == 0
    assert report["bakes"][0]["levels"] == 1
    assert report["bakes"][0]["steps"]["skipped"]["coverage"] == "the sampler uses no mipmaps"


# ----------------------------------------------------------------------------- coverage down the chain


def _coverage_by_level(path, cutoff):
    levels = load_texture(path).levels
    return [alpha_coverage(px[..., 3] / 255.0, cutoff) for px in levels if px.shape[0] * px.shape[1] >= 16]


def test_a_cutout_keeps_its_own_cutoffs_coverage(tmp_path, rng, validate, ktx_parse):
    n = 32
    alpha = np.rint(rng.random((n, n)) ** 2 * 255).astype(np.uint8)  # soft: bc3 keeps the gradient
    images = {"leaf": colour_rgba(rng, n, alpha)}
    results = {}
    for cutoff in (0.3, 0.5):
        folder = tmp_path / f"c{cutoff}"
        folder.mkdir()
        path = build(folder / "leaf.gltf", images, [("leaf", None)],
                     [{"name": "leaf", "alphaMode": "MASK", "alphaCutoff": cutoff, "slots": {"baseColorTexture": 0}}])
        report = scene.bake_scene(path, folder / "out", preset=PRESET)
        check_outputs(folder / "out", report, validate, ktx_parse)
        assert report["bakes"][0]["format"] == "bc3"
        results[cutoff] = folder / "out" / report["bakes"][0]["output"]
    for cutoff, path in results.items():
        target = alpha_coverage(alpha / 255.0, cutoff)
        got = _coverage_by_level(path, cutoff)
        assert len(got) == 4
        assert max(abs(c - target) for c in got) < 0.07, (cutoff, target, got)
    # each bake is made for its own cutoff: measured at the other one, the chain drifts
    for cutoff, other in ((0.3, 0.5), (0.5, 0.3)):
        target = alpha_coverage(alpha / 255.0, other)
        drift = max(abs(c - target) for c in _coverage_by_level(results[cutoff], other))
        assert drift > 0.15, (cutoff, other, drift)


# ----------------------------------------------------------------------------- command line


def test_cli_scene(every_slot, tmp_path, cli_run, validate):
    code, out, err = cli_run("scene", every_slot, "-o", tmp_path / "out", "--preset", PRESET)
    assert code == 0, err
    validate(tmp_path / "out" / "every.gltf")
    assert "occlusion.ktx2: texture 5 (opaque occlusionTexture): bc4 linear" in out
    assert "  srgb: skipped, occlusion is linear data" in out
    assert "rebuilds Z" in err
    code, out, err = cli_run("scene", every_slot, "-o", tmp_path / "out2", "--preset", PRESET, "--json")
    assert code == 0 and len(json.loads(out)["bakes"]) == 8
    code, _, err = cli_run("scene", every_slot, "-o", tmp_path / "x", "--target", "mobile", "--container", "dds")
    assert code == 2 and "DDS" in err
    code, _, err = cli_run("scene", tmp_path / "missing.gltf", "-o", tmp_path / "y")
    assert code == 1 and "no such file" in err


def test_mobile_bakes_etc2_and_judges_data_on_the_channels_read(tmp_path, rng, validate, ktx_parse):
    images = {"mr": rgb(rng), "cut": colour_rgba(rng, alpha=rng.integers(0, 256, (16, 16)))}
    materials = [{"name": "m", "alphaMode": "MASK", "slots": {"metallicRoughnessTexture": 0, "baseColorTexture": 1}}]
    path = build(tmp_path / "mobile.gltf", images, [("mr", None), ("cut", None)], materials)
    out = tmp_path / "out"
    report = scene.bake_scene(path, out, target="mobile", preset=PRESET, available=["etc2", "rgba8"])
    check_outputs(out, report, validate, ktx_parse)
    mr, cut = report["bakes"]
    assert (mr["format"], mr["psnr_channels"]) == ("etc2", "GB")
    # weights (0, 1, 1) spend the effort on green and blue (noise: 13.8-14.3 dB on GB over four seeds,
    # equal weights 12.7-13.3)
    assert mr["psnr"] > 13.5
    assert (cut["format"], cut["psnr_channels"]) == ("etc2a8", "RGBA")


def test_glb_without_a_binary_chunk_gets_one(tmp_path, rng, validate, ktx_parse):
    """A GLB whose buffers are all external files: the baked textures go into a
    new binary chunk (buffer 0) and the external buffer moves to index 1."""
    src = build(tmp_path / "g.gltf", {"base": rgb(rng, 8)}, [("base", None)],
                [{"name": "m", "slots": {"baseColorTexture": 0}}])
    glb = tmp_path / "g.glb"
    glb.write_bytes(scene._glb_bytes(src.read_text(), None))
    out = tmp_path / "out"
    report = scene.bake_scene(glb, out, preset=PRESET)
    check_outputs(out, report, validate, ktx_parse)
    doc = model_json(out / "g.glb")
    assert "uri" not in doc["buffers"][0] and doc["buffers"][1]["uri"] == "g.bin"
    assert {v["buffer"] for v in doc["bufferViews"][:5]} == {1}
    assert (out / "g.bin").read_bytes() == (tmp_path / "g.bin").read_bytes()
    assert not (out / "base.png").exists() and "source" not in doc["textures"][0]  # dropped: GLB default


def test_mobile_bakes_astc_when_the_build_has_it(every_slot, tmp_path, validate, ktx_parse):
    out = tmp_path / "out"
    report = scene.bake_scene(every_slot, out, target="mobile", preset="fastest")
    check_outputs(out, report, validate, ktx_parse)
    fmts = {b["format"] for b in report["bakes"]}
    assert fmts <= {"astc-4x4", "astc-6x6"} and "astc-4x4" in fmts  # the sizes three.js takes
    model = json.loads((out / "every.gltf").read_text())
    assert scene.EXT_ASTC in model["extensionsUsed"]


# ----------------------------------------------------------------------------- the output folder


def tree_state(folder):
    """Every path under `folder` with its bytes (None for folders, the target for symlinks)."""
    folder = Path(folder)
    if not folder.exists():
        return None
    out = {}
    for p in sorted(folder.rglob("*")):
        rel = str(p.relative_to(folder))
        out[rel] = os.readlink(p) if p.is_symlink() else (None if p.is_dir() else p.read_bytes())
    return out


def test_the_models_folder_is_refused_by_identity(every_slot, tmp_path):
    """Was: compared by abspath only, so `//`, `x/..` or a symlink to the
    folder wrote the rewritten model over the source."""
    folder = every_slot.parent
    before = tree_state(folder)
    (tmp_path.parent / f"{tmp_path.name}-link").symlink_to(folder)
    (folder / "sub").mkdir()
    for out in (tmp_path.parent / f"{tmp_path.name}-link", "/" + str(folder), folder / "sub" / "..",
                Path(str(folder) + "/./")):
        with pytest.raises(UsageError, match="model's own"):
            scene.bake_scene(every_slot, out, preset=PRESET)
    (folder / "sub").rmdir()
    assert tree_state(folder) == before


def test_a_copy_never_lands_on_a_source_file(tmp_path, rng, monkeypatch):
    """OUTDIR the parent of the model's folder: the copy of image `x/t.png`
    would be written to `x/t.png` in OUTDIR, which is the model's image
    `t.png`. Refused before anything is written."""
    model_dir = tmp_path / "x"
    model_dir.mkdir()
    (model_dir / "x").mkdir()
    path = build(model_dir / "m.gltf", {"t": rgb(rng, 8)}, [("t", None)],
                 [{"name": "m", "slots": {"baseColorTexture": 0}}])
    doc = json.loads(path.read_text())
    (model_dir / "x" / "t.png").write_bytes(encoded_image(rgb(rng, 8)))
    doc["images"].append({"uri": "x/t.png"})
    doc["textures"].append({"source": 1})
    doc["materials"][0]["emissiveTexture"] = {"index": 1}
    path.write_text(json.dumps(doc))
    before = tree_state(tmp_path)
    import texcook.pipeline

    monkeypatch.setattr(texcook.pipeline, "bake_file", lambda *a, **k: pytest.fail("baked before the check"))
    with pytest.raises(UsageError, match="model's own files"):
        scene.bake_scene(path, tmp_path, preset=PRESET)
    assert tree_state(tmp_path) == before


def test_a_symlinked_subfolder_in_outdir_is_not_written_through(tmp_path, rng):
    model_dir = tmp_path / "m"
    (model_dir / "tex").mkdir(parents=True)
    path = build(model_dir / "m.gltf", {"a": rgb(rng, 8)}, [("a", None)],
                 [{"name": "m", "slots": {"baseColorTexture": 0}}])
    doc = json.loads(path.read_text())
    (model_dir / "tex" / "b.png").write_bytes(encoded_image(rgb(rng, 8)))
    doc["images"][0]["uri"] = "tex/b.png"
    path.write_text(json.dumps(doc))
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    out = tmp_path / "out"
    out.mkdir()
    (out / "tex").symlink_to(elsewhere)
    with pytest.raises(OutputError, match="outside the output folder"):
        scene.bake_scene(path, out, preset=PRESET)
    assert os.listdir(elsewhere) == [] and sorted(os.listdir(out)) == ["tex"]


# ----------------------------------------------------------------------------- all or nothing


@pytest.fixture
def two_textures(tmp_path, rng):
    images = {"a": rgb(rng, 8), "b": rgb(rng, 8)}
    return build(tmp_path / "two.gltf", images, [("a", None), ("b", None)],
                 [{"name": "m", "slots": {"baseColorTexture": 0, "emissiveTexture": 1}}])


def failing_second_bake(monkeypatch, exc):
    import texcook.pipeline

    real = texcook.pipeline.bake_file
    calls = []

    def bake_file(src, dst, recipe, **kw):
        calls.append(dst)
        if os.path.basename(dst).startswith("bake1."):
            raise exc(dst) if callable(exc) else exc
        return real(src, dst, recipe, **kw)

    monkeypatch.setattr(texcook.pipeline, "bake_file", bake_file)
    return calls


@pytest.mark.parametrize("exc", [InputError("cannot read (truncated)", "b.png"), KeyboardInterrupt()])
def test_a_failed_or_interrupted_bake_leaves_outdir_as_it_was(two_textures, tmp_path, monkeypatch, exc):
    """Was: the first texture stayed in OUTDIR without a model or scene.json."""
    fresh, used = tmp_path / "fresh", tmp_path / "used"
    scene.bake_scene(two_textures, used, preset=PRESET)
    (used / "a.ktx2").write_bytes(b"a previous run")
    before = tree_state(used)
    failing_second_bake(monkeypatch, exc)
    for out in (fresh, used):
        with pytest.raises(type(exc)):
            scene.bake_scene(two_textures, out, preset=PRESET)
    assert not fresh.exists()
    assert tree_state(used) == before


def test_sigterm_during_a_bake_leaves_outdir_as_it_was(two_textures, tmp_path, monkeypatch, cli_run):
    import signal

    def unhandled(*_):  # where scene would not handle SIGTERM, fail the test rather than kill pytest
        pytest.fail("SIGTERM reached the default handler")

    failing_second_bake(monkeypatch, lambda dst: signal.raise_signal(signal.SIGTERM))
    previous = signal.signal(signal.SIGTERM, unhandled)
    try:
        code, _, err = cli_run("scene", two_textures, "-o", tmp_path / "out", "--preset", PRESET)
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert code == 143 and "terminated" in err and not (tmp_path / "out").exists()


def test_a_failed_move_puts_back_what_it_replaced(two_textures, tmp_path, monkeypatch):
    out = tmp_path / "out"
    scene.bake_scene(two_textures, out, preset=PRESET)
    for name in os.listdir(out):
        (out / name).write_bytes(b"old " + name.encode())
    before = tree_state(out)
    real, moves = os.replace, []

    def replace(a, b):
        if os.path.dirname(b) == str(out) and "files" in a:
            moves.append(b)
            if len(moves) == 4:  # after some outputs are already in place
                raise OSError(5, "Input/output error")
        return real(a, b)

    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(OSError):
        scene.bake_scene(two_textures, out, preset=PRESET)
    monkeypatch.undo()
    assert len(moves) == 4 and tree_state(out) == before


def test_outdir_is_marked_incomplete_only_while_outputs_move_in(two_textures, tmp_path, monkeypatch):
    """A process killed during the moves leaves `scene.incomplete`, saying so."""
    out = tmp_path / "out"
    real, seen = os.replace, []

    def replace(a, b):
        if os.path.dirname(b) == str(out) and "files" in a:
            seen.append((out / scene.INCOMPLETE).exists())
        return real(a, b)

    monkeypatch.setattr(os, "replace", replace)
    scene.bake_scene(two_textures, out, preset=PRESET)
    assert seen and all(seen) and not (out / scene.INCOMPLETE).exists()


def test_ctrl_c_while_outputs_move_in_waits_for_the_moves(two_textures, tmp_path, monkeypatch):
    import signal

    out = tmp_path / "out"
    real, moves = os.replace, []

    def replace(a, b):
        if os.path.dirname(b) == str(out) and "files" in a:
            moves.append(b)
            if len(moves) == 2:
                signal.raise_signal(signal.SIGINT)
        return real(a, b)

    monkeypatch.setattr(os, "replace", replace)
    # Python's own Ctrl-C handler, even when the tests run from a shell that
    # started them in the background (SIGINT ignored, inherited)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            scene.bake_scene(two_textures, out, preset=PRESET)
    finally:
        signal.signal(signal.SIGINT, previous)
    monkeypatch.undo()
    assert sorted(os.listdir(out)) == ["a.ktx2", "a.png", "b.ktx2", "b.png", "scene.json", "two.bin", "two.gltf"]


def test_a_stage_left_by_a_killed_run_is_swept(two_textures, tmp_path):
    out = tmp_path / "out"
    (out / ".scene.texcook-dead0").mkdir(parents=True)
    (out / ".scene.texcook-dead0" / "bake0.ktx2").write_bytes(b"x")
    (out / ".scene.texcook-young").mkdir()  # may be a live run's, not locked yet
    os.utime(out / ".scene.texcook-dead0", (0, 0))
    scene.bake_scene(two_textures, out, preset=PRESET)
    assert [n for n in os.listdir(out) if n.startswith(".")] == [".scene.texcook-young"]
    os.rmdir(out / ".scene.texcook-young")
    assert not [n for n in os.listdir(out) if n.startswith(".")]


# ----------------------------------------------------------------------------- refusals and --keep-going


def test_refusals_stop_before_any_bake_unless_keep_going(two_textures, tmp_path, monkeypatch, cli_run):
    doc = json.loads(two_textures.read_text())
    doc["images"][1]["uri"] = "missing.png"
    two_textures.write_text(json.dumps(doc))
    import texcook.pipeline

    calls = []
    real = texcook.pipeline.bake_file
    monkeypatch.setattr(texcook.pipeline, "bake_file", lambda *a, **k: calls.append(a) or real(*a, **k))
    with pytest.raises(InputError, match="image 1 .missing.png.: no such file"):
        scene.bake_scene(two_textures, tmp_path / "out", preset=PRESET)
    assert not calls and not (tmp_path / "out").exists()
    for fallback in ("keep", "drop"):
        out = tmp_path / fallback
        report = scene.bake_scene(two_textures, out, preset=PRESET, keep_going=True, fallback=fallback)
        assert len(report["bakes"]) == 1 and [r["slot"] for r in report["not_baked"]] == ["emissiveTexture"]
        assert "no such file" in report["not_baked"][0]["why"]
        # the one error is the source's: the refused file is not there
        doc = model_json(out / "two.gltf")
        missing = doc["textures"][1]["source"]
        assert doc["textures"][1] == {"source": missing}  # the unbaked texture is the source's
        assert doc["images"][missing] == {"uri": "missing.png"}  # refused: left as it was, not copied
        errors = node_tool("validate.mjs", "gltf-validator")([out / "two.gltf"])[0]["issues"]["messages"]
        assert [(m["code"], m["pointer"]) for m in errors if m["severity"] == 0] == [
            ("IO_ERROR", f"/images/{missing}/uri")]
        assert ("source" in doc["textures"][0]) == (fallback == "keep")
    code, out, err = cli_run("scene", two_textures, "-o", tmp_path / "cli", "--preset", PRESET, "--keep-going")
    assert code == 1 and "texcook: not baked: m emissiveTexture: image 1 (missing.png): no such file" in err
    assert "1 texture in 1 bake, 1 texture not baked" in out


def test_keep_going_keeps_the_fallback_of_a_bake_that_failed(tmp_path, rng, monkeypatch, validate):
    path = build(tmp_path / "two.glb", {"a": rgb(rng, 8), "b": rgb(rng, 8)}, [("a", None), ("b", None)],
                 [{"name": "m", "slots": {"baseColorTexture": 0, "emissiveTexture": 1}}], storage="bufferView")
    failing_second_bake(monkeypatch, InputError("cannot decode", "b.png"))
    report = scene.bake_scene(path, tmp_path / "out", preset=PRESET, keep_going=True)
    assert report["fallback"] == "drop" and len(report["bakes"]) == 1
    assert report["not_baked"][0]["slot"] == "emissiveTexture" and "cannot decode" in report["not_baked"][0]["why"]
    # an error naming the output names it in OUTDIR, not in the private folder where it was made
    monkeypatch.undo()
    failing_second_bake(monkeypatch, lambda dst: OutputError("no space left on the device", dst))
    with pytest.raises(OutputError) as err:
        scene.bake_scene(path, tmp_path / "full", preset=PRESET)
    assert str(err.value) == f"{tmp_path / 'full' / 'two.glb'}: no space left on the device"
    validate(tmp_path / "out" / "two.glb")
    doc = model_json(tmp_path / "out" / "two.glb")
    assert "source" not in doc["textures"][0]
    assert doc["images"][doc["textures"][1]["source"]]["mimeType"] == "image/png"  # the failed one's image stays
    assert len(doc["images"]) == 2  # image 0 is dropped, image 1 kept, one baked


# ----------------------------------------------------------------------------- scene.json


def test_scene_json_grows_linearly_with_textures_sharing_an_image(tmp_path, rng):
    """2,000 textures on one image make one bake. Was: each entry listed the
    1,999 others ("shared"), 8 MB and quadratic."""
    n = 2000
    (tmp_path / "a.png").write_bytes(encoded_image(rgb(rng, 8)))
    doc = {"asset": {"version": "2.0"}, "images": [{"uri": "a.png"}],
           "textures": [{"source": 0} for _ in range(n)],
           "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": i}}} for i in range(n)]}
    (tmp_path / "many.gltf").write_text(json.dumps(doc))
    report = scene.bake_scene(tmp_path / "many.gltf", tmp_path / "out", preset=PRESET)
    size = (tmp_path / "out" / "scene.json").stat().st_size
    assert size / n < 400, size
    assert len(report["bakes"]) == 1 and len(report["textures"]) == n
    assert report["bakes"][0]["textures"] == list(range(n))
    out = model_json(tmp_path / "out" / "many.gltf")
    assert all(t["extensions"][scene.EXT_KTX2]["source"] == 1 for t in out["textures"])
    assert b"\n" not in (tmp_path / "out" / "many.gltf").read_bytes()  # on one line, as its source


# ----------------------------------------------------------------------------- the rewritten model


def raw_model(folder, rng, glb=False):
    """A model written by hand, as an exporter would: named samplers, extras
    and extensions everywhere, defaults left implicit."""
    folder = Path(folder)
    pos = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32).tobytes()
    uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32).tobytes()
    idx = np.array([0, 1, 2, 0, 2, 3], np.uint16).tobytes()
    pngs = [encoded_image(colour_rgba(rng, 8)), encoded_image(rgb(rng, 8))]
    blob = bytearray(pos + uv + idx + b"\0\0")
    views = [{"buffer": 0, "byteLength": 48, "target": 34962, "name": "positions"},
             {"buffer": 0, "byteOffset": 48, "byteLength": 32, "target": 34962},
             {"buffer": 0, "byteOffset": 80, "byteLength": 12, "target": 34963}]
    images = []
    for k, data in enumerate(pngs):
        if glb:
            views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)})
            images.append({"bufferView": len(views) - 1, "mimeType": "image/png", "name": f"img{k}",
                           "extras": {"k": k}})
            blob += data + b"\0" * (-len(data) % 4)
        else:
            (folder / f"img{k}.png").write_bytes(data)
            images.append({"uri": f"img{k}.png", "name": f"img{k}", "extras": {"k": k}})
    doc = {
        "asset": {"version": "2.0", "generator": "hand", "extras": {"author": "x"}},
        "extensionsUsed": ["KHR_materials_emissive_strength", "KHR_texture_transform"],
        "scene": 0, "scenes": [{"nodes": [0], "name": "root"}],
        "nodes": [{"mesh": 0, "name": "quad", "translation": [0.5, 0, 0], "extras": {"tag": 1}}],
        "meshes": [{"name": "quad", "primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2,
                                                     "material": 0}]}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 1, 0]},
                      {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
                      {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}],
        "bufferViews": views,
        "buffers": [{"byteLength": len(blob)} if glb else {"uri": "q.bin", "byteLength": len(blob), "name": "geo"}],
        "images": images,
        "samplers": [{"name": "trilinear repeat", "minFilter": 9987, "magFilter": 9729},
                     {"name": "clamped", "wrapS": 33071, "wrapT": 33071, "extras": {"s": True}}],
        "textures": [{"source": 0, "sampler": 0, "name": "albedo", "extras": {"t": 0}},
                     {"source": 1, "sampler": 1, "name": "glow"}],
        "materials": [{"name": "paint", "alphaMode": "MASK", "alphaCutoff": 0.25, "doubleSided": True,
                       "pbrMetallicRoughness": {"baseColorTexture": {"index": 0, "extensions": {
                           "KHR_texture_transform": {"scale": [2, 2]}}}, "metallicFactor": 0},
                       "emissiveTexture": {"index": 1, "texCoord": 0}, "emissiveFactor": [1, 1, 1],
                       "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 2.5}},
                       "extras": {"m": [1, 2]}}],
        "extras": {"root": "kept"},
    }
    if glb:
        path = folder / "hand.glb"
        path.write_bytes(scene._glb_bytes(json.dumps(doc), blob))
    else:
        (folder / "q.bin").write_bytes(bytes(blob))
        path = folder / "hand.gltf"
        path.write_text(json.dumps(doc, indent=1))
    return path, doc


@pytest.mark.parametrize("kind,fallback", [("gltf", "keep"), ("gltf", "drop"), ("glb", "keep"), ("glb", "drop")])
def test_the_rewritten_model_changes_only_its_textures(tmp_path, rng, validate, kind, fallback):
    """Was: rewritten through pygltflib, which dropped the samplers' names and
    wrote out about a hundred defaults."""
    folder = tmp_path / "src"
    folder.mkdir()
    path, src = raw_model(folder, rng, glb=kind == "glb")
    default = "drop" if kind == "glb" else "keep"
    report = scene.bake_scene(path, tmp_path / "out", preset=PRESET, **({} if fallback == default else
                                                                         {"fallback": fallback}))
    out = model_json(tmp_path / "out" / path.name)
    validate(tmp_path / "out" / path.name)
    texture_keys = {"images", "textures", "bufferViews", "buffers", "extensionsUsed", "extensionsRequired"}
    for key in set(src) | set(out):
        if key not in texture_keys:
            assert out.get(key) == src.get(key), key
    exts = [scene.EXT_KTX2]
    assert out["extensionsUsed"] == src["extensionsUsed"] + exts
    assert out.get("extensionsRequired") == (exts if fallback == "drop" else None)
    baked = {b["image"] for b in report["bakes"]}
    for t, tex in enumerate(out["textures"]):
        ext = tex.pop("extensions")
        assert ext[scene.EXT_KTX2]["source"] in baked
        want = dict(src["textures"][t])
        if fallback == "drop":
            del want["source"]
        else:
            assert out["images"][tex["source"]] == src["images"][want["source"]]
        assert tex == want
    assert len(out["images"]) == (2 if fallback == "drop" else 4)
    if kind == "glb":  # geometry views unchanged; the PNGs' views go with their images when dropped
        n = 3 if fallback == "drop" else 5
        assert out["bufferViews"][:n] == src["bufferViews"][:n] and len(out["bufferViews"]) == n + 2
    else:
        assert out["bufferViews"] == src["bufferViews"] and out["buffers"] == src["buffers"]
        assert sorted(os.listdir(tmp_path / "out")) == sorted(
            ["hand.gltf", "scene.json", "q.bin", "img0.ktx2", "img1.ktx2"]
            + (["img0.png", "img1.png"] if fallback == "keep" else []))


def test_a_glb_with_jpegs_holds_only_its_baked_textures_when_dropped(tmp_path, corpus, validate):
    """Was: the JPEGs stayed beside uncompressed KTX2 payloads, and loose
    copies were written beside the GLB (DamagedHelmet 3.8 MB -> 20.6 MB)."""
    from texcook.image import read_image

    folder = tmp_path / "src"
    folder.mkdir()
    path, doc = raw_model(folder, np.random.default_rng(5), glb=True)
    data = bytearray(Path(path).read_bytes())
    # the two PNGs replaced by JPEGs of photographs (64x64 crops of corpus images)
    jpegs = [encoded_image(read_image(corpus / "rgb" / f"ldr-rgb-0{k}.png").integer_values()[:64, :64, :3],
                           ".jpg", 90) for k in (0, 3)]
    blob = bytearray(gl.GLTF2.load_from_bytes(bytes(data)).binary_blob()[:96])
    for k, j in enumerate(jpegs):
        doc["bufferViews"][3 + k].update(byteOffset=len(blob), byteLength=len(j))
        doc["images"][k]["mimeType"] = "image/jpeg"
        blob += j + b"\0" * (-len(j) % 4)
    doc["buffers"][0]["byteLength"] = len(blob)
    path.write_bytes(scene._glb_bytes(json.dumps(doc), blob))
    sizes = {}
    for fallback in ("drop", "keep"):
        out = tmp_path / fallback
        report = scene.bake_scene(path, out, preset=PRESET, fallback=fallback)
        validate(out / "hand.glb")
        glb = (out / "hand.glb").read_bytes()
        assert report["size"] == {"before": path.stat().st_size, "after": len(glb)}
        assert os.listdir(out) == ["hand.glb", "scene.json"] or sorted(os.listdir(out)) == ["hand.glb", "scene.json"]
        assert all(b["recipe"]["output"]["zstd"] == scene.DEFAULT_ZSTD for b in report["bakes"])
        sizes[fallback] = len(glb)
        baked = sum(b["bytes"] for b in report["bakes"])
        if fallback == "drop":
            assert not any(j in glb for j in jpegs)
            # what is left: the geometry, the baked textures and the JSON
            assert len(glb) <= path.stat().st_size - sum(len(j) for j in jpegs) + baked + 2048
        else:
            assert all(j in glb for j in jpegs)
    assert sizes["keep"] - sizes["drop"] >= sum(len(j) for j in jpegs)


def test_zstd_level_and_none(tmp_path, corpus):
    from texcook.container.ktx2 import read_ktx2
    from texcook.image import read_image

    px = read_image(corpus / "rgb" / "ldr-rgb-00.png").integer_values()  # 256x256: zstd's frames cost more on tiny files
    two_textures = build(tmp_path / "two.gltf", {"a": px, "b": px}, [("a", None), ("b", None)],
                         [{"name": "m", "slots": {"baseColorTexture": 0, "emissiveTexture": 1}}])

    sizes = {}
    for level in (None, 0, 3):
        out = tmp_path / f"z{level}"
        report = scene.bake_scene(two_textures, out, preset=PRESET, zstd=level)
        head = (out / "a.ktx2").read_bytes()
        scheme = int.from_bytes(head[44:48], "little")  # supercompressionScheme
        assert scheme == (0 if level == 0 else 2)
        assert report["zstd"] == {None: scene.DEFAULT_ZSTD, 0: None, 3: 3}[level]
        read_ktx2(head)
        sizes[level] = report["bakes"][0]["bytes"]
    assert sizes[None] <= sizes[3] < sizes[0]
    with pytest.raises(UsageError, match="zstd"):
        scene.bake_scene(two_textures, tmp_path / "dds", container="dds", zstd=5)


# ----------------------------------------------------------------------------- text and progress


def test_text_says_each_fact_once_the_steps_that_ran_and_counts_textures_and_bakes(tmp_path, rng, cli_run):
    """Was: the note on an image used several ways printed once per bake,
    texture lines listing only skipped steps, and "4 texture(s) baked"."""
    images = {"orm": rgb(rng), "albedo": rgb(rng), "nrm": normal_map(rng)}
    textures = [("orm", None), ("orm", None), ("albedo", 0), ("albedo", 1), ("albedo", 2), ("nrm", None)]
    samplers = [{"minFilter": 9987}, {"minFilter": 9985, "magFilter": 9728}, {"wrapS": 33071}]
    materials = [{"name": "a", "slots": {"occlusionTexture": 0, "metallicRoughnessTexture": 1,
                                         "baseColorTexture": 2, "normalTexture": 5}},
                 {"name": "b", "slots": {"baseColorTexture": 3, "emissiveTexture": 4}},
                 {"name": "c", "slots": {"occlusionTexture": 2}}]
    path = build(tmp_path / "shared.gltf", images, textures, materials, samplers)
    code, out, err = cli_run("scene", path, "-o", tmp_path / "out", "--preset", PRESET)
    assert code == 0, err
    assert err.count("is used 3 incompatible ways") == 1
    assert err.count("rebuilds Z") == 1
    assert "albedo.colour.ktx2: textures 2, 3 (a baseColorTexture, b baseColorTexture): bc1 srgb" in out
    assert "; ran srgb, mips\n" in out
    assert "  mips: ran, minFilter LINEAR_MIPMAP_LINEAR (9987) uses mipmaps" in out
    assert "  renormalise: ran, normal map" in out
    assert "  srgb: skipped, metallic-roughness and occlusion are linear data" in out
    assert "6 textures in 5 bakes;" in out and "model with its files" in out
    assert "source images kept (the .gltf default" in out
    assert "\r" not in err and "bake/s" not in err  # no bar when stderr is not a terminal
    code, out, err = cli_run("scene", path, "-o", tmp_path / "quiet", "--preset", PRESET, "--quiet")
    assert code == 0 and out == "" and err == ""
    code, out, _ = cli_run("scene", path, "-o", tmp_path / "json", "--preset", PRESET, "--json")
    assert code == 0 and json.loads(out) == json.loads((tmp_path / "json" / "scene.json").read_text())


def test_progress_advances_per_bake_as_each_finishes(every_slot, tmp_path, capsys):
    from texcook.cli import _SceneBar

    seen = []
    report = scene.bake_scene(every_slot, tmp_path / "out", preset=PRESET,
                              progress=lambda i, r, n: seen.append((i, n, r["output"] if isinstance(r, dict) else r)))
    assert [(i, n) for i, n, _ in seen] == [(None, 8)] + [(i, 8) for i in range(8)]
    assert len(report["bakes"]) == 8
    bar = _SceneBar()
    scene.bake_scene(every_slot, tmp_path / "bar", preset=PRESET, progress=bar)
    assert (bar.bar.n, bar.bar.total) == (8, 8)
    bar.close()
    assert "/8 [" in capsys.readouterr().err


def test_glb_summary_says_the_size_and_why_images_are_dropped(tmp_path, rng, cli_run):
    path = build(tmp_path / "g.glb", {"a": rgb(rng, 8)}, [("a", None)],
                 [{"name": "m", "slots": {"baseColorTexture": 0}}], storage="bufferView")
    code, out, err = cli_run("scene", path, "-o", tmp_path / "out", "--preset", PRESET)
    assert code == 0, err
    report = json.loads((tmp_path / "out" / "scene.json").read_text())
    from texcook.fileio import format_size

    assert (f"1 texture in 1 bake; model {format_size(report['size']['before'])} -> "
            f"{format_size(report['size']['after'])}; source images dropped (the GLB default") in out
