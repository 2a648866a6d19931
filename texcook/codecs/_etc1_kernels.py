"""ETC1 kernels: bit packing, decoding and the block search.

A block is handled in symbolic form, an int64 vector of SYM_LEN fields:

    0 diff, 1 flip,
    2..4  base colour of sub-block 1 (4-bit values, or 5-bit in differential mode)
    5..7  base colour of sub-block 2 (4-bit, or the absolute 5-bit colour; the
          packer turns it into a delta)
    8, 9  modifier table of sub-block 1 and 2
    10..25 selector of each texel in row-major order (y * 4 + x):
          0 -> +a, 1 -> +b, 2 -> -a, 3 -> -b (the (MSB, LSB) pairs 00, 01, 10, 11)

The search only ever produces symbolic blocks; `pack_sym` / `unpack_sym` are the
only code that knows the bit layout.
"""

import numpy as np

from texcook._jit import jit
from texcook._jit import jit_inner as _inner  # helpers only called from other kernels

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


# ---------------------------------------------------------------- bit packing


@jit
def pack_sym(sym, out):
    """Symbolic block -> 8 bytes (big-endian 64-bit word)."""
    diff = sym[0]
    if diff:
        for c in range(3):
            d = sym[5 + c] - sym[2 + c]
            out[c] = ((sym[2 + c] & 31) << 3) | (d & 7)
    else:
        for c in range(3):
            out[c] = ((sym[2 + c] & 15) << 4) | (sym[5 + c] & 15)
    out[3] = ((sym[8] & 7) << 5) | ((sym[9] & 7) << 2) | ((diff & 1) << 1) | (sym[1] & 1)
    msb = 0
    lsb = 0
    for y in range(4):
        for x in range(4):
            s = sym[10 + y * 4 + x]
            k = x * 4 + y  # texels are numbered down the columns
            msb |= ((s >> 1) & 1) << k
            lsb |= (s & 1) << k
    out[4] = (msb >> 8) & 255
    out[5] = msb & 255
    out[6] = (lsb >> 8) & 255
    out[7] = lsb & 255


@jit
def unpack_sym(data, sym):
    """8 bytes -> symbolic block (inverse of pack_sym)."""
    diff = (data[3] >> 1) & 1
    sym[0] = diff
    sym[1] = data[3] & 1
    for c in range(3):
        v = np.int64(data[c])
        if diff:
            base = v >> 3
            d = v & 7
            if d >= 4:
                d -= 8
            sym[2 + c] = base
            sym[5 + c] = base + d
        else:
            sym[2 + c] = v >> 4
            sym[5 + c] = v & 15
    sym[8] = (data[3] >> 5) & 7
    sym[9] = (data[3] >> 2) & 7
    msb = (np.int64(data[4]) << 8) | np.int64(data[5])
    lsb = (np.int64(data[6]) << 8) | np.int64(data[7])
    for y in range(4):
        for x in range(4):
            k = x * 4 + y
            sym[10 + y * 4 + x] = (((msb >> k) & 1) << 1) | ((lsb >> k) & 1)


@_inner
def _expand(v, diff):
    # 5-bit sums outside 0..31 are invalid ETC1 (ETC2 reads them as other
    # modes); wrap to 5 bits as ETC1 hardware does
    if diff:
        return EXPAND5[v & 31]
    return EXPAND4[v & 15]


@jit
def decode_sym(sym, texels):
    """Symbolic block -> texels (16, 4) uint8 RGBA, row-major."""
    diff = sym[0]
    flip = sym[1]
    for y in range(4):
        for x in range(4):
            second = (y >= 2) if flip else (x >= 2)
            off = 5 if second else 2
            t = sym[9] if second else sym[8]
            m = MODS[t, sym[10 + y * 4 + x]]
            i = y * 4 + x
            for c in range(3):
                v = _expand(sym[off + c], diff) + m
                texels[i, c] = min(255, max(0, v))
            texels[i, 3] = 255


@jit
def decode_blocks(data, out):
    sym = np.zeros(SYM_LEN, np.int64)
    for n in range(data.shape[0]):
        unpack_sym(data[n], sym)
        decode_sym(sym, out[n])


@jit
def pack_blocks(syms, out):
    for n in range(syms.shape[0]):
        pack_sym(syms[n], out[n])


