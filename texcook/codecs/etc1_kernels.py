"""ETC1 kernels: bit packing, decoding and the block search, on the symbolic
block of texcook.codecs.etc1_tables (its slots are named there).
"""

from collections import namedtuple

import numpy as np

from texcook._jit import borrow, jit
from texcook._jit import jit_inner as _inner  # helpers only called from other kernels

from .etc1_tables import (EXPAND4, EXPAND5, MODS, QUANT4, QUANT5, S_BASE1, S_BASE2, S_DIFF, S_FLIP, S_SEL,
                          S_TABLE1, S_TABLE2, SINGLE_CODE, SINGLE_ERR, SUB_BIT, SUB_IDX, SYM_LEN, TABLES)


# ---------------------------------------------------------------- bit packing


@_inner
def pack_selectors(sel, o, out):
    """The 16 2-bit selectors sel[o + 4y + x] (row-major) into bytes 4-7 of
    out: every ETC1/ETC2 block but planar stores them as a plane of high bits
    then one of low bits, texels numbered down the columns."""
    msb = 0
    lsb = 0
    for y in range(4):
        for x in range(4):
            s = sel[o + y * 4 + x]
            k = x * 4 + y
            msb |= ((s >> 1) & 1) << k
            lsb |= (s & 1) << k
    out[4] = (msb >> 8) & 255
    out[5] = msb & 255
    out[6] = (lsb >> 8) & 255
    out[7] = lsb & 255


@_inner
def unpack_selectors(data, sel, o):
    """Bytes 4-7 of data -> sel[o + 4y + x] (inverse of pack_selectors)."""
    msb = (np.int64(data[4]) << 8) | np.int64(data[5])
    lsb = (np.int64(data[6]) << 8) | np.int64(data[7])
    for y in range(4):
        for x in range(4):
            k = x * 4 + y
            sel[o + y * 4 + x] = (((msb >> k) & 1) << 1) | ((lsb >> k) & 1)


@jit
def pack_sym(sym, out):
    """Symbolic block -> 8 bytes (big-endian 64-bit word)."""
    diff = sym[S_DIFF]
    if diff:
        for c in range(3):
            d = sym[S_BASE2 + c] - sym[S_BASE1 + c]
            out[c] = ((sym[S_BASE1 + c] & 31) << 3) | (d & 7)
    else:
        for c in range(3):
            out[c] = ((sym[S_BASE1 + c] & 15) << 4) | (sym[S_BASE2 + c] & 15)
    out[3] = ((sym[S_TABLE1] & 7) << 5) | ((sym[S_TABLE2] & 7) << 2) | ((diff & 1) << 1) | (sym[S_FLIP] & 1)
    pack_selectors(sym, S_SEL, out)


@jit
def unpack_sym(data, sym):
    """8 bytes -> symbolic block (inverse of pack_sym)."""
    diff = (data[3] >> 1) & 1
    sym[S_DIFF] = diff
    sym[S_FLIP] = data[3] & 1
    for c in range(3):
        v = np.int64(data[c])
        if diff:
            base = v >> 3
            d = v & 7
            if d >= 4:
                d -= 8
            sym[S_BASE1 + c] = base
            sym[S_BASE2 + c] = base + d
        else:
            sym[S_BASE1 + c] = v >> 4
            sym[S_BASE2 + c] = v & 15
    sym[S_TABLE1] = (data[3] >> 5) & 7
    sym[S_TABLE2] = (data[3] >> 2) & 7
    unpack_selectors(data, sym, S_SEL)


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
    diff = sym[S_DIFF]
    flip = sym[S_FLIP]
    for y in range(4):
        for x in range(4):
            second = (y >= 2) if flip else (x >= 2)
            off = S_BASE2 if second else S_BASE1
            t = sym[S_TABLE2] if second else sym[S_TABLE1]
            m = MODS[t, sym[S_SEL + y * 4 + x]]
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

# The search reads its preset through a record of etc1.SEARCH (its columns
# are documented there), named prm in every function that reads it.

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
def select(px, w, b0, b1, b2, t, sel):
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


