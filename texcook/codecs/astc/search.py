"""ASTC encoder search: RGBA texels of one block -> one symbolic block.

The search never touches bits; it fills the (n, SYM_LEN) rows that pack.py
turns into 128-bit blocks. Every candidate is scored after the decoder's own
arithmetic: colour values unquantised through the range tables, the CEM's
decode (swap and blue-contraction included), the weight grid's infill and the
16-bit interpolation, so the error measured is the error a GPU shows.

Per block:

1. A block of one colour becomes a void-extent block (exact).
2. For each partition count the preset allows (1 to 4): partitionings are
   ranked by how well their texel split matches a small k-means clustering of
   the block, and the best few are tried.
3. For each partitioning and plane layout (one plane, or two with one colour
   component on its own plane): a principal-axis fit per partition (from
   sums of per-texel moments made once per block) gives ideal endpoints and
   ideal weights. A fit whose texels lie farther from their lines than the
   best error so far is dropped (no encoding can do better), and so, where
   the preset says, is one that comes too little closer to lines than the
   first fit.
4. Every legal (grid, weight range, dual plane) mode the preset tries gets a
   cheap error estimate: the error of fitting the ideal weights with its grid
   (decimated onto it and infilled back, or a separable least-squares estimate
   for the fast presets), plus the expected errors of its weight range and of
   the colour range its leftover bits allow for each CEM family. The best few
   (mode, CEM family) pairs are encoded for real.
5. A real encoding re-fits the endpoints by least squares to the quantised
   weights, quantises them for its CEMs (direct, or blue-contracted when that
   is closer; base+scale; base+offset where the range keeps its bits), moves
   grid weights a step where the decoded error drops, decodes and measures;
   refinement rounds re-derive the weights from the decoded endpoints and
   repeat.

Error is a weighted sum of squared 8-bit channel differences (channel weights
from the caller).
"""

import itertools
from collections import namedtuple

import numpy as np

from ..._jit import borrow, jit, jit_inner
from . import quant as Q
from .decode import decode_endpoints
from .modes import BM_DUAL, BM_GRID_H, BM_GRID_W, BM_WEIGHT_BITS, BM_WQUANT, block_modes
from .modes import colour_range, config_bits
from .partitions import partition_table, partition_usable
from .symbolic import (
    KIND_NORMAL,
    KIND_VOID,
    S_CCS,
    S_CEM,
    S_CQUANT,
    S_DUAL,
    S_ENDPOINTS,
    S_GRID_H,
    S_GRID_W,
    S_KIND,
    S_PARTS,
    S_PINDEX,
    S_VOID,
    S_WEIGHTS,
    S_WQUANT,
    SYM_LEN,
)

# ---------------------------------------------------------------------------
# parameter vector (filled by presets.py)

P_MAX_PARTS = 0  # highest partition count tried (1..4)
P_PART_CANDS = 1  # partitionings tried per partition count
P_DUAL = 2  # 0 none, 1 the one most independent component, 2 every component
P_MODE_CANDS = 3  # (mode, CEM family) pairs encoded for real per fit
P_REFINE = 4  # refinement rounds after the first encoding
P_SCALE_CEMS = 5  # also try base+scale (6/10) and base+offset (9/13) CEMs
P_EARLY_OUT = 6  # skip more partitions below this error per texel (x100)
P_DECIM_ITERS = 7  # least-squares passes when decimating weights onto a grid
P_KMEANS_ITERS = 8
P_PART_FULL = 9  # of those, how many (best line fit) get the full mode search
P_REALIGN = 10  # passes moving each grid weight one step where the decoded error drops
P_WQ_SCALE = 11  # weight quantisation error estimate, percent of the uniform-weight figure
P_DUAL_CORR = 12  # dual mode 1: a second plane only below this correlation (x100)
P_SEP_RANK = 13  # rank modes by a separable least-squares estimate of each grid
P_EST_SKIP = 14  # skip encoding candidates estimated above this times the best so far (x100)
P_LUMA_CEMS = 15  # also try luminance CEMs (0/4) for partitions that are not quite grey
P_FIT_GAIN = 16  # later fits only below this share of the first fit's line residual (x100)
P_CQ_SCALE = 17  # weight of the colour range's quantisation error in the mode estimate (x100)
P_PLANE_ALWAYS = 18  # 1: the second plane is tried whatever the early-out (set for normal maps)
P_LEN = 19

# CEM families: per partition the content (grey?, opaque?) picks the mode
FAM_DIRECT = 0  # 0 / 4 / 8 / 12
FAM_SCALE = 1  # 0 / 4 / 6 / 10
FAM_OFFSET = 2  # 0 / 4 / 9 / 13, only where the colour range keeps them exact
FAM_LUMA = 3  # 0 / 4 for every partition: two colour values buy the widest colour range
OFFSET_MIN_RANGE = 17  # 128 levels: every bit base+offset uses survives

# ---------------------------------------------------------------------------
# tables per block size (built in Python, passed to the kernel as arrays)

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


