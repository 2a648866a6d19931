"""See a texture on a surface, sampled the way a sampler asks, against a
supersampled reference.

    from texcook.preview import render, save
    result = render("wall.ktx2", scene="plane", filter="all", size=(512, 512))
    save(result, "view.png")

Stages, one module each: `scenes` (geometry), `raster` (perspective-correct
G-buffer with analytic derivatives), `sample` (the filters), `reference`
(shading, ground truth, error), `label` (text for the side-by-side image),
`source` (levels and sampler).
"""

import math
import os
import time
from dataclasses import dataclass, field

import numpy as np

from ..colour import linear_to_srgb, quantize_unorm8
from ..errors import UsageError
from ..fileio import check_memory
from . import scenes as _scenes
from .label import draw_text, text_width
from .raster import rasterise, scale_uv, triangle_setup
from .reference import ALPHA_MODES, background, blur_alias, composite, db, psnr, reference_frame
from .sample import FILTERS, Chain, lod_frame, mag_linear_of, padded_sat, parse_filter, sample_frame, uses_mips
from .source import load, resolve_sampler

SCENES = tuple(_scenes.SCENES)
FAR_LOD = 2.0  # "far" pixels, where coverage is judged: level of detail at least this
MAX_SIZE = 4096
# Bytes a render holds per frame pixel: the G-buffer, level of detail and one
# frame's samples (FRAME_BYTES), each further filter's kept frame and its
# temporaries (FILTER_BYTES), the reference with the error measures' FFT tiles
# (REFERENCE_BYTES); per texel of level 0: the linear levels and their packed
# copy (4/3 for a chain), the summed-area table for `sat`. Fitted to the peak
# resident size of `texcook preview` at 512x512 to 2048x2048 (about 150 bytes a
# pixel for one filter, 520 for `all`).
FRAME_BYTES, FILTER_BYTES, REFERENCE_BYTES = 110, 40, 180
TEXEL_BYTES, SAT_TEXEL_BYTES = 2 * 16, 32
DEFAULT_SCENE, CUTOUT_SCENE = "plane", "quad"


@dataclass
class Frame:
    name: str
    rgb: np.ndarray  # display values (sRGB-encoded for sRGB textures), float32 (H, W, 3), 0..1
    covered: np.ndarray  # alpha coverage per pixel (H, W): 0/1 for filters, a fraction for the reference
    seconds: float  # wall time per frame: rasterise, filter, shade
    cpu_seconds: float  # the same in CPU time, summed over threads


@dataclass
class Preview:
    texture: str
    scene: str
    width: int
    height: int
    srgb: bool
    alpha_mode: str
    alpha_cutoff: float
    sampler: dict
    levels_loaded: int
    level_count: int
    raster_seconds: float
    frames: list = field(default_factory=list)
    reference: Frame = None
    rows: list = field(default_factory=list)  # one dict per filter: time and error
    lod: np.ndarray = None  # level of detail per pixel (NaN where empty)
    valid: np.ndarray = None  # pixels the error is measured on
    image: np.ndarray = None  # uint8 (H', W', 3): the frame, or the labelled side-by-side

    def to_dict(self):
        ref = None
        if self.reference is not None:
            ref = {"seconds": self.reference.seconds, "cpu_seconds": self.reference.cpu_seconds, "coverage": _mean(self.reference.covered, self.valid),
                   "coverage_far": _mean(self.reference.covered, self.valid & self._far())}
        return {
            "texture": self.texture, "scene": self.scene, "size": [self.width, self.height], "srgb": self.srgb,
            "alpha_mode": self.alpha_mode, "alpha_cutoff": self.alpha_cutoff, "sampler": self.sampler,
            "levels_loaded": self.levels_loaded, "level_count": self.level_count,
            "raster_seconds": self.raster_seconds, "reference": ref, "filters": self.rows,
        }

    def _far(self):
        return np.nan_to_num(self.lod, nan=-1.0) >= FAR_LOD


def _mean(values, mask):
    return float(values[mask].mean()) if mask.any() else None


def _finite_or_none(x):
    """No NaN in results: None when nothing was measured (no covered pixel)."""
    return None if x is None or math.isnan(x) else x


