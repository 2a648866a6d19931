"""Uncompressed formats through the same interface as the block codecs.

8-bit formats take uint8 RGBA and store the first 1, 2 or 4 channels; float
formats take float32 RGBA. Decoding returns RGBA the way a GPU samples it:
missing colour channels read 0 and missing alpha reads opaque.
"""

from dataclasses import dataclass

import numpy as np

from ._base import Codec


@dataclass(frozen=True)
class Uncompressed(Codec):
    dtype: str = "uint8"

    presets = ("fastest", "fast", "medium", "thorough", "exhaustive")

    @property
    def _np_dtype(self):
        return np.dtype(self.dtype).newbyteorder("<")

    def encode(self, rgba, preset="medium", threads=None, **options) -> bytes:
        self.check_preset(preset)
        rgba = self.check_input(rgba)
        # no copy besides the bytes themselves when the type already matches
        return np.ascontiguousarray(rgba[:, :, : self.channels]).astype(self._np_dtype, copy=False).tobytes()

    def decode(self, data, width, height):
        buf = self.check_data(data, width, height)
        px = buf.view(self._np_dtype).reshape(height, width, self.channels)
        out_dtype = np.float32 if self.float_input else np.uint8
        out = np.zeros((height, width, 4), out_dtype)
        out[:, :, 3] = 1.0 if self.float_input else 255
        out[:, :, : self.channels] = px
        return out


R8 = Uncompressed("r8", 1, 1, 1, 1, vk_unorm=9, vk_srgb=15, description="8-bit red")
RG8 = Uncompressed("rg8", 1, 1, 2, 2, vk_unorm=16, vk_srgb=22, description="8-bit red-green")
RGBA8 = Uncompressed("rgba8", 1, 1, 4, 4, vk_unorm=37, vk_srgb=43, description="8-bit RGBA")
RGBA16F = Uncompressed(
    "rgba16f", 1, 1, 8, 4, vk_unorm=97, float_input=True, dtype="float16",
    description="16-bit float RGBA",
)
RGBA32F = Uncompressed(
    "rgba32f", 1, 1, 16, 4, vk_unorm=109, float_input=True, dtype="float32",
    description="32-bit float RGBA",
)
