"""ETC2 kernels: the T, H and planar modes (bit packing, decoding, search),
the ETC2 RGB and punch-through decoders, and the passes that improve an ETC1
stream into an ETC2 one. ETC1's individual and differential modes are
etc1_kernels' (its search, packing and decoding are used as they are).
"""

import numpy as np

from texcook._jit import borrow, jit
from texcook._jit import jit_inner as _inner  # helpers only called from other kernels

from ._kernels import moments
from .etc1_kernels import (BIG, decode_sym, eval_all, fast_block, floor_code, pack_selectors, pack_sym, quant,
                           select, unpack_selectors, unpack_sym)
from .etc1_tables import EXPAND4, EXPAND5, QUANT5, S_BASE1, S_BASE2, S_DIFF, S_FLIP, S_SEL, S_TABLE1, \
    S_TABLE2, SUB_IDX, TABLES
from .etc2_tables import (DIST, E_A, E_B, E_C, E_DIST, E_MODE, E_OPAQUE, E_SEL, EXPAND6, EXPAND7, MODE_H,
                          MODE_PLANAR, MODE_T, PLANAR_BITS, PLANAR_PINV)

MODE_ETC1 = 0  # individual or differential: etc1_kernels' symbolic block


# ---------------------------------------------------------------- bit packing


@_inner
def _signed3(v):
    return v - 8 if v >= 4 else v


@_inner
def mode_of(blk, punch):
    """MODE_ETC1, MODE_T, MODE_H or MODE_PLANAR for 8 block bytes. A
    differential block whose red, green or blue base plus delta leaves 0..31
    is T, H or planar (tested in that order); the punch-through format reads
    every block as differential (bit 33 is its opaque flag)."""
    if not punch and (blk[3] >> 1) & 1 == 0:
        return MODE_ETC1
    for c in range(3):
        v = np.int64(blk[c])
        s = (v >> 3) + _signed3(v & 7)
        if s < 0 or s > 31:
            return MODE_T + c
    return MODE_ETC1


@jit
def mode_of_bytes(blk, punch):
    """mode_of, callable from Python."""
    return mode_of(blk, punch)


@_inner
def _h_order(e):
    """1 if H's first colour >= its second as 12-bit numbers (R high), else 0:
    the lowest bit of H's distance index, which is not stored."""
    a = (e[E_A] << 8) | (e[E_A + 1] << 4) | e[E_A + 2]
    b = (e[E_B] << 8) | (e[E_B + 1] << 4) | e[E_B + 2]
    return 1 if a >= b else 0


@jit
def unpack_e(blk, mode, e):
    """8 bytes of a T, H or planar block (mode from mode_of) -> e."""
    d0 = np.int64(blk[0])
    d1 = np.int64(blk[1])
    d2 = np.int64(blk[2])
    d3 = np.int64(blk[3])
    d4 = np.int64(blk[4])
    d5 = np.int64(blk[5])
    d6 = np.int64(blk[6])
    d7 = np.int64(blk[7])
    e[E_MODE] = mode
    e[E_OPAQUE] = (d3 >> 1) & 1
    if mode == MODE_PLANAR:
        e[E_OPAQUE] = 1  # planar blocks are opaque in the punch-through format too
        e[E_A] = (d0 >> 1) & 63
        e[E_A + 1] = ((d0 & 1) << 6) | ((d1 >> 1) & 63)
        e[E_A + 2] = ((d1 & 1) << 5) | (((d2 >> 3) & 3) << 3) | ((d2 & 3) << 1) | (d3 >> 7)
        e[E_B] = (((d3 >> 2) & 31) << 1) | (d3 & 1)
        e[E_B + 1] = d4 >> 1
        e[E_B + 2] = ((d4 & 1) << 5) | (d5 >> 3)
        e[E_C] = ((d5 & 7) << 3) | (d6 >> 5)
        e[E_C + 1] = ((d6 & 31) << 2) | (d7 >> 6)
        e[E_C + 2] = d7 & 63
        return
    if mode == MODE_T:
        e[E_A] = (((d0 >> 3) & 3) << 2) | (d0 & 3)
        e[E_A + 1] = d1 >> 4
        e[E_A + 2] = d1 & 15
        e[E_B] = d2 >> 4
        e[E_B + 1] = d2 & 15
        e[E_B + 2] = d3 >> 4
        e[E_DIST] = (((d3 >> 2) & 3) << 1) | (d3 & 1)
    else:
        e[E_A] = (d0 >> 3) & 15
        e[E_A + 1] = ((d0 & 7) << 1) | ((d1 >> 4) & 1)
        e[E_A + 2] = (d1 & 8) | ((d1 & 3) << 1) | (d2 >> 7)
        e[E_B] = (d2 >> 3) & 15
        e[E_B + 1] = ((d2 & 7) << 1) | (d3 >> 7)
        e[E_B + 2] = (d3 >> 3) & 15
        e[E_DIST] = (((d3 >> 2) & 1) << 2) | ((d3 & 1) << 1) | _h_order(e)
    unpack_selectors(blk, e, E_SEL)


