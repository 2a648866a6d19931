"""BC6H kernels: the decoder of every mode and the encoder's search.

Values live in the "finished" domain: the half float's bit pattern read as an
integer, sign and magnitude turned into a signed integer (-0x7BFF..0x7BFF;
unsigned blocks 0..0x7BFF). The decoder interpolates unquantised endpoints and
scales the result by 31/64 (unsigned) or 31/32 (signed) into that domain, so a
palette entry there is exact integer arithmetic, and the encoder measures its
error there: squared differences of half-float bit patterns, which for normal
numbers is log2 of the value times 1024 (see docs/bc.md).
"""

import numpy as np

from .._jit import jit
from ._kernels import get_bits, moments, order_by
from .bc6h_tables import (ANCHORS, F_MODE, F_PART, HALF_MAX, I_BASE, I_DELTA, I_HEADER, I_REGIONS,
                          I_TRANSFORMED, I_VALUE, LAYOUT, MODE_INFO, MODE_OF_VALUE, NMODES, PARTITIONS,
                          WEIGHTS3, WEIGHTS4)

BIG = np.int64(1) << 62
# the texels of region 1 of each two-region shape, their count in column 16
REGION1 = np.zeros((32, 17), np.int64)
for _p in range(32):
    _ts = np.nonzero(PARTITIONS[_p])[0]
    REGION1[_p, :_ts.size] = _ts
    REGION1[_p, 16] = _ts.size
del _p, _ts
ONE_REGION = np.zeros(16, np.int64)  # every texel in region 0


# ---------------------------------------------------------------- bits


@jit
def _put(blk, pos, n, v):
    for k in range(n):
        p = pos + k
        blk[p >> 3] |= np.uint8(((v >> k) & 1) << (p & 7))


@jit
def _sign_extend(v, bits):
    v &= (np.int64(1) << bits) - 1
    if v >> (bits - 1):
        v -= np.int64(1) << bits
    return v


# ---------------------------------------------------------------- value maps


@jit
def unquantize(c, bits, signed):
    """An endpoint of `bits` bits to the 16-bit (signed: 15 bits and sign)
    interpolation domain, as the specification's unquantize."""
    if not signed:
        if bits >= 15 or c == 0:
            return c
        if c == (np.int64(1) << bits) - 1:
            return np.int64(0xFFFF)
        return ((c << 16) + 0x8000) >> bits
    if bits >= 16:
        return c
    neg = c < 0
    m = -c if neg else c
    if m == 0:
        u = np.int64(0)
    elif m >= (np.int64(1) << (bits - 1)) - 1:
        u = np.int64(0x7FFF)
    else:
        u = ((m << 15) + 0x4000) >> (bits - 1)
    return -u if neg else u


@jit
def finish(u, signed):
    """An interpolated value to the finished domain (the half's bit pattern):
    x 31/64 unsigned, x 31/32 with the sign kept apart for signed."""
    if not signed:
        return (u * 31) >> 6
    if u < 0:
        return -(((-u) * 31) >> 5)
    return (u * 31) >> 5


@jit
def lerp(u0, u1, w):
    return (u0 * (64 - w) + u1 * w + 32) >> 6


@jit
def to_half_bits(f):
    """Finished value -> the stored 16-bit pattern."""
    return (0x8000 | (-f)) if f < 0 else f


# ---------------------------------------------------------------- decoder