# ---------------------------------------------------------------- search
#
# The error of a texel is sum_c w_c (clamp(base_c + m) - p_c)^2 with integer
# channel weights w; the search minimises it exactly.

# indices into the params vector (see etc1.py for the presets)
P_FAST = 0  # 1: pick flip and mode from sub-block averages before searching
P_TABLE_SEEDS = 1  # 1: add one seed per table (base refined for that table)
P_RADIUS = 2  # lattice radius around each seed, in quantised steps
P_REFINE = 3  # rounds of re-centring the base on the chosen selectors
P_REFINE_RADIUS = 4  # lattice radius around each refined base
P_CONSTRAINED = 5  # 1: always try constrained differential pairs
P_BOX = 6  # 1: also try every floor/ceiling code combination around each target
P_LEN = 7

MAX_CAND = 4096
BIG = np.int64(1) << 62


@_inner(inline="always")
def _eval_table(px, w, b0, b1, b2, t, cap):
    """Exact error of 8 texels against base (b0, b1, b2) and table t; stops
    once the sum reaches cap."""
    ma = MODS[t, 0]
    mb = MODS[t, 1]
    # the four candidate colours, clamped (scalars: no allocation in the hot path)
    pa0 = min(255, b0 + ma)
    pa1 = min(255, b1 + ma)
    pa2 = min(255, b2 + ma)
    pb0 = min(255, b0 + mb)
    pb1 = min(255, b1 + mb)
    pb2 = min(255, b2 + mb)
    na0 = max(0, b0 - ma)
    na1 = max(0, b1 - ma)
    na2 = max(0, b2 - ma)
    nb0 = max(0, b0 - mb)
    nb1 = max(0, b1 - mb)
    nb2 = max(0, b2 - mb)
    w0 = w[0]
    w1 = w[1]
    w2 = w[2]
    err = np.int64(0)
    for i in range(8):
        p0 = px[i, 0]
        p1 = px[i, 1]
        p2 = px[i, 2]
        d0 = pa0 - p0
        d1 = pa1 - p1
        d2 = pa2 - p2
        best = w0 * d0 * d0 + w1 * d1 * d1 + w2 * d2 * d2
        d0 = pb0 - p0
        d1 = pb1 - p1
        d2 = pb2 - p2
        e = w0 * d0 * d0 + w1 * d1 * d1 + w2 * d2 * d2
        best = min(best, e)
        d0 = na0 - p0
        d1 = na1 - p1
        d2 = na2 - p2
        e = w0 * d0 * d0 + w1 * d1 * d1 + w2 * d2 * d2
        best = min(best, e)
        d0 = nb0 - p0
        d1 = nb1 - p1
        d2 = nb2 - p2
        e = w0 * d0 * d0 + w1 * d1 * d1 + w2 * d2 * d2
        best = min(best, e)
        err += best
        if err >= cap:
            return err
    return err


@_inner
def _select(px, w, b0, b1, b2, t, sel):
    """Best selector of each of 8 texels (exact, first best on ties); returns the error."""
    err = np.int64(0)
    for i in range(8):
        best = BIG
        bk = 0
        for k in range(4):
            m = MODS[t, k]
            d0 = min(255, max(0, b0 + m)) - px[i, 0]
            d1 = min(255, max(0, b1 + m)) - px[i, 1]
            d2 = min(255, max(0, b2 + m)) - px[i, 2]
            e = w[0] * d0 * d0 + w[1] * d1 * d1 + w[2] * d2 * d2
            if e < best:
                best = e
                bk = k
        sel[i] = bk
        err += best
    return err


@_inner(inline="always")
def _nearest_mod(d, t):
    """Modifier of table t nearest to d (unclamped model)."""
    a = TABLES[t, 0]
    b = TABLES[t, 1]
    ad = abs(d)
    m = a if ad * 2.0 < a + b else b
    return m if d >= 0 else -m


