"""The bake plan: every decision of a bake, made once, from what an image file
says before its pixels are read (texcook.image.Header), the recipe and the
output container.

    plan_bake(header, recipe, output, container) -> BakePlan     no pixel read
    settle(plan, image)                          -> BakePlan     the decisions that need pixels

The pipeline executes a plan; `texcook bake --plan` prints one; preview, scene
(its scene.json "steps") and `bench --stages` read theirs. Two decisions need
the pixels: `--colour-space auto` (measured on the colour values) and the
notes on channels a format drops (an RGB source that is grey, an alpha that
is opaque). A plan made from a header names them in `pixel_checks`; `settle`
makes them, on the same rules, when the pixels are there.
"""

from __future__ import annotations

import dataclasses
import json
import os
from dataclasses import dataclass, field

import numpy as np

from . import codecs, transforms
from .colour import auto_colour_space, linear_to_srgb
from .container import ktx2_keys as keys, table as containers
from .errors import InputError, UsageError
from .formats import level_dims, max_levels
from .image import Header, finite_pixels, header_of, read_header
from .recipe import Recipe, check_normal_layout

# the keys a plan writes (container.ktx2_keys says what each holds and who reads it)
COLOUR_KEY, CONTENT_KEY, ALPHA_CUTOFF_KEY = keys.COLOUR_SPACE.name, keys.CONTENT.name, keys.ALPHA_CUTOFF.name

# The steps a plan says it runs or skips, in the order the bake meets them.
STEPS = ("decode", "srgb", "mips", "premultiply", "coverage", "renormalise", "range", "transform", "rdo", "zstd",
         "sat")

# Without --format an uncompressed output keeps the source's channels; a grey
# KTX2 texture says with KTXswizzle how a loader spreads its channels.
_GREY_LAYOUT = {1: ("r8", "rrr1"), 2: ("rg8", "rrrg")}
_AUTO_RULE = "linear when at least 75% of the colour values are above 116/255, else sRGB"


