"""ETC1: 4x4 RGB blocks of 64 bits, stored in KTX2 as ETC2_R8G8B8 (ETC2 decodes
every valid ETC1 block the same way).

Each block is two 2x4 or 4x2 sub-blocks (the flip bit), each with a base colour
(4-bit individual or 5-bit differential with 3-bit deltas) and one of eight
modifier tables; every texel adds one of the table's four offsets to all three
channels of its sub-block's base.

Presets (every one picks texel selectors exactly, clamping included, and
encodes a one-colour block as well as ETC1 can; all but fastest pick tables
exactly too):

- fastest: flip chosen from how well the sub-block averages fit; differential
  mode when the 5-bit averages fit the deltas (else the better of a clamped
  differential pair and individual mode); bases are quantised averages; the
  tables are estimated without clamping (exact selectors), one pass per block.
- fast: both flips, both modes; the quantised average, then one re-centring of
  the base on its selectors (the best base for fixed selectors is the average
  minus the mean modifier, a move along the grey axis).
- medium: as fast, trying every floor/ceiling rounding of each channel around
  each target rather than only the nearest code.
- thorough: as medium, plus one target per modifier table (the average moved
  to that table's optimum).
- exhaustive: as thorough with a +-1 code lattice around every target, two
  re-centring rounds, and differential pairs searched with one sub-block held
  at its best and the other constrained to the delta range.

Option `weights=(r, g, b)`: per-channel error weights (None = uniform, which is
what RGB PSNR measures; (0.299, 0.587, 0.114) for a luma-weighted fit).
"""

from dataclasses import dataclass

import numpy as np

from . import etc1_kernels as K
from .. import formats
from ._base import WEIGHTS_RGB, Codec, relative_weights, run_chunked
from ._presets import PresetTable


SEARCH = PresetTable(
    "etc1",
    columns={
        "fast_path": "1: pick flip and mode from sub-block averages before searching",
        "table_seeds": "1: add one seed per table (base refined for that table)",
        "radius": "lattice radius around each seed, in quantised steps",
        "refine": "rounds of re-centring the base on the chosen selectors",
        "refine_radius": "lattice radius around each re-centred base",
        "constrained": "1: always try differential pairs inside the delta box",
        "box": "1: try every floor/ceiling code combination around each target",
    },
    rows={
        #              fast_path table_seeds radius refine refine_radius constrained box
        "fastest":    (1,        0,          0,     0,     0,            0,          0),
        "fast":       (0,        0,          0,     1,     0,            0,          0),
        "medium":     (0,        0,          0,     1,     0,            0,          1),
        "thorough":   (0,        1,          0,     1,     0,            0,          1),
        "exhaustive": (0,        1,          1,     2,     0,            1,          1),
    },
)

WEIGHT_SCALE = 64  # largest weight after scaling to integers


def integer_weights(weights):
    """(r, g, b) floats -> int64 weights with the largest at WEIGHT_SCALE."""
    if weights is None:
        return np.ones(3, np.int64)
    return np.maximum(np.rint(relative_weights(weights, 3) * WEIGHT_SCALE), 0).astype(np.int64)


@dataclass(frozen=True)
class ETC1Codec(Codec):
    compile_seconds = 7  # CPU s a first 256x256 bake spends compiling (docs/performance.md)
    options = (WEIGHTS_RGB,)
    preset_tables = (SEARCH,)

    def _encode_blocks(self, blocks, out, preset, threads, weights=None):
        w = integer_weights(weights)
        run_chunked(K.encode_blocks, blocks, out, threads, SEARCH.record(preset), w)

    def _decode_blocks(self, data, out):
        K.decode_blocks(np.ascontiguousarray(data), out)


CODECS = {"etc1": ETC1Codec(formats.get("etc1"))}
