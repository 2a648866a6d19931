"""Planning a scene: the model's material slots and samplers become texture
uses, uses that agree share one bake, and each bake gets its recipe and the
reasons for every step it runs or skips.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from .. import codecs, formats
from ..choices import SCENE_CONTAINERS
from ..choices import SCENE_TARGETS as TARGETS
from ..container import table as containers
from ..errors import InputError, UsageError
from ..plan import BakePlan, plan_bake
from ..rdo import supports as rdo_supports
from ..recipe import Recipe
from ..view.three import LOADS_CONTAINER, three_takes
from .model import alpha_facts

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

# Format per target and use class (docs/scene.md). "mask-binary": a cut-out
# whose alpha is already two-level, which a 1-bit (punch-through) alpha holds
# at half the size of an 8-bit one, its threshold at the cutoff. "mask": a
# soft alpha keeps its gradient so that magnified cut-out edges stay smooth; on
# desktop in BC3, whose alpha has a block of its own (BC7 weighs alpha as one
# of four channels and lost a noisy cut-out's coverage at the cutoff in the
# small levels). "blend" has no test and takes BC7 on desktop: BC3's size,
# colour not held to one line per block. "occlusion": an image only occlusion
# reads (R alone). "normal-xyz": a normal map for readers that do not rebuild
# Z from X and Y (the container table's gltf_rebuilds_z). One column per
# target (choices.SCENE_TARGETS). "mobile" is ASTC in the sizes three.js's
# KTX2Loader takes (4x4, 6x6; 8x8 would be smaller for data but is refused).
# "mobile-etc" is for OpenGL ES 3.0 and WebGL devices without ASTC, and what
# "mobile" falls back to in a build without an ASTC encoder: ETC2 and EAC,
# which every OpenGL ES 3.0, Vulkan and Metal device decodes. Its two-level
# cut-outs take etc2a8, not the punch-through etc2a1 at half the size:
# three.js's KTX2Loader refuses etc2a1 (vkFormats 149, 150).
FORMAT_TABLE = {
    "desktop": {"colour": "bc1", "mask": "bc3", "mask-binary": "bc1a", "blend": "bc7",
                "occlusion": "bc4", "data": "bc1", "normal": "bc5", "normal-xyz": "bc1"},
    "mobile": {"colour": "astc-6x6", "mask": "astc-6x6", "mask-binary": "astc-6x6", "blend": "astc-6x6",
               "occlusion": "astc-6x6", "data": "astc-6x6", "normal": "astc-4x4", "normal-xyz": "astc-4x4"},
    "mobile-etc": {"colour": "etc2", "mask": "etc2a8", "mask-binary": "etc2a8", "blend": "etc2a8",
                   "occlusion": "eac-r11", "data": "etc2", "normal": "eac-rg11", "normal-xyz": "etc2"},
    "universal": {"colour": "etc1s", "mask": "etc1s-rgba", "mask-binary": "etc1s-rgba", "blend": "etc1s-rgba",
                  "occlusion": "etc1s", "data": "etc1s", "normal": None, "normal-xyz": None},
}
# Why a target leaves a use class in its source image (None in its column).
# ETC1S gives each 4x4 block one base colour moved along the grey axis, so X and
# Y cannot vary apart within a block: 24-37 dB on X/Y of the corpus's and the
# example's normal maps even with every block its own endpoint (quality 255),
# against 44 dB for BC5. Basis Universal's other payload, UASTC, holds normals;
# texcook does not write it.
KEPT_SOURCE = {
    ("universal", "normal"): "ETC1S cannot hold a normal map's X and Y apart within a block (one colour line "
                             "per block): the normal map stays in its source image",
}
# The column a target takes when this build cannot encode every format of its own.
FALLBACK_TABLE = {"mobile": "mobile-etc"}

STEPS = ("srgb", "alpha", "mips", "premultiply", "coverage", "renormalise")


def choose_format(target, use, available=None):
    """The format for a use class on a target: its own column, or its
    fallback's (mobile without an ASTC encoder: mobile-etc) when this build
    cannot encode every format of its own."""
    table = FORMAT_TABLE[target]
    if target in FALLBACK_TABLE:
        available = set(codecs.names() if available is None else available)
        if not set(table.values()) <= available:
            table = FORMAT_TABLE[FALLBACK_TABLE[target]]
    return table[use]


def three_refuses(fmt, srgb):
    """The vkFormat three.js's KTX2Loader refuses for `fmt` stored so, or None."""
    row = formats.get(fmt)
    return None if three_takes(row, srgb) else (row.vk_srgb if srgb else row.vk_unorm)



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
    plan: BakePlan | None = None  # the bake's plan, made once (scene.json's steps and the bake read it)
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



