"""RGBA ETC2 (ETC2_R8G8B8A8): 16 bytes a 4x4 block, an 8-bit EAC alpha block
(bytes 0-7) then an ETC2 RGB block (bytes 8-15).

Alpha is searched by texcook.codecs.eac (the 8-bit variant: multiplier 1..15,
as the format requires of encoders), colour by texcook.codecs.etc2 (ETC1's
modes and T, H and planar) with the same preset, and each half decoded by
its codec's decoder.

Option `weights=(r, g, b)`: the colour search's per-channel error weights.
"""

from dataclasses import dataclass

import numpy as np

from .. import formats
from . import etc2
from ._base import WEIGHTS_RGB, Codec
from .eac import SEARCH, decode_alpha, encode_alpha


@dataclass(frozen=True)
class ETC2A8Codec(Codec):
    compile_seconds = 18  # CPU s a first 256x256 bake spends compiling (docs/performance.md)
    options = (WEIGHTS_RGB,)
    preset_tables = (SEARCH,) + etc2.ETC2Codec.preset_tables

    def _encode_blocks(self, blocks, out, preset, threads, weights=None):
        encode_alpha(blocks, out, preset, threads)
        colour = np.zeros((blocks.shape[0], 8), np.uint8)
        etc2.encode_colour_blocks(blocks, colour, preset, threads, weights)
        out[:, 8:] = colour

    def _decode_blocks(self, data, out):
        etc2.CODECS["etc2"]._decode_blocks(np.ascontiguousarray(data[:, 8:]), out)
        decode_alpha(data, out)


CODECS = {"etc2a8": ETC2A8Codec(formats.get("etc2a8"))}
