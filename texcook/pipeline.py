"""One texture, source to file: read -> linear float -> mip chain -> encode each
level -> container -> atomic write.

A Recipe says which optional steps run and with what settings. Only the steps a
recipe names run: no mips when `mips=False`, no coverage search without
`alpha_cutoff`, no sRGB conversion for data textures.
"""

import os
from dataclasses import dataclass, field

import numpy as np

from . import __version__, codecs
from .colour import decode_colour, encode_colour, quantize_unorm8
from .errors import InputError, TexcookError, UsageError
from .fileio import atomic_write, read_bytes, refuse_same_file
from .image import Image, read_image

FILTERS = ("box", "triangle", "lanczos", "kaiser")
WEIGHTED_FORMATS = ("bc1", "bc1a", "bc3", "etc1")  # encoders whose colour search takes --weights
WRAPS = ("clamp", "repeat", "mirror")


@dataclass(frozen=True)
class Recipe:
    format: str = "rgba8"
    srgb: bool = None  # None: sRGB for colour sources that are sRGB-encoded, linear otherwise
    mips: bool = True
    mip_filter: str = "box"
    wrap: tuple = ("clamp", "clamp")  # (x, y)
    lanczos_a: int = 3
    kaiser_width: float = None  # None: the mip module's documented default
    kaiser_alpha: float = None
    premultiply: bool = False
    alpha_cutoff: float = None
    normal_map: bool = False
    nan_to_zero: bool = False
    preset: str = "medium"
    threads: int = None
    weights: tuple = None  # channel weights for colour codecs
    zstd: int = None  # Zstandard level, None for no supercompression
    dds_dx10: bool = False
    clamp: bool = False  # values beyond the format's range: clamp (True) or refuse (False)

    def __post_init__(self):
        if self.mip_filter not in FILTERS:
            raise UsageError(f"unknown mip filter {self.mip_filter!r}; choose one of {', '.join(FILTERS)}")
        wrap = self.wrap
        if isinstance(wrap, str):
            wrap = tuple(wrap.split(",")) if "," in wrap else (wrap, wrap)
            object.__setattr__(self, "wrap", wrap)
        if len(wrap) != 2 or any(w not in WRAPS for w in wrap):
            raise UsageError(f"wrap must be one or two of {', '.join(WRAPS)} (x,y), not {','.join(wrap)}")
        if self.alpha_cutoff is not None and not 0.0 <= self.alpha_cutoff <= 1.0:
            raise UsageError(f"alpha cutoff must be within 0..1, not {self.alpha_cutoff}")
        if self.zstd is not None and not 1 <= self.zstd <= 22:
            raise UsageError(f"zstd level must be within 1..22, not {self.zstd}")
        if self.lanczos_a < 1:
            raise UsageError(f"lanczos a must be at least 1, not {self.lanczos_a}")
        codec = codecs.get(self.format)
        codec.check_preset(self.preset)
        if self.weights is not None and self.format not in WEIGHTED_FORMATS:
            raise UsageError(f"--weights applies to {', '.join(WEIGHTED_FORMATS)}, not {self.format}")
        if self.weights is not None and (len(self.weights) != 3 or min(self.weights) < 0 or sum(self.weights) <= 0):
            raise UsageError("weights must be three non-negative numbers r,g,b, not all zero")


@dataclass
class Baked:
    """Encoded levels, ready for a container."""

    codec: object
    srgb: bool
    width: int
    height: int
    levels: list  # bytes per level, base first
    kv: dict = field(default_factory=dict)
    clamped: int = 0  # values clamped to the format's range (--clamp)

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
        xy = px * 2.0 - 1.0
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
    if not recipe.nan_to_zero:
        n = int(bad.sum())
        raise InputError(f"{n} NaN or Inf value(s) in the pixels; use --nan-to-zero to replace them with 0", image.path)
    return np.where(bad, np.float32(0.0), px)


def fit_range(levels, codec, clamp, path=None):
    """Values a float format cannot hold (beyond +-65504 for rgba16f, which
    would become Inf) are refused with their count, or clamped to the largest
    finite value with `clamp`. Checked on every level: Lanczos and Kaiser mips
    can overshoot the source. Returns (levels, number clamped)."""
    dtype = np.dtype(getattr(codec, "dtype", "uint8"))
    if not codec.float_input or dtype.kind != "f" or dtype.itemsize >= 4:
        return levels, 0
    top = np.float32(np.finfo(dtype).max)
    over = sum(int(np.count_nonzero(np.abs(lv) > top)) for lv in levels)
    if not over:
        return levels, 0
    if not clamp:
        raise InputError(f"{over} value(s) beyond the {codec.name} range (+-{float(top):g}); "
                         "use --clamp to clamp them, or a 32-bit float format", path)
    return [np.clip(lv, -top, top) for lv in levels], over