@dataclass(frozen=True)
class BakePlan:
    """Everything one bake does, decided. Option and key/value tables are
    tuples of pairs (a plan is frozen); `options` and `key_values` give dicts.
    A value of None in `kv` is written by the bake from the pixels (the
    transform stage's record, the auto colour-space record before `settle`)."""

    source: Header
    recipe: Recipe  # the recipe as it runs (a .astc output's mips turned off)
    container: str
    output: str | None
    format: str
    preset: str
    codec_options: tuple  # (name, value): what the codec gets
    srgb: bool | None  # the output's encoding; None: --colour-space auto, decided from the pixels
    colour_reason: str | None  # why auto chose what it did (None unless auto)
    to_light: bool  # auto chose linear storage for sRGB colour: texels converted to linear light
    decode: bool  # sRGB texels decoded to linear light before the chain
    layout_swizzle: str | None  # KTXswizzle of the grey layouts (rrr1, rrrg)
    levels: tuple  # (width, height) of each level, base first
    chain: tuple  # (name, value): the mip chain's settings, () without mips
    rebuild_z: bool  # a two-channel normal map: Z rebuilt from X and Y
    stream: bool  # each level encoded as it is built (no step that sees every level at once)
    level0_from_stored: bool  # level 0 quantised from the source's stored integers
    range_limit: float | None  # the largest magnitude a float format holds, checked on every level; None: no check
    kv: tuple  # (key, value) of the texcook KTX2 keys and KTXswizzle
    notes: tuple  # what a user should know
    steps: tuple  # (step, ran, why) for each of STEPS
    pixel_checks: tuple  # what is still decided from the pixels (empty once settled)
    settled: bool  # the pixel decisions are made (settle)
    sat: str | None = None  # where the summed-area table goes
    requested: Recipe = field(default=None, compare=False, repr=False)  # the recipe as given

    @property
    def codec(self):
        return codecs.get(self.format)

    @property
    def options(self):
        return dict(self.codec_options)

    @property
    def key_values(self):
        return dict(self.kv)

    @property
    def vk_format(self):
        return None if self.srgb is None else self.codec.vk_format(self.srgb)

    def writing_to(self, output):
        """This plan with its bytes going to `output` (a path of the plan's
        container, which the caller has checked as pipeline.plan_file would):
        where the output goes changes none of the bake's decisions."""
        return dataclasses.replace(self, output=os.fspath(output))

    def step(self, name):
        """(ran, why) of one of STEPS."""
        for step, ran, why in self.steps:
            if step == name:
                return ran, why
        raise KeyError(name)

    def ran(self):
        return {s: why for s, ran, why in self.steps if ran}

    def skipped(self):
        return {s: why for s, ran, why in self.steps if not ran}

    def to_dict(self):
        """Plain values: what `texcook bake --plan --json` prints."""
        src = self.source
        out = {
            "input": {"path": src.path, "width": src.width, "height": src.height, "channels": src.channels,
                      "sample": src.source_dtype, "colour_space": src.colour_space, "alpha": src.alpha},
            "output": self.output,
            "container": self.container,
            "format": self.format,
            "vk_format": self.vk_format,
            "preset": self.preset,
            "codec_options": {k: list(v) if isinstance(v, tuple) else v for k, v in self.codec_options},
            "colour_space": {"chosen": None if self.srgb is None else ("srgb" if self.srgb else "linear"),
                             "why": self.step("srgb")[1], "auto_reason": self.colour_reason,
                             "to_light": self.to_light},
            "decode_to_linear": self.decode,
            "levels": [list(wh) for wh in self.levels],
            "chain": {k: list(v) if isinstance(v, tuple) else v for k, v in self.chain} or None,
            "transforms": [{"name": n, "params": list(p) if isinstance(p, tuple) else p}
                           for n, p in self.recipe.transform.steps],
            "key_values": dict(self.kv) if containers.get(self.container).key_values else {},
            "notes": list(self.notes),
            "steps": {"ran": self.ran(), "skipped": self.skipped()},
            "pixel_checks": list(self.pixel_checks),
            "recipe": self.recipe.to_dict(),
        }
        if self.sat is not None:
            out["sat"] = self.sat
        return out

    def text(self):
        """The plan for a terminal: one fact a line."""
        src = self.source
        d = self.to_dict()
        space = d["colour_space"]["chosen"] or "decided from the pixels"
        lines = [
            (f"input      {src.path or '(in memory)'}: {src.width}x{src.height}, {src.channels} channel(s), "
             f"{src.source_dtype}, {src.colour_space}, alpha {src.alpha}"),
            f"output     {self.output or '-'} ({self.container})",
            f"format     {self.format}, preset {self.preset}"
            + (f", vkFormat {self.vk_format}" if self.vk_format is not None else ""),
            f"options    {', '.join(f'{k}={v}' for k, v in d['codec_options'].items()) or '-'}",
            f"colour     {space}: {d['colour_space']['why']}",
            f"levels     {len(self.levels)}: " + ", ".join(f"{w}x{h}" for w, h in self.levels),
        ]
        if self.chain:
            lines.append("chain      " + ", ".join(f"{k}={_words(v)}" for k, v in self.chain))
        for name, params in self.recipe.transform.steps:
            lines.append(f"transform  {name} {_words(params)}")
        for key, value in self.kv if containers.get(self.container).key_values else ():
            lines.append(f"key/value  {key} = {value if value is not None else '(from the pixels)'}")
        lines += [f"ran        {s}: {why}" for s, why in self.ran().items()]
        lines += [f"skipped    {s}: {why}" for s, why in self.skipped().items()]
        lines += [f"note       {n}" for n in self.notes]
        lines += [f"pixels     {c}" for c in self.pixel_checks]
        return "\n".join(lines)


def _words(v):
    if isinstance(v, tuple):
        return ",".join(str(x) for x in v)
    return str(v)


# --- the decisions -------------------------------------------------------------------


def resolve_format(header, recipe: Recipe, container=containers.DEFAULT):
    """(format name, KTXswizzle or None) of the output."""
    if recipe.codec.format is not None:
        return recipe.codec.format, None
    if header.is_float:
        return "rgba16f", None
    if containers.get(container).key_values and not recipe.source.normal_map and header.channels in _GREY_LAYOUT:
        # R8G8_SRGB would sRGB-encode the alpha kept in green: sRGB grey+alpha stays RGBA
        srgb = recipe.output.colour_space == "srgb" or (
            recipe.output.colour_space is None and header.colour_space == "srgb")
        # "auto" may choose sRGB: keep RGBA then too
        if header.channels == 1 or (not srgb and recipe.output.colour_space != "auto"):
            return _GREY_LAYOUT[header.channels]
    layout = recipe.output.normal_layout
    if recipe.source.normal_map and (layout == "xy" or (layout is None and header.channels == 2)):
        return "rg8", None
    return "rgba8", None


