"""EAC: R11 (one channel, 8 bytes a 4x4 block) and RG11 (two, 16 bytes),
the single- and two-channel formats of every OpenGL ES 3 / Vulkan ETC2 device.

`eac-r11` holds a lone channel (occlusion, roughness: texcook's bc4 use),
`eac-rg11` a normal map's X and Y (the reader rebuilds Z, as for bc5). Each
channel is a block of base codeword, multiplier and one of 16 modifier tables,
decoding to 11 bits. texcook writes the UNSIGNED variants (vkFormats 153, 155):
its inputs are 8-bit unsigned images, and a normal map stored unsigned reads
back as BC5's does. The SIGNED ones (154, 156) are the rows' signed twins:
`decode(..., signed=True)` decodes them.

8-bit decode (what `decode` returns and every metric reads): the 11-bit value
without its low 3 bits, signed values offset by 1023 first, as
texture2ddecoder returns them. The search aims each texel at the middle of the
11-bit values that read back as its 8-bit input (see eac_kernels).

Presets (every one picks each texel's index exactly, clamping included, and
holds a one-value block exactly):

- fastest: for each of the 16 tables, the multiplier that spans the block's
  range (and its neighbours) with the base that centres it; one
  least-squares round.
- fast / medium / thorough: multipliers and bases within a growing window
  around each table's fit, and more least-squares rounds.
- exhaustive: every base, multiplier and table (those whose value range
  cannot beat the best are skipped unmeasured).

Option `angular` (eac-rg11): search by the angle of the rebuilt normal, as
bc5's `angular` does (texcook.codecs.bc5_angular's cost).
"""

from dataclasses import dataclass

import numpy as np

from .. import formats
from . import eac_kernels as K
from ._base import ANGULAR, Codec, blocks_to_image, run_chunked
from ._presets import PresetTable
from .eac_tables import ALPHA8, SIGNED11, UNSIGNED11

SEARCH = PresetTable(
    "eac",
    columns={
        "mult_radius": "multipliers within +-radius of each table's range fit are measured",
        "base_radius": "bases within +-radius of the centring base are measured",
        "refine": "least-squares rounds (base and multiplier for the chosen indices)",
        "full_scan": "1: measure every base, multiplier and table (with a lower-bound cut)",
    },
    rows={
        #              mult_radius  base_radius  refine  full_scan
        "fastest":    (1,           0,           1,      0),
        "fast":       (1,           1,           1,      0),
        "medium":     (1,           2,           2,      0),
        "thorough":   (2,           4,           3,      0),
        "exhaustive": (2,           4,           3,      1),
    },
)


def encode_alpha(blocks, out, preset, threads):
    """RGBA ETC2's alpha blocks (channel 3) into bytes 0-7 of out (n, 16)."""
    run_chunked(K.encode_run, blocks, out, threads, SEARCH.record(preset),
                np.int64(ALPHA8), np.int64(3), np.int64(1), np.int64(0))


def decode_alpha(data, out):
    """RGBA ETC2's alpha blocks (bytes 0-7 of data (n, 16)) into channel 3 of out."""
    K.decode_alpha_run(np.ascontiguousarray(data), out)


@dataclass(frozen=True)
class EACCodec(Codec):
    compile_seconds = 5  # CPU s a first 256x256 bake spends compiling (docs/performance.md)
    preset_tables = (SEARCH,)

    def _encode_blocks(self, blocks, out, preset, threads):
        run_chunked(K.encode_run, blocks, out, threads, SEARCH.record(preset),
                    np.int64(UNSIGNED11), np.int64(0), np.int64(self.channels), np.int64(0))

    def _decode_blocks(self, data, out, signed=False):
        K.decode_run(np.ascontiguousarray(data), out, np.int64(self.channels),
                     np.int64(SIGNED11 if signed else UNSIGNED11))

    def decode(self, data, width, height, signed=False) -> np.ndarray:
        """As Codec.decode; signed=True reads the blocks as the SIGNED variant
        (vkFormat 154 / 156), returned as (v + 1023) >> 3."""
        buf = self.check_data(data, width, height).reshape(-1, self.bytes_per_block)
        out = np.zeros((buf.shape[0], 16, 4), np.uint8)
        self._decode_blocks(buf, out, signed)
        return blocks_to_image(out, width, height, 4, 4)


@dataclass(frozen=True)
class EACRG11Codec(EACCodec):
    options = (ANGULAR,)

    def _encode_blocks(self, blocks, out, preset, threads, angular=False):
        if not angular:
            return super()._encode_blocks(blocks, out, preset, threads)
        # rounds of alternating X and Y grow with the preset, as bc5's do
        rounds = SEARCH.row(preset).refine + 1
        run_chunked(K.encode_rg_angular_run, blocks, out, threads, SEARCH.record(preset),
                    np.int64(UNSIGNED11), np.int64(rounds))


CODECS = {
    "eac-r11": EACCodec(formats.get("eac-r11")),
    "eac-rg11": EACRG11Codec(formats.get("eac-rg11")),
}
