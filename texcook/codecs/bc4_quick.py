"""BC4's `fastest` search over whole images, vectorised across blocks.

The search is the one bc4.encode_single_block runs for a SEARCH row with no
window, no least-squares rounds and no full scan: the block's min and max in
the 8-value mode, and, where the block holds an exact 0 or 255, the min and
max of its other values in the 6-value mode, the better of the two kept; the
same bytes.

The image kernel reads its blocks straight from the image (no gathered copy)
and works on groups of up to GROUP whole blocks of a block row, one step at a
time over the group, each step a loop over the blocks that LLVM vectorises
(as bc1_quick does: working values in flat arrays at constant offsets,
unsigned indices). A block crossing the right edge (its texels past it
repeating the last column) is a group of one.

A texel's index is found by counting thresholds, as bc4._eval does, but
without its per-block merge of equal palette values, which does not
vectorise: there is a threshold between every two neighbouring palette
entries in ascending order, so the count is the entry's position, and its
value and index follow from the position by arithmetic. Equal neighbours
need no merge: they occur only where the endpoints are less than 7 (5 in the
6-value mode) apart, where neighbouring values differ by at most one, so no
texel value lies between two thresholds that a merge would move, and the
threshold's tie bit sends a texel of their value to the one of lower index
(the 6-value mode with lo6 == hi6 aside: see _thresholds6): the choice of a
palette scan in index order (tests/test_bc4.py checks every endpoint pair and
value).
"""

import sys

import numpy as np

from .._jit import borrow, jit, jit_inner

GROUP = 64
# rows of W (int64), GROUP values a row
_LO, _HI, _LO6, _HI6 = 0, 1, 2, 3
_T8 = 4  # 7 rows: the 8-value mode's thresholds on twice a texel's value
_T6 = 11  # 7 rows: the 6-value mode's
_BITS8, _BITS6, _E8, _E6 = 18, 19, 20, 21
_W_ROWS = 22
# a texel read as one 32-bit word: where each channel's byte sits
_SHIFT = (0, 8, 16, 24) if sys.byteorder == "little" else (24, 16, 8, 0)
# the index of each palette position, ascending: r1, the interpolants from r1's
# side, r0 (8-value); 0, r0, the interpolants, r1, 255 (6-value); 3 bits each
_CODE8 = sum(i << (3 * p) for p, i in enumerate((1, 7, 6, 5, 4, 3, 2, 0)))
_CODE6 = sum(i << (3 * p) for p, i in enumerate((6, 0, 2, 3, 4, 5, 1, 7)))
_BIG = sys.byteorder == "big"
# floor(n / 7) for n <= 13109 and floor(n / 5) for n <= 16383 as a multiply and a shift
_DIV7, _DIV5 = 9363, 13108


@jit_inner(inline="always")
def _at(row, g):
    """The index of block g's value `row` in a working array."""
    return np.uint64(row * GROUP + g)


@jit_inner
def _load_group(px, x0, n, T, shift):
    """The channel at `shift` of whole blocks x0 // 4 .. + n of the block row
    whose four texel rows are px (4 arrays of 32-bit texels) into T (texel i
    of block g at _at(i, g))."""
    for y in range(4):
        row = px[y][x0:x0 + 4 * n]
        for x in range(4):
            i = 4 * y + x
            for g in range(n):
                T[_at(i, g)] = (row[np.uint64(4 * g + x)] >> shift) & 255


@jit_inner
def _load_edge(px, x0, width, T, shift):
    """The channel at `shift` of the block at x0 of the block row, which
    crosses the image's right edge, into T as block 0, the last column
    repeated."""
    for y in range(4):
        for x in range(4):
            T[_at(4 * y + x, 0)] = (px[y][min(x0 + x, width - 1)] >> shift) & 255


@jit_inner
def _ranges(T, W, n):
    """Each block's min and max, and the min and max of its values other than
    0 and 255 (lo6 > hi6 where it has none)."""
    for g in range(n):
        lo = np.int64(255)
        hi = np.int64(0)
        lo6 = np.int64(255)
        hi6 = np.int64(0)
        for i in range(16):
            x = np.int64(T[_at(i, g)])
            lo = min(lo, x)
            hi = max(hi, x)
            inner = (x != 0) & (x != 255)
            lo6 = min(lo6, x if inner else 255)
            hi6 = max(hi6, x if inner else 0)
        W[_at(_LO, g)] = lo
        W[_at(_HI, g)] = hi
        W[_at(_LO6, g)] = lo6
        W[_at(_HI6, g)] = hi6