def colour_choice(image, recipe, codec, pixels=True):
    """(srgb, reason, to_light) of the output. reason is None unless the recipe
    asks for "auto"; to_light: the rule chose linear storage for an sRGB-encoded
    colour source, whose texels are then converted to linear light (colour,
    not data kept as it is). Only "auto" looks at the pixels; without them
    (`pixels` False, `image` a Header) it gives (None, None, False) where it
    would."""
    space, normal = recipe.output.colour_space, recipe.source.normal_map
    if space == "auto":
        if normal:
            return False, "a normal map holds vectors", False
        if not codec.format.has_srgb or codec.float_input:
            return False, f"{codec.name} has no sRGB variant", hdr_blocks(codec) and image.colour_space == "srgb"
        if not pixels:
            return None, None, False
        colour = [c for c in range(image.channels) if c != image.alpha_channel]
        values = finite_pixels(image, recipe.source.nan_to_zero)[..., colour]
        if image.colour_space != "srgb":
            values = linear_to_srgb(np.clip(values, 0.0, 1.0))
        chosen, share = auto_colour_space(values)
        reason = f"{100 * share:.1f}% of the colour values are above 116/255; linear from 75%"
        return chosen == "srgb", reason, chosen == "linear" and image.colour_space == "srgb"
    if space is not None:
        if space == "srgb":
            codec.vk_format(True)  # raises when there is no sRGB variant
        return space == "srgb", None, False
    srgb = (image.colour_space == "srgb" and codec.format.has_srgb and not normal and not codec.float_input
            and not recipe.source.data)
    # an HDR block format (BC6H) holds linear light: sRGB colour is decoded to it
    to_light = hdr_blocks(codec) and image.colour_space == "srgb" and not normal
    return srgb, None, to_light


def hdr_blocks(codec):
    """Whether a codec stores float colour in blocks (BC6H): an HDR format,
    sampled as linear light."""
    return codec.float_input and codec.is_block_compressed


def output_srgb(image, recipe, codec):
    """The colour encoding of the output (colour_choice's first answer)."""
    return colour_choice(image, recipe, codec)[0]


def _colour_why(recipe, codec, srgb, reason):
    """Why the output is (or is not) sRGB, in words."""
    space = recipe.output.colour_space
    if space == "auto":
        return f"auto: {reason}" if reason is not None else f"auto: {_AUTO_RULE}, measured on the pixels"
    if space is not None:
        return f"colour space {space} asked for"
    if srgb:
        return f"an sRGB source, and {codec.name} has an sRGB variant"
    if recipe.source.data:
        return "the source holds linear data"
    if recipe.source.normal_map:
        return "a normal map holds vectors"
    if not codec.format.has_srgb or codec.float_input:
        return f"{codec.name} has no sRGB variant"
    return "the source is linear"


def decodes(srgb, to_light, source_colour_space):
    """The one rule for decoding an sRGB-encoded source to linear light before
    the chain: only for sRGB output, or colour that auto stores linear. Baked
    to a linear format (bc4, bc5, --linear) its values are data (masks,
    heights, vectors) and are kept as they are."""
    return bool(srgb or to_light) and source_colour_space == "srgb"


def codec_options(codec, recipe, container, srgb=False):
    """The options the codec gets: the recipe's, then defaults that follow from
    the container and the source's use, for the options the codec declares."""
    declared = {o.name for o in codec.options}
    options = dict(recipe.codec.options)
    for name, value in containers.get(container).codec_defaults.items():
        if name in declared:
            options.setdefault(name, value)
    if "alpha_threshold" in declared and recipe.source.alpha_cutoff is not None:
        options.setdefault("alpha_threshold", int(round(recipe.source.alpha_cutoff * 255)))
    if "srgb" in declared:
        options.setdefault("srgb", srgb)
    if "normal_map" in declared and recipe.source.normal_map:
        options.setdefault("normal_map", True)
    if "normal_layout" in declared and recipe.source.normal_map and recipe.output.normal_layout is not None:
        options.setdefault("normal_layout", recipe.output.normal_layout)
    return options


