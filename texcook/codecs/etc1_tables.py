"""ETC1's fixed tables and its symbolic block.

A block is handled in symbolic form, an int64 row of SYM_LEN slots:

    S_DIFF       1 differential mode, 0 individual
    S_FLIP       1: sub-blocks are 4x2 (top, bottom); 0: 2x4 (left, right)
    S_BASE1+c    base colour of sub-block 1 (4-bit values, or 5-bit in differential mode)
    S_BASE2+c    base colour of sub-block 2 (4-bit, or the absolute 5-bit colour; the
                 packer turns it into a delta)
    S_TABLE1/2   modifier table of sub-block 1 and 2 (S_TABLE1 + half)
    S_SEL+i      selector of texel i in row-major order (i = y * 4 + x), 16 slots:
                 0 -> +a, 1 -> +b, 2 -> -a, 3 -> -b (the (MSB, LSB) pairs 00, 01, 10, 11)

The search only ever produces symbolic blocks; `etc1_kernels.pack_sym` and
`unpack_sym` are the only code that knows the bit layout.
"""

import numpy as np

S_DIFF = 0
S_FLIP = 1
S_BASE1 = 2  # 3 slots
S_BASE2 = 5  # 3 slots
S_TABLE1 = 8
S_TABLE2 = 9
S_SEL = 10  # 16 slots
SYM_LEN = 26

# (a, b) of each modifier table; a texel adds +a, +b, -a or -b to all channels
TABLES = np.array(
    [[2, 8], [5, 17], [9, 29], [13, 42], [18, 60], [24, 80], [33, 106], [47, 183]], np.int64
)
# modifier for (table, selector)
MODS = np.array([[a, b, -a, -b] for a, b in TABLES], np.int64)

# texel indices (row-major) of the four possible sub-blocks:
# 0 left 2x4, 1 right 2x4 (flip 0); 2 top 4x2, 3 bottom 4x2 (flip 1)
SUB_IDX = np.array(
    [
        [0, 1, 4, 5, 8, 9, 12, 13],
        [2, 3, 6, 7, 10, 11, 14, 15],
        [0, 1, 2, 3, 4, 5, 6, 7],
        [8, 9, 10, 11, 12, 13, 14, 15],
    ],
    np.int64,
)
# the bit of each of those texels in the selector planes (texels are numbered
# down the columns there: x * 4 + y)
SUB_BIT = (SUB_IDX % 4) * 4 + SUB_IDX // 4


def _expand_table(bits):
    if bits == 4:
        return np.array([(c << 4) | c for c in range(16)], np.int64)
    return np.array([(c << 3) | (c >> 2) for c in range(32)], np.int64)


EXPAND4 = _expand_table(4)
EXPAND5 = _expand_table(5)


def _nearest_table(expand):
    out = np.zeros(256, np.int64)
    for v in range(256):
        out[v] = int(np.argmin(np.abs(expand - v)))
    return out


# 8-bit value -> nearest 4-bit / 5-bit code
QUANT4 = _nearest_table(EXPAND4)
QUANT5 = _nearest_table(EXPAND5)


def _single_colour_tables():
    """For each precision (0: 4-bit, 1: 5-bit), table, selector and 8-bit value:
    the code whose expanded value plus that modifier lands nearest the value,
    and the squared distance. Channels are independent for a constant colour,
    so these give the best encoding of any constant sub-block."""
    code = np.zeros((2, 8, 4, 256), np.int64)
    err = np.zeros((2, 8, 4, 256), np.int64)
    v = np.arange(256)[:, None]
    for p, expand in enumerate((EXPAND4, EXPAND5)):
        for t in range(8):
            for k in range(4):
                out = np.clip(expand[None, :] + MODS[t, k], 0, 255)
                e = (out - v) ** 2
                code[p, t, k] = np.argmin(e, axis=1)
                err[p, t, k] = e.min(axis=1)
    # stored narrow (codes < 32, errors <= 255^2): numba embeds global arrays
    # in every compiled module that reads them, so their size is compile time
    return code.astype(np.uint8), err.astype(np.uint16)


SINGLE_CODE, SINGLE_ERR = _single_colour_tables()