def _infill_1d(n, g):
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
        if gw * gh == t:  # _decimate and _infill take a full grid's infill as the identity
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
        u, sv, _ = np.linalg.svd(_infill_1d(bw, gw), full_matrices=False)
        r = int(np.sum(sv > 1e-9 * sv[0]))
        ux[:, uoff[gw]:uoff[gw] + r] = u[:, :r]
    for gh in range(2, bh + 1):
        a = _infill_1d(bh, gh)
        q = a @ np.linalg.pinv(a)
        k = 0
        for y in range(bh):
            for y2 in range(y, bh):
                qyp[gh, k] = q[y, y2] * (1.0 if y2 == y else 2.0)
                k += 1
    perms = np.zeros((3, 24, 4), np.int32)
    nperm = np.zeros(3, np.int32)
    for c in range(2, 5):
        ps = list(itertools.permutations(range(c)))
        nperm[c - 2] = len(ps)
        perms[c - 2, :len(ps), :c] = ps
    out = dict(
        g_dims=g_dims, g_idx=g_idx, g_wt=g_wt,
        g_tex=g_tex, g_tw=g_tw, g_tn=g_tn,
        modes=mode_arr, ptab=ptab, pmask=pmask, p2mask=p2mask, plist=plist, pcount=pcount, perms=perms,
        nperm=nperm,
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


# the implicit colour range for (bits left, colour value count); -1 illegal
_CR_TAB = np.array([[colour_range(nv, bits) for nv in range(19)] for bits in range(129)],
                   np.int64)


def kernel_args(bw, bh):
    tb = tables(bw, bh)
    return (tb["g_dims"], tb["g_idx"], tb["g_wt"], tb["g_tex"], tb["g_tw"],
            tb["g_tn"], tb["modes"], tb["ptab"], tb["ux"], tb["uoff"], tb["qyp"],
            tb["pmask"], tb["p2mask"], tb["plist"], tb["pcount"], tb["perms"], tb["nperm"],
            tb["cq_err"], tb["wq_err"], _CR_TAB,
            _COLOUR_UNQUANT, _COLOUR_QUANT, _WEIGHT_UNQUANT, _WEIGHT_QUANT,
            _WEIGHT_ORDER, _WEIGHT_RANK, Q.RANGE_LEVELS.astype(np.int64))


# ---------------------------------------------------------------------------
# kernel helpers


@jit_inner
def _cem_for(fam, grey, opaque):
    if grey or fam == FAM_LUMA:
        return 0 if opaque else 4
    if fam == FAM_SCALE:
        return 6 if opaque else 10
    if fam == FAM_OFFSET:
        return 9 if opaque else 13
    return 8 if opaque else 12


@jit_inner
def _promote(cem, minclass):
    """A CEM of at least class minclass that stores the same content."""
    while (cem >> 2) < minclass:
        if cem == 0:
            cem = 4 if minclass == 1 else 8
        elif cem == 6:
            cem = 10 if minclass == 2 else 12
        elif cem == 4:
            cem = 12
        elif cem == 8 or cem == 10:
            cem = 12
        elif cem == 9:
            cem = 13
        else:
            cem = 12
    return cem


@jit_inner(inline="always")
def _choose_cems(fam, nparts, pgrey, popaque, cems):
    """CEM per partition for a family; classes kept within one step of each other
    (what the multi-partition CEM field can say). Returns (colour value count,
    1 if all partitions share one CEM)."""
    maxc = 0
    for p in range(nparts):
        cems[p] = _cem_for(fam, pgrey[p], popaque[p])
        if (cems[p] >> 2) > maxc:
            maxc = cems[p] >> 2
    nv = 0
    same = 1
    for p in range(nparts):
        if (cems[p] >> 2) < maxc - 1:
            cems[p] = _promote(cems[p], maxc - 1)
        nv += 2 * ((cems[p] >> 2) + 1)
        if cems[p] != cems[0]:
            same = 0
    return nv, same


@jit_inner(inline="always")
def _expand(e, srgb):
    if srgb:
        return (e << 8) | 0x80
    return e * 257


@jit_inner
def _decode_err(x, chw, labels, nt, wt1, wt2, dual, ccs, ee0, ee1):
    """Weighted squared error of the decoded block against texels x (T,4);
    ee0, ee1 are the partitions' endpoints widened to 16 bits (_expand)."""
    err = 0.0
    for t in range(nt):
        p = labels[t]
        for c in range(4):
            w = wt2[t] if (dual and c == ccs) else wt1[t]
            v = ((ee0[p, c] * (64 - w) + ee1[p, c] * w + 32) >> 6) >> 8
            d = v - x[t, c]
            err += chw[c] * d * d
    return err


@jit_inner(inline="always")
def _q8(v):
    """Float -> nearest 0..255 integer."""
    i = int(np.floor(v + 0.5))
    if i < 0:
        return 0
    if i > 255:
        return 255
    return i


@jit_inner(inline="always")
def _cq(v, cq, cquant):
    return cquant[cq, _q8(v)]


@jit_inner
def _ep_err(chw, e0, e1, p, a0, a1, q, nc):
    """Weighted squared distance of endpoints (a0[q], a1[q]) from (e0[p], e1[p])."""
    s = 0.0
    for c in range(nc):
        u = a0[q, c] - e0[p, c]
        v = a1[q, c] - e1[p, c]
        s += chw[c] * (u * u + v * v)
    return s


@jit_inner
def _decode_direct(vals, off, cq, cunq, alpha, d0, d1, p):
    """The decoder's CEM 8/12 on vals[off:]: swap and blue-contract when the
    sum says so; endpoints into d0[p], d1[p]."""
    r0 = cunq[cq, vals[off]]
    r1 = cunq[cq, vals[off + 1]]
    g0 = cunq[cq, vals[off + 2]]
    g1 = cunq[cq, vals[off + 3]]
    b0 = cunq[cq, vals[off + 4]]
    b1 = cunq[cq, vals[off + 5]]
    a0 = cunq[cq, vals[off + 6]] if alpha else 255
    a1 = cunq[cq, vals[off + 7]] if alpha else 255
    if r1 + g1 + b1 >= r0 + g0 + b0:
        d0[p, 0] = r0
        d0[p, 1] = g0
        d0[p, 2] = b0
        d0[p, 3] = a0
        d1[p, 0] = r1
        d1[p, 1] = g1
        d1[p, 2] = b1
        d1[p, 3] = a1
    else:
        d0[p, 0] = (r1 + b1) >> 1
        d0[p, 1] = (g1 + b1) >> 1
        d0[p, 2] = b1
        d0[p, 3] = a1
        d1[p, 0] = (r0 + b0) >> 1
        d1[p, 1] = (g0 + b0) >> 1
        d1[p, 2] = b0
        d1[p, 3] = a0


@jit_inner
def _quant_endpoints(cem, e0, e1, p, cq, chw, cunq, cquant, vals, off, d0, d1, alt, altd):
    """Quantise partition p's float endpoints e0[p], e1[p] for its CEM: ISE
    values into vals[off:], decoded 8-bit endpoints into d0[p], d1[p] (what
    the decoder computes). alt (8,) and altd (2, 4) are scratch. Returns the
    number of values written."""
    if cem == 0 or cem == 4:
        wl = max(chw[0] + chw[1] + chw[2], 1e-9)
        l0 = (e0[p, 0] * chw[0] + e0[p, 1] * chw[1] + e0[p, 2] * chw[2]) / wl
        l1 = (e1[p, 0] * chw[0] + e1[p, 1] * chw[1] + e1[p, 2] * chw[2]) / wl
        vals[off] = _cq(l0, cq, cquant)
        vals[off + 1] = _cq(l1, cq, cquant)
        a = cunq[cq, vals[off]]
        b = cunq[cq, vals[off + 1]]
        for c in range(3):
            d0[p, c] = a
            d1[p, c] = b
        if cem == 0:
            d0[p, 3] = 255
            d1[p, 3] = 255
            return 2
        vals[off + 2] = _cq(e0[p, 3], cq, cquant)
        vals[off + 3] = _cq(e1[p, 3], cq, cquant)
        d0[p, 3] = cunq[cq, vals[off + 2]]
        d1[p, 3] = cunq[cq, vals[off + 3]]
        return 4
    if cem == 6 or cem == 10:
        for c in range(3):
            vals[off + c] = _cq(e1[p, c], cq, cquant)
            d1[p, c] = cunq[cq, vals[off + c]]
        num = 0.0
        den = 0.0
        for c in range(3):
            num += chw[c] * e0[p, c] * d1[p, c]
            den += chw[c] * d1[p, c] * d1[p, c]
        sv = 256.0 * num / den if den > 0 else 255.0
        # the nearest scale code and its neighbours a quarter-step away
        best = -1.0
        bcode = 0
        for k in range(3):
            cand = _cq(sv + (k - 1) * 4.0, cq, cquant)
            su = cunq[cq, cand]
            err = 0.0
            for c in range(3):
                dd = ((d1[p, c] * su) >> 8) - e0[p, c]
                err += chw[c] * dd * dd
            if best < 0 or err < best:
                best = err
                bcode = cand
        vals[off + 3] = bcode
        su = cunq[cq, bcode]
        for c in range(3):
            d0[p, c] = (d1[p, c] * su) >> 8
        if cem == 6:
            d0[p, 3] = 255
            d1[p, 3] = 255
            return 4
        vals[off + 4] = _cq(e0[p, 3], cq, cquant)
        vals[off + 5] = _cq(e1[p, 3], cq, cquant)
        d0[p, 3] = cunq[cq, vals[off + 4]]
        d1[p, 3] = cunq[cq, vals[off + 5]]
        return 6
    if cem == 9 or cem == 13:
        # base + signed 6-bit offset: v(2c) holds the base's low 7 bits, v(2c+1)
        # its top bit and the offset (bit_transfer_signed in reverse)
        nc = 4 if cem == 13 else 3
        for c in range(nc):
            b = _q8(e0[p, c])
            o = min(max(_q8(e1[p, c]) - b, -32), 31)
            vals[off + 2 * c] = cquant[cq, (b & 0x7F) << 1]
            vals[off + 2 * c + 1] = cquant[cq, (b & 0x80) | ((o & 0x3F) << 1)]
        for k in range(2 * nc):
            alt[k] = cunq[cq, vals[off + k]]
        decode_endpoints(cem, alt, d0[p], d1[p])
        return 2 * nc
    # RGB / RGBA direct (8 / 12): plain order, or swapped with blue-contraction
    alpha = cem == 12
    n = 8 if alpha else 6
    nc = 4 if alpha else 3
    for c in range(nc):
        vals[off + 2 * c] = _cq(e0[p, c], cq, cquant)
        vals[off + 2 * c + 1] = _cq(e1[p, c], cq, cquant)
    _decode_direct(vals, off, cq, cunq, alpha, d0, d1, p)
    err_plain = _ep_err(chw, e0, e1, p, d0, d1, p, nc)
    # blue-contracted: odd values hold e0 and even values e1, red and green
    # stored as 2x - b so the decoder's (x + b) >> 1 gives them back at
    # twice the precision
    for c in range(2):
        r0 = 2.0 * e0[p, c] - e0[p, 2]
        r1 = 2.0 * e1[p, c] - e1[p, 2]
        if r0 < -0.5 or r0 > 255.5 or r1 < -0.5 or r1 > 255.5:
            return n
    for c in range(nc):
        if c < 2:
            alt[2 * c] = _cq(2.0 * e1[p, c] - e1[p, 2], cq, cquant)
            alt[2 * c + 1] = _cq(2.0 * e0[p, c] - e0[p, 2], cq, cquant)
        else:
            alt[2 * c] = _cq(e1[p, c], cq, cquant)
            alt[2 * c + 1] = _cq(e0[p, c], cq, cquant)
    s0 = cunq[cq, alt[0]] + cunq[cq, alt[2]] + cunq[cq, alt[4]]
    s1 = cunq[cq, alt[1]] + cunq[cq, alt[3]] + cunq[cq, alt[5]]
    if s1 >= s0:
        return n  # would decode unswapped: not a blue-contracted pair
    # np.int64(0), not 0: a literal argument makes numba compile the callee
    # again for that value
    zero = np.int64(0)
    _decode_direct(alt, zero, cq, cunq, alpha, altd, altd[1:], zero)
    if _ep_err(chw, e0, e1, p, altd, altd[1:], zero, nc) < err_plain:
        for k in range(n):
            vals[off + k] = alt[k]
        for c in range(4):
            d0[p, c] = altd[0, c]
            d1[p, c] = altd[1, c]
    return n


# ---------------------------------------------------------------------------
# fitting


@jit_inner(inline="always")
def _principal_axis(cov, a, b):
    """Unit principal axis of a 4x4 covariance into a (zero when there is no
    variance): four steps of power iteration from the row of the largest
    variance, on the covariance divided by its trace (its largest eigenvalue
    is then between 1/4 and 1, so the steps need no normalising). b (4,) is
    scratch."""
    best = 0
    for c in range(1, 4):
        if cov[c, c] > cov[best, best]:
            best = c
    tr = cov[0, 0] + cov[1, 1] + cov[2, 2] + cov[3, 3]
    if tr <= 1e-12:
        for c in range(4):
            a[c] = 0.0
        return
    f = 1.0 / tr
    for c in range(4):
        a[c] = cov[best, c] * f
    for _ in range(2):
        for c in range(4):
            b[c] = (cov[c, 0] * a[0] + cov[c, 1] * a[1] + cov[c, 2] * a[2] + cov[c, 3] * a[3]) * f
        for c in range(4):
            a[c] = (cov[c, 0] * b[0] + cov[c, 1] * b[1] + cov[c, 2] * b[2] + cov[c, 3] * b[3]) * f
    nrm = np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2] + a[3] * a[3])
    if nrm <= 1e-30:
        for c in range(4):
            a[c] = 0.0
    else:
        for c in range(4):
            a[c] /= nrm


