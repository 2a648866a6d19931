"""ASTC partition patterns: the spec's select_partition hash, and per block
size a table of every partition index's texel labels.

A multi-partition block names its pattern by a 10-bit index; the hash turns
(index, texel position, partition count) into the texel's partition. Blocks of
fewer than 31 texels hash doubled coordinates (the spec's small-block rule).
"""

import numpy as np

from ..._jit import jit_typed

_M32 = 0xFFFFFFFF


@jit_typed("int64(int64)")
def _hash52(p):
    p &= _M32
    p ^= p >> 15
    p = (p - (p << 17)) & _M32
    p = (p + (p << 7)) & _M32
    p = (p + (p << 4)) & _M32
    p ^= p >> 5
    p = (p + (p << 16)) & _M32
    p ^= p >> 7
    p ^= p >> 3
    p = (p ^ (p << 6)) & _M32
    p ^= p >> 17
    return p


@jit_typed("int64(int64, int64, int64, int64, int64, int64)")
def select_partition(seed, x, y, z, count, small_block):
    """Partition (0..count-1) of texel (x, y, z) for pattern `seed` (0..1023)."""
    if count < 2:
        return 0
    if small_block:
        x <<= 1
        y <<= 1
        z <<= 1
    seed = seed + (count - 1) * 1024
    rnum = _hash52(np.int64(seed))
    s1 = rnum & 0xF
    s2 = (rnum >> 4) & 0xF
    s3 = (rnum >> 8) & 0xF
    s4 = (rnum >> 12) & 0xF
    s5 = (rnum >> 16) & 0xF
    s6 = (rnum >> 20) & 0xF
    s7 = (rnum >> 24) & 0xF
    s8 = (rnum >> 28) & 0xF
    s9 = (rnum >> 18) & 0xF
    s10 = (rnum >> 22) & 0xF
    s11 = (rnum >> 26) & 0xF
    s12 = ((rnum >> 30) | (rnum << 2)) & 0xF
    s1 *= s1
    s2 *= s2
    s3 *= s3
    s4 *= s4
    s5 *= s5
    s6 *= s6
    s7 *= s7
    s8 *= s8
    s9 *= s9
    s10 *= s10
    s11 *= s11
    s12 *= s12
    if seed & 1:
        sh1 = 4 if seed & 2 else 5
        sh2 = 6 if count == 3 else 5
    else:
        sh1 = 6 if count == 3 else 5
        sh2 = 4 if seed & 2 else 5
    sh3 = sh1 if seed & 0x10 else sh2
    s1 >>= sh1
    s2 >>= sh2
    s3 >>= sh1
    s4 >>= sh2
    s5 >>= sh1
    s6 >>= sh2
    s7 >>= sh1
    s8 >>= sh2
    s9 >>= sh3
    s10 >>= sh3
    s11 >>= sh3
    s12 >>= sh3
    a = (s1 * x + s2 * y + s11 * z + (rnum >> 14)) & 0x3F
    b = (s3 * x + s4 * y + s12 * z + (rnum >> 10)) & 0x3F
    c = (s5 * x + s6 * y + s9 * z + (rnum >> 6)) & 0x3F
    d = (s7 * x + s8 * y + s10 * z + (rnum >> 2)) & 0x3F
    if count < 4:
        d = 0
    if count < 3:
        c = 0
    if a >= b and a >= c and a >= d:
        return 0
    if b >= c and b >= d:
        return 1
    if c >= d:
        return 2
    return 3


@jit_typed("void(int64, int64, uint8[:, :, ::1])")
def _fill_table(bw, bh, out):
    small = 1 if bw * bh < 31 else 0
    for count in range(2, 5):
        for seed in range(1024):
            for y in range(bh):
                for x in range(bw):
                    out[count, seed, y * bw + x] = select_partition(seed, x, y, 0, count, small)


_TABLES = {}


def partition_table(bw, bh):
    """uint8 (5, 1024, bw*bh): [count, index, texel] -> partition, texels row-major.
    Rows for count 0 and 1 are all zero. Built once per block size."""
    key = (int(bw), int(bh))
    if key not in _TABLES:
        t = np.zeros((5, 1024, key[0] * key[1]), np.uint8)
        _fill_table(np.int64(key[0]), np.int64(key[1]), t)
        t.setflags(write=False)
        _TABLES[key] = t
    return _TABLES[key]


_USABLE = {}


def partition_usable(bw, bh):
    """bool (5, 1024): True where index's pattern gives every one of `count`
    partitions at least one texel and no lower index gives the same split of
    texels (up to renaming partitions). An encoder need only try these."""
    key = (int(bw), int(bh))
    if key not in _USABLE:
        table = partition_table(*key)
        ok = np.zeros((5, 1024), bool)
        for count in range(2, 5):
            seen = set()
            for seed in range(1024):
                labels = table[count, seed]
                if np.unique(labels).size != count:
                    continue
                # canonical names: partitions numbered in order of first appearance
                _, first = np.unique(labels, return_index=True)
                rename = np.empty(4, np.uint8)
                rename[labels[np.sort(first)]] = np.arange(count)
                canon = rename[labels].tobytes()
                if canon not in seen:
                    seen.add(canon)
                    ok[count, seed] = True
        ok.setflags(write=False)
        _USABLE[key] = ok
    return _USABLE[key]