@_inner
def _overflow_bits(x, y):
    """A 5-bit base field whose low two bits are x and a 3-bit delta whose low
    two bits are y, with the free high bits set so that base + delta leaves
    0..31: (bits 7-5 of the field's byte, the delta's sign bit)."""
    if x + y >= 4:
        return 7, 0  # 28 + x + y > 31
    return 0, 1  # x + y - 4 < 0


@jit
def pack_e(e, out):
    """e (T, H or planar) -> 8 bytes. H's distance index must agree with its
    colours' order (see _h_order)."""
    mode = e[E_MODE]
    op = e[E_OPAQUE] & 1
    if mode == MODE_PLANAR:
        ro, go, bo = e[E_A], e[E_A + 1], e[E_A + 2]
        rh, gh, bh = e[E_B], e[E_B + 1], e[E_B + 2]
        rv, gv, bv = e[E_C], e[E_C + 1], e[E_C + 2]
        # bit 63 and bit 55 copy the red and green deltas' sign bits so those sums stay in range
        out[0] = (((ro >> 1) & 1) << 7) | (ro << 1) | (go >> 6)
        out[1] = (((go >> 1) & 1) << 7) | ((go & 63) << 1) | (bo >> 5)
        hi, neg = _overflow_bits((bo >> 3) & 3, (bo >> 1) & 3)
        out[2] = (hi << 5) | (((bo >> 3) & 3) << 3) | (neg << 2) | ((bo >> 1) & 3)
        out[3] = ((bo & 1) << 7) | ((rh >> 1) << 2) | 2 | (rh & 1)
        out[4] = (gh << 1) | (bh >> 5)
        out[5] = ((bh & 31) << 3) | (rv >> 3)
        out[6] = ((rv & 7) << 5) | (gv >> 2)
        out[7] = ((gv & 3) << 6) | bv
        return
    dist = e[E_DIST]
    if mode == MODE_T:
        r1 = e[E_A]
        hi, neg = _overflow_bits(r1 >> 2, r1 & 3)
        out[0] = (hi << 5) | ((r1 >> 2) << 3) | (neg << 2) | (r1 & 3)
        out[1] = (e[E_A + 1] << 4) | e[E_A + 2]
        out[2] = (e[E_B] << 4) | e[E_B + 1]
        out[3] = (e[E_B + 2] << 4) | ((dist >> 1) << 2) | (op << 1) | (dist & 1)
    else:
        r1, g1, b1 = e[E_A], e[E_A + 1], e[E_A + 2]
        r2, g2, b2 = e[E_B], e[E_B + 1], e[E_B + 2]
        out[0] = (((g1 >> 3) & 1) << 7) | (r1 << 3) | (g1 >> 1)
        hi, neg = _overflow_bits(((g1 & 1) << 1) | (b1 >> 3), (b1 >> 1) & 3)
        out[1] = (hi << 5) | ((g1 & 1) << 4) | (b1 & 8) | (neg << 2) | ((b1 >> 1) & 3)
        out[2] = ((b1 & 1) << 7) | (r2 << 3) | (g2 >> 1)
        out[3] = ((g2 & 1) << 7) | (b2 << 3) | ((dist >> 2) << 2) | (op << 1) | ((dist >> 1) & 1)
    pack_selectors(e, E_SEL, out)


# ---------------------------------------------------------------- decoding


@_inner
def _planar_expand(v, c):
    return EXPAND7[v] if c == 1 else EXPAND6[v]


