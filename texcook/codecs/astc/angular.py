"""ASTC normal maps judged by the angle of the rebuilt normal (--normal-metric angular).

With ``normal_map=True`` a block stores X in R, G and B and Y in alpha, and a
shader rebuilds Z = sqrt(1 - X^2 - Y^2). The search minimises the X and Y
errors, which is not the angle: near the rim Z is steep, and one texel's X and
Y errors add up in its angle. `search_by_angle` turns the X/Y search into an
angular one:

1. Every block is searched as without the objective, then refined (below).
2. Per-block weights. For a unit normal (x, y, z) with z rebuilt, errors dx,
   dy turn it by an angle whose square is about
   dx^2 + dy^2 + (x dx + y dy)^2 / z^2, so X errors cost 1 + x^2/z^2 times
   what they cost at the centre, and Y errors 1 + y^2/z^2. Blocks are put in
   classes by the ratio of the two (averaged over the block, in steps of
   2^CLASS_STEP); the blocks of every class but 1:1 are searched again with X
   and Y weighted in their class's ratio, refined, and keep whichever encoding
   has the lower angular cost (`refine_kernel` reports it). The cross term
   x y dx dy has no place in per-channel weights.
3. Refinement (`refine_kernel`) keeps what the search chose (block mode,
   partitioning, CEMs, colour range) and moves the stored values of each block
   while the summed angular cost of its texels drops:

   - weights: each grid weight of the planes that drive X (R) or Y (alpha)
     tries the codes up to `WEIGHT_STEPS` levels above and below its own,
     measured on the texels it reaches;
   - endpoints: each colour value of a partition one level up and down,
     alone and with the other end of its channel (the same way, or apart or
     closer), each move followed by a weight pass; a move is kept when the
     block's cost (all texels) drops. Judged before the weights follow, most
     endpoint moves look worse than they are.

   Rounds (a weight pass, then the endpoint moves) repeat until one changes
   nothing or the preset's rounds run out. Only changes that lower the cost
   are kept, so a refined block is never worse than the search's by this
   measure; codes stay within the block's ranges, so the block still packs.

Cost of a texel: 1 - cos(angle) between the source normal and the decoded one,
as texcook.codecs.bc5_angular measures it (the same functions). Decoded values
come from the decoder's arithmetic: endpoints through its range tables and
texcook.codecs.astc.decode.decode_endpoints, 16-bit widening, the weight
infill (its per-grid-point spread is read off decode.infill_weights) and the
interpolation.
"""

from collections import namedtuple

import numpy as np

from ..._jit import jit, jit_inner
from .._base import run_chunked
from ..bc5_angular import angle_cost as _cost
from ..bc5_angular import unit_normal as _unit_normal
from . import quant as Q
from .decode import decode_endpoints, infill_weights
from .partitions import select_partition
from .symbolic import (KIND_NORMAL, KIND_VOID, S_CCS, S_CEM, S_CQUANT, S_DUAL, S_ENDPOINTS,
                       S_GRID_H, S_GRID_W, S_KIND, S_PARTS, S_PINDEX, S_VOID, S_WEIGHTS, S_WQUANT)

CLASS_STEP = 0.5  # log2 of the X:Y weight ratio between neighbouring classes
Z2_FLOOR = 0.02  # z^2 at most 50x amplification: texels on the rim would swamp a block's ratio
WEIGHT_STEPS = 2  # weight levels tried each side of the current code

_TABLES = {}


def sensitivity_classes(blocks):
    """blocks uint8 (n, T, 4), X in R and Y in alpha -> int (n,) class k: the
    block's X errors cost about 2^(k * CLASS_STEP) times its Y errors in angle."""
    x = blocks[..., 0] / 127.5 - 1.0
    y = blocks[..., 3] / 127.5 - 1.0
    z2 = np.maximum(1.0 - x * x - y * y, Z2_FLOOR)
    ratio = (1.0 + x * x / z2).mean(axis=1) / (1.0 + y * y / z2).mean(axis=1)
    return np.rint(np.log2(ratio) / CLASS_STEP).astype(np.int64)