@_inner(inline="always")
def _unclamped(e0, wsum, t, dabs):
    """Error of table t for 8 texels were no colour clamped (see eval_all):
    each texel takes the better of modifiers +-a and +-b, E0 + W m^2 - 2 m |D|;
    e0 the texels' summed error against the base, dabs their |D|, wsum W."""
    a = TABLES[t, 0]
    b = TABLES[t, 1]
    wa = wsum * a * a
    wb = wsum * b * b
    e = e0
    for i in range(8):
        d = dabs[i]
        e += min(wa - 2 * a * d, wb - 2 * b * d)
    return e


@_inner
def eval_all(px, w, b0, b1, b2, dabs):
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
        b = TABLES[t, 1]
        if hi + b > 255 or lo - b < 0:
            continue
        e = _unclamped(e0, wsum, t, dabs)
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
def quant(v, prec):
    iv = int(np.floor(v + 0.5))
    iv = min(255, max(0, iv))
    return QUANT5[iv] if prec == 5 else QUANT4[iv]


@_inner
def expand_p(c, prec):
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
def floor_code(v, prec):
    """Largest code whose expansion is <= v (0 if none)."""
    top = 31 if prec == 5 else 15
    c = min(top, max(0, int(v * top / 255.0)))
    while c < top and expand_p(c + 1, prec) <= v:
        c += 1
    while c > 0 and expand_p(c, prec) > v:
        c -= 1
    return c


@_inner
def _around(prec, v0, v1, v2, box, r, lo, hi, stamp, gen, cc, n):
    """List the codes around the continuous base (v0, v1, v2): the nearest
    code with a lattice of radius r, and with `box` also every floor/ceiling
    combination (rounding each channel to nearest is not always best).
    Only lists them: _search_sub evaluates, so that the evaluation's code is
    not compiled into this function's module as well."""
    q0 = min(hi[0], max(lo[0], quant(v0, prec)))
    q1 = min(hi[1], max(lo[1], quant(v1, prec)))
    q2 = min(hi[2], max(lo[2], quant(v2, prec)))
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
        f0 = min(hi[0], max(lo[0], floor_code(v0, prec)))
        f1 = min(hi[1], max(lo[1], floor_code(v1, prec)))
        f2 = min(hi[2], max(lo[2], floor_code(v2, prec)))
        for c0 in range(f0, min(hi[0], f0 + 1) + 1):
            for c1 in range(f1, min(hi[1], f1 + 1) + 1):
                for c2 in range(f2, min(hi[2], f2 + 1) + 1):
                    n = _push(c0, c1, c2, stamp, gen, cc, n)
    return n


@_inner
def _search_sub(px, lum, w, wsum, prec, prm, lo, hi, gen, found, work):
    """Search base colours (codes of `prec` bits within lo..hi per channel) for
    one 8-texel sub-block. Every colour evaluated is listed in found = (cc,
    ce, ct) (code, error, best table); returns the count. work = (stamp, ws_f,
    ws_i): the codes seen (by generation gen) and float64 (>= 12) and int64
    (>= 16) scratch space, passed in to keep allocation out of the per-block
    loop.

    The seeds are listed first and evaluated in one loop, in the order
    listed; each re-centring round lists its codes and goes round that loop
    again. One call site of eval_all keeps the compiled search small."""
    cc, ce, ct = found
    stamp, ws_f, ws_i = work
    avg = ws_f[8:11]
    dabs = ws_i[0:8]
    sel = ws_i[8:16]
    radius = prm.radius
    box = prm.box
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
    if prm.table_seeds:
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
    rr = prm.refine_radius
    done = 0
    rounds = 0
    while True:
        for j in range(done, n):
            e, t = eval_all(px, w, expand_p(cc[j, 0], prec), expand_p(cc[j, 1], prec),
                            expand_p(cc[j, 2], prec), dabs)
            ce[j] = e
            ct[j] = t
        done = n
        if rounds >= prm.refine:
            break
        rounds += 1
        # re-centre on the best colour's selectors
        bi = 0
        for j in range(1, n):
            if ce[j] < ce[bi]:
                bi = j
        t = ct[bi]
        select(px, w, expand_p(cc[bi, 0], prec), expand_p(cc[bi, 1], prec),
               expand_p(cc[bi, 2], prec), t, sel)
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
    sym[S_FLIP] = 0
    if e5 <= e4:
        sym[S_DIFF] = 1
        sym[S_BASE1] = a0
        sym[S_BASE1 + 1] = a1
        sym[S_BASE1 + 2] = a2
        sym[S_TABLE1] = t5
    else:
        sym[S_DIFF] = 0
        sym[S_BASE1] = b0
        sym[S_BASE1 + 1] = b1
        sym[S_BASE1 + 2] = b2
        sym[S_TABLE1] = t4
    for c in range(3):
        sym[S_BASE2 + c] = sym[S_BASE1 + c]  # one colour: the delta is 0
    sym[S_TABLE2] = sym[S_TABLE1]
    return True