@_inner
def _paint(mode, a0, a1, a2, b0, b1, b2, d, pal):
    """The four paint colours of a T or H block from its expanded base
    colours and distance: T: a, b + d, b, b - d; H: a + d, a - d, b + d, b - d."""
    if mode == MODE_T:
        pal[0, 0] = a0
        pal[0, 1] = a1
        pal[0, 2] = a2
        pal[2, 0] = b0
        pal[2, 1] = b1
        pal[2, 2] = b2
        pal[1, 0] = min(255, b0 + d)
        pal[1, 1] = min(255, b1 + d)
        pal[1, 2] = min(255, b2 + d)
        pal[3, 0] = max(0, b0 - d)
        pal[3, 1] = max(0, b1 - d)
        pal[3, 2] = max(0, b2 - d)
    else:
        pal[0, 0] = min(255, a0 + d)
        pal[0, 1] = min(255, a1 + d)
        pal[0, 2] = min(255, a2 + d)
        pal[1, 0] = max(0, a0 - d)
        pal[1, 1] = max(0, a1 - d)
        pal[1, 2] = max(0, a2 - d)
        pal[2, 0] = min(255, b0 + d)
        pal[2, 1] = min(255, b1 + d)
        pal[2, 2] = min(255, b2 + d)
        pal[3, 0] = max(0, b0 - d)
        pal[3, 1] = max(0, b1 - d)
        pal[3, 2] = max(0, b2 - d)


@jit
def decode_e(e, texels, pal):
    """e (T, H or planar) -> texels (16, 4) uint8 RGBA, row-major; pal: int64
    (4, 3) scratch. With E_OPAQUE 0, T/H index 2 is transparent black."""
    if e[E_MODE] == MODE_PLANAR:
        for y in range(4):
            for x in range(4):
                for c in range(3):
                    o = _planar_expand(e[E_A + c], c)
                    h = _planar_expand(e[E_B + c], c)
                    v = _planar_expand(e[E_C + c], c)
                    texels[y * 4 + x, c] = min(255, max(0, (x * (h - o) + y * (v - o) + 4 * o + 2) >> 2))
                texels[y * 4 + x, 3] = 255
        return
    _paint(e[E_MODE], EXPAND4[e[E_A]], EXPAND4[e[E_A + 1]], EXPAND4[e[E_A + 2]], EXPAND4[e[E_B]],
           EXPAND4[e[E_B + 1]], EXPAND4[e[E_B + 2]], DIST[e[E_DIST]], pal)
    for i in range(16):
        s = e[E_SEL + i]
        if s == 2 and e[E_OPAQUE] == 0:
            for c in range(4):
                texels[i, c] = 0
        else:
            for c in range(3):
                texels[i, c] = pal[s, c]
            texels[i, 3] = 255


@_inner
def _decode_one(blk, texels, punch, sym, e, tmp, pal):
    mode = mode_of(blk, punch)
    if mode != MODE_ETC1:
        unpack_e(blk, mode, e)
        decode_e(e, texels, pal)
        return
    for k in range(8):
        tmp[k] = blk[k]
    if punch:
        tmp[3] |= 2  # no individual mode: the bases are always differential
    unpack_sym(tmp, sym)
    decode_sym(sym, texels)
    if punch and (blk[3] >> 1) & 1 == 0:
        # opaque bit 0: the modifier +-a becomes 0, and selector 2 transparent black
        for y in range(4):
            for x in range(4):
                i = y * 4 + x
                s = sym[S_SEL + i]
                second = (y >= 2) if sym[S_FLIP] else (x >= 2)
                off = S_BASE2 if second else S_BASE1
                if s == 2:
                    for c in range(4):
                        texels[i, c] = 0
                elif s == 0:
                    for c in range(3):
                        texels[i, c] = EXPAND5[sym[off + c] & 31]


@jit
def decode_blocks(data, out, punch, work):
    """data uint8 (n, 8) -> out uint8 (n, 16, 4); punch: the punch-through
    format. work: the scratch() of the encoder (its decoding slots)."""
    for n in range(data.shape[0]):
        _decode_one(data[n], out[n], punch, work.sym, work.e, work.tmp, work.pal)


# ---------------------------------------------------------------- search
#
# Errors are sum_c w_c (decoded_c - source_c)^2 over the texels that are not
# transparent, with integer channel weights w; every candidate is measured
# exactly as it decodes.


@_inner(inline="always")
def _werr(w, d0, d1, d2):
    return w[0] * d0 * d0 + w[1] * d1 * d1 + w[2] * d2 * d2


@_inner
def _planar_code(v, c):
    """The planar code of channel c whose expansion is nearest v."""
    top = (np.int64(1) << PLANAR_BITS[c]) - 1
    q = min(top, max(np.int64(0), np.int64(np.floor(v * top / 255.0 + 0.5))))
    best = q
    for k in (q - 1, q + 1):
        if 0 <= k <= top and abs(_planar_expand(k, c) - v) < abs(_planar_expand(best, c) - v):
            best = k
    return best


@_inner
def _planar_fit(px, c):
    """The least-squares O, H and V of channel c of px (16 texels, row-major),
    each rounded to its nearest code."""
    fo = 0.0
    fh = 0.0
    fv = 0.0
    for i in range(16):
        fo += PLANAR_PINV[0, i] * px[i, c]
        fh += PLANAR_PINV[1, i] * px[i, c]
        fv += PLANAR_PINV[2, i] * px[i, c]
    return _planar_code(fo, c), _planar_code(fh, c), _planar_code(fv, c)


