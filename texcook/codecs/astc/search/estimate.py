"""ASTC search: the mode estimate. Every (block mode, CEM family) pair of a
fit gets a cheap error estimate, and the best few are kept for a real
encoding."""

from collections import namedtuple

import numpy as np

from ...._jit import jit_inner
from .endpoints import FAM_OFFSET
from .grid import grid_quant_err

# _nrt=False on the helpers called per fit or candidate: no reference
# counting of their array arguments (why: grid.py)

# one thread's scratch for the mode estimate: the modes the preset tries by plane count (mlist, mcount,
# mbits (2, modes)), per grid whether and how its error is known (gdone, gerr) and its decimated weights
# per plane (gc1, gc2 (grids, 64)), the CEM families tried (fam_list) and per family (N_FAMILIES) its
# colour value count and bits (fam_nv, fam_bits) and what the family itself misses (fam_extra),
# the colour-range error tables (cqe_tab, cqe_off), per mode the estimates (mest) and the
# candidates kept (c_est, c_mode, c_fam (64,)), and per weight range the quantisation error of the fit's
# own ideal weights (wqe (12,), own_wq_err), and a cache of the modes' colour-range errors (ckey (2, CSLOTS)
# int64, -1 when empty; cval (2, CSLOTS, modes); cnext (2,) int64: the slot filled next, per plane count);
# the modes lie grouped by grid (in the size's tables' morder): per plane count the grids with modes (gid (2,
# grids), ngr (2,)), where each one's modes start (gst (2, grids + 1)), and per mode its weight range (mwq (2,
# modes)) and its row in the mode table (mord (2, modes)); per grid (by place) the least estimate of its modes in
# a fit (gmin (grids,)) and per cache slot the least colour-range error of its modes (cvmin (2, CSLOTS, grids))
# and per mode the least of its own and its grid's later modes' (cvsuf (2, CSLOTS, modes)); per candidate kept,
# its family's place and mode's row (c_key (64,)), which break ties as passing over the pairs in the table's
# order would; gsel (grids,) int64 scratch
EstWork = namedtuple("EstWork", "mlist mcount mbits gdone gerr gc1 gc2 fam_list fam_nv fam_bits fam_extra cqe_tab "
                     "cqe_off mest c_est c_mode c_fam wqe ckey cval cnext gid ngr gst mwq mord gmin cvmin c_key "
                     "cvsuf gsel")
# (colour bits, value count, table) combinations whose per-mode colour-range
# errors a call keeps: a block of one partition uses three, of two a few more
CSLOTS = 16
# a candidate's tie key: its family's place in the list times this, plus its mode's row
KEY_FAM = 1 << 16


@jit_inner(inline="always")
def colour_range_err(cr_tab, bits, nv, off, cqe_tab, cqe_off):
    """The estimated error of the colour range `bits` leave for nv values:
    base+offset's table (off 1) or the direct-like families' (off 0)."""
    cq = cr_tab[max(bits, 0), nv]
    return cqe_off[cq + 1] if off else cqe_tab[cq + 1]


@jit_inner
def wq_tables(wunq, wquant, err, val):
    """Per weight 0..64 (rounded as quantise_grid rounds) and range (65,
    ranges each): the value its quantisation decodes to (val, 0..1) and the
    squared error of that (err)."""
    for v in range(65):
        for wq in range(err.shape[1]):
            q = wunq[wq, wquant[wq, v]] / 64.0
            val[v, wq] = q
            d = q - v / 64.0  # both exact in binary: the difference is too
            err[v, wq] = d * d


