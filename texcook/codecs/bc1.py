"""BC1 (DXT1): 4x4 blocks of 8 bytes, two RGB565 endpoints and 2-bit indices.

Decoding convention
-------------------
Endpoints expand to 8 bits by bit replication; the interpolated colours are
computed on the 8-bit values with truncating integer division:

    c0 > c1 (as u16):  c2 = (2*c0 + c1) // 3,  c3 = (c0 + 2*c1) // 3
    c0 <= c1:          c2 = (c0 + c1) // 2,    c3 = black (transparent in BC1A)

This is the exact KDF formula rounded down, the rule texture2ddecoder
implements (checked bit for bit in the tests). It is no single GPU vendor's:
NVIDIA hardware interpolates from the 5/6-bit values and AMD uses
(43*a + 21*b + 32) >> 6, so on those GPUs a texel can differ by one or two
levels. The encoder measures every candidate with this decoding, so it is
the one the encoder optimises for.

Encoder
-------
A block is searched for a pair of 565 endpoints and a mode; the search grows
with the preset (see ``SEARCH``):

- constant colours use tables of the best endpoint pair for each 8-bit value
  and channel width (per mode), so a flat colour comes back as close as BC1
  allows;
- principal axis by power iteration on the covariance (from moments summed
  while the texels are gathered), range fit along it: only the extreme
  projections, no sort;
- least-squares refinement of the endpoints from the chosen indices
  (repeated while it helps, stopping when a pair repeats);
- cluster fit: every ordered split of the texels sorted along the axis into
  4 (or 3) groups, endpoints solved by least squares for each;
- hill climbing over the quantised endpoints (one 565 step at a time), each
  candidate measured with the exact decoding above; ``exhaustive`` also moves
  the endpoints apart and together, climbs again from the next-best cluster
  fit pairs, and tries 3-colour cluster fits with the darkest texels left to
  the black entry.

Every candidate is measured exactly: the error of a texel against a palette
entry q is |x|^2 + (|q|^2 - 2 x.q), so with the block's sum of |x|^2 known a
texel costs one dot product per entry.

The 3-colour mode (c0 <= c1) is tried per block when the preset allows and
kept when it lowers the error; in plain BC1 its black entry is usable as a
fourth colour, in BC1A it marks transparent texels (alpha < threshold).

Error is a weighted sum of squared channel differences; ``weights=(r, g, b)``
changes it. The default is (1, 1, 1), which maximises RGB PSNR.
"""

from dataclasses import dataclass

import numpy as np

from .. import formats
from ._base import WEIGHTS_RGB, Codec, Option, relative_weights, run_chunked
from ._presets import PresetTable
from .bc1_kernels import YES, ZERO, colour_run, decode_run
from .bc1_quick import integer_weights, quick_image

# blocks per kernel call of the quick path, at least (see BC1Codec._encode)
QUICK_RUN = 4096


def quick_blocks(rgba, n, threads, preset, w, sw, thr, three_colour):
    """(n, 8) BC1 blocks of an image (h, width, 4) uint8 by the preset's quick
    search (its row's `quick`), read from the image itself."""
    h, wd = rgba.shape[:2]
    out = np.empty((n, 8), np.uint8)
    row = SEARCH.row(preset)
    run_chunked(quick_image, np.arange(n, dtype=np.int64), out, threads, rgba.reshape(h, wd * 4).view(np.uint32),
                w, integer_weights(w), sw, np.int64(row.power_iters), np.int64(row.ls_iters), thr, three_colour,
                min_chunk=QUICK_RUN)
    return out


