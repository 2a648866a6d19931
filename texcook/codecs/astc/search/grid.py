"""ASTC search: weight grids. Ideal texel weights decimated onto a grid
(least squares), the errors of a grid (decimated, or the separable estimate)
and of quantising it to a weight range, and the decoder's infill back."""

import numpy as np

from ...._jit import jit_inner
from .lanes import O_GE, grid_row

# Each step below moves a grid weight by its texels' weighted residual over
# their weighted reach: the simultaneous (SIRT) step, which converges for any
# factor below 2 but slowly at 1 (each texel's residual is shared among the
# four grid points it reaches). 1.8 converges in about half the steps
# (thorough's 8 steps at 1 ~ 4-5 at 1.8) and gives one or two steps more of
# the way (fast 8x8 +0.08 dB on the corpus); 1.5 and 1.95 were no better
# overall (docs/astc.md, "Decimation's steps over-relaxed").
OMEGA = 1.8

# Helpers called per fit or per candidate compile with _nrt=False: numba then
# counts no references to the arrays they take (a call each to take and to
# drop every array of every argument, views of borrowed arrays included),
# a large share of a short call; they allocate nothing and return no
# array, so nothing needs counting.


@jit_inner(_nrt=False)
def decimate(grids, g, nt, w, s, iters, out, r, den):
    """Grid weights (0..1) of grid g whose infill best matches ideal texel
    weights w, weighted by importance s: the transpose of the infill as a
    start, then over-relaxed steps on the residual (OMEGA). grids: the size's GridTables;
    r (nt,) and den (64,) are scratch. Each grid point's sums are gathered
    from the texels it reaches (grids.tex, in texel order, the texels with a
    weight of 0 left out, which add nothing) in registers: the same sums as
    scattering from every texel, without each addition waiting on the store
    of the one before."""
    ng = grids.dims[g, 0] * grids.dims[g, 1]
    if ng == nt:
        # a full grid's infill is the identity (tables() checks)
        for j in range(ng):
            out[j] = w[j]
        return
    gidx, gwt, tex, tw, tn = grids.idx[g], grids.wt[g], grids.tex[g], grids.tw[g], grids.tn[g]
    # texel and grid indices read from the tables are >= 0: as np.uint64
    # numba adds no negative-index wrap-around to each use
    for t in range(nt):
        r[t] = s[t] + 1e-3
    for j in range(ng):
        num = 0.0
        dj = 0.0
        for k in range(tn[j]):
            t = np.uint64(tex[j, k])
            f = tw[j, k] * r[t]
            num += f * w[t]
            dj += f
        den[j] = dj
        out[j] = num / dj if dj > 0 else 0.5
    for _ in range(iters):
        for t in range(nt):
            f = 0.0
            for k in range(4):
                f += gwt[t, k] * out[np.uint64(gidx[t, k])]
            r[t] = (w[t] - f / 16.0) * (s[t] + 1e-3)
        for j in range(ng):
            if den[j] > 0:
                num = 0.0
                for k in range(tn[j]):
                    num += tw[j, k] * r[np.uint64(tex[j, k])]
                out[j] = min(max(out[j] + OMEGA * num / den[j], 0.0), 1.0)


@jit_inner(_nrt=False)
def decim_err(gidx, gwt, nt, g, w, s):
    """Importance-weighted squared error of a float grid's infill."""
    e = 0.0
    for t in range(nt):
        f = 0.0
        for k in range(4):
            f += gwt[t, k] * g[gidx[t, k]]
        d = f / 16.0 - w[t]
        e += s[t] * d * d
    return e