def _way(use, src):
    """The alpha treatment of a colour use: none, mask or blend. The image's
    alpha is looked at only for alpha-tested or blended base colour."""
    if use.slot != "baseColorTexture" or use.alpha_mode == "OPAQUE":
        return "none"
    if src.has_alpha is None:
        src.has_alpha, src.binary_alpha = alpha_facts(src.path)
    if not src.has_alpha:
        return "none"
    return "mask" if use.alpha_mode == "MASK" else "blend"


def check_choices(target, container):
    if target not in TARGETS:
        raise UsageError(f"target must be one of {', '.join(TARGETS)}, not {target!r}")
    if container not in SCENE_CONTAINERS:
        raise UsageError(f"a scene's container must be one of {', '.join(SCENE_CONTAINERS)}, not {container!r}")
    if not _holds_target(container, target):
        can = next(c for c in SCENE_CONTAINERS if _holds_target(c, target))
        raise UsageError(f"{containers.get(container).title} cannot hold the {target} formats: use --container "
                         f"{can} with --target {target}")


def _holds_target(container, target):
    """The container holds every format of one of the target's tables."""
    box = containers.get(container)
    names = [target] + ([FALLBACK_TABLE[target]] if target in FALLBACK_TABLE else [])
    return any(all(box.holds(formats.get(f)) for f in FORMAT_TABLE[name].values() if f) for name in names)


def plan(model, target, container, preset, sources, available=None, zstd=None, rdo=None):
    """Group the model's texture uses into bakes, each with its recipe and
    its plan (texcook.plan, for no output path yet: BakePlan.writing_to).
    `sources` maps image index -> ImageSource (see extract_images);
    `available` overrides the encodable formats (codecs.names()); `zstd`,
    the KTX2 supercompression level of every bake (None: none); `rdo`, the
    RDO lambda of every bake whose format texcook.rdo reworks (None: none)."""
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
        kept = KEPT_SOURCE.get((target, use.kind))
        if kept is not None:
            skipped.append((use, kept))
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
        _recipe_for(bake, target, preset, sources[bake.image], available, container)
        if zstd is not None and not formats.get(bake.recipe.codec.format).basislz:  # BasisLZ is its own supercompression
            bake.recipe = bake.recipe.replace(zstd=zstd)
        if rdo and rdo_supports(bake.recipe.codec.format):  # the formats it cannot rework are baked as they were
            bake.recipe = bake.recipe.replace(rdo=rdo)
        bake.recipe.check_container(container, model.path)
    for bake in bakes:  # scene.json's steps: what each bake's plan runs and skips
        bake.plan = plan_bake(sources[bake.image].path, bake.recipe, container=container)
        bake.steps = _steps(bake, bake.plan)
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


