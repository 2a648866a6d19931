"""One texture, source to file: read -> linear float -> mip chain -> transforms
-> encode each level -> container -> atomic write.

A Recipe (texcook.recipe) says which optional steps run and with what settings.
Only the steps a recipe names run: no mips when its mips are off, no coverage
search without an alpha cutoff, no sRGB conversion for data textures, no
transform unless one is asked for. The recipe is validated, against the output
container too, before any pixel is read.
"""

import json
import os
import time
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from . import __version__, _beside, codecs, formats, transforms
from ._threads import cpu_threads
from .colour import (
    StoredRGBA, _quantize_rows, auto_colour_space, decode_colour, encode_colour, linear_to_srgb, quantize,
    quantize_unorm8, rgba8_from_stored, to_linear_rgba,
)
from ._jit import cached, encoder_first_use, loading_beside as numba_loading_beside
from .errors import ContainerError, InputError, OutputError, TexcookError, UsageError
from .fileio import atomic_write_all, read_bytes, refuse_same_file
from .image import Image, read_image
from .recipe import Recipe, check_normal_layout

SAT_SUFFIX = ".sat.ktx2"
COLOUR_KEY = "texcook.colour_space"  # what --colour-space auto chose and why
CONTENT_KEY = "texcook.content"  # "normal" for a bake with --normal-map
ALPHA_CUTOFF_KEY = "texcook.alphaCutoff"  # a cut-out's alpha-test cutoff, for viewers
STAGES = ("read", "colour", "mips", "transform", "encode", "container", "write")


@contextmanager
def _stage(timings, name):
    """Add the seconds spent in the block to timings[name] (when asked for)."""
    if timings is None:
        yield
        return
    start = time.perf_counter()
    try:
        yield
    finally:
        timings[name] = timings.get(name, 0.0) + time.perf_counter() - start


@dataclass
class Baked:
    """Encoded levels, ready for a container."""

    codec: object
    srgb: bool
    width: int
    height: int
    levels: list  # bytes per level, base first
    kv: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)  # what a user should know (dropped channels)
    colour_reason: str | None = None  # why --colour-space auto chose what it did
    clamped: int = 0  # values clamped to the format's range (source.clamp)

    @property
    def vk_format(self):
        return self.codec.vk_format(self.srgb)


def _to_rgba(px, normal_map):
    """(H, W, C) -> (H, W, 4) the way a sampler sees the source: grey replicates,
    missing alpha is opaque. A two-channel normal map is X, Y with Z rebuilt."""
    h, w, c = px.shape
    out = np.empty((h, w, 4), np.float32)
    out[..., 3] = 1.0
    if normal_map and c == 2:
        out[..., :2] = px
        # X or Y beyond +-1 leaves no room for Z either way; clipped first, the squares cannot overflow
        xy = np.clip(px, 0.0, 1.0) * 2.0 - 1.0
        out[..., 2] = np.sqrt(np.clip(1.0 - np.sum(xy * xy, axis=-1), 0.0, 1.0)) * 0.5 + 0.5
    elif c <= 2:
        out[..., :3] = px[..., :1]
        if c == 2:
            out[..., 3] = px[..., 1]
    else:
        out[..., :c] = px
    return out


def _check_finite(image, recipe):
    px = image.pixels
    bad = ~np.isfinite(px)
    if not bad.any():
        return px
    if not recipe.source.nan_to_zero:
        n = int(bad.sum())
        raise InputError(f"{n} NaN or Inf value(s) in the pixels; use --nan-to-zero to replace them with 0", image.path)
    return np.where(bad, np.float32(0.0), px)


# Without --format an uncompressed output keeps the source's channels; a grey
# KTX2 texture says with KTXswizzle how a loader spreads its channels.
_GREY_LAYOUT = {1: ("r8", "rrr1"), 2: ("rg8", "rrrg")}


