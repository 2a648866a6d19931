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
   ideal weights (the first fit, one partition and one plane, and its grid
   estimates below are made for a run of blocks at once: lanes.py). A fit
   whose texels lie farther from their lines than the best error so far is
   dropped (no encoding can do better), and so, where the preset says, is
   one that comes too little closer to lines than the first fit.
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

import threading
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
from .block_tables import BlockTables, kernel_tables, tables
from .endpoints import (
    FAM_DIRECT,
    FAM_LUMA,
    FAM_OFFSET,
    FAM_SCALE,
    N_FAMILIES,
    OFFSET_MIN_RANGE,
    EndpointWork,
    choose_cems,
    expand,
    fit_err,
    mixed_families,
    quant_endpoints,
)
from .estimate import (
    CSLOTS,
    EstWork,
    colour_range_err,
    own_wq_err,
    refit_wq_err,
    select_modes,
    wq_tables,
)
from .fit import (
    FitWork,
    dual_channels,
    fit_partitions,
    line_resid,
    refit,
    texel_products,
    weights_from,
)
from .grey import grey_modes, grey_one, grey_work
from .grid import decim_err, decimate, grid_quant_err, infill, quantise_grid, sep_errs
from .lanes import TILE, first_tile, lanes_work, tile_moments
from .partitioning import PartWork, flat_best, rank_partitions
from .realign import RealignWork, realign_full, realign_weights, texel_err

Scratch = namedtuple("Scratch", "es ws fw pw x labels pres pslot pmom psm plm tlum mmiss mcode dchan serr gsc gwh "
                     "minbits wq_tab wq_vals wq_acc grey win lanes")

__all__ = ["SYM_LEN", "BlockTables", "kernel_tables", "search_kernel", "tables"]


@jit_inner(inline="always")
def _decode_err(x, chw, labels, nt, wt1, wt2, dual, ccs, ee0, ee1):
    """Weighted squared error of the decoded block against texels x (T,4);
    ee0, ee1 are the partitions' endpoints widened to 16 bits (expand).
    Inlined: its one call site then passes no arrays through reference
    counts."""
    err = 0.0
    c2 = ccs if dual else -1
    for t in range(nt):
        p = labels[t]
        w1 = wt1[t]
        w2 = wt2[t] if dual else w1
        err = texel_err(err, x[t], chw, ee0[p], ee1[p], w1, w2, c2)
    return err


# the tables a candidate's encoding reads (of the size's BlockTables): a
# kernel call passes a record's every array field by value, so the one
# called per candidate gets only these
EncodeTables = namedtuple("EncodeTables", "modes grids colour weight")

# the block being searched: texels x (T, 4), channel weights chw (4,), srgb 1
# for the sRGB decoding
Block = namedtuple("Block", "x chw srgb")

# The separable estimate fits each texel's ideal weight scaled by its
# partition's span, so a narrow partition's weights count as near 0 where
# they are nearly free: beside a wide one (an edge's partition next to a
# flat patch) it ranks coarse grids several times too high and they are
# never encoded (a 10x10 block's 3x10 grid of two weight levels: estimated
# at 770 per texel, where astcenc's encoding misses 10). A fit whose spans
# differ more than the row's span_rank says ranks its grids decimated for
# real, RANK_ITERS steps each (the candidates encoded decimate again with
# the row's steps; one step ranks closer than none: docs/astc.md,
# "Partitions of unequal spans").
RANK_ITERS = 1
# one thread's scratch for encoding a candidate: the partitions' content
# (pgrey, popaque (4,)), the fit's grids decimated per grid (gc1, gc2, shared
# with EstWork), the best encoding's symbolic row, the rounds' weights,
# endpoints (ep: EndpointWork) and sums, and per-texel scratch (num for
# decimate, qa qb fq gq rdq for realign_weights)
Work = namedtuple(
    "Work", "pgrey popaque gc1 gc2 row cems gr1 gr2 codes wt1 wt2 acc1 acc2 ep ee0 ee1 u1 u2 v1 v2 num den qa qb "
    "racc fq gq rdq")


@jit_inner(inline="always")
def more_parts(part_gain, best, cbest, prev):
    """Whether a partition count above two is worth trying (the preset's
    part_gain, as a fraction): the last count brought the best error (best)
    under part_gain of what one fewer partition left (prev); above 1, its own
    best (cbest) is compared instead, as a count that did worse than the one
    below never moves the running best, and says one more will not pay."""
    if part_gain <= 0:
        return True
    return (cbest if part_gain > 1 else best) <= part_gain * prev


@jit_inner(_nrt=False)
def part_labels(x, ptab, nparts, pid, nt, labels, pgrey, popaque):
    """Each texel's partition of pattern pid into labels, and whether each
    partition is wholly grey (R = G = B) and opaque into pgrey, popaque. A
    call of its own: inlined at its two sites it took 4x4 `fast` to 1.03x
    its time (the kernel's code grows; it runs once per fit)."""
    for t in range(nt):
        labels[t] = 0 if nparts == 1 else ptab[nparts - 2, pid, t]
    for p in range(nparts):
        pgrey[p] = 1
        popaque[p] = 1
    for t in range(nt):
        p = labels[t]
        if x[t, 0] != x[t, 1] or x[t, 1] != x[t, 2]:
            pgrey[p] = 0
        if x[t, 3] != 255:
            popaque[p] = 0


