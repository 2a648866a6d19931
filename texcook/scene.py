"""Scenes drive the recipes: a glTF 2.0 model's materials and samplers say what
each texture is for, and each image is baked with only the processing its uses
call for (docs/scene.md).

- base colour is sRGB colour; its material's alphaMode decides the alpha: OPAQUE
  drops it, MASK keeps alpha-test coverage at the cutoff down the chain, BLEND
  filters with premultiplied weighting;
- emissive is sRGB colour without alpha;
- occlusion (R) and metallic-roughness (G roughness, B metalness) are linear
  data: no sRGB curve, a format holding the channels those uses read;
- normal maps get renormalised normal-map mips (BC5 on desktop, Z rebuilt by
  the reader);
- a sampler's wrapS/wrapT become the mip filter's wrap modes, and a minFilter
  without mipmaps means no mips at all.

Uses are grouped per image: uses that agree (same kind, alpha treatment and
sampler settings) share one bake; an image used in incompatible ways is baked
once per way. The jobs are a plain list of (source, output, recipe) run through
texcook.pipeline.bake_file. The outputs are the baked textures, scene.json and
a rewritten model that references them while keeping the original images as
the fallback.
"""

from __future__ import annotations

import base64
import copy
import dataclasses
import json
import math
import os
import re
import struct
import tempfile
import urllib.parse
from dataclasses import dataclass, field

import numpy as np

from . import codecs, formats
from .choices import SCENE_CONTAINERS
from .choices import SCENE_TARGETS as TARGETS
from .errors import InputError, UsageError
from .fileio import atomic_write
from .recipe import Recipe

# glTF sampler constants (glTF 2.0 specification, 5.26).
WRAP_MODES = {33071: "clamp", 33648: "mirror", 10497: "repeat"}
FILTER_NAMES = {9728: "NEAREST", 9729: "LINEAR", 9984: "NEAREST_MIPMAP_NEAREST", 9985: "LINEAR_MIPMAP_NEAREST",
                9986: "NEAREST_MIPMAP_LINEAR", 9987: "LINEAR_MIPMAP_LINEAR"}
NO_MIPMAP_FILTERS = (9728, 9729)
DEFAULT_WRAP = 10497
DEFAULT_CUTOFF = 0.5

# The material slots read here, with the kind of content each holds.
SLOTS = {
    "baseColorTexture": "colour",
    "emissiveTexture": "colour",
    "occlusionTexture": "data",
    "metallicRoughnessTexture": "data",
    "normalTexture": "normal",
}
SLOT_WORDS = {"baseColorTexture": "base colour", "emissiveTexture": "emissive", "occlusionTexture": "occlusion",
              "metallicRoughnessTexture": "metallic-roughness", "normalTexture": "normal"}
# Channels each data slot reads: occlusion R; roughness G, metalness B.
SLOT_CHANNELS = {"occlusionTexture": "r", "metallicRoughnessTexture": "gb"}
KIND_WORDS = {"colour": "sRGB colour", "data": "linear data", "normal": "normal vectors"}

# Format per target and use class. "mask-binary": a cut-out whose alpha is
# already two-level, which BC1's 1-bit alpha holds at half BC3's size; a soft
# alpha keeps its gradient in BC3 so that magnified cut-out edges stay smooth.
# ETC1 has no alpha: alpha uses on mobile without ASTC stay uncompressed.
FORMAT_TABLE = {
    "desktop": {"colour": "bc1", "mask": "bc3", "mask-binary": "bc1a", "blend": "bc3",
                "occlusion": "bc4", "data": "bc1", "normal": "bc5"},
    "mobile-astc": {"colour": "astc-6x6", "mask": "astc-6x6", "mask-binary": "astc-6x6", "blend": "astc-6x6",
                    "occlusion": "astc-8x8", "data": "astc-8x8", "normal": "astc-4x4"},
    "mobile-etc": {"colour": "etc1", "mask": "rgba8", "mask-binary": "rgba8", "blend": "rgba8",
                   "occlusion": "etc1", "data": "etc1", "normal": "etc1"},
}