def resolve_format(image: Image, recipe: Recipe, container="ktx2"):
    """(format name, KTXswizzle or None) of the output."""
    if recipe.codec.format is not None:
        return recipe.codec.format, None
    if image.is_float:
        return "rgba16f", None
    if container == "ktx2" and not recipe.source.normal_map and image.channels in _GREY_LAYOUT:
        # R8G8_SRGB would sRGB-encode the alpha kept in green: sRGB grey+alpha stays RGBA
        srgb = recipe.output.colour_space == "srgb" or (
            recipe.output.colour_space is None and image.colour_space == "srgb")
        # "auto" may choose sRGB: keep RGBA then too
        if image.channels == 1 or (not srgb and recipe.output.colour_space != "auto"):
            return _GREY_LAYOUT[image.channels]
    layout = recipe.output.normal_layout
    if recipe.source.normal_map and (layout == "xy" or (layout is None and image.channels == 2)):
        return "rg8", None
    return "rgba8", None


def fit_range(levels, codec, clamp, path=None):
    """Values a float format cannot hold (beyond +-65504 for rgba16f, which
    would become Inf) are refused with their count, or clamped to the largest
    finite value with `clamp`. Checked on every level: Lanczos and Kaiser mips
    can overshoot the source. Returns (levels, number clamped)."""
    fmt = formats.get(codec.name)
    if not fmt.is_float or np.dtype(fmt.sample).itemsize >= 4:  # float32 holds every float32 value
        return levels, 0
    dtype = np.dtype(fmt.sample)
    top = np.float32(np.finfo(dtype).max)
    over = sum(int(np.count_nonzero(np.abs(lv) > top)) for lv in levels)
    if not over:
        return levels, 0
    if not clamp:
        raise InputError(f"{over} value(s) beyond the {codec.name} range (+-{float(top):g}); "
                         "use --clamp to clamp them, or a 32-bit float format", path)
    return [np.clip(lv, -top, top) for lv in levels], over


def output_srgb(image, recipe, codec):
    """The colour encoding of the output: an explicit colour space wins; otherwise
    sRGB when the source is sRGB colour and the format has an sRGB variant."""
    space = recipe.output.colour_space
    if space == "auto":
        return colour_choice(image, recipe, codec)[0]
    if space is not None:
        if space == "srgb":
            codec.vk_format(True)  # raises when there is no sRGB variant
        return space == "srgb"
    return (image.colour_space == "srgb" and bool(codec.vk_srgb) and not recipe.source.normal_map
            and not codec.float_input)


def colour_choice(image, recipe, codec):
    """(srgb, reason, to_light) of the output. reason is None unless the recipe
    asks for "auto"; to_light: the rule chose linear storage for an sRGB-encoded
    colour source, whose texels are then converted to linear light (colour,
    not data kept as it is)."""
    if recipe.output.colour_space != "auto":
        return output_srgb(image, recipe, codec), None, False
    if recipe.source.normal_map:
        return False, "a normal map holds vectors", False
    if not codec.vk_srgb or codec.float_input:
        return False, f"{codec.name} has no sRGB variant", False
    colour = [c for c in range(image.channels) if c != image.alpha_channel]
    values = _check_finite(image, recipe)[..., colour]
    if image.colour_space != "srgb":
        values = linear_to_srgb(np.clip(values, 0.0, 1.0))
    chosen, share = auto_colour_space(values)
    reason = f"{100 * share:.1f}% of the colour values are above 116/255; linear from 75%"
    return chosen == "srgb", reason, chosen == "linear" and image.colour_space == "srgb"


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


def build_levels(image: Image, recipe: Recipe, srgb_out=False, to_light=False, timings=None, threads=None):
    """iter_levels as a list."""
    return list(iter_levels(image, recipe, srgb_out, to_light, timings, threads))


