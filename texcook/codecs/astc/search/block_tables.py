"""ASTC search, per block size: the tables the search kernel reads (the
decoder's weight infill and its inverse, the legal block modes by grid, the
partition patterns as texel masks, the expected quantisation errors of each
colour and weight range, the bases of the separable grid estimate), built in
Python once per size and passed to the kernel as arrays."""

from collections import namedtuple

import numpy as np

from .. import quant as Q
from ..modes import BM_DUAL, BM_GRID_H, BM_GRID_W, BM_WEIGHT_BITS, BM_WQUANT, COLOUR_RANGE, block_modes
from ..partitions import partition_table, partition_usable


_TABLE_CACHE = {}


def _infill_table(bw, bh, gw, gh):
    """Per texel: 4 grid indices and their 1/16 weights, the decoder's infill."""
    t = bw * bh
    idx = np.zeros((t, 4), np.int32)
    wt = np.zeros((t, 4), np.int32)
    ds = (1024 + bw // 2) // (bw - 1)
    dt = (1024 + bh // 2) // (bh - 1)
    for y in range(bh):
        for x in range(bw):
            gs = (ds * x * (gw - 1) + 32) >> 6
            gt = (dt * y * (gh - 1) + 32) >> 6
            js, fs = gs >> 4, gs & 15
            jt, ft = gt >> 4, gt & 15
            w11 = (fs * ft + 8) >> 4
            ws = (16 - fs - ft + w11, fs - w11, ft - w11, w11)
            v0 = js + jt * gw
            ids = (v0, v0 + 1, v0 + gw, v0 + gw + 1)
            i = y * bw + x
            for k in range(4):
                if ws[k]:
                    idx[i, k] = ids[k]
                    wt[i, k] = ws[k]
                else:
                    idx[i, k] = v0  # weight 0: any valid index
    return idx, wt


def infill_1d(n, g):
    """(n, g) float matrix of the infill along one axis (the decoder's 2D
    infill is this in x times this in y, up to the rounding of its corner
    weight)."""
    a = np.zeros((n, g))
    d = (1024 + n // 2) // (n - 1)
    for x in range(n):
        gs = (d * x * (g - 1) + 32) >> 6
        j, f = gs >> 4, gs & 15
        a[x, j] += (16 - f) / 16.0
        if f:
            a[x, j + 1] += f / 16.0
    return a


def _legal_modes(bw, bh):
    """(gw, gh, wquant, dual, weight bits) of every legal 2D block mode."""
    bm = block_modes(bw, bh)
    return [(int(r[BM_GRID_W]), int(r[BM_GRID_H]), int(r[BM_WQUANT]), int(r[BM_DUAL]),
             int(r[BM_WEIGHT_BITS])) for r in bm]


def tables(bw, bh):
    """Arrays the search kernel needs for one block size (cached)."""
    key = (int(bw), int(bh))
    if key in _TABLE_CACHE:
        return _TABLE_CACHE[key]
    bw, bh = key
    modes = _legal_modes(bw, bh)
    grids = sorted({(m[0], m[1]) for m in modes})
    gid = {g: i for i, g in enumerate(grids)}
    t = bw * bh
    g_dims = np.array(grids, np.int32).reshape(-1, 2)
    g_idx = np.zeros((len(grids), t, 4), np.int32)
    g_wt = np.zeros((len(grids), t, 4), np.int32)
    for i, (gw, gh) in enumerate(grids):
        g_idx[i], g_wt[i] = _infill_table(bw, bh, gw, gh)
        if gw * gh == t:  # decimate and infill take a full grid's infill as the identity
            assert np.array_equal(g_idx[i, :, 0], np.arange(t)) and np.all(g_wt[i, :, 0] == 16)
    # inverse of the infill: per grid point, the texels it reaches and how much
    g_tn = np.zeros((len(grids), 64), np.int32)
    lists = [[[] for _ in range(64)] for _ in grids]
    for i in range(len(grids)):
        for tt in range(t):
            for k in range(4):
                if g_wt[i, tt, k]:
                    lists[i][g_idx[i, tt, k]].append((tt, g_wt[i, tt, k]))
    maxt = max(len(lst) for gl in lists for lst in gl)
    g_tex = np.zeros((len(grids), 64, maxt), np.int32)
    g_tw = np.zeros((len(grids), 64, maxt), np.int32)
    for i, gl in enumerate(lists):
        for j, lst in enumerate(gl):
            g_tn[i, j] = len(lst)
            for k, (tt, w) in enumerate(lst):
                g_tex[i, j, k] = tt
                g_tw[i, j, k] = w
    mode_arr = np.array([(gid[(m[0], m[1])], m[2], m[3], m[4]) for m in modes],
                        np.int32).reshape(-1, 4)
    # the modes grid by grid, the grids of most points first (their error is
    # mostly the least), in table order within a grid: the order in which a
    # fit's mode selection passes over them (estimate.select_modes)
    morder = np.array(sorted(range(len(modes)), key=lambda i: (-modes[i][0] * modes[i][1], gid[modes[i][:2]], i)),
                      np.int64)
    ptab = partition_table(bw, bh)[2:5].copy()
    usable = partition_usable(bw, bh)
    # texel masks per pattern and partition, 48 texels per int64 word
    pmask = np.zeros((3, 1024, 4, 3), np.int64)
    for c in range(3):
        for pid in range(1024):
            for tt in range(t):
                pmask[c, pid, ptab[c, pid, tt], tt // 48] |= 1 << (tt % 48)
    plist = np.zeros((3, 1024), np.int32)
    pcount = np.zeros(3, np.int32)
    for c in range(2, 5):
        ids = np.nonzero(usable[c])[0]
        plist[c - 2, :ids.size] = ids
        pcount[c - 2] = ids.size
    # two partitions: partition 0's texel mask per usable pattern, in list
    # order, so that ranking reads one contiguous array
    p2mask = np.ascontiguousarray(pmask[0, plist[0], 0, :])
    # mean squared error of quantising a uniform 8-bit value to each colour range
    cq_err = np.zeros(Q.N_RANGES, np.float64)
    v = np.arange(256)
    for r in range(Q.N_RANGES):
        d = Q.COLOUR_UNQUANT[r, Q.COLOUR_QUANT[r, v]] - v
        cq_err[r] = float(np.mean(d * d))
    # ... and of quantising a uniform weight (0..1) to each weight range
    wq_err = np.zeros(Q.N_WEIGHT_RANGES, np.float64)
    u = np.arange(65)
    for r in range(Q.N_WEIGHT_RANGES):
        d = (Q.WEIGHT_UNQUANT[r, Q.WEIGHT_QUANT[r, u]] - u) / 64.0
        wq_err[r] = float(np.mean(d * d))
    # separable estimate: per grid width an orthonormal basis of what a row of
    # that many grid columns can make (every width's side by side, from column
    # uoff[gw]), per grid height the projector onto what a column can make,
    # its upper triangle flattened (off-diagonal doubled) so that one pass over
    # a row-space Gram matrix scores every height
    uoff = np.zeros(14, np.int64)
    col = 0
    for gw in range(2, bw + 1):
        uoff[gw] = col
        col += gw
    ux = np.zeros((bw, col))
    qyp = np.zeros((13, bh * (bh + 1) // 2))
    for gw in range(2, bw + 1):
        u, sv, _ = np.linalg.svd(infill_1d(bw, gw), full_matrices=False)
        r = int(np.sum(sv > 1e-9 * sv[0]))
        ux[:, uoff[gw]:uoff[gw] + r] = u[:, :r]
    for gh in range(2, bh + 1):
        a = infill_1d(bh, gh)
        q = a @ np.linalg.pinv(a)
        k = 0
        for y in range(bh):
            for y2 in range(y, bh):
                qyp[gh, k] = q[y, y2] * (1.0 if y2 == y else 2.0)
                k += 1
    out = dict(
        g_dims=g_dims, g_idx=g_idx, g_wt=g_wt,
        g_tex=g_tex, g_tw=g_tw, g_tn=g_tn,
        modes=mode_arr, ptab=ptab, pmask=pmask, p2mask=p2mask, plist=plist, pcount=pcount,
        morder=morder,
        cq_err=cq_err, wq_err=wq_err, ux=ux, uoff=uoff, qyp=qyp,
    )
    _TABLE_CACHE[key] = out
    return out


# writable copies: read-only arrays would give the kernel a second signature
_COLOUR_UNQUANT = Q.COLOUR_UNQUANT.copy()
_COLOUR_QUANT = Q.COLOUR_QUANT.copy()
_WEIGHT_UNQUANT = Q.WEIGHT_UNQUANT.copy()
_WEIGHT_QUANT = Q.WEIGHT_QUANT.copy()
_WEIGHT_ORDER = Q.WEIGHT_ORDER.copy()
_WEIGHT_RANK = Q.WEIGHT_RANK.copy()

# The per-size record the search kernel takes (kernel_tables), the arrays of
# tables() and the range tables every size shares, in sub-records by stage: a
# helper is passed only the sub-records it reads (each array passed to a
# helper that is not inlined costs time per call)
GridTables = namedtuple("GridTables", "dims idx wt tex tw tn")  # per grid: the infill and its inverse
SepTables = namedtuple("SepTables", "ux uoff qyp")  # the separable estimate's bases
PartTables = namedtuple("PartTables", "ptab pmask p2mask plist pcount")
ColourRanges = namedtuple("ColourRanges", "err cr_tab unq quant")  # cr_tab: range by (bits left, values)
WeightRanges = namedtuple("WeightRanges", "err unq quant order rank levels")
BlockTables = namedtuple("BlockTables", "modes grids sep parts colour weight morder")
_RECORDS = {}


def kernel_tables(bw, bh):
    """The BlockTables record of one block size (cached)."""
    key = (int(bw), int(bh))
    if key not in _RECORDS:
        tb = tables(*key)
        _RECORDS[key] = BlockTables(
            tb["modes"],
            GridTables(tb["g_dims"], tb["g_idx"], tb["g_wt"], tb["g_tex"], tb["g_tw"], tb["g_tn"]),
            SepTables(tb["ux"], tb["uoff"], tb["qyp"]),
            PartTables(tb["ptab"], tb["pmask"], tb["p2mask"], tb["plist"], tb["pcount"]),
            ColourRanges(tb["cq_err"], COLOUR_RANGE, _COLOUR_UNQUANT, _COLOUR_QUANT),
            WeightRanges(tb["wq_err"], _WEIGHT_UNQUANT, _WEIGHT_QUANT, _WEIGHT_ORDER, _WEIGHT_RANK,
                         Q.RANGE_LEVELS.astype(np.int64)),
            tb["morder"])
    return _RECORDS[key]

