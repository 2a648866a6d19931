"""What `texcook view PATH` shows, worked out before serving: the kind of PATH
(a `texcook scene` output folder, a glTF model, one texture), the folder
served, and the manifest the page reads (/_texcook/site.json)."""

import json
import os
import tempfile
import urllib.parse

from .. import formats
from ..container import table as containers
from ..errors import InputError, UsageError
from ..fileio import check_regular, read_bytes
from . import three

SCENE_JSON = "scene.json"
MODEL_EXTENSIONS = (".gltf", ".glb")
BROWSER_IMAGES = (".png", ".jpg", ".jpeg")


class Site:
    """root: the served folder; manifest: the page's JSON; made: name -> a
    function returning bytes made for the page; original_files: uri -> path of
    the original model's files (a scene whose source images were dropped)."""

    def __init__(self, kind, root, manifest, made=None, original_files=None):
        self.kind = kind
        self.root = os.path.realpath(root)
        self.manifest = dict(manifest, kind=kind, three=three.three_version(),
                             vk=three.vk_table())
        self.made = made or {}
        self.original_files = original_files or {}

    def manifest_bytes(self):
        return json.dumps(self.manifest).encode()


def _url(rel):
    return "files/" + urllib.parse.quote(rel.replace(os.sep, "/"))


def _json(path, what):
    try:
        return json.loads(read_bytes(path, what))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"not a JSON {what} ({exc})", path) from None


def open_site(path, source=None):
    """The Site for PATH; `source`: the image a single texture was baked from
    (for the difference view; found in a scene.json beside it otherwise)."""
    path = os.fspath(path)
    if os.path.isdir(path):
        if os.path.exists(os.path.join(path, SCENE_JSON)):
            return _scene_site(path)
        models = sorted(n for n in os.listdir(path) if n.lower().endswith(MODEL_EXTENSIONS))
        if len(models) != 1:
            raise UsageError(f"a folder to view holds {SCENE_JSON} or one glTF model; found "
                             f"{len(models)} model(s) and no {SCENE_JSON}", path)
        return _model_site(os.path.join(path, models[0]))
    check_regular(path)
    ext = os.path.splitext(path)[1].lower()
    if ext in MODEL_EXTENSIONS:
        return _model_site(path)
    if containers.of_path(path) is not None:
        return _texture_site(path, source)
    raise UsageError(f"texcook view shows a scene folder, a .gltf/.glb model or a {containers.EXTENSION_LIST} "
                     "texture", path)


def _model_site(path, scene=None, textures=(), original=None, original_files=None):
    root = os.path.dirname(os.path.abspath(path))
    manifest = {"model": _url(os.path.basename(path)), "textures": list(textures), "scene": scene,
                "original": original or {"how": "fallback",
                                         "why": "the model's own source images, where its textures keep them"}}
    return Site("scene", root, manifest, original_files=original_files)


def _scene_site(folder):
    report = _json(os.path.join(folder, SCENE_JSON), SCENE_JSON)
    name = report.get("output_model")
    if not isinstance(name, str) or os.path.basename(name) != name:
        raise InputError(f"{SCENE_JSON} names no output_model in its folder", folder)
    textures = []
    for bake in report.get("bakes", []):
        fmt = formats.FORMATS.get(bake.get("format"))
        srgb = bake.get("colour_space") == "srgb"
        vk = fmt.vk_format(srgb) if fmt is not None and (fmt.has_srgb or not srgb) else None
        textures.append({"name": bake.get("name"), "format": bake.get("format"), "colour_space":
                         bake.get("colour_space"), "width": bake.get("width"), "height": bake.get("height"),
                         "levels": bake.get("levels"), "psnr": bake.get("psnr"),
                         "psnr_channels": bake.get("psnr_channels"), "extension": bake.get("extension"),
                         "image": bake.get("image"), "vk": vk,
                         "slots": sorted({f"{u.get('material_name') or u.get('material')} {u.get('slot')}"
                                          for t in report.get("textures", []) if t.get("bake") == bake.get("id")
                                          for u in t.get("uses", [])})})
    original, files = _original(folder, report)
    return _model_site(os.path.join(folder, name), scene={"target": report.get("target"),
                                                          "container": report.get("container"),
                                                          "fallback": report.get("fallback")},
                       textures=textures, original=original, original_files=files)


def _original(folder, report):
    """How the page shows the source: the rewritten model's fallback images
    when they were kept, else the original model with only the files it names."""
    if report.get("fallback") == "keep" and not report.get("not_baked"):
        return {"how": "fallback", "why": "the source images the rewritten model keeps (--fallback keep)"}, {}
    model = report.get("model")
    found = _original_model(folder, model)
    if found is not None:
        return {"how": "model", "url": "_texcook/original/" + urllib.parse.quote(os.path.basename(found)),
                "why": f"the original model {model}"}, _model_files(found)
    return {"how": "none", "why": f"the source images were dropped and the original model {model!r} is not found"}, {}