@jit
def decode_block(blk, signed, out):
    """One 16-byte block -> out (16, 3) half-float bit patterns. Reserved mode
    numbers decode to 0 in every channel."""
    mi = MODE_OF_VALUE[get_bits(blk, 0, 5)]
    if mi < 0:
        for t in range(16):
            for c in range(3):
                out[t, c] = 0
        return
    regions = MODE_INFO[mi, I_REGIONS]
    base = MODE_INFO[mi, I_BASE]
    header = MODE_INFO[mi, I_HEADER]
    ep = np.zeros((4, 3), np.int64)
    part = 0
    for pos in range(header):
        f = LAYOUT[mi, pos, 0]
        b = LAYOUT[mi, pos, 1]
        if f == F_MODE:
            continue
        bit = get_bits(blk, pos, 1)
        if f == F_PART:
            part |= bit << b
        else:
            e = (f - 2) // 3
            ep[e, (f - 2) % 3] |= bit << b
    transformed = MODE_INFO[mi, I_TRANSFORMED] == 1
    for c in range(3):
        dbits = MODE_INFO[mi, I_DELTA + c]
        if signed:
            ep[0, c] = _sign_extend(ep[0, c], base)
        for e in range(1, 2 * regions):
            if transformed:
                d = _sign_extend(ep[e, c], dbits)
                v = (ep[0, c] + d) & ((np.int64(1) << base) - 1)
                ep[e, c] = _sign_extend(v, base) if signed else v
            elif signed:
                ep[e, c] = _sign_extend(ep[e, c], base)
    for e in range(2 * regions):
        for c in range(3):
            ep[e, c] = unquantize(ep[e, c], base, signed)
    ibits = 3 if regions == 2 else 4
    pos = header
    anchor1 = ANCHORS[part] if regions == 2 else -1
    for t in range(16):
        n = ibits - 1 if t == 0 or t == anchor1 else ibits
        idx = get_bits(blk, pos, n)
        pos += n
        s = PARTITIONS[part, t] if regions == 2 else 0
        w = WEIGHTS3[idx] if regions == 2 else WEIGHTS4[idx]
        for c in range(3):
            out[t, c] = to_half_bits(finish(lerp(ep[2 * s, c], ep[2 * s + 1, c], w), signed))


@jit
def decode_run(data, out, signed):
    for i in range(data.shape[0]):
        decode_block(data[i], signed, out[i])


# ---------------------------------------------------------------- encoder pieces


@jit
def quantize(f, bits, signed):
    """The endpoint code of `bits` bits whose unquantised, finished value is
    nearest the finished value f (a float)."""
    if signed:
        top = (np.int64(1) << (bits - 1)) - 1
        lo = -top
        scale = float(np.int64(1) << (bits - 1)) / 32768.0 * 32.0 / 31.0
    else:
        top = (np.int64(1) << bits) - 1
        lo = np.int64(0)
        scale = float(np.int64(1) << bits) / 65536.0 * 64.0 / 31.0
    c0 = np.int64(np.floor(f * scale))
    best, best_d = lo, 1e300
    for c in range(c0 - 1, c0 + 3):
        if c < lo or c > top:
            continue
        d = abs(float(finish(unquantize(c, bits, signed), signed)) - f)
        if d < best_d:
            best, best_d = c, d
    return best


@jit
def _palette(codes, mi, signed, pal):
    """Finished palette pal (2, n, 3) of the absolute endpoint codes (4, 3)."""
    regions = MODE_INFO[mi, I_REGIONS]
    base = MODE_INFO[mi, I_BASE]
    n = 8 if regions == 2 else 16
    for s in range(regions):
        for c in range(3):
            u0 = unquantize(codes[2 * s, c], base, signed)
            u1 = unquantize(codes[2 * s + 1, c], base, signed)
            for i in range(n):
                w = WEIGHTS3[i] if regions == 2 else WEIGHTS4[i]
                pal[s, i, c] = finish(lerp(u0, u1, w), signed)


@jit
def _assign(q, part, mi, pal, idx):
    """Best index of each texel (an anchor texel keeps to the lower half, its
    top bit is not stored); returns the summed squared error."""
    regions = MODE_INFO[mi, I_REGIONS]
    n = 8 if regions == 2 else 16
    anchor1 = ANCHORS[part] if regions == 2 else -1
    total = 0
    for t in range(16):
        s = PARTITIONS[part, t] if regions == 2 else 0
        m = n // 2 if t == 0 or t == anchor1 else n
        best, bi = BIG, 0
        for i in range(m):
            e = 0
            for c in range(3):
                d = q[t, c] - pal[s, i, c]
                e += d * d
            if e < best:
                best, bi = e, i
        idx[t] = bi
        total += best
    return total


