"""BC3 (DXT5): 16-byte blocks, a BC4 block for alpha followed by a BC1 colour block.

BC3's colour block is a BC1 block that must decode the same whether a decoder
treats it as always 4-colour (the D3D rule) or reads the endpoint order (as
texture2ddecoder does), so the encoder only emits c0 > c1, or c0 == c1 with
every index 0.
"""

from dataclasses import dataclass

import numpy as np

from .. import formats
from .._jit import jit
from ._base import WEIGHTS_RGB, Codec, run_chunked
from . import bc1, bc4
from .bc1 import colour_weights
from .bc1_kernels import NO, ZERO, colour_run, decode_colour_block
from .bc4 import decode_single_block, encode_single_run

# Constant arguments to jitted callees are NumPy scalars (see bc1)
ALPHA = np.int64(3)  # the alpha channel, in the block's first 8 bytes
SECOND = np.int64(8)  # byte offset of the colour block
ONE = np.int64(1)


@jit
def _decode_kernel(data, out):
    pal = np.empty((4, 3), np.int64)
    for b in range(data.shape[0]):
        decode_colour_block(data[b], SECOND, out[b], NO, pal)
        decode_single_block(data[b], ZERO, out[b], ALPHA)


def encode_runs(blocks, out, threads, preset, w, sw):
    """BC3 blocks from blocks (n, 16, 4) uint8 into out (n, 16): alpha and
    colour as two runs over the blocks. The colour run is BC1's own kernel
    (the same compiled code), so BC3 compiles no second copy of BC1's search."""
    run_chunked(encode_single_run, blocks, out, threads, bc4.SEARCH.record(preset), ALPHA, ONE)
    run_chunked(colour_run, blocks, out, threads, SECOND, w, sw, bc1.SEARCH.record(preset), ZERO, NO, NO)


def reads_image(preset):
    """True where both of the preset's searches run on the image itself, each
    vectorised across blocks: BC1's quick colour path (bc1_quick) and BC4's
    extremes-only alpha (bc4_quick)."""
    return bool(bc1.SEARCH.row(preset).quick) and bc4.reads_image(preset)


def encode_image(rgba, n, threads, preset, w, sw):
    """(n, 16) BC3 blocks of an image (h, width, 4) uint8 whose searches read
    the image (reads_image): the same bytes as encode_runs on its blocks,
    through BC4's and BC1's own image paths (so BC3 compiles no copy of their
    kernels); alpha and colour go to blocks of 8 bytes each, put side by side
    after."""
    alpha = bc4.fastest_blocks(rgba, n, threads, preset, ALPHA, ONE)
    colour = bc1.quick_blocks(rgba, n, threads, preset, w, sw, ZERO, NO)
    return np.concatenate((alpha, colour), axis=1)


@dataclass(frozen=True)
class BC3Codec(Codec):
    compile_seconds = 8  # CPU s a first 256x256 bake spends compiling (docs/performance.md)
    options = (WEIGHTS_RGB,)
    preset_tables = (bc1.SEARCH, bc4.SEARCH)

    def _encode(self, rgba, preset, threads, options):
        if not reads_image(preset):
            return super()._encode(rgba, preset, threads, options)
        # the quick searches cost about what gathering the blocks first would
        n = self.blocks_x(rgba.shape[1]) * self.blocks_y(rgba.shape[0])
        w, sw = colour_weights(options.get("weights"))
        return encode_image(rgba, n, threads, preset, w, sw).tobytes()

    def _encode_blocks(self, blocks, out, preset, threads, weights=None):
        w, sw = colour_weights(weights)
        encode_runs(blocks, out, threads, preset, w, sw)

    def _decode_blocks(self, data, out):
        _decode_kernel(data, out)


CODECS = {"bc3": BC3Codec(formats.get("bc3"))}