def _original_model(folder, model):
    """scene.json's `model`, as given to `texcook scene` (relative to where it
    ran, so looked for from here and from the output folder's parent): the
    path of that glTF or GLB file, or None."""
    if not isinstance(model, str) or os.path.splitext(model)[1].lower() not in (".gltf", ".glb"):
        return None
    for base in (os.getcwd(), os.path.dirname(os.path.abspath(folder))):
        candidate = os.path.join(base, model)
        if os.path.isfile(candidate):
            return candidate
    return None


def _resolve(model_path, uri, what):
    """The real path of the file a model's `uri` names, through the scene's one
    guarded resolver (inside the model's real folder, a regular file), or None
    where it refuses it."""
    from ..scene.model import Model, RefusedResource, resolve_uri

    try:
        return resolve_uri(Model(model_path, "gltf", None, None), uri, what)
    except RefusedResource:
        return None


def _model_files(model):
    """uri -> path of a model and the external files it names in its folder."""
    files = {os.path.basename(model): os.path.realpath(model)}
    if not model.lower().endswith(".gltf"):
        return files  # a GLB's own buffers are inside it
    doc = _json(model, "glTF model")
    for kind in ("images", "buffers"):
        for i, item in enumerate(doc.get(kind, [])):
            uri = item.get("uri") if isinstance(item, dict) else None
            path = _resolve(model, uri, f"{kind[:-1]} {i}") if isinstance(uri, str) else None
            if path is not None:
                files[uri] = path
    return files


def _texture_site(path, source):
    """One texture: a KTX2 file served as it is; a DDS or .astc file rewrapped
    as KTX2 (same blocks, the page has one loader); its source image when known."""
    root = os.path.dirname(os.path.abspath(path))
    name = os.path.basename(path)
    box = containers.of_path(path)
    stored = box.read(read_bytes(path, "texture"), path)
    if stored.format is None:
        raise InputError(f"{stored.label} is not a format texcook knows", path)
    fmt = formats.get(stored.format)
    made = {}
    if box.name == three.LOADS_CONTAINER:
        url = _url(name)
    else:
        from ..container.ktx2 import write_ktx2

        data = write_ktx2(fmt.vk_format(stored.srgb), stored.width, stored.height, stored.levels)
        made["texture.ktx2"] = lambda: data
        url = "_texcook/made/texture.ktx2"
    if source is None:
        source = _source_from_scene(root, name)
    source_url = None
    if source is not None:
        made["source.png"] = _source_png(source)
        source_url = "_texcook/made/source.png"
    manifest = {"texture": {"url": url, "name": name, "format": fmt.name, "srgb": stored.srgb,
                            "vk": fmt.vk_format(stored.srgb), "width": stored.width, "height": stored.height,
                            "levels": len(stored.levels), "container": box.title},
                "source": {"url": source_url, "name": os.path.basename(source) if source else None}}
    return Site("texture", root, manifest, made=made)


def _source_from_scene(folder, name):
    """The source image of `name` when a scene.json beside it baked it from a
    file: beside the original model, or copied beside the bakes (--fallback
    keep); a uri that leaves either folder names nothing."""
    path = os.path.join(folder, SCENE_JSON)
    if not os.path.isfile(path):
        return None
    report = _json(path, SCENE_JSON)
    # the uri is resolved against the original model's folder, then the output folder's (scene.json's own)
    models = [_original_model(folder, report.get("model")), os.path.join(folder, SCENE_JSON)]
    for bake in report.get("bakes", []):
        uri = (bake.get("source") or {}).get("uri")
        if bake.get("output") == name and isinstance(uri, str):
            for model in models:
                found = _resolve(model, uri, "source image") if model is not None else None
                if found is not None:
                    return found
    return None


def _source_png(source):
    """A PNG of the source image for the browser, made once now: PNG and JPEG
    as they are, any other image texcook reads converted (8-bit)."""
    check_regular(source)
    if os.path.splitext(source)[1].lower() in BROWSER_IMAGES:
        data = read_bytes(source, "source image")
    else:
        import numpy as np

        from ..image import write_images
        from ..pipeline import load_texture

        decoded = load_texture(source)
        px = decoded.levels[0]
        if px.dtype != np.uint8:
            px = np.rint(np.clip(px, 0, 1) * 255).astype(np.uint8)
        with tempfile.TemporaryDirectory() as tmp:
            out = os.path.join(tmp, "source.png")
            write_images([(out, px)], "srgb" if decoded.srgb else "linear")
            data = read_bytes(out, "converted source image")
    return lambda: data