@_inner
def _eval_all(px, w, b0, b1, b2, dabs):
    """Best (error, table) over the eight tables for one base colour, exact.

    Where no channel of base +- b leaves 0..255, a texel's error for modifier m
    is E0 + 2 m D + W m^2 (E0 its error against the base, D = sum w_c (b_c - p_c),
    W = sum w), so a table costs a few operations per texel; tables that clamp
    are evaluated texel by texel, stopping at the best error so far."""
    w0 = w[0]
    w1 = w[1]
    w2 = w[2]
    wsum = w0 + w1 + w2
    e0 = np.int64(0)
    for i in range(8):
        d0 = b0 - px[i, 0]
        d1 = b1 - px[i, 1]
        d2 = b2 - px[i, 2]
        e0 += w0 * d0 * d0 + w1 * d1 * d1 + w2 * d2 * d2
        dabs[i] = abs(w0 * d0 + w1 * d1 + w2 * d2)
    lo = min(b0, min(b1, b2))
    hi = max(b0, max(b1, b2))
    best = BIG
    bt = 0
    for t in range(8):
        a = TABLES[t, 0]
        b = TABLES[t, 1]
        if hi + b > 255 or lo - b < 0:
            continue
        wa = wsum * a * a
        wb = wsum * b * b
        e = e0
        for i in range(8):
            d = dabs[i]
            e += min(wa - 2 * a * d, wb - 2 * b * d)
        if e < best:
            best = e
            bt = t
    for t in range(8):
        b = TABLES[t, 1]
        if hi + b > 255 or lo - b < 0:
            e = _eval_table(px, w, b0, b1, b2, t, best)
            if e < best:
                best = e
                bt = t
    return best, bt


@_inner
def _quant(v, prec):
    iv = int(np.floor(v + 0.5))
    iv = min(255, max(0, iv))
    return QUANT5[iv] if prec == 5 else QUANT4[iv]


@_inner
def _expand_p(c, prec):
    return EXPAND5[c] if prec == 5 else EXPAND4[c]


@_inner
def _push(c0, c1, c2, stamp, gen, cc, n):
    """List colour code (c0, c1, c2) in cc unless already seen; returns the new count."""
    key = (c0 << 10) | (c1 << 5) | c2
    if stamp[key] == gen or n >= cc.shape[0]:
        return n
    stamp[key] = gen
    cc[n, 0] = c0
    cc[n, 1] = c1
    cc[n, 2] = c2
    return n + 1


@_inner
def _floor_code(v, prec):
    """Largest code whose expansion is <= v (0 if none)."""
    top = 31 if prec == 5 else 15
    c = min(top, max(0, int(v * top / 255.0)))
    while c < top and _expand_p(c + 1, prec) <= v:
        c += 1
    while c > 0 and _expand_p(c, prec) > v:
        c -= 1
    return c


@_inner
def _around(prec, v0, v1, v2, box, r, lo, hi, stamp, gen, cc, n):
    """List the codes around the continuous base (v0, v1, v2): the nearest
    code with a lattice of radius r, and with `box` also every floor/ceiling
    combination (rounding each channel to nearest is not always best).
    Only lists them: _search_sub evaluates, so that the evaluation's code is
    not compiled into this function's module as well."""
    q0 = min(hi[0], max(lo[0], _quant(v0, prec)))
    q1 = min(hi[1], max(lo[1], _quant(v1, prec)))
    q2 = min(hi[2], max(lo[2], _quant(v2, prec)))
    for d0 in range(-r, r + 1):
        c0 = q0 + d0
        if c0 < lo[0] or c0 > hi[0]:
            continue
        for d1 in range(-r, r + 1):
            c1 = q1 + d1
            if c1 < lo[1] or c1 > hi[1]:
                continue
            for d2 in range(-r, r + 1):
                c2 = q2 + d2
                if c2 < lo[2] or c2 > hi[2]:
                    continue
                n = _push(c0, c1, c2, stamp, gen, cc, n)
    if box:
        f0 = min(hi[0], max(lo[0], _floor_code(v0, prec)))
        f1 = min(hi[1], max(lo[1], _floor_code(v1, prec)))
        f2 = min(hi[2], max(lo[2], _floor_code(v2, prec)))
        for c0 in range(f0, min(hi[0], f0 + 1) + 1):
            for c1 in range(f1, min(hi[1], f1 + 1) + 1):
                for c2 in range(f2, min(hi[2], f2 + 1) + 1):
                    n = _push(c0, c1, c2, stamp, gen, cc, n)
    return n