@jit_inner(_nrt=False)
def refit_wq_err(w1, s1, w2, s2, labels, nparts, nt, dual, vtab, wqe, acc):
    """As own_wq_err, with the endpoints refitted to the quantised weights:
    per partition and plane, what is left of the ideal weights after the
    least-squares affine map of their quantised values onto them (weighted
    by each texel's importance; vtab: wq_tables' values). For weights spread
    evenly two levels lose a quarter of what fixed endpoints would, so noisy
    blocks no longer rank their coarse ranges last. acc (4, 4, ranges)
    scratch."""
    nr = wqe.shape[0]
    for wq in range(nr):
        wqe[wq] = 0.0
    for pl in range(1 + dual):
        w = w2 if pl else w1
        s = s2 if pl else s1
        # per partition: rows 0-2 per range the sums of the quantised weights
        # (q, q^2, w q), row 3 the texels' own (n, w, w^2); ranges innermost,
        # so each texel's additions run over contiguous rows of vtab and acc
        for p in range(nparts):
            for k in range(4):
                for wq in range(nr):
                    acc[p, k, wq] = 0.0
        for t in range(nt):
            p = labels[t]
            wt = w[t]
            st = s[t]
            sw = st * wt
            acc[p, 3, 0] += st
            acc[p, 3, 1] += sw
            acc[p, 3, 2] += sw * wt
            v = min(max(int(wt * 64.0 + 0.5), 0), 64)
            a0 = acc[p, 0]
            a1 = acc[p, 1]
            a2 = acc[p, 2]
            qv = vtab[v]
            for wq in range(nr):
                q = qv[wq]
                sq = st * q
                a0[wq] += sq
                a1[wq] += sq * q
                a2[wq] += sw * q
        for p in range(nparts):
            n = acc[p, 3, 0]
            sw = acc[p, 3, 1]
            sww = acc[p, 3, 2]
            if n <= 0:
                continue
            cww = sww - sw * sw / n
            for wq in range(nr):
                sq = acc[p, 0, wq]
                sqq = acc[p, 1, wq]
                swq = acc[p, 2, wq]
                cqq = sqq - sq * sq / n
                cwq = swq - sw * sq / n
                # one level reached by every texel: no map but the mean
                e = cww - cwq * cwq / cqq if cqq > 1e-12 * n else cww
                wqe[wq] += max(e, 0.0)


@jit_inner(_nrt=False)
def own_wq_err(w1, s1, w2, s2, nt, dual, qtab, wqe):
    """Per weight range, the error (weighted by each texel's importance) of
    quantising the fit's ideal texel weights into wqe, from qtab
    (wq_tables' errors; each weight taken at its nearest 64th): a block of two
    colours (weights 0 and 1) loses nothing to two levels, where the range's
    average says it loses the most."""
    nr = wqe.shape[0]
    for wq in range(nr):
        wqe[wq] = 0.0
    # two texel weights per pass over the ranges (a texel's two planes, or
    # two texels), added in the order one at a time would: half the stores
    # and reloads of wqe that each addition otherwise waits on
    t = 0
    while t < nt:
        va = np.uint64(min(max(int(w1[t] * 64.0 + 0.5), 0), 64))
        sa = s1[t]
        if dual:
            vb = np.uint64(min(max(int(w2[t] * 64.0 + 0.5), 0), 64))
            sb = s2[t]
            t += 1
        elif t + 1 < nt:
            vb = np.uint64(min(max(int(w1[t + 1] * 64.0 + 0.5), 0), 64))
            sb = s1[t + 1]
            t += 2
        else:
            for wq in range(nr):
                wqe[wq] += sa * qtab[va, wq]
            break
        for wq in range(nr):
            wqe[wq] = (wqe[wq] + sa * qtab[va, wq]) + sb * qtab[vb, wq]


