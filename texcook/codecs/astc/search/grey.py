"""ASTC search: an opaque grey block (R = G = B in every texel, alpha 255) as
one luminance partition (CEM 0) on the block's own weight grid, fitted in one
dimension.

Such a block's texels lie on the grey line whatever the fit, so the general
search's principal axes, line residuals and grid estimates tell its one-
partition encodings nothing apart; what does is the weight range against the
colour range its leftover bits allow. Each weight range is ranked by the
error it is expected to leave, and the best few are encoded exactly: endpoints
from the block's extremes, every texel's nearest weight level by the decoder's
arithmetic, then rounds of the search's least-squares refit to those
weights, and the best one's endpoints moved a level at a time while that
helps."""

from collections import namedtuple

import numpy as np

from ...._jit import jit_inner
from ..modes import config_bits
from ..quant import RANGE_LEVELS
from ..symbolic import (
    KIND_NORMAL,
    S_CEM,
    S_CQUANT,
    S_ENDPOINTS,
    S_GRID_H,
    S_GRID_W,
    S_KIND,
    S_PARTS,
    S_WEIGHTS,
    S_WQUANT,
)
from .endpoints import expand, quant_endpoints
from .fit import refit
from .realign import STEP_C, STEP_W

# per block: the luminances v, each texel's weight code and weight (codes,
# wt), the best encoding's (bcodes) and each mode's ranking estimate (est);
# per call: the full grid's single-plane modes the preset tries with a legal
# colour range for CEM 0 (modes, their count in nmodes[0]), each one's colour
# range (cq) and its weight range's steps, levels less one (steps)
GreyWork = namedtuple("GreyWork", "v codes wt bcodes modes nmodes est cq steps")


def grey_work(nt, nmodes):
    """A thread's GreyWork for blocks of nt texels and a mode table of nmodes rows."""
    return GreyWork(np.zeros(nt, np.int64), np.zeros(nt, np.int64), np.zeros(nt, np.int64), np.zeros(nt, np.int64),
                    np.zeros(nmodes, np.int64), np.zeros(1, np.int64), np.zeros(nmodes), np.zeros(nmodes, np.int64),
                    np.zeros(nmodes))


@jit_inner(_nrt=False)
def grey_modes(modes, g_dims, mode_on, bw, bh, cr_tab, gw):
    """The single-plane modes on the bw x bh grid that mode_on tries and that
    leave a legal colour range for one CEM 0 partition, into gw.modes (their
    count in gw.nmodes[0]), with that range (gw.cq) and the weight range's
    steps (gw.steps): what grey_one needs of a mode, the same for every
    block."""
    cbits = 128 - config_bits(1, 1, 0)
    n = 0
    for m in range(modes.shape[0]):
        g = modes[m, 0]
        if mode_on[m] and modes[m, 2] == 0 and g_dims[g, 0] == bw and g_dims[g, 1] == bh:
            cq = cr_tab[max(cbits - modes[m, 3], 0), 2]
            if cq >= 0:
                gw.modes[n] = m
                gw.cq[n] = cq
                gw.steps[n] = RANGE_LEVELS[modes[m, 1]] - 1
                n += 1
    gw.nmodes[0] = n


@jit_inner(inline="always")
def _lum(e0, e1, w):
    """The decoder's 8-bit luminance at weight w (0..64) between 16-bit
    endpoints e0, e1."""
    return (e0 + (((e1 - e0) * w + 32) >> 6)) >> 8


@jit_inner(_nrt=False)
def _weights(v, nt, e0, e1, wq, wunq, wquant, codes, wt):
    """Every texel's weight code of range wq whose decoded luminance is
    nearest v[t] (codes, wt updated): the level nearest the ideal weight, or
    the next one the way the decoded value misses, where the decoder's
    rounding makes that closer. Returns the summed squared error."""
    err = 0
    span = e1 - e0
    # the 16-bit value decoding to v[t] is 256 v + 128 at its middle
    scale = 64.0 / span if span != 0 else 0.0
    off = 128.0 - e0
    stw, stc = STEP_W[wq], STEP_C[wq]
    wq_u = np.uint64(wq)
    for t in range(nt):
        wi = min(max((256.0 * v[t] + off) * scale, 0.0), 64.0)
        k = wquant[wq_u, np.uint64(int(wi + 0.5))]
        w = wunq[wq_u, np.uint64(k)]
        d = _lum(e0, e1, w) - v[t]
        e = d * d
        if d != 0:
            # a weight step up moves the value the way of the span
            up = np.uint64(1 if (d < 0) == (span > 0) else 0)
            k2 = stc[up, np.uint64(k)]
            if k2 >= 0:
                w2 = stw[up, np.uint64(k)]
                d = _lum(e0, e1, w2) - v[t]
                if d * d < e:
                    e = d * d
                    k = k2
                    w = w2
        codes[t] = k
        wt[t] = w
        err += e
    return err


