"""EAC kernels: decoding and the block search for one channel of 4x4 texels
(R11 and RG11 EAC, and the alpha block of RGBA ETC2).

A block is (base, multiplier, table) and one 3-bit index per texel; with the
three fixed, picking each texel's index on its own is optimal, so the search
is over the three numbers. Errors are measured in "error units" so that one
integer code serves both kinds a block can be:

- ALPHA8: the decoded 8-bit value against the 8-bit input.
- UNSIGNED11: first the error of the 8-bit decode (v >> 3, what
  texture2ddecoder returns, and what texcook's metrics read), then, as a tie
  break worth less than one 8-bit step over the whole block, the distance of
  twice the 11-bit value from 16 x + 7, the middle of the 11-bit values
  [8x, 8x + 7] that read back as x: a GPU keeps all 11 bits, and that middle
  is within 0.44 of x / 255 there. Palettes hold twice the 11-bit value.
"""

import numpy as np

from texcook._jit import jit
from texcook._jit import jit_inner as _inner

from ._kernels import blank
from .bc5_angular import best_pair, cost_table, palette_cost, unit_normal
from .eac_tables import ALPHA8, MOD_MAX, MOD_MIN, MODIFIERS, SIGNED11, UNSIGNED11

BIG = np.int64(1 << 60)


# ---------------------------------------------------------------- decoding


@_inner
def values(base, mult, table, kind, vals):
    """vals (8,) int64: the values block (base, mult, table) decodes to, as
    the format stores them (8-bit for ALPHA8, 11-bit otherwise)."""
    for j in range(8):
        mod = MODIFIERS[table, j]
        if kind == ALPHA8:
            v = base + mod * mult
            vals[j] = min(255, max(0, v))
        elif kind == UNSIGNED11:
            m = mult * 8 if mult > 0 else 1  # multiplier 0 stands for 1/8
            v = base * 8 + 4 + mod * m
            vals[j] = min(2047, max(0, v))
        else:
            b = base - 256 if base > 127 else base
            if b == -128:
                b = -127  # not a legal codeword; the spec reads it as -127
            m = mult * 8 if mult > 0 else 1
            v = b * 8 + mod * m
            vals[j] = min(1023, max(-1023, v))


@_inner
def to_unorm8(v, kind):
    """An EAC value as texcook's 8-bit decode returns it: 11-bit values lose
    their low 3 bits (signed ones offset by 1023 first), as texture2ddecoder
    does."""
    if kind == UNSIGNED11:
        return v >> 3
    if kind == SIGNED11:
        return (v + 1023) >> 3
    return v


@_inner
def decode_channel(d, o, out, ch, kind, vals):
    """The EAC block d[o:o+8] into channel ch of out (16, 4)."""
    values(np.int64(d[o]), np.int64(d[o + 1]) >> 4, np.int64(d[o + 1]) & 15, kind, vals)
    bits = np.int64(0)
    for k in range(2, 8):
        bits = (bits << 8) | np.int64(d[o + k])
    for i in range(16):
        k = 4 * (i % 4) + i // 4  # indices run down the columns
        out[i, ch] = to_unorm8(vals[(bits >> (45 - 3 * k)) & 7], kind)


@jit
def decode_run(data, out, nch, kind):
    """Blocks of nch EAC channels (8 bytes each) into channels 0 .. nch-1 of
    out; the others read 0, alpha 255."""
    vals = np.empty(8, np.int64)
    for b in range(data.shape[0]):
        blank(out[b])
        for c in range(nch):
            decode_channel(data[b], 8 * c, out[b], c, kind, vals)


@jit
def decode_alpha_run(data, out):
    """The alpha blocks (bytes 0-7) of RGBA ETC2 into channel 3 of out."""
    vals = np.empty(8, np.int64)
    for b in range(data.shape[0]):
        decode_channel(data[b], 0, out[b], 3, ALPHA8, vals)


# ---------------------------------------------------------------- packing


@_inner
def pack(base, mult, table, idx, out, o):
    """(base, mult, table) and the texel indices idx (16, row-major) into out[o:o+8]."""
    out[o] = base
    out[o + 1] = (mult << 4) | table
    bits = np.int64(0)
    for i in range(16):
        k = 4 * (i % 4) + i // 4
        bits |= idx[i] << (45 - 3 * k)
    for k in range(6):
        out[o + 2 + k] = (bits >> (40 - 8 * k)) & 255


