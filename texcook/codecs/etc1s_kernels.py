"""ETC1S kernels: the fit of one endpoint (R5, G5, B5, table) to a set of
blocks, the vector quantiser that builds the endpoint and selector
codebooks (a binary split tree), and the refinement passes.

An ETC1S block is an ETC1 differential block with zero deltas, equal tables
and flip 0: its 16 texels share one base colour and one modifier table. Here
an endpoint is an int64 row (R5, G5, B5, table) and a selector pattern is 16
selectors (ETC1's numbering, texels row-major: etc1_tables.S_SEL's order).
Errors are summed squared RGB differences, exact (clamping included).

The search reads its preset through a record of etc1s.SEARCH (its columns are
documented there), named prm in every function that reads it.
"""

import numpy as np

from texcook._jit import jit
from texcook._jit import jit_inner as _inner

from ._kernels import order_by
from .etc1_kernels import floor_code, pack_sym, quant
from .etc1_tables import (EXPAND5, MODS, S_BASE1, S_BASE2, S_DIFF, S_FLIP, S_SEL, S_TABLE1, S_TABLE2, SINGLE_CODE,
                          SYM_LEN, TABLES)

BIG = np.int64(1) << 62
P5 = np.int64(5)


# ---------------------------------------------------------------- errors of one block


@_inner
def block_error(blk, r, g, b, t, cap):
    """Error of the 16 texels of blk (uint8 (16, >= 3)) against base (r, g, b)
    (8-bit, expanded) and table t with the best selector per texel; stops once
    the sum reaches cap."""
    err = np.int64(0)
    for i in range(16):
        p0 = np.int64(blk[i, 0])
        p1 = np.int64(blk[i, 1])
        p2 = np.int64(blk[i, 2])
        best = BIG
        for k in range(4):
            m = MODS[t, k]
            d0 = min(255, max(0, r + m)) - p0
            d1 = min(255, max(0, g + m)) - p1
            d2 = min(255, max(0, b + m)) - p2
            best = min(best, d0 * d0 + d1 * d1 + d2 * d2)
        err += best
        if err >= cap:
            return err
    return err


@_inner
def block_select(blk, r, g, b, t, sel):
    """Best selector of each texel (first best on ties) into sel[0:16]; returns the error."""
    err = np.int64(0)
    for i in range(16):
        best = BIG
        bk = 0
        for k in range(4):
            m = MODS[t, k]
            d0 = min(255, max(0, r + m)) - np.int64(blk[i, 0])
            d1 = min(255, max(0, g + m)) - np.int64(blk[i, 1])
            d2 = min(255, max(0, b + m)) - np.int64(blk[i, 2])
            e = d0 * d0 + d1 * d1 + d2 * d2
            if e < best:
                best = e
                bk = k
        sel[i] = bk
        err += best
    return err


@_inner
def fixed_error(blk, ep, pat, cap):
    """Error of blk against endpoint ep with the selectors pat (16) fixed."""
    r = EXPAND5[ep[0]]
    g = EXPAND5[ep[1]]
    b = EXPAND5[ep[2]]
    t = ep[3]
    err = np.int64(0)
    for i in range(16):
        m = MODS[t, pat[i]]
        d0 = min(255, max(0, r + m)) - np.int64(blk[i, 0])
        d1 = min(255, max(0, g + m)) - np.int64(blk[i, 1])
        d2 = min(255, max(0, b + m)) - np.int64(blk[i, 2])
        err += d0 * d0 + d1 * d1 + d2 * d2
        if err >= cap:
            return err
    return err


@_inner
def selector_costs(blk, ep, tab, add):
    """tab[i, k] = (or += with add) the error of texel i of blk under
    selector k of endpoint ep, clamping included."""
    r = EXPAND5[ep[0]]
    g = EXPAND5[ep[1]]
    b = EXPAND5[ep[2]]
    for k in range(4):
        m = MODS[ep[3], k]
        v0 = min(255, max(0, r + m))
        v1 = min(255, max(0, g + m))
        v2 = min(255, max(0, b + m))
        for i in range(16):
            d0 = v0 - np.int64(blk[i, 0])
            d1 = v1 - np.int64(blk[i, 1])
            d2 = v2 - np.int64(blk[i, 2])
            if add:
                tab[i, k] += d0 * d0 + d1 * d1 + d2 * d2
            else:
                tab[i, k] = d0 * d0 + d1 * d1 + d2 * d2