# How the rewritten model points a texture at its baked image (docs/scene.md):
# DDS through MSFT_texture_dds; ASTC in KTX2 through EXT_texture_astc; any other
# KTX2 payload (BC, ETC1, RGBA8) through texcook's own optional extension.
EXT_DDS = "MSFT_texture_dds"
EXT_ASTC = "EXT_texture_astc"
EXT_KTX2 = "TEXCOOK_texture_ktx2"
MIME_TYPES = {"ktx2": "image/ktx2", "dds": "image/vnd-ms.dds"}
SOURCE_MAGIC = {b"\x89PNG\r\n\x1a\n": ".png", b"\xff\xd8\xff": ".jpg"}  # what the source reader takes

STEPS = ("srgb", "alpha", "mips", "premultiply", "coverage", "renormalise")
SCENE_JSON = "scene.json"


def choose_format(target, use, available=None):
    """The format for a use class on a target. Mobile takes ASTC when every
    ASTC block size it needs is encodable in this build, else ETC1."""
    if target == "desktop":
        return FORMAT_TABLE["desktop"][use]
    available = set(codecs.names() if available is None else available)
    astc = FORMAT_TABLE["mobile-astc"]
    table = astc if set(astc.values()) <= available else FORMAT_TABLE["mobile-etc"]
    return table[use]


def extension_for(container, fmt):
    if container == "dds":
        return EXT_DDS
    return EXT_ASTC if formats.get(fmt).family == "astc" else EXT_KTX2


# --- reading the model -----------------------------------------------------------------


@dataclass
class Model:
    path: str
    kind: str  # "gltf" or "glb"
    gltf: object  # pygltflib.GLTF2
    blob: bytes | None  # a GLB's binary chunk

    @property
    def folder(self):
        return os.path.dirname(os.path.abspath(self.path))


def load_model(path) -> Model:
    import pygltflib

    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext not in (".gltf", ".glb"):
        raise UsageError(f"a scene is a .gltf or .glb model, not {ext or 'a file without extension'}", path)
    if not os.path.isfile(path):
        raise InputError("no such file", path)
    try:
        if ext == ".glb":
            with open(path, "rb") as fh:
                data = fh.read()
            if data[:4] != b"glTF":
                raise InputError("not a GLB file (no glTF header)", path)
            gltf = pygltflib.GLTF2.load_from_bytes(data)
            if gltf is None:
                raise InputError("GLB file has no JSON chunk", path)
            blob = gltf.binary_blob()
        else:
            gltf = pygltflib.GLTF2.load_json(path)
            blob = None
    except InputError:
        raise
    except (OSError, ValueError, KeyError, TypeError, struct.error) as exc:
        raise InputError(f"not a readable glTF model ({type(exc).__name__}: {str(exc).splitlines()[0][:120]})",
                         path) from None
    version = str(getattr(gltf.asset, "version", "") or "")
    if not version.startswith("2."):
        raise InputError(f"glTF version {version or 'unknown'} is not 2.x", path)
    return Model(path, ext[1:], gltf, bytes(blob) if blob is not None else None)


def _data_uri(uri):
    head, _, payload = uri.partition(",")
    if ";base64" in head:
        return base64.b64decode(payload)
    return urllib.parse.unquote_to_bytes(payload)


def _file_uri(model, uri):
    """The path of an external resource named by a relative URI."""
    return os.path.join(model.folder, urllib.parse.unquote(uri))


def _buffer_data(model, index):
    buffers = model.gltf.buffers or []
    if not 0 <= index < len(buffers):
        raise InputError(f"buffer {index} does not exist", model.path)
    uri = buffers[index].uri
    if uri is None:
        if model.blob is None or index != 0:
            raise InputError(f"buffer {index} has no data (no uri, no GLB binary chunk)", model.path)
        return model.blob
    if uri.startswith("data:"):
        return _data_uri(uri)
    path = _file_uri(model, uri)
    try:
        with open(path, "rb") as fh:
            return fh.read()
    except OSError as exc:
        raise InputError(f"cannot read buffer {index} ({exc.strerror})", path) from None