def parse_size(size):
    """'WxH' or (W, H) -> (W, H), within 1..MAX_SIZE."""
    try:
        w, h = (int(v) for v in (str(size).lower().split("x") if isinstance(size, str) else size))
    except (ValueError, TypeError):
        raise UsageError(f"size must be WxH, like 512x512, not {size!r}") from None
    if not (1 <= w <= MAX_SIZE and 1 <= h <= MAX_SIZE):
        raise UsageError(f"size must be within 1x1..{MAX_SIZE}x{MAX_SIZE}, not {w}x{h}")
    return w, h


def working_bytes(width, height, names, reference, texture=(0, 0), mips=True):
    """What rendering `names` (and the reference) into a width x height frame
    holds in memory at most, with a texture of `texture` (w, h) texels."""
    pixels = int(width) * int(height)
    texels = int(texture[0]) * int(texture[1])
    frame = pixels * (FRAME_BYTES + FILTER_BYTES * len(names) + (REFERENCE_BYTES if reference else 0))
    levels = texels * TEXEL_BYTES * (4 if mips else 3) // 3
    return frame + levels + (texels * SAT_TEXEL_BYTES if "sat" in names else 0)


def _check_budget(path, width, height, names, reference, texture=(0, 0), mips=True):
    """Refuse a frame size and filter set that would not fit the memory budget
    (--max-memory), before anything is rendered."""
    what = f"a {width}x{height} preview with {len(names)} filter(s){' and the reference' if reference else ''}"
    check_memory(working_bytes(width, height, names, reference, texture, mips), what, path, UsageError)


def _display(rgb, srgb):
    rgb = np.clip(rgb, 0.0, 1.0)
    return np.clip(linear_to_srgb(rgb), 0.0, 1.0).astype(np.float32) if srgb else rgb.astype(np.float32)


def _best_time(fn, runs):
    """(result, wall seconds, CPU seconds of all threads) of the fastest of `runs` calls.
    CPU time says what a frame costs when the machine is shared."""
    best, cpu, result = math.inf, math.inf, None
    for _ in range(max(1, runs)):
        t0, c0 = time.perf_counter(), time.process_time()
        result = fn()
        wall = time.perf_counter() - t0
        if wall < best:
            best, cpu = wall, time.process_time() - c0
    return result, best, cpu