def output_srgb(image, recipe, codec):
    """The colour encoding of the output: explicit --srgb/--linear wins; otherwise
    sRGB when the source is sRGB colour and the format has an sRGB variant."""
    if recipe.srgb is not None:
        if recipe.srgb and recipe.normal_map:
            raise UsageError("a normal map holds vectors, not colour: it cannot be stored as sRGB")
        if recipe.srgb:
            codec.vk_format(True)  # raises when there is no sRGB variant
        return recipe.srgb
    return image.colour_space == "srgb" and bool(codec.vk_srgb) and not recipe.normal_map and not codec.float_input


def build_levels(image: Image, recipe: Recipe, srgb_out=False):
    """Float32 RGBA levels, base first, as the recipe asks, in linear light when
    the output is sRGB. An sRGB-encoded source is decoded to linear light only
    for sRGB output: baked to a linear format (bc4, bc5, --linear) its values
    are data (masks, heights, vectors) and are kept as they are."""
    px = _check_finite(image, recipe)
    has_alpha = image.alpha != "none"
    if recipe.alpha_cutoff is not None and not has_alpha:
        raise UsageError("--alpha-cutoff needs a source with an alpha channel", image.path)
    linear = decode_colour(px, srgb_out and image.colour_space == "srgb", image.alpha_channel)
    rgba = _to_rgba(linear, recipe.normal_map)
    if not recipe.mips:
        return [rgba]
    from .mips import build_chain

    extra = {}
    if recipe.kaiser_width is not None:
        extra["kaiser_width"] = recipe.kaiser_width
    if recipe.kaiser_alpha is not None:
        extra["kaiser_alpha"] = recipe.kaiser_alpha
    return build_chain(
        rgba,
        filter=recipe.mip_filter,
        wrap=tuple(recipe.wrap),
        lanczos_a=recipe.lanczos_a,
        premultiply=recipe.premultiply and has_alpha,
        alpha_channel=3 if has_alpha else None,
        alpha_cutoff=recipe.alpha_cutoff,
        normal_map=recipe.normal_map,
        ldr=not image.is_float,
        **extra,
    )


def bake(image: Image, recipe: Recipe = Recipe(), container="ktx2") -> Baked:
    """Mip chain and encoding of one image; no file is touched. `container`
    ("ktx2" or "dds") matters where a reader of that container decodes
    differently."""
    codec = codecs.get(recipe.format)
    srgb = output_srgb(image, recipe, codec)
    options = {}
    if recipe.format == "bc1" and container == "dds":
        options["opaque_black"] = False
    if recipe.weights is not None:
        options["weights"] = tuple(float(w) for w in recipe.weights)
    if recipe.format == "bc1a" and recipe.alpha_cutoff is not None:
        options["alpha_threshold"] = int(round(recipe.alpha_cutoff * 255))
    encoded = []
    levels, clamped = fit_range(build_levels(image, recipe, srgb), codec, recipe.clamp, image.path)
    for level in levels:
        px = encode_colour(level, srgb, 3)
        px = np.ascontiguousarray(px, np.float32) if codec.float_input else quantize_unorm8(px)
        encoded.append(codec.encode(px, recipe.preset, recipe.threads, **options))
    kv = {}
    if recipe.normal_map:
        kv["texcook.content"] = "normal"
    return Baked(codec, srgb, image.width, image.height, encoded, kv, clamped)


def container_bytes(baked: Baked, path, recipe: Recipe) -> bytes:
    """KTX2 (default) or DDS, by the output's extension."""
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext == ".dds":
        if recipe.zstd is not None:
            raise UsageError("--zstd applies to KTX2 output, not DDS", path)
        from .container.dds import write_dds

        try:
            return write_dds(baked.codec.name, baked.width, baked.height, baked.levels, baked.srgb,
                             dx10=recipe.dds_dx10)
        except TexcookError as exc:
            raise exc.naming(path) from None
    if ext != ".ktx2":
        raise UsageError(f"output must end in .ktx2 or .dds, not {ext or 'no extension'!r}", path)
    from .container.ktx2 import write_ktx2

    kv = dict(baked.kv)
    kv["KTXwriter"] = f"texcook {__version__}"
    return write_ktx2(baked.vk_format, baked.width, baked.height, baked.levels, kv=kv, zstd_level=recipe.zstd)