def image_bytes(model, index):
    """(bytes, None) for an embedded image, (None, path) for an external file."""
    image = model.gltf.images[index]
    if image.uri is not None:
        if image.uri.startswith("data:"):
            return _data_uri(image.uri), None
        return None, _file_uri(model, image.uri)
    if image.bufferView is None:
        raise InputError(f"image {index} has neither a uri nor a bufferView", model.path)
    view = model.gltf.bufferViews[image.bufferView]
    data = _buffer_data(model, view.buffer)
    start = view.byteOffset or 0
    return data[start: start + view.byteLength], None


def _sniff(data):
    """The file extension of a PNG or JPEG, else None."""
    for magic, ext in SOURCE_MAGIC.items():
        if data.startswith(magic):
            return ext
    return None


# --- uses ------------------------------------------------------------------------------


@dataclass(frozen=True)
class SamplerInfo:
    index: int | None
    minFilter: int | None
    magFilter: int | None
    wrapS: int
    wrapT: int

    @property
    def mips(self):
        return self.minFilter not in NO_MIPMAP_FILTERS

    @property
    def wrap(self):
        return (WRAP_MODES.get(self.wrapS, "repeat"), WRAP_MODES.get(self.wrapT, "repeat"))

    def to_dict(self):
        return {"index": self.index, "minFilter": self.minFilter, "magFilter": self.magFilter,
                "wrapS": self.wrapS, "wrapT": self.wrapT}


@dataclass(frozen=True)
class Use:
    material: int
    material_name: str
    slot: str
    texture: int
    alpha_mode: str = "OPAQUE"
    cutoff: float | None = None  # MASK: the cutoff on this texture's alpha
    sampler: SamplerInfo | None = None

    @property
    def kind(self):
        return SLOTS[self.slot]

    def label(self):
        return f"{self.material_name} {self.slot}"

    def to_dict(self):
        return {"material": self.material, "material_name": self.material_name, "slot": self.slot}


def _slot_infos(material):
    pbr = material.pbrMetallicRoughness
    yield "baseColorTexture", pbr.baseColorTexture if pbr else None
    yield "metallicRoughnessTexture", pbr.metallicRoughnessTexture if pbr else None
    yield "normalTexture", material.normalTexture
    yield "occlusionTexture", material.occlusionTexture
    yield "emissiveTexture", material.emissiveTexture


def texture_cutoff(material):
    """The cutoff on the base colour texture's alpha: the shader tests
    factor * texture alpha against alphaCutoff, so the texture's own threshold
    is alphaCutoff / baseColorFactor alpha (at most 1)."""
    cutoff = DEFAULT_CUTOFF if material.alphaCutoff is None else float(material.alphaCutoff)
    pbr = material.pbrMetallicRoughness
    factor = pbr.baseColorFactor if pbr and pbr.baseColorFactor is not None else [1.0, 1.0, 1.0, 1.0]
    fa = float(factor[3]) if len(factor) > 3 else 1.0
    if fa <= 0.0:
        return 1.0
    return min(1.0, cutoff / fa)


def collect_uses(gltf):
    """Every core material slot that references a texture."""
    uses = []
    for m, material in enumerate(gltf.materials or []):
        name = material.name or f"material {m}"
        mode = material.alphaMode or "OPAQUE"
        for slot, info in _slot_infos(material):
            if info is None or info.index is None:
                continue
            cutoff = texture_cutoff(material) if slot == "baseColorTexture" and mode == "MASK" else None
            uses.append(Use(m, name, slot, int(info.index), mode if slot == "baseColorTexture" else "OPAQUE",
                            cutoff))
    return uses


def _texture_refs(value):
    """Texture indices in material extensions (textureInfo-like objects)."""
    if isinstance(value, dict):
        if isinstance(value.get("index"), int) and not isinstance(value.get("index"), bool):
            yield value["index"]
        for v in value.values():
            yield from _texture_refs(v)
    elif isinstance(value, list):
        for v in value:
            yield from _texture_refs(v)


def foreign_textures(gltf):
    """Textures also read by slots other than the five core ones (material
    extensions): those texture objects are left as they are."""
    out = set()
    for material in gltf.materials or []:
        out.update(_texture_refs(material.extensions or {}))
    return out