@_inner
def _search_sub(px, lum, w, wsum, prec, params, lo, hi, stamp, gen, cc, ce, ct, ws_f, ws_i):
    """Search base colours (codes of `prec` bits within lo..hi per channel) for
    one 8-texel sub-block. Every colour evaluated is listed in cc/ce/ct
    (code, error, best table); returns the count. ws_f (float64, >= 12) and
    ws_i (int64, >= 16) are scratch space, passed in to keep allocation out of
    the per-block loop.

    The seeds are listed first and evaluated in one loop, in the order
    listed; each re-centring round lists its codes and goes round that loop
    again. One call site of _eval_all keeps the compiled search small."""
    avg = ws_f[8:11]
    dabs = ws_i[0:8]
    sel = ws_i[8:16]
    radius = params[P_RADIUS]
    box = params[P_BOX]
    avg[:] = 0.0
    for i in range(8):
        for c in range(3):
            avg[c] += px[i, c]
    avg /= 8.0
    n = _around(prec, avg[0], avg[1], avg[2], box, radius, lo, hi, stamp, gen, cc, np.int64(0))
    if _is_constant(px):
        # every table's best single-colour code (clamped into the allowed box)
        p = 1 if prec == 5 else 0
        for t in range(8):
            for k in range(4):
                c0 = min(hi[0], max(lo[0], np.int64(SINGLE_CODE[p, t, k, px[0, 0]])))
                c1 = min(hi[1], max(lo[1], np.int64(SINGLE_CODE[p, t, k, px[0, 1]])))
                c2 = min(hi[2], max(lo[2], np.int64(SINGLE_CODE[p, t, k, px[0, 2]])))
                n = _push(c0, c1, c2, stamp, gen, cc, n)
    if params[P_TABLE_SEEDS]:
        # the best unquantised base for fixed selectors is avg - mean(modifier):
        # it moves along the grey axis, so each table has its own optimum
        for t in range(8):
            shift = 0.0
            for _ in range(2):
                lb = (w[0] * (avg[0] - shift) + w[1] * (avg[1] - shift)
                      + w[2] * (avg[2] - shift)) / wsum
                msum = 0.0
                for i in range(8):
                    msum += _nearest_mod(lum[i] - lb, t)
                shift = msum / 8.0
            n = _around(prec, avg[0] - shift, avg[1] - shift, avg[2] - shift, box,
                        radius, lo, hi, stamp, gen, cc, n)
    rr = params[P_REFINE_RADIUS]
    done = 0
    rounds = 0
    while True:
        for j in range(done, n):
            e, t = _eval_all(px, w, _expand_p(cc[j, 0], prec), _expand_p(cc[j, 1], prec),
                             _expand_p(cc[j, 2], prec), dabs)
            ce[j] = e
            ct[j] = t
        done = n
        if rounds >= params[P_REFINE]:
            break
        rounds += 1
        # re-centre on the best colour's selectors
        bi = 0
        for j in range(1, n):
            if ce[j] < ce[bi]:
                bi = j
        t = ct[bi]
        _select(px, w, _expand_p(cc[bi, 0], prec), _expand_p(cc[bi, 1], prec),
                _expand_p(cc[bi, 2], prec), t, sel)
        msum = 0.0
        for i in range(8):
            msum += MODS[t, sel[i]]
        shift = msum / 8.0
        n = _around(prec, avg[0] - shift, avg[1] - shift, avg[2] - shift, box, rr,
                    lo, hi, stamp, gen, cc, n)
        if n == done:
            break
    return n


@_inner
def _best(ce, n):
    bi = 0
    for j in range(1, n):
        if ce[j] < ce[bi]:
            bi = j
    return bi