def bake_file(src, dst, recipe: Recipe = Recipe(), sat_path=None) -> dict:
    """Read `src`, bake, write `dst` (and a summed-area table to `sat_path`).
    Nothing is written unless everything succeeded. Returns a summary."""
    ext = os.path.splitext(os.fspath(dst))[1].lower()
    if ext not in (".ktx2", ".dds"):
        raise UsageError(f"output must end in .ktx2 or .dds, not {ext or 'no extension'!r}", dst)
    refuse_same_file(src, dst)
    if sat_path is not None:
        refuse_same_file(src, sat_path)
    image = read_image(src)
    baked = bake(image, recipe, container=ext[1:])
    data = container_bytes(baked, dst, recipe)
    sat_data = None
    if sat_path is not None:
        sat_data = sat_bytes(image, recipe)
    atomic_write(dst, data)
    if sat_data is not None:
        atomic_write(sat_path, sat_data)
    return {
        "input": os.fspath(src),
        "output": os.fspath(dst),
        "format": baked.codec.name,
        "vk_format": baked.vk_format,
        "colour_space": "srgb" if baked.srgb else "linear",
        "width": baked.width,
        "height": baked.height,
        "levels": len(baked.levels),
        "bytes": len(data),
        "clamped": baked.clamped,
    }


def sat_bytes(image: Image, recipe: Recipe) -> bytes:
    """A summed-area table of the source's stored values as KTX2."""
    from .container.ktx2 import write_ktx2
    from .sat import SummedAreaTable

    if image.is_float:
        values = _check_finite(image, recipe)
    else:
        values = image.integer_values()
    table = SummedAreaTable.build(values)
    vk, levels, kv = table.to_ktx2()
    kv = dict(kv)
    kv["KTXwriter"] = f"texcook {__version__}"
    return write_ktx2(vk, image.width, image.height, levels, kv=kv, zstd_level=recipe.zstd)


# --- reading back --------------------------------------------------------------------


@dataclass
class Decoded:
    """Levels of a texture or image as RGBA arrays in their stored encoding:
    uint8 for 8-bit and block formats, float32 for float formats."""

    levels: list
    channels: int  # channels that carry data (1..4)
    srgb: bool
    source: str


def load_texture(path) -> Decoded:
    """Any image, KTX2 or DDS file as decoded levels."""
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext in (".ktx2", ".dds"):
        data = read_bytes(path, "texture")
        if ext == ".ktx2":
            from .container.ktx2 import read_ktx2

            ktx = read_ktx2(data, path)
            codec, srgb = codecs.by_vk_format(ktx.vk_format)
            if codec is None:
                raise InputError(f"vkFormat {ktx.vk_format} has no decoder here", path)
            width, height, raw = ktx.width, ktx.height, ktx.levels
        else:
            from .container.dds import read_dds

            name, width, height, raw, srgb = read_dds(data, path)
            codec = codecs.get(name)
        from .container.levels import level_dims

        levels = [codec.decode(level, *level_dims(width, height, i)) for i, level in enumerate(raw)]
        return Decoded(levels, codec.channels, srgb, path)
    image = read_image(path)
    px = _to_rgba(image.pixels, False)
    if image.source_dtype == "uint8":
        px = np.rint(px * 255.0).astype(np.uint8)
    channels = {1: 3, 2: 4, 3: 3, 4: 4}[image.channels]
    return Decoded([px], channels, image.colour_space == "srgb", path)


def compare(a, b, level=None):
    """PSNR between two images or textures, per level and channel, on values in
    0..1 (8-bit data scaled by 1/255). Compared channels: those both carry."""
    from . import metrics

    da, db = load_texture(a), load_texture(b)
    n = min(da.channels, db.channels)
    chans = list(range(n))
    count = min(len(da.levels), len(db.levels))
    indices = range(count) if level is None else [level]
    if level is not None and not (0 <= level < count):
        raise UsageError(f"level {level} does not exist in both (they share {count})")
    rows = []
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
    overall = metrics.psnr_from_mse(total_se / total_n, 1.0) if total_n else float("inf")
    return {"a": os.fspath(a), "b": os.fspath(b), "channels": "RGBA"[:n], "psnr": overall, "levels": rows}


def _unit(px):
    px = np.asarray(px)
    if px.dtype == np.uint8:
        return px.astype(np.float64) / 255.0
    return px.astype(np.float64)
