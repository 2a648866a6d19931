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

from collections import namedtuple

import numpy as np

from ...._jit import borrow, jit, jit_inner
from ..modes import config_bits
from ..symbolic import (
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
from .endpoints import FAM_DIRECT, FAM_LUMA, OFFSET_MIN_RANGE, _choose_cems, _expand, _quant_endpoints
from .estimate import _select_modes
from .fit import _dual_channels, _fit, _line_resid, _refit, _texel_moments, _weights_from
from .grid import _decim_err, _decimate, _infill, _quantise_grid, _sep_errs
from .partitioning import _rank_partitions
from .realign import _realign
from .block_tables import kernel_args, tables

__all__ = ["SYM_LEN", "kernel_args", "search_kernel", "tables"]

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