def render(path, scene=None, filter=None, size=(512, 512), reference=False, alpha_cutoff=None, wrap=None,
           runs=1):
    """Render TEXTURE on a scene with one filter (or `all`), optionally against
    the supersampled reference. `filter`, `wrap` and `alpha_cutoff` override the
    sampler a scene.json gives (defaults: trilinear, repeat). `scene` None
    picks the plane, or for an alpha-tested texture (a cutoff is known) the
    quad, where the whole cut-out and its edge are in view. `runs` > 1 times
    each frame that many times and keeps the fastest (the first run includes
    loading compiled kernels). Refused before any rendering when the frame
    would not fit the memory budget."""
    path = os.fspath(path)
    width, height = parse_size(size)
    if scene is not None:
        _scenes.get(scene)  # an unknown name is refused before any file is read
    sampler = resolve_sampler(path, filter, wrap, alpha_cutoff)
    names = list(FILTERS) if sampler.filter == "all" else [sampler.filter]
    for name in names:
        parse_filter(name)
    reference = reference or sampler.filter == "all"
    mips = any(uses_mips(n) for n in names)
    _check_budget(path, width, height, names, reference)

    tex = load(path, mips=mips, alpha_cutoff=sampler.alpha_cutoff)
    _check_budget(path, width, height, names, reference, (tex.width, tex.height), mips)
    cutoff = sampler.alpha_cutoff if sampler.alpha_cutoff is not None else tex.alpha_cutoff
    if cutoff is not None and not tex.has_alpha:
        raise UsageError("an alpha cutoff needs a texture with an alpha channel", path)
    if scene is None:
        scene = CUTOUT_SCENE if cutoff is not None else DEFAULT_SCENE
    sc = _scenes.get(scene)
    if cutoff is not None:
        mode = "mask"
    elif tex.has_alpha and float(tex.levels[0][..., 3].min()) < 1.0:
        mode = "blend"
    else:
        mode = "opaque"

    # Geometry: scale texture coordinates so the nearest pixel sees the texels the scene asks for.
    setup, boxes = triangle_setup(sc.positions, sc.uvs, sc.fov_y, width, height)
    if sc.texels_per_pixel_min:
        gbuf, tri = rasterise(setup, boxes, width, height)
        lam = lod_frame(gbuf, tri, tex.width, tex.height)
        lam = lam[np.isfinite(lam)]
        if lam.size:
            scale_uv(setup, gbuf, sc.texels_per_pixel_min / 2.0 ** float(lam.min()))
    (gbuf, tri), raster_s, raster_cpu = _best_time(lambda: rasterise(setup, boxes, width, height), runs)
    lod = lod_frame(gbuf, tri, tex.width, tex.height)

    chain = Chain(tex.levels) if any(n != "sat" for n in names) else None
    sat = padded_sat(tex.levels[0]) if "sat" in names else None
    bg = background(width, height)
    cut = 0.5 if cutoff is None else cutoff

    result = Preview(path, scene, width, height, tex.srgb, mode, cutoff,
                     {"filter": sampler.filter, "mag_linear": sampler.mag_linear, "wrap": list(sampler.wrap),
                      "source": sampler.source},
                     len(tex.levels), tex.level_count, raster_s, lod=lod)
    for name in names:
        def one(name=name):
            mag = mag_linear_of(name) if sampler.mag_linear is None else sampler.mag_linear
            rgba = sample_frame(name, gbuf, tri, sat if name == "sat" else chain, sampler.wrap, mag)
            return composite(rgba, tri, bg, mode, cut)

        (rgb, covered), seconds, cpu = _best_time(one, runs)
        result.frames.append(Frame(name, _display(rgb, tex.srgb), covered, raster_s + seconds, raster_cpu + cpu))

    valid = tri >= 0
    if reference:
        (ref_rgb, geo, ref_cov), ref_s, ref_cpu = _best_time(
            lambda: reference_frame(setup, gbuf, tri, tex.levels[0], sampler.wrap, bg, mode, cut), 1)
        result.reference = Frame("reference", _display(ref_rgb, tex.srgb), ref_cov, ref_s, ref_cpu)
        valid = valid & (geo >= 1.0)
    result.valid = valid
    far = result._far()
    for f in result.frames:
        row = {"filter": f.name, "seconds": f.seconds, "cpu_seconds": f.cpu_seconds}
        if result.reference is not None:
            blur, alias = blur_alias(f.rgb, result.reference.rgb, valid)
            row.update(psnr=_finite_or_none(psnr(f.rgb, result.reference.rgb, valid)),
                       blur_db=_finite_or_none(db(blur)), alias_db=_finite_or_none(db(alias)))
        if mode == "mask":
            row.update(coverage=_mean(f.covered, valid), coverage_far=_mean(f.covered, valid & far))
        result.rows.append(row)
    result.image = compose(result)
    return result


def _cell(value, fmt, width):
    if value is None:
        return "-".rjust(width)
    if isinstance(value, float) and math.isinf(value):
        return "inf".rjust(width)
    return fmt.format(value).rjust(width)


def table(result):
    """The result as text: what was shown and how, then one row per filter
    (time, and against the reference PSNR, blur and aliasing, coverage)."""
    d = result.to_dict()
    s = d["sampler"]
    cut = f" at {d['alpha_cutoff']:g}" if d["alpha_cutoff"] is not None else ""
    lines = [
        f"{d['texture']}: {'sRGB' if d['srgb'] else 'linear'}, {d['level_count']} level(s), "
        f"{d['levels_loaded']} loaded; alpha {d['alpha_mode']}{cut}",
        f"scene {d['scene']} {result.width}x{result.height}, sampler {s['filter']} wrap {','.join(s['wrap'])} "
        f"({s['source']}), raster {d['raster_seconds'] * 1000:.1f} ms",
    ]
    cols = [("ms/frame", "ms", "{:.1f}"), ("cpu ms", "cpu_ms", "{:.1f}")]
    if d["reference"] is not None:
        cols += [("PSNR dB", "psnr", "{:.2f}"), ("blur dB", "blur_db", "{:.2f}"), ("alias dB", "alias_db", "{:.2f}")]
    if d["alpha_mode"] == "mask":
        cols += [("coverage", "coverage", "{:.3f}"), ("far", "coverage_far", "{:.3f}")]
    rows = [dict(r, ms=r["seconds"] * 1000, cpu_ms=r["cpu_seconds"] * 1000) for r in d["filters"]]
    if d["reference"] is not None:
        ref = d["reference"]
        rows.append({"filter": "reference", "ms": ref["seconds"] * 1000, "cpu_ms": ref["cpu_seconds"] * 1000,
                     "coverage": ref["coverage"], "coverage_far": ref["coverage_far"]})
    widths = [max(9, len(title)) for title, _, _ in cols]
    lines.append("filter     " + " ".join(title.rjust(w) for (title, _, _), w in zip(cols, widths)))
    for r in rows:
        cells = [_cell(r.get(key), fmt, w) for (_, key, fmt), w in zip(cols, widths)]
        lines.append(f"{r['filter']:<10} " + " ".join(cells))
    return "\n".join(lines)