# ---------------------------------------------------------------- the search


@_inner
def target(x, kind):
    """An 8-bit input value in error units."""
    if kind == ALPHA8:
        return x
    return 16 * x + 7


@_inner
def error_values(base, mult, table, kind, pal):
    """pal (8,): the block's values in error units."""
    values(base, mult, table, kind, pal)
    if kind != ALPHA8:
        for j in range(8):
            pal[j] *= 2


# weight of the 8-bit error against the tie break (16 texels * 15^2 < 4096)
STEP8 = np.int64(4096)


@_inner(inline="always")
def cost(t, p, kind):
    """Error of palette value p (error units) for target t (see the module's doc)."""
    d = t - p
    if kind == ALPHA8:
        return d * d
    d8 = (p >> 4) - (t >> 4)  # t = 16 x + 7: t >> 4 is x
    return STEP8 * d8 * d8 + d * d


@_inner(inline="always")
def outside(t, lo, hi, kind):
    """A lower bound of cost(t, p) for every p in [lo, hi]."""
    if kind != ALPHA8:
        t = t >> 4
        lo = lo >> 4
        hi = hi >> 4
    d = lo - t if t < lo else (t - hi if t > hi else 0)
    return d * d * (1 if kind == ALPHA8 else STEP8)


@_inner
def _eval(t, base, mult, table, kind, pal, idx, limit):
    """Error of (base, mult, table) with each texel's best index (into idx);
    stops early (returning a value >= limit) once it cannot win."""
    error_values(base, mult, table, kind, pal)
    err = np.int64(0)
    for i in range(16):
        best = BIG
        bi = 0
        for j in range(8):
            e = cost(t[i], pal[j], kind)
            if e < best:
                best = e
                bi = j
        idx[i] = bi
        err += best
        if err >= limit:
            return err
    return err


@_inner
def _try(t, base, mult, table, kind, pal, tidx, st, bidx):
    """Measure one block; st = [error, base, mult, table] keeps the best, bidx its indices."""
    e = _eval(t, base, mult, table, kind, pal, tidx, st[0])
    if e < st[0]:
        st[0] = e
        st[1] = base
        st[2] = mult
        st[3] = table
        for i in range(16):
            bidx[i] = tidx[i]


@_inner
def mult_range(kind):
    """Smallest multiplier the encoder writes: RGBA ETC2 forbids 0 (R11 reads it as 1/8)."""
    return 1 if kind == ALPHA8 else 0


@_inner
def scales(mult, kind):
    """(error units per base step, per modifier step, offset) of a multiplier."""
    if kind == ALPHA8:
        return 1, mult, 0
    return 16, (16 * mult if mult > 0 else 2), 8


@_inner
def candidates(lo, hi, kind, mult_radius, base_radius, cands):
    """Blocks around the range fit of [lo, hi] (error units) for every table:
    the multiplier that spans the range with the table's modifiers and the base
    that centres them, each +- its radius. Writes (base, mult, table) rows into
    cands; returns how many."""
    n = 0
    mlo = mult_range(kind)
    for table in range(16):
        span = MOD_MAX[table] - MOD_MIN[table]
        unit = 1.0 if kind == ALPHA8 else 16.0
        mc = min(15, max(mlo, np.int64(np.floor((hi - lo) / (unit * span) + 0.5))))
        for mult in range(max(mlo, mc - mult_radius), min(15, mc + mult_radius) + 1):
            s, step, off = scales(mult, kind)
            centre = ((lo + hi) / 2.0 - off - step * (MOD_MIN[table] + MOD_MAX[table]) / 2.0) / s
            bc = np.int64(np.floor(centre + 0.5))
            for base in range(max(0, bc - base_radius), min(255, bc + base_radius) + 1):
                cands[n, 0] = base
                cands[n, 1] = mult
                cands[n, 2] = table
                n += 1
    return n


