"""Publishing a scene: names for the baked textures, the rewritten model that
references them, and scene.json.
"""

from __future__ import annotations

import copy
import math
import os
import re
import struct
import urllib.parse

import numpy as np

from .. import formats
from .model import _image_desc
from .plan import _slot_infos, foreign_textures

# How the rewritten model points a texture at its baked image (docs/scene.md):
# DDS through MSFT_texture_dds; ASTC in KTX2 through EXT_texture_astc; any other
# KTX2 payload (BC, ETC1, RGBA8) through texcook's own optional extension.
EXT_DDS = "MSFT_texture_dds"
EXT_ASTC = "EXT_texture_astc"
EXT_KTX2 = "TEXCOOK_texture_ktx2"
MIME_TYPES = {"ktx2": "image/ktx2", "dds": "image/vnd-ms.dds"}
SCENE_JSON = "scene.json"


def extension_for(container, fmt):
    if container == "dds":
        return EXT_DDS
    return EXT_ASTC if formats.get(fmt).family == "astc" else EXT_KTX2



# --- outputs -----------------------------------------------------------------------------

_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")


def _stem(model, index):
    image = model.gltf.images[index]
    raw = image.name
    if not raw and image.uri and not image.uri.startswith("data:"):
        raw = os.path.splitext(os.path.basename(urllib.parse.unquote(image.uri)))[0]
    stem = _UNSAFE.sub("_", raw or "").strip("._")
    return stem or f"image{index}"


def _unique(name, taken):
    stem, ext = os.path.splitext(name)
    candidate, n = name, 2
    while candidate.lower() in taken:
        candidate = f"{stem}-{n}{ext}"
        n += 1
    taken.add(candidate.lower())
    return candidate


def name_outputs(model, bakes, container, taken):
    """A file name in OUTDIR for each bake: the image's name, with the kind of
    use when the image is baked more than once."""
    count = {}
    for b in bakes:
        count[b.image] = count.get(b.image, 0) + 1
    for b in bakes:
        stem = _stem(model, b.image)
        if count[b.image] > 1:
            stem += f".{b.kind}" if b.alpha == "none" else f".{b.alpha}"
        b.output = _unique(f"{stem}.{container}", taken)


def _resource_copies(model, gltf, taken):
    """(source path, name in OUTDIR) for every external file the model needs,
    with the uris in `gltf` rewritten to the names: relative paths inside the
    model's folder are kept, others become a plain file name."""
    copies = []
    seen = {}
    for obj in list(gltf.buffers or []) + list(gltf.images or []):
        uri = obj.uri
        if uri is None or uri.startswith("data:"):
            continue
        rel = os.path.normpath(urllib.parse.unquote(uri))
        src = os.path.join(model.folder, rel)
        if src in seen:
            obj.uri = seen[src]
            continue
        if os.path.isabs(rel) or rel.startswith(".."):
            rel = os.path.basename(rel)
        rel = _unique(rel.replace(os.sep, "/"), taken)
        copies.append((src, rel))
        seen[src] = obj.uri = urllib.parse.quote(rel)
    return copies


def _slot_info(material, slot):
    for name, info in _slot_infos(material):
        if name == slot:
            return info
    return None


def _glb_bytes(json_text, blob):
    chunk = json_text.encode("utf-8")
    chunk += b" " * (-len(chunk) % 4)
    parts = [struct.pack("<I", len(chunk)), b"JSON", chunk]
    if blob is not None:
        data = bytes(blob) + b"\0" * (-len(blob) % 4)
        parts += [struct.pack("<I", len(data)), b"BIN\0", data]
    body = b"".join(parts)
    return b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body