# ---------------------------------------------------------------- one endpoint for a set of blocks


@_inner
def _set_error(blocks, idx, a, b, c0, c1, c2, t, cap):
    """Error of the blocks idx[a:b] against code (c0, c1, c2) and table t, best selectors."""
    r = EXPAND5[c0]
    g = EXPAND5[c1]
    bl = EXPAND5[c2]
    err = np.int64(0)
    for j in range(a, b):
        err += block_error(blocks[idx[j]], r, g, bl, t, cap - err)
        if err >= cap:
            return err
    return err


@_inner
def _is_flat(blocks, idx, a, b):
    """True when every texel of the blocks idx[a:b] has the same RGB."""
    f = blocks[idx[a]]
    for j in range(a, b):
        blk = blocks[idx[j]]
        for i in range(16):
            for c in range(3):
                if blk[i, c] != f[0, c]:
                    return False
    return True


@jit
def fit_set(blocks, idx, a, b, rec, ep, sel, r, tables):
    """The endpoint (R5, G5, B5, table) with the least error over the blocks
    idx[a:b] (each texel taking its best selector) into ep; returns the error.
    Per table, the base starts at the texels' mean and moves to the mean minus
    the selected modifiers' mean (the best unquantised base for fixed
    selectors), trying the floor and ceiling code of each channel, for all
    eight tables or (tables < 8) the `tables` best at the code nearest the
    mean; r > 0 adds a lattice of that radius around the best code, with the
    tables next to the best. sel: int64 scratch of 16."""
    prm = rec[0]
    cnt = 16.0 * (b - a)
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    for j in range(a, b):
        blk = blocks[idx[j]]
        for i in range(16):
            s0 += blk[i, 0]
            s1 += blk[i, 1]
            s2 += blk[i, 2]
    m0 = s0 / cnt
    m1 = s1 / cnt
    m2 = s2 / cnt
    best = BIG
    if _is_flat(blocks, idx, a, b):
        # one colour: each table and selector has an exact best code per channel
        f = blocks[idx[a]]
        for t in range(8):
            for k in range(4):
                c0 = np.int64(SINGLE_CODE[1, t, k, f[0, 0]])
                c1 = np.int64(SINGLE_CODE[1, t, k, f[0, 1]])
                c2 = np.int64(SINGLE_CODE[1, t, k, f[0, 2]])
                e = _set_error(blocks, idx, a, b, c0, c1, c2, t, best)
                if e < best:
                    best = e
                    ep[0] = c0
                    ep[1] = c1
                    ep[2] = c2
                    ep[3] = t
        return best
    # the tables searched: all, or the `tables` best at the code nearest the mean
    mask = 255
    if tables < 8:
        n0 = quant(m0, P5)
        n1 = quant(m1, P5)
        n2 = quant(m2, P5)
        mask = 0
        for _ in range(tables):
            bt = -1
            be = BIG
            for t in range(8):
                if not (mask >> t) & 1:
                    e = _set_error(blocks, idx, a, b, n0, n1, n2, t, be)
                    if e < be:
                        be = e
                        bt = t
            mask |= 1 << bt
    for t in range(8):
        if not (mask >> t) & 1:
            continue
        shift = 0.0
        tb = BIG
        q0 = np.int64(0)
        q1 = np.int64(0)
        q2 = np.int64(0)
        for _ in range(prm.fit_iters):
            f0 = floor_code(m0 - shift, P5)
            f1 = floor_code(m1 - shift, P5)
            f2 = floor_code(m2 - shift, P5)
            for c0 in range(f0, min(31, f0 + 1) + 1):
                for c1 in range(f1, min(31, f1 + 1) + 1):
                    for c2 in range(f2, min(31, f2 + 1) + 1):
                        e = _set_error(blocks, idx, a, b, c0, c1, c2, t, tb)
                        if e < tb:
                            tb = e
                            q0 = c0
                            q1 = c1
                            q2 = c2
            # re-centre on the selectors this table's best code picks
            msum = 0.0
            for j in range(a, b):
                block_select(blocks[idx[j]], EXPAND5[q0], EXPAND5[q1], EXPAND5[q2], t, sel)
                for i in range(16):
                    msum += MODS[t, sel[i]]
            nshift = msum / cnt
            if nshift == shift:
                break
            shift = nshift
        if tb < best:
            best = tb
            ep[0] = q0
            ep[1] = q1
            ep[2] = q2
            ep[3] = t
    if r > 0:
        # bases that put the texels' darkest or brightest colour exactly on
        # one modifier: the others then clamp at 0 or 255 (a block of black,
        # white and one grey between), which the mean-centred search misses
        for side in range(2):
            lo0 = 255
            lo1 = 255
            lo2 = 255
            hi0 = 0
            hi1 = 0
            hi2 = 0
            for j in range(a, b):
                blk = blocks[idx[j]]
                for i in range(16):
                    lo0 = min(lo0, np.int64(blk[i, 0]))
                    lo1 = min(lo1, np.int64(blk[i, 1]))
                    lo2 = min(lo2, np.int64(blk[i, 2]))
                    hi0 = max(hi0, np.int64(blk[i, 0]))
                    hi1 = max(hi1, np.int64(blk[i, 1]))
                    hi2 = max(hi2, np.int64(blk[i, 2]))
            e0 = lo0 if side == 0 else hi0
            e1 = lo1 if side == 0 else hi1
            e2 = lo2 if side == 0 else hi2
            for t in range(8):
                for k in range(4):
                    md = MODS[t, k]
                    c0 = quant(e0 - md, P5)
                    c1 = quant(e1 - md, P5)
                    c2 = quant(e2 - md, P5)
                    e = _set_error(blocks, idx, a, b, c0, c1, c2, t, best)
                    if e < best:
                        best = e
                        ep[0] = c0
                        ep[1] = c1
                        ep[2] = c2
                        ep[3] = t
        g0 = ep[0]
        g1 = ep[1]
        g2 = ep[2]
        for t in range(max(0, ep[3] - 1), min(7, ep[3] + 1) + 1):
            for c0 in range(max(0, g0 - r), min(31, g0 + r) + 1):
                for c1 in range(max(0, g1 - r), min(31, g1 + r) + 1):
                    for c2 in range(max(0, g2 - r), min(31, g2 + r) + 1):
                        e = _set_error(blocks, idx, a, b, c0, c1, c2, t, best)
                        if e < best:
                            best = e
                            ep[0] = c0
                            ep[1] = c1
                            ep[2] = c2
                            ep[3] = t
    return best


