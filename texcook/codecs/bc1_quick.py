"""BC1's quick colour path (the presets whose SEARCH row has ``quick`` set).

One pass per block, no candidate measured:

- the texels' sums and moments (in integers) give the covariance, and
  power iteration from its row with the largest diagonal the principal axis
  (never normalised); the endpoints are the extreme projections on it,
  quantised to 565;
- indices by projecting each texel on the decoded endpoint line and
  counting the palette midpoints at or below it: the palette of a 565 pair
  is monotone along that line in each channel, so the count is the index of
  the nearest entry along the line, found without a branch per texel (the
  weights rounded to integers, so projections and thresholds are exact);
- ``ls_iters`` rounds of least squares from those indices (the count is the
  texel's weight of c0 in thirds, or halves in the 3-colour mode), indices
  counted again each time.

A block of one colour (or whose endpoints quantise to one pair) takes the
single-colour tables of its mean, in whichever mode decodes it closer. Opaque
blocks are 4-colour (c0 > c1), or c0 == c1 with every index 0, which decode
the same under BC1's and BC3's rules; blocks with transparent texels (BC1A)
are 3-colour with those texels at index 3.

The image kernel reads the blocks straight from the image (edge texels
repeated past the border), so a bake skips gathering them first, and runs
the rule above on groups of whole blocks of a block row step by step, each
step vectorised across the group's blocks (quick_block's arithmetic, the same
bytes); edge blocks, blocks with transparent texels and least-squares rounds
go one block at a time through quick_block.
"""

import sys

import numpy as np

from .._jit import borrow, jit, jit_inner
from ._kernels import byte
from .bc1_kernels import exp5, exp6, quant565
from .bc1_tables import FLAT_ERR, Q5, Q6, SINGLE


@jit_inner(inline="always")
def _ends(c):
    """The 8-bit colour a 565 value decodes to."""
    return exp5((c >> 11) & 31), exp6((c >> 5) & 63), exp5(c & 31)


@jit_inner(inline="always")
def _flat_pair(rgb, w, three_ok, opaque):
    """(c0, c1, index) of the single-colour tables for the colour rgb: the
    4-colour pair unless the 3-colour one decodes closer (three_ok) or texels
    are transparent (opaque False: 3-colour only)."""
    r = byte(rgb[0])
    g = byte(rgb[1])
    b = byte(rgb[2])
    m = 1
    if opaque:
        m = 0
        if three_ok:
            e4 = w[0] * FLAT_ERR[0, 0, r] + w[1] * FLAT_ERR[0, 1, g] + w[2] * FLAT_ERR[0, 0, b]
            e3 = w[0] * FLAT_ERR[1, 0, r] + w[1] * FLAT_ERR[1, 1, g] + w[2] * FLAT_ERR[1, 0, b]
            if e3 < e4:
                m = 1
    hi = (SINGLE[m, 0, r, 0] << 11) | (SINGLE[m, 1, g, 0] << 5) | SINGLE[m, 0, b, 0]
    lo = (SINGLE[m, 0, r, 1] << 11) | (SINGLE[m, 1, g, 1] << 5) | SINGLE[m, 0, b, 1]
    if hi == lo:
        # entry 0 is the colour in either rule
        return hi, lo, 0
    if m == 1:
        # 3-colour: c0 < c1; the midpoint is symmetric
        return min(hi, lo), max(hi, lo), 2
    if hi > lo:
        return hi, lo, 2
    # swapped, the 2/3 point of hi is entry 3
    return lo, hi, 3


