"""One texture, source to file: read -> linear float -> mip chain -> transforms
-> encode each level -> container -> atomic write.

A Recipe (texcook.recipe) says which optional steps run and with what settings;
a BakePlan (texcook.plan) holds every decision of one bake, made from the
image's header before any pixel is read. This module executes plans: it
decides nothing a plan says. Only the steps a plan runs run: no mips when the
recipe's mips are off, no coverage search without an alpha cutoff, no sRGB
conversion for data textures, no transform unless one is asked for.
"""

import json
import os
import time
from contextlib import contextmanager
from dataclasses import dataclass, field, replace

import numpy as np

from . import _beside, codecs, formats, transforms
from ._threads import cpu_threads
from .colour import (
    StoredRGBA, decode_colour, encode_colour, quantize, quantize_kernels_cached, quantize_unorm8, rgba8_from_stored,
    to_linear_rgba, to_rgba,
)
from ._jit import encoder_first_use, loading_beside as numba_loading_beside
from .container import ktx2_keys as keys, table as containers
from .errors import ContainerError, InputError, OutputError, TexcookError, UsageError
from .fileio import atomic_write_all, read_bytes, refuse_same_file
from .image import Image, finite_pixels, header_of, read_image
# the decisions (and the keys they write) are the planner's; named here too as
# this module's API was before plans
from .plan import (  # noqa: F401
    ALPHA_CUTOFF_KEY, COLOUR_KEY, CONTENT_KEY, BakePlan, colour_choice, output_srgb, plan_bake, settle,
)
from .recipe import Recipe

SAT_CONTAINER = containers.get("ktx2")  # a summed-area table is written as KTX2
SAT_SUFFIX = ".sat" + SAT_CONTAINER.extension
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


def fit_range(levels, plan, path=None):
    """Values beyond the plan's range limit (a float format's largest finite
    value: +-65504 for rgba16f, beyond which they would become Inf) are
    refused with their count, or clamped to it with the recipe's clamp.
    Checked on every level: Lanczos and Kaiser mips can overshoot the source.
    Returns (levels, number clamped)."""
    if plan.range_limit is None:
        return levels, 0
    top = np.float32(plan.range_limit)
    over = sum(int(np.count_nonzero(np.abs(lv) > top)) for lv in levels)
    if not over:
        return levels, 0
    if not plan.recipe.source.clamp:
        raise InputError(f"{over} value(s) beyond the {plan.format} range (+-{float(top):g}); "
                         "use --clamp to clamp them, or a 32-bit float format", path)
    return [np.clip(lv, -top, top) for lv in levels], over


def negatives_clamped(levels, codec):
    """A note counting the negative values an unsigned float format (BC6H
    UFLOAT) clamps to 0: in the source, or from a mip filter's overshoot."""
    if not codec.format.unsigned_float:
        return []
    n = sum(int(np.count_nonzero(lv[..., :3] < 0)) for lv in levels)
    return [f"{n} negative value(s) clamped to 0: {codec.name} is unsigned (bc6h-sf keeps the sign)"] if n else []


def _plan_of(image, plan, container=containers.DEFAULT):
    """The settled plan of baking `image`: `plan` itself, or the plan of the
    recipe `plan` is."""
    if not isinstance(plan, BakePlan):
        plan = plan_bake(image, plan, container=container)
    return settle(plan, image)


def build_levels(image: Image, plan, timings=None, threads=None):
    """iter_levels as a list; `plan` a BakePlan or a Recipe."""
    return list(iter_levels(image, plan, timings, threads))