def _range_limit(fmt):
    """The largest magnitude a float format of fewer than 32 bits holds (rgba16f:
    65504; beyond it a value would become Inf), or None: float32 holds every
    float32 value, and UNORM values are quantised into their range."""
    if not fmt.is_float or np.dtype(fmt.sample).itemsize >= 4:
        return None
    return float(np.finfo(np.dtype(fmt.sample)).max)


def _drop_checks(header, recipe, codec):
    """What dropped_channels will look at in the pixels, in words."""
    if recipe.source.normal_map:
        return []  # a normal map keeps what its layout stores, by choice
    colour = header.channels - (header.alpha_channel is not None)
    checks = []
    if colour >= 3 and codec.channels < 3:
        checks.append(f"whether the RGB source is grey ({codec.name} keeps {codec.channels} channel(s))")
    if header.alpha_channel is not None and codec.channels < 4:
        checks.append(f"whether the alpha is opaque ({codec.name} has no alpha)")
    return checks


def dropped_channels(image, recipe, codec):
    """A note when the format stores fewer channels than the source uses."""
    notes = []
    # the stored integers when there are some: no float copy of the source
    px = image.stored if image.stored is not None else image.pixels
    opaque = np.iinfo(px.dtype).max if image.stored is not None else 1.0
    alpha = image.alpha_channel
    colour = image.channels - (alpha is not None)
    stored = codec.channels
    if recipe.source.normal_map:
        return notes  # a normal map keeps what its layout stores (X, Y or X, Y, Z), by choice
    if colour >= 3 and stored < 3:
        grey = np.array_equal(px[..., 0], px[..., 1]) and np.array_equal(px[..., 0], px[..., 2])
        if not grey:
            kept = "red" if stored == 1 else "red and green"
            notes.append(f"{codec.name} keeps only {kept} of an RGB source")
    if alpha is not None and stored < 4 and px[..., alpha].min() < opaque:
        notes.append(f"{codec.name} has no alpha: the source's alpha is dropped")
    return notes


def _mip_steps(header, recipe, has_alpha, no_mips, count):
    """(chain settings, [(step, ran, why)]) of a mip chain of `count` levels."""
    src, mips = recipe.source, recipe.mips
    steps = []
    if not mips.enabled:
        for step in ("mips", "premultiply", "coverage", "renormalise"):
            steps.append((step, False, no_mips))
        return (), steps
    premultiply = mips.premultiply and has_alpha
    chain = [("filter", mips.filter), ("wrap", mips.wrap), ("lanczos_a", mips.lanczos_a)]
    # the chain's own defaults stand unless the recipe names a value
    if mips.kaiser_width is not None:
        chain.append(("kaiser_width", mips.kaiser_width))
    if mips.kaiser_alpha is not None:
        chain.append(("kaiser_alpha", mips.kaiser_alpha))
    chain += [("premultiply", premultiply), ("alpha_channel", 3 if has_alpha else None),
              ("alpha_cutoff", src.alpha_cutoff), ("normal_map", src.normal_map), ("ldr", not header.is_float),
              ("max_levels", count)]
    steps.append(("mips", True, f"{count} levels, {mips.filter} filter, wrap {','.join(mips.wrap)}"))
    if premultiply:
        steps.append(("premultiply", True, "colour filtered weighted by alpha"))
    else:
        steps.append(("premultiply", False, "the source has no alpha channel" if mips.premultiply
                      else "not asked for (straight alpha filtered as it is)"))
    if src.alpha_cutoff is not None:
        steps.append(("coverage", True, f"alpha-test coverage kept at cutoff {src.alpha_cutoff:.6g}"))
    else:
        steps.append(("coverage", False, "no alpha cutoff"))
    steps.append(("renormalise", True, "normal map: each level's vectors renormalised") if src.normal_map
                 else ("renormalise", False, "not a normal map"))
    return tuple(chain), steps


