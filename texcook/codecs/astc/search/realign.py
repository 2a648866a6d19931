"""ASTC search: weight realignment. Grid weights moved one quantisation
step where the decoded error of the texels they reach drops."""

from collections import namedtuple

import numpy as np

from ...._jit import jit_inner
from ..quant import N_WEIGHT_RANGES, RANGE_LEVELS, WEIGHT_ORDER, WEIGHT_UNQUANT

# _nrt=False on the helpers called per fit or candidate: no reference
# counting of their array arguments (why: grid.py)

# the state realign_weights moves for one plane: grid codes (both planes interleaved),
# the plane's infill sums and texel weights, the decoded 16-bit endpoints, and
# qa, qb, fq, gq (T,) and dq (9, 4) scratch
RealignWork = namedtuple("RealignWork", "codes acc wt ee0 ee1 qa qb fq gq dq")


def _step_tables():
    """STEP_C[r, up, code]: in weight range r, the code of the level next
    below (up 0) or next above (up 1) the level of code, -1 past either end;
    STEP_W the weight (0..64) of that level. A step is then one lookup by
    the code it leaves, where code -> rank -> the next rank's code -> its
    weight is three lookups, each waiting on the one before."""
    sw = np.full((N_WEIGHT_RANGES, 2, 32), -1, np.int32)
    sc = np.full((N_WEIGHT_RANGES, 2, 32), -1, np.int32)
    for r in range(N_WEIGHT_RANGES):
        n = RANGE_LEVELS[r]
        for k in range(n):
            for up, k2 in ((0, k - 1), (1, k + 1)):
                if 0 <= k2 < n:
                    sc[r, up, WEIGHT_ORDER[r, k]] = WEIGHT_ORDER[r, k2]
                    sw[r, up, WEIGHT_ORDER[r, k]] = WEIGHT_UNQUANT[r, WEIGHT_ORDER[r, k2]]
    return sw, sc


STEP_W, STEP_C = _step_tables()


@jit_inner(_nrt=False)
def realign_weights(x, chw, labels, nparts, grid, wq, dual, ccs, plane, passes, rw):
    """Move grid weights of one plane a step up or down in value wherever the
    error of the texels they reach drops (a grid smaller than the block: a
    full grid goes to realign_full). acc holds each texel's infill sum
    before rounding; codes, acc and wt are updated. The error of a texel is
    taken as a quadratic in its weight (the decoder's interpolation without
    its rounding, in qa, qb): a move is a guess the caller's exact decode
    then scores. grid: (tex, tw, tn, ng), the grid's rows of the GridTables
    (its ng points' texels); wq the weight range (its steps looked up in STEP_W,
    STEP_C); rw: RealignWork. Only the rows read are taken, not the tables'
    records: a call passes every array of a record, each as its pointer,
    shape and strides (about 210 values pushed at each call site)."""
    tex, tw, tn, ng = grid
    stride = 2 if dual else 1
    unq, stw, stc = WEIGHT_UNQUANT[wq], STEP_W[wq], STEP_C[wq]
    codes, acc, wt, ee0, ee1, qa, qb, fq, gq, dq = rw
    nt = acc.shape[0]
    # decoded value ~ ee0 / 256 - 1/2 + (ee1 - ee0) w / 2^14 (floor's mean):
    # per partition the slope d and the start (dq rows 0-3, 4-7) and the
    # quadratic's leading term (row 8) are made once, not once per texel,
    # and only for the nparts partitions the labels name
    _partition_terms(ee0, ee1, chw, nparts, dual, ccs, plane, dq)
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
            up = np.uint64(0 if slope > 0 else 1)
            c2 = stc[up, np.uint64(cj)]
            if c2 >= 0:
                du = stw[up, np.uint64(cj)] - u
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


