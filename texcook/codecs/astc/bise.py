"""Bounded integer sequence encoding (BISE / ISE) and bit access for 128-bit
ASTC blocks held as uint8[16] (bit k is bit k % 8 of byte k // 8).

A range of 3 * 2^n or 5 * 2^n levels stores each value's low n bits as they
are and packs the high trits five to 8 bits, or the high quints three to 7
bits, interleaved with the low bits (the spec's trit and quint layouts). The
last group may be partial: the stream ends after the last value's own bits,
and a decoder reads the missing packed bits as 0. That is why the encoding
tables below pick, among the packed values that decode to the same digits, the
smallest one: its bits for absent (zero) digits are then zero too.
"""

import numpy as np

from ..._jit import jit_inner, jit_typed
from .quant import RANGE_BITS, RANGE_QUINTS, RANGE_TRITS, ise_bits


def _trits_of(t):
    """The spec's decoding of an 8-bit packed value into five trits."""
    def bits(v, hi, lo):
        return (v >> lo) & ((1 << (hi - lo + 1)) - 1)

    if bits(t, 4, 2) == 7:
        c = (bits(t, 7, 5) << 2) | bits(t, 1, 0)
        t4 = t3 = 2
    else:
        c = bits(t, 4, 0)
        if bits(t, 6, 5) == 3:
            t4, t3 = 2, bits(t, 7, 7)
        else:
            t4, t3 = bits(t, 7, 7), bits(t, 6, 5)
    if bits(c, 1, 0) == 3:
        t2, t1 = 2, bits(c, 4, 4)
        t0 = (bits(c, 3, 3) << 1) | (bits(c, 2, 2) & (1 - bits(c, 3, 3)))
    elif bits(c, 3, 2) == 3:
        t2 = t1 = 2
        t0 = bits(c, 1, 0)
    else:
        t2, t1 = bits(c, 4, 4), bits(c, 3, 2)
        t0 = (bits(c, 1, 1) << 1) | (bits(c, 0, 0) & (1 - bits(c, 1, 1)))
    return t0, t1, t2, t3, t4


def _quints_of(q):
    """The spec's decoding of a 7-bit packed value into three quints."""
    def bits(v, hi, lo):
        return (v >> lo) & ((1 << (hi - lo + 1)) - 1)

    if bits(q, 2, 1) == 3 and bits(q, 6, 5) == 0:
        b0 = bits(q, 0, 0)
        q2 = (b0 << 2) | ((bits(q, 4, 4) & (1 - b0)) << 1) | (bits(q, 3, 3) & (1 - b0))
        q1 = q0 = 4
    else:
        if bits(q, 2, 1) == 3:
            q2 = 4
            c = (bits(q, 4, 3) << 3) | ((3 - bits(q, 6, 5)) << 1) | bits(q, 0, 0)
        else:
            q2 = bits(q, 6, 5)
            c = bits(q, 4, 0)
        if bits(c, 2, 0) == 5:
            q1, q0 = 4, bits(c, 4, 3)
        else:
            q1, q0 = bits(c, 4, 3), bits(c, 2, 0)
    return q0, q1, q2


def _tables():
    tdec = np.array([_trits_of(t) for t in range(256)], np.uint8)
    qdec = np.array([_quints_of(q) for q in range(128)], np.uint8)
    tenc = np.full(243, 255, np.int32)
    for t in range(255, -1, -1):  # descending, so the smallest packed value wins
        d = tdec[t]
        tenc[d[0] + 3 * d[1] + 9 * d[2] + 27 * d[3] + 81 * d[4]] = t
    qenc = np.full(125, 255, np.int32)
    for q in range(127, -1, -1):
        d = qdec[q]
        qenc[d[0] + 5 * d[1] + 25 * d[2]] = q
    assert (tenc < 256).all() and (qenc < 128).all()
    return tdec, tenc.astype(np.uint8), qdec, qenc.astype(np.uint8)


TRIT_DECODE, TRIT_ENCODE, QUINT_DECODE, QUINT_ENCODE = _tables()
"""TRIT_DECODE[T] -> 5 trits; TRIT_ENCODE[t0 + 3 t1 + 9 t2 + 27 t3 + 81 t4] -> T;
QUINT_DECODE[Q] -> 3 quints; QUINT_ENCODE[q0 + 5 q1 + 25 q2] -> Q."""


@jit_typed("int64(uint8[::1], int64, int64, int64)")
def _get(buf, pos, n, end):
    """n (<= 32) bits from bit `pos` of a stream that ends at `end` (<= 128):
    bits past the end read as 0."""
    if pos + n > end:
        n = end - pos
    if n <= 0:
        return 0
    first = pos >> 3
    v = 0
    for b in range(first, ((pos + n - 1) >> 3) + 1):
        v |= np.int64(buf[b]) << (8 * (b - first))
    return (v >> (pos & 7)) & ((1 << n) - 1)


@jit_typed("int64(uint8[::1], int64, int64)")
def read_bits(buf, start, n):
    """n (<= 32) bits of the 128-bit block from bit `start` (>= 0), LSB first."""
    return _get(buf, start, n, 128)


# Where a group's packed bits go: after value k's low bits come GROUP_TBITS[k]
# bits of the packed value, starting at its bit GROUP_TSHIFT[k]. Trits (5 per
# group) first, then quints (3 per group).
_TBITS = np.array([2, 2, 1, 2, 1, 3, 2, 2], np.int64)
_TSHIFT = np.array([0, 2, 4, 5, 7, 0, 3, 5], np.int64)


