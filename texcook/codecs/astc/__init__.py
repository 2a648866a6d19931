"""ASTC LDR: symbolic blocks, range tables, partitions, block modes, BISE,
packing and unpacking, decoding, and the encoder search.

One codec per 2D block size (`astc-4x4` .. `astc-12x12`), 16 bytes per block
whatever the size, so the bit rate is 128 / (bw * bh) bits per texel.

Encode options:
- ``weights=(r, g, b, a)``: per-channel error weights (default equal).
- ``srgb=True``: search for the sRGB decoding (endpoints widen as
  ``(e << 8) | 0x80``), for data stored under an sRGB vkFormat.
- ``normal_map=True``: the input holds a tangent-space normal, X, Y and Z in
  R, G and B. How it is stored is ``normal_layout``:
  - ``"xy"`` (the default): X in R, G and B and Y in alpha (what mobile
    engines sample: X from .r or .g, Y from .a; the shader rebuilds Z), with
    X and Y weighted equally. ``normal_xy`` turns a decoded image back into
    X, Y for angular error.
  - ``"xyz"``: X, Y and Z stay in R, G and B, as a glTF reader samples a
    normal texture; every component is tried on a second weight plane.
- ``angular=True`` (with ``normal_map`` and the "xy" layout): the search
  weighs X and Y per block by how much each turns the rebuilt normal, then
  each block's weights and endpoints are moved while the angle drops
  (texcook.codecs.astc.angular; --normal-metric angular).

Decode takes ``srgb=False``; UNORM and sRGB decoding differ.
"""

import os
import sys
import threading
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from ... import _beside, formats
from ...choices import NORMAL_LAYOUTS
from ...errors import UsageError
from .._base import ANGULAR, Codec, Option, blocks_to_image, run_chunked

# every 2D block size the format defines, in vkFormat order (157 + 2i UNORM)
BLOCK_SIZES = formats.ASTC_BLOCK_SIZES


