"""What every codec shares: the interface, block extraction with edge-replicated
padding, and deterministic multi-threading over blocks.

A codec's jitted kernels work on a run of blocks:

    encode_kernel(blocks: uint8 (n, bh*bw, 4), out: uint8 (n, bytes_per_block), *params)
    decode_kernel(data: uint8 (n, bytes_per_block), out: uint8 (n, bh*bw, 4))

Texels inside a block are in row-major order (index = y * bw + x). Blocks are
independent, so splitting the run into chunks for threads cannot change a byte.
"""

import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from ..errors import UsageError

PRESETS = ("fastest", "fast", "medium", "thorough", "exhaustive")


def cpu_threads(threads):
    if threads is None:
        return os.cpu_count() or 1
    if threads < 1:
        raise UsageError(f"threads must be at least 1, not {threads}")
    return int(threads)


def image_to_blocks(rgba, bw, bh):
    """(H, W, C) -> (nblocks, bh*bw, C), blocks in row-major order. Partial blocks
    are padded by replicating the last row and column, never with zeros, so padding
    adds no colour the encoder must spend precision on."""
    h, w, c = rgba.shape
    nbx = -(-w // bw)
    nby = -(-h // bh)
    pad_y = nby * bh - h
    pad_x = nbx * bw - w
    if pad_x or pad_y:
        rgba = np.pad(rgba, ((0, pad_y), (0, pad_x), (0, 0)), mode="edge")
    blocks = rgba.reshape(nby, bh, nbx, bw, c).transpose(0, 2, 1, 3, 4)
    return np.ascontiguousarray(blocks.reshape(nby * nbx, bh * bw, c))


def blocks_to_image(blocks, width, height, bw, bh):
    """Inverse of image_to_blocks, cropping the padding."""
    nbx = -(-width // bw)
    nby = -(-height // bh)
    c = blocks.shape[-1]
    img = blocks.reshape(nby, nbx, bh, bw, c).transpose(0, 2, 1, 3, 4)
    img = img.reshape(nby * bh, nbx * bw, c)
    return np.ascontiguousarray(img[:height, :width])


# Each kernel call is sized to take about this long: Ctrl-C is seen between calls
# (a jitted kernel cannot be interrupted), so an encode stops within about this
# time, and the last calls still even out the threads' load.
CHUNK_SECONDS = 0.05
FIRST_CHUNK = 16  # blocks in the first call, before the rate is known


def run_chunked(kernel, inputs, out, threads, *params, min_chunk=FIRST_CHUNK):
    """Call kernel(inputs[a:b], out[a:b], *params) over consecutive runs of
    blocks on `threads` threads until all are done. Kernels are nogil, so
    threads run truly in parallel. Each thread takes the next run from a shared
    position and sizes it from its own measured rate. On KeyboardInterrupt (or
    any error) no new run starts; the runs under way finish, then it is raised.
    Blocks are independent, so how the runs fall cannot change a byte."""
    n = inputs.shape[0]
    threads = cpu_threads(threads)
    position = [0]
    lock = threading.Lock()
    stop = threading.Event()

    def work():
        size = max(1, int(min_chunk))
        while not stop.is_set():
            with lock:
                a = position[0]
                b = min(n, a + size)
                position[0] = b
            if a >= n:
                return
            t0 = time.perf_counter()
            try:
                kernel(inputs[a:b], out[a:b], *params)
            except BaseException:
                stop.set()  # the other threads start no new run
                raise
            per_block = (time.perf_counter() - t0) / (b - a)
            size = max(1, min(1 << 16, int(CHUNK_SECONDS / per_block) if per_block > 0 else 1 << 16))

    if threads == 1 or n <= min_chunk:
        work()
        return out
    pool = ThreadPoolExecutor(max_workers=threads)
    try:
        futures = [pool.submit(work) for _ in range(threads)]
        for f in futures:
            f.result()
    except BaseException:
        stop.set()
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
    return out


@dataclass(frozen=True)
class Codec:
    """One texture format. Subclasses set the fields and implement
    `_encode_blocks` / `_decode_blocks` (or override encode/decode)."""

    name: str
    block_w: int
    block_h: int
    bytes_per_block: int
    channels: int  # channels the format stores (1..4)
    vk_unorm: int
    vk_srgb: int = 0  # 0 when the format has no sRGB twin
    float_input: bool = False  # True: encode takes float32, decode returns float32
    description: str = ""

    presets = PRESETS

    @property
    def is_block_compressed(self):
        return self.block_w > 1 or self.block_h > 1

    def vk_format(self, srgb):
        if srgb and not self.vk_srgb:
            raise UsageError(f"format {self.name} has no sRGB variant; use --linear")
        return self.vk_srgb if srgb else self.vk_unorm

    def blocks_x(self, width):
        return -(-width // self.block_w)

    def blocks_y(self, height):
        return -(-height // self.block_h)

    def level_size(self, width, height):
        return self.blocks_x(width) * self.blocks_y(height) * self.bytes_per_block

    def check_preset(self, preset):
        if preset not in self.presets:
            raise UsageError(
                f"unknown preset {preset!r} for {self.name}; choose one of {', '.join(self.presets)}"
            )

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

    def encode(self, rgba, preset="medium", threads=None, **options) -> bytes:
        self.check_preset(preset)
        rgba = self.check_input(rgba)
        blocks = image_to_blocks(rgba, self.block_w, self.block_h)
        out = np.zeros((blocks.shape[0], self.bytes_per_block), np.uint8)
        self._encode_blocks(blocks, out, preset, threads, **options)
        return out.tobytes()

    def decode(self, data, width, height) -> np.ndarray:
        buf = self.check_data(data, width, height).reshape(-1, self.bytes_per_block)
        out = np.zeros((buf.shape[0], self.block_w * self.block_h, 4), np.uint8)
        self._decode_blocks(buf, out)
        return blocks_to_image(out, width, height, self.block_w, self.block_h)

    def _encode_blocks(self, blocks, out, preset, threads, **options):
        raise NotImplementedError

    def _decode_blocks(self, data, out):
        raise NotImplementedError