@jit_inner
def _texel_moments(x, chw, nt, prod, tot):
    """Per texel the 15 moments a line fit needs (1, the four weighted
    components, their ten products) into prod (nt, 16), their sums into tot:
    partitionings are then ranked by adding rows."""
    for k in range(16):
        tot[k] = 0.0
    s0 = np.sqrt(chw[0])
    s1 = np.sqrt(chw[1])
    s2 = np.sqrt(chw[2])
    s3 = np.sqrt(chw[3])
    for t in range(nt):
        v0 = x[t, 0] * s0
        v1 = x[t, 1] * s1
        v2 = x[t, 2] * s2
        v3 = x[t, 3] * s3
        prod[t, 0] = 1.0
        prod[t, 1] = v0
        prod[t, 2] = v1
        prod[t, 3] = v2
        prod[t, 4] = v3
        prod[t, 5] = v0 * v0
        prod[t, 6] = v0 * v1
        prod[t, 7] = v0 * v2
        prod[t, 8] = v0 * v3
        prod[t, 9] = v1 * v1
        prod[t, 10] = v1 * v2
        prod[t, 11] = v1 * v3
        prod[t, 12] = v2 * v2
        prod[t, 13] = v2 * v3
        prod[t, 14] = v3 * v3
        prod[t, 15] = 0.0
        for k in range(16):
            tot[k] += prod[t, k]


@jit_inner(inline="always")
def _partition_moments(labels, nparts, nt, prod, tot, mom):
    """Per partition the sums of the texels' moments (_texel_moments) into
    mom (4, 16): the last partition's are the total less the others'."""
    last = nparts - 1
    for p in range(last):
        for k in range(16):
            mom[p, k] = 0.0
    for t in range(nt):
        p = labels[t]
        if p != last:
            for k in range(16):
                mom[p, k] += prod[t, k]
    for k in range(16):
        acc = tot[k]
        for p in range(last):
            acc -= mom[p, k]
        mom[last, k] = acc


@jit_inner(inline="always")
def _moment_cov(mo, skip, m, cov):
    """Mean m (4,) and covariance cov (4, 4) of weighted texels from their
    moment sums mo (16,) (_texel_moments); component skip (-1: none) left out
    as zero, and so is a component whose spread is only rounding. Returns the
    texel count."""
    n = mo[0]
    k = 5
    for c in range(4):
        m[c] = mo[1 + c] / n if n > 0 else 0.0
        for j in range(c, 4):
            cov[c, j] = mo[k] - mo[1 + c] * mo[1 + j] / n if n > 0 else 0.0
            cov[j, c] = cov[c, j]
            k += 1
    for c in range(4):
        if c == skip or cov[c, c] <= 1e-6:
            for j in range(4):
                cov[c, j] = 0.0
                cov[j, c] = 0.0
    if skip >= 0:
        m[skip] = 0.0
    return n


@jit_inner
def _line_resid(labels, nparts, nt, prod, tot, mom, fsc):
    """Weighted squared distance of the texels from their partition's
    principal line (what _fit returns), from the texels' moments
    (_texel_moments). mom (4, 16) and fsc (8, 4) are scratch."""
    _partition_moments(labels, nparts, nt, prod, tot, mom)
    m = fsc[1]
    a = fsc[2]
    b = fsc[3]
    cov = fsc[4:8]
    resid = 0.0
    for p in range(nparts):
        if _moment_cov(mom[p], -1, m, cov) < 0.5:
            continue
        _principal_axis(cov, a, b)
        for c in range(4):
            resid += cov[c, c]
            for j in range(4):
                resid -= a[c] * cov[c, j] * a[j]
    return resid


@jit_inner
def _fit(x, chw, labels, nparts, nt, dual, ccs, prod, tot, mom, e0f, e1f, w1, w2, s1, s2, fsc):
    """Principal-axis fit per partition: ideal endpoints (float, 0..255) and
    ideal weights (0..1) with their importance (squared weighted endpoint
    distance, the error per unit of weight error). With two planes, component
    ccs is fitted on its own and the axis ignores it. Returns the weighted
    squared distance of the texels from their partition's line. Means and
    covariances come from the texels' moments (_texel_moments); fsc (24, 4)
    is scratch."""
    sq = fsc[0]
    b = fsc[3]
    cov = fsc[4:8]
    mp = fsc[8:12]  # per partition: mean, axis, [lo, hi, lo2, hi2]
    ap = fsc[12:16]
    rng = fsc[16:20]
    for c in range(4):
        sq[c] = np.sqrt(chw[c])
    if dual:
        sq[ccs] = 0.0
    skip = ccs if dual else -1
    _partition_moments(labels, nparts, nt, prod, tot, mom)
    resid = 0.0
    for p in range(nparts):
        _moment_cov(mom[p], skip, mp[p], cov)
        a = ap[p]
        _principal_axis(cov, a, b)
        # what the line leaves unexplained: trace minus the variance along it
        for c in range(4):
            resid += cov[c, c]
            for k in range(4):
                resid -= a[c] * cov[c, k] * a[k]
        # orient so that the second endpoint is the brighter one (the plain
        # CEM 8/12 order needs sum(e1) >= sum(e0))
        rgb = 0.0
        for c in range(3):
            if sq[c] > 0:
                rgb += a[c] / sq[c]
        if rgb < 0:
            for c in range(4):
                a[c] = -a[c]
        rng[p, 0] = 1e18
        rng[p, 1] = -1e18
        rng[p, 2] = 1e9
        rng[p, 3] = -1e9
    # one pass: each texel's position along its partition's axis
    for t in range(nt):
        p = labels[t]
        pr = 0.0
        for c in range(4):
            pr += (x[t, c] * sq[c] - mp[p, c]) * ap[p, c]
        w1[t] = pr
        rng[p, 0] = min(rng[p, 0], pr)
        rng[p, 1] = max(rng[p, 1], pr)
        if dual:
            v = x[t, ccs]
            rng[p, 2] = min(rng[p, 2], v)
            rng[p, 3] = max(rng[p, 3], v)
    for p in range(nparts):
        if mom[p, 0] < 0.5:
            for c in range(4):
                e0f[p, c] = 0.0
                e1f[p, c] = 0.0
            continue
        tlo = rng[p, 0]
        thi = rng[p, 1]
        for c in range(4):
            if sq[c] > 0:
                e0f[p, c] = min(max((mp[p, c] + tlo * ap[p, c]) / sq[c], 0.0), 255.0)
                e1f[p, c] = min(max((mp[p, c] + thi * ap[p, c]) / sq[c], 0.0), 255.0)
            else:
                e0f[p, c] = 0.0
                e1f[p, c] = 0.0
        if dual:
            e0f[p, ccs] = rng[p, 2]
            e1f[p, ccs] = rng[p, 3]
        # channels without weight still decode: give them their mean
        for c in range(4):
            if sq[c] == 0 and not (dual and c == ccs):
                mc = 0.0
                for t in range(nt):
                    if labels[t] == p:
                        mc += x[t, c]
                e0f[p, c] = mc / mom[p, 0]
                e1f[p, c] = mc / mom[p, 0]
    for t in range(nt):
        p = labels[t]
        span = rng[p, 1] - rng[p, 0]
        w1[t] = (w1[t] - rng[p, 0]) / span if span > 1e-9 else 0.0
        s1[t] = span * span
        if dual:
            lo2 = rng[p, 2]
            d2 = rng[p, 3] - lo2
            w2[t] = (x[t, ccs] - lo2) / d2 if d2 > 1e-9 else 0.0
            s2[t] = chw[ccs] * d2 * d2
    return resid


