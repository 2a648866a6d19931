"""ASTC search: the first fit of many blocks at once. Before the search
takes a run of TILE blocks one by one, their first fits (one partition, one
plane: fit.fit_partitions with texel_moments's sums) and those fits' separable
grid estimates (grid.sep_errs) are made here LANES blocks at a time, lane by
lane: every loop's innermost index is the block, over all LANES of them (a
short last run repeats its last block), and each lane's values sit in rows of
one flat array at fixed offsets, so that LLVM sees the lanes are independent
and runs them in vector registers, where one block's fit waits on its own
sums and divisions. Per block the operations and their order are those of the
per-block functions (the covariance's lower half read from its upper, the
row chosen by selects), so the results are the same bits; the search copies
a block's row of Lanes.out where it would have called them. A run of TILE,
not LANES, blocks: each pass pushes the search's tables and scratch out of
the cache, and a run of many blocks pays for that once."""

from collections import namedtuple

import numpy as np

from ...._jit import jit_inner

# blocks side by side (a pass's loops run over them); blocks per run
LANES = 64
TILE = 256
# rows of Lanes.bank, each LANES wide: first those a block's row of Lanes.out
# takes (from O_TOT on): the moment sums (texel_moments's 16), the ideal
# endpoints (4 + 4), the line residual, the importances' sum and the span of
# the texels' positions along the axis (each texel's importance is its
# square); then the mean (4), the axis (4), the positions' range (lo, hi),
# and first_seps's: the root of the importance, the weighted weights' sum
# of squares and two partial sums
L_TOT, L_E0, L_E1, L_RES, L_SS, L_SP, L_M, L_A, L_LO, L_HI = 0, 16, 20, 24, 25, 26, 27, 31, 35, 36
L_RT, L_TS, L_S0, L_S1, L_ROWS = 37, 38, 39, 40, 41
O_TOT, O_E0, O_E1, O_RES, O_SS, O_SP, O_GE = 0, 16, 20, 24, 25, 26, 27
# one thread's: bank (L_ROWS * LANES,); v (4 * T * LANES,) the weighted
# texels, component c of texel t of lane k at (c * T + t) * LANES + k (then
# first_seps's weighted weights); ws (T * LANES,) the ideal weights (t *
# LANES + k); sm (bh * ncol * LANES,), scm (npair * LANES,), ge (ngrids *
# LANES,) first_seps's rows in the widths' bases, their products and the
# grids' estimates (row grid_row); out (TILE, T + O_GE + ngrids): per block
# of the run, what the search reads: its ideal weights (T), then the bank's
# rows up to L_SP and the grids' estimates
Lanes = namedtuple("Lanes", "bank v ws sm scm ge out")