def iter_levels(image: Image, recipe: Recipe, srgb_out=False, to_light=False, timings=None, threads=None,
                stored_level0=False):
    """Float32 RGBA levels, base first, as the recipe asks, in linear light when
    the output is sRGB, one at a time: each is built from the one before when
    it is asked for (checks run before this returns). An sRGB-encoded source is
    decoded to linear light only for sRGB output: baked to a linear format
    (bc4, bc5, --linear) its values are data (masks, heights, vectors) and are
    kept as they are, unless `to_light` (colour stored linear by the auto
    colour-space rule).

    `stored_level0`, for a caller that quantises level 0 from the source's
    stored integers: level 0 of such a source comes as a colour.StoredRGBA,
    and level 1 is filtered from it without a float copy of level 0."""
    has_alpha = image.alpha != "none"
    src, mips = recipe.source, recipe.mips
    if src.alpha_cutoff is not None and not has_alpha:
        raise UsageError("--alpha-cutoff needs a source with an alpha channel", image.path)
    decode = (srgb_out or to_light) and image.colour_space == "srgb"
    unit = False  # every value finite and in [0, 1]: the chain need not look
    if src.normal_map and image.channels == 2:
        # Z is rebuilt from X and Y
        px = _check_finite(image, recipe)
        with _stage(timings, "colour"):
            rgba = _to_rgba(decode_colour(px, decode, image.alpha_channel), True)
    else:
        # stored integers go through the tables; no float copy of the source is made
        values = image.stored if image.stored is not None else _check_finite(image, recipe)
        unit = values.dtype in (np.uint8, np.uint16)
        with _stage(timings, "colour"):
            if unit and stored_level0:
                rgba = StoredRGBA(values, decode, image.alpha_channel)
            else:
                rgba = to_linear_rgba(values, decode, image.alpha_channel, threads)
    if not mips.enabled:
        return iter([rgba])
    from .mips import iter_chain

    extra = {}
    if mips.kaiser_width is not None:
        extra["kaiser_width"] = mips.kaiser_width
    if mips.kaiser_alpha is not None:
        extra["kaiser_alpha"] = mips.kaiser_alpha
    with _stage(timings, "mips"):
        chain = iter_chain(
            rgba,
            filter=mips.filter,
            wrap=mips.wrap,
            lanczos_a=mips.lanczos_a,
            premultiply=mips.premultiply and has_alpha,
            alpha_channel=3 if has_alpha else None,
            alpha_cutoff=src.alpha_cutoff,
            normal_map=src.normal_map,
            ldr=not image.is_float,
            threads=threads,
            unit_range=unit,
            **extra,
        )
    return chain if timings is None else _timed(chain, timings, "mips")


def _timed(levels, timings, name):
    """The levels of an iterator, the time spent making each added to timings[name]."""
    while True:
        with _stage(timings, name):
            level = next(levels, None)
        if level is None:
            return
        yield level
        level = None


def codec_options(codec, recipe, container, srgb=False):
    """The options the codec gets: the recipe's, then defaults that follow from
    the container and the source's use, for the options the codec declares."""
    declared = {o.name for o in codec.options}
    options = dict(recipe.codec.options)
    if container == "dds":
        from .container.dds import CODEC_OPTION_DEFAULTS

        for name, value in CODEC_OPTION_DEFAULTS.items():
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