def sampler_info(gltf, texture, path=None):
    index = gltf.textures[texture].sampler
    if index is None:
        return SamplerInfo(None, None, None, DEFAULT_WRAP, DEFAULT_WRAP)
    if not 0 <= index < len(gltf.samplers or []):
        raise InputError(f"texture {texture} names sampler {index}, which does not exist", path)
    s = gltf.samplers[index]
    wrap_s = DEFAULT_WRAP if s.wrapS is None else int(s.wrapS)
    wrap_t = DEFAULT_WRAP if s.wrapT is None else int(s.wrapT)
    for w in (wrap_s, wrap_t):
        if w not in WRAP_MODES:
            raise InputError(f"sampler {index} has wrap mode {w}; glTF has 33071, 33648 and 10497", path)
    return SamplerInfo(index, s.minFilter, s.magFilter, wrap_s, wrap_t)


# --- planning --------------------------------------------------------------------------


@dataclass
class Bake:
    """One baked texture: an image with the uses it serves and how it is baked."""

    image: int
    kind: str  # colour, data, normal
    alpha: str  # none, mask, blend (colour only)
    cutoff: float | None
    mips: bool
    wrap: tuple
    uses: list = field(default_factory=list)
    channels: str = ""  # data: the channels its uses read
    recipe: Recipe | None = None
    output: str = ""
    steps: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)

    @property
    def read_channels(self):
        """The channels the uses sample, as far as the format stores them."""
        if self.kind == "data":
            return self.channels
        if self.kind == "normal":
            return "rgb"[: min(3, codecs.get(self.recipe.codec.format).channels)]
        return "rgba" if self.alpha in ("mask", "blend") else "rgb"


@dataclass
class ImageSource:
    index: int
    path: str | None  # a file the pipeline can read; None when it cannot be baked
    desc: dict  # how the model stores it
    why: str = ""  # why it cannot be baked
    has_alpha: bool | None = None
    binary_alpha: bool | None = None


def _alpha_facts(path):
    """(has an alpha channel, alpha is two-level 0/1)."""
    from .image import read_image

    image = read_image(path)
    if image.alpha_channel is None:
        return False, False
    a = image.pixels[..., image.alpha_channel]
    return True, bool(np.all((a == 0.0) | (a == 1.0)))


def _way(use, src):
    """The alpha treatment of a colour use: none, mask or blend. The image's
    alpha is looked at only for alpha-tested or blended base colour."""
    if use.slot != "baseColorTexture" or use.alpha_mode == "OPAQUE":
        return "none"
    if src.has_alpha is None:
        src.has_alpha, src.binary_alpha = _alpha_facts(src.path)
    if not src.has_alpha:
        return "none"
    return "mask" if use.alpha_mode == "MASK" else "blend"


def check_choices(target, container):
    if target not in TARGETS:
        raise UsageError(f"target must be one of {', '.join(TARGETS)}, not {target!r}")
    if container not in SCENE_CONTAINERS:
        raise UsageError(f"a scene's container must be one of {', '.join(SCENE_CONTAINERS)}, not {container!r}")
    if container == "dds" and target == "mobile":
        raise UsageError("DDS holds the desktop (BC) formats: use --container ktx2 with --target mobile")


def plan(model, target, container, preset, sources, available=None):
    """Group the model's texture uses into bakes, each with its recipe.
    `sources` maps image index -> ImageSource (see extract_images);
    `available` overrides the encodable formats (codecs.names())."""
    check_choices(target, container)
    gltf = model.gltf
    groups = {}
    skipped = []
    for use in collect_uses(gltf):
        t = use.texture
        if not 0 <= t < len(gltf.textures or []):
            raise InputError(f"{use.label()} names texture {t}, which does not exist", model.path)
        image = gltf.textures[t].source
        src = sources.get(image)
        if image is None or src is None or src.path is None:
            skipped.append((use, "its texture has no source image" if src is None else src.why))
            continue
        s = sampler_info(gltf, t, model.path)
        use = dataclasses.replace(use, sampler=s)
        way = _way(use, src) if use.kind == "colour" else ""
        if way == "mask":
            way_key = ("mask", use.cutoff)
        else:
            way_key = (way,)
        key = (image, s.mips, s.wrap if s.mips else None, use.kind) + way_key
        if key not in groups:
            groups[key] = Bake(image, use.kind, way or "none", use.cutoff if way == "mask" else None, s.mips,
                               s.wrap if s.mips else ("clamp", "clamp"))
        groups[key].uses.append(use)
    bakes = _fold_opaque_into_mask(list(groups.values()))
    bakes.sort(key=lambda b: (b.image, min(u.texture for u in b.uses), b.kind))
    for bake in bakes:
        _recipe_for(bake, target, preset, sources[bake.image], available)
        if container == "dds":
            bake.recipe.check_container("dds", model.path)
    _note_ways(bakes)
    return bakes, skipped


