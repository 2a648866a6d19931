"""BC6H: half-float RGB in 4x4 blocks of 16 bytes, unsigned (`bc6h`,
BC6H_UFLOAT) and signed (`bc6h-sf`, BC6H_SFLOAT).

Decoding
--------
All 14 modes as the Khronos Data Format Specification's BPTC float section
reads them (codecs/bc6h_kernels.decode_block): endpoints from the mode's bit
layout, signed deltas added to the base in transformed modes (wrapping at the
base precision, sign-extended in the signed format), unquantised to 16 bits,
interpolated with the 3- or 4-bit index weights, scaled by 31/64 (unsigned) or
31/32 (signed) into the half float's bit pattern. Reserved mode numbers
decode to 0. decode returns float32 RGBA with alpha 1.

Encoding
--------
Input floats become half floats (round to nearest); for the unsigned format
negative values, NaN and -Inf become 0, and +Inf or values above 65504 become
65504 (the bake pipeline refuses NaN, Inf and out-of-range values first, and
counts the negatives it clamps). The search works on the half's bit pattern
as an integer, where the decoder's interpolation is linear and which is a
piecewise-linear log2 of the value (1024 steps per octave): every candidate is
measured exactly with the decoder's arithmetic, by the squared difference of
those integers (see docs/bc.md for why this space).

Per block: one region (modes 11-14) from the principal axis of the texels,
then two regions: the 32 shapes ranked by what a line per region leaves
unexplained, and on the best ``partitions`` shapes the two-region modes,
finest base precision first, skipping those whose deltas cannot reach the
endpoints (``modes`` of them; all ten in ``exhaustive``). A try quantises the endpoints (deltas clamped to
what the mode stores), keeps the anchor texels to their half of the indices by
orienting each region's endpoints, and assigns every texel its best index;
the best ``refine`` tries are refined by least squares from their indices,
and the winner's codes are nudged one step at a time while the error drops
(``climb``).
"""

from dataclasses import dataclass

import numpy as np

from .. import formats
from ._base import Codec, blocks_to_image, image_to_blocks, run_chunked
from ._presets import PresetTable
from .bc6h_kernels import decode_run, encode_run
from .bc6h_tables import HALF_MAX

SEARCH = PresetTable(
    "bc6h",
    columns={
        "partitions": "two-region shapes (of 32, best first by a line fit) the two-region modes are tried on",
        "modes": "two-region modes tried per shape, finest first among those whose deltas fit (10: all)",
        "refine": "the best (mode, shape) pairs of those tries refined further",
        "ls_iters": "least-squares refinement rounds of a refined pair's endpoints",
        "power_iters": "power-iteration steps for each region's principal axis",
        "climb": "0 none, else passes of one-step moves of the winning block's endpoint codes",
    },
    rows={
        #              partitions modes refine ls_iters power_iters climb
        "fastest":    (1,         2,    1,     1,       2,          0),
        "fast":       (2,         3,    2,     2,       3,          1),
        "medium":     (4,         3,    3,     2,       4,          1),
        "thorough":   (8,         5,    6,     3,       6,          2),
        "exhaustive": (32,        10,   16,    4,       8,          8),
    },
)


def finished_values(rgba, signed):
    """float32 (..., >=3) -> int64 (..., 3): each of R, G, B as a half float's
    bit pattern read as a signed integer (sign and magnitude), the domain the
    kernels search in. Unsigned: negatives, NaN and -Inf to 0; both: +-Inf
    and magnitudes beyond 65504 to +-65504, NaN to 0."""
    x = np.nan_to_num(np.asarray(rgba[..., :3], np.float32), nan=0.0, posinf=65504.0, neginf=-65504.0)
    if not signed:
        x = np.maximum(x, 0.0)
    x = np.clip(x, -65504.0, 65504.0)
    bits = x.astype(np.float16).view(np.uint16).astype(np.int64)
    mag = np.minimum(bits & 0x7FFF, HALF_MAX)
    return np.where(bits & 0x8000, -mag, mag)


@dataclass(frozen=True)
class BC6HCodec(Codec):
    compile_seconds = 15  # CPU s a first 256x256 bake spends compiling (docs/performance.md)
    signed: bool = False
    preset_tables = (SEARCH,)

    def _encode(self, rgba, preset, threads, options) -> bytes:
        blocks = image_to_blocks(finished_values(rgba, self.signed), 4, 4, threads)
        out = np.zeros((blocks.shape[0], 16), np.uint8)
        run_chunked(encode_run, blocks, out, threads, np.bool_(self.signed), SEARCH.record(preset))
        return out.tobytes()

    def decode_half(self, data, width, height) -> np.ndarray:
        """The decoded texels as float16 (H, W, 3), exactly as stored."""
        buf = self.check_data(data, width, height).reshape(-1, 16)
        bits = np.zeros((buf.shape[0], 16, 3), np.uint16)
        decode_run(buf, bits, np.bool_(self.signed))
        return blocks_to_image(bits, width, height, 4, 4).view(np.float16)

    def decode(self, data, width, height) -> np.ndarray:
        half = self.decode_half(data, width, height)
        out = np.ones((height, width, 4), np.float32)
        out[..., :3] = half
        return out


CODECS = {
    "bc6h": BC6HCodec(formats.get("bc6h")),
    "bc6h-sf": BC6HCodec(formats.get("bc6h-sf"), signed=True),
}