def bake(image: Image, recipe: Recipe = Recipe(), container="ktx2", threads=None, timings=None) -> Baked:
    """Mip chain, transforms and encoding of one image; no file is touched.
    `container` ("ktx2" or "dds") matters where a reader of that container
    decodes differently. `timings`, a dict, collects seconds per stage."""
    recipe.check_container(container)
    name, ktx_swizzle = resolve_format(image, recipe, container)
    codec = recipe.codec.codec(name)
    check_normal_layout(codec, recipe.output.normal_layout, image.path)  # the format resolved from the source
    if container == "dds":
        recipe.replace(format=name).check_container(container, image.path)
    srgb, colour_reason, to_light = colour_choice(image, recipe, codec)
    options = codec_options(codec, recipe, container, srgb)
    notes = dropped_channels(image, recipe, codec)
    decoded = (srgb or to_light) and image.colour_space == "srgb"  # as iter_levels decodes
    # Without transform steps, a grey+alpha layout or a float format's range
    # check (these see every level at once), levels stream: each is quantised as
    # soon as it is built and encoded once the next one is built, when the float
    # level before it has been dropped, so at most two float levels are alive.
    # Level 0 of a source of stored integers is quantised from them (an 8-bit
    # source's are its stored values) and encoded first, then level 1 is
    # filtered from them: no float level 0 is made. On a cold kernel cache a
    # helper process compiles the chain's kernels while this one compiles the
    # codec's for level 0.
    plain = not recipe.transform.steps and ktx_swizzle != "rrrg" and not codec.float_input
    stored0 = (plain and image.stored is not None and decoded == srgb
               and not (recipe.source.normal_map and image.channels == 2))
    levels = iter_levels(image, recipe, srgb, to_light, timings, threads, stored_level0=stored0)
    with encoder_first_use(codec), _chain_compiled_beside(image, recipe, srgb, to_light, codec, threads, stored0):
        encoded = []

        def encode(px):
            with _stage(timings, "encode"):
                encoded.append(codec.encode(px, recipe.codec.preset, threads, **options))

        if stored0:
            with _stage(timings, "colour"):
                px = rgba8_from_stored(image.stored, srgb, image.alpha_channel, threads)
            encode(px)
            px = None
            next(levels)  # level 0, as stored: encoded
        clamped, kv = 0, {}
        if not plain:
            levels, clamped = fit_range(list(levels), codec, recipe.source.clamp, image.path)
            with _stage(timings, "transform"):
                levels, kv = transforms.forward(levels, recipe.transform, notes)
                if ktx_swizzle == "rrrg":
                    levels = [_store_grey_alpha(level) for level in levels]
        pending = None
        for level in levels:
            with _stage(timings, "colour"):
                if codec.float_input:
                    px = np.ascontiguousarray(encode_colour(level, srgb, 3), np.float32)
                else:
                    px = quantize(level, srgb, threads)
            level = None
            if pending is not None:
                encode(pending)
            pending, px = px, None
        if pending is not None:
            encode(pending)
    if codec.format.transform:
        # the codec ran the format's transform: recorded so readers undo it
        # (its RGB keeps the source's encoding: no sRGB variant, so nothing was decoded)
        kv = transforms.record_format_step(kv, codec.format.transform, rgb=image.colour_space)
    if colour_reason is not None:
        kv[COLOUR_KEY] = json.dumps({"chosen": "srgb" if srgb else "linear", "reason": colour_reason,
                                     "source": image.colour_space, "to_light": to_light}, sort_keys=True)
    if recipe.source.normal_map:
        kv[CONTENT_KEY] = "normal"
    if recipe.source.alpha_cutoff is not None:
        kv[ALPHA_CUTOFF_KEY] = repr(float(recipe.source.alpha_cutoff))
    if options.get("normal_map") and codec.normal_swizzle and options.get("normal_layout") != "xyz":
        ktx_swizzle = codec.normal_swizzle
    if ktx_swizzle:
        kv["KTXswizzle"] = ktx_swizzle
    return Baked(codec, srgb, image.width, image.height, encoded, kv, notes, colour_reason, clamped)


@contextmanager
def _chain_compiled_beside(image, recipe, srgb, to_light, codec, threads, stored0):
    """While the block runs, a helper process compiles the kernels of the
    chain bake() builds after level 0 of a source of stored integers
    (texcook._beside), when they are not in the kernel cache and the codec has
    block kernels to compile first, on a machine with a core to spare: a cold
    256x256 bc1 or etc1 bake takes about 1.5 s less. Yields the helper (None
    when none was started); it is stopped when the block ends."""
    helper = None
    if (stored0 and recipe.mips.enabled and codec.format.block_w * codec.format.block_h > 1
            and cpu_threads(threads) >= 2
            and cached(_quantize_rows) is False):  # every such chain quantises its levels with it
        helper = _beside.start(compile_chain, _sample(image), recipe, srgb, to_light)
    try:
        yield helper
    finally:
        _beside.stop(helper)


def _sample(image):
    """A small corner of a source of stored integers whose chain takes the
    same kernels as the whole one's."""

    def size(n):
        # the same remainder modulo 32: the first five levels have the same
        # parities, so they take the same (box or separable) kernels
        return n if n <= 64 else 32 + n % 32

    sample = np.ascontiguousarray(image.stored[:size(image.height), :size(image.width)])
    return Image(None, image.colour_space, image.alpha, image.source_dtype, stored=sample)


def compile_chain(image, recipe, srgb, to_light):
    """The levels after level 0 that bake() quantises for a source of stored
    integers, made and dropped: what _chain_compiled_beside's helper runs."""
    levels = iter_levels(image, recipe, srgb, to_light, threads=1, stored_level0=True)
    next(levels)
    for level in levels:
        quantize(level, srgb, 1)


