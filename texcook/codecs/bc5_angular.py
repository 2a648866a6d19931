"""BC5 for tangent-space normal maps, judged by the angle between normals.

BC5 stores X and Y as two independent BC4 blocks and a shader rebuilds
Z = sqrt(1 - X^2 - Y^2). Minimising the X and Y errors separately is not the
same as minimising the angle of the rebuilt normal: near the rim (large |X| or
|Y|) Z is steep, and the X and Y errors of one texel add up in the angle. This
search starts from BC4's X/Y result and then, channel by channel, measures
every endpoint pair within a window by the rebuilt normals' cost, choosing
each texel's X and Y indices jointly.

Cost of a texel: 1 - cos(angle) between the source normal (its X and Y with Z
rebuilt, as texcook.metrics.normal_angular_error reads it) and the decoded one,
which grows as the angle squared. With one channel's palette fixed, the best
cost of each texel for every 8-bit value of the other channel is tabulated
once, so a candidate pair costs 8 look-ups per texel.

The angle cost and its table (unit_normal, angle_cost, cost_table,
palette_cost, best_pair) are public: EAC RG11's angular search
(codecs/eac_kernels.py) and ASTC's (codecs/astc/angular.py) judge normals by
the same cost.
"""

import numpy as np

from .._jit import jit, jit_inner
from .bc4 import encode_single_block, palette, single_scratch


@jit
def unit_normal(x8, y8, out):
    """X, Y in 0..255 -> unit (x, y, z) with z rebuilt; a vector past the rim
    has z = 0 and is normalised, as a shader's normalize() would."""
    x = x8 / 127.5 - 1.0
    y = y8 / 127.5 - 1.0
    r = x * x + y * y
    if r >= 1.0:
        n = np.sqrt(r)
        out[0] = x / n
        out[1] = y / n
        out[2] = 0.0
    else:
        out[0] = x
        out[1] = y
        out[2] = np.sqrt(1.0 - r)


@jit
def angle_cost(n, xv, yv):
    """1 - cos of the angle between unit n and the normal decoded from (xv, yv)."""
    x = xv / 127.5 - 1.0
    y = yv / 127.5 - 1.0
    r = x * x + y * y
    if r >= 1.0:
        return 1.0 - (n[0] * x + n[1] * y) / np.sqrt(r)
    return 1.0 - (n[0] * x + n[1] * y + n[2] * np.sqrt(1.0 - r))


@jit
def cost_table(src, other_pal, ch, table, ends, win):
    """table[t, v]: texel t's best cost when channel ch decodes to v, over the
    other channel's 8 palette values; only for the values the pairs within
    +-win of ends can decode to (between them, and 0 and 255)."""
    lo = max(0, min(ends[0], ends[1]) - win)
    hi = min(255, max(ends[0], ends[1]) + win)
    for t in range(16):
        for v in range(256):
            if v > 0 and v < 255 and (v < lo or v > hi):
                continue
            best = 1e30
            for j in range(8):
                if ch == 0:
                    c = angle_cost(src[t], v, other_pal[j])
                else:
                    c = angle_cost(src[t], other_pal[j], v)
                if c < best:
                    best = c
            table[t, v] = best


@jit_inner
def palette_cost(table, pal, limit):
    """Sum over the 16 texels of their lowest table[t, v] among the 8 values
    pal a block decodes to; stops (returning a sum >= limit) once it cannot win."""
    total = 0.0
    for t in range(16):
        best = 1e30
        for i in range(8):
            c = table[t, pal[i]]
            if c < best:
                best = c
        total += best
        if total >= limit:
            return total
    return total


@jit_inner
def best_pair(n, px, py):
    """(i, j): the X and Y palette entries whose decoded normal is nearest the
    unit normal n, chosen jointly (the first on ties)."""
    best = 1e30
    bi = 0
    bj = 0
    for i in range(8):
        for j in range(8):
            c = angle_cost(n, px[i], py[j])
            if c < best:
                best = c
                bi = i
                bj = j
    return bi, bj


@jit
def _pair_cost(table, a, b, pal, limit):
    palette(a, b, pal)
    return palette_cost(table, pal, limit)


@jit
def _search_channel(table, ends, win, pal):
    """Every pair within +-win of ends (a, b), either order (so both BC4 modes);
    ends keeps the best. Returns its cost."""
    a0 = ends[0]
    b0 = ends[1]
    best = _pair_cost(table, a0, b0, pal, 1e30)
    for da in range(-win, win + 1):
        a = a0 + da
        if a < 0 or a > 255:
            continue
        for db in range(-win, win + 1):
            b = b0 + db
            if b < 0 or b > 255:
                continue
            c = _pair_cost(table, a, b, pal, best)
            if c < best:
                best = c
                ends[0] = a
                ends[1] = b
    return best


@jit
def _write(src, ex, ey, out, px, py):
    """Endpoints and the jointly best indices of each texel into out[0:16]."""
    palette(ex[0], ex[1], px)
    palette(ey[0], ey[1], py)
    bx = np.int64(0)
    by = np.int64(0)
    for t in range(16):
        bi, bj = best_pair(src[t], px, py)
        bx |= np.int64(bi) << (3 * t)
        by |= np.int64(bj) << (3 * t)
    out[0] = ex[0]
    out[1] = ex[1]
    out[8] = ey[0]
    out[9] = ey[1]
    for k in range(6):
        out[2 + k] = (bx >> (8 * k)) & 255
        out[10 + k] = (by >> (8 * k)) & 255


@jit
def encode_kernel(blocks, out, rec, win, rounds):
    """BC5 blocks searched by angle; rec: bc4.SEARCH.record(preset), for the
    BC4 search each block starts from."""
    prm = rec[0]
    scr = single_scratch()
    src = np.empty((16, 3))
    table = np.empty((16, 256))
    px = np.empty(8, np.int64)
    py = np.empty(8, np.int64)
    ex = np.empty(2, np.int64)
    ey = np.empty(2, np.int64)
    for b in range(blocks.shape[0]):
        blk = blocks[b]
        encode_single_block(blk, 0, prm, out[b], 0, scr)
        encode_single_block(blk, 1, prm, out[b], 8, scr)
        for t in range(16):
            unit_normal(np.float64(blk[t, 0]), np.float64(blk[t, 1]), src[t])
        ex[0] = out[b, 0]
        ex[1] = out[b, 1]
        ey[0] = out[b, 8]
        ey[1] = out[b, 9]
        best = 1e30
        for _ in range(rounds):
            palette(ey[0], ey[1], py)
            cost_table(src, py, 0, table, ex, win)
            _search_channel(table, ex, win, px)
            palette(ex[0], ex[1], px)
            cost_table(src, px, 1, table, ey, win)
            cost = _search_channel(table, ey, win, py)
            if cost >= best:
                break
            best = cost
        _write(src, ex, ey, out[b], px, py)