@_inner
def _planar_channel_err(px, c, o, h, v, cap):
    err = np.int64(0)
    for y in range(4):
        for x in range(4):
            d = min(255, max(0, (x * (h - o) + y * (v - o) + 4 * o + 2) >> 2)) - px[y * 4 + x, c]
            err += d * d
            if err >= cap:
                return err
    return err


@_inner
def _planar(px, w, prm, e):
    """Best planar block near the least-squares fit of O, H and V; fills e,
    returns the weighted error. Channels are independent in this mode, so
    each is solved on its own; `prm.planar` 2 tries the codes within one step
    of each rounded value (27 per channel)."""
    r = 1 if prm.planar >= 2 else 0
    total = np.int64(0)
    for c in range(3):
        top = (np.int64(1) << PLANAR_BITS[c]) - 1
        qo, qh, qv = _planar_fit(px, c)
        best = BIG
        bo = qo
        bh = qh
        bv = qv
        for do in range(-r, r + 1):
            co = qo + do
            if co < 0 or co > top:
                continue
            for dh in range(-r, r + 1):
                ch = qh + dh
                if ch < 0 or ch > top:
                    continue
                for dv in range(-r, r + 1):
                    cv = qv + dv
                    if cv < 0 or cv > top:
                        continue
                    err = _planar_channel_err(px, c, _planar_expand(co, c), _planar_expand(ch, c),
                                              _planar_expand(cv, c), best)
                    if err < best:
                        best = err
                        bo = co
                        bh = ch
                        bv = cv
        e[E_A + c] = bo
        e[E_B + c] = bh
        e[E_C + c] = bv
        total += w[c] * best
    e[E_MODE] = MODE_PLANAR
    e[E_OPAQUE] = 1
    return total


@_inner
def _th_eval(px, w, trans, avail, mode, ca, cb, dist, pal, sel, cap):
    """Error of a T or H block with 4-bit colours ca, cb (int64 (3,)) and
    distance index dist, each texel on its best paint colour among those in
    the bit mask avail (transparent texels take index 2); stops at cap."""
    _paint(mode, EXPAND4[ca[0]], EXPAND4[ca[1]], EXPAND4[ca[2]], EXPAND4[cb[0]], EXPAND4[cb[1]],
           EXPAND4[cb[2]], DIST[dist], pal)
    err = np.int64(0)
    for i in range(16):
        if trans[i]:
            sel[i] = 2
            continue
        best = BIG
        bk = 0
        for k in range(4):
            if (avail >> k) & 1:
                e = _werr(w, pal[k, 0] - px[i, 0], pal[k, 1] - px[i, 1], pal[k, 2] - px[i, 2])
                if e < best:
                    best = e
                    bk = k
        sel[i] = bk
        err += best
        if err >= cap:
            return err
    return err


@_inner
def _h_first(ca, cb):
    """1 if 4-bit colour ca >= cb in H's order (see _h_order)."""
    a = (ca[0] << 8) | (ca[1] << 4) | ca[2]
    b = (cb[0] << 8) | (cb[1] << 4) | cb[2]
    return 1 if a >= b else 0


@_inner
def _th_try(px, w, trans, avail, mode, ca, cb, best_err, eb, work):
    """Every distance for colours (ca, cb) in `mode`; keeps the best in eb
    (its error in best_err) and returns that error. In H a distance whose
    lowest bit disagrees with the colours' order cannot be stored: skipped
    (the caller tries the colours the other way round too)."""
    pal, sel = work.pal, work.sel
    order = _h_first(ca, cb)
    for dist in range(8):
        if mode == MODE_H and (dist & 1) != order:
            continue
        err = _th_eval(px, w, trans, avail, mode, ca, cb, dist, pal, sel, best_err)
        if err < best_err:
            best_err = err
            eb[E_MODE] = mode
            eb[E_DIST] = dist
            for c in range(3):
                eb[E_A + c] = ca[c]
                eb[E_B + c] = cb[c]
            for i in range(16):
                eb[E_SEL + i] = sel[i]
    return best_err