# ---------------------------------------------------------------- the fastest preset
#
# One pass per block, no candidate lists: the flip from the sub-block sums,
# the quantised averages as bases, each base's table from the closed form of
# eval_all (clamping ignored, see _fit_half), then exact selectors. The
# per-texel loops have no branches:
#
# - flip: the weighted variance of a pair of sub-blocks is the block's sum of
#   w p^2 less sum w S^2 / 8 over the pair's sums S, so the pair with the
#   larger sum w S^2 has the lower variance (integers, exact);
# - selectors: a texel's error against colour P is
#   sum w P^2 - sum 2 w P p + sum w p^2, and the last term is the same for
#   every colour, so each texel takes the first minimum of four affine terms
#   (clamping included).


@_inner(inline="always")
def _palette(b0, b1, b2, t, w):
    """The four colours of table t around base (b0, b1, b2), clamped, and each
    one's sum w P^2."""
    m0 = MODS[t, 0]
    m1 = MODS[t, 1]
    m2 = MODS[t, 2]
    m3 = MODS[t, 3]
    a0 = min(255, max(0, b0 + m0))
    a1 = min(255, max(0, b1 + m0))
    a2 = min(255, max(0, b2 + m0))
    c0 = min(255, max(0, b0 + m1))
    c1 = min(255, max(0, b1 + m1))
    c2 = min(255, max(0, b2 + m1))
    d0 = min(255, max(0, b0 + m2))
    d1 = min(255, max(0, b1 + m2))
    d2 = min(255, max(0, b2 + m2))
    f0 = min(255, max(0, b0 + m3))
    f1 = min(255, max(0, b1 + m3))
    f2 = min(255, max(0, b2 + m3))
    w0 = w[0]
    w1 = w[1]
    w2 = w[2]
    qa = w0 * a0 * a0 + w1 * a1 * a1 + w2 * a2 * a2
    qc = w0 * c0 * c0 + w1 * c1 * c1 + w2 * c2 * c2
    qd = w0 * d0 * d0 + w1 * d1 * d1 + w2 * d2 * d2
    qf = w0 * f0 * f0 + w1 * f1 * f1 + w2 * f2 * f2
    return (a0, a1, a2, qa), (c0, c1, c2, qc), (d0, d1, d2, qd), (f0, f1, f2, qf)


@_inner
def _fit_half(p, q, const, h, b0, b1, b2, w):
    """(estimated error, table) of half h's best table for base (b0, b1, b2)
    (expanded): every table costs E0 + 2 m D + W m^2 per texel, its error
    were no colour clamped to 0..255 (see eval_all), the first best kept.
    Exact for the tables that do not clamp; for those that do it is an upper
    bound (a clamped colour is nearer every texel), so a table that wins only
    through clamping is missed. A half of one colour (const[h]) is measured
    exactly instead: one texel's error against each table's four colours.
    p[h] holds the texels by channel; q: 8 int64."""
    w0 = w[0]
    w1 = w[1]
    w2 = w[2]
    if const[h]:
        best = BIG
        bt = 0
        for t in range(8):
            pa, pc, pd, pf = _palette(b0, b1, b2, t, w)
            e = BIG
            for k in range(4):
                x = pa if k == 0 else pc if k == 1 else pd if k == 2 else pf
                d0 = x[0] - p[h, 0, 0]
                d1 = x[1] - p[h, 1, 0]
                d2 = x[2] - p[h, 2, 0]
                e = min(e, w0 * d0 * d0 + w1 * d1 * d1 + w2 * d2 * d2)
            if e < best:
                best = e
                bt = t
        return 8 * best, bt
    wsum = w0 + w1 + w2
    e0 = np.int64(0)
    for i in range(8):
        d0 = b0 - p[h, 0, i]
        d1 = b1 - p[h, 1, i]
        d2 = b2 - p[h, 2, i]
        e0 += w0 * d0 * d0 + w1 * d1 * d1 + w2 * d2 * d2
        q[i] = abs(w0 * d0 + w1 * d1 + w2 * d2)
    best = BIG
    bt = 0
    for t in range(8):
        e = _unclamped(e0, wsum, t, q)
        if e < best:
            best = e
            bt = t
        elif e > best:
            break
    return best, bt


