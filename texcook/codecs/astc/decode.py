"""Symbolic ASTC block -> texels (LDR decoding, 8 bits per channel out).

Follows the Khronos spec's decode_unorm8 rules: weights unquantised to 0..64,
bilinear infill from the weight grid with the spec's fixed-point steps,
partition by the hash, colour endpoints from the LDR modes (with blue
contraction and the swap of direct modes), then per channel
C = (C0 * (64 - w) + C1 * w + 32) >> 6 on 16-bit endpoints, output C >> 8.
UNORM widens an 8-bit endpoint e to e * 257; sRGB to (e << 8) | 0x80, so the
two interpolate differently. The error colour is opaque magenta: for illegal
blocks, HDR void extent, and (only their partition's texels) HDR endpoint modes.
"""

import numpy as np

from ..._jit import jit, jit_typed
from .endpoint_decode import decode_endpoints
from .partitions import select_partition
from .quant import COLOUR_UNQUANT, WEIGHT_UNQUANT
from .symbolic import (KIND_NORMAL, KIND_VOID, S_CCS, S_CEM, S_CQUANT, S_DUAL, S_ENDPOINTS,
                       S_GRID_H, S_GRID_W, S_KIND, S_PARTS, S_PINDEX, S_VOID, S_WEIGHTS,
                       S_WQUANT, SYM_LEN)
from .unpack import unpack_block


@jit_typed("void(int64[::1], int64, int64, int64, int64, int64[::1])")
def infill_weights(grid, gw, gh, bw, bh, out):
    """Spec infill: grid (gw*gh weights 0..64, row-major, padded by gw + 1)
    -> out[bw*bh] per-texel weights."""
    ds = (1024 + bw // 2) // (bw - 1)
    dt = (1024 + bh // 2) // (bh - 1)
    for y in range(bh):
        gt = (dt * y * (gh - 1) + 32) >> 6
        jt = gt >> 4
        ft = gt & 15
        for x in range(bw):
            gs = (ds * x * (gw - 1) + 32) >> 6
            js = gs >> 4
            fs = gs & 15
            v0 = js + jt * gw
            w11 = (fs * ft + 8) >> 4
            w10 = ft - w11
            w01 = fs - w11
            w00 = 16 - fs - ft + w11
            out[y * bw + x] = (grid[v0] * w00 + grid[v0 + 1] * w01 + grid[v0 + gw] * w10
                               + grid[v0 + gw + 1] * w11 + 8) >> 4


@jit_typed("void(int32[::1], int64, int64, int64, uint8[:, ::1])")
def decode_symbolic(s, bw, bh, srgb, out):
    """Decode one symbolic block s into out (bw*bh, 4) uint8. s must be legal
    for a bw x bh block, as unpack_block's and pack_block's are."""
    n = bw * bh
    kind = s[S_KIND]
    if kind == KIND_VOID:
        for c in range(4):
            v = np.uint8(s[S_VOID + c] >> 8)
            for t in range(n):
                out[t, c] = v
        return
    if kind != KIND_NORMAL:
        for t in range(n):
            out[t, 0] = 255
            out[t, 1] = 0
            out[t, 2] = 255
            out[t, 3] = 255
        return
    gw = np.int64(s[S_GRID_W])
    gh = np.int64(s[S_GRID_H])
    wq = s[S_WQUANT]
    dual = s[S_DUAL]
    planes = 2 if dual else 1
    # unquantised grid weights per plane; the padding serves the infill's
    # zero-weighted reads past the last row and column
    grid = np.zeros((2, 64 + 16), np.int64)
    for k in range(gw * gh):
        for p in range(planes):
            grid[p, k] = WEIGHT_UNQUANT[wq, s[S_WEIGHTS + k * planes + p]]
    texw = np.zeros((2, n), np.int64)
    for p in range(planes):
        infill_weights(grid[p], gw, gh, bw, bh, texw[p])
    ccs = s[S_CCS] if dual else -1

    parts = s[S_PARTS]
    cq = s[S_CQUANT]
    ends = np.zeros((4, 2, 4), np.int64)
    v = np.zeros(8, np.int64)
    base = 0
    for p in range(parts):
        cem = s[S_CEM + p]
        nv = 2 * ((cem >> 2) + 1)
        for i in range(nv):
            v[i] = COLOUR_UNQUANT[cq, s[S_ENDPOINTS + base + i]]
        base += nv
        if not decode_endpoints(cem, v, ends[p, 0], ends[p, 1]):
            ends[p, 0, 0], ends[p, 0, 1], ends[p, 0, 2], ends[p, 0, 3] = 255, 0, 255, 255
            ends[p, 1, 0], ends[p, 1, 1], ends[p, 1, 2], ends[p, 1, 3] = 255, 0, 255, 255
        for e in range(2):
            for c in range(4):
                x = ends[p, e, c]
                ends[p, e, c] = (x << 8) | 0x80 if srgb else x * 257
    small = 1 if n < 31 else 0
    pindex = s[S_PINDEX]
    for y in range(bh):
        for x in range(bw):
            t = y * bw + x
            p = select_partition(pindex, x, y, 0, parts, small) if parts > 1 else 0
            for c in range(4):
                w = texw[1, t] if c == ccs else texw[0, t]
                col = (ends[p, 0, c] * (64 - w) + ends[p, 1, c] * w + 32) >> 6
                out[t, c] = np.uint8(col >> 8)


@jit
def decode_blocks(data, out, bw, bh, srgb):
    """data uint8 (n, 16) -> out uint8 (n, bw*bh, 4), texels row-major in each
    block. bw, bh: block size; srgb: 1 for sRGB decoding, 0 for UNORM."""
    s = np.zeros(SYM_LEN, np.int32)
    blk = np.zeros(16, np.uint8)  # a writable copy: data may be a read-only buffer
    for i in range(data.shape[0]):
        for k in range(16):
            blk[k] = data[i, k]
        unpack_block(blk, s, bw, bh)
        decode_symbolic(s, bw, bh, srgb, out[i])