def lanes_work(bw, bh, ncol):
    """A thread's Lanes for blocks of bw x bh texels (ncol: the columns of
    the size's separable bases)."""
    nt = bw * bh
    return Lanes(np.zeros(L_ROWS * LANES), np.zeros(4 * nt * LANES), np.zeros(nt * LANES),
                 np.zeros(bh * ncol * LANES), np.zeros(bh * (bh + 1) // 2 * LANES),
                 np.zeros((bw - 1) * (bh - 1) * LANES), np.zeros((TILE, nt + O_GE + (bw - 1) * (bh - 1))))


@jit_inner(inline="always")
def _at(row, k):
    """Lane k of a bank row, as an index that numba need not wrap."""
    return np.uint64(row * LANES + k)


@jit_inner(inline="always")
def _times(cov, x0, x1, x2, x3, f):
    """f times the symmetric 4x4 matrix whose upper half is cov (row by
    row) times (x0, x1, x2, x3), each row summed as fit._principal_axis sums
    it."""
    c00, c01, c02, c03, c11, c12, c13, c22, c23, c33 = cov
    return ((c00 * x0 + c01 * x1 + c02 * x2 + c03 * x3) * f, (c01 * x0 + c11 * x1 + c12 * x2 + c13 * x3) * f,
            (c02 * x0 + c12 * x1 + c22 * x2 + c23 * x3) * f, (c03 * x0 + c13 * x1 + c23 * x2 + c33 * x3) * f)


@jit_inner(inline="always")
def _less_row(res, cii, ai, row, a0, a1, a2, a3):
    """res plus the diagonal entry cii of row i of the covariance (row: its
    four entries) less that row's part of the variance along the axis
    (a0..a3; ai the axis's component i), term by term as
    fit.fit_partitions subtracts them."""
    r0, r1, r2, r3 = row
    res += cii
    res -= ai * r0 * a0
    res -= ai * r1 * a1
    res -= ai * r2 * a2
    res -= ai * r3 * a3
    return res


@jit_inner(_nrt=False)
def first_fits(blocks, i0, chw, lw):
    """The first fit (fit.fit_partitions of one partition, one plane, with
    fit.texel_moments's sums) of blocks i0 .. i0 + LANES - 1 (past the last
    block: the last again) into lw (Lanes), lane k for block i0 + k."""
    bank, v, ws = lw.bank, lw.v, lw.ws
    nb = blocks.shape[0]
    nt = blocks.shape[1]
    fn = float(nt)
    sq0 = np.sqrt(chw[0])
    sq1 = np.sqrt(chw[1])
    sq2 = np.sqrt(chw[2])
    sq3 = np.sqrt(chw[3])
    for k in range(LANES):
        bk = blocks[min(i0 + k, nb - 1)]
        for t in range(nt):
            o = np.uint64(t * LANES + k)
            v[o] = bk[t, 0] * sq0
            v[o + np.uint64(nt * LANES)] = bk[t, 1] * sq1
            v[o + np.uint64(2 * nt * LANES)] = bk[t, 2] * sq2
            v[o + np.uint64(3 * nt * LANES)] = bk[t, 3] * sq3
    # texel_moments: sums in texel order, each from 0.0
    for r in range(16):
        for k in range(LANES):
            bank[_at(L_TOT + r, k)] = 0.0
    for k in range(LANES):
        bank[_at(L_TOT, k)] = fn
    for t in range(nt):
        b0 = np.uint64(t * LANES)
        b1 = np.uint64((nt + t) * LANES)
        b2 = np.uint64((2 * nt + t) * LANES)
        b3 = np.uint64((3 * nt + t) * LANES)
        for k in range(LANES):
            kk = np.uint64(k)
            v0 = v[b0 + kk]
            v1 = v[b1 + kk]
            v2 = v[b2 + kk]
            v3 = v[b3 + kk]
            bank[_at(L_TOT + 1, k)] += v0
            bank[_at(L_TOT + 2, k)] += v1
            bank[_at(L_TOT + 3, k)] += v2
            bank[_at(L_TOT + 4, k)] += v3
            bank[_at(L_TOT + 5, k)] += v0 * v0
            bank[_at(L_TOT + 6, k)] += v0 * v1
            bank[_at(L_TOT + 7, k)] += v0 * v2
            bank[_at(L_TOT + 8, k)] += v0 * v3
            bank[_at(L_TOT + 9, k)] += v1 * v1
            bank[_at(L_TOT + 10, k)] += v1 * v2
            bank[_at(L_TOT + 11, k)] += v1 * v3
            bank[_at(L_TOT + 12, k)] += v2 * v2
            bank[_at(L_TOT + 13, k)] += v2 * v3
            bank[_at(L_TOT + 14, k)] += v3 * v3
    for k in range(LANES):
        # _moment_cov: mean and covariance, a component whose spread is only
        # rounding left out (as selects, lane by lane)
        t0 = bank[_at(L_TOT + 1, k)]
        t1 = bank[_at(L_TOT + 2, k)]
        t2 = bank[_at(L_TOT + 3, k)]
        t3 = bank[_at(L_TOT + 4, k)]
        bank[_at(L_M, k)] = t0 / fn
        bank[_at(L_M + 1, k)] = t1 / fn
        bank[_at(L_M + 2, k)] = t2 / fn
        bank[_at(L_M + 3, k)] = t3 / fn
        c00 = bank[_at(L_TOT + 5, k)] - t0 * t0 / fn
        c01 = bank[_at(L_TOT + 6, k)] - t0 * t1 / fn
        c02 = bank[_at(L_TOT + 7, k)] - t0 * t2 / fn
        c03 = bank[_at(L_TOT + 8, k)] - t0 * t3 / fn
        c11 = bank[_at(L_TOT + 9, k)] - t1 * t1 / fn
        c12 = bank[_at(L_TOT + 10, k)] - t1 * t2 / fn
        c13 = bank[_at(L_TOT + 11, k)] - t1 * t3 / fn
        c22 = bank[_at(L_TOT + 12, k)] - t2 * t2 / fn
        c23 = bank[_at(L_TOT + 13, k)] - t2 * t3 / fn
        c33 = bank[_at(L_TOT + 14, k)] - t3 * t3 / fn
        z0 = c00 <= 1e-6
        z1 = c11 <= 1e-6
        z2 = c22 <= 1e-6
        z3 = c33 <= 1e-6
        c00 = 0.0 if z0 else c00
        c01 = 0.0 if z0 or z1 else c01
        c02 = 0.0 if z0 or z2 else c02
        c03 = 0.0 if z0 or z3 else c03
        c11 = 0.0 if z1 else c11
        c12 = 0.0 if z1 or z2 else c12
        c13 = 0.0 if z1 or z3 else c13
        c22 = 0.0 if z2 else c22
        c23 = 0.0 if z2 or z3 else c23
        c33 = 0.0 if z3 else c33
        # _principal_axis: power iteration from the row of the largest variance
        # (as selects, which run lane by lane: the same row chosen)
        r0, r1, r2, r3, bd = c00, c01, c02, c03, c00
        g = c11 > bd
        r0, r1, r2, r3, bd = (c01 if g else r0), (c11 if g else r1), (c12 if g else r2), (c13 if g else r3), \
            (c11 if g else bd)
        g = c22 > bd
        r0, r1, r2, r3, bd = (c02 if g else r0), (c12 if g else r1), (c22 if g else r2), (c23 if g else r3), \
            (c22 if g else bd)
        g = c33 > bd
        r0, r1, r2, r3 = (c03 if g else r0), (c13 if g else r1), (c23 if g else r2), (c33 if g else r3)
        tr = c00 + c11 + c22 + c33
        f = 1.0 / tr
        a0 = r0 * f
        a1 = r1 * f
        a2 = r2 * f
        a3 = r3 * f
        # fit._principal_axis's two steps of two products each
        cov = (c00, c01, c02, c03, c11, c12, c13, c22, c23, c33)
        for _ in range(4):
            a0, a1, a2, a3 = _times(cov, a0, a1, a2, a3, f)
        nrm = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2 + a3 * a3)
        zero = tr <= 1e-12 or nrm <= 1e-30
        a0 = 0.0 if zero else a0 / nrm
        a1 = 0.0 if zero else a1 / nrm
        a2 = 0.0 if zero else a2 / nrm
        a3 = 0.0 if zero else a3 / nrm
        # what the line leaves unexplained: trace minus the variance along it
        res = _less_row(0.0, c00, a0, (c00, c01, c02, c03), a0, a1, a2, a3)
        res = _less_row(res, c11, a1, (c01, c11, c12, c13), a0, a1, a2, a3)
        res = _less_row(res, c22, a2, (c02, c12, c22, c23), a0, a1, a2, a3)
        res = _less_row(res, c33, a3, (c03, c13, c23, c33), a0, a1, a2, a3)
        bank[_at(L_RES, k)] = res
        # the brighter endpoint second
        rgb = 0.0
        if sq0 > 0:
            rgb += a0 / sq0
        if sq1 > 0:
            rgb += a1 / sq1
        if sq2 > 0:
            rgb += a2 / sq2
        flip = rgb < 0
        bank[_at(L_A, k)] = -a0 if flip else a0
        bank[_at(L_A + 1, k)] = -a1 if flip else a1
        bank[_at(L_A + 2, k)] = -a2 if flip else a2
        bank[_at(L_A + 3, k)] = -a3 if flip else a3
        bank[_at(L_LO, k)] = 1e18
        bank[_at(L_HI, k)] = -1e18
    # each texel's position along the axis
    for t in range(nt):
        b0 = np.uint64(t * LANES)
        b1 = np.uint64((nt + t) * LANES)
        b2 = np.uint64((2 * nt + t) * LANES)
        b3 = np.uint64((3 * nt + t) * LANES)
        for k in range(LANES):
            kk = np.uint64(k)
            pr = 0.0
            pr += (v[b0 + kk] - bank[_at(L_M, k)]) * bank[_at(L_A, k)]
            pr += (v[b1 + kk] - bank[_at(L_M + 1, k)]) * bank[_at(L_A + 1, k)]
            pr += (v[b2 + kk] - bank[_at(L_M + 2, k)]) * bank[_at(L_A + 2, k)]
            pr += (v[b3 + kk] - bank[_at(L_M + 3, k)]) * bank[_at(L_A + 3, k)]
            ws[b0 + kk] = pr
            bank[_at(L_LO, k)] = min(bank[_at(L_LO, k)], pr)
            bank[_at(L_HI, k)] = max(bank[_at(L_HI, k)], pr)
    for c in range(4):
        sc = np.sqrt(chw[c])
        if sc > 0:
            for k in range(LANES):
                bank[_at(L_E0 + c, k)] = min(max((bank[_at(L_M + c, k)] + bank[_at(L_LO, k)] * bank[_at(L_A + c, k)])
                                                 / sc, 0.0), 255.0)
                bank[_at(L_E1 + c, k)] = min(max((bank[_at(L_M + c, k)] + bank[_at(L_HI, k)] * bank[_at(L_A + c, k)])
                                                 / sc, 0.0), 255.0)
        else:
            # a channel without weight still decodes: its mean
            for k in range(LANES):
                mc = 0.0
                for t in range(nt):
                    mc += float(blocks[min(i0 + k, nb - 1), t, c])
                bank[_at(L_E0 + c, k)] = mc / fn
                bank[_at(L_E1 + c, k)] = mc / fn
    # the importance is the same for every texel of one partition: each
    # lane's sum added texel by texel, as fit_partitions adds it
    for k in range(LANES):
        span = bank[_at(L_HI, k)] - bank[_at(L_LO, k)]
        sp2 = span * span
        acc = 0.0
        for t in range(nt):
            acc += sp2
        bank[_at(L_SS, k)] = acc
        bank[_at(L_SP, k)] = span
    for t in range(nt):
        b0 = np.uint64(t * LANES)
        for k in range(LANES):
            kk = np.uint64(k)
            span = bank[_at(L_SP, k)]
            ws[b0 + kk] = (ws[b0 + kk] - bank[_at(L_LO, k)]) / span if span > 1e-9 else 0.0