@jit_inner
def _refit(x, labels, nparts, nt, wt1, wt2, dual, ccs, e0f, e1f, acc):
    """Least-squares endpoints per partition and component for fixed weights,
    from one pass of sums. acc (4, 4, 5) is scratch: per partition and
    component the sums of (1-u)^2, u(1-u), u^2, (1-u)x and ux."""
    for p in range(nparts):
        for c in range(4):
            for k in range(5):
                acc[p, c, k] = 0.0
    for t in range(nt):
        p = labels[t]
        u = wt1[t] / 64.0
        v = 1.0 - u
        for c in range(4):
            if dual and c == ccs:
                u2 = wt2[t] / 64.0
                v2 = 1.0 - u2
                acc[p, c, 0] += v2 * v2
                acc[p, c, 1] += u2 * v2
                acc[p, c, 2] += u2 * u2
                acc[p, c, 3] += v2 * x[t, c]
                acc[p, c, 4] += u2 * x[t, c]
            else:
                acc[p, c, 0] += v * v
                acc[p, c, 1] += u * v
                acc[p, c, 2] += u * u
                acc[p, c, 3] += v * x[t, c]
                acc[p, c, 4] += u * x[t, c]
    for p in range(nparts):
        for c in range(4):
            aa = acc[p, c, 0]
            ab = acc[p, c, 1]
            bb = acc[p, c, 2]
            xa = acc[p, c, 3]
            xb = acc[p, c, 4]
            n = aa + 2.0 * ab + bb  # (1-u) + u = 1 per texel
            if n < 0.5:
                continue
            det = aa * bb - ab * ab
            if det > 1e-6 * (aa + bb) * (aa + bb):
                e0 = (xa * bb - xb * ab) / det
                e1 = (xb * aa - xa * ab) / det
            else:
                e0 = (xa + xb) / n
                e1 = e0
            e0f[p, c] = min(max(e0, 0.0), 255.0)
            e1f[p, c] = min(max(e1, 0.0), 255.0)


@jit_inner
def _weights_from(x, chw, labels, nt, d0, d1, dual, ccs, w1, w2, s1, s2):
    """Ideal weights for decoded endpoints: projection onto each partition's
    decoded segment."""
    for t in range(nt):
        p = labels[t]
        num = 0.0
        den = 0.0
        for c in range(4):
            if dual and c == ccs:
                continue
            d = d1[p, c] - d0[p, c]
            num += chw[c] * (x[t, c] - d0[p, c]) * d
            den += chw[c] * d * d
        w1[t] = min(max(num / den, 0.0), 1.0) if den > 0 else 0.0
        s1[t] = den
        if dual:
            d = d1[p, ccs] - d0[p, ccs]
            w2[t] = min(max((x[t, ccs] - d0[p, ccs]) / d, 0.0), 1.0) if d != 0 else 0.0
            s2[t] = chw[ccs] * d * d


@jit_inner
def _decimate(gidx, gwt, nt, ng, w, s, iters, out, num, den):
    """Grid weights (0..1) whose infill best matches ideal texel weights w,
    weighted by importance s: the transpose of the infill as a start, then
    Jacobi steps on the residual."""
    if ng == nt:
        # a full grid's infill is the identity (tables() checks)
        for j in range(ng):
            out[j] = w[j]
        return
    for j in range(ng):
        num[j] = 0.0
        den[j] = 0.0
    for t in range(nt):
        st = s[t] + 1e-3
        for k in range(4):
            f = gwt[t, k] * st
            num[gidx[t, k]] += f * w[t]
            den[gidx[t, k]] += f
    for j in range(ng):
        out[j] = num[j] / den[j] if den[j] > 0 else 0.5
    for _ in range(iters):
        for j in range(ng):
            num[j] = 0.0
        for t in range(nt):
            f = 0.0
            for k in range(4):
                f += gwt[t, k] * out[gidx[t, k]]
            r = (w[t] - f / 16.0) * (s[t] + 1e-3)
            for k in range(4):
                num[gidx[t, k]] += gwt[t, k] * r
        for j in range(ng):
            if den[j] > 0:
                out[j] = min(max(out[j] + num[j] / den[j], 0.0), 1.0)


@jit_inner
def _decim_err(gidx, gwt, nt, g, w, s):
    """Importance-weighted squared error of a float grid's infill."""
    e = 0.0
    for t in range(nt):
        f = 0.0
        for k in range(4):
            f += gwt[t, k] * g[gidx[t, k]]
        d = f / 16.0 - w[t]
        e += s[t] * d * d
    return e


@jit_inner
def _sep_errs(w, s, bw, bh, ux, uoff, qyp, errs, sc, used):
    """errs[gw, gh] += the squared error of the separable least-squares fit of
    each grid the modes tried use (used[gw, gh]) to the ideal weights (bh rows
    of bw), each scaled by the root of its importance; clamping and the
    infill's rounding left out: an estimate for ranking grids. The fit's error
    is what the projection onto the grid's row and column spaces leaves, so
    one Gram matrix per width serves every height. sc (bw*bh + bh*ncol +
    bh*bh) is scratch. Inner loops run over independent outputs, so they need
    no reordered sums to vectorise."""
    nt = bw * bh
    ncol = ux.shape[1]
    v = sc[:nt]
    m = sc[nt:nt + bh * ncol]  # rows in every width's basis: (bh, ncol)
    cm = sc[nt + bh * ncol:nt + bh * ncol + bh * bh]
    tot = 0.0
    for t in range(nt):
        v[t] = w[t] * np.sqrt(s[t])
        tot += v[t] * v[t]
    for y in range(bh):
        for j in range(ncol):
            m[ncol * y + j] = 0.0
        for x in range(bw):
            a = v[y * bw + x]
            for j in range(ncol):
                m[ncol * y + j] += a * ux[x, j]
    for gw in range(2, bw + 1):
        # the heights used at this width (a full grid, gw * gh == nt, loses nothing)
        wanted = 0
        for gh in range(2, bh + 1):
            if used[gw, gh] and gw * gh < nt:
                wanted += 1
        if wanted == 0:
            continue
        c0 = uoff[gw]
        k = 0
        for y in range(bh):
            for y2 in range(y, bh):
                acc = 0.0
                for j in range(c0, c0 + gw):
                    acc += m[ncol * y + j] * m[ncol * y2 + j]
                cm[k] = acc
                k += 1
        npair = bh * (bh + 1) // 2
        for gh in range(2, bh + 1):
            if not used[gw, gh] or gw * gh == nt:
                continue
            # two sums, so that the additions overlap
            acc0 = 0.0
            acc1 = 0.0
            for k in range(0, npair - 1, 2):
                acc0 += cm[k] * qyp[gh, k]
                acc1 += cm[k + 1] * qyp[gh, k + 1]
            if npair & 1:
                acc0 += cm[npair - 1] * qyp[gh, npair - 1]
            errs[gw, gh] += tot - acc0 - acc1


@jit_inner
def _quantise_grid(g, ng, wq, wunq, wquant, codes, stride, off):
    for j in range(ng):
        v = int(np.floor(g[j] * 64.0 + 0.5))
        v = min(max(v, 0), 64)
        codes[j * stride + off] = wquant[wq, v]


@jit_inner
def _grid_quant_err(g, ng, wq, wunq, wquant):
    """Squared error (weights 0..1) of quantising grid weights g to range wq,
    rounded as _quantise_grid rounds them."""
    e = 0.0
    for j in range(ng):
        u = g[j] * 64.0
        v = min(max(int(np.floor(u + 0.5)), 0), 64)
        d = (wunq[wq, wquant[wq, v]] - u) / 64.0
        e += d * d
    return e


@jit_inner
def _infill(gidx, gwt, nt, ng, codes, stride, off, wq, wunq, wt, acc):
    """Texel weights 0..64 exactly as decoded from grid codes; acc gets the
    sums before rounding."""
    if ng == nt:  # a full grid: each texel its own weight (tables() checks)
        for t in range(nt):
            u = wunq[wq, codes[t * stride + off]]
            acc[t] = 16 * u
            wt[t] = u
        return
    for t in range(nt):
        a = 0
        for k in range(4):
            a += gwt[t, k] * wunq[wq, codes[gidx[t, k] * stride + off]]
        acc[t] = a
        wt[t] = (a + 8) >> 4