@_inner
def _full_scan(t, kind, pal, tidx, st, bidx):
    """Every (base, mult, table), skipping blocks whose value range leaves the
    texels outside it at least the best error away."""
    for table in range(16):
        for mult in range(mult_range(kind), 16):
            for base in range(256):
                error_values(base, mult, table, kind, pal)
                lo = pal[0]
                hi = pal[0]
                for j in range(1, 8):
                    lo = min(lo, pal[j])
                    hi = max(hi, pal[j])
                bound = np.int64(0)
                for i in range(16):
                    bound += outside(t[i], lo, hi, kind)
                if bound < st[0]:
                    _try(t, base, mult, table, kind, pal, tidx, st, bidx)


@_inner
def _refine(t, kind, pal, tidx, st, bidx):
    """Least-squares base and multiplier for the best block's table and indices,
    then the blocks around the rounded fit; False when nothing improved."""
    table = st[3]
    sx = 0.0
    sxx = 0.0
    sy = 0.0
    sxy = 0.0
    for i in range(16):
        m = np.float64(MODIFIERS[table, bidx[i]])
        sx += m
        sxx += m * m
        sy += t[i]
        sxy += m * t[i]
    det = 16.0 * sxx - sx * sx
    s, step, off = scales(np.int64(1), kind)  # step: error units per modifier step at multiplier 1
    if abs(det) < 1e-9:
        mult_f = np.float64(st[2])
        a = (sy - sx * (st[2] * step if st[2] > 0 else 2.0)) / 16.0
    else:
        a = (sy * sxx - sx * sxy) / det  # intercept: off + s * base
        mult_f = (16.0 * sxy - sx * sy) / det / step
    base_f = (a - off) / s
    before = st[0]
    bc = np.int64(np.floor(base_f + 0.5))
    mc = np.int64(np.floor(mult_f + 0.5))
    for mult in range(max(mult_range(kind), mc - 1), min(15, mc + 1) + 1):
        for base in range(max(0, bc - 1), min(255, bc + 1) + 1):
            _try(t, base, mult, table, kind, pal, tidx, st, bidx)
    return st[0] < before


@_inner
def encode_channel(blk, ch, kind, prm, out, o, scr):
    """Channel ch of blk (16, 4) uint8 into the EAC block out[o:o+8]; prm: an
    eac.SEARCH record."""
    t, pal, tidx, bidx, st, cands = scr
    lo = BIG
    hi = -BIG
    for i in range(16):
        x = target(np.int64(blk[i, ch]), kind)
        t[i] = x
        lo = min(lo, x)
        hi = max(hi, x)
    st[0] = BIG
    if lo == hi:
        # one value: table 13 has a 0 modifier, so the base alone holds it
        # (R11 at multiplier 0 lands on 8x + 4, an 8-bit decode of x)
        x = np.int64(blk[0, ch])
        _try(t, x, mult_range(kind), 13, kind, pal, tidx, st, bidx)
    else:
        n = candidates(lo, hi, kind, prm.mult_radius, prm.base_radius, cands)
        for c in range(n):
            _try(t, cands[c, 0], cands[c, 1], cands[c, 2], kind, pal, tidx, st, bidx)
        if prm.full_scan != 0:
            _full_scan(t, kind, pal, tidx, st, bidx)
        for _ in range(prm.refine):
            if not _refine(t, kind, pal, tidx, st, bidx):
                break
    pack(st[1], st[2], st[3], bidx, out, o)


@jit
def scratch():
    """Working arrays of one thread's search."""
    return (np.zeros(16, np.int64), np.zeros(8, np.int64), np.zeros(16, np.int64), np.zeros(16, np.int64),
            np.zeros(4, np.int64), np.zeros((16 * 31 * 31, 3), np.int64))


@jit
def encode_run(blocks, out, rec, kind, ch0, nch, byte0):
    """Channels ch0 .. ch0+nch-1 of each block into out[b, byte0+8c : byte0+8c+8]
    (R11: channel 0; RG11: 0 and 1; RGBA ETC2's alpha: channel 3 at byte 0);
    rec: eac.SEARCH.record(preset)."""
    prm = rec[0]
    scr = scratch()
    for b in range(blocks.shape[0]):
        for c in range(nch):
            encode_channel(blocks[b], ch0 + c, kind, prm, out[b], byte0 + 8 * c, scr)


# ---------------------------------------------------------------- normal maps by angle