@jit_inner
def _thresholds8(W, n):
    """The 8-value mode's thresholds for (r0, r1) = (hi, lo). Ascending, the
    palette is a_k = lo + floor(k (hi - lo) / 7), k = 0 .. 7, with indices
    1, 7, 6, .., 2, 0; the threshold between positions k and k + 1 is
    a_k + a_(k+1), plus one where a texel halfway between them goes down
    (the lower index wins): where a_k is lo (index 1 beats 2 .. 7) and
    a_(k+1) is not hi (index 0). Written out, one block per iteration, so
    LLVM vectorises it across blocks."""
    for g in range(n):
        lo = W[_at(_LO, g)]
        hi = W[_at(_HI, g)]
        m = (hi - lo) * _DIV7
        a1 = lo + (m >> 16)
        a2 = lo + ((2 * m) >> 16)
        a3 = lo + ((3 * m) >> 16)
        a4 = lo + ((4 * m) >> 16)
        a5 = lo + ((5 * m) >> 16)
        a6 = lo + ((6 * m) >> 16)
        W[_at(_T8, g)] = lo + a1 + np.int64(a1 != hi)
        W[_at(_T8 + 1, g)] = a1 + a2 + ((a1 == lo) & (a2 != hi))
        W[_at(_T8 + 2, g)] = a2 + a3 + ((a2 == lo) & (a3 != hi))
        W[_at(_T8 + 3, g)] = a3 + a4 + ((a3 == lo) & (a4 != hi))
        W[_at(_T8 + 4, g)] = a4 + a5 + ((a4 == lo) & (a5 != hi))
        W[_at(_T8 + 5, g)] = a5 + a6 + ((a5 == lo) & (a6 != hi))
        W[_at(_T8 + 6, g)] = a6 + hi


@jit_inner
def _thresholds6(W, n):
    """The 6-value mode's thresholds for (r0, r1) = (lo6, hi6), 1 <= lo6 <=
    hi6 <= 254. Ascending, the palette is 0, b_0 .. b_5, 255 with b_k = lo6 +
    floor(k (hi6 - lo6) / 5), indices 6, 0, 2, 3, 4, 5, 1, 7; ties go down
    (as above) everywhere but from 0 to lo6 (index 0) and into hi6's run
    (index 1) from a value other than lo6. Where lo6 == hi6 the six entries
    are one run beside 0 and 255, the one exception to the rule of equal
    neighbours above: its thresholds are moved onto the one above it."""
    for g in range(n):
        lo = W[_at(_LO6, g)]
        hi = W[_at(_HI6, g)]
        m = (hi - lo) * _DIV5
        b1 = lo + (m >> 16)
        b2 = lo + ((2 * m) >> 16)
        b3 = lo + ((3 * m) >> 16)
        b4 = lo + ((4 * m) >> 16)
        top = hi + 256
        # one value for six entries: lo6's (index 0) takes every texel up to the midpoint to 255
        one = lo == hi
        W[_at(_T6, g)] = lo
        W[_at(_T6 + 1, g)] = top if one else lo + b1 + 1
        W[_at(_T6 + 2, g)] = top if one else b1 + b2 + ((b1 == lo) | (b2 != hi))
        W[_at(_T6 + 3, g)] = top if one else b2 + b3 + ((b2 == lo) | (b3 != hi))
        W[_at(_T6 + 4, g)] = top if one else b3 + b4 + ((b3 == lo) | (b4 != hi))
        W[_at(_T6 + 5, g)] = top if one else b4 + hi + np.int64(b4 == lo)
        W[_at(_T6 + 6, g)] = top