def iter_levels(image: Image, plan, timings=None, threads=None, stored_level0=False):
    """Float32 RGBA levels, base first, as the plan says (`plan` a BakePlan,
    or a Recipe to plan from), one at a time: each is built from the one
    before when it is asked for (checks run before this returns). An
    sRGB-encoded source is decoded to linear light when the plan's `decode`
    says so (texcook.plan.decodes).

    `stored_level0`, for a caller that quantises level 0 from the source's
    stored integers: level 0 of such a source comes as a colour.StoredRGBA,
    and level 1 is filtered from it without a float copy of level 0."""
    plan = _plan_of(image, plan)
    decode, nan_to_zero = plan.decode, plan.recipe.source.nan_to_zero
    unit = False  # every value finite and in [0, 1]: the chain need not look
    if plan.rebuild_z:
        px = finite_pixels(image, nan_to_zero)
        with _stage(timings, "colour"):
            rgba = to_rgba(decode_colour(px, decode, image.alpha_channel), True)
    else:
        # stored integers go through the tables; no float copy of the source is made
        values = image.stored if image.stored is not None else finite_pixels(image, nan_to_zero)
        unit = values.dtype in (np.uint8, np.uint16)
        with _stage(timings, "colour"):
            if unit and stored_level0:
                rgba = StoredRGBA(values, decode, image.alpha_channel)
            else:
                rgba = to_linear_rgba(values, decode, image.alpha_channel, threads)
    if not plan.chain:
        return iter([rgba])
    from .mips import iter_chain

    with _stage(timings, "mips"):
        chain = iter_chain(rgba, threads=threads, unit_range=unit, **dict(plan.chain))
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


def bake(image: Image, recipe=Recipe(), container=containers.DEFAULT, threads=None, timings=None) -> Baked:
    """Mip chain, transforms and encoding of one image; no file is touched.
    `recipe` is a BakePlan (texcook.plan), or a Recipe planned here for the
    `container` ("ktx2", "dds" or "astc"). `timings`, a dict, collects
    seconds per stage."""
    plan = _plan_of(image, recipe, container)
    recipe, codec, srgb = plan.recipe, plan.codec, plan.srgb
    options = plan.options
    notes = list(plan.notes)
    # A streaming plan's levels are quantised as soon as each is built and
    # encoded once the next one is built, when the float level before it has
    # been dropped, so at most two float levels are alive. Level 0 of a
    # source of stored integers is quantised from them (an 8-bit source's are
    # its stored values) and encoded first, then level 1 is filtered from
    # them: no float level 0 is made. On a cold kernel cache a helper process
    # compiles the chain's kernels while this one compiles the codec's for
    # level 0.
    stored0 = plan.level0_from_stored and image.stored is not None
    levels = iter_levels(image, plan, timings, threads, stored_level0=stored0)
    with encoder_first_use(codec), _chain_compiled_beside(image, plan, threads, stored0):
        encoded = []
        encode_level = codec.encoder(plan.preset, threads, **options)  # preset and options checked once
        rdo_lambda = recipe.codec.rdo if plan.step("rdo")[0] else 0.0
        if rdo_lambda:
            from . import rdo

        def encode(px):
            with _stage(timings, "encode"):
                data = encode_level(px)
                if rdo_lambda:  # after the level's blocks are settled, against the texels they encode
                    data = rdo.optimise(codec.name, data, px, rdo_lambda, options)
                encoded.append(data)

        if stored0:
            with _stage(timings, "colour"):
                px = rgba8_from_stored(image.stored, srgb, image.alpha_channel, threads)
            encode(px)
            px = None
            next(levels)  # level 0, as stored: encoded
        clamped, kv = 0, {}
        if not plan.stream:
            levels, clamped = fit_range(list(levels), plan, image.path)
            notes += negatives_clamped(levels, codec)
            with _stage(timings, "transform"):
                levels, kv = transforms.forward(levels, recipe.transform, notes)
                if plan.layout_swizzle == "rrrg":
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
    kv.update((k, v) for k, v in plan.kv if v is not None)  # the transform record is the stage's
    return Baked(codec, srgb, image.width, image.height, encoded, kv, notes, plan.colour_reason, clamped)