@jit_inner(inline="always")
def _colour_slot(dual, fam, bits, nv, cr_tab, cqe_tab, cqe_off, mlists, cache):
    """The cache slot of the colour-range errors of family fam's modes (of
    dual + 1 planes) with `bits` before the weights and nv colour values:
    they depend on those and the table alone, so they are made once per
    kernel call for each combination (cval, with per grid their least,
    cvmin, and per mode the least from it to its grid's last, cvsuf).
    mlists: EstWork's (mbits, gst, ngr); cache: its (ckey, cval, cnext,
    cvmin, cvsuf): the arrays passed apart, as the record whole would be one
    more copy of it for the kernel's compilation to take apart."""
    mbits, gst, ngr = mlists
    ckey, cval, cnext, cvmin, cvsuf = cache
    off = 1 if fam == FAM_OFFSET else 0
    key = (bits * 32 + nv) * 2 + off
    for k in range(CSLOTS):
        if ckey[dual, k] == key:
            return k
    slot = cnext[dual]
    cnext[dual] = (slot + 1) % CSLOTS
    ckey[dual, slot] = key
    for gi in range(ngr[dual]):
        for mi in range(gst[dual, gi], gst[dual, gi + 1]):
            cval[dual, slot, mi] = colour_range_err(cr_tab, bits - mbits[dual, mi], nv, off, cqe_tab, cqe_off)
        cl = np.inf
        for mi in range(gst[dual, gi + 1] - 1, gst[dual, gi] - 1, -1):
            cl = min(cl, cval[dual, slot, mi])
            cvsuf[dual, slot, mi] = cl
        cvmin[dual, slot, gi] = cl
    return slot