def search_by_angle(blocks, sym, chw, search, bw, bh, preset, srgb, threads):
    """Fill sym (n, SYM_LEN) for blocks (n, T, 4) in the stored layout:
    search(blocks, sym, channel_weights) runs the X/Y search. Every block is
    searched with chw and refined; blocks whose sensitivity class is not 1:1
    are searched again with X and Y weighted in their class's ratio and
    refined, and each keeps whichever of its two encodings has the lower
    angular cost."""
    from .presets import table_for

    args = kernel_args(bw, bh, srgb)
    # refinement rounds (weights, then endpoints): more effort, more rounds
    params = (np.int64(table_for(bw, bh).row(preset).angular_rounds), np.int64(WEIGHT_STEPS)) + args

    def refine(b, s):
        costs = np.zeros(b.shape[0])
        run_chunked(refine_kernel, b, s, threads, *params, also=(costs,))
        return costs

    search(blocks, sym, chw)
    costs = refine(blocks, sym)
    classes = sensitivity_classes(blocks)
    for k in np.unique(classes):
        if k == 0:
            continue
        idx = np.nonzero(classes == k)[0]
        ratio = 2.0 ** (k * CLASS_STEP)
        w = chw.copy()
        w[:3] *= min(1.0, ratio)
        w[3] *= min(1.0, 1.0 / ratio)
        part_blocks = np.ascontiguousarray(blocks[idx])
        part = np.zeros((idx.size, sym.shape[1]), sym.dtype)
        search(part_blocks, part, w)
        better = refine(part_blocks, part) < costs[idx]
        sym[idx[better]] = part[better]


def infill_tables(bw, bh):
    """How each grid point's weight spreads over a bw x bh block, for every grid
    size that fits: (gid (13, 13) -> grid id or -1, count (G, 64), texel
    (G, 64, K), share (G, 64, K) in sixteenths). A texel's weight is
    (sum of share * grid weight + 8) >> 4, the decoder's infill; each share is
    read by infilling a grid with 16 at that point and 0 elsewhere."""
    key = (int(bw), int(bh))
    if key in _TABLES:
        return _TABLES[key]
    bw, bh = key
    nt = bw * bh
    dims = [(gw, gh) for gw in range(2, bw + 1) for gh in range(2, bh + 1) if gw * gh <= 64]
    gid = np.full((13, 13), -1, np.int64)
    spread = np.zeros((len(dims), 64, nt), np.int64)
    grid = np.zeros(64 + 16, np.int64)
    out = np.zeros(nt, np.int64)
    for g, (gw, gh) in enumerate(dims):
        gid[gw, gh] = g
        for j in range(gw * gh):
            grid[:] = 0
            grid[j] = 16
            infill_weights(grid, np.int64(gw), np.int64(gh), np.int64(bw), np.int64(bh), out)
            spread[g, j] = out
    count = (spread > 0).sum(axis=2)
    k = int(count.max())
    texel = np.zeros((len(dims), 64, k), np.int64)
    share = np.zeros((len(dims), 64, k), np.int64)
    for g in range(len(dims)):
        for j in range(64):
            ts = np.nonzero(spread[g, j])[0]
            texel[g, j, :ts.size] = ts
            share[g, j, :ts.size] = spread[g, j, ts]
    _TABLES[key] = (gid, count.astype(np.int64), texel, share)
    return _TABLES[key]


# the tables refine_kernel reads for one block size: grid ids, the infill's
# spread of each grid point (infill_tables), the colour range tables and the
# weight range tables; the weight pass, which runs most, is passed only its
# sub-records (each array passed costs time per call)
Spread = namedtuple("Spread", "count texel share")
WeightTables = namedtuple("WeightTables", "unq order rank levels")
AngularTables = namedtuple("AngularTables", "gid spread cunq corder crank weight")

# the block being refined: source normals (T, 3), labels, partition endpoints
# (4, 4) 16-bit, infill sums and weights per plane (2, T), each texel's cost
State = namedtuple("State", "src labels ends acc tw cost")
# one thread's scratch: the State, decode scratch v, d0, d1, and the saved_
# copies a rejected endpoint move returns to
Refine = namedtuple("Refine", "state v d0 d1 saved_row saved_acc saved_tw saved_cost saved_ends")