@jit_inner
def _realign(x, chw, labels, ng, wq, wunq, worder, wrank, nlev, tex, tw, tn, codes, stride,
             plane, acc, wt, ee0, ee1, dual, ccs, passes, qa, qb):
    """Move grid weights of one plane a step up or down in value wherever the
    error of the texels they reach drops. acc holds each texel's infill sum
    before rounding; codes, acc and wt are updated. The error of a texel is
    taken as a quadratic in its weight (the decoder's interpolation without
    its rounding, in qa, qb): a move is a guess the caller's exact decode
    then scores."""
    nt = acc.shape[0]
    for t in range(nt):
        p = labels[t]
        a2 = 0.0
        a1 = 0.0
        for c in range(4):
            if dual and ((c == ccs) != (plane == 1)):
                continue
            # decoded value ~ ee0 / 256 - 1/2 + (ee1 - ee0) w / 2^14 (floor's mean)
            d = (ee1[p, c] - ee0[p, c]) / 16384.0
            o = ee0[p, c] / 256.0 - 0.5 - x[t, c]
            a2 += chw[c] * d * d
            a1 += 2.0 * chw[c] * o * d
        qa[t] = a2
        qb[t] = a1
    if ng == nt:
        # a full grid: each weight reaches its own texel alone, at 16/16
        # (tables() checks), so a step moves that texel's weight by the step
        for _ in range(passes):
            moved = 0
            for t in range(nt):
                cj = codes[t * stride + plane]
                r = wrank[wq, cj]
                w = wt[t]
                r2 = r - 1 if 2.0 * qa[t] * w + qb[t] > 0 else r + 1
                if 0 <= r2 < nlev:
                    c2 = worder[wq, r2]
                    w2 = wunq[wq, c2]
                    if (qa[t] * w2 + qb[t]) * w2 < (qa[t] * w + qb[t]) * w:
                        acc[t] = 16 * w2
                        wt[t] = w2
                        codes[t * stride + plane] = c2
                        moved += 1
            if moved == 0:
                break
        return
    for _ in range(passes):
        moved = 0
        for j in range(ng):
            cj = codes[j * stride + plane]
            r = wrank[wq, cj]
            u = wunq[wq, cj]
            cur = 0.0
            slope = 0.0
            for k in range(tn[j]):
                t = tex[j, k]
                w = wt[t]
                cur += (qa[t] * w + qb[t]) * w
                slope += (2.0 * qa[t] * w + qb[t]) * tw[j, k]
            best = cur
            bcode = cj
            # only the step the error's slope points to
            r2 = r - 1 if slope > 0 else r + 1
            if 0 <= r2 < nlev:
                c2 = worder[wq, r2]
                du = wunq[wq, c2] - u
                e = 0.0
                for k in range(tn[j]):
                    t = tex[j, k]
                    w = (acc[t] + tw[j, k] * du + 8) >> 4
                    e += (qa[t] * w + qb[t]) * w
                if e < best:
                    best = e
                    bcode = c2
            if bcode != cj:
                du = wunq[wq, bcode] - u
                for k in range(tn[j]):
                    t = tex[j, k]
                    acc[t] += tw[j, k] * du
                    wt[t] = (acc[t] + 8) >> 4
                codes[j * stride + plane] = bcode
                moved += 1
        if moved == 0:
            break


# ---------------------------------------------------------------------------
# partitioning


@jit_inner
def _kmeans(x, chw, nt, k, iters, cl, cen, ksc):
    """A few Lloyd iterations from farthest-point seeds; labels into cl. ksc
    (6, 4) is scratch."""
    m = ksc[0]
    for ii in range(m.shape[0]):
        m[ii] = 0.0
    for t in range(nt):
        for c in range(4):
            m[c] += x[t, c]
    for c in range(4):
        m[c] /= nt
    far = 0
    bd = -1.0
    for t in range(nt):
        d = 0.0
        for c in range(4):
            d += chw[c] * (x[t, c] - m[c]) ** 2
        if d > bd:
            bd = d
            far = t
    for c in range(4):
        cen[0, c] = x[far, c]
    for j in range(1, k):
        far = 0
        bd = -1.0
        for t in range(nt):
            dm = 1e30
            for i in range(j):
                d = 0.0
                for c in range(4):
                    d += chw[c] * (x[t, c] - cen[i, c]) ** 2
                dm = min(dm, d)
            if dm > bd:
                bd = dm
                far = t
        for c in range(4):
            cen[j, c] = x[far, c]
    cnt = ksc[1]
    acc = ksc[2:6]
    for it in range(iters + 1):
        for t in range(nt):
            bi = 0
            bd = 1e30
            for i in range(k):
                d = 0.0
                for c in range(4):
                    d += chw[c] * (x[t, c] - cen[i, c]) ** 2
                if d < bd:
                    bd = d
                    bi = i
            cl[t] = bi
        if it == iters:
            break
        for ii in range(cnt.shape[0]):
            cnt[ii] = 0.0
        for ii in range(acc.shape[0]):
            for jj in range(acc.shape[1]):
                acc[ii, jj] = 0.0
        for t in range(nt):
            cnt[cl[t]] += 1
            for c in range(4):
                acc[cl[t], c] += x[t, c]
        for i in range(k):
            if cnt[i] > 0:
                for c in range(4):
                    cen[i, c] = acc[i, c] / cnt[i]


@jit_inner(inline="always")
def _popcount(v):
    """Set bits of an int64 (the bit-sliced sum LLVM turns into one popcnt)."""
    v = v - ((v >> 1) & 0x5555555555555555)
    v = (v & 0x3333333333333333) + ((v >> 2) & 0x3333333333333333)
    v = (v + (v >> 4)) & 0x0F0F0F0F0F0F0F0F
    return (v * 0x0101010101010101) >> 56


@jit_inner
def _agreement(pmask, pc, pid, nparts, nw, cmask, perms, nperm, cnt):
    """Texels on which pattern pid and the clusters agree, best renaming."""
    for a in range(nparts):
        for b in range(nparts):
            c = 0
            for w in range(nw):
                c += _popcount(pmask[pc, pid, a, w] & cmask[b, w])
            cnt[a, b] = c
    agree = 0
    for q in range(nperm[pc]):
        a = 0
        for j in range(nparts):
            a += cnt[j, perms[pc, q, j]]
        agree = max(agree, a)
    return agree