@jit_inner(inline="always")
def select_modes(dual, nfam, ncand, cscale, sums, offset_ok, wq_scale, wq_own, sep, skip, cap, tab, ws):
    """The ncand best (block mode, CEM family) pairs of a fit by their
    estimated error, best first, in c_est, c_mode and c_fam; returns how many.
    A mode's estimate is its grid's error plus the weight quantisation error
    of its range: the decimated grid's own when it is known (gdone 2: a
    two-colour block loses nothing to two levels), else, with wq_own, that of
    the fit's ideal texel weights (ws.wqe, own_wq_err), else the range's
    average (each scaled by wq_scale); each of the nfam families in
    ws.fam_list adds the error of the colour range the mode's leftover bits
    allow (cscale times a table's entry) and what the family itself misses
    (fam_extra: base+scale's and luminance's losses). Returns 0 at once when
    every mode's estimate is above `skip` (the caller would skip them all:
    families only add to it). A pair whose estimate is at or above `cap` is
    left out: the caller passes one only where it would never encode such a
    pair (inf elsewhere). sums: the fit's (ssum1, ssum2); sep 1 when every
    grid's error is the separable estimate (gdone 1); tab: the size's
    BlockTables; ws: EstWork."""
    g_dims, cr_tab = tab.grids.dims, tab.colour.cr_tab
    wunq, wquant, wq_err = tab.weight.unq, tab.weight.quant, tab.weight.err
    (mlist, mcount, mbits, gdone, gerr, gc1, gc2, fam_list, fam_nv, fam_bits, fam_extra, cqe_tab, cqe_off, mest,
     c_est, c_mode, c_fam, wqe, ckey, cval, cnext, gid, ngr, gst, mwq, mord, gmin, cvmin, c_key, cvsuf, gsel) = ws
    ssum1, ssum2 = sums
    ssum = ssum1 + ssum2
    gd, gs, mw, mo = gid[dual], gst[dual], mwq[dual], mord[dual]
    ngr_d = ngr[dual]
    low = np.inf
    # with the fit's own weight-range errors and no grid decimated (the
    # separable estimate: every grid's gdone 1) a mode's estimate is made
    # where the pairs are ranked, and a grid's least from its ranges' least
    # error: every rounded operation here is monotonic in its operands, so
    # that is the least of its modes' estimates, bit for bit
    lazy = wq_own and sep
    for gi in range(ngr_d):
        g = gd[gi]
        ge = gerr[g]
        if lazy:
            # two minima, so that they do not wait on each other (exact)
            wa = np.inf
            wb = np.inf
            mi = gs[gi]
            while mi + 1 < gs[gi + 1]:
                wa = min(wa, wqe[np.uint64(mw[np.uint64(mi)])])
                wb = min(wb, wqe[np.uint64(mw[np.uint64(mi + 1)])])
                mi += 2
            if mi < gs[gi + 1]:
                wa = min(wa, wqe[np.uint64(mw[np.uint64(mi)])])
            gl = ge + min(wa, wb) * wq_scale
            gmin[gi] = gl
            low = min(low, gl)
            continue
        dec = gdone[g] == 2
        ng = g_dims[g, 0] * g_dims[g, 1]
        gl = np.inf
        for mi in range(gs[gi], gs[gi + 1]):
            u = np.uint64(mi)
            wq = mw[u]
            if dec:
                qe = ssum1 / ng * grid_quant_err(gc1[g], ng, wq, wunq, wquant)
                if dual:
                    qe += ssum2 / ng * grid_quant_err(gc2[g], ng, wq, wunq, wquant)
                e = ge + qe * wq_scale
            elif wq_own:
                e = ge + wqe[np.uint64(wq)] * wq_scale
            else:
                e = ge + ssum * wq_err[wq] * wq_scale
            mest[u] = e
            gl = min(gl, e)
        gmin[gi] = gl
        low = min(low, gl)
    if low > skip:
        return 0
    # (the hot loops index as np.uint64: numba wraps no negative index then)
    # a pair is kept while its estimate is under the last kept one's (thr,
    # once ncand are kept), an equal one while it comes first in the order of
    # families and of the mode table (c_key): the pairs that passing over them
    # in that order would keep
    nfound = 0
    thr = np.inf
    lim = cap  # min(thr, cap)
    for fi in range(nfam):
        fam = fam_list[fi]
        nv = fam_nv[fam]
        if nv < 0 or (fam == FAM_OFFSET and not offset_ok):
            continue
        bits = fam_bits[fam]
        extra = fam_extra[fam]
        slot = _colour_slot(dual, fam, bits, nv, cr_tab, cqe_tab, cqe_off, (mbits, gst, ngr),
                            (ckey, cval, cnext, cvmin, cvsuf))
        cv = cval[dual, slot]
        cvm = cvmin[dual, slot]
        cs = cvsuf[dual, slot]
        # a bound on a grid's every estimate (each term is at least its least
        # over the grid's modes, the colour range's scale >= 0); the grids
        # whose bound can enter the list now listed first without a branch
        # (a few of them), then passed over again as the list fills
        nsel = 0
        for gi in range(ngr_d):
            bound = gmin[gi] + cscale * cvm[gi] + extra
            gsel[nsel] = gi
            nsel += 1 if (bound <= thr and bound < cap) else 0
        for k in range(nsel):
            gi = gsel[k]
            bound = gmin[gi] + cscale * cvm[gi] + extra
            if bound > thr or bound >= cap:
                continue
            ge = gerr[gd[gi]]
            for mi in range(gs[gi], gs[gi + 1]):
                u = np.uint64(mi)
                # the bound of this mode and the grid's later ones: past
                # it, none of them can enter
                tail = gmin[gi] + cscale * cs[u] + extra
                if tail > thr or tail >= cap:
                    break
                e = ge + wqe[np.uint64(mw[u])] * wq_scale if lazy else mest[u]
                est = e + cscale * cv[u] + extra
                if not est < lim:
                    # an equal estimate only in place of a later pair
                    if not (est == thr and nfound == ncand and est < cap):
                        continue
                    if fi * KEY_FAM + mo[u] > c_key[ncand - 1]:
                        continue
                ck = fi * KEY_FAM + mo[u]
                if nfound == ncand:
                    pos = ncand - 1
                else:
                    pos = nfound
                    nfound += 1
                while pos > 0 and (c_est[pos - 1] > est or (c_est[pos - 1] == est and c_key[pos - 1] > ck)):
                    c_est[pos] = c_est[pos - 1]
                    c_mode[pos] = c_mode[pos - 1]
                    c_fam[pos] = c_fam[pos - 1]
                    c_key[pos] = c_key[pos - 1]
                    pos -= 1
                c_est[pos] = est
                c_mode[pos] = mlist[dual, mi]
                c_fam[pos] = fam
                c_key[pos] = ck
                if nfound == ncand:
                    thr = c_est[ncand - 1]
                    lim = min(thr, cap)
    return nfound