@contextmanager
def _chain_compiled_beside(image, plan, threads, stored0):
    """While the block runs, a helper process compiles the kernels of the
    chain bake() builds after level 0 of a source of stored integers
    (texcook._beside), when they are not in the kernel cache and the codec has
    block kernels to compile first, on a machine with a core to spare: a cold
    256x256 bc1 or etc1 bake takes about 1.5 s less. Yields the helper (None
    when none was started); it is stopped when the block ends."""
    helper = None
    fmt = plan.codec.format
    if (stored0 and plan.chain and fmt.block_w * fmt.block_h > 1
            and cpu_threads(threads) >= 2
            and quantize_kernels_cached() is False):  # every such chain quantises its levels with it
        sample = _sample(image)
        # the sample's own plan, settled by the bake's decisions: no pixel is looked at again
        helper = _beside.start(compile_chain, sample, replace(plan, source=header_of(sample)))
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


def compile_chain(image, plan):
    """The levels after level 0 that bake() quantises for a source of stored
    integers, made and dropped: what _chain_compiled_beside's helper runs."""
    levels = iter_levels(image, plan, threads=1, stored_level0=True)
    next(levels)
    for level in levels:
        quantize(level, plan.srgb, 1)


def _store_grey_alpha(level):
    """Grey in red and alpha in green, for a two-channel grey+alpha output."""
    out = level.copy()
    out[..., 1] = level[..., 3]
    return out


TEXTURE_EXTENSIONS = containers.EXTENSIONS


def container_of(path):
    """The name of an output's container (container.table) from its extension, or UsageError."""
    return containers.for_output(path).name


def container_bytes(baked: Baked, container, recipe: Recipe) -> bytes:
    """The file's bytes in the container (a name in container.table)."""
    stored = containers.Stored(baked.codec.name, baked.srgb, baked.width, baked.height, baked.levels, baked.kv)
    return containers.get(container).write(stored, recipe.output)


def sat_path_for(dst, recipe: Recipe, sat_path=None):
    """Where the summed-area table goes (see sat_path_of), its folder checked
    to exist before work."""
    sat_path = sat_path_of(dst, recipe, sat_path)
    if sat_path is not None and not os.path.isdir(os.path.dirname(os.path.abspath(sat_path))):
        raise OutputError("output directory does not exist", sat_path)
    return sat_path


def sat_path_of(dst, recipe: Recipe, sat_path=None):
    """Where the summed-area table goes: the given path, or beside the output
    when the recipe asks for one; None when there is none. Touches no file."""
    if sat_path is None and not recipe.output.sat:
        return None
    if sat_path is None:
        sat_path = os.path.splitext(os.fspath(dst))[0] + SAT_SUFFIX
    sat_path = os.fspath(sat_path)
    if containers.of_path(sat_path) is not SAT_CONTAINER:
        raise UsageError(f"the summed-area table is written as {SAT_CONTAINER.extension}", sat_path)
    if os.path.abspath(sat_path) == os.path.abspath(os.fspath(dst)):
        raise UsageError("the summed-area table cannot be written over the texture itself", sat_path)
    return sat_path


def plan_file(src, dst, recipe: Recipe = Recipe(), sat_path=None) -> BakePlan:
    """The plan of baking `src` into `dst` (and its summed-area table), from
    the source's header: every check that needs no pixel is made, no pixel is
    read, nothing is written."""
    container = container_of(dst)
    sat_path = sat_path_for(dst, recipe, sat_path)
    for out in (dst, sat_path):
        if out is not None:
            refuse_same_file(src, out)
    folder = os.path.dirname(os.path.abspath(os.fspath(dst)))
    if not os.path.isdir(folder):
        raise OutputError("output directory does not exist", dst)
    return plan_bake(src, recipe, os.fspath(dst), container, sat_path)