@jit_inner(_nrt=False)
def realign_full(x, chw, labels, nparts, wq, dual, ccs, passes, codes, planes, ends, dq):
    """A full grid's realignment and decoded error in one pass over the
    texels: each grid weight reaches its own texel alone (tables() checks),
    so realign_weights' moves of one texel's weights depend on that texel
    alone, and a texel that does not move in one pass moves in none after:
    its passes are made in turn (up to `passes`, until it stays), its weight
    in each plane, then its decoded error, summed as _decode_err sums it.
    The same moves and the same error as realign_weights on each plane and
    then _decode_err; codes and planes' (acc1, wt1, acc2, wt2) (acc2, wt2
    for a second plane) are updated the same. wq: the weight range; ends:
    (ee0, ee1) the decoded 16-bit endpoints; dq (9, 4) scratch.
    Returns the weighted squared error of the decoded block."""
    acc1, wt1, acc2, wt2 = planes
    ee0, ee1 = ends
    stride = 2 if dual else 1
    nt = acc1.shape[0]
    # the partitions' slopes and starts (rows 0-3, 4-7) and the first
    # plane's leading terms (row 8) as realign_weights makes them; the second
    # plane's (its one component ccs) are made per texel below
    _partition_terms(ee0, ee1, chw, nparts, dual, ccs, 0, dq)
    c2 = ccs if dual else -1
    stw = STEP_W[wq]
    stc = STEP_C[wq]
    err = 0.0
    for t in range(nt):
        # unsigned indices: numba adds no negative-index wrap-around
        p = np.uint64(labels[t])
        p4 = np.uint64(4 + labels[t])
        qb_t = 0.0
        for c in range(4):
            if dual and c == ccs:
                continue
            o = dq[p4, c] - x[t, c]
            qb_t += 2.0 * chw[c] * o * dq[p, c]
        w1 = _steps(dq[8, p], qb_t, wt1[t], t * stride, stw, stc, passes, codes)
        wt1[t] = w1
        acc1[t] = 16 * w1
        w2 = w1
        if dual:
            d = dq[p, c2]
            qa_t = 0.0 + chw[c2] * d * d
            o = dq[p4, c2] - x[t, c2]
            qb_t = 0.0 + 2.0 * chw[c2] * o * d
            w2 = _steps(qa_t, qb_t, wt2[t], t * stride + 1, stw, stc, passes, codes)
            wt2[t] = w2
            acc2[t] = 16 * w2
        err = texel_err(err, x[t], chw, ee0[p], ee1[p], w1, w2, c2)
    return err


@jit_inner(inline="always")
def _steps(qa_t, qb_t, w, k, stw, stc, passes, codes):
    """One texel's weight w (code codes[k]) moved a step at a time, up to
    passes steps, while the step its quadratic's slope points to lowers it
    (stw, stc: the range's STEP_W, STEP_C); returns the weight, codes[k]
    updated. Codes are >= 0: unsigned indices, no wrap-around."""
    cj = codes[k]
    for _ in range(passes):
        up = np.uint64(0 if 2.0 * qa_t * w + qb_t > 0 else 1)
        wn = stw[up, np.uint64(cj)]
        if wn < 0:
            break
        if not (qa_t * wn + qb_t) * wn < (qa_t * w + qb_t) * w:
            break
        cj = stc[up, np.uint64(cj)]
        w = wn
    codes[k] = cj
    return w


@jit_inner(inline="always")
def _partition_terms(ee0, ee1, chw, nparts, dual, ccs, plane, dq):
    """Per partition the decoded value's slope in the weight (dq rows 0-3) and
    its start (rows 4-7), and the quadratic's leading term over the
    components on plane `plane` (row 8): made once per partition, not once
    per texel."""
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


@jit_inner(inline="always")
def texel_err(err, xt, chw, e0p, e1p, w1, w2, c2):
    """err plus one texel's weighted squared decoding error, added component
    by component (the order a block's sum has always taken): xt its texel,
    e0p, e1p its partition's endpoints widened to 16 bits, w1 its weight
    (w2 for component c2 of a second plane; c2 -1 for none). The
    interpolation (e0 (64 - w) + e1 w + 32) >> 6 is taken as
    e0 + ((e1 - e0) w + 32) >> 6, the same integer (64 e0 is a multiple of
    64), one product fewer."""
    for c in range(4):
        w = w2 if c == c2 else w1
        e0 = e0p[c]
        v = (e0 + (((e1p[c] - e0) * w + 32) >> 6)) >> 8
        d = v - xt[c]
        err += chw[c] * d * d
    return err
