"""ASTC search: the mode estimate. Every (block mode, CEM family) pair of a
fit gets a cheap error estimate, and the best few are kept for a real
encoding."""

from collections import namedtuple

import numpy as np

from ...._jit import jit_inner
from .endpoints import FAM_OFFSET
from .grid import grid_quant_err

# one thread's scratch for the mode estimate: the modes the preset tries by plane count (mlist, mcount,
# mbits (2, modes)), per grid whether and how its error is known (gdone, gerr) and its decimated weights
# per plane (gc1, gc2 (grids, 64)), the CEM families tried (fam_list) and per family (N_FAMILIES) its
# colour value count and bits (fam_nv, fam_bits) and what the family itself misses (fam_extra),
# the colour-range error tables (cqe_tab, cqe_off), per mode the estimates (mest, fest) and the
# candidates kept (c_est, c_mode, c_fam (64,)), and per weight range the quantisation error of the fit's
# own ideal weights (wqe (12,), own_wq_err), and a cache of the modes' colour-range errors (ckey (2, CSLOTS)
# int64, -1 when empty; cval (2, CSLOTS, modes); cnext (2,) int64: the slot filled next, per plane count)
EstWork = namedtuple("EstWork", "mlist mcount mbits gdone gerr gc1 gc2 fam_list fam_nv fam_bits fam_extra cqe_tab "
                     "cqe_off mest fest c_est c_mode c_fam wqe ckey cval cnext")
# (colour bits, value count, table) combinations whose per-mode colour-range
# errors a call keeps: a block of one partition uses three, of two a few more
CSLOTS = 16


@jit_inner(inline="always")
def colour_range_err(cr_tab, bits, nv, off, cqe_tab, cqe_off):
    """The estimated error of the colour range `bits` leave for nv values:
    base+offset's table (off 1) or the direct-like families' (off 0)."""
    cq = cr_tab[max(bits, 0), nv]
    return cqe_off[cq + 1] if off else cqe_tab[cq + 1]


@jit_inner
def wq_err_table(wunq, wquant, out):
    """out (65, ranges): per weight 0..64 (rounded as quantise_grid rounds)
    and range, the squared error (weights 0..1) of its quantisation."""
    for v in range(65):
        for wq in range(out.shape[1]):
            d = (wunq[wq, wquant[wq, v]] - v) / 64.0
            out[v, wq] = d * d


@jit_inner
def own_wq_err(w1, s1, w2, s2, nt, dual, qtab, wqe):
    """Per weight range, the error (weighted by each texel's importance) of
    quantising the fit's ideal texel weights into wqe, from qtab
    (wq_err_table; each weight taken at its nearest 64th): a block of two
    colours (weights 0 and 1) loses nothing to two levels, where the range's
    average says it loses the most."""
    nr = wqe.shape[0]
    for wq in range(nr):
        wqe[wq] = 0.0
    for t in range(nt):
        v = min(max(int(w1[t] * 64.0 + 0.5), 0), 64)
        st = s1[t]
        for wq in range(nr):
            wqe[wq] += st * qtab[v, wq]
        if dual:
            v = min(max(int(w2[t] * 64.0 + 0.5), 0), 64)
            st = s2[t]
            for wq in range(nr):
                wqe[wq] += st * qtab[v, wq]


@jit_inner(inline="always")
def select_modes(dual, nfam, ncand, cscale, sums, offset_ok, wq_scale, wq_own, skip, tab, es):
    """The ncand best (block mode, CEM family) pairs of a fit by their
    estimated error, best first, in c_est, c_mode and c_fam; returns how many.
    A mode's estimate is its grid's error plus the weight quantisation error
    of its range: the decimated grid's own when it is known (gdone 2: a
    two-colour block loses nothing to two levels), else, with wq_own, that of
    the fit's ideal texel weights (es.wqe, own_wq_err), else the range's
    average (each scaled by wq_scale); each of the nfam families in
    es.fam_list adds the error of the colour range the mode's leftover bits
    allow (cscale times a table's entry) and what the family itself misses
    (fam_extra: base+scale's and luminance's losses). Returns 0 at once when
    every mode's estimate is above `skip` (the caller would skip them all:
    families only add to it). sums: the fit's (ssum1, ssum2); tab: the size's
    BlockTables; es: EstWork."""
    g_dims, modes, cr_tab = tab.grids.dims, tab.modes, tab.colour.cr_tab
    wunq, wquant, wq_err = tab.weight.unq, tab.weight.quant, tab.weight.err
    (mlist, mcount, mbits, gdone, gerr, gc1, gc2, fam_list, fam_nv, fam_bits, fam_extra, cqe_tab, cqe_off, mest,
     fest, c_est, c_mode, c_fam, wqe, ckey, cval, cnext) = es
    ssum1, ssum2 = sums
    nml = mcount[dual]
    ssum = ssum1 + ssum2
    for mi in range(nml):
        m = mlist[dual, mi]
        g = modes[m, 0]
        wq = modes[m, 1]
        if gdone[g] == 2:
            ng = g_dims[g, 0] * g_dims[g, 1]
            qe = ssum1 / ng * grid_quant_err(gc1[g], ng, wq, wunq, wquant)
            if dual:
                qe += ssum2 / ng * grid_quant_err(gc2[g], ng, wq, wunq, wquant)
            mest[mi] = gerr[g] + qe * wq_scale
        elif wq_own:
            mest[mi] = gerr[g] + wqe[wq] * wq_scale
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
    for fi in range(nfam):
        fam = fam_list[fi]
        nv = fam_nv[fam]
        if nv < 0 or (fam == FAM_OFFSET and not offset_ok):
            continue
        bits = fam_bits[fam]
        extra = fam_extra[fam]
        # each mode's colour-range error depends on the bits left, the value
        # count and the table alone: made once per call for each combination
        off = 1 if fam == FAM_OFFSET else 0
        key = (bits * 32 + nv) * 2 + off
        slot = -1
        for k in range(CSLOTS):
            if ckey[dual, k] == key:
                slot = k
                break
        if slot < 0:
            slot = cnext[dual]
            cnext[dual] = (slot + 1) % CSLOTS
            ckey[dual, slot] = key
            for mi in range(nml):
                cval[dual, slot, mi] = colour_range_err(cr_tab, bits - mbits[dual, mi], nv, off, cqe_tab, cqe_off)
        cv = cval[dual, slot]
        for mi in range(nml):
            fest[mi] = mest[mi] + cscale * cv[mi] + extra
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