def rewrite_model(model, gltf, bakes, container, baked_data):
    """Rewrite `gltf` (a copy of the model's, its resource uris already
    pointing at their copies) to reference the baked textures. Returns the GLB
    binary chunk (None for .gltf) and the texture index each (texture, bake)
    pair now reads.

    Each bake becomes an image; each (texture, bake) pair a texture whose
    `source` stays the original image (the fallback) and whose extension names
    the baked one. A texture keeps its index for its first bake; further bakes
    get copies. Textures that material extensions also read are never changed:
    all their bakes get copies."""
    import pygltflib

    gltf.images = list(gltf.images or [])
    gltf.textures = list(gltf.textures or [])
    blob = None
    if model.kind == "glb":
        gltf.buffers = list(gltf.buffers or [])
        gltf.bufferViews = list(gltf.bufferViews or [])
        if not gltf.buffers or gltf.buffers[0].uri is not None:
            # the GLB binary chunk must be buffer 0: move the others up
            for view in gltf.bufferViews:
                view.buffer += 1
            gltf.buffers.insert(0, pygltflib.Buffer(byteLength=0))
            blob = bytearray()
        else:
            blob = bytearray(model.blob or b"")
    used = []
    image_of = []
    for b, data in zip(bakes, baked_data):
        ext = extension_for(container, b.recipe.codec.format)
        if ext not in used:
            used.append(ext)
        image = pygltflib.Image(name=os.path.splitext(b.output)[0])
        if blob is not None:
            blob += b"\0" * (-len(blob) % 4)
            gltf.bufferViews.append(pygltflib.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data)))
            blob += data
            image.bufferView = len(gltf.bufferViews) - 1
            image.mimeType = MIME_TYPES[container]
        else:
            image.uri = urllib.parse.quote(b.output)
        gltf.images.append(image)
        image_of.append((len(gltf.images) - 1, ext))
    if blob is not None:
        gltf.buffers[0].byteLength = len(blob)
    foreign = foreign_textures(model.gltf)
    kept = set()
    texture_of = {}
    for bi, b in enumerate(bakes):
        for u in b.uses:
            key = (u.texture, bi)
            if key not in texture_of:
                if u.texture in foreign or u.texture in kept:
                    gltf.textures.append(copy.deepcopy(model.gltf.textures[u.texture]))
                    index = len(gltf.textures) - 1
                else:
                    kept.add(u.texture)
                    index = u.texture
                tex = gltf.textures[index]
                image, ext = image_of[bi]
                tex.extensions = dict(tex.extensions or {})
                tex.extensions[ext] = {"source": image}
                texture_of[key] = index
            _slot_info(gltf.materials[u.material], u.slot).index = texture_of[key]
    gltf.extensionsUsed = list(gltf.extensionsUsed or []) + [e for e in used if e not in (gltf.extensionsUsed or [])]
    return blob, texture_of


def level0_psnr(result, channels):
    """PSNR of level 0 over the channels the uses read (from a pipeline.compare
    result): an occlusion texture is judged on R, not on what a format happens
    to store in G and B."""
    from ..metrics import psnr_from_mse

    per = result["levels"][0]["channels"]
    mses = [0.0 if math.isinf(per[c]) else 10.0 ** (-per[c] / 10.0) for c in channels.upper() if c in per]
    return {"channels": "".join(c for c in channels.upper() if c in per),
            "psnr": psnr_from_mse(sum(mses) / len(mses), 1.0) if mses else math.nan}


def _finite(x):
    """JSON has no infinity: an exact level 0 (lossless) is written as the string "inf"."""
    if isinstance(x, float) and not np.isfinite(x):
        return "inf" if x > 0 else "-inf"
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_finite(v) for v in x]
    return x


def describe(model, bakes, skipped, summaries, psnr, texture_of, target, container, preset, model_name,
             extensions):
    """scene.json: one entry per texture and way it is baked."""
    gltf = model.gltf
    entries = []
    for bi, (b, summary, db) in enumerate(zip(bakes, summaries, psnr)):
        by_texture = {}
        for u in b.uses:
            by_texture.setdefault(u.texture, []).append(u)
        for t, uses in sorted(by_texture.items()):
            tex = gltf.textures[t]
            entry = {
                "texture": t,
                "output_texture": texture_of[(t, bi)],
                "source": _image_desc(model, b.image),
                "sampler": uses[0].sampler.to_dict(),
                "uses": [u.to_dict() for u in uses],
                "recipe": b.recipe.to_dict(),
                "steps": b.steps,
                "output": b.output,
                "bytes": summary["bytes"],
                "format": summary["format"],
                "colour_space": summary["colour_space"],
                "width": summary["width"],
                "height": summary["height"],
                "levels": summary["levels"],
                "psnr": db["psnr"],
                "psnr_channels": db["channels"],
                "extension": extension_for(container, b.recipe.codec.format),
                "notes": b.notes + summary["notes"],
            }
            if tex.name:
                entry["name"] = tex.name
            if len(b.uses) != len(uses):
                entry["shared"] = sorted({u.texture for u in b.uses} - {t})
            entries.append(entry)
    return {
        "model": model.path,
        "output_model": model_name,
        "target": target,
        "container": container,
        "preset": preset,
        "extensionsUsed": extensions,
        "bakes": len(bakes),
        "textures": entries,
        "not_baked": [dict(u.to_dict(), texture=u.texture, why=why) for u, why in skipped],
    }