@_inner
def _argsort(a, n, r, stack):
    """r[:n] = the indices that sort a[:n], by the same steps as numba's
    np.argsort (median-of-three quicksort, insertion sort below 16 items), so
    equal values come out in the same order. Written out here because the
    library's generic version costs seconds of compile time on a cold cache.
    stack: int64 scratch of >= 200 entries."""
    for i in range(n):
        r[i] = i
    if n < 2:
        return
    stack[0] = 0
    stack[1] = n - 1
    top = 1
    while top > 0:
        top -= 1
        low = stack[2 * top]
        high = stack[2 * top + 1]
        while high - low >= 15:
            # partition r[low..high] around the median of three
            mid = (low + high) >> 1
            if a[r[mid]] < a[r[low]]:
                r[low], r[mid] = r[mid], r[low]
            if a[r[high]] < a[r[mid]]:
                r[high], r[mid] = r[mid], r[high]
            if a[r[mid]] < a[r[low]]:
                r[low], r[mid] = r[mid], r[low]
            pivot = a[r[mid]]
            r[high], r[mid] = r[mid], r[high]
            i = low
            j = high - 1
            while True:
                while i < high and a[r[i]] < pivot:
                    i += 1
                while j >= low and pivot < a[r[j]]:
                    j -= 1
                if i >= j:
                    break
                r[i], r[j] = r[j], r[i]
                i += 1
                j -= 1
            r[i], r[high] = r[high], r[i]
            # keep the larger side for later, go on with the smaller
            if high - i > i - low:
                if high > i:
                    stack[2 * top] = i + 1
                    stack[2 * top + 1] = high
                    top += 1
                high = i - 1
            else:
                if i > low:
                    stack[2 * top] = low
                    stack[2 * top + 1] = i - 1
                    top += 1
                low = i + 1
        for i in range(low + 1, high + 1):
            k = r[i]
            v = a[k]
            j = i
            while j > low and v < a[r[j - 1]]:
                r[j] = r[j - 1]
                j -= 1
            r[j] = k


@_inner(inline="always")
def _pair(ca, ea, na, cb, eb, nb, oa, ob, stack):
    """Cheapest pair of 5-bit colours whose difference fits the 3-bit deltas
    (-4..3 per channel). Returns (error, index a, index b); index -1 if none.
    oa, ob (>= na, nb entries) and stack (>= 200) are int64 scratch."""
    best = BIG
    ba = -1
    bb = -1
    if na == 0 or nb == 0:
        return best, ba, bb
    if na == 1 and nb == 1:
        for c in range(3):
            d = cb[0, c] - ca[0, c]
            if d < -4 or d > 3:
                return best, ba, bb
        return ea[0] + eb[0], 0, 0
    _argsort(ea, na, oa, stack)
    _argsort(eb, nb, ob, stack)
    emin_b = eb[ob[0]]
    for ia in range(na):
        i = oa[ia]
        if ea[i] + emin_b >= best:
            break
        for ib in range(nb):
            j = ob[ib]
            if ea[i] + eb[j] >= best:
                break
            ok = True
            for c in range(3):
                d = cb[j, c] - ca[i, c]
                if d < -4 or d > 3:
                    ok = False
            if ok:
                best = ea[i] + eb[j]
                ba = i
                bb = j
    return best, ba, bb


@_inner
def _const_best(v0, v1, v2, w, prec):
    """Best base code and table for a constant colour: (error per texel, c0, c1, c2, table)."""
    p = 1 if prec == 5 else 0
    best = BIG
    bt = 0
    bk = 0
    for t in range(8):
        for k in range(4):
            e = (w[0] * np.int64(SINGLE_ERR[p, t, k, v0]) + w[1] * np.int64(SINGLE_ERR[p, t, k, v1])
                 + w[2] * np.int64(SINGLE_ERR[p, t, k, v2]))
            if e < best:
                best = e
                bt = t
                bk = k
    c0 = np.int64(SINGLE_CODE[p, bt, bk, v0])
    c1 = np.int64(SINGLE_CODE[p, bt, bk, v1])
    c2 = np.int64(SINGLE_CODE[p, bt, bk, v2])
    return best, c0, c1, c2, bt


@_inner
def _is_constant(px):
    for i in range(1, 8):
        if px[i, 0] != px[0, 0] or px[i, 1] != px[0, 1] or px[i, 2] != px[0, 2]:
            return False
    return True