@_inner
def _select_half(u, s2, h, s, b0, b1, b2, t, w):
    """Selectors of half h (sub-block s) for base (b0, b1, b2) and table t, the
    first best of each texel as select picks it: (error, msb plane, lsb plane)
    with the half's bits set."""
    pa, pc, pd, pf = _palette(b0, b1, b2, t, w)
    err = np.int64(0)
    msb = np.int64(0)
    lsb = np.int64(0)
    for i in range(8):
        u0 = u[h, 0, i]
        u1 = u[h, 1, i]
        u2 = u[h, 2, i]
        e = pa[3] - pa[0] * u0 - pa[1] * u1 - pa[2] * u2
        k = np.int64(0)
        x = pc[3] - pc[0] * u0 - pc[1] * u1 - pc[2] * u2
        k = np.int64(1) if x < e else k
        e = min(e, x)
        x = pd[3] - pd[0] * u0 - pd[1] * u1 - pd[2] * u2
        k = np.int64(2) if x < e else k
        e = min(e, x)
        x = pf[3] - pf[0] * u0 - pf[1] * u1 - pf[2] * u2
        k = np.int64(3) if x < e else k
        e = min(e, x)
        err += e
        bit = SUB_BIT[s, i]
        msb |= (k >> 1) << bit
        lsb |= (k & 1) << bit
    return err + s2[h], msb, lsb


@_inner(inline="always")
def _half_code(p, sums, const, h, w, prec):
    """Base code of half h for the `fastest` preset: the quantised average, or
    the best single-colour code when the half is one colour."""
    if const[h]:
        _, c0, c1, c2, _ = _const_best(p[h, 0, 0], p[h, 1, 0], p[h, 2, 0], w, prec)
        return c0, c1, c2
    q = QUANT5 if prec == 5 else QUANT4
    # the average rounded to the nearest integer, S / 8 + 0.5 floored
    return q[(sums[h, 0] + 4) >> 3], q[(sums[h, 1] + 4) >> 3], q[(sums[h, 2] + 4) >> 3]


# fast_blocks' per-thread working arrays: quad the 2x2 quadrants' sums and
# sums of squares by channel; p, u, s2, sums, const each of the block's two
# halves' texels by channel, 2 w p, sum w p^2, channel sums, and whether it is
# one colour; q 8 int64.
FastScratch = namedtuple("FastScratch", "quad p u s2 sums const q")


def fast_scratch():
    """One thread's FastScratch for fast_blocks (and etc2's fastest pass)."""
    z = np.zeros
    return FastScratch(z((2, 4, 3), np.int64), z((2, 3, 8), np.int64), z((2, 3, 8), np.int64), z(2, np.int64),
                       z((2, 3), np.int64), z(2, np.int64), z(8, np.int64))