@jit_inner(_nrt=False)
def _encode_mode(blk, labels, nparts, pindex, mode, fam, ccs, refine, realign, decim_iters, gate, tab, ws):
    """Encode the block blk with partitioning (labels, nparts, pindex), one
    block mode and CEM family and ccs on the second plane if the mode has
    one, starting from the grid weights decimated into ws.gc1[g], ws.gc2[g];
    `refine` rounds re-derive the weights, `realign` passes move them.
    gate (lim, sxx): a round whose refit endpoints, before quantisation,
    miss by more than lim (inf: never) ends the encoding (sxx: the block's
    weighted sum of squared texel values, which that error needs). The best
    round goes into ws.row. Returns its error (inf when the
    combination is illegal). tab: the size's EncodeTables; ws: Work.
    Compiled with _nrt=False: numba then takes and drops no reference to
    the some 70 arrays of its arguments on every call (each a call of its
    own, for borrowed views too: about half its own time in a profile);
    it allocates nothing and returns no array."""
    x, chw, srgb = blk
    lim, sxx = gate
    nt = labels.shape[0]
    grids, weight, modes = tab.grids, tab.weight, tab.modes
    g_dims, g_idx, g_wt = grids.dims, grids.idx, grids.wt
    cr_tab, cunq, cquant = tab.colour.cr_tab, tab.colour.unq, tab.colour.quant
    wunq, wquant = weight.unq, weight.quant
    pgrey, popaque, gc1, gc2, row, ep = ws.pgrey, ws.popaque, ws.gc1, ws.gc2, ws.row, ws.ep
    # the fields the rounds use, taken out once: each taking of an array out
    # of a record is a reference count call that LLVM cannot see through,
    # so loads after it are made again
    codes, wt1, wt2, acc1, acc2, racc, ee0, ee1 = ws.codes, ws.wt1, ws.wt2, ws.acc1, ws.acc2, ws.racc, ws.ee0, ws.ee1
    d0, d1, vals = ep.d0, ep.d1, ep.vals
    u1, u2, v1, v2, wnum, wden = ws.u1, ws.u2, ws.v1, ws.v2, ws.num, ws.den
    g = modes[mode, 0]
    wq = modes[mode, 1]
    dual = modes[mode, 2]
    wbits = modes[mode, 3]
    gw = g_dims[g, 0]
    gh = g_dims[g, 1]
    ng = gw * gh
    cems = ws.cems
    rw1 = RealignWork(codes, acc1, wt1, ee0, ee1, ws.qa, ws.qb, ws.fq, ws.gq, ws.rdq)
    rw2 = RealignWork(codes, acc2, wt2, ee0, ee1, ws.qa, ws.qb, ws.fq, ws.gq, ws.rdq)
    nv, same = choose_cems(fam, nparts, pgrey, popaque, cems)
    if nv > 18:
        return np.inf
    cq = cr_tab[max(128 - config_bits(nparts, same, dual) - wbits, 0), nv]
    if cq < 0:
        return np.inf
    gidx = g_idx[g]
    gwt = g_wt[g]
    # the grid's rows realign_weights reads
    gtex, gtw, gtn = grids.tex[g], grids.tw[g], grids.tn[g]
    stride = 2 if dual else 1
    gr1 = ws.gr1
    gr2 = ws.gr2
    wquant_q = wquant[wq]
    best = np.inf
    # planes as np.int64, not literals: numba compiles a callee once per
    # literal value it is passed
    plane0 = np.int64(0)
    plane1 = np.int64(1)
    for rnd in range(refine + 1):
        # the first round quantises the grid decimated for the fit as it is
        # (no copy), later ones what decimate re-derived into gr1, gr2
        quantise_grid(gc1[g] if rnd == 0 else gr1, ng, wquant_q, codes, stride, plane0)
        infill(gidx, gwt, nt, ng, codes, stride, plane0, wq, wunq, wt1, acc1)
        if dual:
            quantise_grid(gc2[g] if rnd == 0 else gr2, ng, wquant_q, codes, stride, plane1)
            infill(gidx, gwt, nt, ng, codes, stride, plane1, wq, wunq, wt2, acc2)
        refit(x, labels, nparts, nt, wt1, wt2, dual, ccs, ep.e0, ep.e1, racc)
        if lim < np.inf:
            ferr = fit_err(racc, nparts, chw, ep.e0, ep.e1, sxx)
            if ferr > lim:
                # quantising the endpoints only adds to this error
                return min(best, ferr)
        nvals = np.int64(0)  # a literal 0 is typed first and compiled for too
        for p in range(nparts):
            nvals += quant_endpoints(cems[p], p, cq, chw, cunq, cquant, nvals, ep, racc)
        for p in range(nparts):
            for c in range(4):
                ee0[p, c] = expand(d0[p, c], srgb)
                ee1[p, c] = expand(d1[p, c], srgb)
        if realign > 0 and ng == nt:
            # a full grid: each texel realigned and decoded in one pass
            err = realign_full(x, chw, labels, nparts, wq, dual, ccs, realign, codes, (acc1, wt1, acc2, wt2),
                               (ee0, ee1), ws.rdq)
        else:
            if realign > 0:
                realign_weights(x, chw, labels, nparts, (gtex, gtw, gtn, ng), wq, dual, ccs, plane0, realign, rw1)
                if dual:
                    realign_weights(x, chw, labels, nparts, (gtex, gtw, gtn, ng), wq, dual, ccs, plane1, realign, rw2)
            err = _decode_err(x, chw, labels, nt, wt1, wt2, dual, ccs, ee0, ee1)
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
                row[S_ENDPOINTS + k] = vals[k]
            for k in range(ng * stride):
                row[S_WEIGHTS + k] = codes[k]
        if rnd == refine or err == 0:
            break
        # re-derive weights from what the decoder makes of these endpoints
        weights_from(x, chw, labels, nt, d0, d1, dual, ccs, u1, u2, v1, v2)
        decimate(grids, g, nt, u1, v1, decim_iters, gr1, wnum, wden)
        if dual:
            decimate(grids, g, nt, u2, v2, decim_iters, gr2, wnum, wden)
    return best