@jit
def _fit_codes(ends, mi, signed, codes):
    """Float endpoints ends (4, 3) -> codes (4, 3) the mode can store: each
    quantised on its own, then in transformed modes every delta from the base
    clamped to what its bits hold."""
    regions = MODE_INFO[mi, I_REGIONS]
    base = MODE_INFO[mi, I_BASE]
    transformed = MODE_INFO[mi, I_TRANSFORMED] == 1
    for c in range(3):
        codes[0, c] = quantize(ends[0, c], base, signed)
        dbits = MODE_INFO[mi, I_DELTA + c]
        hi = (np.int64(1) << (dbits - 1)) - 1
        for e in range(1, 2 * regions):
            v = quantize(ends[e, c], base, signed)
            if transformed:
                v = codes[0, c] + min(hi, max(-hi - 1, v - codes[0, c]))
            codes[e, c] = v


@jit
def _least_squares(q, part, mi, idx, ends):
    """Endpoints (float, finished domain) that best fit the texels for the
    chosen indices, per region and channel; a region whose texels all share
    one weight keeps its endpoints."""
    regions = MODE_INFO[mi, I_REGIONS]
    for s in range(regions):
        for c in range(3):
            aa = ab = bb = ax = bx = 0.0
            for t in range(16):
                if regions == 2 and PARTITIONS[part, t] != s:
                    continue
                w = (WEIGHTS3[idx[t]] if regions == 2 else WEIGHTS4[idx[t]]) / 64.0
                a, b = 1.0 - w, w
                aa += a * a
                ab += a * b
                bb += b * b
                ax += a * q[t, c]
                bx += b * q[t, c]
            det = aa * bb - ab * ab
            if abs(det) < 1e-9:
                break
            ends[2 * s, c] = (bb * ax - ab * bx) / det
            ends[2 * s + 1, c] = (aa * bx - ab * ax) / det


@jit
def _principal_fit(q, part, s, regions, iters, lo, hi, ends):
    """Endpoints of region s: the extremes of its texels' projections on their
    principal axis (power iteration on the covariance), within [lo, hi].
    Scalars only: numba allocates every small array on the heap."""
    member = PARTITIONS[part] if regions == 2 else ONE_REGION
    _, m0, m1, m2, c00, c01, c02, c11, c12, c22 = moments(q, member, s)
    a0, a1, a2 = c00 + 1e-3, c11 + 1e-3, c22 + 1e-3  # start near the widest channel
    for _ in range(iters):
        b0 = c00 * a0 + c01 * a1 + c02 * a2
        b1 = c01 * a0 + c11 * a1 + c12 * a2
        b2 = c02 * a0 + c12 * a1 + c22 * a2
        norm = np.sqrt(b0 * b0 + b1 * b1 + b2 * b2)
        if norm < 1e-12:
            break
        a0, a1, a2 = b0 / norm, b1 / norm, b2 / norm
    norm = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    a0, a1, a2 = a0 / norm, a1 / norm, a2 / norm
    tmin, tmax = 1e300, -1e300
    for t in range(16):
        if regions == 1 or PARTITIONS[part, t] == s:
            p = (q[t, 0] - m0) * a0 + (q[t, 1] - m1) * a1 + (q[t, 2] - m2) * a2
            tmin = min(tmin, p)
            tmax = max(tmax, p)
    ends[2 * s, 0] = min(hi, max(lo, m0 + tmin * a0))
    ends[2 * s, 1] = min(hi, max(lo, m1 + tmin * a1))
    ends[2 * s, 2] = min(hi, max(lo, m2 + tmin * a2))
    ends[2 * s + 1, 0] = min(hi, max(lo, m0 + tmax * a0))
    ends[2 * s + 1, 1] = min(hi, max(lo, m1 + tmax * a1))
    ends[2 * s + 1, 2] = min(hi, max(lo, m2 + tmax * a2))