@jit_inner(inline="always")
def grid_row(gw, gh, bh):
    """The row of a grid's lane estimates in Lanes.ge."""
    return (gw - 2) * (bh - 1) + gh - 2


@jit_inner(_nrt=False)
def first_seps(lw, bw, bh, ux, uoff, qyp, used):
    """grid.sep_errs of the first fits first_fits left in lw (Lanes), lane
    by lane: per grid used (and not full) its estimate into lw.ge's row
    grid_row. lw.v (the weighted texels, no longer needed) takes the weights
    times the roots of their importance."""
    L = np.uint64(LANES)
    bank, vl, ws, sm, scm, ge = lw.bank, lw.v, lw.ws, lw.sm, lw.scm, lw.ge
    nt = bw * bh
    ncol = ux.shape[1]
    # each texel's weight times the root of its importance (the span's square)
    for k in range(LANES):
        sp = bank[_at(L_SP, k)]
        bank[_at(L_RT, k)] = np.sqrt(sp * sp)
        bank[_at(L_TS, k)] = 0.0
    for t in range(nt):
        o = np.uint64(t) * L
        for k in range(LANES):
            kk = np.uint64(k)
            a = ws[o + kk] * bank[_at(L_RT, k)]
            vl[o + kk] = a
            bank[_at(L_TS, k)] += a * a
    # the rows in every width's basis, four texels of a row at a time
    for y in range(bh):
        for j in range(ncol):
            r = np.uint64(y * ncol + j) * L
            for k in range(LANES):
                sm[r + np.uint64(k)] = 0.0
        x = 0
        while x + 4 <= bw:
            o0 = np.uint64(y * bw + x) * L
            o1 = o0 + L
            o2 = o1 + L
            o3 = o2 + L
            for j in range(ncol):
                u0, u1, u2, u3 = ux[x, j], ux[x + 1, j], ux[x + 2, j], ux[x + 3, j]
                r = np.uint64(y * ncol + j) * L
                for k in range(LANES):
                    kk = np.uint64(k)
                    sm[r + kk] = (((sm[r + kk] + vl[o0 + kk] * u0) + vl[o1 + kk] * u1) + vl[o2 + kk] * u2) \
                        + vl[o3 + kk] * u3
            x += 4
        while x < bw:
            o0 = np.uint64(y * bw + x) * L
            for j in range(ncol):
                u0 = ux[x, j]
                r = np.uint64(y * ncol + j) * L
                for k in range(LANES):
                    kk = np.uint64(k)
                    sm[r + kk] += vl[o0 + kk] * u0
            x += 1
    npair = bh * (bh + 1) // 2
    for gw in range(2, bw + 1):
        wanted = 0
        for gh in range(2, bh + 1):
            if used[gw, gh] and gw * gh < nt:
                wanted += 1
        if wanted == 0:
            continue
        c0 = uoff[gw]
        # the rows' products at this width, pair (y, y2 >= y) by pair
        q = 0
        for y in range(bh):
            for y2 in range(y, bh):
                r = np.uint64(q) * L
                for k in range(LANES):
                    scm[r + np.uint64(k)] = 0.0
                for j in range(c0, c0 + gw):
                    ra = np.uint64(y * ncol + j) * L
                    rb = np.uint64(y2 * ncol + j) * L
                    for k in range(LANES):
                        kk = np.uint64(k)
                        scm[r + kk] += sm[ra + kk] * sm[rb + kk]
                q += 1
        for gh in range(2, bh + 1):
            if not used[gw, gh] or gw * gh == nt:
                continue
            # two sums, the even pairs' and the odd ones', as sep_errs adds them
            for k in range(LANES):
                bank[_at(L_S0, k)] = 0.0
                bank[_at(L_S1, k)] = 0.0
            for kp in range(0, npair - 1, 2):
                q0 = qyp[gh, kp]
                q1 = qyp[gh, kp + 1]
                r0 = np.uint64(kp) * L
                r1 = r0 + L
                for k in range(LANES):
                    kk = np.uint64(k)
                    bank[_at(L_S0, k)] += scm[r0 + kk] * q0
                    bank[_at(L_S1, k)] += scm[r1 + kk] * q1
            if npair & 1:
                ql = qyp[gh, npair - 1]
                rl = np.uint64(npair - 1) * L
                for k in range(LANES):
                    bank[_at(L_S0, k)] += scm[rl + np.uint64(k)] * ql
            rg = np.uint64(grid_row(gw, gh, bh)) * L
            for k in range(LANES):
                ge[rg + np.uint64(k)] = (bank[_at(L_TS, k)] - bank[_at(L_S0, k)]
                                         - bank[_at(L_S1, k)])