@jit
def fit_blocks(blocks, eps, rec, pats, errs):
    """Each block's own best endpoint (eps (n, 4)), selectors (pats (n, 16))
    and error (errs (n,)): the unconstrained ETC1S fit."""
    prm = rec[0]
    idx = np.zeros(1, np.int64)
    for n in range(blocks.shape[0]):
        idx[0] = n
        fit_set(blocks, idx, 0, 1, rec, eps[n], pats[n], prm.radius, prm.fit_tables)
        ep = eps[n]
        errs[n] = block_select(blocks[n], EXPAND5[ep[0]], EXPAND5[ep[1]], EXPAND5[ep[2]], ep[3], pats[n])


@jit
def refit_fixed(blocks, idx, a, b, pats, psel, ep):
    """ep moved to the endpoint with the least error over the blocks idx[a:b],
    each keeping its selector pattern pats[psel[block]]: per table, the floor
    and ceiling codes around the mean of texel minus modifier. ep is kept when
    nothing beats it; returns the error."""
    best = np.int64(0)
    for j in range(a, b):
        n = idx[j]
        best += fixed_error(blocks[n], ep, pats[psel[n]], BIG)
    trial = np.zeros(4, np.int64)
    cnt = 16.0 * (b - a)
    for t in range(8):
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        for j in range(a, b):
            n = idx[j]
            blk = blocks[n]
            pat = pats[psel[n]]
            for i in range(16):
                m = MODS[t, pat[i]]
                s0 += blk[i, 0] - m
                s1 += blk[i, 1] - m
                s2 += blk[i, 2] - m
        f0 = floor_code(s0 / cnt, P5)
        f1 = floor_code(s1 / cnt, P5)
        f2 = floor_code(s2 / cnt, P5)
        trial[3] = t
        for c0 in range(f0, min(31, f0 + 1) + 1):
            for c1 in range(f1, min(31, f1 + 1) + 1):
                for c2 in range(f2, min(31, f2 + 1) + 1):
                    trial[0] = c0
                    trial[1] = c1
                    trial[2] = c2
                    e = np.int64(0)
                    for j in range(a, b):
                        n = idx[j]
                        e += fixed_error(blocks[n], trial, pats[psel[n]], best - e)
                        if e >= best:
                            break
                    if e < best:
                        best = e
                        ep[:] = trial
    return best


