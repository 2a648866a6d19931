"""A slow, readable decoder of symbolic ASTC blocks, written from the spec
independently of the encoder's search, to check what the search claims."""

import numpy as np

from texcook.codecs.astc import quant as Q
from texcook.codecs.astc import symbolic as S
from texcook.codecs.astc.partitions import partition_table


def _blue_contract(r, g, b, a):
    return [(r + b) >> 1, (g + b) >> 1, b, a]


def endpoints(cem, v):
    """Unquantised colour values (0..255) -> two RGBA endpoints."""
    if cem == 0:
        return [v[0]] * 3 + [255], [v[1]] * 3 + [255]
    if cem == 4:
        return [v[0]] * 3 + [v[2]], [v[1]] * 3 + [v[3]]
    if cem in (6, 10):
        a0, a1 = (v[4], v[5]) if cem == 10 else (255, 255)
        return [(v[c] * v[3]) >> 8 for c in range(3)] + [a0], [v[0], v[1], v[2], a1]
    if cem in (8, 12):
        a0, a1 = (v[6], v[7]) if cem == 12 else (255, 255)
        if v[1] + v[3] + v[5] >= v[0] + v[2] + v[4]:
            return [v[0], v[2], v[4], a0], [v[1], v[3], v[5], a1]
        return _blue_contract(v[1], v[3], v[5], a1), _blue_contract(v[0], v[2], v[4], a0)
    raise ValueError(f"CEM {cem} not covered by this reference")


def infill(grid, gw, gh, bw, bh):
    ds = (1024 + bw // 2) // (bw - 1)
    dt = (1024 + bh // 2) // (bh - 1)
    out = np.zeros(bw * bh, np.int64)
    for y in range(bh):
        for x in range(bw):
            gs = (ds * x * (gw - 1) + 32) >> 6
            gt = (dt * y * (gh - 1) + 32) >> 6
            js, fs, jt, ft = gs >> 4, gs & 15, gt >> 4, gt & 15
            w11 = (fs * ft + 8) >> 4
            w10, w01, w00 = ft - w11, fs - w11, 16 - fs - ft + w11

            def p(i, j):
                return grid[j * gw + i] if i < gw and j < gh else 0

            out[y * bw + x] = (p(js, jt) * w00 + p(js + 1, jt) * w01 + p(js, jt + 1) * w10
                               + p(js + 1, jt + 1) * w11 + 8) >> 4
    return out


def decode_symbolic(row, bw, bh, srgb=False):
    """uint8 (bw*bh, 4) for one symbolic block."""
    row = np.asarray(row).astype(np.int64)
    nt = bw * bh
    if row[S.S_KIND] == S.KIND_VOID:
        return np.tile((row[S.S_VOID:S.S_VOID + 4] >> 8).astype(np.uint8), (nt, 1))
    gw, gh, wq = row[S.S_GRID_W], row[S.S_GRID_H], row[S.S_WQUANT]
    dual, ccs, parts = row[S.S_DUAL], row[S.S_CCS], row[S.S_PARTS]
    cq = row[S.S_CQUANT]
    planes = 2 if dual else 1
    wvals = Q.WEIGHT_UNQUANT[wq, row[S.S_WEIGHTS:S.S_WEIGHTS + gw * gh * planes]]
    tw = [infill(wvals[k::planes], gw, gh, bw, bh) for k in range(planes)]
    labels = (partition_table(bw, bh)[parts, row[S.S_PINDEX]] if parts > 1
              else np.zeros(nt, np.int64))
    eps = []
    off = 0
    for p in range(parts):
        cem = row[S.S_CEM + p]
        n = 2 * ((cem >> 2) + 1)
        v = [int(Q.COLOUR_UNQUANT[cq, c]) for c in row[S.S_ENDPOINTS + off:S.S_ENDPOINTS + off + n]]
        eps.append(endpoints(cem, v))
        off += n
    out = np.zeros((nt, 4), np.uint8)
    for t in range(nt):
        e0, e1 = eps[labels[t]]
        for c in range(4):
            w = tw[1][t] if dual and c == ccs else tw[0][t]
            a = (e0[c] << 8) | 0x80 if srgb else e0[c] * 257
            b = (e1[c] << 8) | 0x80 if srgb else e1[c] * 257
            out[t, c] = ((a * (64 - w) + b * w + 32) >> 6) >> 8
    return out