def _work(nt, ngrid):
    """A thread's Work for blocks of nt texels and ngrid weight grids (its
    gc1, gc2 are shared with the EstWork)."""
    ep = EndpointWork(np.zeros((4, 4)), np.zeros((4, 4)), np.zeros(32, np.int64), np.zeros((4, 4), np.int64),
                      np.zeros((4, 4), np.int64), np.zeros(8, np.int64), np.zeros((2, 4), np.int64))
    return Work(np.zeros(4, np.int64), np.zeros(4, np.int64), np.zeros((ngrid, 64)), np.zeros((ngrid, 64)),
                np.zeros(SYM_LEN, np.int32), np.zeros(4, np.int64), np.zeros(64), np.zeros(64),
                np.zeros(128, np.int64), np.zeros(nt, np.int64), np.zeros(nt, np.int64), np.zeros(nt, np.int64),
                np.zeros(nt, np.int64), ep, np.zeros((4, 4), np.int64), np.zeros((4, 4), np.int64),
                np.zeros(nt), np.zeros(nt), np.zeros(nt), np.zeros(nt), np.zeros(nt), np.zeros(64), np.zeros(nt),
                np.zeros(nt), np.zeros((4, 4, 5)), np.zeros(nt), np.zeros(nt), np.zeros((9, 4)))


def _fit_work(nt, runs=None):
    """A thread's FitWork for blocks of nt texels; runs: its Lanes's out
    (none: the fits are all made per block)."""
    return FitWork(np.zeros((nt, 16)), np.zeros(16), np.zeros((4, 16)), np.zeros((4, 4)), np.zeros((4, 4)),
                   np.zeros(nt), np.zeros(nt), np.zeros(nt), np.zeros(nt), np.zeros((24, 4)),
                   np.zeros((1, 1)) if runs is None else runs)


def _part_work(nt):
    """A thread's PartWork for blocks of nt texels."""
    return PartWork(np.zeros(1024, np.int64), np.zeros(nt, np.int64), np.zeros((4, 4)), np.zeros((6, 4)),
                    np.zeros((4, 3), np.int64), np.zeros((4, 4), np.int64), np.zeros(64, np.int64),
                    np.zeros(1024, np.int64))


def beside_kernels(bw, bh):
    """(kernel, argument types) of what search_kernel calls for blocks of bw x
    bh texels, in the order a second process should compile them while this
    one compiles search_kernel (texcook.codecs.astc, beside a first encode):
    _encode_mode, the largest, which the kernel reaches last, then the others
    from the last the kernel reaches to the first. The kernel compiles each
    one it reaches and finds missing from the disk cache itself, so the two
    processes meet in the middle. The types are those of the values the
    kernel passes (its scratch records made by the same builders):
    tests/test_prepare.py checks that an encode loads every one."""
    from numba import typeof

    full = kernel_tables(bw, bh)
    nt = bw * bh
    ngrid = full.grids.dims.shape[0]
    lw = lanes_work(bw, bh, full.sep.ux.shape[1])
    ws, fw, pw = _work(nt, ngrid), _fit_work(nt, lw.out), _part_work(nt)
    i64, f64 = typeof(np.int64(0)), typeof(0.0)  # the kernel's counts, indices and flags; errors
    f1, f2, f3 = typeof(np.zeros(1)), typeof(np.zeros((1, 1))), typeof(np.zeros((1, 1, 1)))
    n1 = typeof(np.zeros(1, np.int64))
    x, labels, chw = typeof(np.zeros((nt, 4))), n1, f1
    wunq, wquant = typeof(full.weight.unq), typeof(full.weight.quant)
    blk = Block(np.zeros((nt, 4)), np.ones(4), np.int64(0))
    etab = EncodeTables(full.modes, full.grids, full.colour, full.weight)
    gidx, gwt = typeof(full.grids.idx[0]), typeof(full.grids.wt[0])
    return (
        (_encode_mode, (typeof(blk), labels, *[i64] * 8, typeof((1.0, 1.0)), typeof(etab), typeof(ws))),
        (grid_quant_err, (f1, i64, i64, wunq, wquant)),
        (own_wq_err, (f1, f1, f1, f1, i64, i64, f2, f1)),
        (refit_wq_err, (f1, f1, f1, f1, labels, i64, i64, i64, f2, f1, f3)),
        (decim_err, (gidx, gwt, i64, f1, f1, f1)),
        (decimate, (typeof(full.grids), typeof(full.modes[0, 0]), i64, f1, f1, i64, f1, f1, f1)),
        (decimate, (typeof(full.grids), i64, i64, f1, f1, i64, f1, f1, f1)),
        (sep_errs, (f1, f1, i64, i64, typeof(full.sep.ux), typeof(full.sep.uoff), typeof(full.sep.qyp), f2, f1,
                    typeof(np.zeros((1, 1), np.int64)), i64, f2)),
        (mixed_families, (i64, n1, f1, f1, typeof(True), n1, f1, i64, f2, typeof(np.zeros((1, 1), np.int64)))),
        (fit_partitions, (x, chw, labels, i64, i64, i64, i64, typeof(fw), i64)),
        (dual_channels, (f1, i64, i64, f64, n1, f2)),
        (line_resid, (typeof(full.parts.pmask[0, 0]), i64, i64, f2, f1, f2, f2, f64)),
        (rank_partitions, (x, chw, i64, i64, i64, i64, typeof(full.parts), typeof(pw))),
        (flat_best, (typeof(full.parts.pmask), i64, i64, x, n1, i64, i64, f1)),
        (texel_products, (x, chw, i64, f2)),
        (wq_tables, (wunq, wquant, f2, f2)),
        (part_labels, (x, typeof(full.parts.ptab), i64, i64, i64, labels, n1, n1)),
        # the run's first fits, which the kernel reaches first
        (first_tile, (typeof(np.zeros((1, nt, 4), np.uint8)), i64, chw, typeof(lw), i64, i64, typeof(full.sep),
                      typeof(np.zeros((1, 1), np.int64)))),
    )


