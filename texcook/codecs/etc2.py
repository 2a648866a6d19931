"""ETC2 RGB (`etc2`) and ETC2 RGB with punch-through alpha (`etc2a1`): 4x4
blocks of 64 bits.

ETC2 RGB decodes every ETC1 block as ETC1 does and adds three modes in the
differential blocks whose base-plus-delta would leave 0..31 (red: T, green:
H, blue: planar):

- T and H: two 4-bit base colours and a distance d from {3, 6, 11, 16, 23,
  32, 41, 64}; four paint colours (T: the first base, and the second base
  plus d, plus 0, minus d; H: each base plus and minus d), each texel
  picking one with 2 bits. For blocks of two separate colour groups.
- planar: colours O, H and V (6, 7, 6 bits for R, G, B) at the block's
  corners, interpolated linearly; for smooth gradients ETC1 bands.

The punch-through format has no individual mode: bit 33 says whether the
block is opaque. With it 0, differential blocks lose the modifier +-a (0
instead) and their selector 2 is transparent black, as is index 2 of T and H
blocks; planar blocks are always opaque. Texels whose alpha is below
`alpha_threshold` (from --alpha-cutoff, 128 by default, as for bc1a) are
made transparent and the rest opaque, so coverage at the cutoff is kept
exactly.

Encoder: the ETC1 search (texcook.codecs.etc1, same preset) encodes every
block first; an ETC1 block is a valid ETC2 block, and a planar, T or H block
replaces it only when its error is strictly lower, so an ETC2 stream is
never worse than the ETC1 stream of the same preset. Punch-through blocks
with transparent texels are searched in the modes that can hold them; an
opaque block whose ETC1 encoding is in individual mode is moved into
differential mode first. Presets (`SEARCH`):

- planar: the least-squares fit of O, H and V per channel, rounded (1), or
  with every code within one step of it (2);
- T and H: the opaque texels split in two along their principal axis, at the
  mean (th 1) or at every position (th 2), the groups' quantised means
  tried as either base with every distance; then rounds re-fitting the bases
  to the chosen paint colours (th_refine), with every floor/ceiling code
  combination (th_box).

Option `weights=(r, g, b)`: per-channel error weights, as for etc1.
"""

from collections import namedtuple
from dataclasses import dataclass

import numpy as np

from .. import formats
from . import etc1
from . import etc1_kernels as K1
from . import etc2_kernels as K
from ._base import WEIGHTS_RGB, Codec, run_chunked
from ._presets import PresetTable
from .bc1 import ALPHA_THRESHOLD
from .etc1_tables import SYM_LEN
from .etc2_tables import E_LEN

SEARCH = PresetTable(
    "etc2",
    columns={
        "planar": "0 no planar mode; 1 the rounded least-squares fit; 2 every code within one step of it",
        "th": "0 no T/H modes; 1 split the texels at the mean of their principal axis; 2 at every position",
        "th_refine": "rounds of re-fitting the T/H base colours to their paint colours",
        "th_box": "1: re-fitting (and punch-through differential bases) try every floor/ceiling code",
    },
    rows={
        #              planar th th_refine th_box
        "fastest":    (1,     0, 0,        0),
        "fast":       (2,     1, 1,        0),
        "medium":     (2,     1, 2,        1),
        "thorough":   (2,     2, 2,        1),
        "exhaustive": (2,     2, 4,        1),
    },
)

# improve_blocks' per-thread working arrays (made here: numba's own allocation
# compiles a routine per shape and dtype): px/trans the block's texels and
# which are transparent; sym/e/eb/tmp/texels/pal blocks being built or
# decoded; the rest the T/H and differential searches' small vectors.
Scratch = namedtuple("Scratch", "px trans sym e eb tmp texels pal sel sel8 order proj fa fb ca cb ws codes na nb "
                                "errs lo hi sub dabs")


def scratch():
    """One thread's Scratch for etc2_kernels.improve_blocks and decode_blocks."""
    z = np.zeros
    i8 = np.int64
    return Scratch(z((16, 3), i8), z(16, i8), z(SYM_LEN, i8), z(E_LEN, i8), z((2, E_LEN), i8), z(8, np.uint8),
                   z((16, 4), np.uint8), z((4, 3), i8), z(16, i8), z(8, i8), z(16, i8), z(16, np.float64),
                   z(3, np.float64), z(3, np.float64), z(3, i8), z(3, i8), z(6, np.float64), z((6, 3), i8),
                   z(3, i8), z(3, i8), z(2, i8), z(3, i8), z(3, i8), z((8, 3), i8), z(8, i8))


def _encode_run(blocks, out, preset, w, thr, punch):
    """ETC1 then the ETC2 pass over one run of blocks, with working arrays of
    its own: run_chunked calls this from several threads at once. RGB without
    T/H (`fastest`) runs as one pass over the blocks (K.fast_blocks)."""
    rec = SEARCH.record(preset)
    if not punch and etc1.SEARCH.record(preset)[0].fast_path and rec[0].th == 0:
        K.fast_blocks(blocks, out, rec, w, K1.fast_scratch(), scratch())
        return
    K1.encode_blocks(blocks, out, etc1.SEARCH.record(preset), w)
    K.improve_blocks(blocks, out, rec, w, np.int64(thr), np.bool_(punch), scratch())


def encode_colour_blocks(blocks, out, preset, threads, weights=None):
    """ETC2 RGB colour blocks: blocks uint8 (n, 16, 4) (alpha ignored) ->
    out uint8 (n, 8), 8-byte ETC2_R8G8B8 blocks; preset one of the five
    presets, threads as for Codec.encode, weights (r, g, b) or None. The
    bytes do not depend on the thread count. The one entry point for formats
    that hold an ETC2 RGB block (etc2a8's colour half)."""
    run_chunked(_encode_run, blocks, out, threads, preset, etc1.integer_weights(weights), 0, False)


@dataclass(frozen=True)
class ETC2Codec(Codec):
    compile_seconds = 17  # CPU s a first 256x256 bake spends compiling (docs/performance.md)
    punch_through: bool = False
    preset_tables = (etc1.SEARCH, SEARCH)

    @property
    def options(self):
        return (WEIGHTS_RGB, ALPHA_THRESHOLD) if self.punch_through else (WEIGHTS_RGB,)

    def _encode_blocks(self, blocks, out, preset, threads, weights=None, alpha_threshold=128):
        if not self.punch_through:
            encode_colour_blocks(blocks, out, preset, threads, weights)
            return
        run_chunked(_encode_run, blocks, out, threads, preset, etc1.integer_weights(weights),
                    int(alpha_threshold), True)

    def _decode_blocks(self, data, out):
        K.decode_blocks(np.ascontiguousarray(data), out, np.bool_(self.punch_through), scratch())


CODECS = {
    "etc2": ETC2Codec(formats.get("etc2")),
    "etc2a1": ETC2Codec(formats.get("etc2a1"), punch_through=True),
}