@jit_inner(inline="always")
def or_bits(lo, hi, pos, n, v):
    """(lo, hi), the 128 bits of a block as two words, with the n-bit value v
    ORed in at bit pos."""
    if pos < 64:
        lo |= v << pos
        if pos + n > 64:
            hi |= v >> (64 - pos)
    else:
        hi |= v << (pos - 64)
    return lo, hi


@jit_inner(inline="always")
def ise_words(values, count, qr, start, lo, hi):
    """(lo, hi, end): the two words of a block (bits 0-63, 64-127) with
    values[0:count] (each 0..levels-1 of range qr) ORed in from bit `start`
    (the bits they cover must be zero), and the bit after the stream. In
    registers: the packer assembles a whole block this way and stores it once."""
    n = np.int64(RANGE_BITS[qr])
    mask = (1 << n) - 1
    end = start + ise_bits(count, qr)
    wlo = np.int64(0)
    whi = np.int64(0)
    if RANGE_TRITS[qr]:
        per, base, first = 5, 3, 0
    elif RANGE_QUINTS[qr]:
        per, base, first = 3, 5, 5
    else:
        per, base, first = 0, 1, 0
        for i in range(count):
            wlo, whi = or_bits(wlo, whi, start + i * n, n, np.int64(values[i]) & mask)
    p = start
    for g in range((count + per - 1) // per if per else 0):
        packed = 0
        mul = 1
        for k in range(per):
            i = g * per + k
            if i < count:
                packed += (np.int64(values[i]) >> n) * mul
            mul *= base
        packed = np.int64(TRIT_ENCODE[packed]) if per == 5 else np.int64(QUINT_ENCODE[packed])
        for k in range(per):
            i = g * per + k
            low = np.int64(values[i]) & mask if i < count else 0
            if p < end:
                wlo, whi = or_bits(wlo, whi, p, n, low)
            p += n
            tb = _TBITS[first + k]
            if p < end:
                wlo, whi = or_bits(wlo, whi, p, tb, (packed >> _TSHIFT[first + k]) & ((1 << tb) - 1))
            p += tb
    # the stream stops at end: a last group's unused bits are dropped
    if end < 64:
        wlo &= (np.int64(1) << end) - 1
        whi = 0
    elif end < 128:
        whi &= (np.int64(1) << (end - 64)) - 1
    return lo | wlo, hi | whi, end


@jit_typed("int64(int32[::1], int64, int64, uint8[::1], int64)")
def ise_encode(values, count, qr, buf, start):
    """Write values[0:count] (each 0..levels-1 of range qr) from bit `start`.
    The block bits it covers must be zero. Returns the bit after the stream."""
    lo, hi, end = ise_words(values, count, qr, start, np.int64(0), np.int64(0))
    for b in range(start >> 3, (end + 7) >> 3):
        word = lo if b < 8 else hi
        buf[b] |= np.uint8((word >> (8 * (b & 7))) & 0xFF)
    return end


@jit_typed("int64(uint8[::1], int64, int64, int64, int32[::1])")
def ise_decode(buf, start, count, qr, out):
    """Read count values of range qr from bit `start` into out[0:count]."""
    n = np.int64(RANGE_BITS[qr])
    end = start + ise_bits(count, qr)
    if RANGE_TRITS[qr]:
        per, first = 5, 0
    elif RANGE_QUINTS[qr]:
        per, first = 3, 5
    else:
        for i in range(count):
            out[i] = _get(buf, start + i * n, n, end)
        return end
    low = np.zeros(5, np.int64)
    p = start
    for g in range((count + per - 1) // per):
        packed = 0
        for k in range(per):
            low[k] = _get(buf, p, n, end)
            p += n
            tb = _TBITS[first + k]
            packed |= _get(buf, p, tb, end) << _TSHIFT[first + k]
            p += tb
        for k in range(per):
            i = g * per + k
            if i < count:
                digit = np.int64(TRIT_DECODE[packed, k]) if per == 5 else np.int64(QUINT_DECODE[packed, k])
                out[i] = (digit << n) | low[k]
    return end


BIT_REVERSED = np.array([int(f"{i:08b}"[::-1], 2) for i in range(256)], np.uint8)
"""BIT_REVERSED[b]: the byte b with its bits in reverse order."""


@jit_typed("void(uint8[::1], uint8[::1])")
def bit_reverse_into(src, dst):
    """dst |= src with the 128 bits in reverse order (bit k -> bit 127 - k):
    the weight stream is written upward from bit 0 of a scratch block and
    lands downward from bit 127."""
    for i in range(16):
        dst[i] |= BIT_REVERSED[src[15 - i]]


@jit_inner(inline="always")
def reverse64(v):
    """The 64 bits of v in reverse order (bit k -> bit 63 - k): halves, then
    quarters and so on swapped, in registers."""
    v = ((v >> 1) & 0x5555555555555555) | ((v & 0x5555555555555555) << 1)
    v = ((v >> 2) & 0x3333333333333333) | ((v & 0x3333333333333333) << 2)
    v = ((v >> 4) & 0x0F0F0F0F0F0F0F0F) | ((v & 0x0F0F0F0F0F0F0F0F) << 4)
    v = ((v >> 8) & 0x00FF00FF00FF00FF) | ((v & 0x00FF00FF00FF00FF) << 8)
    v = ((v >> 16) & 0x0000FFFF0000FFFF) | ((v & 0x0000FFFF0000FFFF) << 16)
    return ((v >> 32) & 0xFFFFFFFF) | (v << 32)
