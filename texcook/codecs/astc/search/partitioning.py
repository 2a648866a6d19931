"""ASTC search: partitioning. Partition patterns ranked by how well their
texel split agrees with a small k-means clustering of the block."""

from collections import namedtuple

import numpy as np

from ...._jit import jit_inner

# one thread's scratch for ranking partitionings: out (1024,) the ranked pattern indices, cl (T,) and
# cen (4, 4) the clustering, ksc (6, 4), cmask (4, 3), cnt (4, 4), score (64,) and dist (1024,)
PartWork = namedtuple("PartWork", "out cl cen ksc cmask cnt score dist")


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
        same = it > 0
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
            same = same and cl[t] == bi
            cl[t] = bi
        # labels as the pass before: the centres and every later pass would
        # come out as they are
        if it == iters or same:
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


@jit_inner(inline="always")
def flat_spread(pmask, nparts, nt, x, s_all, q_all):
    """Squared distance of the texels' first component (x (nt, 4)) from its
    partition's mean, summed over the partitions of a pattern (pmask (4, 3):
    each partition's texels as bits, 48 a word; the last partition is the
    rest, from the block's sums s_all, q_all of the component and its
    square): a grey block's split, ranked where every split lies on its
    lines."""
    s_rest = s_all
    q_rest = q_all
    n_rest = float(nt)
    tot = 0.0
    for p in range(nparts - 1):
        n = 0.0
        sp = 0.0
        qp = 0.0
        for w in range((nt + 47) // 48):
            bits = pmask[p, w]
            while bits != 0:
                low = bits & -bits
                bits ^= low
                t = w * 48 + _popcount(low - 1)
                n += 1.0
                sp += x[t, 0]
                qp += x[t, 0] * x[t, 0]
        if n > 0:
            tot += max(qp - sp * sp / n, 0.0)
        s_rest -= sp
        q_rest -= qp
        n_rest -= n
    if n_rest > 0.5:
        tot += max(q_rest - s_rest * s_rest / n_rest, 0.0)
    return tot


@jit_inner(_nrt=False)
def flat_best(pmask, nparts, nt, x, pids, npid, nkeep, spread):
    """Of the npid patterns in pids, the nkeep whose partitions' spread
    (flat_spread) is least moved to its front, least first, ties to the
    earlier; returns how many (pmask: PartTables.pmask; spread (64,) scratch).
    A grey block's split, ranked where every split lies on its lines."""
    # the block's sums, the same for every pattern
    s_all = 0.0
    q_all = 0.0
    for t in range(nt):
        s_all += x[t, 0]
        q_all += x[t, 0] * x[t, 0]
    nk = 0
    for k in range(npid):
        q = pids[k]
        r = flat_spread(pmask[nparts - 2, q], nparts, nt, x, s_all, q_all)
        if nk == nkeep and r >= spread[nk - 1]:
            continue
        j = nk if nk < nkeep else nk - 1
        nk = max(nk, j + 1)
        while j > 0 and spread[j - 1] > r:
            spread[j] = spread[j - 1]
            pids[j] = pids[j - 1]
            j -= 1
        spread[j] = r
        pids[j] = q
    return nk


@jit_inner(inline="always")
def _pairing(cnt, r, a, b):
    """Texels in common of partitions r, r + 1 with clusters a, b, the
    better way round."""
    return max(cnt[r, a] + cnt[r + 1, b], cnt[r, b] + cnt[r + 1, a])


# inlined into rank_partitions, which calls it once per pattern: a call
# passes its arrays through reference counts
@jit_inner(inline="always")
def _agreement(pmask, pc, pid, nparts, nw, cmask, cnt):
    """Texels on which pattern pid (three or four partitions) and the
    clusters agree, best renaming: the most texels in common over every
    one-to-one pairing of partitions with clusters."""
    for a in range(nparts):
        for b in range(nparts):
            c = 0
            for w in range(nw):
                c += _popcount(pmask[pc, pid, a, w] & cmask[b, w])
            cnt[a, b] = c
    if nparts == 3:
        c00, c01, c02 = cnt[0, 0], cnt[0, 1], cnt[0, 2]
        c10, c11, c12 = cnt[1, 0], cnt[1, 1], cnt[1, 2]
        c20, c21, c22 = cnt[2, 0], cnt[2, 1], cnt[2, 2]
        return max(max(c00 + c11 + c22, c00 + c12 + c21), max(c01 + c10 + c22, c01 + c12 + c20),
                   max(c02 + c10 + c21, c02 + c11 + c20))
    # four: partitions 0 and 1 paired with two clusters (g, by the pair of
    # clusters), 2 and 3 with the other two (h); the best of the six splits
    g01, g02, g03 = _pairing(cnt, 0, 0, 1), _pairing(cnt, 0, 0, 2), _pairing(cnt, 0, 0, 3)
    g12, g13, g23 = _pairing(cnt, 0, 1, 2), _pairing(cnt, 0, 1, 3), _pairing(cnt, 0, 2, 3)
    h01, h02, h03 = _pairing(cnt, 2, 0, 1), _pairing(cnt, 2, 0, 2), _pairing(cnt, 2, 0, 3)
    h12, h13, h23 = _pairing(cnt, 2, 1, 2), _pairing(cnt, 2, 1, 3), _pairing(cnt, 2, 2, 3)
    return max(max(g01 + h23, g23 + h01), max(g02 + h13, g13 + h02), max(g03 + h12, g12 + h03))


@jit_inner
def rank_partitions(x, chw, nt, nparts, kiters, ncand, parts, pw):
    """The ncand partition indices whose split disagrees least with a k-means
    clustering (best renaming of partitions), counted on 48-bit texel masks.
    Returns how many were found, the indices in pw.out (PartWork); parts is
    the size's PartTables. With ncand at least the patterns' count every
    pattern is returned in table order (the caller ranks them by line fit)."""
    _, pmask, p2mask, plist, pcount = parts
    out, cl, cen, ksc, cmask, cnt, score, dist = pw
    pc = nparts - 2
    npat = pcount[pc]
    if ncand >= npat:
        for i in range(npat):
            out[i] = plist[pc, i]
        return npat
    score = score[:ncand]
    _kmeans(x, chw, nt, nparts, kiters, cl, cen, ksc)
    nw = (nt + 47) // 48
    for ii in range(cmask.shape[0]):
        for jj in range(cmask.shape[1]):
            cmask[ii, jj] = 0
    for t in range(nt):
        cmask[cl[t], t // 48] |= np.int64(1) << (t % 48)
    if nparts == 2:
        # two partitions: the mismatch is one popcount of the XOR, either naming
        if nw == 1:  # up to 48 texels: a loop of one word a pattern, which LLVM vectorises
            c0 = cmask[0, 0]
            for i in range(npat):
                d = _popcount(p2mask[i, 0] ^ c0)
                dist[i] = min(d, nt - d)
        else:
            for i in range(npat):
                d = 0
                for w in range(nw):
                    d += _popcount(p2mask[i, w] ^ cmask[0, w])
                dist[i] = min(d, nt - d)
    else:
        for i in range(npat):
            dist[i] = nt - _agreement(pmask, pc, plist[pc, i], nparts, nw, cmask, cnt)
    for ii in range(score.shape[0]):
        score[ii] = 1 << 30
    found = 0
    worst = 1 << 30  # the last kept's distance once the list is full (kept in a register)
    for i in range(npat):
        sc = dist[i]
        if sc < worst:
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
            if found == ncand:
                worst = score[ncand - 1]
    return found