@_inner
def _axis_order(px, trans, order, proj):
    """Opaque texels' indices in order[:n] sorted by their projection on the
    principal axis (power iteration on the covariance); returns n."""
    n, m0, m1, m2, c00, c01, c02, c11, c12, c22 = moments(px, trans, 0)
    if n == 0:
        return 0
    a0 = 1.0
    a1 = 1.0
    a2 = 1.0
    for _ in range(8):
        b0 = c00 * a0 + c01 * a1 + c02 * a2
        b1 = c01 * a0 + c11 * a1 + c12 * a2
        b2 = c02 * a0 + c12 * a1 + c22 * a2
        s = max(abs(b0), max(abs(b1), abs(b2)))
        if s == 0.0:
            break
        a0 = b0 / s
        a1 = b1 / s
        a2 = b2 / s
    k = 0
    for i in range(16):
        if not trans[i]:
            p = (px[i, 0] - m0) * a0 + (px[i, 1] - m1) * a1 + (px[i, 2] - m2) * a2
            # insertion sort, stable: equal projections keep texel order
            j = k
            while j > 0 and proj[j - 1] > p:
                proj[j] = proj[j - 1]
                order[j] = order[j - 1]
                j -= 1
            proj[j] = p
            order[j] = i
            k += 1
    return n


@_inner
def _group_means(px, order, lo, hi, mean):
    for c in range(3):
        s = 0.0
        for j in range(lo, hi):
            s += px[order[j], c]
        mean[c] = s / (hi - lo)


@_inner
def _refit(px, trans, mode, eb, ws):
    """The continuous base colours that fit eb's selectors best (each texel's
    value minus its paint colour's offset, averaged per base): ws[0:3] and
    ws[3:6]; a base no texel uses keeps its expanded colour."""
    d = DIST[eb[E_DIST]]
    for half in range(2):
        for c in range(3):
            s = 0.0
            cnt = 0
            for i in range(16):
                if trans[i]:
                    continue
                k = eb[E_SEL + i]
                if mode == MODE_T:
                    if (k == 0) != (half == 0):
                        continue
                    off = 0 if k == 0 or k == 2 else (d if k == 1 else -d)
                else:
                    if (k >> 1) != half:
                        continue
                    off = d if (k & 1) == 0 else -d
                s += px[i, c] - off
                cnt += 1
            slot = E_A if half == 0 else E_B
            ws[3 * half + c] = s / cnt if cnt else float(EXPAND4[eb[slot + c]])


@_inner
def _codes_around(v, box, codes):
    """4-bit codes to try for a continuous value: the nearest, and with box
    the floor and ceiling codes too; returns the count."""
    q = quant(v, np.int64(4))
    codes[0] = q
    n = 1
    if box:
        f = floor_code(v, np.int64(4))
        for k in (f, min(15, f + 1)):
            if k != codes[0] and (n < 2 or k != codes[1]):
                codes[n] = k
                n += 1
    return n


@_inner
def _any_transparent(trans):
    for i in range(16):
        if trans[i]:
            return True
    return False


@_inner
def _th_search(px, w, trans, avail, prm, work):
    """The best T or H block for the texels (transparent ones excluded):
    split the opaque texels in two along the principal axis (at the mean, or
    with prm.th 2 at every position), each mode and each assignment of the
    halves' quantised means to the base colours with every distance; then
    prm.th_refine rounds of re-fitting each mode's best bases to its selectors
    (with prm.th_box, every floor/ceiling code combination of the fit).
    Fills work.e and returns its error (BIG if there are fewer than 2 opaque
    texels)."""
    order, proj, mean_a, mean_b = work.order, work.proj, work.fa, work.fb
    ca, cb, eb, ws, codes = work.ca, work.cb, work.eb, work.ws, work.codes
    n = _axis_order(px, trans, order, proj)
    if n < 2:
        return BIG
    errs = work.errs
    errs[0] = BIG
    errs[1] = BIG
    # split at the mean projection: the first k texels have projections below 0
    kmean = 1
    while kmean < n - 1 and proj[kmean] < 0.0:
        kmean += 1
    k0 = 1 if prm.th >= 2 else kmean
    k1 = n - 1 if prm.th >= 2 else kmean
    for k in range(k0, k1 + 1):
        _group_means(px, order, 0, k, mean_a)
        _group_means(px, order, k, n, mean_b)
        for mi in range(2):
            mode = MODE_T + mi
            for swap in range(2):
                for c in range(3):
                    a = quant(mean_a[c], np.int64(4))
                    b = quant(mean_b[c], np.int64(4))
                    ca[c] = b if swap else a
                    cb[c] = a if swap else b
                errs[mi] = _th_try(px, w, trans, avail, mode, ca, cb, errs[mi], eb[mi], work)
    na = work.na
    nb = work.nb
    # H's colours the other way round reach the other distances (not with
    # transparent texels: index 2 would move)
    both = not _any_transparent(trans)
    for mi in range(2):
        mode = MODE_T + mi
        if errs[mi] >= BIG:
            continue
        for _ in range(prm.th_refine):
            _refit(px, trans, mode, eb[mi], ws)
            before = errs[mi]
            for c in range(3):
                na[c] = _codes_around(ws[c], prm.th_box, codes[c])
                nb[c] = _codes_around(ws[3 + c], prm.th_box, codes[3 + c])
            for i0 in range(na[0]):
                for i1 in range(na[1]):
                    for i2 in range(na[2]):
                        for j0 in range(nb[0]):
                            for j1 in range(nb[1]):
                                for j2 in range(nb[2]):
                                    ca[0] = codes[0, i0]
                                    ca[1] = codes[1, i1]
                                    ca[2] = codes[2, i2]
                                    cb[0] = codes[3, j0]
                                    cb[1] = codes[4, j1]
                                    cb[2] = codes[5, j2]
                                    errs[mi] = _th_try(px, w, trans, avail, mode, ca, cb, errs[mi],
                                                       eb[mi], work)
                                    if mode == MODE_H and both:
                                        errs[mi] = _th_try(px, w, trans, avail, mode, cb, ca, errs[mi],
                                                           eb[mi], work)
            if errs[mi] >= before:
                break
    mi = 0 if errs[0] <= errs[1] else 1
    for j in range(eb.shape[1]):
        work.e[j] = eb[mi, j]
    return errs[mi]


