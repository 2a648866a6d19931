"""BC7 (BPTC UNORM): 4x4 blocks of 16 bytes in eight modes.

Decoding
--------
The Khronos Data Format Specification's BPTC decoding, exactly: endpoints
expand to 8 bits (p-bit appended, top bits replicated), each channel is
((64 - w) * e0 + w * e1 + 32) >> 6 with the 2-, 3- or 4-bit weight table,
modes 0-3 decode alpha as 255, modes 4 and 5 swap alpha with R, G or B
after decoding (rotation). A block whose first byte is 0 (reserved mode)
decodes to 0 in every channel, alpha included, as the specification asks
(texture2ddecoder does the same). bc7_kernels holds the symbolic block, the
bits and the decoder.

Encoder
-------
The search (bc7_search) fills a symbolic block (mode, partition, rotation,
index selector, endpoints, p-bits, indices), then the anchor rule is
established (endpoints swapped, indices mirrored where an anchor's top bit
would be 1) and the block packed. Per block:

- a constant block is mode 5 with each colour channel at index 1 of an
  endpoint pair from a single-colour table and alpha in the 8-bit endpoints:
  exact for every RGBA value;
- a block whose alpha is one value throughout (all opaque, all transparent)
  keeps it exactly: modes 6 and 7 take its low bit as both p-bits, and any
  other candidate that would change it is refused;
- opaque blocks try the modes in ``opaque_modes``, blocks with any alpha
  below 255 those in ``alpha_modes`` (bit k = mode k); modes 0-3 pay for the
  alpha they cannot store, so the choice is by the true error either way;
- single-subset modes go first; a mode with partitions ranks all of them
  (16 for mode 0, else 64) by a quick estimate (each subset's distance from
  its principal axis plus the rounding to the index steps along it) and fits
  the best ``partitions``, with ``prune`` only while the estimate is below
  that percentage of the best error so far;
- modes 4 and 5 try every rotation (``rotations``) and, in mode 4, both
  index selectors;
- each subset: principal axis by power iteration (``power_iters``), range
  fit along it, endpoints quantised with the p-bits chosen by their own
  rounding error or, with ``pbits``, every p-bit combination measured; then
  up to ``ls_iters`` rounds of least-squares endpoints from the indices,
  while they lower the error;
- the chosen block's endpoints are then hill-climbed (``climb`` passes: each
  stored channel one step either way, each p-bit flipped, kept if better).

Every candidate is measured exactly on the decoded palette; its indices
are the nearest entries, among all (``every_index``) or among the three
around each texel's projection on the line through the end entries. The error is the sum of squared channel
differences weighted by ``weights=(r, g, b)`` (default equal; alpha weighs
as much as the heaviest colour channel), which with equal weights is what
RGBA PSNR measures. Blocks are independent and ties keep the earlier
candidate, so the bytes do not depend on the thread count.
"""

from dataclasses import dataclass

import numpy as np

from .. import formats
from ._base import WEIGHTS_RGB, Codec, relative_weights, run_chunked
from ._presets import PresetTable
from .bc7_kernels import SYM_LEN, decode_run
from .bc7_search import encode_run


def _modes(*modes):
    return sum(1 << m for m in modes)


SEARCH = PresetTable(
    "bc7",
    columns={
        "opaque_modes": "modes tried for opaque blocks (bit k: mode k)",
        "alpha_modes": "modes tried for blocks with alpha (bit k: mode k)",
        "partitions": "partitions fitted per partitioned mode, best estimates first",
        "power_iters": "power-iteration steps for each subset's axis",
        "ls_iters": "least-squares refinement rounds per subset",
        "pbits": "1: measure every p-bit combination, 0: pick them by rounding error",
        "rotations": "1: modes 4 and 5 try all four rotations, 0: none",
        "every_index": "1: each texel's index from every palette entry, 0: from the 3 around its projection",
        "prune": "0, or fit a partition only while its estimate is below this percentage of the best error",
        "climb": "hill-climbing passes over the chosen block's stored endpoints (one step, p-bit flips)",
    },
    rows={
        # modes: bit k tries mode k      partitions, power_iters, ls_iters, pbits, rotations, every_index,
        #                                prune, climb
        #             opaque_modes                  alpha_modes
        "fastest":    (_modes(1, 3, 6),             _modes(5, 6),       1, 2, 0, 0, 0, 0, 100, 0),
        "fast":       (_modes(1, 3, 6),             _modes(4, 5, 6, 7), 1, 3, 1, 0, 0, 0, 100, 0),
        "medium":     (_modes(0, 1, 2, 3, 6),       _modes(4, 5, 6, 7), 6, 4, 3, 1, 1, 0, 200, 2),
        "thorough":   (_modes(0, 1, 2, 3, 4, 5, 6), _modes(4, 5, 6, 7), 16, 6, 4, 1, 1, 1, 0, 2),
        "exhaustive": (_modes(0, 1, 2, 3, 4, 5, 6), _modes(4, 5, 6, 7), 64, 8, 8, 1, 1, 1, 0, 8),
    },
)


# mode 6 in every row: its bounding-box fit is the candidate that keeps every
# block at least as good as the trivial fit (and a flat alpha exact)
if not all(SEARCH.row(p).opaque_modes >> 6 & SEARCH.row(p).alpha_modes >> 6 & 1 for p in SEARCH.presets):
    raise ValueError("bc7 presets: every row must try mode 6")

# encode_run's outputs for the tests' view of the search, left empty by the codec
NO_SYMS = np.zeros((0, SYM_LEN), np.int64)
NO_ERRS = np.zeros(0)


def channel_weights(weights):
    """(w, sqrt(w)) float64 (4,): r, g, b from the weights option (largest 1),
    alpha 1. A zero weight becomes 1/1000: the axis search divides by its root."""
    w = np.ones(4)
    w[:3] = np.maximum(relative_weights(weights, 3), 1e-3)
    return w, np.sqrt(w)


@dataclass(frozen=True)
class BC7Codec(Codec):
    options = (WEIGHTS_RGB,)
    preset_tables = (SEARCH,)
    # cold minus warm CPU time of a 256x256 RGBA bake: 18.3 s against 0.9 s (docs/bc.md)
    compile_seconds = 17

    def _encode_blocks(self, blocks, out, preset, threads, weights=None):
        w, sw = channel_weights(weights)
        run_chunked(encode_run, blocks, out, threads, w, sw, SEARCH.record(preset), NO_SYMS, NO_ERRS)

    def _decode_blocks(self, data, out):
        decode_run(data, out)


CODECS = {"bc7": BC7Codec(formats.get("bc7"))}
