"""Small jitted helpers that several codecs' kernels share, each a rule of
texcook's block codecs written once."""

import numpy as np

from .._jit import jit_inner


@jit_inner
def blank(texels):
    """A block's texels (16, 4) before a one- or two-channel format's channels
    are written into them: what such a decode returns for the channels it
    lacks (0, alpha 255)."""
    for i in range(16):
        texels[i, 0] = 0
        texels[i, 1] = 0
        texels[i, 2] = 0
        texels[i, 3] = 255


@jit_inner
def get_bits(d, pos, n):
    """n bits of the block bytes d from bit pos, the first the lowest (BC6H's
    and BC7's bit order)."""
    v = 0
    for k in range(n):
        p = pos + k
        v |= ((np.int64(d[p >> 3]) >> (p & 7)) & 1) << k
    return v