def _fold_opaque_into_mask(bakes):
    """An opaque colour use of an image that is also a cut-out (same sampler
    settings) reads the cut-out's bake: its colour is filtered the same way and
    it ignores alpha. With several cutoffs it joins the lowest."""
    out = []
    masks = {}
    for b in bakes:
        if b.kind == "colour" and b.alpha == "mask":
            k = (b.image, b.mips, b.wrap)
            if k not in masks or b.cutoff < masks[k].cutoff:
                masks[k] = b
    for b in bakes:
        target = masks.get((b.image, b.mips, b.wrap)) if b.kind == "colour" and b.alpha == "none" else None
        if target is not None:
            target.uses.extend(b.uses)
        else:
            out.append(b)
    return out


def _codec_weights(fmt, channels):
    """Error weights that spend the encoder's effort on the channels the uses
    read, when the codec takes weights; None for equal weights."""
    if channels == "rgb" or fmt is None:
        return None
    opt = {o.name: o for o in codecs.get(fmt).options}.get("weights")
    if opt is None:
        return None
    return tuple(1.0 if c in channels else 0.0 for c in "rgba"[: opt.count or 3])


def _recipe_for(bake, target, preset, src, available):
    if bake.kind == "normal":
        use = "normal"
    elif bake.kind == "data":
        bake.channels = "".join(c for c in "rgb" if any(c in SLOT_CHANNELS[u.slot] for u in bake.uses))
        use = "occlusion" if bake.channels == "r" else "data"
    elif bake.alpha == "mask":
        use = "mask-binary" if src.binary_alpha else "mask"
    else:
        use = bake.alpha if bake.alpha == "blend" else "colour"
    fmt = choose_format(target, use, available)
    flat = dict(format=fmt, preset=preset, mips=bake.mips, wrap=bake.wrap,
                srgb=bake.kind == "colour", normal_map=bake.kind == "normal",
                premultiply=bake.alpha == "blend" and bake.mips,
                alpha_cutoff=bake.cutoff if bake.alpha == "mask" else None)
    if bake.kind == "data":
        weights = _codec_weights(fmt, bake.channels)
        if weights is not None:
            flat["weights"] = weights
    bake.recipe = Recipe.of(**flat)
    bake.steps = _steps(bake)
    if bake.kind == "normal" and codecs.get(fmt).channels == 2:
        bake.notes.append(f"{fmt} stores X and Y only: the reader rebuilds Z = sqrt(1 - X^2 - Y^2)")
    if use in ("mask", "mask-binary", "blend") and fmt == "rgba8":
        bake.notes.append("ETC1 has no alpha: this alpha texture is stored uncompressed (rgba8)")


def _join(reasons, sep="; "):
    seen = []
    for r in reasons:
        if r not in seen:
            seen.append(r)
    return sep.join(seen)


def _slots(uses):
    """("occlusion", "is") or ("metallic-roughness and occlusion", "are")."""
    words = _join((SLOT_WORDS[u.slot] for u in uses), " and ")
    return words, "are" if " and " in words else "is"