# ---------------------------------------------------------------- punch-through differential


@_inner
def _half_punch(px, w, trans, s, lo, hi, box, code):
    """Best 5-bit base (within lo..hi per channel) and table for half s of a
    block whose opaque bit is 0: each opaque texel takes the base, base + b or
    base - b. Fills code; returns (error, table). A half without opaque
    texels costs nothing and takes the code nearest the middle of its box."""
    cnt = 0
    m0 = 0.0
    m1 = 0.0
    m2 = 0.0
    for j in range(8):
        i = SUB_IDX[s, j]
        if not trans[i]:
            m0 += px[i, 0]
            m1 += px[i, 1]
            m2 += px[i, 2]
            cnt += 1
    if cnt == 0:
        for c in range(3):
            code[c] = (lo[c] + hi[c]) // 2
        return np.int64(0), np.int64(0)
    best = BIG
    bt = np.int64(0)
    b0 = b1 = b2 = np.int64(0)
    m = (m0 / cnt, m1 / cnt, m2 / cnt)
    f = (floor_code(m[0], np.int64(5)), floor_code(m[1], np.int64(5)), floor_code(m[2], np.int64(5)))
    q = (quant(m[0], np.int64(5)), quant(m[1], np.int64(5)), quant(m[2], np.int64(5)))
    ncand = 9 if box else 1
    for cand in range(ncand):
        if cand == 0:
            c0, c1, c2 = q
        else:
            k = cand - 1
            c0 = f[0] + (k & 1)
            c1 = f[1] + ((k >> 1) & 1)
            c2 = f[2] + ((k >> 2) & 1)
        c0 = min(hi[0], max(lo[0], c0))
        c1 = min(hi[1], max(lo[1], c1))
        c2 = min(hi[2], max(lo[2], c2))
        v0 = EXPAND5[c0]
        v1 = EXPAND5[c1]
        v2 = EXPAND5[c2]
        for t in range(8):
            bb = TABLES[t, 1]
            err = np.int64(0)
            for j in range(8):
                i = SUB_IDX[s, j]
                if trans[i]:
                    continue
                p0 = px[i, 0]
                p1 = px[i, 1]
                p2 = px[i, 2]
                e = _werr(w, v0 - p0, v1 - p1, v2 - p2)
                e = min(e, _werr(w, min(255, v0 + bb) - p0, min(255, v1 + bb) - p1, min(255, v2 + bb) - p2))
                e = min(e, _werr(w, max(0, v0 - bb) - p0, max(0, v1 - bb) - p1, max(0, v2 - bb) - p2))
                err += e
                if err >= best:
                    break
            if err < best:
                best = err
                bt = t
                b0 = c0
                b1 = c1
                b2 = c2
    code[0] = b0
    code[1] = b1
    code[2] = b2
    return best, bt