def _store_grey_alpha(level):
    """Grey in red and alpha in green, for a two-channel grey+alpha output."""
    out = level.copy()
    out[..., 1] = level[..., 3]
    return out


TEXTURE_EXTENSIONS = (".ktx2", ".dds", ".astc")


def container_of(path):
    """"ktx2", "dds" or "astc" from an output's extension, or UsageError."""
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext not in TEXTURE_EXTENSIONS:
        raise UsageError(f"output must end in .ktx2, .dds or .astc, not {ext or 'no extension'!r}", path)
    return ext[1:]


def container_bytes(baked: Baked, container, recipe: Recipe) -> bytes:
    """The file's bytes in the container ("ktx2", "dds" or "astc": level 0 only)."""
    if container == "astc":
        from .container.astcfile import write_astc

        return write_astc(baked.codec.block_w, baked.codec.block_h, baked.width, baked.height, baked.levels[0])
    if container == "dds":
        from .container.dds import write_dds

        return write_dds(baked.codec.name, baked.width, baked.height, baked.levels, baked.srgb,
                         dx10=recipe.output.dds_dx10)
    from .container.ktx2 import write_ktx2

    kv = dict(baked.kv)
    kv["KTXwriter"] = f"texcook {__version__}"
    return write_ktx2(baked.vk_format, baked.width, baked.height, baked.levels, kv=kv,
                      zstd_level=recipe.output.zstd)


def sat_path_for(dst, recipe: Recipe, sat_path=None):
    """Where the summed-area table goes: the given path, or beside the output
    when the recipe asks for one; None when there is none. Checked before work."""
    if sat_path is None and not recipe.output.sat:
        return None
    if sat_path is None:
        sat_path = os.path.splitext(os.fspath(dst))[0] + SAT_SUFFIX
    sat_path = os.fspath(sat_path)
    if not sat_path.lower().endswith(".ktx2"):
        raise UsageError("the summed-area table is written as .ktx2", sat_path)
    if os.path.abspath(sat_path) == os.path.abspath(os.fspath(dst)):
        raise UsageError("the summed-area table cannot be written over the texture itself", sat_path)
    folder = os.path.dirname(os.path.abspath(sat_path))
    if not os.path.isdir(folder):
        raise OutputError("output directory does not exist", sat_path)
    return sat_path


def bake_file(src, dst, recipe: Recipe = Recipe(), sat_path=None, threads=None, timings=None) -> dict:
    """Read `src`, bake, write `dst` (and its summed-area table, when the recipe
    asks for one or `sat_path` is given). Everything is checked before the image
    is read, and nothing is written unless every output succeeded. Returns a
    summary; `timings`, a dict, collects seconds per stage (STAGES)."""
    container = container_of(dst)
    recipe.check_container(container, dst)
    notes = []
    if container == "astc" and recipe.mips.enabled:
        recipe = recipe.replace(mips=False)  # an .astc file holds one image
        notes.append("a .astc file holds one level: no mips were built")
    sat_path = sat_path_for(dst, recipe, sat_path)
    for out in (dst, sat_path):
        if out is not None:
            refuse_same_file(src, out)
    folder = os.path.dirname(os.path.abspath(os.fspath(dst)))
    if not os.path.isdir(folder):
        raise OutputError("output directory does not exist", dst)
    with numba_loading_beside():
        with _stage(timings, "read"):
            image = read_image(src)
        baked = bake(image, recipe, container, threads, timings)
    with _stage(timings, "container"):
        try:
            outputs = [(dst, container_bytes(baked, container, recipe))]
        except TexcookError as exc:
            raise exc.naming(dst) from None
        if sat_path is not None:
            outputs.append((sat_path, sat_bytes(image, recipe)))
    with _stage(timings, "write"):
        atomic_write_all(outputs)
    summary = {
        "input": os.fspath(src),
        "output": os.fspath(dst),
        "format": baked.codec.name,
        "vk_format": baked.vk_format,
        "colour_space": "srgb" if baked.srgb else "linear",
        "width": baked.width,
        "height": baked.height,
        "levels": len(baked.levels),
        "bytes": len(outputs[0][1]),
        "notes": notes + baked.notes,
        "clamped": baked.clamped,
    }
    if container == "astc":  # the values are encoded as colour_space says; the file cannot say so
        summary["colour_space_recorded"] = False
    if baked.colour_reason is not None:
        summary["colour_space_reason"] = "auto: " + baked.colour_reason
    if sat_path is not None:
        summary["sat"] = sat_path
    return summary