def _steps(bake):
    """{"ran": {step: why}, "skipped": {step: why}}: what the recipe runs and
    why, from the uses it serves."""
    ran, skipped = {}, {}
    uses = bake.uses
    words, verb = _slots(uses)
    what = {"colour": "sRGB colour", "data": "linear data", "normal": "vectors, not colour"}[bake.kind]
    if bake.kind == "normal":
        verb = "holds" if verb == "is" else "hold"
    (ran if bake.kind == "colour" else skipped)["srgb"] = f"{words} {verb} {what}"
    if bake.alpha in ("mask", "blend"):
        ran["alpha"] = _join(f"alphaMode {u.alpha_mode} ({u.material_name})" for u in uses
                             if u.alpha_mode in ("MASK", "BLEND"))
    else:
        skipped["alpha"] = _join(_no_alpha_why(u) for u in uses)
    sampler = _join(_sampler_words(u) for u in uses)
    if bake.mips:
        ran["mips"] = f"{sampler}; wrap {','.join(bake.wrap)}"
    else:
        skipped["mips"] = sampler
    no_mips = "the sampler uses no mipmaps"
    not_alpha = f"{words} {verb} {what}" if bake.kind != "colour" else None
    if bake.alpha == "blend" and bake.mips:
        ran["premultiply"] = "alphaMode BLEND: colour filtered weighted by alpha"
    else:
        skipped["premultiply"] = not_alpha or {
            "blend": no_mips, "mask": "alphaMode MASK keeps straight alpha for the test"}.get(
            bake.alpha, skipped.get("alpha"))
    if bake.alpha == "mask" and bake.mips:
        ran["coverage"] = _join(f"alphaMode MASK at cutoff {_num(u.cutoff)} ({u.material_name})"
                                for u in uses if u.alpha_mode == "MASK")
    else:
        skipped["coverage"] = not_alpha or {"blend": "alphaMode BLEND", "mask": no_mips}.get(
            bake.alpha, skipped.get("alpha"))
    if bake.kind == "normal" and bake.mips:
        ran["renormalise"] = "normal map: each mip level's vectors renormalised"
    else:
        skipped["renormalise"] = no_mips if bake.kind == "normal" else (
            f"{words} {'are not normal maps' if verb == 'are' else 'is not a normal map'}")
    return {"ran": ran, "skipped": skipped}


def _no_alpha_why(use):
    if use.kind == "data":
        return f"{SLOT_WORDS[use.slot]} reads only {SLOT_CHANNELS[use.slot].upper()}"
    if use.kind == "normal":
        return "normal reads only X, Y, Z"
    if use.slot == "emissiveTexture":
        return "emissive has no alpha"
    if use.alpha_mode == "OPAQUE":
        return "alphaMode OPAQUE"
    return f"alphaMode {use.alpha_mode} but the image has no alpha channel"


def _sampler_words(use):
    s = use.sampler
    if s is None or s.index is None:
        return "no sampler: mipmaps by default"
    if s.minFilter is None:
        return "minFilter unset: mipmaps by default"
    name = FILTER_NAMES.get(s.minFilter, "unknown")
    return f"minFilter {name} ({s.minFilter}) uses {'no ' if not s.mips else ''}mipmaps"


def _way_words(bake):
    details = []
    if bake.alpha == "mask":
        details.append(f"alpha-tested at {_num(bake.cutoff)}")
    elif bake.alpha == "blend":
        details.append("blended alpha")
    details.append(f"wrap {','.join(bake.wrap)}" if bake.mips else "no mips")
    return f" ({', '.join(details)})"


def _num(x):
    return f"{x:.6g}"


def _note_ways(bakes):
    """Notes on images baked more than once."""
    by_image = {}
    for b in bakes:
        by_image.setdefault(b.image, []).append(b)
    for image, group in by_image.items():
        if len(group) < 2:
            continue
        kinds = {b.kind for b in group}
        ways = "; ".join(f"{KIND_WORDS[b.kind]}{_way_words(b)} for {', '.join(u.label() for u in b.uses)}"
                         for b in group)
        what = "incompatible ways" if len(kinds) > 1 else "ways"
        note = f"image {image} is used {len(group)} {what}, baked once for each: {ways}"
        for b in group:
            b.notes.append(note)


# --- images ------------------------------------------------------------------------------


def _image_desc(model, index):
    image = model.gltf.images[index]
    desc = {"image": index}
    if image.name:
        desc["name"] = image.name
    if image.uri is not None:
        if image.uri.startswith("data:"):
            desc["data_uri"] = True
        else:
            desc["uri"] = image.uri
    if image.bufferView is not None:
        desc["bufferView"] = image.bufferView
    if image.mimeType:
        desc["mimeType"] = image.mimeType
    return desc


