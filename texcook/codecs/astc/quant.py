"""ASTC value ranges: how many levels each range has, how the integer sequence
encoding spends trits, quints and bits on it, and how stored values turn back
into colour (0..255) and weight (0..64) values.

Range index r (0..20) means RANGE_LEVELS[r] levels; weights use r 0..11.
Unquantisation follows the Khronos Data Format Specification's ASTC chapter:
bit replication for power-of-two ranges, and for trit/quint ranges the A/B/C/D
procedure, whose B bit patterns are transcribed below as the spec prints them.
That procedure scrambles the order of values, so encoders use the inverse
tables (nearest code for a value), which are derived here from the forward
tables rather than typed in.
"""

import numpy as np

from ..._jit import jit_typed

RANGE_LEVELS = np.array(
    [2, 3, 4, 5, 6, 8, 10, 12, 16, 20, 24, 32, 40, 48, 64, 80, 96, 128, 160, 192, 256], np.int32)
N_RANGES = 21  # colour ranges 0..20
N_WEIGHT_RANGES = 12  # weight ranges 0..11 (2..32 levels)


def _split(levels):
    levels = int(levels)
    for trits, quints, base in ((1, 0, 3), (0, 1, 5), (0, 0, 1)):
        if levels % base == 0 and ((levels // base) & (levels // base - 1)) == 0:
            return trits, quints, (levels // base).bit_length() - 1
    raise ValueError(levels)


RANGE_TRITS = np.array([_split(v)[0] for v in RANGE_LEVELS], np.int32)
RANGE_QUINTS = np.array([_split(v)[1] for v in RANGE_LEVELS], np.int32)
RANGE_BITS = np.array([_split(v)[2] for v in RANGE_LEVELS], np.int32)

# The spec's colour unquantisation parameters: levels -> (B pattern, C), 9-bit A/B.
_COLOUR_ABCD = {
    6: ("000000000", 204), 10: ("000000000", 113), 12: ("b000b0bb0", 93),
    20: ("b0000bb00", 54), 24: ("cb000cbcb", 44), 40: ("cb0000cbc", 26),
    48: ("dcb000dcb", 22), 80: ("dcb0000dc", 13), 96: ("edcb000ed", 11),
    160: ("edcb0000e", 6), 192: ("fedcb000f", 5),
}
# ... and for weights (7-bit A/B).
_WEIGHT_ABCD = {
    6: ("0000000", 50), 10: ("0000000", 28), 12: ("b000b0b", 23),
    20: ("b0000b0", 13), 24: ("cb000cb", 11),
}


def _abcd(levels, value, table, width, top):
    """Unquantise one trit/quint-range value with the spec's A/B/C/D procedure."""
    _, quints, n = _split(levels)
    pattern, c = table[levels]
    d = value >> n  # the trit or quint
    m = value & ((1 << n) - 1)
    a = m & 1
    big_a = ((1 << width) - 1) if a else 0
    big_b = 0
    for k, ch in enumerate(pattern):  # pattern is MSB first
        if ch != "0":
            bit = (m >> (ord(ch) - ord("a"))) & 1
            big_b |= bit << (width - 1 - k)
    unq = d * c + big_b
    unq ^= big_a
    return (big_a & top) | (unq >> 2)


def _replicate(value, nbits, width):
    """Bit replication of an nbits value to `width` bits, MSB first."""
    out = 0
    filled = 0
    while filled < width:
        out = (out << nbits) | value
        filled += nbits
    return out >> (filled - width)


def _colour_unquant(levels, v):
    trits, quints, n = _split(levels)
    if trits == 0 and quints == 0:
        return _replicate(v, n, 8)
    if levels in _COLOUR_ABCD:
        return _abcd(levels, v, _COLOUR_ABCD, 9, 0x80)
    # 3 and 5 levels never carry colours in a legal block (the bit-count rule
    # guarantees at least 6 levels); spread them evenly so the table is total.
    return (v * 255 + (levels - 1) // 2) // (levels - 1)


def _weight_unquant(levels, v):
    trits, quints, n = _split(levels)
    if trits == 0 and quints == 0:
        unq = _replicate(v, n, 6)
    elif levels == 3:
        unq = (0, 32, 63)[v]
    elif levels == 5:
        unq = (0, 16, 32, 47, 63)[v]
    else:
        unq = _abcd(levels, v, _WEIGHT_ABCD, 7, 0x20)
    return unq + 1 if unq > 32 else unq


def _build():
    cu = np.zeros((N_RANGES, 256), np.int32)
    for r, lv in enumerate(RANGE_LEVELS):
        for v in range(lv):
            cu[r, v] = _colour_unquant(int(lv), v)
    wu = np.zeros((N_WEIGHT_RANGES, 32), np.int32)
    for r in range(N_WEIGHT_RANGES):
        lv = int(RANGE_LEVELS[r])
        for v in range(lv):
            wu[r, v] = _weight_unquant(lv, v)
    return cu, wu


COLOUR_UNQUANT, WEIGHT_UNQUANT = _build()
"""COLOUR_UNQUANT[r, code] -> 0..255; WEIGHT_UNQUANT[r, code] -> 0..64 (unused codes 0)."""


def _inverse(unq, levels, nvalues):
    """For each value 0..nvalues-1, the code whose unquantised value is nearest
    (ties go to the smaller unquantised value); plus the codes sorted by value
    and each code's rank in that order."""
    nr = unq.shape[0]
    nearest = np.zeros((nr, nvalues), np.int32)
    order = np.zeros((nr, unq.shape[1]), np.int32)
    rank = np.zeros((nr, unq.shape[1]), np.int32)
    for r in range(nr):
        lv = int(levels[r])
        vals = unq[r, :lv].astype(np.int64)
        srt = np.argsort(vals, kind="stable")
        order[r, :lv] = srt
        rank[r, srt] = np.arange(lv)
        sv = vals[srt]
        for x in range(nvalues):
            d = np.abs(sv - x)
            nearest[r, x] = srt[int(np.argmin(d))]  # argmin keeps the first (smaller) tie
    return nearest, order, rank


COLOUR_QUANT, COLOUR_ORDER, COLOUR_RANK = _inverse(COLOUR_UNQUANT, RANGE_LEVELS, 256)
"""COLOUR_QUANT[r, 0..255] -> nearest code; COLOUR_ORDER[r, k] the code with the k-th
smallest value; COLOUR_RANK[r, code] -> k (step a code up or down in value)."""
WEIGHT_QUANT, WEIGHT_ORDER, WEIGHT_RANK = _inverse(WEIGHT_UNQUANT, RANGE_LEVELS[:N_WEIGHT_RANGES], 65)
"""WEIGHT_QUANT[r, 0..64] -> nearest code; WEIGHT_ORDER / WEIGHT_RANK as for colours."""


@jit_typed("int64(int64, int64)")
def ise_bits(count, qr):
    """Bits the integer sequence encoding of `count` values of range qr takes."""
    return (count * RANGE_BITS[qr] + (8 * count * RANGE_TRITS[qr] + 4) // 5
            + (7 * count * RANGE_QUINTS[qr] + 2) // 3)


def _floor_ceil(unq, levels):
    """Per range and integer 0..255: the code of the largest value at or below
    it and of the smallest at or above it (colour values span 0..255, so
    both exist)."""
    nr = unq.shape[0]
    lo = np.zeros((nr, 256), np.int64)
    hi = np.zeros((nr, 256), np.int64)
    xs = np.arange(256)
    for r in range(nr):
        vals = unq[r, :int(levels[r])]
        order = np.argsort(vals)  # codes are not in value order (trits, quints)
        ordered = vals[order]
        lo[r] = order[np.searchsorted(ordered, xs, "right") - 1]
        hi[r] = order[np.searchsorted(ordered, xs, "left")]
    return lo, hi


COLOUR_FLOOR, COLOUR_CEIL = _floor_ceil(COLOUR_UNQUANT, RANGE_LEVELS)
"""COLOUR_FLOOR[r, x] -> the code whose value is the largest <= x; COLOUR_CEIL the
smallest >= x: a float's two neighbouring codes are FLOOR[floor(v)], CEIL[ceil(v)]."""