@_inner(inline="always")
def fast_block(blk, ob, w, scr):
    """The `fastest` preset on one block: blk uint8 (16, 4) -> ob uint8 (8,);
    returns the block's error. scr: a FastScratch (borrowed views).

    The flip whose sub-blocks vary least around their averages; differential
    mode when the two 5-bit averages fit the deltas, else the better of a
    differential pair with the second base moved into the first's delta box
    and individual mode; bases the quantised averages (a one-colour half: its
    best single-colour code; a one-colour block: the best over both modes)."""
    quad, p, u, s2, sums, const, q = scr
    for k in range(4):
        for c in range(3):
            quad[0, k, c] = 0
            quad[1, k, c] = 0
    for i in range(16):
        k = ((i >> 3) << 1) | ((i >> 1) & 1)  # quadrant: top/bottom, left/right
        for c in range(3):
            v = np.int64(blk[i, c])
            quad[0, k, c] += v
            quad[1, k, c] += v * v
    # one colour: 16 sum p^2 == S^2 in every channel
    flat = True
    for c in range(3):
        sc = quad[0, 0, c] + quad[0, 1, c] + quad[0, 2, c] + quad[0, 3, c]
        qc = quad[1, 0, c] + quad[1, 1, c] + quad[1, 2, c] + quad[1, 3, c]
        flat = flat and 16 * qc == sc * sc
    # sum w S^2 of the left/right pair and of the top/bottom pair
    lr = np.int64(0)
    tb = np.int64(0)
    for c in range(3):
        sl = quad[0, 0, c] + quad[0, 2, c]
        sr = quad[0, 1, c] + quad[0, 3, c]
        st = quad[0, 0, c] + quad[0, 1, c]
        sb = quad[0, 2, c] + quad[0, 3, c]
        lr += w[c] * (sl * sl + sr * sr)
        tb += w[c] * (st * st + sb * sb)
    flip = 1 if tb > lr and not flat else 0
    for h in range(2):
        s = 2 * flip + h
        acc = np.int64(0)
        one = True
        for c in range(3):
            a = np.int64(0)
            a2 = np.int64(0)
            wc = w[c]
            for j in range(8):
                v = np.int64(blk[SUB_IDX[s, j], c])
                p[h, c, j] = v
                u[h, c, j] = 2 * wc * v
                a += v
                a2 += v * v
            sums[h, c] = a
            acc += wc * a2
            one = one and 8 * a2 == a * a
        s2[h] = acc
        const[h] = one
    p5 = np.int64(5)  # run-time values: one compiled callee for both precisions
    p4 = np.int64(4)
    H0 = np.int64(0)
    H1 = np.int64(1)
    if flat:
        v0 = p[0, 0, 0]
        v1 = p[0, 1, 0]
        v2 = p[0, 2, 0]
        e5, a0, a1, a2, t5 = _const_best(v0, v1, v2, w, p5)
        e4, x0, x1, x2, t4 = _const_best(v0, v1, v2, w, p4)
        diff = 1 if e5 <= e4 else 0
        if diff:
            qa0, qa1, qa2, ta = a0, a1, a2, t5
        else:
            qa0, qa1, qa2, ta = x0, x1, x2, t4
        qb0, qb1, qb2, tb_ = qa0, qa1, qa2, ta
    else:
        qa0, qa1, qa2 = _half_code(p, sums, const, 0, w, p5)
        qb0, qb1, qb2 = _half_code(p, sums, const, 1, w, p5)
        fits = (-4 <= qb0 - qa0 <= 3) and (-4 <= qb1 - qa1 <= 3) and (-4 <= qb2 - qa2 <= 3)
        if not fits:
            # move the second base into the box the deltas allow around the first
            qb0 = min(qa0 + 3, max(qa0 - 4, qb0))
            qb1 = min(qa1 + 3, max(qa1 - 4, qb1))
            qb2 = min(qa2 + 3, max(qa2 - 4, qb2))
        ea, ta = _fit_half(p, q, const, H0, EXPAND5[qa0], EXPAND5[qa1], EXPAND5[qa2], w)
        eb, tb_ = _fit_half(p, q, const, H1, EXPAND5[qb0], EXPAND5[qb1], EXPAND5[qb2], w)
        diff = 1
        if not fits:
            ia0, ia1, ia2 = _half_code(p, sums, const, 0, w, p4)
            ib0, ib1, ib2 = _half_code(p, sums, const, 1, w, p4)
            ea4, ta4 = _fit_half(p, q, const, H0, EXPAND4[ia0], EXPAND4[ia1], EXPAND4[ia2], w)
            eb4, tb4 = _fit_half(p, q, const, H1, EXPAND4[ib0], EXPAND4[ib1], EXPAND4[ib2], w)
            if ea4 + eb4 < ea + eb:
                diff = 0
                qa0, qa1, qa2, ta = ia0, ia1, ia2, ta4
                qb0, qb1, qb2, tb_ = ib0, ib1, ib2, tb4
    if diff:
        ob[0] = ((qa0 & 31) << 3) | ((qb0 - qa0) & 7)
        ob[1] = ((qa1 & 31) << 3) | ((qb1 - qa1) & 7)
        ob[2] = ((qa2 & 31) << 3) | ((qb2 - qa2) & 7)
        ea, ma, la = _select_half(u, s2, H0, 2 * flip, EXPAND5[qa0], EXPAND5[qa1], EXPAND5[qa2], ta, w)
        eb, mb, lb = _select_half(u, s2, H1, 2 * flip + 1, EXPAND5[qb0], EXPAND5[qb1], EXPAND5[qb2], tb_, w)
    else:
        ob[0] = (qa0 << 4) | qb0
        ob[1] = (qa1 << 4) | qb1
        ob[2] = (qa2 << 4) | qb2
        ea, ma, la = _select_half(u, s2, H0, 2 * flip, EXPAND4[qa0], EXPAND4[qa1], EXPAND4[qa2], ta, w)
        eb, mb, lb = _select_half(u, s2, H1, 2 * flip + 1, EXPAND4[qb0], EXPAND4[qb1], EXPAND4[qb2], tb_, w)
    ob[3] = (ta << 5) | (tb_ << 2) | (diff << 1) | flip
    msb = ma | mb
    lsb = la | lb
    ob[4] = (msb >> 8) & 255
    ob[5] = msb & 255
    ob[6] = (lsb >> 8) & 255
    ob[7] = lsb & 255
    return ea + eb