@jit_inner(_nrt=False)
def sep_errs(w, s, bw, bh, ux, uoff, qyp, errs, sc, used, lane, runs):
    """errs[gw, gh] += the squared error of the separable least-squares fit of
    each grid the modes tried use (used[gw, gh]) to the ideal weights (bh rows
    of bw), each scaled by the root of its importance; clamping and the
    infill's rounding left out: an estimate for ranking grids. The fit's error
    is what the projection onto the grid's row and column spaces leaves, so
    one Gram matrix per width serves every height. sc (bw*bh + bh*ncol +
    bh*bh) is scratch. Inner loops run over independent outputs, so they need
    no reordered sums to vectorise. The hot loops index as np.uint64: numba
    wraps no negative index then (it cannot tell that offsets read from the
    tables are >= 0). lane >= 0: w, s are the first fit of row lane of runs
    (lanes.Lanes.out), whose estimates lanes.first_seps made: copied."""
    nt = bw * bh
    if lane >= 0:
        for gw in range(2, bw + 1):
            for gh in range(2, bh + 1):
                if used[gw, gh] and gw * gh < nt:
                    errs[gw, gh] += runs[lane, nt + O_GE + grid_row(gw, gh, bh)]
        return
    ncol = ux.shape[1]
    v = sc[:nt]
    m = sc[nt:nt + bh * ncol]  # rows in every width's basis: (bh, ncol)
    cm = sc[nt + bh * ncol:nt + bh * ncol + bh * bh]
    # the roots apart from the sum, so that they vectorise
    for t in range(nt):
        v[t] = w[t] * np.sqrt(s[t])
    tot = 0.0
    for t in range(nt):
        tot += v[t] * v[t]
    # each row's sums over its texels four at a time, each in the same order
    # as one at a time (from 0.0): a pass over the columns (vectorised) adds
    # four products, where one per pass waited on the store of the last
    for y in range(bh):
        r = np.uint64(ncol * y)
        for j in range(ncol):
            m[r + np.uint64(j)] = 0.0
        x = 0
        while x + 4 <= bw:
            a0, a1, a2, a3 = v[y * bw + x], v[y * bw + x + 1], v[y * bw + x + 2], v[y * bw + x + 3]
            u0, u1, u2, u3 = ux[x], ux[x + 1], ux[x + 2], ux[x + 3]
            for j in range(ncol):
                m[r + np.uint64(j)] = (((m[r + np.uint64(j)] + a0 * u0[j]) + a1 * u1[j]) + a2 * u2[j]) + a3 * u3[j]
            x += 4
        while x < bw:
            a = v[y * bw + x]
            ux_x = ux[x]
            for j in range(ncol):
                m[r + np.uint64(j)] += a * ux_x[j]
            x += 1
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
            # two pairs of a row at a time, sharing its loads
            y2 = y
            while y2 + 1 < bh:
                acc = 0.0
                acc2 = 0.0
                for j in range(c0, c0 + gw):
                    a = m[np.uint64(ncol * y + j)]
                    acc += a * m[np.uint64(ncol * y2 + j)]
                    acc2 += a * m[np.uint64(ncol * y2 + ncol + j)]
                cm[k] = acc
                cm[k + 1] = acc2
                k += 2
                y2 += 2
            if y2 < bh:
                acc = 0.0
                for j in range(c0, c0 + gw):
                    acc += m[np.uint64(ncol * y + j)] * m[np.uint64(ncol * y2 + j)]
                cm[k] = acc
                k += 1
        npair = bh * (bh + 1) // 2
        gh = 2
        while gh <= bh:
            if not used[gw, gh] or gw * gh == nt:
                gh += 1
                continue
            # two sums per height, so that the additions overlap, and two
            # heights at a time where two are used (each summed in the same
            # order as alone)
            gh2 = gh + 1
            while gh2 <= bh and (not used[gw, gh2] or gw * gh2 == nt):
                gh2 += 1
            if gh2 > bh:
                acc0 = 0.0
                acc1 = 0.0
                for k in range(0, npair - 1, 2):
                    acc0 += cm[np.uint64(k)] * qyp[gh, np.uint64(k)]
                    acc1 += cm[np.uint64(k + 1)] * qyp[gh, np.uint64(k + 1)]
                if npair & 1:
                    acc0 += cm[npair - 1] * qyp[gh, npair - 1]
                errs[gw, gh] += tot - acc0 - acc1
                break
            acc0 = 0.0
            acc1 = 0.0
            bcc0 = 0.0
            bcc1 = 0.0
            for k in range(0, npair - 1, 2):
                acc0 += cm[np.uint64(k)] * qyp[gh, np.uint64(k)]
                acc1 += cm[np.uint64(k + 1)] * qyp[gh, np.uint64(k + 1)]
                bcc0 += cm[np.uint64(k)] * qyp[gh2, np.uint64(k)]
                bcc1 += cm[np.uint64(k + 1)] * qyp[gh2, np.uint64(k + 1)]
            if npair & 1:
                acc0 += cm[npair - 1] * qyp[gh, npair - 1]
                bcc0 += cm[npair - 1] * qyp[gh2, npair - 1]
            errs[gw, gh] += tot - acc0 - acc1
            errs[gw, gh2] += tot - bcc0 - bcc1
            gh = gh2 + 1


@jit_inner(_nrt=False)
def quantise_grid(g, ng, wquant, codes, stride, off):
    """Grid weights g (0..1) to codes of a weight range (wquant: its row of
    the quantisation table, by 64ths), into codes[j * stride + off]. Both
    indices are >= 0: as np.uint64, numba adds no negative-index wrap-around."""
    for j in range(ng):
        v = int(np.floor(g[j] * 64.0 + 0.5))
        v = min(max(v, 0), 64)
        codes[np.uint64(j * stride + off)] = wquant[np.uint64(v)]


@jit_inner(_nrt=False)
def grid_quant_err(g, ng, wq, wunq, wquant):
    """Squared error (weights 0..1) of quantising grid weights g to range wq,
    rounded as quantise_grid rounds them."""
    e = 0.0
    for j in range(ng):
        u = g[j] * 64.0
        v = min(max(int(np.floor(u + 0.5)), 0), 64)
        d = (wunq[wq, wquant[wq, v]] - u) / 64.0
        e += d * d
    return e


@jit_inner(inline="always")
def infill(gidx, gwt, nt, ng, codes, stride, off, wq, wunq, wt, acc):
    """Texel weights 0..64 exactly as decoded from grid codes; acc gets the
    sums before rounding. Inlined: its call sites then pass no arrays
    through reference counts."""
    wrow = wunq[wq]  # (codes and grid indices are >= 0: np.uint64, no wrap-around)
    if ng == nt:  # a full grid: each texel its own weight (tables() checks)
        for t in range(nt):
            u = wrow[np.uint64(codes[t * stride + off])]
            acc[t] = 16 * u
            wt[t] = u
        return
    for t in range(nt):
        a = 0
        for k in range(4):
            a += gwt[t, k] * wrow[np.uint64(codes[np.uint64(gidx[t, k] * stride + off)])]
        acc[t] = a
        wt[t] = (a + 8) >> 4
