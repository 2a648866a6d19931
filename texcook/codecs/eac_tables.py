"""EAC's fixed tables (KDF "ETC2", the alpha part of RGBA ETC2 and R11/RG11 EAC).

An EAC block is 64 bits, big-endian: base codeword (bits 63-56), multiplier
(55-52), modifier table index (51-48), then sixteen 3-bit texel indices from
bit 47 down, texel a first; texels are numbered down the columns (texel
(x, y) is the (4x + y)-th index).
"""

import numpy as np

# The sixteen modifier tables, index 0..7 as stored (the first four negative).
MODIFIERS = np.array([
    [-3, -6, -9, -15, 2, 5, 8, 14],
    [-3, -7, -10, -13, 2, 6, 9, 12],
    [-2, -5, -8, -13, 1, 4, 7, 12],
    [-2, -4, -6, -13, 1, 3, 5, 12],
    [-3, -6, -8, -12, 2, 5, 7, 11],
    [-3, -7, -9, -11, 2, 6, 8, 10],
    [-4, -7, -8, -11, 3, 6, 7, 10],
    [-3, -5, -8, -11, 2, 4, 7, 10],
    [-2, -6, -8, -10, 1, 5, 7, 9],
    [-2, -5, -8, -10, 1, 4, 7, 9],
    [-2, -4, -8, -10, 1, 3, 7, 9],
    [-2, -5, -7, -10, 1, 4, 6, 9],
    [-3, -4, -7, -10, 2, 3, 6, 9],
    [-1, -2, -3, -10, 0, 1, 2, 9],
    [-4, -6, -8, -9, 3, 5, 7, 8],
    [-3, -5, -7, -9, 2, 4, 6, 8],
], np.int64)

# Smallest and largest modifier of each table.
MOD_MIN = MODIFIERS.min(axis=1)
MOD_MAX = MODIFIERS.max(axis=1)

# How a block's values are read (the `kind` argument of the kernels):
ALPHA8 = 0  # RGBA ETC2 alpha: clamp(base + modifier * multiplier, 0, 255)
UNSIGNED11 = 1  # R11: clamp(base * 8 + 4 + modifier * m, 0, 2047), m = multiplier * 8 or 1
SIGNED11 = 2  # signed R11: clamp(base * 8 + modifier * m, -1023, 1023), base -128 read as -127

# Texel i (row-major, i = 4y + x) holds the (4x + y)-th index of the block.
INDEX_OF_TEXEL = np.array([4 * (i % 4) + i // 4 for i in range(16)], np.int64)