def scratch(tab, nt):
    """search_kernel's Scratch for blocks of nt texels of the block size whose
    BlockTables is tab (one per call: a call runs on one thread)."""
    ngrid = tab.grids.dims.shape[0]
    nmodes = tab.modes.shape[0]
    nranges = tab.colour.err.shape[0]
    bh = nt // tab.sep.ux.shape[0]
    ws = _work(nt, ngrid)
    gc1, gc2 = ws.gc1, ws.gc2
    es = EstWork(np.zeros((2, nmodes), np.int64), np.zeros(2, np.int64), np.zeros((2, nmodes), np.int64),
                 np.zeros(ngrid, np.int64), np.zeros(ngrid), gc1, gc2, np.zeros(16, np.int64),
                 np.zeros(N_FAMILIES, np.int64), np.zeros(N_FAMILIES, np.int64), np.zeros(N_FAMILIES),
                 np.full(nranges + 1, np.inf), np.full(nranges + 1, np.inf),
                 np.zeros(nmodes), np.zeros(64), np.zeros(64, np.int64), np.zeros(64, np.int64),
                 np.zeros(tab.weight.unq.shape[0]), np.zeros((2, CSLOTS), np.int64),
                 np.zeros((2, CSLOTS, nmodes)), np.zeros(2, np.int64), np.zeros((2, ngrid), np.int64),
                 np.zeros(2, np.int64), np.zeros((2, ngrid + 1), np.int64), np.zeros((2, nmodes), np.int64),
                 np.zeros((2, nmodes), np.int64), np.zeros(ngrid), np.zeros((2, CSLOTS, ngrid)),
                 np.zeros(64, np.int64), np.zeros((2, CSLOTS, nmodes)), np.zeros(ngrid, np.int64))
    lw = lanes_work(tab.sep.ux.shape[0], bh, tab.sep.ux.shape[1])
    fw = _fit_work(nt, lw.out)
    pw = _part_work(nt)
    x = np.zeros((nt, 4))
    labels = np.zeros(nt, np.int64)
    pres = np.zeros(64)
    pslot = np.zeros(64, np.int64)  # per pattern kept, its slot of pmom
    pmom = np.zeros((64, 4, 16))  # the kept patterns' partition moment sums (line_resid's)
    psm = np.zeros(4)  # per partition, what base+scale and luminance miss
    plm = np.zeros(4)
    tlum = np.zeros(nt)  # per texel, its weighted squared distance from grey
    mmiss = np.zeros((2, 9))  # mixed_families' scratch
    mcode = np.zeros((2, 9), np.int64)
    dchan = np.zeros(4, np.int64)
    serr = np.zeros((13, 13))
    gsc = np.zeros(nt + bh * tab.sep.ux.shape[1] + bh * bh)
    gwh = np.zeros((2, 13, 13), np.int64)  # grids used, by plane count, width and height
    minbits = np.zeros(2, np.int64)  # the fewest weight bits of a mode tried, by plane count
    wq_tab = np.zeros((65, tab.weight.unq.shape[0]))
    wq_vals = np.zeros((65, tab.weight.unq.shape[0]))
    wq_acc = np.zeros((4, 4, tab.weight.unq.shape[0]))  # refit_wq_err's sums
    return fresh(Scratch(es, ws, fw, pw, x, labels, pres, pslot, pmom, psm, plm, tlum, mmiss, mcode, dchan, serr, gsc,
                         gwh, minbits, wq_tab, wq_vals, wq_acc, grey_work(nt, nmodes), np.zeros(5, np.int64), lw))


_scratches = threading.local()  # per thread: {id(tables): (tables, Scratch)}


def search(blocks, sym, rec, mode_on, chw, srgb, tab):
    """search_kernel over blocks into sym, with this thread's Scratch for the
    block size (made once: some hundred arrays, 50 us a call, where an
    encode calls the kernel twice per image and a mip chain once per level
    more): what the kernel accumulates in it is set afresh first (fresh())."""
    kept = getattr(_scratches, "by_table", None)
    if kept is None:
        kept = _scratches.by_table = {}
    nt = blocks.shape[1]
    held = kept.get(id(tab))
    if held is None or held[0] is not tab or held[1].x.shape[0] != nt:
        held = kept[id(tab)] = (tab, scratch(tab, nt))
    search_kernel(blocks, sym, rec, mode_on, chw, srgb, tab, fresh(held[1]))


def fresh(sc):
    """sc with what search_kernel accumulates over its call set as it starts:
    the lists of modes tried (counts, grids, fewest weight bits, grids used)
    and the colour-range cache (no keys, next slot 0). Returns sc."""
    es = sc.es
    es.mcount[:] = 0
    es.ngr[:] = 0
    es.cnext[:] = 0
    es.ckey[:] = -1
    sc.minbits[:] = 1 << 20
    sc.gwh[:] = 0
    return sc