@_inner(inline="always")
def _constant_block(px, w, sym):
    """A block of one colour: the best single-colour encoding over both
    precisions (both halves share it, so the delta is 0). Returns False if the
    block is not constant."""
    if not (_is_constant(px[0]) and _is_constant(px[1]) and px[0, 0, 0] == px[1, 0, 0]
            and px[0, 0, 1] == px[1, 0, 1] and px[0, 0, 2] == px[1, 0, 2]):
        return False
    v0 = px[0, 0, 0]
    v1 = px[0, 0, 1]
    v2 = px[0, 0, 2]
    # precisions as run-time int64, not literals: numba would compile a
    # separate copy of the callee for each literal value
    e5, a0, a1, a2, t5 = _const_best(v0, v1, v2, w, np.int64(5))
    e4, b0, b1, b2, t4 = _const_best(v0, v1, v2, w, np.int64(4))
    sym[1] = 0
    if e5 <= e4:
        sym[0] = 1
        sym[2] = a0
        sym[3] = a1
        sym[4] = a2
        sym[8] = t5
    else:
        sym[0] = 0
        sym[2] = b0
        sym[3] = b1
        sym[4] = b2
        sym[8] = t4
    sym[5] = sym[2]
    sym[6] = sym[3]
    sym[7] = sym[4]
    sym[9] = sym[8]
    return True


@_inner
def _fast_code(px, avg, w, prec):
    """Base code of the `fastest` preset: the quantised average, or the best
    single-colour code when the sub-block is one colour."""
    if _is_constant(px):
        _, c0, c1, c2, _ = _const_best(px[0, 0], px[0, 1], px[0, 2], w, prec)
        return c0, c1, c2
    return _quant(avg[0], prec), _quant(avg[1], prec), _quant(avg[2], prec)


@_inner(inline="always")
def _fast_block(px, w, sym, ws_f, ws_i):
    """The `fastest` preset: flip from how well each pair of sub-block averages
    fits, then differential mode if the 5-bit averages fit the deltas (or one
    can be moved into the other's box), else individual; bases are quantised
    averages, tables searched exactly. Fills sym's colours, tables and mode."""
    avg = ws_f[0:12].reshape((4, 3))
    dabs = ws_i[0:8]
    var0 = 0.0
    var1 = 0.0
    for s in range(4):
        v = 0.0
        for c in range(3):
            m = 0.0
            for i in range(8):
                m += px[s, i, c]
            m /= 8.0
            avg[s, c] = m
            for i in range(8):
                d = px[s, i, c] - m
                v += w[c] * d * d
        if s < 2:
            var0 += v
        else:
            var1 += v
    flip = 1 if var1 < var0 else 0
    sa = 2 * flip
    sb = sa + 1
    sym[1] = flip
    p5 = np.int64(5)  # run-time value: one compiled callee for both precisions
    p4 = np.int64(4)
    qa0, qa1, qa2 = _fast_code(px[sa], avg[sa], w, p5)
    qb0, qb1, qb2 = _fast_code(px[sb], avg[sb], w, p5)
    fits = (-4 <= qb0 - qa0 <= 3) and (-4 <= qb1 - qa1 <= 3) and (-4 <= qb2 - qa2 <= 3)
    ea, ta = _eval_all(px[sa], w, EXPAND5[qa0], EXPAND5[qa1], EXPAND5[qa2], dabs)
    if fits:
        eb, tb = _eval_all(px[sb], w, EXPAND5[qb0], EXPAND5[qb1], EXPAND5[qb2], dabs)
        best = ea + eb
    else:
        # move the second base into the box the deltas allow around the first
        qb0 = min(qa0 + 3, max(qa0 - 4, qb0))
        qb1 = min(qa1 + 3, max(qa1 - 4, qb1))
        qb2 = min(qa2 + 3, max(qa2 - 4, qb2))
        eb, tb = _eval_all(px[sb], w, EXPAND5[qb0], EXPAND5[qb1], EXPAND5[qb2], dabs)
        best = ea + eb
    sym[0] = 1
    sym[2] = qa0
    sym[3] = qa1
    sym[4] = qa2
    sym[5] = qb0
    sym[6] = qb1
    sym[7] = qb2
    sym[8] = ta
    sym[9] = tb
    if fits:
        return
    ia0, ia1, ia2 = _fast_code(px[sa], avg[sa], w, p4)
    ib0, ib1, ib2 = _fast_code(px[sb], avg[sb], w, p4)
    ea, ta = _eval_all(px[sa], w, EXPAND4[ia0], EXPAND4[ia1], EXPAND4[ia2], dabs)
    eb, tb = _eval_all(px[sb], w, EXPAND4[ib0], EXPAND4[ib1], EXPAND4[ib2], dabs)
    if ea + eb < best:
        sym[0] = 0
        sym[2] = ia0
        sym[3] = ia1
        sym[4] = ia2
        sym[5] = ib0
        sym[6] = ib1
        sym[7] = ib2
        sym[8] = ta
        sym[9] = tb