def _channel_weights(name, weights, normal_map):
    if weights is None:
        w = np.ones(4)
    else:
        try:
            w = np.asarray(weights, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            raise UsageError(f"{name}: weights must be four numbers r,g,b,a, not {weights!r}") from None
        if w.size != 4 or not np.all(np.isfinite(w)) or np.any(w < 0) or w.max() <= 0:
            raise UsageError(f"{name}: weights must be four non-negative numbers r,g,b,a, "
                             f"not all 0: {weights!r}")
        w = w / w.max()
    if normal_map:
        # X is stored three times: a third of the weight on each copy
        x = w[0] if weights is not None else 1.0
        y = w[1] if weights is not None else 1.0
        w = np.array([x / 3, x / 3, x / 3, y])
    return np.ascontiguousarray(w, np.float64)


def to_rrrg(rgba):
    """Normal map with X in R and Y in G -> X in R, G, B and Y in alpha."""
    out = np.empty_like(rgba)
    out[..., 0] = rgba[..., 0]
    out[..., 1] = rgba[..., 0]
    out[..., 2] = rgba[..., 0]
    out[..., 3] = rgba[..., 1]
    return out


def normal_xy(decoded):
    """A decoded "rrrg" normal map -> X in R, Y in G (B 0, A 255), the layout
    texcook.metrics.normal_angular_error reads."""
    out = np.zeros_like(decoded)
    out[..., 0] = decoded[..., 0]
    out[..., 1] = decoded[..., 3]
    out[..., 3] = 255
    return out


@dataclass(frozen=True)
class ASTCCodec(Codec):
    compile_seconds = 27  # s a first 256x256 bake spends compiling, helper beside it (docs/performance.md)
    def _encode_blocks(self, blocks, out, preset, threads, weights=None, srgb=False,
                       normal_map=False, normal_layout="xy", angular=False, **options):
        if options:
            raise UsageError(f"{self.name}: unknown option(s) {', '.join(sorted(options))}")
        if angular and not normal_map:
            raise UsageError(f"{self.name}: the angular objective judges normals: it needs normal_map")
        two_plane = normal_map and normal_layout == "xy"
        if angular and not two_plane:
            raise UsageError(f"{self.name}: the angular objective judges X and Y with Z rebuilt: it needs "
                             "the xy normal layout")
        from . import presets, search

        with _compiled_beside(self, threads, search.search_kernel):
            bw, bh = self.block_w, self.block_h
            chw = _channel_weights(self.name, weights, two_plane)
            if two_plane:
                blocks = np.ascontiguousarray(to_rrrg(blocks))
            params = presets.record(bw, bh, preset)
            if normal_map:
                # X and Y vary apart by construction: Y's plane of its own is worth
                # more than the early-out's saving (4x4 fast: 44.0 -> 48.2 dB X/Y)
                params["plane_always"] = 1
            if normal_map and not two_plane:
                # X, Y and Z lie on a sphere, not along a line: each component is
                # tried on a plane of its own, whatever the preset (docs/astc.md)
                params["dual"] = 2
            sym = np.zeros((blocks.shape[0], search.SYM_LEN), np.int32)
            mode_on = presets.mode_mask(bw, bh, preset)

            def run_search(blocks, sym, chw):
                run_chunked(search.search, blocks, sym, threads, params, mode_on, chw,
                            np.int64(1 if srgb else 0), search.kernel_tables(bw, bh))

            if angular:
                from .angular import search_by_angle

                search_by_angle(blocks, sym, chw, run_search, bw, bh, preset, srgb, threads)
            else:
                run_search(blocks, sym, chw)
            from . import pack  # after the search: see _compiled_beside

            bad = pack.encode_symbolic_blocks(sym, out)
            if bad >= 0:
                raise AssertionError(f"{self.name}: the search made an unpackable block ({bad})")
            return sym

    def encode_symbolic(self, rgba, preset="medium", threads=None, **options):
        """(bytes, symbolic blocks (n, SYM_LEN)) for tests and tools."""
        from .._base import image_to_blocks

        self.check_preset(preset)
        rgba = self.check_input(rgba)
        blocks = image_to_blocks(rgba, self.block_w, self.block_h, threads)
        out = np.zeros((blocks.shape[0], 16), np.uint8)
        sym = self._encode_blocks(blocks, out, preset, threads, **options)
        return out.tobytes(), sym

    def decode(self, data, width, height, srgb=False) -> np.ndarray:
        from .decode import decode_blocks

        buf = self.check_data(data, width, height).reshape(-1, 16)
        out = np.zeros((buf.shape[0], self.block_w * self.block_h, 4), np.uint8)
        decode_blocks(np.ascontiguousarray(buf), out, np.int64(self.block_w),
                      np.int64(self.block_h), np.int64(1 if srgb else 0))
        return blocks_to_image(out, width, height, self.block_w, self.block_h)


# the options the codec declares; the pipeline fills srgb and normal_map from the recipe
ASTCCodec.options = (
    Option("weights", "floats", None, min=0.0, count=4, help="per-channel error weights r,g,b,a"),
    Option("srgb", "bool", False, help="search for the sRGB decoding (set for sRGB output)"),
    Option("normal_map", "bool", False, help="the input is a normal map (set by --normal-map)"),
    Option("normal_layout", "choice", "xy", choices=NORMAL_LAYOUTS,
           help="with normal_map: xy stores X in RGB and Y in alpha, xyz keeps X, Y, Z in RGB "
                "(set by --normal-layout)"),
    ANGULAR,
)
ASTCCodec.srgb_decode = True
ASTCCodec.normal_swizzle = "ra01"  # how a loader presents X, Y of an "xy" normal map in R, G
ASTCCodec.normal_layouts = NORMAL_LAYOUTS


_beside_started = threading.Lock()  # held once a first encode has looked at the cache


@contextmanager
def _compiled_beside(codec, threads, search_kernel):
    """While the block runs (the first encode of a process), when the
    search's kernel is not in the disk cache (a first use) and there is a core
    to spare, a helper process (texcook._beside) compiles part of what this
    one would: the functions the search's kernel calls (compile_beside), from
    the candidate encoding, which this process reaches last, backwards, while
    this one compiles them from the first (one that the other is compiling
    is waited for under its compile lock, texcook._jit, and loaded), then the
    packing of symbolic blocks into bits (imported here only after the search
    has run). The helper is stopped when the block ends."""
    helper = None
    if _beside_started.acquire(blocking=False):
        from ..._jit import cached
        from ..._threads import cpu_threads

        if ("texcook.codecs.astc.pack" not in sys.modules and cpu_threads(threads) >= 2 and _core_idle()
                and cached(search_kernel) is False):
            fn, args = codec.compile_beside  # the job `texcook prepare` runs beside the codec's too
            helper = _beside.start(fn, *args)
    try:
        yield
    finally:
        _beside.stop(helper)


def _core_idle():
    """A core is idle (the load average of the last minute leaves one): the
    helper is a niced process, and this one may wait for its kernels, which
    on a machine busy with other work would come later than compiling them
    here."""
    try:
        return os.getloadavg()[0] < (os.cpu_count() or 1) - 0.5
    except (AttributeError, OSError):  # no load average here
        return True


def compile_beside(bw, bh):
    """What _compiled_beside's helper runs: what the search's kernel calls,
    for the types it calls them with (search.beside_kernels, the last it
    reaches first), then the packing of a block (the values do not matter,
    the types do), each into the disk cache. The packing is imported after:
    its typed kernels compile as it loads."""
    from . import search

    for kernel, types in search.beside_kernels(bw, bh):
        kernel.compile(types)
    from . import pack
    from .symbolic import SYM_LEN

    pack.encode_symbolic_blocks(np.zeros((1, SYM_LEN), np.int32), np.zeros((1, 16), np.uint8))


def _preset_tables(codec):
    from .presets import table_for

    return (table_for(codec.block_w, codec.block_h),)


ASTCCodec.preset_tables = property(_preset_tables)  # the table of the codec's block-size class
ASTCCodec.compile_beside = property(lambda self: (compile_beside, (self.block_w, self.block_h)))

CODECS = {f.name: ASTCCodec(f) for f in formats.FORMATS.values() if f.family == "astc"}