def extract_images(model, workdir, images):
    """ImageSource for each image index in `images`: external files are read in
    place, embedded ones (bufferView, data URI) are written to `workdir`."""
    sources = {}
    n = len(model.gltf.images or [])
    for i in sorted(images):
        if not 0 <= i < n:
            raise InputError(f"a texture names image {i}, which does not exist", model.path)
        desc = _image_desc(model, i)
        data, path = image_bytes(model, i)
        if data is None:
            if not os.path.isfile(path):
                raise InputError(f"image {i}: no such file", path)
            with open(path, "rb") as fh:
                data = fh.read(16)
        ext = _sniff(data)
        if ext is None:
            sources[i] = ImageSource(i, None, desc, f"image {i} is not PNG or JPEG")
            continue
        if path is None:
            path = os.path.join(workdir, f"image{i}{ext}")
            with open(path, "wb") as fh:
                fh.write(data)
        sources[i] = ImageSource(i, path, desc)
    return sources


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


def run_jobs(jobs, threads=None):
    """Bake each (source, output, recipe) job; the summaries in job order."""
    from .pipeline import bake_file

    return [bake_file(src, dst, recipe, threads=threads) for src, dst, recipe in jobs]


def bake_scene(model_path, outdir, target="desktop", container="ktx2", preset="medium", threads=None,
               available=None):
    """Bake every texture of a glTF model for its uses into `outdir`, with
    scene.json and the rewritten model. Returns the scene.json content."""
    from .pipeline import compare

    check_choices(target, container)
    model = load_model(model_path)
    outdir = os.fspath(outdir)
    if os.path.abspath(outdir) == model.folder:
        raise UsageError("the output folder is the model's own: the rewritten model and its files would "
                         "replace the originals; choose another -o", outdir)
    if os.path.exists(outdir) and not os.path.isdir(outdir):
        raise UsageError("the output must be a folder", outdir)
    gltf = model.gltf
    uses = collect_uses(gltf)
    textures = gltf.textures or []
    images = {textures[u.texture].source for u in uses
              if 0 <= u.texture < len(textures) and textures[u.texture].source is not None}
    model_name = os.path.basename(model.path)
    taken = {SCENE_JSON, model_name.lower()}
    with tempfile.TemporaryDirectory(prefix="texcook-scene-") as work:
        sources = extract_images(model, work, images)
        bakes, skipped = plan(model, target, container, preset, sources, available)
        new = copy.deepcopy(gltf)
        # the copied resources are named first, so that baked names avoid them
        copies = _resource_copies(model, new, taken)
        name_outputs(model, bakes, container, taken)
        os.makedirs(outdir, exist_ok=True)
        jobs = [(sources[b.image].path, os.path.join(outdir, b.output), b.recipe) for b in bakes]
        summaries = run_jobs(jobs, threads)
        psnr = [level0_psnr(compare(src, dst, level=0), b.read_channels) for (src, dst, _), b in zip(jobs, bakes)]
        baked_data = []
        for _, dst, _ in jobs:
            with open(dst, "rb") as fh:
                baked_data.append(fh.read())
    blob, texture_of = rewrite_model(model, new, bakes, container, baked_data)
    for src, rel in copies:
        dst = os.path.join(outdir, rel)
        os.makedirs(os.path.dirname(dst), exist_ok=True)
        try:
            with open(src, "rb") as fh:
                data = fh.read()
        except OSError as exc:
            raise InputError(f"cannot read ({exc.strerror})", src) from None
        atomic_write(dst, data)
    text = new.gltf_to_json()
    out_model = os.path.join(outdir, model_name)
    atomic_write(out_model, _glb_bytes(text, blob) if model.kind == "glb" else text.encode("utf-8"))
    report = describe(model, bakes, skipped, summaries, psnr, texture_of, target, container, preset,
                      model_name, [e for e in new.extensionsUsed if e in (EXT_DDS, EXT_ASTC, EXT_KTX2)])
    atomic_write(os.path.join(outdir, SCENE_JSON), (json.dumps(_finite(report), indent=2) + "\n").encode())
    return report


def level0_psnr(result, channels):
    """PSNR of level 0 over the channels the uses read (from a pipeline.compare
    result): an occlusion texture is judged on R, not on what a format happens
    to store in G and B."""
    from .metrics import psnr_from_mse

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