def scratch():
    """encode_blocks' working arrays, made by the caller (one set per thread):
    numba's own array allocation compiles a routine per shape and dtype,
    about half a second of a cold start.

    stamp: colour codes seen (by generation); c5/e5/t5/n5: the 5-bit
    candidates (code, error, table) of the four sub-blocks, kept for pairing;
    c4/e4/t4 and cx/ex/tx: candidate lists of one search; best4*: each
    sub-block's best 4-bit candidate; px/lum: the texels by sub-block and
    their weighted luminance; lo/hi4/hi5/lo_c/hi_c: code boxes; the rest are
    small working vectors."""
    z = np.zeros
    hi4 = np.full(3, 15, np.int64)
    hi5 = np.full(3, 31, np.int64)
    return (z(32768, np.int64),
            z((4, MAX_CAND, 3), np.int64), z((4, MAX_CAND), np.int64), z((4, MAX_CAND), np.int64),
            z(4, np.int64),
            z((MAX_CAND, 3), np.int64), z(MAX_CAND, np.int64), z(MAX_CAND, np.int64),
            z((MAX_CAND, 3), np.int64), z(MAX_CAND, np.int64), z(MAX_CAND, np.int64),
            z((4, 3), np.int64), z(4, np.int64), z(4, np.int64),
            z((4, 8, 3), np.int64), z((4, 8), np.float64),
            z(3, np.int64), hi4, hi5, z(3, np.int64), z(3, np.int64),
            z(SYM_LEN, np.int64), z(8, np.int64), z(16, np.float64), z(48, np.int64),
            z(3, np.int64), z(3, np.int64), z(MAX_CAND, np.int64), z(MAX_CAND, np.int64), z(200, np.int64))