@_inner
def _diff_punch(px, w, trans, prm, work):
    """The best differential block with opaque bit 0 (transparent texels on
    selector 2) over both flips, one half searched freely and the other
    within the deltas of it, each way round. Fills work.sym; returns the
    error."""
    sym, lo, hi, ca, cb = work.sym, work.lo, work.hi, work.ca, work.cb
    best = BIG
    for flip in range(2):
        for side in range(2):
            s_free = 2 * flip + side
            s_con = 2 * flip + 1 - side
            for c in range(3):
                lo[c] = 0
                hi[c] = 31
            ef, tf = _half_punch(px, w, trans, s_free, lo, hi, prm.th_box, ca)
            for c in range(3):
                # the second base is the first plus -4..3
                lo[c] = max(0, ca[c] - 4) if side == 0 else max(0, ca[c] - 3)
                hi[c] = min(31, ca[c] + 3) if side == 0 else min(31, ca[c] + 4)
            ec, tc = _half_punch(px, w, trans, s_con, lo, hi, prm.th_box, cb)
            if ef + ec < best:
                best = ef + ec
                sym[S_DIFF] = 1
                sym[S_FLIP] = flip
                for c in range(3):
                    sym[S_BASE1 + c] = ca[c] if side == 0 else cb[c]
                    sym[S_BASE2 + c] = cb[c] if side == 0 else ca[c]
                sym[S_TABLE1] = tf if side == 0 else tc
                sym[S_TABLE2] = tc if side == 0 else tf
    # selectors: transparent 2; else the best of base (0), +b (1), -b (3)
    for half in range(2):
        s = 2 * sym[S_FLIP] + half
        off = S_BASE1 + 3 * half
        v0 = EXPAND5[sym[off]]
        v1 = EXPAND5[sym[off + 1]]
        v2 = EXPAND5[sym[off + 2]]
        bb = TABLES[sym[S_TABLE1 + half], 1]
        for j in range(8):
            i = SUB_IDX[s, j]
            if trans[i]:
                sym[S_SEL + i] = 2
                continue
            p0 = px[i, 0]
            p1 = px[i, 1]
            p2 = px[i, 2]
            k = 0
            e = _werr(w, v0 - p0, v1 - p1, v2 - p2)
            e1 = _werr(w, min(255, v0 + bb) - p0, min(255, v1 + bb) - p1, min(255, v2 + bb) - p2)
            if e1 < e:
                e = e1
                k = 1
            e3 = _werr(w, max(0, v0 - bb) - p0, max(0, v1 - bb) - p1, max(0, v2 - bb) - p2)
            if e3 < e:
                k = 3
            sym[S_SEL + i] = k
    return best


@_inner
def _to_differential(px, w, work):
    """work.sym (an ETC1 block) in differential mode: an individual block's
    4-bit bases become the nearest 5-bit codes, one of them moved into the
    other's delta range (both ways tried), tables and selectors chosen again.
    The punch-through format has no individual mode."""
    sym, sub, dabs, sel, ca, cb = work.sym, work.sub, work.dabs, work.sel8, work.ca, work.cb
    if sym[S_DIFF]:
        return
    flip = sym[S_FLIP]
    best = BIG
    t1 = np.int64(0)
    t2 = np.int64(0)
    ta = np.int64(0)
    tb = np.int64(0)
    for side in range(2):
        for c in range(3):
            qa = QUANT5[EXPAND4[sym[S_BASE1 + c]]]
            qb = QUANT5[EXPAND4[sym[S_BASE2 + c]]]
            if side == 0:
                qb = min(qa + 3, max(qa - 4, qb))
            else:
                qa = min(qb + 4, max(qb - 3, qa))
            ca[c] = qa
            cb[c] = qb
        err = np.int64(0)
        for half in range(2):
            s = 2 * flip + half
            cc = ca if half == 0 else cb
            for j in range(8):
                for c in range(3):
                    sub[j, c] = px[SUB_IDX[s, j], c]
            e, t = eval_all(sub, w, EXPAND5[cc[0]], EXPAND5[cc[1]], EXPAND5[cc[2]], dabs)
            err += e
            if half == 0:
                ta = t
            else:
                tb = t
        if err < best:
            best = err
            for c in range(3):
                work.lo[c] = ca[c]
                work.hi[c] = cb[c]
            t1 = ta
            t2 = tb
    sym[S_DIFF] = 1
    for c in range(3):
        sym[S_BASE1 + c] = work.lo[c]
        sym[S_BASE2 + c] = work.hi[c]
    sym[S_TABLE1] = t1
    sym[S_TABLE2] = t2
    for half in range(2):
        s = 2 * flip + half
        off = S_BASE1 + 3 * half
        for j in range(8):
            for c in range(3):
                sub[j, c] = px[SUB_IDX[s, j], c]
        select(sub, w, EXPAND5[sym[off]], EXPAND5[sym[off + 1]], EXPAND5[sym[off + 2]], sym[S_TABLE1 + half], sel)
        for j in range(8):
            sym[S_SEL + SUB_IDX[s, j]] = sel[j]