# ---------------------------------------------------------------- vector quantiser


@jit
def tree_vq(feat, wt, k, order, start, node_of, parent, child, curve):
    """Split the points feat (n, d) (weights wt) into at most k clusters: the
    cluster of largest weighted squared error is split along its principal
    axis at its mean until there are k or none can be split. The clusters are
    ranges start[c]..start[c + 1] of the points in order; returns their count.
    The splits are kept as a binary tree (node 0 the root; parent, child
    (2k, 2), node_of[c] the leaf of cluster c) for the candidate lists.
    curve[j] (k + 1 entries) is the clusters' summed error about their means
    when there were j of them (unreached counts keep the last)."""
    n, d = feat.shape
    for i in range(n):
        order[i] = i
    ends = np.zeros(k, np.int64)
    sse = np.zeros(k)
    mean = np.zeros(d)
    cov = np.zeros((d, d))
    axis = np.zeros(d)
    nxt = np.zeros(d)
    proj = np.zeros(n)
    start[0] = 0
    ends[0] = n
    node_of[0] = 0
    parent[0] = -1
    child[0, 0] = -1
    child[0, 1] = -1
    nodes = 1
    sse[0] = _sse(feat, wt, order, 0, n, mean)
    total = sse[0]
    curve[0] = total
    curve[1] = total
    m = 1
    while m < k:
        c = 0
        for j in range(1, m):
            if sse[j] > sse[c]:
                c = j
        if sse[c] <= 0.0:
            break
        a = start[c]
        b = ends[c]
        _sse(feat, wt, order, a, b, mean)
        # principal axis: power iteration from the axis of largest variance
        cov[:, :] = 0.0
        for j in range(a, b):
            p = order[j]
            for u in range(d):
                du = feat[p, u] - mean[u]
                for v in range(d):
                    cov[u, v] += wt[p] * du * (feat[p, v] - mean[v])
        bu = 0
        for u in range(1, d):
            if cov[u, u] > cov[bu, bu]:
                bu = u
        axis[:] = 0.0
        axis[bu] = 1.0
        for _ in range(6):
            nrm = 0.0
            for u in range(d):
                acc = 0.0
                for v in range(d):
                    acc += cov[u, v] * axis[v]
                nxt[u] = acc
                nrm += acc * acc
            if nrm <= 0.0:
                break
            nrm = np.sqrt(nrm)
            for u in range(d):
                axis[u] = nxt[u] / nrm
        # partition around the mean's projection (points on it go left)
        i = a
        j = b - 1
        for q in range(a, b):
            s = 0.0
            p = order[q]
            for u in range(d):
                s += (feat[p, u] - mean[u]) * axis[u]
            proj[p] = s
        while i <= j:
            if proj[order[i]] <= 0.0:
                i += 1
            else:
                order[i], order[j] = order[j], order[i]
                j -= 1
        if i == a or i == b:
            # cannot be split along this axis: left whole (its error stays in the total)
            sse[c] = 0.0
            continue
        ends[c] = i
        start[m] = i
        ends[m] = b
        total -= sse[c]
        sse[c] = _sse(feat, wt, order, a, i, mean)
        sse[m] = _sse(feat, wt, order, i, b, mean)
        total += sse[c] + sse[m]
        curve[m + 1] = total
        leaf = node_of[c]
        for side in range(2):
            parent[nodes + side] = leaf
            child[nodes + side, 0] = -1
            child[nodes + side, 1] = -1
            child[leaf, side] = nodes + side
        node_of[c] = nodes
        node_of[m] = nodes + 1
        nodes += 2
        m += 1
    for j in range(m + 1, k + 1):
        curve[j] = curve[m]
    # clusters renumbered in the order of their ranges, so start[c + 1] ends cluster c
    at = np.full(n, -1, np.int64)
    for c in range(m):
        at[start[c]] = node_of[c]
    c = 0
    for i in range(n):
        if at[i] >= 0:
            start[c] = i
            node_of[c] = at[i]
            c += 1
    start[m] = n
    return m