def plan_bake(source, recipe: Recipe = Recipe(), output=None, container=containers.DEFAULT, sat=None) -> BakePlan:
    """The plan of baking `source` (an image file's path, whose header alone
    is read; a texcook.image.Header; or an Image) by `recipe` into `container`
    (the output's kind: "ktx2", "dds", "astc"). Every check that needs no
    pixel runs here, the recipe's fit to the container first (before a file
    is opened): a recipe that cannot bake this source is refused before its
    pixels are read."""
    recipe.check_container(container, output)
    header = read_header(source) if isinstance(source, (str, os.PathLike)) else header_of(source)
    return _plan(header, recipe, output, container, sat, None, None)


def settle(plan: BakePlan, image) -> BakePlan:
    """The plan with the decisions that need pixels made from `image`'s (the
    image the plan was made for)."""
    header = header_of(image)
    if (header.width, header.height, header.channels, header.source_dtype, header.colour_space,
            header.alpha) != (plan.source.width, plan.source.height, plan.source.channels,
                              plan.source.source_dtype, plan.source.colour_space, plan.source.alpha):
        raise InputError("the image is not the one the bake was planned for (did the file change?)", header.path)
    if plan.settled:
        return plan
    codec = plan.codec
    colour = colour_choice(image, plan.recipe, codec) if plan.srgb is None else None
    notes = dropped_channels(image, plan.recipe, codec)
    return _plan(plan.source, plan.requested, plan.output, plan.container, plan.sat, colour, notes)


def _rdo_step(recipe, name, box, notes, path):
    """("rdo", ran, why); UsageError for a format the stage cannot rework."""
    lam = recipe.codec.rdo
    if not lam:
        return "rdo", False, "not asked for"
    from . import rdo

    if not rdo.supports(name):
        raise UsageError(f"--rdo works on {', '.join(rdo.FORMATS)}, not {name}", path)
    if recipe.output.zstd is None:
        notes.append("--rdo without Zstandard (" + ("--zstd" if box.zstd else f"{box.title} has none")
                     + "): the file is no smaller, only more compressible by whatever compresses it later")
    return "rdo", True, (f"lambda {lam:g}: each block may repeat fields of the {rdo.WINDOW} before it, at most "
                         f"{lam:g} squared error per byte saved")