# ---------------------------------------------------------------- the pass over a run of blocks


@_inner
def _block_err(blk, px, w, trans, punch, work):
    """Error of the 8 block bytes blk as decoded, over the opaque texels."""
    tex = work.texels
    _decode_one(blk, tex, punch, work.sym, work.e, work.tmp, work.pal)
    err = np.int64(0)
    for i in range(16):
        if not trans[i]:
            err += _werr(w, np.int64(tex[i, 0]) - px[i, 0], np.int64(tex[i, 1]) - px[i, 1],
                         np.int64(tex[i, 2]) - px[i, 2])
    return err


@jit
def improve_blocks(blocks, out, rec, w, thr, punch, work):
    """blocks uint8 (n, 16, 4), out uint8 (n, 8) holding their ETC1 encoding
    -> out the ETC2 (punch=False) or ETC2 punch-through (punch=True) blocks.
    rec: etc2.SEARCH.record(preset), w: int64 (3,) weights, thr: alpha below
    it is transparent (punch only), work: this thread's scratch().

    RGB: the ETC1 block stays unless a planar, T or H block has a strictly
    lower error. Punch-through: blocks with transparent texels are searched
    in the modes that can hold them (differential with opaque bit 0, T, H);
    opaque blocks start from the ETC1 block in differential mode."""
    prm = rec[0]
    px, trans, sym, e = work.px, work.trans, work.sym, work.e
    for n in range(blocks.shape[0]):
        blk = blocks[n]
        ntrans = 0
        for i in range(16):
            for c in range(3):
                px[i, c] = blk[i, c]
            trans[i] = 1 if punch and blk[i, 3] < thr else 0
            ntrans += trans[i]
        ob = out[n]
        if ntrans == 16:
            # differential, base 0, opaque bit 0, every selector 2
            for k in range(8):
                ob[k] = 0
            ob[4] = 255
            ob[5] = 255
            continue
        if ntrans:
            best = _diff_punch(px, w, trans, prm, work)
            pack_sym(sym, ob)
            ob[3] &= 253  # opaque bit 0
            avail = 11  # T/H index 2 is transparent
        else:
            if punch:
                unpack_sym(ob, sym)
                if sym[S_DIFF] == 0:
                    _to_differential(px, w, work)
                    pack_sym(sym, ob)
            best = _block_err(ob, px, w, trans, punch, work)
            avail = 15
            if prm.planar and best > 0:
                pe = _planar(px, w, prm, e)
                if pe < best:
                    best = pe
                    pack_e(e, ob)
        if prm.th and best > 0:
            te = _th_search(px, w, trans, avail, prm, work)
            if te < best:
                e[E_OPAQUE] = 0 if ntrans else 1
                pack_e(e, ob)


@_inner
def _planar_rounded(blk, w, e, limit):
    """The rounded planar fit of blk (16, 4): fills e and returns its weighted
    error, or stops (returning a value >= limit) as soon as the channels
    measured so far reach limit: the block is wanted only if it beats that."""
    total = np.int64(0)
    for c in range(3):
        qo, qh, qv = _planar_fit(blk, c)
        e[E_A + c] = qo
        e[E_B + c] = qh
        e[E_C + c] = qv
        if w[c] == 0:
            continue
        cap = (limit - total + w[c] - 1) // w[c]  # the channel error from which the block loses
        total += w[c] * _planar_channel_err(blk, c, _planar_expand(qo, c), _planar_expand(qh, c),
                                            _planar_expand(qv, c), cap)
        if total >= limit:
            return total
    e[E_MODE] = MODE_PLANAR
    e[E_OPAQUE] = 1
    return total


@jit
def fast_blocks(blocks, out, rec, w, fscr, work):
    """The `fastest` preset of ETC2 RGB in one pass: each block's ETC1
    encoding (etc1_kernels.fast_block, which gives its exact error), replaced
    by the rounded planar fit where that is strictly better, as
    improve_blocks would (without decoding the ETC1 block again, and
    measuring the planar block only until it has lost). rec:
    etc2.SEARCH.record("fastest"), fscr: etc1_kernels.fast_scratch(), work:
    this thread's scratch()."""
    prm = rec[0]
    ws = borrow(fscr)  # views without reference counting (fscr outlives them)
    wt = (w[0], w[1], w[2])
    e = work.e
    for n in range(blocks.shape[0]):
        blk = blocks[n]
        ob = out[n]
        best = fast_block(blk, ob, wt, ws)
        if prm.planar and best > 0:
            if _planar_rounded(blk, wt, e, best) < best:
                pack_e(e, ob)