@jit
def _residual(n, s0, s1, s2, s00, s01, s02, s11, s12, s22, iters):
    """What the best line through n points leaves, from their sums and sums
    of products: the covariance's trace less its largest eigenvalue (power
    iteration)."""
    if n == 0:
        return 0.0
    c00, c01, c02 = s00 - s0 * s0 / n, s01 - s0 * s1 / n, s02 - s0 * s2 / n
    c11, c12, c22 = s11 - s1 * s1 / n, s12 - s1 * s2 / n, s22 - s2 * s2 / n
    # unnormalised power iteration: a few products of entries below 2^36 stay
    # far inside float64's range, and the Rayleigh quotient needs no unit axis
    a0, a1, a2 = c00 + 1e-3, c11 + 1e-3, c22 + 1e-3
    for _ in range(iters):
        a0, a1, a2 = (c00 * a0 + c01 * a1 + c02 * a2, c01 * a0 + c11 * a1 + c12 * a2,
                      c02 * a0 + c12 * a1 + c22 * a2)
    norm = a0 * a0 + a1 * a1 + a2 * a2
    if norm < 1e-300:
        return 0.0
    along = (a0 * (c00 * a0 + c01 * a1 + c02 * a2) + a1 * (c01 * a0 + c11 * a1 + c12 * a2)
             + a2 * (c02 * a0 + c12 * a1 + c22 * a2)) / norm
    return c00 + c11 + c22 - along


@jit
def _rank_partitions(q, iters, rough):
    """The rough cost of each of the 32 shapes: what a line per region leaves
    unexplained. Region 1's sums are gathered per shape, region 0's are the
    block's less those."""
    t0 = t1 = t2 = t00 = t01 = t02 = t11 = t12 = t22 = 0.0
    for t in range(16):
        x0, x1, x2 = float(q[t, 0]), float(q[t, 1]), float(q[t, 2])
        t0 += x0
        t1 += x1
        t2 += x2
        t00 += x0 * x0
        t01 += x0 * x1
        t02 += x0 * x2
        t11 += x1 * x1
        t12 += x1 * x2
        t22 += x2 * x2
    for p in range(32):
        n = REGION1[p, 16]
        s0 = s1 = s2 = s00 = s01 = s02 = s11 = s12 = s22 = 0.0
        for k in range(n):
            t = REGION1[p, k]
            x0, x1, x2 = float(q[t, 0]), float(q[t, 1]), float(q[t, 2])
            s0 += x0
            s1 += x1
            s2 += x2
            s00 += x0 * x0
            s01 += x0 * x1
            s02 += x0 * x2
            s11 += x1 * x1
            s12 += x1 * x2
            s22 += x2 * x2
        rough[p] = (_residual(n, s0, s1, s2, s00, s01, s02, s11, s12, s22, iters)
                    + _residual(16 - n, t0 - s0, t1 - s1, t2 - s2, t00 - s00, t01 - s01, t02 - s02,
                                t11 - s11, t12 - s12, t22 - s22, iters))


@jit
def _orient(q, part, regions, ends):
    """Swap a region's endpoints so its anchor texel lies nearer endpoint 0:
    the anchor's index then fits in the bits it has."""
    for s in range(regions):
        t = 0 if s == 0 else ANCHORS[part]
        d0 = d1 = 0.0
        for c in range(3):
            d0 += (q[t, c] - ends[2 * s, c]) ** 2
            d1 += (q[t, c] - ends[2 * s + 1, c]) ** 2
        if d1 < d0:
            for c in range(3):
                ends[2 * s, c], ends[2 * s + 1, c] = ends[2 * s + 1, c], ends[2 * s, c]


