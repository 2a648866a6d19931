"""BC5: two BC4 blocks, X (red) then Y (green), 16 bytes a block; the usual
home of tangent-space normal maps (the reader rebuilds Z).

Encoded as two independent BC4 channels, or with the `angular` option by the
search of texcook.codecs.bc5_angular, which judges X and Y together by the
angle of the rebuilt normal.
"""

from dataclasses import dataclass

import numpy as np

from .. import formats
from ._base import ANGULAR, run_chunked
from .bc4 import SEARCH, BC4Codec


@dataclass(frozen=True)
class BC5Codec(BC4Codec):
    compile_seconds = 4  # CPU s a first 256x256 bake spends compiling (docs/performance.md)
    options = (ANGULAR,)

    def _encode_blocks(self, blocks, out, preset, threads, angular=False):
        if not angular:
            return super()._encode_blocks(blocks, out, preset, threads)
        from .bc5_angular import encode_kernel

        p = SEARCH.row(preset)
        # the window and rounds grow with the preset, as BC4's search does
        run_chunked(encode_kernel, blocks, out, threads, SEARCH.record(preset),
                    np.int64(max(1, p.window)), np.int64(p.ls_iters + 1))


CODECS = {"bc5": BC5Codec(formats.get("bc5"))}
