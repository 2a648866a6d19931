"""ETC2's constants beyond ETC1's (texcook.codecs.etc1_tables), and the
symbolic form of a T, H or planar block.

A T, H or planar block is handled as an int64 row of E_LEN slots:

    E_MODE       MODE_T, MODE_H or MODE_PLANAR
    E_A+c        T/H: first base colour (4-bit); planar: O (6-bit R, B; 7-bit G)
    E_B+c        T/H: second base colour (4-bit); planar: H
    E_C+c        planar: V
    E_DIST       T/H: distance index 0..7 (in H its lowest bit must equal
                 "first colour >= second colour": the format stores only the
                 upper two bits)
    E_OPAQUE     0 in a punch-through block with transparent texels
    E_SEL+i      T/H: paint colour index of texel i (row-major, i = y * 4 + x)

`etc2_kernels.pack_e` and `unpack_e` are the only code that knows where
these bits sit in the 64-bit word.
"""

import numpy as np

MODE_T = 1
MODE_H = 2
MODE_PLANAR = 3

E_MODE = 0
E_A = 1  # 3 slots
E_B = 4  # 3 slots
E_C = 7  # 3 slots
E_DIST = 10
E_OPAQUE = 11
E_SEL = 12  # 16 slots
E_LEN = 28

# T and H: the distance between paint colours, by index
DIST = np.array([3, 6, 11, 16, 23, 32, 41, 64], np.int64)

# planar: bits of O, H and V per channel
PLANAR_BITS = np.array([6, 7, 6], np.int64)
EXPAND6 = np.array([(c << 2) | (c >> 4) for c in range(64)], np.int64)
EXPAND7 = np.array([(c << 1) | (c >> 6) for c in range(128)], np.int64)


def _planar_pinv():
    """The least-squares solve of the planar model: a channel's value at (x, y)
    is O + x (H - O) / 4 + y (V - O) / 4, linear in (O, H, V); row k of the
    3x16 result gives O, H or V from the 16 texel values (row-major)."""
    a = np.zeros((16, 3))
    for y in range(4):
        for x in range(4):
            a[y * 4 + x] = (1 - x / 4 - y / 4, x / 4, y / 4)
    return np.linalg.pinv(a)


PLANAR_PINV = _planar_pinv()