@jit_inner(_nrt=False)
def first_tile(blocks, i0, chw, lw, bw, bh, sep, used):
    """The first fits and their grid estimates (first_fits, first_seps) of
    blocks i0 .. i0 + TILE - 1 (those there are), LANES at a time, into the
    rows of lw.out; used: the grids the search's modes use (sep_errs's)."""
    nb = blocks.shape[0]
    nt = bw * bh
    ux, uoff, qyp = sep
    bank, ws, ge, out = lw.bank, lw.ws, lw.ge, lw.out
    ngr = (bw - 1) * (bh - 1)
    for s0 in range(0, TILE, LANES):
        if i0 + s0 >= nb:
            break
        first_fits(blocks, i0 + s0, chw, lw)
        first_seps(lw, bw, bh, ux, uoff, qyp, used)
        for k in range(min(LANES, nb - i0 - s0)):
            o = out[s0 + k]
            for t in range(nt):
                o[t] = ws[np.uint64(t * LANES + k)]
            for j in range(O_GE):
                o[nt + O_TOT + j] = bank[_at(L_TOT + j, k)]
            for r in range(ngr):
                o[nt + O_GE + r] = ge[np.uint64(r * LANES + k)]


@jit_inner(inline="always")
def tile_moments(runs, k, nt, tot):
    """texel_moments's sums of block k of the run first_tile made (runs:
    Lanes.out)."""
    o = runs[k]
    for j in range(16):
        tot[j] = o[nt + O_TOT + j]