def _kernel(fast):
    """encode_blocks for the `fastest` preset (fast=True: averages, no search)
    or for the others (the search). Two kernels from one source: numba drops
    the branches on the constant before typing, so a bake compiles only the
    path its preset runs; its cache keys the two apart (the key hashes the
    closure's constants)."""

    @jit
    def encode_blocks(blocks, out, params, w, stamp, c5, e5, t5, n5, c4, e4, t4, cx, ex, tx, best4c, best4e, best4t,
                      px, lum, lo, hi4, hi5, lo_c, hi_c, sym, sel, ws_f, ws_i, dca, dcb, order_a, order_b, sort_stack):
        """blocks uint8 (n, 16, 4) -> out uint8 (n, 8). params: int64 (P_LEN,),
        w: int64 (3,) channel weights; the rest: working arrays from scratch()."""
        wsum = float(w[0] + w[1] + w[2])
        gen = np.int64(0)
        # stamps are compared with generations counted from 0 in this call
        for i in range(stamp.shape[0]):
            stamp[i] = 0
        # precisions and counters are run-time int64 so that each callee is
        # compiled once, not once per literal value it is called with
        p5 = np.int64(5)
        p4 = np.int64(4)
        for n in range(blocks.shape[0]):
            blk = blocks[n]
            for s in range(4):
                for i in range(8):
                    for c in range(3):
                        px[s, i, c] = blk[SUB_IDX[s, i], c]
            if not fast:
                for s in range(4):
                    for i in range(8):
                        lum[s, i] = (w[0] * px[s, i, 0] + w[1] * px[s, i, 1]
                                     + w[2] * px[s, i, 2]) / wsum
            if _constant_block(px, w, sym):
                f0 = 0
                f1 = 0  # solved exactly, no search
            elif fast:  # a constant of the kernel (see _kernel)
                _fast_block(px, w, sym, ws_f, ws_i)
                f0 = 0
                f1 = 0
            else:
                f0 = 0
                f1 = 2
            if not fast:
                best_total = BIG
                for flip in range(f0, f1):
                    sa = 2 * flip
                    sb = sa + 1
                    # differential: 5-bit colours whose difference fits the deltas
                    for s in (sa, sb):
                        gen += 1
                        n5[s] = _search_sub(px[s], lum[s], w, wsum, p5, params, lo, hi5, stamp, gen,
                                            c5[s], e5[s], t5[s], ws_f, ws_i)
                    de, ia, ib = _pair(c5[sa], e5[sa], n5[sa], c5[sb], e5[sb], n5[sb],
                                       order_a, order_b, sort_stack)
                    dta = 0
                    dtb = 0
                    if ia >= 0:
                        for c in range(3):
                            dca[c] = c5[sa, ia, c]
                            dcb[c] = c5[sb, ib, c]
                        dta = t5[sa, ia]
                        dtb = t5[sb, ib]
                    if ia < 0 or params[P_CONSTRAINED]:
                        # hold one sub-block at its best and search the other inside
                        # the box the deltas allow
                        for side in range(2):
                            s_fix = sa if side == 0 else sb
                            s_oth = sb if side == 0 else sa
                            bi = _best(e5[s_fix], n5[s_fix])
                            for c in range(3):
                                f = c5[s_fix, bi, c]
                                if side == 0:
                                    lo_c[c] = max(0, f - 4)
                                    hi_c[c] = min(31, f + 3)
                                else:
                                    lo_c[c] = max(0, f - 3)
                                    hi_c[c] = min(31, f + 4)
                            gen += 1
                            nx = _search_sub(px[s_oth], lum[s_oth], w, wsum, p5, params, lo_c, hi_c,
                                             stamp, gen, cx, ex, tx, ws_f, ws_i)
                            bj = _best(ex, nx)
                            tot = e5[s_fix, bi] + ex[bj]
                            if tot < de:
                                de = tot
                                if side == 0:
                                    for c in range(3):
                                        dca[c] = c5[sa, bi, c]
                                        dcb[c] = cx[bj, c]
                                    dta = t5[sa, bi]
                                    dtb = tx[bj]
                                else:
                                    for c in range(3):
                                        dca[c] = cx[bj, c]
                                        dcb[c] = c5[sb, bi, c]
                                    dta = tx[bj]
                                    dtb = t5[sb, bi]
                    if de < best_total:
                        best_total = de
                        sym[0] = 1
                        sym[1] = flip
                        for c in range(3):
                            sym[2 + c] = dca[c]
                            sym[5 + c] = dcb[c]
                        sym[8] = dta
                        sym[9] = dtb
                    # individual: 4-bit colours, each sub-block on its own
                    for s in (sa, sb):
                        gen += 1
                        k = _search_sub(px[s], lum[s], w, wsum, p4, params, lo, hi4, stamp, gen,
                                        c4, e4, t4, ws_f, ws_i)
                        bi = _best(e4, k)
                        for c in range(3):
                            best4c[s, c] = c4[bi, c]
                        best4e[s] = e4[bi]
                        best4t[s] = t4[bi]
                    ie = best4e[sa] + best4e[sb]
                    if ie < best_total:
                        best_total = ie
                        sym[0] = 0
                        sym[1] = flip
                        for c in range(3):
                            sym[2 + c] = best4c[sa, c]
                            sym[5 + c] = best4c[sb, c]
                        sym[8] = best4t[sa]
                        sym[9] = best4t[sb]
            # selectors for the chosen symbolic block
            prec = 5 if sym[0] else 4
            flip = sym[1]
            for half in range(2):
                s = 2 * flip + half
                off = 2 + 3 * half
                _select(px[s], w, _expand_p(sym[off], prec), _expand_p(sym[off + 1], prec),
                        _expand_p(sym[off + 2], prec), sym[8 + half], sel)
                for i in range(8):
                    sym[10 + SUB_IDX[s, i]] = sel[i]
            pack_sym(sym, out[n])

    return encode_blocks


_FAST = _kernel(True)
_SEARCH = _kernel(False)


def encode_blocks(blocks, out, params, w, *work):
    """blocks uint8 (n, 16, 4) -> out uint8 (n, 8) with the kernel the preset
    needs; work: the arrays from scratch()."""
    (_FAST if params[P_FAST] else _SEARCH)(blocks, out, params, w, *work)