@_inner
def _sse(feat, wt, order, a, b, mean):
    """Weighted squared error of the points order[a:b] about their weighted mean (into mean)."""
    d = feat.shape[1]
    mean[:] = 0.0
    ws = 0.0
    for j in range(a, b):
        p = order[j]
        ws += wt[p]
        for u in range(d):
            mean[u] += wt[p] * feat[p, u]
    if ws <= 0.0:
        return 0.0
    mean /= ws
    e = 0.0
    for j in range(a, b):
        p = order[j]
        for u in range(d):
            du = feat[p, u] - mean[u]
            e += wt[p] * du * du
    return e


@jit
def tree_candidates(m, node_of, parent, child, want, cand, ncand):
    """For each cluster c, the clusters under its lowest ancestor holding at
    least `want` leaves (at most cand.shape[1], c itself first) into
    cand[c, :ncand[c]]: clusters split from one another lie close."""
    nodes = 2 * m - 1
    leaves = np.zeros(nodes, np.int64)
    cl = np.full(nodes, -1, np.int64)
    for c in range(m):
        cl[node_of[c]] = c
    # children are numbered after their parents: count leaves bottom-up
    for v in range(nodes - 1, -1, -1):
        if child[v, 0] < 0:
            leaves[v] = 1
        else:
            leaves[v] = leaves[child[v, 0]] + leaves[child[v, 1]]
    stack = np.zeros(nodes + 1, np.int64)
    cap = cand.shape[1]
    for c in range(m):
        v = node_of[c]
        while parent[v] >= 0 and leaves[v] < want:
            v = parent[v]
        cand[c, 0] = c
        cnt = 1
        top = 1
        stack[0] = v
        while top > 0 and cnt < cap:
            top -= 1
            u = stack[top]
            if child[u, 0] < 0:
                if cl[u] != c:
                    cand[c, cnt] = cl[u]
                    cnt += 1
            else:
                stack[top] = child[u, 1]
                stack[top + 1] = child[u, 0]
                top += 2
        ncand[c] = cnt


@jit
def group(assign, m, order, start):
    """Counting sort: the blocks of cluster c are order[start[c]:start[c + 1]]."""
    start[:] = 0
    for i in range(assign.shape[0]):
        start[assign[i] + 1] += 1
    for c in range(m):
        start[c + 1] += start[c]
    pos = start[:m].copy()
    for i in range(assign.shape[0]):
        c = assign[i]
        order[pos[c]] = i
        pos[c] += 1


# ---------------------------------------------------------------- refinement passes (per block)


@jit
def assign_endpoints(blocks, bep, eps, cand, ncand, errs):
    """Each block's endpoint re-picked among the candidates of its current
    one, each texel taking its best selector (errs: the new errors)."""
    for n in range(blocks.shape[0]):
        blk = blocks[n]
        c = bep[n]
        best = BIG
        bi = c
        for j in range(ncand[c]):
            e = eps[cand[c, j]]
            err = block_error(blk, EXPAND5[e[0]], EXPAND5[e[1]], EXPAND5[e[2]], e[3], best)
            if err < best:
                best = err
                bi = cand[c, j]
        bep[n] = bi
        errs[n] = best