def kernel_args(bw, bh, srgb):
    """The block size, srgb and AngularTables that refine_kernel takes after rounds and steps."""
    gid, count, texel, share = infill_tables(bw, bh)
    return (np.int64(bw), np.int64(bh), np.int64(1 if srgb else 0),
            AngularTables(gid, Spread(count, texel, share),
                          Q.COLOUR_UNQUANT.astype(np.int64), Q.COLOUR_ORDER.astype(np.int64),
                          Q.COLOUR_RANK.astype(np.int64),
                          WeightTables(Q.WEIGHT_UNQUANT.astype(np.int64), Q.WEIGHT_ORDER.astype(np.int64),
                                       Q.WEIGHT_RANK.astype(np.int64), Q.RANGE_LEVELS.astype(np.int64))))


@jit_inner
def _widen(e, srgb):
    """An 8-bit endpoint as the decoder widens it to 16 bits."""
    if srgb:
        return (e << 8) | 0x80
    return e * 257


@jit_inner
def _lerp8(a, b, w):
    """The decoder's interpolation of 16-bit endpoints, as its 8-bit output."""
    return ((a * (64 - w) + b * w + 32) >> 6) >> 8


@jit_inner
def _partition_ends(row, p, cunq, srgb, v, d0, d1, ends):
    """Decode partition p's colour values into ends[p] = (X0, X1, Y0, Y1),
    16-bit. Returns False for a mode LDR decoding paints as an error."""
    base = 0
    for q in range(p):
        base += 2 * ((row[S_CEM + q] >> 2) + 1)
    cem = row[S_CEM + p]
    cq = row[S_CQUANT]
    for k in range(2 * ((cem >> 2) + 1)):
        v[k] = cunq[cq, row[S_ENDPOINTS + base + k]]
    if not decode_endpoints(cem, v, d0, d1):
        return False
    ends[p, 0] = _widen(d0[0], srgb)
    ends[p, 1] = _widen(d1[0], srgb)
    ends[p, 2] = _widen(d0[3], srgb)
    ends[p, 3] = _widen(d1[3], srgb)
    return True


@jit_inner
def _texel_cost(src, t, ends, p, wx, wy):
    return _cost(src[t], np.float64(_lerp8(ends[p, 0], ends[p, 1], wx)),
                 np.float64(_lerp8(ends[p, 2], ends[p, 3], wy)))


@jit_inner
def _weight_pass(row, st, planes, pl_x, pl_y, g, spread, weight, steps):
    """Each grid weight of a plane that drives X or Y to the code within
    +-steps levels that lowers the cost of its texels most (st: the block's
    State; spread, weight: AngularTables' sub-records). Returns the drop."""
    src, labels, ends, acc, tw, cost = st
    count, texel, share = spread
    wunq, worder, wrank, levels = weight
    wq = row[S_WQUANT]
    ng = row[S_GRID_W] * row[S_GRID_H]
    nlev = levels[wq]
    gain = 0.0
    for q in range(planes):
        if q != pl_x and q != pl_y:
            continue
        for j in range(ng):
            slot = S_WEIGHTS + j * planes + q
            cur = wunq[wq, row[slot]]
            r0 = wrank[wq, row[slot]]
            best = 0.0
            bcode = -1
            for r in range(max(0, r0 - steps), min(nlev, r0 + steps + 1)):
                if r == r0:
                    continue
                code = worder[wq, r]
                delta = wunq[wq, code] - cur
                d = 0.0
                for k in range(count[g, j]):
                    t = texel[g, j, k]
                    w = (acc[q, t] + share[g, j, k] * delta + 8) >> 4
                    wx = w if q == pl_x else tw[pl_x, t]
                    wy = w if q == pl_y else tw[pl_y, t]
                    d += _texel_cost(src, t, ends, labels[t], wx, wy) - cost[t]
                if d < best - 1e-12:
                    best = d
                    bcode = code
            if bcode < 0:
                continue
            delta = wunq[wq, bcode] - cur
            row[slot] = bcode
            for k in range(count[g, j]):
                t = texel[g, j, k]
                acc[q, t] += share[g, j, k] * delta
                tw[q, t] = (acc[q, t] + 8) >> 4
                cost[t] = _texel_cost(src, t, ends, labels[t], tw[pl_x, t], tw[pl_y, t])
            gain -= best
    return gain


