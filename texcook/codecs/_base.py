"""What every codec shares: the interface, block extraction with edge-replicated
padding, and deterministic multi-threading over blocks.

A codec's jitted kernels work on a run of blocks:

    encode_kernel(blocks: uint8 (n, bh*bw, 4), out: uint8 (n, bytes_per_block), *params)
    decode_kernel(data: uint8 (n, bytes_per_block), out: uint8 (n, bh*bw, 4))

Texels inside a block are in row-major order (index = y * bw + x). Blocks are
independent, so splitting the run into chunks for threads cannot change a byte.
"""

import threading
import time
from dataclasses import dataclass

import numpy as np

from .._jit import jit
from .._threads import cpu_threads, parallel_for, run_workers
from ..choices import DEFAULT_PRESET, PRESETS
from ..errors import UsageError
from ..formats import Format, block_count


_GATHER_KERNEL_TEXELS = 1 << 18


def image_to_blocks(rgba, bw, bh, threads=None):
    """(H, W, C) -> (nblocks, bh*bw, C), blocks in row-major order. Partial blocks
    are padded by replicating the last row and column, never with zeros, so padding
    adds no colour the encoder must spend precision on. Rows of blocks are
    gathered on `threads` threads."""
    rgba = np.ascontiguousarray(rgba)
    h, w, c = rgba.shape
    nbx, nby = block_count(w, bw), block_count(h, bh)
    if bw == bh == 1:
        return rgba.reshape(h * w, 1, c)
    if h * w < _GATHER_KERNEL_TEXELS:
        # NumPy's copy: below this size the kernel costs more to load (or compile) than it saves
        padded = rgba
        if nby * bh != h or nbx * bw != w:
            padded = np.pad(rgba, ((0, nby * bh - h), (0, nbx * bw - w), (0, 0)), mode="edge")
        # always a copy: callers may change their blocks, never the caller's image
        return np.array(padded.reshape(nby, bh, nbx, bw, c).transpose(0, 2, 1, 3, 4), order="C").reshape(
            nby * nbx, bh * bw, c)
    out = np.empty((nby * nbx, bh * bw, c), rgba.dtype)
    # as rows of values: a block's row is bw * c consecutive values of an image row
    flat, flat_out = rgba.reshape(h, w * c), out.reshape(nby * nbx, bh * bw * c)
    parallel_for(lambda a, b: _gather_blocks(flat, a, b, bw, bh, c, flat_out), nby, threads,
                 max(1, 16384 // (nbx * bw * bh)))
    return out


@jit
def _gather_blocks(img, by0, by1, bw, bh, c, out):
    """Rows by0..by1-1 of blocks of img (h, w * c) into their places in out
    (nblocks, bh * bw * c); texels past the image's edge repeat its last row
    and column."""
    h = img.shape[0]
    w = img.shape[1] // c
    nbx = (w + bw - 1) // bw
    span = bw * c
    for by in range(by0, by1):
        for y in range(bh):
            row = img[min(by * bh + y, h - 1)]
            base = y * span
            for bx in range(nbx):
                o = out[by * nbx + bx]
                x0 = bx * bw
                if x0 + bw <= w:
                    s0 = x0 * c
                    for i in range(span):
                        o[base + i] = row[s0 + i]
                else:
                    for x in range(bw):
                        s0 = min(x0 + x, w - 1) * c
                        for k in range(c):
                            o[base + x * c + k] = row[s0 + k]


def blocks_to_image(blocks, width, height, bw, bh):
    """Inverse of image_to_blocks, cropping the padding."""
    nbx, nby = block_count(width, bw), block_count(height, bh)
    c = blocks.shape[-1]
    img = blocks.reshape(nby, nbx, bh, bw, c).transpose(0, 2, 1, 3, 4)
    img = img.reshape(nby * bh, nbx * bw, c)
    return np.ascontiguousarray(img[:height, :width])


# Each kernel call is sized to take about this long: Ctrl-C is seen between calls
# (a jitted kernel cannot be interrupted), so an encode stops within about this
# time, and the last calls still even out the threads' load.
CHUNK_SECONDS = 0.05
FIRST_CHUNK = 16  # blocks in the first call, before the rate is known


def run_chunked(kernel, inputs, out, threads, *params, min_chunk=FIRST_CHUNK, also=()):
    """Call kernel(inputs[a:b], out[a:b], *params, *(x[a:b] for x in also))
    over consecutive runs of blocks on `threads` threads (the caller and the
    shared pool's) until all are done (`also`: more per-block arrays, sliced
    like the inputs). Kernels are nogil, so threads run truly in parallel. Each
    thread takes the next run from a shared position and sizes it from its own
    measured rate, and never larger than a share of what is left, so the
    threads finish together. On KeyboardInterrupt (or any error) no new run
    starts; the runs under way finish, then it is raised. Blocks are
    independent, so how the runs fall cannot change a byte."""
    n = inputs.shape[0]
    threads = cpu_threads(threads)
    floor = max(1, int(min_chunk))
    workers = 1 if n <= floor else threads
    position = [0]
    lock = threading.Lock()

    def work(stop):
        size = floor
        while not stop:
            with lock:
                a = position[0]
                # guided: at most half a thread's share of the rest (one
                # thread has no one to share with: its runs are sized by time)
                share = (n - a) // (2 * workers) if workers > 1 else n
                b = min(n, a + min(size, max(floor, share)))
                position[0] = b
            if a >= n:
                return
            t0 = time.perf_counter()
            kernel(inputs[a:b], out[a:b], *params, *(x[a:b] for x in also))
            per_block = (time.perf_counter() - t0) / (b - a)
            size = max(1, min(1 << 16, int(CHUNK_SECONDS / per_block) if per_block > 0 else 1 << 16))

    run_workers(work, workers)
    return out


@dataclass(frozen=True)
class Option:
    """One encoder option a codec declares: the pipeline, the CLI and
    `texcook formats` read these, so a codec's options are listed once."""

    name: str
    type: str  # "bool", "int", "floats" or "choice"
    default: object = None
    min: float = None
    max: float = None
    count: int = None  # "floats": how many numbers
    help: str = ""
    choices: tuple = ()  # "choice": the words it takes

    def check(self, codec_name, value):
        """The value normalised (tuples for lists), or UsageError."""
        bad = f"{codec_name}: option {self.name}"
        if value is None:
            return None
        if self.type == "bool":
            if not isinstance(value, (bool, np.bool_)):
                raise UsageError(f"{bad} must be true or false, not {value!r}")
            return bool(value)
        if self.type == "int":
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise UsageError(f"{bad} must be an integer, not {value!r}")
            if not self.min <= value <= self.max:
                raise UsageError(f"{bad} must be within {self.min}..{self.max}, not {value}")
            return int(value)
        if self.type == "choice":
            if value not in self.choices:
                raise UsageError(f"{bad} must be one of {', '.join(self.choices)}, not {value!r}")
            return value
        # "floats": non-negative weights, not all zero
        try:
            values = tuple(float(v) for v in value)
        except (TypeError, ValueError):
            raise UsageError(f"{bad} must be {self.count} numbers, not {value!r}") from None
        if len(values) != self.count or not all(np.isfinite(values)):
            raise UsageError(f"{bad} must be {self.count} finite numbers, not {value!r}")
        if min(values) < self.min or max(values) <= 0:
            raise UsageError(f"{bad} must be {self.count} numbers >= {self.min}, not all zero, not {value!r}")
        return values

    def facts(self):
        out = {"name": self.name, "type": self.type, "default": self.default, "help": self.help}
        if self.min is not None:
            out["min"] = self.min
        if self.max is not None:
            out["max"] = self.max
        if self.count is not None:
            out["count"] = self.count
        if self.choices:
            out["choices"] = list(self.choices)
        return out


WEIGHTS_RGB = Option("weights", "floats", None, min=0.0, count=3,
                     help="per-channel error weights r,g,b (default equal, what RGB PSNR measures)")


def relative_weights(weights, count):
    """A weights option's values (checked by Option.check: `count` finite
    non-negative numbers, not all zero) as float64 with the largest 1; equal
    weights when None."""
    if weights is None:
        return np.ones(count)
    w = np.asarray(weights, np.float64).reshape(count)
    return w / w.max()

# --normal-metric angular: a normal map searched by the angle of the rebuilt
# normal instead of the X and Y errors (bc5: codecs.bc5_angular; ASTC with
# normal_map: codecs.astc.angular)
ANGULAR = Option("angular", "bool", False,
                 help="normal maps: search for the lowest angular error after Z is rebuilt, "
                      "not the lowest X/Y error (--normal-metric angular)")


@dataclass(frozen=True)
class Codec:
    """The encoder and decoder of one format. Facts come from the format table;
    subclasses implement `_encode_blocks` / `_decode_blocks` (or override
    encode/decode) and declare their options in `options`."""

    format: Format

    presets = PRESETS
    preset_tables = ()  # the codecs._presets tables its search reads
    options = ()  # Option declarations; anything else is refused
    srgb_decode = False  # True: decode(data, w, h, srgb=...) differs for sRGB data
    normal_swizzle = None  # KTXswizzle presenting X, Y in R, G when encoded with normal_map=True
    # seconds a first bake of a 256x256 PNG spends compiling this codec's kernels on a
    # cold cache (each codec module declares its own; docs/performance.md)
    compile_seconds = 10
    # (function, arguments) a second process can run to compile part of what a
    # first encode compiles, into the shared disk cache (texcook prepare runs it
    # beside the codec's own job), or None
    compile_beside = None

    @property
    def normal_layouts(self):
        """How this format can store a normal map, its default first: "xy"
        (X and Y; the reader rebuilds Z) or "xyz" (X, Y, Z in R, G, B)."""
        return {1: (), 2: ("xy",)}.get(self.channels, ("xyz",))

    name = property(lambda self: self.format.name)
    block_w = property(lambda self: self.format.block_w)
    block_h = property(lambda self: self.format.block_h)
    bytes_per_block = property(lambda self: self.format.bytes_per_block)
    channels = property(lambda self: self.format.channels)
    vk_unorm = property(lambda self: self.format.vk_unorm)
    vk_srgb = property(lambda self: self.format.vk_srgb)
    description = property(lambda self: self.format.description)

    @property
    def float_input(self):
        """True: encode takes float32 and decode returns float32; else uint8."""
        return self.format.is_float

    @property
    def is_block_compressed(self):
        return self.format.is_block_compressed

    def vk_format(self, srgb):
        return self.format.vk_format(srgb)

    def blocks_x(self, width):
        return block_count(width, self.block_w)

    def blocks_y(self, height):
        return block_count(height, self.block_h)

    def level_size(self, width, height):
        return self.format.level_size(width, height)

    def check_preset(self, preset):
        if preset not in self.presets:
            raise UsageError(
                f"unknown preset {preset!r} for {self.name}; choose one of {', '.join(self.presets)}"
            )

    def check_options(self, options):
        """Options normalised, defaults filled in; unknown names and values out of
        range are usage errors, for every codec alike."""
        declared = {o.name: o for o in self.options}
        unknown = sorted(set(options) - set(declared))
        if unknown:
            have = ", ".join(declared) or "none"
            raise UsageError(f"{self.name} has no option {', '.join(unknown)} (its options: {have})")
        return {name: o.check(self.name, options.get(name, o.default)) for name, o in declared.items()}

    def check_input(self, rgba):
        want = np.float32 if self.float_input else np.uint8
        if not isinstance(rgba, np.ndarray) or rgba.ndim != 3 or rgba.shape[2] != 4:
            raise UsageError(f"{self.name}.encode wants an (H, W, 4) array")
        if rgba.dtype != want:
            raise UsageError(f"{self.name}.encode wants {np.dtype(want).name}, got {rgba.dtype}")
        if rgba.shape[0] < 1 or rgba.shape[1] < 1:
            raise UsageError(f"{self.name}.encode: empty image")
        return np.ascontiguousarray(rgba)

    def check_data(self, data, width, height):
        need = self.level_size(width, height)
        buf = np.frombuffer(bytes(data), dtype=np.uint8)
        if buf.size != need:
            raise UsageError(
                f"{self.name}: {width}x{height} needs {need} bytes of data, got {buf.size}"
            )
        return buf

    def encoder(self, preset=DEFAULT_PRESET, threads=None, **options):
        """encode(rgba) -> bytes for each level of a texture: the preset and
        options are checked here, once, not again for every level."""
        self.check_preset(preset)
        options = self.check_options(options)

        def encode(rgba):
            return self._encode(self.check_input(rgba), preset, threads, options)

        return encode

    def encode(self, rgba, preset=DEFAULT_PRESET, threads=None, **options) -> bytes:
        return self.encoder(preset, threads, **options)(rgba)

    def _encode(self, rgba, preset, threads, options) -> bytes:
        blocks = image_to_blocks(rgba, self.block_w, self.block_h, threads)
        out = np.zeros((blocks.shape[0], self.bytes_per_block), np.uint8)
        self._encode_blocks(blocks, out, preset, threads, **options)
        return out.tobytes()

    def decode(self, data, width, height) -> np.ndarray:
        buf = self.check_data(data, width, height).reshape(-1, self.bytes_per_block)
        out = np.zeros((buf.shape[0], self.block_w * self.block_h, 4), np.uint8)
        self._decode_blocks(buf, out)
        return blocks_to_image(out, width, height, self.block_w, self.block_h)

    def facts(self):
        return dict(self.format.facts(), presets=list(self.presets),
                    options=[o.facts() for o in self.options])

    def _encode_blocks(self, blocks, out, preset, threads, **options):
        raise NotImplementedError

    def _decode_blocks(self, data, out):
        raise NotImplementedError