SEARCH = PresetTable(
    "bc1",
    columns={
        "power_iters": "power-iteration steps for the principal axis",
        "ls_iters": "least-squares refinement rounds after a fit",
        "three_colour": "1: try the 3-colour mode",
        "cluster": "0 none, 1 cluster fit (best estimate), 2 measure every split exactly",
        "climb": "0 none, else maximum hill-climbing passes over the endpoints",
        "mean_colour": "1: try the block's mean through the single-colour tables",
        "wide": "1: climbing also moves the endpoints apart or together",
        "starts": "climb again from this many next-best exact cluster-fit pairs",
        "dark": "exact 3-colour cluster fits leaving up to this many dark texels to black",
        "quick": "1: one pass per block (bc1_quick: axis extent, indices by counting along the "
                 "endpoint line, ls_iters refits); the columns after ls_iters are unused",
    },
    rows={
        #              power_iters ls_iters three_colour cluster climb mean_colour wide starts dark quick
        "fastest":    (1,          0,       0,           0,      0,    0,          0,   0,     0,   1),
        "fast":       (2,          3,       0,           0,      0,    0,          0,   0,     0,   0),
        "medium":     (6,          4,       1,           0,      2,    1,          0,   0,     0,   0),
        "thorough":   (8,          4,       1,           1,      4,    1,          0,   0,     0,   0),
        "exhaustive": (8,          8,       1,           2,      32,   1,          1,   4,     4,   0),
    },
)


def colour_weights(weights):
    """(w, sqrt(w)) float64 arrays from the weights option; default (1, 1, 1)."""
    # a zero weight becomes 1/1000 of the largest: the search still needs a
    # direction in that channel (it divides by the square root of the weight)
    w = np.maximum(relative_weights(weights, 3), 1e-3)
    return w, np.sqrt(w)


@dataclass(frozen=True)
class BC1Codec(Codec):
    compile_seconds = 5  # CPU s a first 256x256 bake spends compiling (docs/performance.md)
    punch_through: bool = False
    preset_tables = (SEARCH,)

    @property
    def options(self):
        if self.punch_through:
            return (WEIGHTS_RGB, ALPHA_THRESHOLD)
        return (WEIGHTS_RGB, OPAQUE_BLACK)

    def _encode(self, rgba, preset, threads, options):
        if not SEARCH.row(preset).quick:
            return super()._encode(rgba, preset, threads, options)
        # the quick path reads its blocks from the image: gathering them first
        # would take about a third of its time. At about 40 ns a block, what
        # each call costs in Python matters: the weights are made once, the
        # row is read as a tuple, and runs are at least QUICK_RUN blocks (one
        # call for a 256x256 level; still well under CHUNK_SECONDS)
        n = self.blocks_x(rgba.shape[1]) * self.blocks_y(rgba.shape[0])
        w, sw, thr, _ = self._params(**options)
        return quick_blocks(rgba, n, threads, preset, w, sw, thr, YES).tobytes()

    def _params(self, weights=None, alpha_threshold=128, opaque_black=True):
        w, sw = colour_weights(weights)
        thr = int(alpha_threshold) if self.punch_through else 0
        return w, sw, np.int64(thr), np.bool_(bool(opaque_black) and not self.punch_through)

    def _encode_blocks(self, blocks, out, preset, threads, weights=None, alpha_threshold=128,
                       opaque_black=True):
        w, sw, thr, black = self._params(weights, alpha_threshold, opaque_black)
        run_chunked(colour_run, blocks, out, threads, ZERO, w, sw, SEARCH.record(preset), thr, YES, black)

    def _decode_blocks(self, data, out):
        decode_run(data, out, self.punch_through)


# Plain BC1 may use the 3-colour mode's black entry as a colour: Vulkan's
# BC1_RGB reads it opaque, but Direct3D has only BC1-with-alpha and reads it
# transparent, so DDS output turns it off (the DDS row's codec defaults in container.table).
OPAQUE_BLACK = Option("opaque_black", "bool", True,
                      help="use the 3-colour mode's black as an opaque colour (off for DDS)")
ALPHA_THRESHOLD = Option("alpha_threshold", "int", 128, min=0, max=256,
                         help="alpha below this becomes transparent (set from --alpha-cutoff)")

CODECS = {
    "bc1": BC1Codec(formats.get("bc1")),
    "bc1a": BC1Codec(formats.get("bc1a"), punch_through=True),
}