@jit(_nrt=False, link_late=True)
def search_kernel(blocks, sym, rec, mode_on, chw, srgb, tab, sc):
    """blocks uint8 (n, T, 4) -> sym int32 (n, SYM_LEN). rec: the preset's
    record (presets.record; read as prm), mode_on (one per row of tab.modes):
    0 for block modes the preset does not try, chw (4,) channel weights, srgb
    1 to search for the sRGB decoding, tab: the block size's BlockTables, sc:
    the call's Scratch (made by scratch(): a call runs on one thread). The
    kernel allocates nothing, so it is compiled without reference counting:
    about 40% of its code otherwise, and of the time LLVM takes over it."""
    prm = rec[0]
    nb = blocks.shape[0]
    nt = blocks.shape[1]
    ngrid = tab.grids.dims.shape[0]
    nmodes = tab.modes.shape[0]
    max_parts = prm.max_parts
    part_cands = max(prm.part_cands, 1)
    dual_mode = prm.dual
    ncand = max(prm.mode_cands, 1)
    refine = prm.refine
    # families tried: direct, then base+scale and base+offset, then luminance
    nfam = 3 if prm.scale_cems else 1
    if prm.luma_cems and nfam == 3:
        nfam = 4
    mixed = prm.mixed_cems and nfam > 1
    early = prm.early_out / 100.0
    plane_early = prm.plane_early / 100.0
    enough = prm.enough / 1000.0
    done_err = prm.done_err / 100.0
    decim_iters = prm.decim_iters
    kiters = prm.kmeans_iters
    part_full = max(prm.part_full, 1)
    realign = prm.realign
    # the refit and realignment recover much of what coarse weight ranges
    # lose, so their estimate is scaled down
    wq_scale = prm.wq_scale / 100.0
    dual_corr = prm.dual_corr / 100.0
    sep_rank = prm.sep_rank
    wq_own = prm.wq_own
    est_skip = prm.est_skip / 100.0
    fit_gain = prm.fit_gain / 100.0
    part_gain = prm.part_gain / 100.0
    cq_scale = prm.cq_scale / 100.0
    plane_always = prm.plane_always
    done_planes = prm.done_planes
    est_resid = prm.est_resid
    fit_gate = prm.fit_gate / 100.0
    grey_early = prm.grey_early / 100.0
    grey_fit = prm.grey_fit
    grey_rounds = prm.grey_rounds
    grey_nudge = prm.grey_nudge
    grey_also = prm.grey_also
    polish = prm.polish
    span_rank = prm.span_rank / 10.0
    nranges = tab.colour.err.shape[0]
    bw = tab.sep.ux.shape[0]
    bh = nt // bw

    # every array the blocks' loop uses, as views without reference counts
    # (_jit.borrow): helpers here take many arrays and run many times a block
    # (the caller keeps the arrays alive)
    sc, chw, tab, blocks, sym, mode_on = borrow((sc, chw, tab, blocks, sym, mode_on))
    (es, ws, fw, pw, x, labels, pres, pslot, pmom, psm, plm, tlum, mmiss, mcode, dchan, serr, gsc, gwh, minbits,
     wq_tab, wq_vals, wq_acc, gwk, win, lw) = sc
    gc1, gc2 = ws.gc1, ws.gc2
    blk = Block(x, chw, srgb)
    etab = EncodeTables(tab.modes, tab.grids, tab.colour, tab.weight)
    modes, ptab, cq_err = tab.modes, tab.parts.ptab, tab.colour.err
    wunq = tab.weight.unq
    g_dims, g_idx, g_wt = tab.grids.dims, tab.grids.idx, tab.grids.wt
    ux, uoff, qyp = tab.sep
    gc1, gc2, gdone, gerr, fam_nv, fam_bits = es.gc1, es.gc2, es.gdone, es.gerr, es.fam_nv, es.fam_bits
    fam_list, fam_extra = es.fam_list, es.fam_extra
    # the preset's families lead every fit's list (mixed ones follow); direct's
    # and base+offset's misses are nothing, the others' are set per fit
    for fam in range(nfam):
        fam_list[fam] = fam
        fam_extra[fam] = 0.0
    c_est, c_mode = es.c_est, es.c_mode
    pgrey, popaque, row = ws.pgrey, ws.popaque, ws.row
    tprod, ttot, mom, e0f, e1f, w1, w2, s1, s2, fsc, runs = fw
    pids = pw.out
    # fields the blocks' loop reads, taken out of their records once (as in
    # _encode_mode: each taking is a call LLVM cannot see through)
    grids, parts, cr_tab = tab.grids, tab.parts, tab.colour.cr_tab
    cems, wnum, wden = ws.cems, ws.num, ws.den
    cqe_tab, cqe_off, wqe, c_fam = es.cqe_tab, es.cqe_off, es.wqe, es.c_fam
    # the modes tried, per plane count, grid by grid in the order the
    # selection passes over them (tab.morder), each grid's first in gst
    gid, ngr, gst = es.gid, es.ngr, es.gst
    for mm in range(nmodes):
        m = tab.morder[mm]
        if mode_on[m]:
            d = modes[m, 2]
            k = es.mcount[d]
            g = modes[m, 0]
            if ngr[d] == 0 or gid[d, ngr[d] - 1] != g:
                gid[d, ngr[d]] = g
                gst[d, ngr[d]] = k
                ngr[d] += 1
            es.mlist[d, k] = m
            es.mbits[d, k] = modes[m, 3]
            es.mwq[d, k] = modes[m, 1]
            es.mord[d, k] = m
            es.mcount[d] += 1
            gwh[d, g_dims[g, 0], g_dims[g, 1]] = 1
            minbits[d] = min(minbits[d], modes[m, 3])
    for d in range(2):
        gst[d, ngr[d]] = es.mcount[d]
    # colour-range error by range + 1 (0: no range fits), for the direct-like
    # families and for base+offset (8-bit rounding only, where the range
    # keeps every bit it uses)
    for r in range(cq_err.shape[0]):
        es.cqe_tab[r + 1] = cq_err[r]
        if r >= OFFSET_MIN_RANGE:
            es.cqe_off[r + 1] = 1.0 / 12.0
    ncand = min(ncand, 64)
    grey_modes(modes, g_dims, mode_on, bw, bh, cr_tab, gwk)
    wq_tables(tab.weight.unq, tab.weight.quant, wq_tab, wq_vals)
    # up to 64 ranked by the clustering; 1024 (every pattern): by line fit alone
    part_cands = part_cands if part_cands >= 1024 else min(part_cands, 64)

    for i in range(nb):
        if i % TILE == 0:
            # the run's first fits and their grid estimates, blocks side by side
            first_tile(blocks, np.int64(i), chw, lw, bw, bh, tab.sep, gwh[0])
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
        if const:
            for jj in range(sym.shape[1]):
                sym[i, jj] = 0
            sym[i, S_KIND] = KIND_VOID
            for c in range(4):
                sym[i, S_VOID + c] = blocks[i, 0, c] * 257
            continue
        best = np.inf
        # polish's winner (mode, partition count, pattern, family, the plane's
        # component) in the scratch: five more scalars live across the
        # blocks' loop took 4x4 `fast` to 1.18x its time, polish or not
        win[0] = -1  # none from the mode search yet
        resid1 = np.inf
        lum_done = False  # tlum and lsum not yet made for this block
        lsum = 0.0
        grey = True
        for t in range(nt):
            if x[t, 0] != x[t, 1] or x[t, 1] != x[t, 2]:
                grey = False
                break
        # a wholly grey block's partitions cost a luminance pair each: its
        # early-outs are the row's share grey_early
        ge = grey_early if grey else 1.0
        # an opaque grey block's one partition: fitted in one dimension
        # (grey.py) in place of the search's one-partition fits, or with
        # grey_also beside them (they reach the decimated grids)
        grey_one_done = False
        if grey and opaque and grey_fit > 0 and gwk.nmodes[0] > 0:
            best = grey_one((x, chw, srgb), (nt, bw, bh), grey_fit, grey_rounds, grey_nudge,
                            (modes, tab.colour.unq, tab.colour.quant, tab.weight.unq, tab.weight.quant, cq_err),
                            gwk, row, (labels, ws.ep, ws.racc))
            # gw.modes is never empty here, so an encoding was made
            for jj in range(sym.shape[1]):
                sym[i, jj] = row[jj]
            grey_one_done = grey_also == 0
            resid1 = 0.0  # texels on the grey line: none off its one line
            if grey_one_done and (max_parts == 1 or best <= ge * early * nt):
                continue  # no second partition would be tried (the loop's first test)
        tile_moments(runs, i % TILE, nt, ttot)
        sxx = ttot[5] + ttot[9] + ttot[12] + ttot[14]
        # good enough: an error this small a share of the block's own
        # variation (weighted, about the mean) ends the block's search
        stop = -1.0
        if enough > 0:
            var = 0.0
            for c in range(4):
                var += ttot[5 + (0, 4, 7, 9)[c]] - ttot[1 + c] * ttot[1 + c] / nt
            stop = enough * var
        if done_err > 0 and (done_planes or not plane_always):
            # for normal maps only where the preset says: their Y plane of
            # its own is worth more than ending a block early
            stop = max(stop, ge * done_err * nt)
        # the components worth a plane of their own: found when a second
        # plane is first reached (most blocks stop before; -1: not yet); none
        # in an opaque grey block, where R, G and B move together (a normal
        # map's RRRG X with its Y in alpha is not opaque)
        ndch = -1 if dual_mode > 0 and not (grey and opaque) else 0
        prev = np.inf  # the best error with one partition fewer than the last count tried
        cbest = np.inf  # the last count's own best (or the bound that ruled a fit out)
        for nparts in range(1, max_parts + 1):
            if nparts > 1 and (best <= ge * early * nt or best <= stop):
                break
            if nparts > 2 and not more_parts(part_gain, best, cbest, prev):
                break  # the last partition added gained too little for another to pay
            if nparts > 1:
                prev = best
            cbest = np.inf
            if nparts == 1 and grey_one_done:
                cbest = best
                continue
            if nparts == 1:
                npid = 1
                pids[0] = 0
            else:
                if nparts == 2:
                    # the per-texel moments, which partitions are fitted from
                    texel_products(x, chw, nt, tprod)
                # an opaque grey block's texels lie on the grey line however
                # they are split, so the line residual below ranks nothing:
                # where more than one pattern is fitted the part_full of least
                # spread about their partitions' means go on to it, else the
                # clustering's first is the one fitted
                flat = grey and opaque
                pcand = min(part_cands, part_full) if flat and part_full == 1 else part_cands
                npid = rank_partitions(x, chw, nt, nparts, kiters, pcand, parts, pw)
                if flat and part_full > 1:
                    npid = flat_best(parts.pmask, nparts, nt, x, pids, npid, part_full, pres)
                # keep the few whose partitions lie closest to lines, ties to
                # the earlier in rank; once part_full are kept, a candidate that
                # cannot come under the last of them is not fitted (line_resid's
                # bound)
                nkeep = 0
                for k in range(npid):
                    q = pids[k]
                    lim = pres[nkeep - 1] if nkeep == part_full else np.inf
                    r = line_resid(parts.pmask[nparts - 2, q], nparts, nt, tprod, ttot, mom, fsc, lim)
                    if r >= lim:
                        continue
                    j = nkeep if nkeep < part_full else nkeep - 1  # full: the last drops out
                    # the kept pattern's moment sums (in mom), for its fits:
                    # a new slot, or the one of the pattern dropped
                    sl = nkeep if nkeep < part_full else pslot[j]
                    for p in range(nparts):
                        for kk in range(16):
                            pmom[sl, p, kk] = mom[p, kk]
                    nkeep = max(nkeep, j + 1)
                    while j > 0 and pres[j - 1] > r:
                        pres[j] = pres[j - 1]
                        pids[j] = pids[j - 1]
                        pslot[j] = pslot[j - 1]
                        j -= 1
                    pres[j] = r
                    pids[j] = q
                    pslot[j] = sl
                npid = nkeep
            for pi in range(npid):
                pid = pids[pi]
                # moments from line_resid beyond one partition; the first
                # fit made for the run, its row -1 - given (flag as np.int64)
                given = np.int64(1 if nparts > 1 else -1 - i % TILE)
                plm_done = False
                if nparts > 1:
                    sl = pslot[pi]
                    for p in range(nparts):
                        for kk in range(16):
                            mom[p, kk] = pmom[sl, p, kk]
                part_labels(x, ptab, nparts, pid, nt, labels, pgrey, popaque)
                # four partitions leave no room for two planes; ndch is at most
                # one component with dual 1, four with dual 2, two with 3
                nplanes = 1 + ((ndch if ndch >= 0 else (dual_mode if dual_mode != 2 else 4)) if nparts < 4 else 0)
                for pl in range(nplanes):
                    if pl > 0 and best <= ge * plane_early * nt and not plane_always:
                        break  # a second plane is not needed either
                    if best <= stop:
                        break
                    if pl > 0:
                        if ndch < 0:
                            ndch = dual_channels(ttot, opaque, dual_mode, dual_corr, dchan, fsc)
                        if pl > ndch:
                            break
                    dual = 1 if pl > 0 else 0
                    ccs = dchan[pl - 1] if dual else 0
                    resid = fit_partitions(x, chw, labels, nparts, nt, dual, ccs, fw, given)
                    if nparts == 1 and pl == 0:
                        resid1 = resid
                    elif fit_gain > 0 and resid > fit_gain * resid1:
                        continue  # too little closer to lines than one partition, one plane
                    if resid >= best:
                        # the texels' distance from their partitions' lines (less
                        # the plane of its own) bounds any encoding from below
                        cbest = min(cbest, resid)
                        continue
                    # the importances' sums (fit_partitions's)
                    ssum1 = fsc[20, 0]
                    ssum2 = fsc[20, 1]
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
                            psm[p] = 0.0
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
                            psm[p] = d2 * mom[p, 0] / 3.0  # the fit left texel counts there
                            smiss += psm[p]
                    # luminance for every partition loses each texel's distance
                    # from grey (weighted), charged in full
                    lmiss = 0.0
                    allgrey = 1
                    for p in range(nparts):
                        if not pgrey[p]:
                            allgrey = 0
                    if nfam > 3 and not allgrey:
                        if not lum_done:
                            # each texel's distance from grey and their sum
                            # (in texel order): the block's, for its every fit
                            wl = chw[0] + chw[1] + chw[2]
                            lsum = 0.0
                            for t in range(nt):
                                lum = (chw[0] * x[t, 0] + chw[1] * x[t, 1] + chw[2] * x[t, 2]) / wl
                                e = 0.0
                                for c in range(3):
                                    d = x[t, c] - lum
                                    e += chw[c] * d * d
                                tlum[t] = e
                                lsum += e
                            lum_done = True
                        lmiss = lsum
                        if mixed and nparts > 1 and not plm_done:
                            # per partition (mixed_families'): the pattern's, for both planes
                            for p in range(nparts):
                                plm[p] = 0.0
                            for t in range(nt):
                                plm[labels[t]] += tlum[t]
                            plm_done = True
                    # base+offset reaches 31 levels from the base, and pays
                    # only when the range keeps its bits
                    offset_ok = nfam > 2
                    for p in range(nparts):
                        for c in range(4):
                            if abs(e1f[p, c] - e0f[p, c]) > 30.5:
                                offset_ok = False
                    # the families tried: the preset's, then with each colour
                    # partition its own kind
                    nfl = nfam
                    fam_extra[FAM_SCALE] = smiss
                    if nfam > 3:
                        fam_extra[FAM_LUMA] = lmiss
                    if mixed and nparts > 1:
                        nfl = mixed_families(nparts, pgrey, psm, plm, nfam > 3 and not allgrey, fam_list, fam_extra,
                                             nfl, mmiss, mcode)
                    # CEMs per family depend on the partitions only
                    for fi in range(nfl):
                        fam = fam_list[fi]
                        nv, same = choose_cems(fam, nparts, pgrey, popaque, cems)
                        scl = 1 if fam == FAM_DIRECT else 0
                        for p in range(nparts):
                            if cems[p] != 0 and cems[p] != 4:
                                scl = 1
                        if fam == FAM_LUMA:
                            scl = 1 - allgrey  # with every partition grey it is direct
                        # a family other than direct only when some partition
                        # differs from direct
                        fam_nv[fam] = nv if (scl and nv <= 18) else -1
                        fam_bits[fam] = 128 - config_bits(nparts, same, dual)
                    cscale = cq_scale * nt * wsum
                    if est_resid and est_skip > 0 and best < np.inf:
                        # no candidate's estimate is below its family's colour
                        # error at the most colour bits a mode leaves: when even
                        # that, with the line residual, is past est_skip, the
                        # fit's every candidate would be skipped
                        low = np.inf
                        for fi in range(nfl):
                            fam = fam_list[fi]
                            nv = fam_nv[fam]
                            if nv < 0 or (fam == FAM_OFFSET and not offset_ok):
                                continue
                            off = 1 if fam == FAM_OFFSET else 0
                            ce = colour_range_err(cr_tab, fam_bits[fam] - minbits[dual], nv, off, cqe_tab, cqe_off)
                            low = min(low, cscale * ce + fam_extra[fam])
                        if low + resid > est_skip * best:
                            continue
                    # the estimate leaves out the texels' distance from their lines
                    eres = resid if est_resid else 0.0
                    # every grid's error: the separable estimate, or decimated
                    # (gdone per grid: 2 decimated into gc1/gc2 with the row's
                    # steps, 1 otherwise); partitions of unequal spans
                    # (fit_partitions's ranges, fsc[16:20]) decimated (span_rank)
                    sep_fit = sep_rank
                    if sep_rank and span_rank > 0 and nparts > 1:
                        smin = np.inf
                        smax = 0.0
                        for p in range(nparts):
                            sp = fsc[16 + p, 1] - fsc[16 + p, 0]
                            smin = min(smin, sp)
                            smax = max(smax, sp)
                        sep_fit = smax <= span_rank * smin
                    rk_iters = min(decim_iters, RANK_ITERS) if sep_rank else decim_iters
                    if sep_fit:
                        for ii in range(2, bw + 1):
                            for jj in range(2, bh + 1):
                                serr[ii, jj] = 0.0
                        # the first fit's: made for the run (its row of lanes.out)
                        lane = -1 - given if (given < 0 and not dual) else np.int64(-1)
                        sep_errs(w1, s1, bw, bh, ux, uoff, qyp, serr, gsc, gwh[dual], lane, runs)
                        if dual:
                            sep_errs(w2, s2, bw, bh, ux, uoff, qyp, serr, gsc, gwh[dual], np.int64(-1), runs)
                        for g in range(ngrid):
                            gerr[g] = max(serr[g_dims[g, 0], g_dims[g, 1]], 0.0)
                            gdone[g] = 1
                    else:
                        for g in range(ngrid):
                            if not gwh[dual, g_dims[g, 0], g_dims[g, 1]]:
                                continue
                            decimate(grids, g, nt, w1, s1, rk_iters, gc1[g], wnum, wden)
                            gerr[g] = decim_err(g_idx[g], g_wt[g], nt, gc1[g], w1, s1)
                            if dual:
                                decimate(grids, g, nt, w2, s2, rk_iters, gc2[g], wnum, wden)
                                gerr[g] += decim_err(g_idx[g], g_wt[g], nt, gc2[g], w2, s2)
                            gdone[g] = 2 if rk_iters == decim_iters else 1
                    skip = est_skip * best - eres if est_skip > 0 else np.inf
                    # with no refinement round a candidate past skip is never
                    # encoded, so the selection leaves it out (cap: skip widened
                    # past any rounding of the test below)
                    cap = np.inf
                    if refine == 0 and skip < np.inf:
                        cap = skip + 1e-9 * (est_skip * best + eres)
                    run = True
                    if sep_rank and wq_own:
                        # a mode's estimate is at least its grid's error: when
                        # every grid's is past skip, the selection would find
                        # none (and needs no weight ranges' errors to say so)
                        glow = np.inf
                        for gi in range(ngr[dual]):
                            glow = min(glow, gerr[gid[dual, gi]])
                        run = glow <= skip
                        if run and wq_own == 2:
                            refit_wq_err(w1, s1, w2, s2, labels, nparts, nt, dual, wq_vals, wqe, wq_acc)
                        elif run:
                            own_wq_err(w1, s1, w2, s2, nt, dual, wq_tab, wqe)
                    nfound = 0
                    if run:
                        nfound = select_modes(dual, nfl, ncand, cscale, (ssum1, ssum2),
                                              offset_ok, wq_scale, wq_own, sep_rank, skip, cap, tab, es)
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
                        if est_skip > 0 and c_est[kk] + eres > est_skip * best:
                            continue  # the estimate says this cannot win
                        if best <= stop:
                            break
                        m = c_mode[kk]
                        g = modes[m, 0]
                        if gdone[g] == 1:
                            # ranked by the separable estimate: decimate for real
                            decimate(grids, g, nt, w1, s1, decim_iters, gc1[g], wnum, wden)
                            if dual:
                                decimate(grids, g, nt, w2, s2, decim_iters, gc2[g], wnum, wden)
                            gdone[g] = 2
                        # realign only the encodings that can be kept
                        ra = realign if (rounds > 0 or refine == 0) else 0
                        lim = fit_gate * best if fit_gate > 0 else np.inf
                        err = _encode_mode(blk, labels, nparts, pid, m, c_fam[kk], ccs, rounds, ra,
                                           decim_iters, (lim, sxx), etab, ws)
                        if err < fbest:
                            fbest = err
                            fk = kk
                        cbest = min(cbest, err)
                        if err < best:
                            best = err
                            if polish > 0:
                                win[0], win[1], win[2], win[3], win[4] = m, nparts, pid, c_fam[kk], ccs
                            for jj in range(sym.shape[1]):  # the whole row (SYM_LEN)
                                sym[i, jj] = row[jj]
        if polish > 0 and win[0] >= 0 and best > 0:
            b_mode, b_np, b_pid, b_fam, b_ccs = win[0], win[1], win[2], win[3], win[4]
            # refinement rounds for the block's winner only, from its own grid
            # weights (`refine` on each fit's best costs a round per fit and
            # gained less: docs/astc.md, "Polishing the winner")
            g = modes[b_mode, 0]
            wq = modes[b_mode, 1]
            stride = 2 if modes[b_mode, 2] else 1
            part_labels(x, ptab, b_np, b_pid, nt, labels, pgrey, popaque)
            for j in range(g_dims[g, 0] * g_dims[g, 1]):
                gc1[g, j] = wunq[wq, sym[i, S_WEIGHTS + j * stride]] / 64.0
                if stride == 2:
                    gc2[g, j] = wunq[wq, sym[i, S_WEIGHTS + j * stride + 1]] / 64.0
            err = _encode_mode(blk, labels, b_np, b_pid, b_mode, b_fam, b_ccs, polish, realign, decim_iters,
                               (np.inf, sxx), etab, ws)
            if err < best:
                best = err
                for jj in range(sym.shape[1]):
                    sym[i, jj] = row[jj]
        if best == np.inf:
            # cannot happen for legal tables; fall back to the block's mean as void extent
            for jj in range(sym.shape[1]):
                sym[i, jj] = 0
            sym[i, S_KIND] = KIND_VOID
            for c in range(4):
                acc = 0.0
                for t in range(nt):
                    acc += x[t, c]
                sym[i, S_VOID + c] = int(acc / nt + 0.5) * 257