@jit
def fast_blocks(blocks, out, w, scr):
    """The `fastest` preset: blocks uint8 (n, 16, 4) -> out uint8 (n, 8);
    w: int64 (3,) channel weights, scr: this thread's fast_scratch()."""
    ws = borrow(scr)  # the pieces take views without reference counting (scr outlives them)
    wt = (w[0], w[1], w[2])
    for n in range(blocks.shape[0]):
        fast_block(blocks[n], out[n], wt, ws)


# search_blocks' per-thread working arrays, made by the caller: numba's own
# array allocation compiles a routine per shape and dtype, about half a second
# of a cold start. stamp: colour codes seen (by generation); c5/e5/t5/n5: the
# 5-bit candidates (code, error, table) of the four sub-blocks, kept for
# pairing; c4/e4/t4 and cx/ex/tx: candidate lists of one search; best4*: each
# sub-block's best 4-bit candidate; px/lum: the texels by sub-block and their
# weighted luminance; lo/hi4/hi5/lo_c/hi_c: code boxes; the rest are small
# working vectors.
Scratch = namedtuple("Scratch", "stamp c5 e5 t5 n5 c4 e4 t4 cx ex tx best4c best4e best4t px lum lo hi4 hi5 "
                                "lo_c hi_c sym sel ws_f ws_i dca dcb order_a order_b sort_stack")


def scratch():
    """One thread's Scratch for search_blocks."""
    z = np.zeros
    hi4 = np.full(3, 15, np.int64)
    hi5 = np.full(3, 31, np.int64)
    return Scratch(z(32768, np.int64),
                   z((4, MAX_CAND, 3), np.int64), z((4, MAX_CAND), np.int64), z((4, MAX_CAND), np.int64),
                   z(4, np.int64),
                   z((MAX_CAND, 3), np.int64), z(MAX_CAND, np.int64), z(MAX_CAND, np.int64),
                   z((MAX_CAND, 3), np.int64), z(MAX_CAND, np.int64), z(MAX_CAND, np.int64),
                   z((4, 3), np.int64), z(4, np.int64), z(4, np.int64),
                   z((4, 8, 3), np.int64), z((4, 8), np.float64),
                   z(3, np.int64), hi4, hi5, z(3, np.int64), z(3, np.int64),
                   z(SYM_LEN, np.int64), z(8, np.int64), z(16, np.float64), z(48, np.int64),
                   z(3, np.int64), z(3, np.int64), z(MAX_CAND, np.int64), z(MAX_CAND, np.int64), z(200, np.int64))