@jit_inner(inline="always")
def _next_level(unq, quant, k, d):
    """The code of the colour level next to code k's value in direction d
    (-1 down, 1 up; 0: k itself), or -1 past the range's ends: the nearest
    code of the values beyond it (trit and quint codes are not in value
    order)."""
    if d == 0:
        return k
    v = unq[k] + d
    while 0 <= v <= 255:
        c = quant[v]
        if c != k:
            return c
        v += d
    return -1


@jit_inner(_nrt=False)
def grey_one(blk, dims, tries, rounds, nudge, tables, gw, row, fit):
    """Encode an opaque grey block as one CEM 0 partition on the full grid:
    the `tries` weight ranges of gw.modes (grey_modes) with the least expected error, each
    from the block's extremes and then `rounds` refits (the search's own:
    least-squares endpoints for the weights, quantised as CEM 0); the best
    then `nudge` passes of its luminances a level either way. The best
    goes into row (a symbolic row); returns its weighted squared error (inf
    when gw.modes is empty). blk: (x (nt, 4), chw, srgb); dims: (nt, bw, bh);
    tables: (modes, cunq, cquant, wunq, wquant, cq_err) of the size's
    BlockTables; fit: (labels, ep, racc), the search's scratch for a refit
    (labels (nt,) set to 0 here, ep the EndpointWork, racc refit's sums)."""
    x, chw, srgb = blk
    nt, bw, bh = dims
    modes, cunq, cquant, wunq, wquant, cq_err = tables
    labels, ep, racc = fit
    for t in range(nt):
        labels[t] = 0
    zero = np.int64(0)
    v, codes, wt, bcodes, gmodes, est, gcq, steps = gw.v, gw.codes, gw.wt, gw.bcodes, gw.modes, gw.est, gw.cq, gw.steps
    nm = gw.nmodes[0]
    lo = 255
    hi = 0
    for t in range(nt):
        v[t] = np.int64(x[t, 0])
        lo = min(lo, v[t])
        hi = max(hi, v[t])
    span = float(hi - lo)
    # expected error per texel: rounding to the weight range's steps across
    # the block's span, and the colour range's own rounding
    for i in range(nm):
        step = span / steps[i]
        est[i] = step * step / 12.0 + cq_err[gcq[i]]
    wl = chw[0] + chw[1] + chw[2]
    best = np.inf
    bk0 = bk1 = bwq = bcq = 0
    for _ in range(min(tries, nm)):
        j = -1
        for i in range(nm):
            if est[i] < np.inf and (j < 0 or est[i] < est[j]):
                j = i
        if j < 0:
            break
        est[j] = np.inf
        m = gmodes[j]
        wq = modes[m, 1]
        cq = gcq[j]
        k0 = cquant[cq, lo]
        k1 = cquant[cq, hi]
        for rnd in range(rounds + 1):
            if rnd > 0:
                refit(x, labels, 1, nt, wt, wt, zero, zero, ep.e0, ep.e1, racc)
                quant_endpoints(zero, zero, cq, chw, cunq, cquant, zero, ep, racc)
                k0 = ep.vals[0]
                k1 = ep.vals[1]
            e0 = expand(np.int64(cunq[cq, k0]), srgb)
            e1 = expand(np.int64(cunq[cq, k1]), srgb)
            err = wl * _weights(v, nt, e0, e1, wq, wunq, wquant, codes, wt)
            if err < best:
                best = err
                bk0, bk1, bwq, bcq = k0, k1, wq, cq
                for t in range(nt):
                    bcodes[t] = codes[t]
            if err == 0:
                break
        if best == 0:
            break
    # the two luminances a colour level either way, the weights chosen
    # again, while it helps
    better = best < np.inf
    nk0, nk1 = bk0, bk1
    unq_r, quant_r = cunq[bcq], cquant[bcq]
    for _ in range(nudge):
        if not better or best == 0:
            break
        better = False
        for d0 in range(-1, 2):
            k0 = _next_level(unq_r, quant_r, bk0, d0)
            if k0 < 0:
                continue
            e0 = expand(np.int64(unq_r[k0]), srgb)
            for d1 in range(-1, 2):
                k1 = _next_level(unq_r, quant_r, bk1, d1)
                if (d0 == 0 and d1 == 0) or k1 < 0:
                    continue
                e1 = expand(np.int64(unq_r[k1]), srgb)
                err = wl * _weights(v, nt, e0, e1, bwq, wunq, wquant, codes, wt)
                if err < best:
                    best = err
                    nk0, nk1 = k0, k1
                    better = True
                    for t in range(nt):
                        bcodes[t] = codes[t]
        if better:
            bk0, bk1 = nk0, nk1
    if best < np.inf:
        for k in range(row.shape[0]):
            row[k] = 0
        row[S_KIND] = KIND_NORMAL
        row[S_GRID_W] = bw
        row[S_GRID_H] = bh
        row[S_WQUANT] = bwq
        row[S_PARTS] = 1
        row[S_CEM] = 0
        row[S_CQUANT] = bcq
        row[S_ENDPOINTS] = bk0
        row[S_ENDPOINTS + 1] = bk1
        for t in range(nt):
            row[S_WEIGHTS + t] = bcodes[t]
    return best