def _plan(header, recipe, output, container, sat, colour, dropped):
    """plan_bake, with the pixel decisions given (`colour`: colour_choice's
    answer, `dropped`: dropped_channels') or left to the pixels (None)."""
    requested = recipe
    notes = []
    no_mips = "not asked for (--no-mips)"
    box = containers.get(container)
    if not box.mips and recipe.mips.enabled:
        recipe = recipe.replace(mips=False)
        no_mips = f"a {box.title} file holds one level"
        notes.append(no_mips + ": no mips were built")
    path = header.path
    has_alpha = header.alpha != "none"
    src = recipe.source
    if src.alpha_cutoff is not None and not has_alpha:
        raise UsageError("--alpha-cutoff needs a source with an alpha channel", path)
    name, layout_swizzle = resolve_format(header, recipe, container)
    codec = recipe.codec.codec(name)
    check_normal_layout(codec, recipe.output.normal_layout, path)  # the format resolved from the source
    if recipe.codec.format is None:  # the format resolved from the source must fit the container too
        box.check_format(name, recipe.output.colour_space == "srgb", path)

    pixel_checks = []
    srgb, reason, to_light = colour if colour is not None else colour_choice(header, recipe, codec, pixels=False)
    if srgb is None:
        pixel_checks.append(f"colour space: auto, {_AUTO_RULE}")
        # either way auto chooses, colour from an sRGB source is filtered in linear light
        decode = header.colour_space == "srgb"
    else:
        decode = decodes(srgb, to_light, "linear" if src.data else header.colour_space)
    if dropped is None:
        pixel_checks += _drop_checks(header, recipe, codec)
    else:
        notes += dropped
    if hdr_blocks(codec) and not header.is_float:
        notes.append(f"{codec.name} is an HDR format: the 8-bit source is stored as half floats in 0..1"
                     + (", its sRGB colour decoded to linear light" if decode else "")
                     + "; an 8-bit format holds it in as many bits or fewer")
    options = codec_options(codec, recipe, container, srgb)  # srgb None: auto, not yet decided

    steps = []
    if srgb is None and decode:
        steps.append(("decode", True, "sRGB colour: filtered in linear light whichever encoding auto chooses"))
    elif decode:
        steps.append(("decode", True, f"{codec.name} holds linear light: converted to it" if hdr_blocks(codec)
                      else "colour stored linear by the auto rule: converted to linear light"
                      if to_light else "sRGB source, sRGB output: filtered in linear light"))
    elif src.data:
        steps.append(("decode", False, "the source holds linear data, kept as it is"
                      + (": stored through the sRGB curve, which the sampler's decode undoes" if srgb else "")))
    else:
        steps.append(("decode", False, "the source is linear" if header.colour_space != "srgb"
                      else "linear output: the values are data, kept as they are"))
    steps.append(("srgb", bool(srgb), _colour_why(recipe, codec, srgb, reason)))
    count = max_levels(header.width, header.height) if recipe.mips.enabled else 1
    chain, mip_steps = _mip_steps(header, recipe, has_alpha, no_mips, count)
    steps += mip_steps
    limit = _range_limit(codec.format)
    if limit is not None:
        steps.append(("range", True, f"values beyond +-{limit:g} {'clamped' if src.clamp else 'refused'}, "
                                     "on every level (filters can overshoot)"))
    else:
        steps.append(("range", False, f"{name} holds every value the chain gives" if codec.format.is_float
                      else "values are quantised into the format's range"))
    kinds = [n for n, _ in recipe.transform.steps]
    if codec.format.transform:
        kinds.append(f"{codec.format.transform} (by the {codec.name} codec)")
    steps.append(("transform", True, ", ".join(kinds)) if kinds else ("transform", False, "none asked for"))
    zstd = recipe.output.zstd
    steps.append(_rdo_step(recipe, name, box, notes, path))
    steps.append(("zstd", True, f"level {zstd}") if zstd is not None else ("zstd", False, "not asked for"))
    steps.append(("sat", True, f"written to {sat}") if sat is not None else ("sat", False, "not asked for"))

    kv = []
    if kinds:
        kv.append((transforms.KV_KEY, None))
    if reason is not None or (srgb is None and recipe.output.colour_space == "auto"):
        kv.append((COLOUR_KEY, None if srgb is None else json.dumps(
            {"chosen": "srgb" if srgb else "linear", "reason": reason, "source": header.colour_space,
             "to_light": to_light}, sort_keys=True)))
    elif src.data and srgb:  # texcook's reader gives back the data, not its sRGB encoding
        kv.append((COLOUR_KEY, json.dumps({"chosen": "srgb", "reason": "linear data stored through the sRGB curve",
                                           "source": "linear", "to_light": False}, sort_keys=True)))
    if src.normal_map:
        kv.append((CONTENT_KEY, "normal"))
    if src.alpha_cutoff is not None:
        kv.append((ALPHA_CUTOFF_KEY, repr(float(src.alpha_cutoff))))
    swizzle = layout_swizzle
    if options.get("normal_map") and codec.normal_swizzle and options.get("normal_layout") != "xyz":
        swizzle = codec.normal_swizzle
    if swizzle:
        kv.append((keys.SWIZZLE.name, swizzle))

    levels = tuple(level_dims(header.width, header.height, i) for i in range(count))
    rebuild_z = src.normal_map and header.channels == 2
    # Without transform steps, a grey+alpha layout or a float format's range
    # check (these see every level at once), levels stream (pipeline.bake).
    stream = not recipe.transform.steps and layout_swizzle != "rrrg" and not codec.float_input
    from_stored = stream and not header.is_float and srgb is not None and decode == srgb and not rebuild_z
    return BakePlan(
        source=header, recipe=recipe, container=container, output=None if output is None else str(output),
        format=name, preset=recipe.codec.preset, codec_options=tuple(sorted(options.items())),
        srgb=srgb, colour_reason=reason, to_light=to_light, decode=decode, layout_swizzle=layout_swizzle,
        levels=levels, chain=chain, rebuild_z=rebuild_z, stream=stream, level0_from_stored=from_stored,
        range_limit=limit,
        kv=tuple(kv), notes=tuple(notes), steps=tuple(steps), pixel_checks=tuple(pixel_checks),
        settled=dropped is not None,
        sat=None if sat is None else str(sat), requested=requested,
    )
