"""Uncompressed formats through the same interface as the block codecs.

8-bit formats take uint8 RGBA and store the first 1, 2 or 4 channels; float
formats take float32 RGBA. Decoding returns RGBA the way a GPU samples it:
missing colour channels read 0 and missing alpha reads opaque.
"""

from dataclasses import dataclass

import numpy as np

from .. import formats
from ._base import Codec

_STORED = {"unorm8": "u1", "float16": "<f2", "float32": "<f4"}


@dataclass(frozen=True)
class Uncompressed(Codec):
    compile_seconds = 1  # CPU s a first 256x256 bake spends compiling (docs/performance.md)
    @property
    def _np_dtype(self):
        return np.dtype(_STORED[self.format.sample])

    def _encode(self, rgba, preset, threads, options) -> bytes:
        px = np.ascontiguousarray(rgba[:, :, : self.channels])
        try:
            # no copy besides the bytes themselves when the type already matches
            with np.errstate(over="raise"):
                return px.astype(self._np_dtype, copy=False).tobytes()
        except FloatingPointError:
            # finite values beyond a half float's +-65504 saturate; only an Inf stays Inf
            top = np.finfo(self._np_dtype).max
            return np.where(np.isinf(px), px, np.clip(px, -top, top)).astype(self._np_dtype).tobytes()

    def decode(self, data, width, height):
        buf = self.check_data(data, width, height)
        px = buf.view(self._np_dtype).reshape(height, width, self.channels)
        out_dtype = np.float32 if self.float_input else np.uint8
        out = np.zeros((height, width, 4), out_dtype)
        out[:, :, 3] = 1.0 if self.float_input else 255
        out[:, :, : self.channels] = px
        return out


CODECS = {
    f.name: Uncompressed(f)
    for f in formats.FORMATS.values()
    if f.codec_module == __name__
}