@jit_inner(inline="always")
def _count8_half(T, W, g, first):
    """Indices (3 bits each, from bit 0) of texels first .. first + 7 in the
    8-value mode."""
    t0 = W[_at(_T8, g)]
    t1 = W[_at(_T8 + 1, g)]
    t2 = W[_at(_T8 + 2, g)]
    t3 = W[_at(_T8 + 3, g)]
    t4 = W[_at(_T8 + 4, g)]
    t5 = W[_at(_T8 + 5, g)]
    t6 = W[_at(_T8 + 6, g)]
    bits = np.int64(0)
    for j in range(8):
        x2 = 2 * np.int64(T[_at(first + j, g)])
        c = (np.int64(x2 >= t0) + np.int64(x2 >= t1) + np.int64(x2 >= t2) + np.int64(x2 >= t3)
             + np.int64(x2 >= t4) + np.int64(x2 >= t5) + np.int64(x2 >= t6))
        bits |= ((_CODE8 >> (3 * c)) & 7) << (3 * j)
    return bits


@jit_inner
def _count8(T, W, n):
    """The 8-value mode's indices of every block (W[_BITS8]), in two halves:
    one loop of 16 texels is too big for LLVM to unroll."""
    for g in range(n):
        W[_at(_BITS8, g)] = _count8_half(T, W, g, 0)
    for g in range(n):
        W[_at(_BITS8, g)] |= _count8_half(T, W, g, 8) << 24


@jit_inner(inline="always")
def _err8_half(T, W, g, first):
    """The 8-value mode's squared error of texels first .. first + 7: the value
    of a counted position follows from the position (no palette look-up)."""
    lo = W[_at(_LO, g)]
    m = (W[_at(_HI, g)] - lo) * _DIV7
    t0 = W[_at(_T8, g)]
    t1 = W[_at(_T8 + 1, g)]
    t2 = W[_at(_T8 + 2, g)]
    t3 = W[_at(_T8 + 3, g)]
    t4 = W[_at(_T8 + 4, g)]
    t5 = W[_at(_T8 + 5, g)]
    t6 = W[_at(_T8 + 6, g)]
    err = np.int64(0)
    for j in range(8):
        x = np.int64(T[_at(first + j, g)])
        x2 = 2 * x
        c = (np.int64(x2 >= t0) + np.int64(x2 >= t1) + np.int64(x2 >= t2) + np.int64(x2 >= t3)
             + np.int64(x2 >= t4) + np.int64(x2 >= t5) + np.int64(x2 >= t6))
        e = x - lo - ((c * m) >> 16)
        err += e * e
    return err


@jit_inner(inline="always")
def _count6_half(T, W, g, first):
    """The 6-value mode's indices (3 bits each, from bit 0) and squared error
    of texels first .. first + 7."""
    lo = W[_at(_LO6, g)]
    m = (W[_at(_HI6, g)] - lo) * _DIV5
    t0 = W[_at(_T6, g)]
    t1 = W[_at(_T6 + 1, g)]
    t2 = W[_at(_T6 + 2, g)]
    t3 = W[_at(_T6 + 3, g)]
    t4 = W[_at(_T6 + 4, g)]
    t5 = W[_at(_T6 + 5, g)]
    t6 = W[_at(_T6 + 6, g)]
    err = np.int64(0)
    bits = np.int64(0)
    for j in range(8):
        x = np.int64(T[_at(first + j, g)])
        x2 = 2 * x
        c = (np.int64(x2 >= t0) + np.int64(x2 >= t1) + np.int64(x2 >= t2) + np.int64(x2 >= t3)
             + np.int64(x2 >= t4) + np.int64(x2 >= t5) + np.int64(x2 >= t6))
        v = lo + (((c - 1) * m) >> 16)
        v = 0 if c == 0 else (255 if c == 7 else v)
        e = x - v
        err += e * e
        bits |= ((_CODE6 >> (3 * c)) & 7) << (3 * j)
    return bits, err


@jit_inner
def _errors(T, W, n):
    """Both modes' squared errors (W[_E8], W[_E6]) and the 6-value mode's
    indices (W[_BITS6]) of every block, in halves as _count8."""
    for g in range(n):
        W[_at(_E8, g)] = _err8_half(T, W, g, 0)
    for g in range(n):
        W[_at(_E8, g)] += _err8_half(T, W, g, 8)
    for g in range(n):
        bits, err = _count6_half(T, W, g, 0)
        W[_at(_BITS6, g)] = bits
        W[_at(_E6, g)] = err
    for g in range(n):
        bits, err = _count6_half(T, W, g, 8)
        W[_at(_BITS6, g)] |= bits << 24
        W[_at(_E6, g)] += err