@jit
def _try_mode(q, part, mi, signed, prm, ends0, codes, idx, best_err, pal, ends):
    """Quantise ends0 for mode mi, assign indices and refine by least squares
    (prm.ls_iters rounds). codes and idx hold (best so far, this mode's best,
    scratch); this mode's result replaces the best when it beats best_err.
    Returns this mode's error."""
    regions = MODE_INFO[mi, I_REGIONS]
    for e in range(4):
        for c in range(3):
            ends[e, c] = ends0[e, c]
    err = BIG
    for it in range(prm.ls_iters + 1):
        _orient(q, part, regions, ends)
        _fit_codes(ends, mi, signed, codes[2])
        _palette(codes[2], mi, signed, pal)
        e = _assign(q, part, mi, pal, idx[2])
        if e < err:
            err = e
            _take(codes, idx, 1, 2)
        elif it > 0:
            break
        if it < prm.ls_iters:
            _least_squares(q, part, mi, idx[2], ends)
    if err < best_err:
        _take(codes, idx, 0, 1)
    return err


@jit
def _codes_fit(codes, mi, signed):
    """Whether absolute codes are storable in mode mi (deltas within bits)."""
    regions = MODE_INFO[mi, I_REGIONS]
    base = MODE_INFO[mi, I_BASE]
    if signed:
        top = (np.int64(1) << (base - 1)) - 1
        lo = -top
    else:
        top = (np.int64(1) << base) - 1
        lo = np.int64(0)
    for c in range(3):
        hi = (np.int64(1) << (MODE_INFO[mi, I_DELTA + c] - 1)) - 1
        for e in range(2 * regions):
            if codes[e, c] < lo or codes[e, c] > top:
                return False
            if e > 0 and MODE_INFO[mi, I_TRANSFORMED] == 1:
                d = codes[e, c] - codes[0, c]
                if d > hi or d < -hi - 1:
                    return False
    return True