@jit
def best_patterns(blocks, pats, eps, bep):
    """Each block's best selectors for its endpoint into pats (n, 16)."""
    for n in range(blocks.shape[0]):
        e = eps[bep[n]]
        block_select(blocks[n], EXPAND5[e[0]], EXPAND5[e[1]], EXPAND5[e[2]], e[3], pats[n])


@jit
def selector_features(pats, bep, eps, feat, wt):
    """A block's selectors as 16 modifiers of its table divided by the
    table's largest (+-1 and about +-0.3) and the weight 3 b^2: the squared
    feature distance times the weight is about the error of swapping patterns."""
    for n in range(pats.shape[0]):
        t = eps[bep[n], 3]
        b = TABLES[t, 1]
        wt[n] = 3.0 * b * b
        for i in range(16):
            feat[n, i] = MODS[t, pats[n, i]] / b


@jit
def endpoint_features(eps, pats, feat):
    """A block's endpoint as its expanded base and sqrt(3) times the RMS of
    its selected modifiers: a base off by D costs about 16 |D|^2, a spread
    off by S about 48 S^2, both as the squared feature distance times 16."""
    for n in range(eps.shape[0]):
        e = eps[n]
        feat[n, 0] = EXPAND5[e[0]]
        feat[n, 1] = EXPAND5[e[1]]
        feat[n, 2] = EXPAND5[e[2]]
        s = 0.0
        for i in range(16):
            m = MODS[e[3], pats[n, i]]
            s += m * m
        feat[n, 3] = np.sqrt(3.0 * s / 16.0)


@jit
def assign_selectors(blocks, bsel, pats, cand, ncand, eps, bep, errs):
    """Each block's selector pattern re-picked among the candidates of its
    current one, its endpoint fixed."""
    for n in range(blocks.shape[0]):
        blk = blocks[n]
        c = bsel[n]
        ep = eps[bep[n]]
        best = BIG
        bi = c
        for j in range(ncand[c]):
            err = fixed_error(blk, ep, pats[cand[c, j]], best)
            if err < best:
                best = err
                bi = cand[c, j]
        bsel[n] = bi
        errs[n] = best


@jit
def assign_endpoints_fixed(blocks, bep, eps, cand, ncand, pats, bsel, errs):
    """Each block's endpoint re-picked among the candidates of its current
    one, its selector pattern fixed."""
    for n in range(blocks.shape[0]):
        blk = blocks[n]
        c = bep[n]
        pat = pats[bsel[n]]
        best = BIG
        bi = c
        for j in range(ncand[c]):
            err = fixed_error(blk, eps[cand[c, j]], pat, best)
            if err < best:
                best = err
                bi = cand[c, j]
        bep[n] = bi
        errs[n] = best