@_inner
def _unorm8_values(base, mult, table, kind, vals):
    values(base, mult, table, kind, vals)
    for j in range(8):
        vals[j] = to_unorm8(vals[j], kind)


@_inner
def _angle_total(cost, base, mult, table, kind, vals, limit):
    """Sum over texels of the best cost[t, v] among the block's 8-bit values."""
    _unorm8_values(base, mult, table, kind, vals)
    return palette_cost(cost, vals, limit)


@_inner
def _angle_channel(cost, blk, ch, kind, prm, cur, vals, cands):
    """The block of channel ch with the lowest total of cost (its candidates
    and the neighbours of the current cur = [base, mult, table]); cur keeps
    it. Returns its cost."""
    lo = BIG
    hi = -BIG
    for i in range(16):
        x = target(np.int64(blk[i, ch]), kind)
        lo = min(lo, x)
        hi = max(hi, x)
    best = _angle_total(cost, cur[0], cur[1], cur[2], kind, vals, 1e30)
    n = candidates(lo, hi, kind, max(1, prm.mult_radius), max(1, prm.base_radius), cands)
    for c in range(n):
        e = _angle_total(cost, cands[c, 0], cands[c, 1], cands[c, 2], kind, vals, best)
        if e < best:
            best = e
            cur[0] = cands[c, 0]
            cur[1] = cands[c, 1]
            cur[2] = cands[c, 2]
    b0 = cur[0]
    m0 = cur[1]
    for mult in range(max(mult_range(kind), m0 - 1), min(15, m0 + 1) + 1):
        for base in range(max(0, b0 - 2), min(255, b0 + 2) + 1):
            e = _angle_total(cost, base, mult, cur[2], kind, vals, best)
            if e < best:
                best = e
                cur[0] = base
                cur[1] = mult
    return best


@jit
def encode_rg_angular_run(blocks, out, rec, kind, rounds):
    """RG11 blocks of normal maps searched by the angle of the rebuilt normal:
    each starts from the X and Y searches of encode_channel, then X and Y in
    turn take the block that lowers the summed angle cost given the other's
    values (as bc5_angular does for BC5), and each texel's two indices are
    picked jointly."""
    prm = rec[0]
    scr = scratch()
    cands = scr[5]
    src = np.empty((16, 3))
    cost = np.empty((16, 256))
    vx = np.empty(8, np.int64)
    vy = np.empty(8, np.int64)
    cx = np.empty(3, np.int64)
    cy = np.empty(3, np.int64)
    full = np.array([0, 255], np.int64)
    idx_x = np.empty(16, np.int64)
    idx_y = np.empty(16, np.int64)
    for b in range(blocks.shape[0]):
        blk = blocks[b]
        o = out[b]
        encode_channel(blk, 0, kind, prm, o, 0, scr)
        encode_channel(blk, 1, kind, prm, o, 8, scr)
        for t in range(16):
            unit_normal(np.float64(blk[t, 0]), np.float64(blk[t, 1]), src[t])
        cx[0] = o[0]
        cx[1] = np.int64(o[1]) >> 4
        cx[2] = np.int64(o[1]) & 15
        cy[0] = o[8]
        cy[1] = np.int64(o[9]) >> 4
        cy[2] = np.int64(o[9]) & 15
        best = 1e30
        for _ in range(rounds):
            _unorm8_values(cy[0], cy[1], cy[2], kind, vy)
            cost_table(src, vy, 0, cost, full, 0)
            _angle_channel(cost, blk, 0, kind, prm, cx, vx, cands)
            _unorm8_values(cx[0], cx[1], cx[2], kind, vx)
            cost_table(src, vx, 1, cost, full, 0)
            c = _angle_channel(cost, blk, 1, kind, prm, cy, vy, cands)
            if c >= best:
                break
            best = c
        _unorm8_values(cx[0], cx[1], cx[2], kind, vx)
        _unorm8_values(cy[0], cy[1], cy[2], kind, vy)
        for t in range(16):
            idx_x[t], idx_y[t] = best_pair(src[t], vx, vy)
        pack(cx[0], cx[1], cx[2], idx_x, o, 0)
        pack(cy[0], cy[1], cy[2], idx_y, o, 8)