def sat_bytes(image: Image, recipe: Recipe) -> bytes:
    """A summed-area table of the source's stored values as KTX2."""
    from .container.ktx2 import write_ktx2
    from .sat import SummedAreaTable

    if image.is_float:
        values = _check_finite(image, recipe)
    else:
        values = image.integer_values()
    table = SummedAreaTable.build(values)
    try:
        vk, levels, kv = table.to_ktx2()
    except InputError as exc:
        raise exc.naming(image.path) from None
    kv = dict(kv)
    kv["KTXwriter"] = f"texcook {__version__}"
    return write_ktx2(vk, image.width, image.height, levels, kv=kv, zstd_level=recipe.output.zstd)


# --- reading back --------------------------------------------------------------------


@dataclass
class Decoded:
    """Levels of a texture or image as RGBA arrays in their stored encoding:
    uint8 for 8-bit and block formats, float32 for float formats and where the
    restored values fall between 8-bit codes (renormalised textures, colour
    that --colour-space auto stored in linear light, read back as sRGB)."""

    levels: list
    channels: int  # channels that carry data (1..4)
    srgb: bool
    source: str
    normal_map: bool = False  # the file says it holds a tangent-space normal map (X, Y in R, G)


def load_texture(path) -> Decoded:
    """Any image, KTX2 or DDS file as decoded levels. A KTX2 file's KTXswizzle
    and recorded transforms are applied, so a texture reads in its source's
    units."""
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext not in TEXTURE_EXTENSIONS:
        image = read_image(path)
        px = _to_rgba(image.pixels, False)
        if image.source_dtype == "uint8":
            px = np.rint(px * 255.0).astype(np.uint8)
        channels = {1: 3, 2: 4, 3: 3, 4: 4}[image.channels]
        return Decoded([px], channels, image.colour_space == "srgb", path)
    data = read_bytes(path, "texture")
    swizzle, steps, to_light, normal_map = None, None, False, False
    if ext == ".ktx2":
        from .container.ktx2 import read_ktx2

        ktx = read_ktx2(data, path)
        codec, srgb = codecs.by_vk_format(ktx.vk_format)
        if codec is None:
            raise InputError(f"vkFormat {ktx.vk_format} has no decoder here", path)
        width, height, raw = ktx.width, ktx.height, ktx.levels
        swizzle, steps = ktx.text("KTXswizzle"), ktx.text(transforms.KV_KEY)
        to_light = _stored_as_light(ktx.text(COLOUR_KEY), path)
        normal_map = ktx.text(CONTENT_KEY) == "normal"
    elif ext == ".astc":
        from .container.astcfile import read_astc

        astc = read_astc(data, path)
        # the file says nothing of colour space: decoded as UNORM, as astcenc does by default
        codec, width, height, raw, srgb = codecs.get(astc.format_name), astc.width, astc.height, [astc.data], False
    else:
        from .container.dds import read_dds

        name, width, height, raw, srgb = read_dds(data, path)
        codec = codecs.get(name)
    from .container.levels import level_dims

    extra = {"srgb": srgb} if codec.srgb_decode else {}
    levels = [codec.decode(level, *level_dims(width, height, i), **extra) for i, level in enumerate(raw)]
    channels = codec.channels
    if swizzle is not None and swizzle != "rgba":
        if len(swizzle) != 4 or any(c not in "rgba01" for c in swizzle):
            raise InputError(f"KTXswizzle {swizzle!r} is not four of r, g, b, a, 0, 1", path)
        levels = transforms.swizzle(levels, swizzle)
        # up to the last channel that reads stored data: rrr1 -> 3, rrrg -> 4, ra01 -> 2
        channels = max(i for i, c in enumerate(swizzle) if c not in "01") + 1
    if steps is not None:
        levels = _undo_transforms(levels, steps, srgb, path)
        channels = transforms.channels_after(steps, channels, path)
        srgb = srgb or transforms.rgb_encoding(steps, path) == "srgb"
    if to_light and not srgb:
        # colour the auto rule stored in linear light reads in its source's sRGB
        # encoding, as float: the encoded values fall between 8-bit codes
        levels = [encode_colour(_unit(px).astype(np.float32), True, 3) for px in levels]
        srgb = True
    return Decoded(levels, channels, srgb, path, normal_map)


