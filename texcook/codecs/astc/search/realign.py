"""ASTC search: weight realignment. Grid weights moved one quantisation
step where the decoded error of the texels they reach drops."""

from collections import namedtuple

import numpy as np

from ...._jit import jit_inner

# _nrt=False on the helpers called per fit or candidate: no reference
# counting of their array arguments (why: grid.py)

# the state realign_weights moves for one plane: grid codes (both planes interleaved),
# the plane's infill sums and texel weights, the decoded 16-bit endpoints, and
# qa, qb, fq, gq (T,) and dq (9, 4) scratch
RealignWork = namedtuple("RealignWork", "codes acc wt ee0 ee1 qa qb fq gq dq")


@jit_inner(_nrt=False)
def realign_weights(x, chw, labels, nparts, tex, tw, tn, ng, unq, order, rank, nlev, dual, ccs, plane, passes, rw):
    """Move grid weights of one plane a step up or down in value wherever the
    error of the texels they reach drops. acc holds each texel's infill sum
    before rounding; codes, acc and wt are updated. The error of a texel is
    taken as a quadratic in its weight (the decoder's interpolation without
    its rounding, in qa, qb): a move is a guess the caller's exact decode
    then scores. tex, tw, tn: the grid's rows of the GridTables (its ng
    points' texels); unq, order, rank: the weight range's rows of the
    WeightRanges, nlev its levels; rw: RealignWork. Only the rows read are
    taken, not the tables' records: a call passes every array of a record,
    each as its pointer, shape and strides (about 150 values pushed at
    each of the two call sites)."""
    stride = 2 if dual else 1
    codes, acc, wt, ee0, ee1, qa, qb, fq, gq, dq = rw
    nt = acc.shape[0]
    # decoded value ~ ee0 / 256 - 1/2 + (ee1 - ee0) w / 2^14 (floor's mean):
    # per partition the slope d and the start (dq rows 0-3, 4-7) and the
    # quadratic's leading term (row 8) are made once, not once per texel,
    # and only for the nparts partitions the labels name
    for p in range(nparts):
        a2 = 0.0
        for c in range(4):
            d = (ee1[p, c] - ee0[p, c]) / 16384.0
            dq[p, c] = d
            dq[4 + p, c] = ee0[p, c] / 256.0 - 0.5
            if dual and ((c == ccs) != (plane == 1)):
                continue
            a2 += chw[c] * d * d
        dq[8, p] = a2
    if ng == nt:
        # a full grid: each weight reaches its own texel alone, at 16/16
        # (tables() checks), so a step moves that texel's weight by the step;
        # a texel's quadratic is made where its step is tried (in registers,
        # the same terms in the same order as the per-texel rows below); a
        # later pass reads its linear term back from qb
        for ps in range(passes):
            moved = 0
            for t in range(nt):
                # unsigned indices: numba adds no negative-index wrap-around
                p = np.uint64(labels[t])
                if ps == 0:
                    p4 = np.uint64(4 + labels[t])
                    qb_t = 0.0
                    for c in range(4):
                        if dual and ((c == ccs) != (plane == 1)):
                            continue
                        o = dq[p4, c] - x[t, c]
                        qb_t += 2.0 * chw[c] * o * dq[p, c]
                    qb[t] = qb_t
                else:
                    qb_t = qb[t]
                qa_t = dq[8, p]
                cj = codes[t * stride + plane]
                r = rank[np.uint64(cj)]
                w = wt[t]
                r2 = r - 1 if 2.0 * qa_t * w + qb_t > 0 else r + 1
                if 0 <= r2 < nlev:
                    c2 = order[np.uint64(r2)]
                    w2 = unq[np.uint64(c2)]
                    if (qa_t * w2 + qb_t) * w2 < (qa_t * w + qb_t) * w:
                        acc[t] = 16 * w2
                        wt[t] = w2
                        codes[t * stride + plane] = c2
                        moved += 1
            if moved == 0:
                break
        return
    for t in range(nt):
        p = labels[t]
        a1 = 0.0
        for c in range(4):
            if dual and ((c == ccs) != (plane == 1)):
                continue
            o = dq[4 + p, c] - x[t, c]
            a1 += 2.0 * chw[c] * o * dq[p, c]
        qa[t] = dq[8, p]
        qb[t] = a1
    # each texel's error and slope at its weight, made once and again only
    # where a move changes the weight (a grid point reaches several texels).
    # Texel indices and codes (>= 0) index as np.uint64: numba adds no
    # negative-index wrap-around then
    for t in range(nt):
        w = wt[t]
        fq[t] = (qa[t] * w + qb[t]) * w
        gq[t] = 2.0 * qa[t] * w + qb[t]
    for _ in range(passes):
        moved = 0
        for j in range(ng):
            cj = codes[j * stride + plane]
            r = rank[np.uint64(cj)]
            u = unq[np.uint64(cj)]
            texj, twj = tex[j], tw[j]
            nk = tn[j]
            cur = 0.0
            slope = 0.0
            for k in range(nk):
                t = np.uint64(texj[k])
                cur += fq[t]
                slope += gq[t] * twj[k]
            best = cur
            bcode = cj
            # only the step the error's slope points to
            r2 = r - 1 if slope > 0 else r + 1
            if 0 <= r2 < nlev:
                c2 = order[np.uint64(r2)]
                du = unq[np.uint64(c2)] - u
                e = 0.0
                for k in range(nk):
                    t = np.uint64(texj[k])
                    w = (acc[t] + twj[k] * du + 8) >> 4
                    e += (qa[t] * w + qb[t]) * w
                if e < best:
                    best = e
                    bcode = c2
            if bcode != cj:
                du = unq[np.uint64(bcode)] - u
                for k in range(nk):
                    t = np.uint64(texj[k])
                    acc[t] += twj[k] * du
                    w = (acc[t] + 8) >> 4
                    wt[t] = w
                    fq[t] = (qa[t] * w + qb[t]) * w
                    gq[t] = 2.0 * qa[t] * w + qb[t]
                codes[j * stride + plane] = bcode
                moved += 1
        if moved == 0:
            break