@jit
def search_blocks(blocks, out, rec, w, scr):
    """blocks uint8 (n, 16, 4) -> out uint8 (n, 8). rec: etc1.SEARCH.record(preset),
    w: int64 (3,) channel weights, scr: this thread's scratch()."""
    prm = rec[0]
    (stamp, c5, e5, t5, n5, c4, e4, t4, cx, ex, tx, best4c, best4e, best4t, px, lum, lo, hi4, hi5, lo_c, hi_c,
     sym, sel, ws_f, ws_i, dca, dcb, order_a, order_b, sort_stack) = scr
    work = (stamp, ws_f, ws_i)
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
        for s in range(4):
            for i in range(8):
                lum[s, i] = (w[0] * px[s, i, 0] + w[1] * px[s, i, 1]
                             + w[2] * px[s, i, 2]) / wsum
        # a block of one colour is solved exactly, without the search
        nflips = 0 if _constant_block(px, w, sym) else 2
        best_total = BIG
        for flip in range(nflips):
            sa = 2 * flip
            sb = sa + 1
            # differential: 5-bit colours whose difference fits the deltas
            for s in (sa, sb):
                gen += 1
                n5[s] = _search_sub(px[s], lum[s], w, wsum, p5, prm, lo, hi5, gen,
                                    (c5[s], e5[s], t5[s]), work)
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
            if ia < 0 or prm.constrained:
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
                    nx = _search_sub(px[s_oth], lum[s_oth], w, wsum, p5, prm, lo_c, hi_c,
                                     gen, (cx, ex, tx), work)
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
                sym[S_DIFF] = 1
                sym[S_FLIP] = flip
                for c in range(3):
                    sym[S_BASE1 + c] = dca[c]
                    sym[S_BASE2 + c] = dcb[c]
                sym[S_TABLE1] = dta
                sym[S_TABLE2] = dtb
            # individual: 4-bit colours, each sub-block on its own
            for s in (sa, sb):
                gen += 1
                k = _search_sub(px[s], lum[s], w, wsum, p4, prm, lo, hi4, gen,
                                (c4, e4, t4), work)
                bi = _best(e4, k)
                for c in range(3):
                    best4c[s, c] = c4[bi, c]
                best4e[s] = e4[bi]
                best4t[s] = t4[bi]
            ie = best4e[sa] + best4e[sb]
            if ie < best_total:
                best_total = ie
                sym[S_DIFF] = 0
                sym[S_FLIP] = flip
                for c in range(3):
                    sym[S_BASE1 + c] = best4c[sa, c]
                    sym[S_BASE2 + c] = best4c[sb, c]
                sym[S_TABLE1] = best4t[sa]
                sym[S_TABLE2] = best4t[sb]
        # selectors for the chosen symbolic block
        prec = 5 if sym[S_DIFF] else 4
        flip = sym[S_FLIP]
        for half in range(2):
            s = 2 * flip + half
            off = S_BASE1 + 3 * half  # S_BASE2 for the second
            select(px[s], w, expand_p(sym[off], prec), expand_p(sym[off + 1], prec),
                   expand_p(sym[off + 2], prec), sym[S_TABLE1 + half], sel)
            for i in range(8):
                sym[S_SEL + SUB_IDX[s, i]] = sel[i]
        pack_sym(sym, out[n])




def encode_blocks(blocks, out, rec, w):
    """blocks uint8 (n, 16, 4) -> out uint8 (n, 8) with the kernel the preset
    record rec needs (etc1.SEARCH.record), w int64 (3,) channel weights; the
    working arrays are made here, one set per call (run_chunked calls from
    several threads at once)."""
    prm = rec[0]
    if prm.fast_path:
        fast_blocks(blocks, out, w, fast_scratch())
    else:
        search_blocks(blocks, out, rec, w, scratch())