def _stored_as_light(text, path):
    """True when the file's colour-space record says an sRGB source was stored in linear light."""
    if text is None:
        return False
    try:
        record = json.loads(text)
        return bool(record["to_light"]) and record["source"] == "srgb"
    except (ValueError, KeyError, TypeError):
        raise ContainerError(f"bad {COLOUR_KEY} value", path) from None


def _undo_transforms(levels, steps, srgb, path):
    """Recorded transforms undone in linear light, where they were applied,
    then back to the stored encoding: as float32 when the steps give values
    between 8-bit codes (a renormalisation's rescaled values)."""
    keep_float = transforms.fractional(steps, path)
    out = []
    for px in levels:
        f = px.astype(np.float32)
        if px.dtype == np.uint8:
            f /= 255.0
        out.append(decode_colour(f, srgb, 3))
    out = transforms.inverse(out, steps, path)
    res = []
    for px, orig in zip(out, levels):
        px = encode_colour(px, srgb, 3)
        if orig.dtype != np.uint8:
            res.append(px.astype(orig.dtype))
        else:
            # a UNORM texture's values stay within 0..1, as when they are quantised
            res.append(np.clip(px, 0.0, 1.0).astype(np.float32) if keep_float else quantize_unorm8(px))
    return res


def compare(a, b, level=None, normal_map=False):
    """PSNR between two images or textures, per level and channel, on values in
    0..1 (8-bit data scaled by 1/255). Compared channels: those both carry.
    When either file says it is a normal map (a bake with --normal-map), or
    normal_map is set, also the angle between the normals (X, Y in R, G, Z
    rebuilt) in degrees: mean, 99th percentile and largest, per level and over
    all compared levels."""
    from . import metrics

    da, db = load_texture(a), load_texture(b)
    normal_map = normal_map or da.normal_map or db.normal_map
    n = min(da.channels, db.channels)
    if normal_map and n < 2:
        raise UsageError("one channel: a normal map comparison needs X and Y", a if da.channels < 2 else b)
    chans = list(range(n))
    count = min(len(da.levels), len(db.levels))
    indices = range(count) if level is None else [level]
    if level is not None and not (0 <= level < count):
        raise UsageError(f"level {level} does not exist in both (they share {count})")
    rows = []
    angles = []
    total_se, total_n = 0.0, 0
    for i in indices:
        la, lb = _unit(da.levels[i]), _unit(db.levels[i])
        if la.shape != lb.shape:
            raise UsageError(
                f"level {i} sizes differ: {la.shape[1]}x{la.shape[0]} here, {lb.shape[1]}x{lb.shape[0]} in {b}", a
            )
        row, se_sum, se_n = metrics.compare_level(la, lb, chans)
        total_se += se_sum
        total_n += se_n
        rows.append({"level": i, "width": la.shape[1], "height": la.shape[0], **row})
        if normal_map:
            angles.append(metrics.normal_angular_errors(la, lb))
            rows[-1]["angular"] = metrics.angle_summary(angles[-1])
    overall = metrics.psnr_from_mse(total_se / total_n, 1.0) if total_n else float("inf")
    result = {"a": os.fspath(a), "b": os.fspath(b), "channels": "RGBA"[:n], "psnr": overall, "levels": rows}
    if normal_map:
        result["normal_map"] = True
        result["angular"] = metrics.angle_summary(np.concatenate(angles))
    return result


def _unit(px):
    px = np.asarray(px)
    if px.dtype == np.uint8:
        return px.astype(np.float64) / 255.0
    return px.astype(np.float64)