@jit
def assign_all(blocks, bep, eps, pats, which, ep_order, ep_keys, ep_start, bsel, errs):
    """Each block re-picks among every entry of one codebook, the other part
    fixed: which 0 the endpoint (bep among eps), 1 the selector pattern (bsel
    among pats).

    Endpoints: with the pattern fixed and no channel clamped, a base b of
    table t costs 16 |b - c_t|^2 + r_t (c_t the mean of texel minus modifier,
    r_t what is left), so the best of each table is the base nearest c_t.
    ep_order lists the endpoints by table, then by the sum of their expanded
    base (ep_keys, in that order; table t is ep_start[t]..ep_start[t + 1]);
    the search walks out from c_t's sum and stops each way once the sum
    alone (|b - c|^2 >= (sum b - sum c)^2 / 3) cannot beat the best. Each
    endpoint met is measured exactly (texel by texel where it clamps).

    Patterns: a pattern's error is a sum of 16 looked-up texel errors,
    stopped once the texels left cannot make it the best."""
    tab = np.zeros((16, 4), np.int64)
    spread = np.zeros(16, np.int64)
    least = np.zeros(16, np.int64)
    rest = np.zeros(17, np.int64)
    torder = np.zeros(16, np.int64)
    s1 = np.zeros((8, 3), np.int64)
    s2 = np.zeros(8, np.int64)
    mlo = np.zeros(8, np.int64)
    mhi = np.zeros(8, np.int64)
    for n in range(blocks.shape[0]):
        blk = blocks[n]
        if which == 0:
            pat = pats[bsel[n]]
            for t in range(8):
                s2[t] = 0
                mlo[t] = 255
                mhi[t] = -255
                for c in range(3):
                    s1[t, c] = 0
                for i in range(16):
                    m = MODS[t, pat[i]]
                    mlo[t] = min(mlo[t], m)
                    mhi[t] = max(mhi[t], m)
                    for c in range(3):
                        v = np.int64(blk[i, c]) - m
                        s1[t, c] += v
                        s2[t] += v * v
            best = fixed_error(blk, eps[bep[n]], pat, BIG)
            for t in range(8):
                a = ep_start[t]
                b = ep_start[t + 1]
                if a == b:
                    continue
                target = (s1[t, 0] + s1[t, 1] + s1[t, 2]) / 16.0
                left = (s2[t] - (s1[t, 0] * s1[t, 0] + s1[t, 1] * s1[t, 1] + s1[t, 2] * s1[t, 2]) / 16.0)
                # first key >= target
                lo = a
                hi = b
                while lo < hi:
                    mid = (lo + hi) >> 1
                    if ep_keys[mid] < target:
                        lo = mid + 1
                    else:
                        hi = mid
                up = lo
                down = lo - 1
                while up < b or down >= a:
                    for side in range(2):
                        j = up if side == 0 else down
                        if j < a or j >= b:
                            continue
                        dk = ep_keys[j] - target
                        if 16.0 * dk * dk / 3.0 + left >= best:
                            if side == 0:
                                up = b
                            else:
                                down = a - 1
                            continue
                        k = ep_order[j]
                        e = eps[k]
                        r = EXPAND5[e[0]]
                        g = EXPAND5[e[1]]
                        bl = EXPAND5[e[2]]
                        if min(r, min(g, bl)) + mlo[t] >= 0 and max(r, max(g, bl)) + mhi[t] <= 255:
                            err = s2[t] - 2 * (r * s1[t, 0] + g * s1[t, 1] + bl * s1[t, 2]) \
                                + 16 * (r * r + g * g + bl * bl)
                        else:
                            err = fixed_error(blk, e, pat, best)
                        if err < best:
                            best = err
                            bep[n] = k
                        if side == 0:
                            up += 1
                        else:
                            down -= 1
        else:
            selector_costs(blk, eps[bep[n]], tab, False)
            cur = pats[bsel[n]]
            best = np.int64(0)
            for i in range(16):
                best += tab[i, cur[i]]
            # texels in order of how much a wrong selector costs, and the least
            # error the texels after each can add: a candidate stops as soon as
            # it cannot win
            for i in range(16):
                lo = min(min(tab[i, 0], tab[i, 1]), min(tab[i, 2], tab[i, 3]))
                spread[i] = -(max(max(tab[i, 0], tab[i, 1]), max(tab[i, 2], tab[i, 3])) - lo)
                least[i] = lo
            order_by(spread, torder)
            rest[16] = 0
            for ii in range(15, -1, -1):
                rest[ii] = rest[ii + 1] + least[torder[ii]]
            for j in range(pats.shape[0]):
                p = pats[j]
                err = np.int64(0)
                for ii in range(16):
                    i = torder[ii]
                    err += tab[i, p[i]]
                    if err + rest[ii + 1] >= best:
                        err = BIG
                        break
                if err < best:
                    best = err
                    bsel[n] = j
        errs[n] = best