def _recipe_for(bake, target, preset, src, available, container="ktx2"):
    if bake.kind == "normal":
        use = "normal"
        fmt = choose_format(target, use, available)
        if codecs.get(fmt).channels == 2 and not containers.get(container).rebuilds_z(fmt):
            use = "normal-xyz"
    elif bake.kind == "data":
        bake.channels = "".join(c for c in "rgb" if any(c in SLOT_CHANNELS[u.slot] for u in bake.uses))
        use = "occlusion" if bake.channels == "r" else "data"
    elif bake.alpha == "mask":
        use = "mask-binary" if src.binary_alpha else "mask"
    else:
        use = bake.alpha if bake.alpha == "blend" else "colour"
    fmt = choose_format(target, use, available)
    srgb = bake.kind == "colour"
    # three.js's GLTFLoader hands the KTX2 files to its KTX2Loader, whose vkFormats are listed
    refused = three_refuses(fmt, srgb) if container == LOADS_CONTAINER else None
    # data in a format three.js takes in its sRGB variant only (ETC2 RGB): stored
    # through the sRGB curve, which the sampler's decode undoes (--data --srgb)
    through_srgb = refused is not None and bake.kind == "data" and three_refuses(fmt, True) is None
    flat = dict(format=fmt, preset=preset, mips=bake.mips, wrap=bake.wrap,
                srgb=srgb or through_srgb, normal_map=bake.kind == "normal",
                premultiply=bake.alpha == "blend" and bake.mips,
                alpha_cutoff=bake.cutoff if bake.alpha == "mask" else None)
    if bake.kind == "normal":
        # a glTF reader samples X, Y and Z from R, G and B: stored so wherever the
        # format holds three channels; a two-channel one (BC5) only for readers
        # of an extension that rebuild Z (docs/scene.md)
        flat["normal_layout"] = "xyz" if "xyz" in codecs.get(fmt).normal_layouts else "xy"
    if through_srgb:
        flat["data"] = True
        bake.notes.append(f"three.js's KTX2Loader refuses linear {fmt} (vkFormat {refused}) and takes its sRGB "
                          f"variant ({formats.get(fmt).vk_srgb}): the linear data is stored through the sRGB "
                          "curve, which the sampler's sRGB decode undoes")
    elif refused is not None:
        bake.notes.append(f"three.js's KTX2Loader refuses {fmt} {'sRGB' if srgb else 'linear'} (vkFormat "
                          f"{refused}): a viewer built on it shows the fallback image")
    if bake.kind == "data":
        weights = _codec_weights(fmt, bake.channels)
        if weights is not None:
            flat["weights"] = weights
    bake.recipe = Recipe.of(**flat)
    if bake.kind == "normal" and codecs.get(fmt).channels == 2:
        bake.notes.append(f"{fmt} stores X and Y only: the reader rebuilds Z = sqrt(1 - X^2 - Y^2)")
    elif use == "normal-xyz":
        ext = containers.get(container).gltf_extension(fmt)
        bake.notes.append(f"{ext} readers sample Z as stored: X, Y and Z kept in {fmt}, not two-channel "
                          f"{choose_format(target, 'normal', available)}")


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


def _steps(bake, bake_plan):
    """{"ran": {step: why}, "skipped": {step: why}}: what the bake's plan
    (texcook.plan) runs and skips, said in the words of the uses that asked
    for it; where the plan decides otherwise than they asked, its own reason.
    "alpha" is the uses' alpha treatment (a material's, not a bake's step)."""
    asked = _asked_steps(bake)
    ran, skipped = {}, {}
    for step in STEPS:
        did = step in asked["ran"] if step == "alpha" else bake_plan.step(step)[0]
        words = asked["ran" if did else "skipped"].get(step)
        (ran if did else skipped)[step] = words if words is not None else bake_plan.step(step)[1]
    return {"ran": ran, "skipped": skipped}


def _asked_steps(bake):
    """{"ran": {step: why}, "skipped": {step: why}}: what the uses ask of the
    bake, and why."""
    ran, skipped = {}, {}
    uses = bake.uses
    words, verb = _slots(uses)
    what = {"colour": "sRGB colour", "data": "linear data", "normal": "vectors, not colour"}[bake.kind]
    if bake.kind == "normal":
        verb = "holds" if verb == "is" else "hold"
    if bake.kind == "data" and bake.recipe.source.data and bake.recipe.output.colour_space == "srgb":
        ran["srgb"] = (f"{words} {verb} {what}, stored through the sRGB curve: three.js takes "
                       f"{bake.recipe.codec.format} as sRGB only")
    else:
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
    """A note on each image baked more than once, on its first bake only:
    one fact, said once (the note names every way)."""
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
        group[0].notes.append(f"image {image} is used {len(group)} {what}, baked once for each: {ways}")
