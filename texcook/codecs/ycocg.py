"""bc3-ycocg: scaled YCoCg-DXT5 (van Waveren and Castano, "Real-Time YCoCg-DXT
Compression", 2007), RGB at BC3's size with more colour precision than BC1.

Luma goes to the BC3 alpha block (eight interpolated 8-bit values, where the eye
is most sensitive); the chroma differences Co and Cg go to the colour block's
red and green, multiplied per block by s in {1, 2, 4} so that low-chroma blocks
use more of the endpoints' 5 and 6 bits; blue holds s - 1 as a constant 5-bit
value. `texcook.transforms.ycocg_layout` makes the layout and `ycocg_rgb` is the
shader's reconstruction (both documented there and in docs/quality.md).

The file is plain BC3 (vkFormat 137) with a "ycocg" step in the texcook.transforms
key/value; readers decode BC3 and undo the step. This codec's encode takes RGB
and its decode returns RGB, like every codec.

The blocks are encoded with BC3's own block encoders (texcook.codecs.bc1 and
bc4). Colour error is weighted 2 on Co and 3 on Cg, the weights an error in each
carries into RGB's squared error (an error e in Co moves R and B by e; in Cg
moves all three). Blue is then pinned to the block's scale code: the encoders
never gain by moving it, but a reader divides by it, so it must be exact.
"""

from dataclasses import dataclass

import numpy as np

from .. import formats
from .._jit import jit
from ..colour import quantize_unorm8
from ..transforms import ycocg_layout, ycocg_rgb
from ._base import Codec, image_to_blocks, run_chunked
from . import bc1, bc4
from .bc1 import colour_weights
from .bc1_kernels import NO, ZERO, colour_run
from .bc3 import ALPHA, ONE, SECOND
from .bc3 import CODECS as BC3_CODECS
from .bc4 import encode_single_run

CHROMA_WEIGHTS = (2.0, 3.0, 1.0)


@jit
def _pin_blue(blue, out, o):
    """Set both endpoints' 5-bit blue to `blue`, keeping the decoded red and
    green: reorder to c0 > c1 (swapping the indices' meaning), or all index 0
    when the endpoints become equal."""
    c0 = (np.int64(out[o]) | (np.int64(out[o + 1]) << 8)) & ~np.int64(31) | blue
    c1 = (np.int64(out[o + 2]) | (np.int64(out[o + 3]) << 8)) & ~np.int64(31) | blue
    bits = (np.int64(out[o + 4]) | (np.int64(out[o + 5]) << 8) | (np.int64(out[o + 6]) << 16)
            | (np.int64(out[o + 7]) << 24))
    if c0 < c1:
        c0, c1 = c1, c0
        bits ^= np.int64(0x55555555)  # 0 <-> 1 and 2 <-> 3: the same colours after the swap
    elif c0 == c1:
        bits = np.int64(0)
    out[o] = c0 & 255
    out[o + 1] = c0 >> 8
    out[o + 2] = c1 & 255
    out[o + 3] = c1 >> 8
    for k in range(4):
        out[o + 4 + k] = (bits >> (8 * k)) & 255


@jit
def _pin_blue_run(blocks, out):
    for b in range(blocks.shape[0]):
        _pin_blue(np.int64(blocks[b, 0, 2]) >> 3, out[b], SECOND)


def _encode_run(blocks, out, alpha_rec, colour_rec, w, sw):
    # BC3's two runs (see bc3.encode_runs), then blue pinned block by block
    encode_single_run(blocks, out, alpha_rec, ALPHA, ONE)
    colour_run(blocks, out, SECOND, w, sw, colour_rec, ZERO, NO, NO)
    _pin_blue_run(blocks, out)


@dataclass(frozen=True)
class YCoCgCodec(Codec):
    compile_seconds = 8  # CPU s a first 256x256 bake spends compiling (docs/performance.md)
    preset_tables = (bc1.SEARCH, bc4.SEARCH)

    def _encode(self, rgba, preset, threads, options):
        layout = quantize_unorm8(ycocg_layout(rgba.astype(np.float32) / 255.0))
        blocks = image_to_blocks(layout, self.block_w, self.block_h, threads)
        out = np.zeros((blocks.shape[0], self.bytes_per_block), np.uint8)
        w, sw = colour_weights(CHROMA_WEIGHTS)
        run_chunked(_encode_run, blocks, out, threads, bc4.SEARCH.record(preset), bc1.SEARCH.record(preset), w, sw)
        return out.tobytes()

    def decode_layout(self, data, width, height):
        """The stored BC3 texels (Co, Cg, scale code, Y) as uint8, before reconstruction."""
        return BC3_CODECS["bc3"].decode(data, width, height)

    def decode(self, data, width, height):
        return quantize_unorm8(ycocg_rgb(self.decode_layout(data, width, height).astype(np.float32) / 255.0))


CODECS = {"bc3-ycocg": YCoCgCodec(formats.get("bc3-ycocg"))}