@jit_inner
def _rank_partitions(x, chw, nt, nparts, pmask, p2mask, plist, pcount, perms, nperm, kiters,
                     ncand, out, cl, cen, ksc, cmask, cnt, score, dist):
    """The ncand partition indices whose split disagrees least with a k-means
    clustering (best renaming of partitions), counted on 48-bit texel masks.
    Returns how many were found. ksc, cmask (4, 3), cnt (4, 4), score
    (ncand,) and dist (1024,) are scratch."""
    _kmeans(x, chw, nt, nparts, kiters, cl, cen, ksc)
    pc = nparts - 2
    nw = (nt + 47) // 48
    for ii in range(cmask.shape[0]):
        for jj in range(cmask.shape[1]):
            cmask[ii, jj] = 0
    for t in range(nt):
        cmask[cl[t], t // 48] |= np.int64(1) << (t % 48)
    npat = pcount[pc]
    if nparts == 2:
        # two partitions: the mismatch is one popcount of the XOR, either naming
        for i in range(npat):
            d = 0
            for w in range(nw):
                d += _popcount(p2mask[i, w] ^ cmask[0, w])
            dist[i] = min(d, nt - d)
    else:
        for i in range(npat):
            dist[i] = nt - _agreement(pmask, pc, plist[pc, i], nparts, nw, cmask, perms, nperm,
                                      cnt)
    for ii in range(score.shape[0]):
        score[ii] = 1 << 30
    found = 0
    for i in range(npat):
        sc = dist[i]
        if found < ncand or sc < score[found - 1]:
            # insertion into the sorted short list
            pos = found if found < ncand else ncand - 1
            while pos > 0 and score[pos - 1] > sc:
                if pos < ncand:
                    score[pos] = score[pos - 1]
                    out[pos] = out[pos - 1]
                pos -= 1
            score[pos] = sc
            out[pos] = plist[pc, i]
            if found < ncand:
                found += 1
    return found


# ---------------------------------------------------------------------------
# one (mode, CEM family) encoded for real


@jit_inner
def _encode_mode(x, chw, srgb, labels, nparts, pindex, nt, mode, fam, pgrey, popaque,
                 ccs, gc1, gc2, w1, w2, s1, s2, refine, decim_iters, realign, tab, ws, row):
    """Encode with one block mode and CEM family, starting from the grid
    weights decimated into gc1[g], gc2[g]; the best round goes into row.
    Returns its error (inf when the combination is illegal)."""
    (g_dims, g_idx, g_wt, g_tex, g_tw, g_tn, modes, cr_tab, cunq, cquant, wunq, wquant, worder,
     wrank, levels) = tab
    g = modes[mode, 0]
    wq = modes[mode, 1]
    dual = modes[mode, 2]
    wbits = modes[mode, 3]
    gw = g_dims[g, 0]
    gh = g_dims[g, 1]
    ng = gw * gh
    cems = ws.cems
    nv, same = _choose_cems(fam, nparts, pgrey, popaque, cems)
    if nv > 18:
        return np.inf
    cq = cr_tab[max(128 - config_bits(nparts, same, dual) - wbits, 0), nv]
    if cq < 0:
        return np.inf
    gidx = g_idx[g]
    gwt = g_wt[g]
    stride = 2 if dual else 1
    gr1 = ws.gr1
    gr2 = ws.gr2
    for j in range(ng):
        gr1[j] = gc1[g, j]
        if dual:
            gr2[j] = gc2[g, j]
    best = np.inf
    # planes as np.int64, not literals: numba compiles a callee once per
    # literal value it is passed
    plane0 = np.int64(0)
    plane1 = np.int64(1)
    for rnd in range(refine + 1):
        _quantise_grid(gr1, ng, wq, wunq, wquant, ws.codes, stride, plane0)
        _infill(gidx, gwt, nt, ng, ws.codes, stride, plane0, wq, wunq, ws.wt1, ws.acc1)
        if dual:
            _quantise_grid(gr2, ng, wq, wunq, wquant, ws.codes, stride, plane1)
            _infill(gidx, gwt, nt, ng, ws.codes, stride, plane1, wq, wunq, ws.wt2, ws.acc2)
        _refit(x, labels, nparts, nt, ws.wt1, ws.wt2, dual, ccs, ws.e0, ws.e1, ws.racc)
        nvals = np.int64(0)  # a literal 0 is typed first and compiled for too
        for p in range(nparts):
            nvals += _quant_endpoints(cems[p], ws.e0, ws.e1, p, cq, chw, cunq, cquant,
                                      ws.vals, nvals, ws.d0, ws.d1, ws.sc, ws.altd)
        for p in range(nparts):
            for c in range(4):
                ws.ee0[p, c] = _expand(ws.d0[p, c], srgb)
                ws.ee1[p, c] = _expand(ws.d1[p, c], srgb)
        if realign > 0:
            _realign(x, chw, labels, ng, wq, wunq, worder, wrank, levels[wq], g_tex[g],
                     g_tw[g], g_tn[g], ws.codes, stride, plane0, ws.acc1, ws.wt1, ws.ee0, ws.ee1,
                     dual, ccs, realign, ws.qa, ws.qb)
            if dual:
                _realign(x, chw, labels, ng, wq, wunq, worder, wrank, levels[wq], g_tex[g],
                         g_tw[g], g_tn[g], ws.codes, stride, plane1, ws.acc2, ws.wt2, ws.ee0,
                         ws.ee1, dual, ccs, realign, ws.qa, ws.qb)
        err = _decode_err(x, chw, labels, nt, ws.wt1, ws.wt2, dual, ccs, ws.ee0, ws.ee1)
        if err < best:
            best = err
            for ii in range(row.shape[0]):
                row[ii] = 0
            row[S_KIND] = KIND_NORMAL
            row[S_GRID_W] = gw
            row[S_GRID_H] = gh
            row[S_WQUANT] = wq
            row[S_DUAL] = dual
            row[S_CCS] = ccs if dual else 0
            row[S_PARTS] = nparts
            row[S_PINDEX] = pindex
            for p in range(nparts):
                row[S_CEM + p] = cems[p]
            row[S_CQUANT] = cq
            for k in range(nvals):
                row[S_ENDPOINTS + k] = ws.vals[k]
            for k in range(ng * stride):
                row[S_WEIGHTS + k] = ws.codes[k]
        if rnd == refine or err == 0:
            break
        # re-derive weights from what the decoder makes of these endpoints
        _weights_from(x, chw, labels, nt, ws.d0, ws.d1, dual, ccs, ws.u1, ws.u2, ws.v1, ws.v2)
        _decimate(gidx, gwt, nt, ng, ws.u1, ws.v1, decim_iters, gr1, ws.num, ws.den)
        if dual:
            _decimate(gidx, gwt, nt, ng, ws.u2, ws.v2, decim_iters, gr2, ws.num, ws.den)
    return best


Work = namedtuple(
    "Work", "cems gr1 gr2 codes wt1 wt2 acc1 acc2 e0 e1 vals d0 d1 ee0 ee1 sc altd u1 u2 v1 v2 num den qa qb "
    "racc")


@jit_inner(inline="always")
def _select_modes(dual, nfam, ncand, cscale, ssum1, ssum2, smiss, lmiss, offset_ok, wq_scale, skip,
                  tab, mlist, mcount, mbits, gdone, gerr, gc1, gc2, wq_err, fam_nv, fam_bits, cqe_tab,
                  cqe_off, mest, fest, c_est, c_mode, c_fam):
    """The ncand best (block mode, CEM family) pairs of a fit by their
    estimated error, best first, in c_est, c_mode and c_fam; returns how many.
    A mode's estimate is its grid's error plus the weight quantisation error
    of its range: the decimated grid's own when it is known (gdone 2: a
    two-colour block loses nothing to two levels), else the range's average
    (scaled by wq_scale); a family adds the error of the colour range the
    mode's leftover bits allow (cscale times a table's entry) and what the
    family itself misses (smiss for base+scale, lmiss for luminance). Returns
    0 at once when every mode's estimate is above `skip` (the caller would skip
    them all: families only add to it)."""
    g_dims, _, _, _, _, _, modes, cr_tab, _, _, wunq, wquant, _, _, _ = tab
    nml = mcount[dual]
    ssum = ssum1 + ssum2
    for mi in range(nml):
        m = mlist[dual, mi]
        g = modes[m, 0]
        wq = modes[m, 1]
        if gdone[g] == 2:
            ng = g_dims[g, 0] * g_dims[g, 1]
            qe = ssum1 / ng * _grid_quant_err(gc1[g], ng, wq, wunq, wquant)
            if dual:
                qe += ssum2 / ng * _grid_quant_err(gc2[g], ng, wq, wunq, wquant)
            mest[mi] = gerr[g] + qe * wq_scale
        else:
            mest[mi] = gerr[g] + ssum * wq_err[wq] * wq_scale
    low = np.inf
    for mi in range(nml):
        low = min(low, mest[mi])
    if low > skip:
        return 0
    # per family the lookups first, kept apart from the selection so that
    # they vectorise
    nfound = 0
    for fam in range(nfam):
        nv = fam_nv[fam]
        if nv < 0 or (fam == FAM_OFFSET and not offset_ok):
            continue
        bits = fam_bits[fam]
        extra = smiss if fam == FAM_SCALE else (lmiss if fam == FAM_LUMA else 0.0)
        ctab = cqe_off if fam == FAM_OFFSET else cqe_tab
        for mi in range(nml):
            cq = cr_tab[max(bits - mbits[dual, mi], 0), nv]
            fest[mi] = mest[mi] + cscale * ctab[cq + 1] + extra
        for mi in range(nml):
            est = fest[mi]
            if est < np.inf and (nfound < ncand or est < c_est[nfound - 1]):
                pos = nfound if nfound < ncand else ncand - 1
                while pos > 0 and c_est[pos - 1] > est:
                    c_est[pos] = c_est[pos - 1]
                    c_mode[pos] = c_mode[pos - 1]
                    c_fam[pos] = c_fam[pos - 1]
                    pos -= 1
                c_est[pos] = est
                c_mode[pos] = mlist[dual, mi]
                c_fam[pos] = fam
                if nfound < ncand:
                    nfound += 1
    return nfound


@jit_inner
def _dual_channels(tot, opaque, mode, max_corr, out, fsc):
    """Components worth a plane of their own: all that vary (mode 2), or the
    one least correlated with the rest when its correlation with them is below
    max_corr (mode 1), from the block's moment sums tot (_texel_moments; a
    component without weight does not vary there). Returns the count. fsc
    (8, 4) is scratch."""
    cov = fsc[4:8]
    _moment_cov(tot, -1, fsc[0], cov)
    n = 0
    best = -1
    bscore = 2.0
    for c in range(4):
        if cov[c, c] <= 0 or (c == 3 and opaque):
            continue
        if mode == 2:
            out[n] = c
            n += 1
            continue
        worst = 0.0
        for k in range(4):
            if k != c and cov[k, k] > 0:
                r = abs(cov[c, k]) / np.sqrt(cov[c, c] * cov[k, k])
                worst = max(worst, r)
        if worst < bscore:
            bscore = worst
            best = c
    if mode == 1 and best >= 0 and bscore < max_corr:
        out[0] = best
        n = 1
    return n


@jit
def search_kernel(blocks, sym, params, mode_on, chw, srgb, g_dims, g_idx, g_wt, g_tex, g_tw,
                  g_tn, modes, ptab, ux, uoff, qyp,
                  pmask, p2mask, plist, pcount, perms, nperm, cq_err, wq_err, cr_tab, cunq, cquant,
                  wunq, wquant,
                  worder, wrank, levels):
    """blocks uint8 (n, T, 4) -> sym int32 (n, SYM_LEN). mode_on (one per row
    of modes): 0 for block modes the preset does not try."""
    nb = blocks.shape[0]
    nt = blocks.shape[1]
    ngrid = g_dims.shape[0]
    nmodes = modes.shape[0]
    max_parts = params[P_MAX_PARTS]
    part_cands = max(params[P_PART_CANDS], 1)
    dual_mode = params[P_DUAL]
    ncand = max(params[P_MODE_CANDS], 1)
    refine = params[P_REFINE]
    # families tried: direct, then base+scale and base+offset, then luminance
    nfam = 3 if params[P_SCALE_CEMS] else 1
    if params[P_LUMA_CEMS] and nfam == 3:
        nfam = 4
    early = params[P_EARLY_OUT] / 100.0
    decim_iters = params[P_DECIM_ITERS]
    kiters = params[P_KMEANS_ITERS]
    part_full = max(params[P_PART_FULL], 1)
    realign = params[P_REALIGN]
    # the refit and realignment recover much of what coarse weight ranges
    # lose, so their estimate is scaled down
    wq_scale = params[P_WQ_SCALE] / 100.0
    dual_corr = params[P_DUAL_CORR] / 100.0
    sep_rank = params[P_SEP_RANK]
    est_skip = params[P_EST_SKIP] / 100.0
    fit_gain = params[P_FIT_GAIN] / 100.0
    cq_scale = params[P_CQ_SCALE] / 100.0
    plane_always = params[P_PLANE_ALWAYS]
    # the modes tried, per plane count
    mlist = np.zeros((2, nmodes), np.int64)
    mcount = np.zeros(2, np.int64)
    mbits = np.zeros((2, nmodes), np.int64)
    gwh = np.zeros((2, 13, 13), np.int64)  # grids used, by plane count, width and height
    for m in range(nmodes):
        if mode_on[m]:
            d = modes[m, 2]
            mlist[d, mcount[d]] = m
            mbits[d, mcount[d]] = modes[m, 3]
            mcount[d] += 1
            gwh[d, g_dims[modes[m, 0], 0], g_dims[modes[m, 0], 1]] = 1
    mest = np.zeros(nmodes)
    fest = np.zeros(nmodes)
    # colour-range error by range + 1 (0: no range fits), for the direct-like
    # families and for base+offset (8-bit rounding only, where the range
    # keeps every bit it uses)
    cqe_tab = np.full(cq_err.shape[0] + 1, np.inf)
    cqe_off = np.full(cq_err.shape[0] + 1, np.inf)
    for r in range(cq_err.shape[0]):
        cqe_tab[r + 1] = cq_err[r]
        if r >= OFFSET_MIN_RANGE:
            cqe_off[r + 1] = 1.0 / 12.0
    bw = ux.shape[0]
    bh = nt // bw

    ws = Work(np.zeros(4, np.int64), np.zeros(64), np.zeros(64), np.zeros(128, np.int64),
              np.zeros(nt, np.int64), np.zeros(nt, np.int64), np.zeros(nt, np.int64),
              np.zeros(nt, np.int64), np.zeros((4, 4)),
              np.zeros((4, 4)), np.zeros(32, np.int64), np.zeros((4, 4), np.int64),
              np.zeros((4, 4), np.int64), np.zeros((4, 4), np.int64), np.zeros((4, 4), np.int64),
              np.zeros(8, np.int64), np.zeros((2, 4), np.int64),
              np.zeros(nt), np.zeros(nt),
              np.zeros(nt), np.zeros(nt), np.zeros(64), np.zeros(64), np.zeros(nt),
              np.zeros(nt), np.zeros((4, 4, 5)))
    x = np.zeros((nt, 4))
    labels = np.zeros(nt, np.int64)
    cl = np.zeros(nt, np.int64)
    cen = np.zeros((4, 4))
    e0f = np.zeros((4, 4))
    e1f = np.zeros((4, 4))
    w1 = np.zeros(nt)
    w2 = np.zeros(nt)
    s1 = np.zeros(nt)
    s2 = np.zeros(nt)
    gc1 = np.zeros((ngrid, 64))
    gc2 = np.zeros((ngrid, 64))
    gdone = np.zeros(ngrid, np.int64)
    gerr = np.zeros(ngrid)
    pgrey = np.zeros(4, np.int64)
    popaque = np.zeros(4, np.int64)
    pids = np.zeros(64, np.int64)
    pres = np.zeros(64)
    dchan = np.zeros(4, np.int64)
    c_est = np.zeros(64)
    c_mode = np.zeros(64, np.int64)
    c_fam = np.zeros(64, np.int64)
    row = np.zeros(SYM_LEN, np.int32)
    fsc = np.zeros((24, 4))
    ksc = np.zeros((6, 4))
    cmask = np.zeros((4, 3), np.int64)
    icnt = np.zeros((4, 4), np.int64)
    score = np.zeros(64, np.int64)
    pdist = np.zeros(1024, np.int64)
    mom = np.zeros((4, 16))
    tprod = np.zeros((nt, 16))
    ttot = np.zeros(16)
    fam_nv = np.zeros(4, np.int64)
    fam_bits = np.zeros(4, np.int64)
    serr = np.zeros((13, 13))
    gsc = np.zeros(nt + bh * ux.shape[1] + bh * bh)
    # every array the blocks' loop uses, as views without reference counts
    # (_jit.borrow): helpers here take many arrays and run many times a block.
    # `own` keeps the arrays alive; the kernel returns its length to use it last
    own = (ws, x, labels, cl, cen, e0f, e1f, w1, w2, s1, s2, gc1, gc2, gdone, gerr, pgrey, popaque,
           pids, pres, dchan, c_est, c_mode, c_fam, row, fsc, ksc, cmask, icnt, score, pdist, mom,
           tprod, ttot, fam_nv, fam_bits, serr, gsc, g_dims, g_idx, g_wt, g_tex, g_tw, g_tn, modes,
           ptab, ux, uoff, qyp, pmask, p2mask, plist, pcount, perms, nperm, cq_err, wq_err, cr_tab,
           cunq, cquant, wunq, wquant, worder, wrank, levels, blocks, sym, chw, mode_on, mlist,
           mcount, gwh, mest, mbits, fest, cqe_tab, cqe_off)
    (ws, x, labels, cl, cen, e0f, e1f, w1, w2, s1, s2, gc1, gc2, gdone, gerr, pgrey, popaque, pids,
     pres, dchan, c_est, c_mode, c_fam, row, fsc, ksc, cmask, icnt, score, pdist, mom, tprod, ttot,
     fam_nv, fam_bits, serr, gsc, g_dims, g_idx, g_wt, g_tex, g_tw, g_tn, modes, ptab, ux, uoff,
     qyp, pmask, p2mask, plist, pcount, perms, nperm, cq_err, wq_err, cr_tab, cunq, cquant, wunq,
     wquant, worder, wrank, levels, blocks, sym, chw, mode_on, mlist, mcount, gwh, mest, mbits,
     fest, cqe_tab, cqe_off) = borrow(own)
    tab = (g_dims, g_idx, g_wt, g_tex, g_tw, g_tn, modes, cr_tab, cunq, cquant, wunq, wquant,
           worder, wrank, levels)
    ncand = min(ncand, 64)
    part_cands = min(part_cands, 64)

    for i in range(nb):
        const = True
        # callees take flags as np.int64 values, never literals: numba compiles a
        # function once more for every literal value a caller passes it
        opaque = np.int64(1)
        for t in range(nt):
            for c in range(4):
                x[t, c] = blocks[i, t, c]
                if blocks[i, t, c] != blocks[i, 0, c]:
                    const = False
            if blocks[i, t, 3] != 255:
                opaque = 0
        for jj in range(sym.shape[1]):
            sym[i, jj] = 0
        if const:
            sym[i, S_KIND] = KIND_VOID
            for c in range(4):
                sym[i, S_VOID + c] = blocks[i, 0, c] * 257
            continue
        best = np.inf
        resid1 = np.inf
        _texel_moments(x, chw, nt, tprod, ttot)
        ndch = (_dual_channels(ttot, opaque, dual_mode, dual_corr, dchan, fsc)
                if dual_mode > 0 else 0)
        for nparts in range(1, max_parts + 1):
            if nparts > 1 and best <= early * nt:
                break
            if nparts == 1:
                npid = 1
                pids[0] = 0
            else:
                npid = _rank_partitions(x, chw, nt, nparts, pmask, p2mask, plist, pcount, perms,
                                        nperm, kiters, part_cands, pids, cl, cen, ksc,
                                        cmask, icnt, score[:part_cands], pdist)
                # keep the few whose partitions lie closest to lines
                for k in range(npid):
                    for t in range(nt):
                        labels[t] = ptab[nparts - 2, pids[k], t]
                    pres[k] = _line_resid(labels, nparts, nt, tprod, ttot, mom, fsc)
                for k in range(1, npid):
                    r = pres[k]
                    q = pids[k]
                    j = k
                    while j > 0 and pres[j - 1] > r:
                        pres[j] = pres[j - 1]
                        pids[j] = pids[j - 1]
                        j -= 1
                    pres[j] = r
                    pids[j] = q
                npid = min(npid, part_full)
            for pi in range(npid):
                pid = pids[pi]
                for t in range(nt):
                    labels[t] = 0 if nparts == 1 else ptab[nparts - 2, pid, t]
                # content of each partition: grey? opaque?
                for p in range(nparts):
                    pgrey[p] = 1
                    popaque[p] = 1
                for t in range(nt):
                    p = labels[t]
                    if x[t, 0] != x[t, 1] or x[t, 1] != x[t, 2]:
                        pgrey[p] = 0
                    if x[t, 3] != 255:
                        popaque[p] = 0
                nplanes = 1 + (ndch if nparts < 4 else 0)  # four leave no room for two planes
                for pl in range(nplanes):
                    if pl > 0 and best <= early * nt and not plane_always:
                        break  # a second plane is not needed either
                    dual = 1 if pl > 0 else 0
                    ccs = dchan[pl - 1] if dual else 0
                    resid = _fit(x, chw, labels, nparts, nt, dual, ccs, tprod, ttot, mom, e0f,
                                 e1f, w1, w2, s1, s2, fsc)
                    if nparts == 1 and pl == 0:
                        resid1 = resid
                    elif fit_gain > 0 and resid > fit_gain * resid1:
                        continue  # too little closer to lines than one partition, one plane
                    if resid >= best:
                        # the texels' distance from their partitions' lines (less
                        # the plane of its own) bounds any encoding from below
                        continue
                    # per grid: 1 separable estimate only, 2 decimated into gc1/gc2
                    ssum1 = 0.0
                    ssum2 = 0.0
                    for t in range(nt):
                        ssum1 += s1[t]
                        ssum2 += s2[t] if dual else 0.0
                    # colour-quantisation error estimate needs the weighted
                    # channels the partitions store
                    wsum = chw[0] + chw[1] + chw[2]
                    for p in range(nparts):
                        if not popaque[p]:
                            wsum += chw[3]
                            break
                    # base+scale puts the dark endpoint on the bright one's ray
                    # from black: what that costs, with a weight of 1/3 per texel
                    smiss = 0.0
                    if nfam > 1:
                        for p in range(nparts):
                            if pgrey[p]:
                                continue
                            num = 0.0
                            den = 0.0
                            for c in range(3):
                                num += chw[c] * e0f[p, c] * e1f[p, c]
                                den += chw[c] * e1f[p, c] * e1f[p, c]
                            f = num / den if den > 0 else 0.0
                            d2 = 0.0
                            for c in range(3):
                                d = e0f[p, c] - f * e1f[p, c]
                                d2 += chw[c] * d * d
                            smiss += d2 * mom[p, 0] / 3.0  # the fit left texel counts there
                    # luminance for every partition loses each texel's distance
                    # from grey (weighted), charged in full
                    lmiss = 0.0
                    allgrey = 1
                    for p in range(nparts):
                        if not pgrey[p]:
                            allgrey = 0
                    if nfam > 3 and not allgrey:
                        wl = chw[0] + chw[1] + chw[2]
                        for t in range(nt):
                            lum = (chw[0] * x[t, 0] + chw[1] * x[t, 1] + chw[2] * x[t, 2]) / wl
                            for c in range(3):
                                d = x[t, c] - lum
                                lmiss += chw[c] * d * d
                    # base+offset reaches 31 levels from the base, and pays
                    # only when the range keeps its bits
                    offset_ok = nfam > 2
                    for p in range(nparts):
                        for c in range(4):
                            if abs(e1f[p, c] - e0f[p, c]) > 30.5:
                                offset_ok = False
                    # CEMs per family depend on the partitions only
                    for fam in range(nfam):
                        nv, same = _choose_cems(fam, nparts, pgrey, popaque, ws.cems)
                        scl = 1 if fam == FAM_DIRECT else 0
                        for p in range(nparts):
                            if ws.cems[p] != 0 and ws.cems[p] != 4:
                                scl = 1
                        if fam == FAM_LUMA:
                            scl = 1 - allgrey  # with every partition grey it is direct
                        # a family other than direct only when some partition
                        # differs from direct
                        fam_nv[fam] = nv if (scl and nv <= 18) else -1
                        fam_bits[fam] = 128 - config_bits(nparts, same, dual)
                    # every grid's error: the separable estimate, or decimated
                    if sep_rank:
                        for ii in range(2, bw + 1):
                            for jj in range(2, bh + 1):
                                serr[ii, jj] = 0.0
                        _sep_errs(w1, s1, bw, bh, ux, uoff, qyp, serr, gsc, gwh[dual])
                        if dual:
                            _sep_errs(w2, s2, bw, bh, ux, uoff, qyp, serr, gsc, gwh[dual])
                        for g in range(ngrid):
                            gerr[g] = max(serr[g_dims[g, 0], g_dims[g, 1]], 0.0)
                            gdone[g] = 1
                    else:
                        for g in range(ngrid):
                            if not gwh[dual, g_dims[g, 0], g_dims[g, 1]]:
                                continue
                            ng = g_dims[g, 0] * g_dims[g, 1]
                            _decimate(g_idx[g], g_wt[g], nt, ng, w1, s1, decim_iters,
                                      gc1[g], ws.num, ws.den)
                            gerr[g] = _decim_err(g_idx[g], g_wt[g], nt, gc1[g], w1, s1)
                            if dual:
                                _decimate(g_idx[g], g_wt[g], nt, ng, w2, s2, decim_iters,
                                          gc2[g], ws.num, ws.den)
                                gerr[g] += _decim_err(g_idx[g], g_wt[g], nt, gc2[g], w2, s2)
                            gdone[g] = 2
                    skip = est_skip * best if est_skip > 0 else np.inf
                    nfound = _select_modes(dual, nfam, ncand, cq_scale * nt * wsum, ssum1, ssum2, smiss,
                                           lmiss, offset_ok, wq_scale, skip, tab, mlist, mcount, mbits,
                                           gdone, gerr, gc1, gc2, wq_err, fam_nv, fam_bits, cqe_tab,
                                           cqe_off, mest, fest, c_est, c_mode, c_fam)
                    # every candidate once, then refinement for the fit's best
                    fbest = np.inf
                    fk = -1
                    # a lone candidate is encoded once, with its refinement
                    k0 = 1 if (nfound == 1 and refine > 0) else 0
                    if k0:
                        fk = 0
                    for k in range(k0, nfound + (1 if refine > 0 else 0)):
                        kk = k
                        rounds = 0
                        if k == nfound:
                            if fk < 0:
                                break
                            kk = fk
                            rounds = refine
                        if est_skip > 0 and c_est[kk] > est_skip * best:
                            continue  # the estimate says this cannot win
                        m = c_mode[kk]
                        g = modes[m, 0]
                        if gdone[g] == 1:
                            # ranked by the separable estimate: decimate for real
                            ng = g_dims[g, 0] * g_dims[g, 1]
                            _decimate(g_idx[g], g_wt[g], nt, ng, w1, s1, decim_iters,
                                      gc1[g], ws.num, ws.den)
                            if dual:
                                _decimate(g_idx[g], g_wt[g], nt, ng, w2, s2, decim_iters,
                                          gc2[g], ws.num, ws.den)
                            gdone[g] = 2
                        # realign only the encodings that can be kept
                        ra = realign if (rounds > 0 or refine == 0) else 0
                        err = _encode_mode(x, chw, srgb, labels, nparts, pid, nt, m, c_fam[kk],
                                           pgrey, popaque, ccs, gc1, gc2, w1, w2, s1, s2,
                                           rounds, decim_iters, ra, tab, ws, row)
                        if err < fbest:
                            fbest = err
                            fk = kk
                        if err < best:
                            best = err
                            for jj in range(sym.shape[1]):
                                sym[i, jj] = row[jj]
        if best == np.inf:
            # cannot happen for legal tables; fall back to the block's mean as void extent
            sym[i, S_KIND] = KIND_VOID
            for c in range(4):
                acc = 0.0
                for t in range(nt):
                    acc += x[t, c]
                sym[i, S_VOID + c] = int(acc / nt + 0.5) * 257
    return len(own)