@jit
def update_patterns(blocks, order, start, m, bep, eps, pats):
    """Each selector pattern c set, texel by texel, to the selector with the
    least error summed over its blocks order[start[c]:start[c + 1]] (each with
    its own endpoint): the exact best pattern for those blocks."""
    acc = np.zeros((16, 4), np.int64)
    for c in range(m):
        a = start[c]
        b = start[c + 1]
        if a == b:
            continue
        acc[:, :] = 0
        for j in range(a, b):
            n = order[j]
            selector_costs(blocks[n], eps[bep[n]], acc, True)
        for i in range(16):
            bk = 0
            for k in range(1, 4):
                if acc[i, k] < acc[i, bk]:
                    bk = k
            pats[c, i] = bk


@jit
def refit_endpoints(blocks, order, start, m, rec, eps, dirty):
    """Each endpoint c refitted to its blocks order[start[c]:start[c + 1]]
    (best selectors per texel), kept when the fit is no better; only those
    marked dirty (their blocks changed). Without the
    lattice: over many blocks the re-centred base is as good as the codes
    next to it, and the lattice would cost most of the encode."""
    prm = rec[0]
    sel = np.zeros(16, np.int64)
    trial = np.zeros(4, np.int64)
    for c in range(m):
        a = start[c]
        b = start[c + 1]
        if a == b or not dirty[c]:
            continue
        e = eps[c]
        cur = _set_error(blocks, order, a, b, e[0], e[1], e[2], e[3], BIG)
        got = fit_set(blocks, order, a, b, rec, trial, sel, 0, prm.refit_tables)
        if got < cur:
            eps[c, :] = trial


@jit
def refit_endpoints_fixed(blocks, order, start, m, pats, bsel, eps):
    """Each endpoint c refitted to its blocks with their selector patterns fixed."""
    for c in range(m):
        if start[c] < start[c + 1]:
            refit_fixed(blocks, order, start[c], start[c + 1], pats, bsel, eps[c])


@_inner
def _beside(index, n, x, nbx, side):
    """index[] of block n itself (side 0), of its left neighbour (1) or of
    the one above (2); -1 where the block has no such neighbour."""
    if side == 1:
        return index[n - 1] if x > 0 else -1
    if side == 2:
        return index[n - nbx] if n >= nbx else -1
    return index[n]


@jit
def coherence(blocks, nbx, bep, bsel, eps, pats, slack, errs):
    """In raster order, a block takes its left or upper neighbour's endpoint
    and/or selector pattern (the container codes a repeat of a neighbour's
    nearly for free) when the error that adds is below a bonus per part
    taken: slack[0] / 256 of the block's error plus slack[1]."""
    for n in range(blocks.shape[0]):
        blk = blocks[n]
        x = n % nbx
        bonus = (errs[n] * slack[0]) // 256 + slack[1]
        be = bep[n]
        bs = bsel[n]
        best = errs[n]
        for side in range(3):
            ce = _beside(bep, n, x, nbx, side)
            if ce < 0:
                continue
            for sside in range(3):
                cs = _beside(bsel, n, x, nbx, sside)
                if cs < 0:
                    continue
                taken = (ce != bep[n]) + (cs != bsel[n])
                if taken == 0:
                    continue
                e = fixed_error(blk, eps[ce], pats[cs], best + taken * bonus)
                if e - taken * bonus < best:
                    best = e - taken * bonus
                    be = ce
                    bs = cs
        if be != bep[n] or bs != bsel[n]:
            errs[n] = fixed_error(blk, eps[be], pats[bs], BIG)
        bep[n] = be
        bsel[n] = bs


# ---------------------------------------------------------------- bytes


@jit
def pack_etc1s(eps, pats, bep, bsel, out):
    """Blocks as ETC1S bytes: differential, zero deltas, equal tables, flip 0."""
    sym = np.zeros(SYM_LEN, np.int64)
    sym[S_DIFF] = 1
    sym[S_FLIP] = 0
    for n in range(bep.shape[0]):
        e = eps[bep[n]]
        p = pats[bsel[n]]
        for c in range(3):
            sym[S_BASE1 + c] = e[c]
            sym[S_BASE2 + c] = e[c]
        sym[S_TABLE1] = e[3]
        sym[S_TABLE2] = e[3]
        for i in range(16):
            sym[S_SEL + i] = p[i]
        pack_sym(sym, out[n])