@jit_inner
def _step_code(row, k, d, cq, corder, crank, nlev):
    """Colour value k moved d levels; False (row unchanged) past the range."""
    r = crank[cq, row[S_ENDPOINTS + k]] + d
    if r < 0 or r >= nlev:
        return False
    row[S_ENDPOINTS + k] = corder[cq, r]
    return True


@jit_inner
def _total(cost, nt):
    total = 0.0
    for t in range(nt):
        total += cost[t]
    return total


@jit_inner
def _copy_state(row, acc, tw, cost, ends, to_row, to_acc, to_tw, to_cost, to_ends, nt):
    """A block's state into the to_ arrays (explicit loops: numba compiles
    slice assignments far more slowly)."""
    for k in range(row.shape[0]):
        to_row[k] = row[k]
    for q in range(2):
        for t in range(nt):
            to_acc[q, t] = acc[q, t]
            to_tw[q, t] = tw[q, t]
    for t in range(nt):
        to_cost[t] = cost[t]
    for p in range(4):
        for c in range(4):
            to_ends[p, c] = ends[p, c]


@jit_inner
def _endpoint_pass(row, rs, planes, pl_x, pl_y, g, nt, tab, srgb, steps):
    """Endpoint moves judged after the weights have followed them: each
    colour value one level up and down, alone and with the other end of its
    channel (the same way or the opposite way), then a weight pass; a move is
    kept when the block's cost drops (rs: the block's Refine state, tab:
    AngularTables). Returns the drop."""
    st = rs.state
    src, labels, ends, acc, tw, cost = st
    _, v, d0, d1, saved_row, saved_acc, saved_tw, saved_cost, saved_ends = rs
    cunq, corder, crank, levels = tab.cunq, tab.corder, tab.crank, tab.weight.levels
    cq = row[S_CQUANT]
    nlev = levels[cq]
    gain = 0.0
    base = 0
    for p in range(row[S_PARTS]):
        nv = 2 * ((row[S_CEM + p] >> 2) + 1)
        for m in range(2 * nv):
            # each value alone, then each pair (both ends of a channel) the
            # same way or opposite ways; every move up and down
            if m < nv:
                k, k2, s2 = m, -1, 0
            else:
                k = 2 * ((m - nv) // 2)
                k2 = k + 1
                s2 = 1 if (m - nv) & 1 else -1
            for sign in (-1, 1):
                before = _total(cost, nt)
                _copy_state(row, acc, tw, cost, ends, saved_row, saved_acc, saved_tw, saved_cost,
                            saved_ends, nt)
                if not _step_code(row, base + k, sign, cq, corder, crank, nlev):
                    continue
                if k2 >= 0 and not _step_code(row, base + k2, s2 * sign, cq, corder, crank, nlev):
                    _step_code(row, base + k, -sign, cq, corder, crank, nlev)
                    continue
                if _partition_ends(row, p, cunq, srgb, v, d0, d1, ends):
                    for t in range(nt):
                        if labels[t] == p:
                            cost[t] = _texel_cost(src, t, ends, p, tw[pl_x, t], tw[pl_y, t])
                    _weight_pass(row, st, planes, pl_x, pl_y, g, tab.spread, tab.weight, steps)
                    after = _total(cost, nt)
                    if after < before - 1e-12:
                        gain += before - after
                        continue
                _copy_state(saved_row, saved_acc, saved_tw, saved_cost, saved_ends, row, acc, tw,
                            cost, ends, nt)
        base += nv
    return gain


@jit_inner
def _setup(row, blk, bw, bh, srgb, tab, rs):
    """The state of one normal block into rs (Refine): source normals,
    partition labels, endpoints, infilled weights and each texel's cost.
    Returns (ok, planes, plane driving X, plane driving Y, grid id); ok is
    False for a block whose endpoints decode to the error colour."""
    src, labels, ends, acc, tw, cost = rs.state
    v, d0, d1 = rs.v, rs.d0, rs.d1
    gid, cunq, wunq = tab.gid, tab.cunq, tab.weight.unq
    count, texel, share = tab.spread
    nt = bw * bh
    parts = row[S_PARTS]
    for p in range(parts):
        if not _partition_ends(row, p, cunq, srgb, v, d0, d1, ends):
            return False, 0, 0, 0, 0
    planes = 2 if row[S_DUAL] else 1
    pl_x = 1 if (planes == 2 and row[S_CCS] == 0) else 0
    pl_y = 1 if (planes == 2 and row[S_CCS] == 3) else 0
    g = gid[row[S_GRID_W], row[S_GRID_H]]
    wq = row[S_WQUANT]
    for t in range(nt):
        acc[0, t] = 0
        acc[1, t] = 0
    for q in range(planes):
        for j in range(row[S_GRID_W] * row[S_GRID_H]):
            gv = wunq[wq, row[S_WEIGHTS + j * planes + q]]
            for k in range(count[g, j]):
                acc[q, texel[g, j, k]] += share[g, j, k] * gv
    small = 1 if nt < 31 else 0
    for t in range(nt):
        tw[0, t] = (acc[0, t] + 8) >> 4
        tw[1, t] = (acc[1, t] + 8) >> 4
        _unit_normal(np.float64(blk[t, 0]), np.float64(blk[t, 3]), src[t])
        labels[t] = select_partition(row[S_PINDEX], t % bw, t // bw, 0, parts, small) if parts > 1 else 0
        cost[t] = _texel_cost(src, t, ends, labels[t], tw[pl_x, t], tw[pl_y, t])
    return True, planes, pl_x, pl_y, g


@jit
def refine_kernel(blocks, sym, rounds, steps, bw, bh, srgb, tab, costs):
    """blocks uint8 (n, T, 4) in the stored layout (X in R, G, B; Y in alpha)
    and their symbolic blocks from the search -> sym refined in place, and
    costs[i] the summed angular cost of block i as it now decodes (inf for an
    error block). rounds 0 only measures. tab: AngularTables (kernel_args)."""
    nt = bw * bh
    rs = Refine(State(np.zeros((nt, 3)), np.zeros(nt, np.int64), np.zeros((4, 4), np.int64),
                      np.zeros((2, nt), np.int64), np.zeros((2, nt), np.int64), np.zeros(nt)),
                np.zeros(8, np.int64), np.zeros(4, np.int64), np.zeros(4, np.int64),
                np.zeros(sym.shape[1], sym.dtype), np.zeros((2, nt), np.int64), np.zeros((2, nt), np.int64),
                np.zeros(nt), np.zeros((4, 4), np.int64))
    src = rs.state.src
    for i in range(blocks.shape[0]):
        row = sym[i]
        costs[i] = np.inf
        if row[S_KIND] == KIND_VOID:  # one exact value: nothing to move
            total = 0.0
            for t in range(nt):
                _unit_normal(np.float64(blocks[i, t, 0]), np.float64(blocks[i, t, 3]), src[0])
                total += _cost(src[0], np.float64(row[S_VOID] >> 8), np.float64(row[S_VOID + 3] >> 8))
            costs[i] = total
            continue
        if row[S_KIND] != KIND_NORMAL:
            continue
        ok, planes, pl_x, pl_y, g = _setup(row, blocks[i], bw, bh, srgb, tab, rs)
        if not ok:
            continue
        for _ in range(rounds):
            gain = _weight_pass(row, rs.state, planes, pl_x, pl_y, g, tab.spread, tab.weight, steps)
            gain += _endpoint_pass(row, rs, planes, pl_x, pl_y, g, nt, tab, srgb, steps)
            if gain <= 0.0:
                break
        costs[i] = _total(rs.state.cost, nt)