@jit
def _climb(q, part, mi, signed, passes, codes, idx, err, pal, tab, col):
    """Move one endpoint code of codes[1] (indices idx[1], error err) one step
    at a time while the exact error drops. A step changes one channel of one
    region's palette, so each texel's error for every index is kept in a
    table (tab, 16 x 16) and only that channel's share of that region's
    texels is redone (col: the changed channel's palette)."""
    regions = MODE_INFO[mi, I_REGIONS]
    base = MODE_INFO[mi, I_BASE]
    n = 8 if regions == 2 else 16
    anchor1 = ANCHORS[part] if regions == 2 else -1
    _palette(codes[1], mi, signed, pal)
    for t in range(16):
        s = PARTITIONS[part, t] if regions == 2 else 0
        for i in range(n):
            v = 0
            for c in range(3):
                d = q[t, c] - pal[s, i, c]
                v += d * d
            tab[t, i] = v
    for _ in range(passes):
        improved = False
        for e in range(2 * regions):
            r = e // 2
            for c in range(3):
                for step in range(-1, 2, 2):
                    _take(codes, idx, 2, 1)
                    codes[2, e, c] += step
                    if not _codes_fit(codes[2], mi, signed):
                        continue
                    u0 = unquantize(codes[2, 2 * r, c], base, signed)
                    u1 = unquantize(codes[2, 2 * r + 1, c], base, signed)
                    for i in range(n):
                        col[i] = finish(lerp(u0, u1, WEIGHTS3[i] if regions == 2 else WEIGHTS4[i]), signed)
                    total = 0
                    for t in range(16):
                        if regions == 2 and PARTITIONS[part, t] != r:
                            total += tab[t, idx[1, t]]
                            continue
                        best = BIG
                        for i in range(n // 2 if t == 0 or t == anchor1 else n):
                            d0 = q[t, c] - pal[r, i, c]
                            d1 = q[t, c] - col[i]
                            v = tab[t, i] - d0 * d0 + d1 * d1
                            if v < best:
                                best = v
                        total += best
                    if total >= err:
                        continue
                    err = total
                    improved = True
                    for k in range(4):
                        codes[1, k, c] = codes[2, k, c]
                    for t in range(16):
                        if regions == 2 and PARTITIONS[part, t] != r:
                            continue
                        best, bi = BIG, 0
                        for i in range(n):
                            d0 = q[t, c] - pal[r, i, c]
                            d1 = q[t, c] - col[i]
                            tab[t, i] += d1 * d1 - d0 * d0
                            if i < (n // 2 if t == 0 or t == anchor1 else n) and tab[t, i] < best:
                                best, bi = tab[t, i], i
                        idx[1, t] = bi
                    for i in range(n):
                        pal[r, i, c] = col[i]
        if not improved:
            break
    return err


@jit
def pack_block(mi, part, codes, idx, signed, out):
    """Write a block: header fields from the layout, then the indices."""
    for k in range(16):
        out[k] = 0
    regions = MODE_INFO[mi, I_REGIONS]
    base = MODE_INFO[mi, I_BASE]
    header = MODE_INFO[mi, I_HEADER]
    transformed = MODE_INFO[mi, I_TRANSFORMED] == 1
    value = MODE_INFO[mi, I_VALUE]
    stored = np.zeros((4, 3), np.int64)
    for c in range(3):
        stored[0, c] = codes[0, c] & ((np.int64(1) << base) - 1)
        dbits = MODE_INFO[mi, I_DELTA + c]
        for e in range(1, 2 * regions):
            if transformed:
                stored[e, c] = (codes[e, c] - codes[0, c]) & ((np.int64(1) << dbits) - 1)
            else:
                stored[e, c] = codes[e, c] & ((np.int64(1) << base) - 1)
    for pos in range(header):
        f = LAYOUT[mi, pos, 0]
        b = LAYOUT[mi, pos, 1]
        if f == F_MODE:
            bit = (value >> b) & 1
        elif f == F_PART:
            bit = (part >> b) & 1
        else:
            bit = (stored[(f - 2) // 3, (f - 2) % 3] >> b) & 1
        _put(out, pos, 1, bit)
    ibits = 3 if regions == 2 else 4
    pos = header
    anchor1 = ANCHORS[part] if regions == 2 else -1
    for t in range(16):
        n = ibits - 1 if t == 0 or t == anchor1 else ibits
        _put(out, pos, n, idx[t])
        pos += n


@jit
def _take(codes, idx, dst, src):
    """codes[dst], idx[dst] = codes[src], idx[src] (loops: numba compiles a
    slice assignment into a heavy routine)."""
    for e in range(4):
        for c in range(3):
            codes[dst, e, c] = codes[src, e, c]
    for t in range(16):
        idx[dst, t] = idx[src, t]


@jit
def _first_fit(q, part, mi, signed, ends0, codes, idx, pal, ends):
    """Mode mi on the principal-axis endpoints ends0, without refinement:
    the codes and indices land in codes[2], idx[2]; returns the error."""
    for e in range(4):
        for c in range(3):
            ends[e, c] = ends0[e, c]
    _orient(q, part, MODE_INFO[mi, I_REGIONS], ends)
    _fit_codes(ends, mi, signed, codes[2])
    _palette(codes[2], mi, signed, pal)
    return _assign(q, part, mi, pal, idx[2])


# two-region modes, finest base precision first: 11 bits (modes 3-5), 10, 9,
# 8 (modes 7-9), 7, and mode 10's untransformed 6 bits, which always fits
BY_PRECISION = np.array([2, 3, 4, 0, 5, 6, 7, 8, 1, 9], np.int64)


@jit
def _deltas_fit(ends0, part, mi, signed):
    """Whether the region endpoints' offsets from the base endpoint fit the
    mode's delta bits (with half a range to spare: clamping a little may
    still beat a coarser mode)."""
    if MODE_INFO[mi, I_TRANSFORMED] == 0:
        return True
    base = MODE_INFO[mi, I_BASE]
    step = (32768.0 if signed else 65536.0) / float(np.int64(1) << (base - (1 if signed else 0)))
    step *= (31.0 / 32.0) if signed else (31.0 / 64.0)
    for c in range(3):
        reach = 1.5 * float((np.int64(1) << (MODE_INFO[mi, I_DELTA + c] - 1))) * step
        for e in range(1, 4):
            if abs(ends0[e, c] - ends0[0, c]) > reach:
                return False
    return True


@jit
def _keep(cand, err, mi, part):
    """Insert (err, mode, partition) into the list cand (n, 3), kept sorted
    by error, when it beats the last."""
    n = cand.shape[0]
    if err >= cand[n - 1, 0]:
        return
    k = n - 1
    while k > 0 and cand[k - 1, 0] > err:
        for j in range(3):
            cand[k, j] = cand[k - 1, j]
        k -= 1
    cand[k, 0], cand[k, 1], cand[k, 2] = err, mi, part


@jit
def _region_fits(q, part, regions, iters, lo, hi, ends0):
    """Principal-axis endpoints of every region of a partition."""
    for s in range(regions):
        _principal_fit(q, part, s, regions, iters, lo, hi, ends0)


@jit
def encode_run(blocks, out, signed, rec):
    """Search each block of finished values (16, 3) and write it: every mode
    quantised from the principal-axis endpoints (one region; two regions on
    the best prm.partitions shapes), the best prm.refine of those (mode,
    shape) pairs refined, and the winner's codes nudged (prm.climb). The
    search's top level is here, with the block loop, and the working arrays
    are made once per run: numba compiles every caller with its callees."""
    prm = rec[0]
    lo = -float(HALF_MAX) if signed else 0.0
    hi = float(HALF_MAX)
    codes = np.zeros((3, 4, 3), np.int64)  # best, this mode's best, scratch
    idx = np.zeros((3, 16), np.int64)
    pal = np.zeros((2, 16, 3), np.int64)
    ends = np.zeros((4, 3))
    ends0 = np.zeros((4, 3))
    cand = np.zeros((max(1, prm.refine), 3), np.int64)
    rough = np.zeros(32)
    order = np.zeros(32, np.int64)
    tab = np.zeros((16, 16), np.int64)
    col = np.zeros(16, np.int64)
    for b in range(blocks.shape[0]):
        q = blocks[b]
        for r in range(cand.shape[0]):
            cand[r, 0] = BIG
        best_err = BIG
        best_mode, best_part = 10, 0
        # one region: modes 11..14
        _region_fits(q, 0, 1, prm.power_iters, lo, hi, ends0)
        for mi in range(10, NMODES):
            e = _first_fit(q, 0, mi, signed, ends0, codes, idx, pal, ends)
            _keep(cand, e, mi, 0)
            if e < best_err:
                best_err, best_mode, best_part = e, mi, 0
                _take(codes, idx, 0, 2)
        if best_err > 0 and prm.partitions > 0:
            # two regions: rank the 32 shapes by what a line per region
            # leaves, then the two-region modes on the best of them
            _rank_partitions(q, prm.power_iters, rough)
            order_by(rough, order)  # the shapes by rough cost, cheapest first
            for k in range(min(32, prm.partitions)):
                p = order[k]
                _region_fits(q, p, 2, prm.power_iters, lo, hi, ends0)
                tried = 0
                for mi in BY_PRECISION:
                    if tried == prm.modes:
                        break
                    if prm.modes < 10 and not _deltas_fit(ends0, p, mi, signed):
                        continue
                    tried += 1
                    e = _first_fit(q, p, mi, signed, ends0, codes, idx, pal, ends)
                    _keep(cand, e, mi, p)
                    if e < best_err:
                        best_err, best_mode, best_part = e, mi, p
                        _take(codes, idx, 0, 2)
        for r in range(cand.shape[0]):
            if cand[r, 0] == BIG or best_err == 0 or prm.ls_iters == 0:
                break
            mi, p = cand[r, 1], cand[r, 2]
            _region_fits(q, p, MODE_INFO[mi, I_REGIONS], prm.power_iters, lo, hi, ends0)
            e = _try_mode(q, p, mi, signed, prm, ends0, codes, idx, best_err, pal, ends)
            if e < best_err:
                best_err, best_mode, best_part = e, mi, p
        if prm.climb > 0 and best_err > 0:
            _take(codes, idx, 1, 0)
            best_err = _climb(q, best_part, best_mode, signed, prm.climb, codes, idx, best_err, pal, tab, col)
            _take(codes, idx, 0, 1)
        pack_block(best_mode, best_part, codes[0], idx[0], signed, out[b])