@jit_inner(inline="always")
def _little(w):
    """The uint64 whose bytes in memory are w's from the lowest up."""
    if _BIG:
        r = np.uint64(0)
        for k in range(8):
            r |= ((w >> np.uint64(8 * k)) & np.uint64(255)) << np.uint64(56 - 8 * k)
        return r
    return w


@jit_inner
def _words(W, n, tries, out, o, step):
    """Each block's 8 bytes as one little-endian word into out[o + g * step]:
    the endpoints and indices of the better mode (the 8-value one unless the
    block may take the 6-value one and it measured less), or a constant
    block's value with every index 0."""
    for g in range(n):
        lo = W[_at(_LO, g)]
        hi = W[_at(_HI, g)]
        word = hi | (lo << 8) | (W[_at(_BITS8, g)] << 16)
        if tries:
            lo6 = W[_at(_LO6, g)]
            hi6 = W[_at(_HI6, g)]
            six = (((lo == 0) | (hi == 255)) & (lo6 <= hi6)) & (W[_at(_E6, g)] < W[_at(_E8, g)])
            word = (lo6 | (hi6 << 8) | (W[_at(_BITS6, g)] << 16)) if six else word
        word = (lo | (lo << 8)) if lo == hi else word
        out[np.uint64(o + g * step)] = _little(np.uint64(word))


@jit
def fastest_image_run(ids, words, img, rec, ch0, nch, work):
    """Channels ch0 .. ch0+nch-1 of the blocks numbered ids of img (h, width)
    (a texel per 32-bit word; blocks in row-major order, the image's last row
    and column repeated past its edges) into words[k * nch + c] (a block's
    8 bytes as one little-endian 64-bit word); rec: SEARCH.record of a preset
    with no window, rounds or scan. work: the working arrays (T, W). Runs of
    whole blocks of one block row go through the steps above GROUP at a time;
    a block crossing the right edge is a group of one."""
    prm = rec[0]
    six = prm.six_value != 0
    h = img.shape[0]
    width = img.shape[1]
    nbx = (width + 3) // 4
    whole = width // 4
    T, W = borrow(work)
    ow = borrow(words)
    k = 0
    while k < ids.shape[0]:
        by, bx = divmod(ids[k], nbx)
        px = (img[min(4 * by, h - 1)], img[min(4 * by + 1, h - 1)], img[min(4 * by + 2, h - 1)],
              img[min(4 * by + 3, h - 1)])
        edge = bx >= whole
        n = 1
        while not edge and n < GROUP and k + n < ids.shape[0] and ids[k + n] == ids[k] + n and bx + n < whole:
            n += 1
        for c in range(nch):
            if edge:
                _load_edge(px, 4 * bx, width, T, _SHIFT[ch0 + c])
            else:
                _load_group(px, 4 * bx, n, T, _SHIFT[ch0 + c])
            _ranges(T, W, n)
            _thresholds8(W, n)
            _count8(T, W, n)
            # the 6-value mode where some block holds 0 or 255 besides other values
            tries = False
            for g in range(n):
                lo = W[_at(_LO, g)]
                hi = W[_at(_HI, g)]
                tries |= six & ((lo == 0) | (hi == 255)) & (lo < hi) & (W[_at(_LO6, g)] <= W[_at(_HI6, g)])
            if tries:
                _thresholds6(W, n)
                _errors(T, W, n)
            _words(W, n, tries, ow, k * nch + c, nch)
        k += n


def fastest_image(ids, out, img, rec, ch0, nch):
    """fastest_image_run with working arrays of its own: run_chunked calls
    this from several threads at once."""
    work = (np.empty(16 * GROUP, np.uint8), np.empty(_W_ROWS * GROUP, np.int64))
    fastest_image_run(ids, out.reshape(-1).view(np.uint64), img, rec, ch0, nch, work)