@jit_inner(inline="always")
def _count(P, mask, wi, c0, c1, three):
    """Indices of the 16 texels P (rows r, g, b) for endpoints c0, c1 (c0 > c1
    4-colour, else 3-colour with the texels outside mask at index 3), by
    counting the palette midpoints along the endpoint line at or below each
    texel, and the sums a least-squares fit needs: (bits, sum of a, sum of
    a*a, sums of a*x per channel), a the texel's weight of c0 (in thirds, or
    halves)."""
    r0, g0, b0 = _ends(c0)
    r1, g1, b1 = _ends(c1)
    # wi: the weights as integers (scaled to 256 at most), so every
    # projection and threshold is exact
    k0 = wi[0] * (r0 - r1)
    k1 = wi[1] * (g0 - g1)
    k2 = wi[2] * (b0 - b1)
    p0 = k0 * r0 + k1 * g0 + k2 * b0
    p1 = k0 * r1 + k1 * g1 + k2 * b1
    if three:
        pm = k0 * ((r0 + r1) // 2) + k1 * ((g0 + g1) // 2) + k2 * ((b0 + b1) // 2)
        # thresholds on twice the projection; the third never reached
        t1 = p1 + pm
        t2 = pm + p0
        t3 = np.int64(1) << 62
        # count 0, 1, 2 -> index 1, 2, 0
        code = 0x09
    else:
        p2 = k0 * ((2 * r0 + r1) // 3) + k1 * ((2 * g0 + g1) // 3) + k2 * ((2 * b0 + b1) // 3)
        p3 = k0 * ((r0 + 2 * r1) // 3) + k1 * ((g0 + 2 * g1) // 3) + k2 * ((b0 + 2 * b1) // 3)
        t1 = p1 + p3
        t2 = p3 + p2
        t3 = p2 + p0
        # count 0, 1, 2, 3 -> index 1, 3, 2, 0
        code = 0x2D
    bits = np.int64(0)
    sa = np.int64(0)
    saa = np.int64(0)
    ax0 = ax1 = ax2 = np.int64(0)
    for i in range(16):
        x0 = np.int64(P[0, i])
        x1 = np.int64(P[1, i])
        x2 = np.int64(P[2, i])
        on = (mask >> i) & 1
        t = 2 * (k0 * x0 + k1 * x1 + k2 * x2)
        a = (np.int64(t >= t1) + np.int64(t >= t2) + np.int64(t >= t3)) * on
        # transparent texels: index 3
        s = ((code >> (2 * a)) & 3) | ((1 - on) * 3)
        bits |= s << (2 * i)
        sa += a
        saa += a * a
        ax0 += a * x0
        ax1 += a * x1
        ax2 += a * x2
    return bits, sa, saa, ax0, ax1, ax2


@jit_inner(inline="always")
def _least_squares(n, d, sums, sx):
    """Least-squares endpoints (ok, c0, c1 as unquantised rgb tuples) from
    _count's sums for n texels with weights a/d of c0 and (d-a)/d of c1."""
    sa, saa, ax0, ax1, ax2 = sums
    aa = np.float64(saa)
    bb = np.float64(n * d * d - 2 * d * sa + saa)
    ab = np.float64(d * sa - saa)
    det = aa * bb - ab * ab
    if det < 0.5:
        return False, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    f = d / det
    bx0 = d * sx[0] - ax0
    bx1 = d * sx[1] - ax1
    bx2 = d * sx[2] - ax2
    return (True,
            ((ax0 * bb - bx0 * ab) * f, (ax1 * bb - bx1 * ab) * f, (ax2 * bb - bx2 * ab) * f),
            ((bx0 * aa - ax0 * ab) * f, (bx1 * aa - ax1 * ab) * f, (bx2 * aa - ax2 * ab) * f))


@jit_inner(inline="always")
def _pair(a, b, three):
    """(c0, c1, ok) ordered for the mode; ok False when they are equal."""
    # selects, not branches: which end quantises higher is a coin toss
    hi = max(a, b)
    lo = min(a, b)
    return (lo if three else hi), (hi if three else lo), a != b


@jit_inner(inline="always")
def quick_block(P, mask, w, wi, sw, iters, rounds, three_ok):
    """(c0, c1, index bits) of the block whose texels' r, g, b are the rows of
    P (3, 16); the texels outside mask (bit i: texel i) are transparent.
    w, sw: the channel weights and their square roots; wi: integer_weights(w);
    iters power-iteration steps, rounds least-squares rounds; three_ok: a
    flat opaque block may use the 3-colour mode."""
    if mask == 0:
        return np.int64(0), np.int64(0), np.int64(0xFFFFFFFF)
    opaque = mask == 0xFFFF
    three = not opaque
    n = np.int64(0)
    s0 = s1 = s2 = m00 = m01 = m02 = m11 = m12 = m22 = np.int64(0)
    for i in range(16):
        on = (mask >> i) & 1
        x0 = np.int64(P[0, i]) * on
        x1 = np.int64(P[1, i]) * on
        x2 = np.int64(P[2, i]) * on
        n += on
        s0 += x0
        s1 += x1
        s2 += x2
        m00 += x0 * x0
        m01 += x0 * x1
        m02 += x0 * x2
        m11 += x1 * x1
        m12 += x1 * x2
        m22 += x2 * x2
    c0 = c1 = np.int64(0)
    ok = False
    # covariance times n, exact in integers
    c00 = (n * m00 - s0 * s0) * (sw[0] * sw[0])
    c01 = (n * m01 - s0 * s1) * (sw[0] * sw[1])
    c02 = (n * m02 - s0 * s2) * (sw[0] * sw[2])
    c11 = (n * m11 - s1 * s1) * (sw[1] * sw[1])
    c12 = (n * m12 - s1 * s2) * (sw[1] * sw[2])
    c22 = (n * m22 - s2 * s2) * (sw[2] * sw[2])
    if c00 + c11 + c22 > 0.5:
        # power iteration from the covariance row with the largest diagonal,
        # never normalised: only the direction matters
        first = (c00 >= c11) & (c00 >= c22)
        second = c11 >= c22
        v0 = c00 if first else (c01 if second else c02)
        v1 = c01 if first else (c11 if second else c12)
        v2 = c02 if first else (c12 if second else c22)
        for _ in range(iters):
            v0, v1, v2 = (c00 * v0 + c01 * v1 + c02 * v2, c01 * v0 + c11 * v1 + c12 * v2,
                          c02 * v0 + c12 * v1 + c22 * v2)
        # K: the axis seen from the unweighted texels (v * sw), scaled to
        # 2^12 at most and rounded: integer projections, exact
        u0 = v0 * sw[0]
        u1 = v1 * sw[1]
        u2 = v2 * sw[2]
        big = max(abs(u0), abs(u1), abs(u2))
        if big > 0.0:
            f = 4096.0 / big
            k0 = np.int64(np.round(u0 * f))
            k1 = np.int64(np.round(u1 * f))
            k2 = np.int64(np.round(u2 * f))
            lo = np.int64(1 << 40)
            hi = -lo
            if opaque:
                for i in range(16):
                    p = np.int64(P[0, i]) * k0 + np.int64(P[1, i]) * k1 + np.int64(P[2, i]) * k2
                    lo = min(lo, p)
                    hi = max(hi, p)
            else:
                for i in range(16):
                    p = np.int64(P[0, i]) * k0 + np.int64(P[1, i]) * k1 + np.int64(P[2, i]) * k2
                    on = (mask >> i) & 1
                    lo = min(lo, p) if on else lo
                    hi = max(hi, p) if on else hi
            # x = mean + s * d with d = K / w, so K.x = K.mean + s * K.d
            inv = 1.0 / n
            m0 = s0 * inv
            m1 = s1 * inv
            m2 = s2 * inv
            d0 = k0 / w[0]
            d1 = k1 / w[1]
            d2 = k2 / w[2]
            km = k0 * m0 + k1 * m1 + k2 * m2
            kd = 1.0 / (k0 * d0 + k1 * d1 + k2 * d2)
            sh = (hi - km) * kd
            sl = (lo - km) * kd
            qa = quant565(m0 + sh * d0, m1 + sh * d1, m2 + sh * d2)
            qb = quant565(m0 + sl * d0, m1 + sl * d1, m2 + sl * d2)
            c0, c1, ok = _pair(qa, qb, three)
    if not ok:
        # one colour, or a spread too small for two 565 levels
        inv = 1.0 / n
        f0, f1, s = _flat_pair((s0 * inv, s1 * inv, s2 * inv), w, three_ok, opaque)
        bits = np.int64(0)
        for i in range(16):
            bits |= (s if (mask >> i) & 1 else 3) << (2 * i)
        return f0, f1, bits
    res = _count(P, mask, wi, c0, c1, three)
    d = 2 if three else 3
    sx = (s0, s1, s2)
    for _ in range(rounds):
        fit, ea, eb = _least_squares(n, d, res[1:], sx)
        if not fit:
            break
        a, b, ok = _pair(quant565(ea[0], ea[1], ea[2]), quant565(eb[0], eb[1], eb[2]), three)
        if not ok or (a == c0 and b == c1):
            break
        c0, c1 = a, b
        res = _count(P, mask, wi, c0, c1, three)
    return c0, c1, res[0]


@jit_inner(inline="always")
def _store(out, b, o, c0, c1, bits):
    out[b, o] = c0 & 255
    out[b, o + 1] = (c0 >> 8) & 255
    out[b, o + 2] = c1 & 255
    out[b, o + 3] = (c1 >> 8) & 255
    out[b, o + 4] = bits & 255
    out[b, o + 5] = (bits >> 8) & 255
    out[b, o + 6] = (bits >> 16) & 255
    out[b, o + 7] = (bits >> 24) & 255


@jit_inner(inline="always")
def _mask(P, thr):
    """Bit i set when texel i is opaque (alpha, row 3 of P, at least thr)."""
    if thr <= 0:
        return np.int64(0xFFFF)
    mask = np.int64(0)
    for i in range(16):
        mask |= np.int64(P[3, i] >= thr) << i
    return mask


@jit
def quick_blocks_run(blocks, out, o, w, wi, sw, iters, rounds, thr, three_ok, P):
    """The quick path over gathered blocks (n, 16, 4) uint8 into out[b, o:o+8];
    P (4, 16) uint8: a block's channels as rows."""
    wt = (w[0], w[1], w[2])
    swt = (sw[0], sw[1], sw[2])
    wit = (wi[0], wi[1], wi[2])
    # borrowed: passed to the helpers without reference counting (the
    # arguments outlive them)
    Pb, ob = borrow((P, out))
    for b in range(blocks.shape[0]):
        for i in range(16):
            for c in range(4):
                Pb[c, i] = blocks[b, i, c]
        c0, c1, bits = quick_block(Pb, _mask(Pb, thr), wt, wit, swt, iters, rounds, three_ok)
        _store(ob, b, o, c0, c1, bits)


# The image kernel works on groups of up to GROUP whole blocks of one block
# row, one step at a time over the group: each step is a loop over the blocks
# whose body holds one block's work unrolled, which LLVM vectorises across
# blocks (a loop over a block's 16 texels does not vectorise usefully). The
# working values sit in three flat arrays (by type), a row of GROUP per value,
# indexed with unsigned integers: at constant offsets into one array numba's
# loops need no run-time alias checks (several arrays would need more than
# LLVM allows, and it leaves the loop scalar), and unsigned indices carry no
# negative-index wraparound, which would hide the unit stride.
GROUP = 64
# rows of T (uint8): texel i's red at i, green at 16 + i, blue at 32 + i, alpha at 48 + i
# rows of W (int64); _LINE: the count's k0, k1, k2, t1, t2, t3
_S0, _K0, _LO, _HI, _E0, _C0, _C1, _BITS, _OPAQUE, _LINE = 0, 3, 6, 7, 8, 14, 15, 16, 17, 18
_W_ROWS = 24
# rows of F (float64): the covariance (00, 01, 02, 11, 12, 22), the axis
_COV, _V = 0, 6
_F_ROWS = 9
# a texel read as one 32-bit word: where each channel's byte sits
_SHIFT = (0, 8, 16, 24) if sys.byteorder == "little" else (24, 16, 8, 0)


@jit_inner(inline="always")
def _at(row, g):
    """The index of block g's value `row` in a working array."""
    return np.uint64(row * GROUP + g)


@jit_inner
def _load_group(px, x0, n, T, alpha):
    """Whole blocks x0 // 4 .. + n of the block row whose four texel rows are
    px (4 arrays of 32-bit texels) into T, with their alpha if asked."""
    for y in range(4):
        row = px[y][x0:x0 + 4 * n]
        for x in range(4):
            i = 4 * y + x
            for g in range(n):
                p = row[np.uint64(4 * g + x)]
                T[_at(i, g)] = (p >> _SHIFT[0]) & 255
                T[_at(16 + i, g)] = (p >> _SHIFT[1]) & 255
                T[_at(32 + i, g)] = (p >> _SHIFT[2]) & 255
            if alpha:
                for g in range(n):
                    T[_at(48 + i, g)] = (row[np.uint64(4 * g + x)] >> _SHIFT[3]) & 255


@jit_inner
def _opaque(T, W, n, thr):
    """W[_OPAQUE]: 1 where every texel of the block has alpha >= thr."""
    for g in range(n):
        lo = T[_at(48, g)]
        for i in range(1, 16):
            lo = min(lo, T[_at(48 + i, g)])
        W[_at(_OPAQUE, g)] = lo >= thr


@jit_inner
def _moments(T, W, F, n, sw):
    """The channel sums (W) and the weighted covariance times 16 (F), exact
    integers until scaled, as quick_block computes them; then the starting
    axis, the covariance row with the largest diagonal. In three loops of a
    few sums each: one loop with all nine is too big for LLVM to unroll."""
    for g in range(n):
        s0 = s1 = s2 = np.int64(0)
        for i in range(16):
            s0 += T[_at(i, g)]
            s1 += T[_at(16 + i, g)]
            s2 += T[_at(32 + i, g)]
        W[_at(_S0, g)] = s0
        W[_at(_S0 + 1, g)] = s1
        W[_at(_S0 + 2, g)] = s2
    q00 = sw[0] * sw[0]
    q11 = sw[1] * sw[1]
    q22 = sw[2] * sw[2]
    for g in range(n):
        m00 = m11 = m22 = np.int64(0)
        for i in range(16):
            x0 = np.int64(T[_at(i, g)])
            x1 = np.int64(T[_at(16 + i, g)])
            x2 = np.int64(T[_at(32 + i, g)])
            m00 += x0 * x0
            m11 += x1 * x1
            m22 += x2 * x2
        s0 = W[_at(_S0, g)]
        s1 = W[_at(_S0 + 1, g)]
        s2 = W[_at(_S0 + 2, g)]
        F[_at(_COV, g)] = (16 * m00 - s0 * s0) * q00
        F[_at(_COV + 3, g)] = (16 * m11 - s1 * s1) * q11
        F[_at(_COV + 5, g)] = (16 * m22 - s2 * s2) * q22
    q01 = sw[0] * sw[1]
    q02 = sw[0] * sw[2]
    q12 = sw[1] * sw[2]
    for g in range(n):
        m01 = m02 = m12 = np.int64(0)
        for i in range(16):
            x0 = np.int64(T[_at(i, g)])
            x1 = np.int64(T[_at(16 + i, g)])
            x2 = np.int64(T[_at(32 + i, g)])
            m01 += x0 * x1
            m02 += x0 * x2
            m12 += x1 * x2
        s0 = W[_at(_S0, g)]
        s1 = W[_at(_S0 + 1, g)]
        s2 = W[_at(_S0 + 2, g)]
        c01 = (16 * m01 - s0 * s1) * q01
        c02 = (16 * m02 - s0 * s2) * q02
        c12 = (16 * m12 - s1 * s2) * q12
        F[_at(_COV + 1, g)] = c01
        F[_at(_COV + 2, g)] = c02
        F[_at(_COV + 4, g)] = c12
        c00 = F[_at(_COV, g)]
        c11 = F[_at(_COV + 3, g)]
        c22 = F[_at(_COV + 5, g)]
        first = (c00 >= c11) & (c00 >= c22)
        second = c11 >= c22
        F[_at(_V, g)] = c00 if first else (c01 if second else c02)
        F[_at(_V + 1, g)] = c01 if first else (c11 if second else c12)
        F[_at(_V + 2, g)] = c02 if first else (c12 if second else c22)


@jit_inner
def _axis(W, F, n, sw, iters):
    """iters power-iteration steps, then the axis as integers (W[_K0..]),
    zero where the block has no spread: quick_block's rule."""
    for _ in range(iters):
        for g in range(n):
            v0 = F[_at(_V, g)]
            v1 = F[_at(_V + 1, g)]
            v2 = F[_at(_V + 2, g)]
            c00 = F[_at(_COV, g)]
            c01 = F[_at(_COV + 1, g)]
            c02 = F[_at(_COV + 2, g)]
            c11 = F[_at(_COV + 3, g)]
            c12 = F[_at(_COV + 4, g)]
            c22 = F[_at(_COV + 5, g)]
            F[_at(_V, g)] = c00 * v0 + c01 * v1 + c02 * v2
            F[_at(_V + 1, g)] = c01 * v0 + c11 * v1 + c12 * v2
            F[_at(_V + 2, g)] = c02 * v0 + c12 * v1 + c22 * v2
    for g in range(n):
        u0 = F[_at(_V, g)] * sw[0]
        u1 = F[_at(_V + 1, g)] * sw[1]
        u2 = F[_at(_V + 2, g)] * sw[2]
        big = max(abs(u0), abs(u1), abs(u2))
        live = (F[_at(_COV, g)] + F[_at(_COV + 3, g)] + F[_at(_COV + 5, g)] > 0.5) & (big > 0.0)
        f = 4096.0 / (big if live else 1.0)
        W[_at(_K0, g)] = np.int64(np.round(u0 * f)) if live else 0
        W[_at(_K0 + 1, g)] = np.int64(np.round(u1 * f)) if live else 0
        W[_at(_K0 + 2, g)] = np.int64(np.round(u2 * f)) if live else 0


@jit_inner
def _endpoints(T, W, n, w):
    """The extreme projections on the axis, the colours there (each channel
    rounded to a byte: W[_E0..]), then the 565 pair ordered c0 > c1 (W[_C0],
    W[_C1]; equal where the block takes the single-colour tables)."""
    for g in range(n):
        k0 = W[_at(_K0, g)]
        k1 = W[_at(_K0 + 1, g)]
        k2 = W[_at(_K0 + 2, g)]
        lo = np.int64(1 << 40)
        hi = -lo
        for i in range(16):
            p = T[_at(i, g)] * k0 + T[_at(16 + i, g)] * k1 + T[_at(32 + i, g)] * k2
            lo = min(lo, p)
            hi = max(hi, p)
        W[_at(_LO, g)] = lo
        W[_at(_HI, g)] = hi
    for g in range(n):
        k0 = W[_at(_K0, g)]
        k1 = W[_at(_K0 + 1, g)]
        k2 = W[_at(_K0 + 2, g)]
        m0 = W[_at(_S0, g)] * 0.0625
        m1 = W[_at(_S0 + 1, g)] * 0.0625
        m2 = W[_at(_S0 + 2, g)] * 0.0625
        d0 = k0 / w[0]
        d1 = k1 / w[1]
        d2 = k2 / w[2]
        km = k0 * m0 + k1 * m1 + k2 * m2
        kd = 1.0 / (k0 * d0 + k1 * d1 + k2 * d2)
        sh = (W[_at(_HI, g)] - km) * kd
        sl = (W[_at(_LO, g)] - km) * kd
        W[_at(_E0, g)] = byte(m0 + sh * d0)
        W[_at(_E0 + 1, g)] = byte(m1 + sh * d1)
        W[_at(_E0 + 2, g)] = byte(m2 + sh * d2)
        W[_at(_E0 + 3, g)] = byte(m0 + sl * d0)
        W[_at(_E0 + 4, g)] = byte(m1 + sl * d1)
        W[_at(_E0 + 5, g)] = byte(m2 + sl * d2)
    for g in range(n):
        qa = (Q5[W[_at(_E0, g)]] << 11) | (Q6[W[_at(_E0 + 1, g)]] << 5) | Q5[W[_at(_E0 + 2, g)]]
        qb = (Q5[W[_at(_E0 + 3, g)]] << 11) | (Q6[W[_at(_E0 + 4, g)]] << 5) | Q5[W[_at(_E0 + 5, g)]]
        live = (W[_at(_K0, g)] | W[_at(_K0 + 1, g)] | W[_at(_K0 + 2, g)]) != 0
        W[_at(_C0, g)] = max(qa, qb) if live else 0
        W[_at(_C1, g)] = min(qa, qb) if live else 0


@jit_inner(inline="always")
def _count_half(T, W, g, first):
    """_count's 4-colour indices of texels first .. first + 7 of block g
    (bits from 0), from the line and thresholds in W[_LINE..]."""
    k0 = W[_at(_LINE, g)]
    k1 = W[_at(_LINE + 1, g)]
    k2 = W[_at(_LINE + 2, g)]
    t1 = W[_at(_LINE + 3, g)]
    t2 = W[_at(_LINE + 4, g)]
    t3 = W[_at(_LINE + 5, g)]
    bits = np.int64(0)
    for j in range(8):
        i = first + j
        t = 2 * (k0 * T[_at(i, g)] + k1 * T[_at(16 + i, g)] + k2 * T[_at(32 + i, g)])
        # counts 0, 1, 2, 3 -> index 1, 3, 2, 0
        bits |= (np.int64(t < t2) | (np.int64(t >= t1) & np.int64(t < t3)) << 1) << (2 * j)
    return bits


@jit_inner
def _count_group(T, W, n, wi):
    """_count for 4-colour pairs of opaque blocks: W[_BITS]."""
    for g in range(n):
        r0, g0, b0 = _ends(W[_at(_C0, g)])
        r1, g1, b1 = _ends(W[_at(_C1, g)])
        k0 = wi[0] * (r0 - r1)
        k1 = wi[1] * (g0 - g1)
        k2 = wi[2] * (b0 - b1)
        p0 = k0 * r0 + k1 * g0 + k2 * b0
        p1 = k0 * r1 + k1 * g1 + k2 * b1
        p2 = k0 * ((2 * r0 + r1) // 3) + k1 * ((2 * g0 + g1) // 3) + k2 * ((2 * b0 + b1) // 3)
        p3 = k0 * ((r0 + 2 * r1) // 3) + k1 * ((g0 + 2 * g1) // 3) + k2 * ((b0 + 2 * b1) // 3)
        W[_at(_LINE, g)] = k0
        W[_at(_LINE + 1, g)] = k1
        W[_at(_LINE + 2, g)] = k2
        W[_at(_LINE + 3, g)] = p1 + p3
        W[_at(_LINE + 4, g)] = p3 + p2
        W[_at(_LINE + 5, g)] = p2 + p0
    # two halves: one loop over the 16 texels is too big for LLVM to unroll
    for g in range(n):
        W[_at(_BITS, g)] = _count_half(T, W, g, 0)
    for g in range(n):
        W[_at(_BITS, g)] |= _count_half(T, W, g, 8) << 16


@jit_inner
def _one_block(P, thr, w, wi, sw, iters, rounds, three_ok):
    """quick_block of the block in P, its mask from alpha: compiled once for
    quick_image_run's two callers (quick_block is inlined where called)."""
    return quick_block(P, _mask(P, thr), w, wi, sw, iters, rounds, three_ok)


@jit
def quick_image_run(ids, out, img, w, wi, sw, iters, rounds, thr, three_ok, work):
    """The quick path for the blocks numbered ids of img (h, width) (a texel
    per 32-bit word), blocks in row-major order, the image's last row and
    column repeated past its edges. Runs of whole blocks of one block row go
    through the group steps above (GROUP at a time); blocks at the right edge,
    blocks with transparent texels and presets with least-squares rounds go
    one at a time through quick_block, which gives the same bytes for the
    group's blocks. work: (P (4, 16) uint8, T, W, F) working arrays."""
    h = img.shape[0]
    width = img.shape[1]
    nbx = (width + 3) // 4
    whole = width // 4
    wt = (w[0], w[1], w[2])
    swt = (sw[0], sw[1], sw[2])
    wit = (wi[0], wi[1], wi[2])
    P, T, W, F = borrow(work)
    ob = borrow(out)
    alpha = thr > 0
    k = 0
    while k < ids.shape[0]:
        by, bx = divmod(ids[k], nbx)
        px = (img[min(4 * by, h - 1)], img[min(4 * by + 1, h - 1)], img[min(4 * by + 2, h - 1)],
              img[min(4 * by + 3, h - 1)])
        if bx >= whole or rounds > 0:
            # one block, copied into P with the edge repeated
            for y in range(4):
                for x in range(4):
                    p = px[y][min(4 * bx + x, width - 1)]
                    for c in range(4):
                        P[c, 4 * y + x] = (p >> _SHIFT[c]) & 255
            c0, c1, bits = _one_block(P, thr, wt, wit, swt, iters, rounds, three_ok)
            _store(ob, k, 0, c0, c1, bits)
            k += 1
            continue
        n = 1
        while n < GROUP and k + n < ids.shape[0] and ids[k + n] == ids[k] + n and bx + n < whole:
            n += 1
        _load_group(px, 4 * bx, n, T, alpha)
        if alpha:
            _opaque(T, W, n, thr)
        _moments(T, W, F, n, sw)
        _axis(W, F, n, sw, iters)
        _endpoints(T, W, n, w)
        _count_group(T, W, n, wi)
        for g in range(n):
            if alpha and W[_at(_OPAQUE, g)] == 0:
                for c in range(4):
                    for i in range(16):
                        P[c, i] = T[_at(16 * c + i, g)]
                c0, c1, bits = _one_block(P, thr, wt, wit, swt, iters, rounds, three_ok)
            else:
                c0 = W[_at(_C0, g)]
                c1 = W[_at(_C1, g)]
                bits = W[_at(_BITS, g)]
                if c0 == c1:
                    # one colour, or a spread too small for two 565 levels
                    inv = 1.0 / 16
                    c0, c1, s = _flat_pair((W[_at(_S0, g)] * inv, W[_at(_S0 + 1, g)] * inv,
                                            W[_at(_S0 + 2, g)] * inv), wt, three_ok, True)
                    bits = s * np.int64(0x55555555)
            _store(ob, k + g, 0, c0, c1, bits)
        k += n


def integer_weights(w):
    """The channel weights as integers, the largest 256 (none below 1)."""
    return np.maximum(1, np.floor(256.0 * w / w.max() + 0.5)).astype(np.int64)


def quick_image(ids, out, img, w, wi, sw, iters, rounds, thr, three_ok):
    """quick_image_run with working arrays of its own: run_chunked calls this
    from several threads at once. img: (h, width) uint32, a texel a word;
    wi: integer_weights(w)."""
    work = (np.empty((4, 16), np.uint8), np.empty(64 * GROUP, np.uint8), np.empty(_W_ROWS * GROUP, np.int64),
            np.empty(_F_ROWS * GROUP, np.float64))
    quick_image_run(ids, out, img, w, wi, sw, iters, rounds, thr, three_ok, work)


def quick_blocks(blocks, out, o, w, sw, iters, rounds, thr, three_ok):
    """quick_blocks_run with a block buffer of its own (for BC3's colour run)."""
    quick_blocks_run(blocks, out, o, w, integer_weights(w), sw, iters, rounds, thr, three_ok,
                     np.zeros((4, 16), np.uint8))