def bake_file(src, dst, recipe: Recipe = Recipe(), sat_path=None, threads=None, timings=None) -> dict:
    """Read `src`, bake, write `dst` (and its summed-area table, when the recipe
    asks for one or `sat_path` is given). Everything is checked before the image
    is read (plan_file; `recipe` may be the plan it made for `dst`), and nothing
    is written unless every output succeeded. Returns a summary; `timings`, a
    dict, collects seconds per stage (STAGES)."""
    if isinstance(recipe, BakePlan):
        plan = recipe
        if plan.output != os.fspath(dst) or (sat_path is not None and plan.sat != os.fspath(sat_path)):
            raise UsageError("the plan was made for another output", dst)
    else:
        plan = plan_file(src, dst, recipe, sat_path)
    container, sat_path, recipe = plan.container, plan.sat, plan.recipe
    with numba_loading_beside():
        with _stage(timings, "read"):
            image = read_image(src)
        baked = bake(image, plan, container, threads, timings)
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
        "notes": baked.notes,
        "clamped": baked.clamped,
    }
    if not containers.get(container).srgb:  # the values are encoded as colour_space says; the file cannot say so
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
        values = finite_pixels(image, recipe.source.nan_to_zero)
    else:
        values = image.integer_values()
    table = SummedAreaTable.build(values)
    try:
        vk, levels, kv = table.to_ktx2()
    except InputError as exc:
        raise exc.naming(image.path) from None
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
    kv: dict = field(default_factory=dict)  # the file's key/values as text (containers that hold them)


def load_texture(path) -> Decoded:
    """Any image, KTX2 or DDS file as decoded levels. A KTX2 file's KTXswizzle
    and recorded transforms are applied, so a texture reads in its source's
    units."""
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext not in TEXTURE_EXTENSIONS:
        image = read_image(path)
        px = to_rgba(image.pixels, False)
        if image.source_dtype == "uint8":
            px = np.rint(px * 255.0).astype(np.uint8)
        channels = {1: 3, 2: 4, 3: 3, 4: 4}[image.channels]
        return Decoded([px], channels, image.colour_space == "srgb", path)
    stored = containers.of_path(path).read(read_bytes(path, "texture"), path)
    if stored.format is None or stored.format not in codecs.names():
        raise InputError(f"{stored.label} has no decoder here", path)
    codec, srgb, width, height, raw, kv = (codecs.get(stored.format), stored.srgb, stored.width, stored.height,
                                           stored.levels, stored.kv)
    swizzle, steps = kv.get(keys.SWIZZLE.name), kv.get(transforms.KV_KEY)
    to_light, data = _stored_as_light(kv.get(COLOUR_KEY), path)
    normal_map = kv.get(CONTENT_KEY) == "normal"
    extra = {"srgb": srgb} if codec.srgb_decode else {}
    levels = [codec.decode(level, *formats.level_dims(width, height, i), **extra) for i, level in enumerate(raw)]
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
    elif data and srgb:
        # linear data stored through the sRGB curve reads as the data, as a sampler
        # decodes it: as float, between 8-bit codes
        levels = [decode_colour(_unit(px).astype(np.float32), True, 3) for px in levels]
        srgb = False
    return Decoded(levels, channels, srgb, path, normal_map, kv)


def _stored_as_light(text, path):
    """(to_light, data) from the file's colour-space record: an sRGB source
    stored in linear light; linear data stored sRGB-encoded."""
    if text is None:
        return False, False
    try:
        record = json.loads(text)
        return (bool(record["to_light"]) and record["source"] == "srgb",
                record["source"] == "linear" and record["chosen"] == "srgb")
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
        if da.levels[i].dtype != np.uint8 or db.levels[i].dtype != np.uint8:
            # HDR: errors relative to the value, as the eye and tone mapping see them
            rgb = chans[:3]
            rows[-1]["log2_psnr"] = metrics.log2_psnr(la[..., rgb], lb[..., rgb])
            rows[-1]["mpsnr"] = metrics.mpsnr(la[..., rgb], lb[..., rgb])
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