# --- the picture -----------------------------------------------------------------------

_LOD_PALETTE = np.array([
    (0.20, 0.20, 0.90), (0.10, 0.65, 0.95), (0.10, 0.80, 0.45), (0.60, 0.85, 0.10), (0.95, 0.80, 0.10),
    (0.95, 0.45, 0.10), (0.90, 0.15, 0.20), (0.75, 0.15, 0.65), (0.50, 0.50, 0.50),
])


def lod_image(lod):
    """Level of detail as colour: one hue per level (level 0 blue, 1 cyan, 2 green,
    3 lime, 4 yellow, 5 orange, 6 red, 7 purple, 8+ grey), blended between levels;
    magnification (lambda < 0) is darker, empty pixels black."""
    lam = np.nan_to_num(lod, nan=-np.inf)
    empty = np.isnan(lod)
    top = len(_LOD_PALETTE) - 1
    c = np.clip(lam, 0.0, top)
    i = np.minimum(np.floor(c).astype(np.int64), top - 1)
    f = (c - i)[..., None]
    rgb = _LOD_PALETTE[i] * (1.0 - f) + _LOD_PALETTE[i + 1] * f
    rgb = rgb * np.where(lam < 0.0, 0.55, 1.0)[..., None]
    rgb[empty] = 0.0
    return quantize_unorm8(rgb)


def _label(r, reference):
    if r.get("psnr") is None or reference is None:
        return f"{r['filter']} {r['seconds']:.3f}s"
    return f"{r['filter']} {r['psnr']:.2f}db {r['seconds']:.3f}s"


def compose(result):
    """The frame alone, or with the reference (and, for several filters, a level
    of detail map) side by side under one-line labels."""
    frames = [quantize_unorm8(f.rgb) for f in result.frames]
    if result.reference is None and len(frames) == 1:
        return frames[0]
    panels = [(_label(r, result.reference), img) for r, img in zip(result.rows, frames)]
    if result.reference is not None:
        panels.append((f"reference {result.reference.seconds:.2f}s", quantize_unorm8(result.reference.rgb)))
    if len(panels) > 2:
        panels.append(("level of detail", lod_image(result.lod)))
    w, h = result.width, result.height
    scale = 2 if w >= 320 else 1
    strip = 7 * scale + 6
    cols = min(4, len(panels))
    rows = -(-len(panels) // cols)
    gap = 2
    out = np.full((rows * (h + strip) + (rows - 1) * gap, cols * w + (cols - 1) * gap, 3), 24, np.uint8)
    for k, (text, img) in enumerate(panels):
        y = (k // cols) * (h + strip + gap)
        x = (k % cols) * (w + gap)
        while len(text) > 3 and text_width(text, scale) > w - 6:
            text = text[:-1]
        draw_text(out, text, x + 3, y + 3, scale=scale)
        out[y + strip:y + strip + h, x:x + w] = img
    return out


def save(result, output):
    """Write the preview image (PNG or any 8-bit format OpenImageIO writes), atomically."""
    from ..image import write_image

    write_image(output, result.image, "srgb" if result.srgb else "linear")
    return os.fspath(output)


__all__ = ["render", "save", "table", "Preview", "Frame", "SCENES", "FILTERS", "ALPHA_MODES", "parse_size", "lod_image"]
