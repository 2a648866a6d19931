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
def byte(v):
    """A float colour value rounded and clamped to 0..255."""
    if v <= 0.0:
        return 0
    if v >= 255.0:
        return 255
    return np.int64(v + 0.5)


@jit_inner
def get_bits(d, pos, n):
    """n bits of the block bytes d from bit pos, the first the lowest (BC6H's
    and BC7's bit order)."""
    v = 0
    for k in range(n):
        p = pos + k
        v |= ((np.int64(d[p >> 3]) >> (p & 7)) & 1) << k
    return v


@jit_inner
def moments(px, member, s):
    """Of the RGB texels px[t] (16) with member[t] == s: their count, mean and
    the sums of products of their deviations from it (a covariance times the
    count): (n, m0, m1, m2, c00, c01, c02, c11, c12, c22). The mean is 0 when
    no texel is a member."""
    n = 0
    m0 = 0.0
    m1 = 0.0
    m2 = 0.0
    for t in range(16):
        if member[t] == s:
            n += 1
            m0 += px[t, 0]
            m1 += px[t, 1]
            m2 += px[t, 2]
    if n > 0:
        m0 /= n
        m1 /= n
        m2 /= n
    c00 = c01 = c02 = c11 = c12 = c22 = 0.0
    for t in range(16):
        if member[t] == s:
            d0 = px[t, 0] - m0
            d1 = px[t, 1] - m1
            d2 = px[t, 2] - m2
            c00 += d0 * d0
            c01 += d0 * d1
            c02 += d0 * d2
            c11 += d1 * d1
            c12 += d1 * d2
            c22 += d2 * d2
    return n, m0, m1, m2, c00, c01, c02, c11, c12, c22


@jit_inner
def order_by(key, out):
    """out = the indices 0..len(out)-1 in ascending order of key[index]
    (a stable insertion sort: for the handful of values a block ranks)."""
    for i in range(out.shape[0]):
        j = i
        while j > 0 and key[out[j - 1]] > key[i]:
            out[j] = out[j - 1]
            j -= 1
        out[j] = i
