"""The symbolic ASTC block: everything a 128-bit block says, as a flat int32 row.

One block is one row of SYM_LEN int32 values, so a run of blocks is a plain
(n, SYM_LEN) array that jitted search, packer, unpacker and decoder pass
around without Python objects. The slots:

    S_KIND       0 normal block, 1 void-extent (constant) block, 2 illegal/error block
    S_GRID_W/H   weight grid size
    S_WQUANT     weight range index 0..11 (2, 3, 4, 5, 6, 8, 10, 12, 16, 20, 24, 32 levels)
    S_DUAL       1 for two weight planes
    S_CCS        colour component (0..3) that the second plane drives
    S_PARTS      partition count 1..4
    S_PINDEX     partition index 0..1023 (0 with one partition)
    S_CEM+p      LDR colour endpoint mode of partition p (4 slots; unused ones 0)
    S_CQUANT     colour range index 0..20 (2..256 levels); the packer checks that it
                 is the largest range the bits left by the weights allow (several
                 partitions with one CEM: or the smaller range left when the CEM
                 field takes its per-partition form, which the packer then writes)
    S_VOID+c     void extent: RGBA as UNORM16
    S_ENDPOINTS  18 slots: colour ISE values in bitstream order, as coded (before
                 unquantisation), partition 0's values first
    S_WEIGHTS    64 slots: weight ISE values in bitstream order; with two planes
                 the planes alternate per grid point (p0, p1, p0, p1, ...)

Slots a block does not use are 0.
"""

import numpy as np

KIND_NORMAL, KIND_VOID, KIND_ERROR = 0, 1, 2

S_KIND = 0
S_GRID_W = 1
S_GRID_H = 2
S_WQUANT = 3
S_DUAL = 4
S_CCS = 5
S_PARTS = 6
S_PINDEX = 7
S_CEM = 8  # 4 slots
S_CQUANT = 12
S_VOID = 13  # 4 slots
S_ENDPOINTS = 17  # 18 slots
S_WEIGHTS = 35  # 64 slots
SYM_LEN = 99

MAX_COLOUR_VALUES = 18
MAX_WEIGHTS = 64


def colour_value_count(cems):
    """Colour integers a block needs: 2 * (cem // 4 + 1) per partition."""
    return sum(2 * (int(c) // 4 + 1) for c in cems)


def empty(n=1):
    """n zeroed symbolic blocks (n, SYM_LEN)."""
    return np.zeros((n, SYM_LEN), np.int32)


def make_normal(grid_w, grid_h, wquant, cems, cquant, endpoints, weights,
                dual=False, ccs=0, pindex=0):
    """One symbolic normal block from Python values (for tests and tools).
    `cems` has one entry per partition; `endpoints` and `weights` are ISE values
    in bitstream order."""
    cems = [int(c) for c in cems]
    endpoints = np.asarray(endpoints, np.int64).ravel()
    weights = np.asarray(weights, np.int64).ravel()
    if not 1 <= len(cems) <= 4:
        raise ValueError("1 to 4 partitions")
    if endpoints.size != colour_value_count(cems):
        raise ValueError(f"{colour_value_count(cems)} colour values needed, got {endpoints.size}")
    nw = grid_w * grid_h * (2 if dual else 1)
    if weights.size != nw or nw > MAX_WEIGHTS:
        raise ValueError(f"{nw} weights needed, got {weights.size}")
    s = np.zeros(SYM_LEN, np.int32)
    s[S_KIND] = KIND_NORMAL
    s[S_GRID_W] = grid_w
    s[S_GRID_H] = grid_h
    s[S_WQUANT] = wquant
    s[S_DUAL] = 1 if dual else 0
    s[S_CCS] = ccs if dual else 0
    s[S_PARTS] = len(cems)
    s[S_PINDEX] = pindex if len(cems) > 1 else 0
    s[S_CEM:S_CEM + len(cems)] = cems
    s[S_CQUANT] = cquant
    s[S_ENDPOINTS:S_ENDPOINTS + endpoints.size] = endpoints
    s[S_WEIGHTS:S_WEIGHTS + weights.size] = weights
    return s


def make_void(rgba16):
    """A void-extent (constant colour) block; rgba16 are UNORM16 values."""
    s = np.zeros(SYM_LEN, np.int32)
    s[S_KIND] = KIND_VOID
    s[S_VOID:S_VOID + 4] = [int(v) for v in rgba16]
    return s


def make_void8(rgba8):
    """A void-extent block for an 8-bit colour (v * 257 keeps it exact)."""
    return make_void([int(v) * 257 for v in rgba8])


def make_error():
    s = np.zeros(SYM_LEN, np.int32)
    s[S_KIND] = KIND_ERROR
    return s


def describe(s):
    """A readable dict of one symbolic block (for test failures and debugging)."""
    s = np.asarray(s)
    kind = int(s[S_KIND])
    if kind == KIND_VOID:
        return {"kind": "void", "rgba16": [int(v) for v in s[S_VOID:S_VOID + 4]]}
    if kind != KIND_NORMAL:
        return {"kind": "error"}
    parts = int(s[S_PARTS])
    cems = [int(c) for c in s[S_CEM:S_CEM + parts]]
    nw = int(s[S_GRID_W] * s[S_GRID_H] * (2 if s[S_DUAL] else 1))
    nc = colour_value_count(cems)
    return {
        "kind": "normal",
        "grid": (int(s[S_GRID_W]), int(s[S_GRID_H])),
        "wquant": int(s[S_WQUANT]),
        "dual": bool(s[S_DUAL]),
        "ccs": int(s[S_CCS]),
        "parts": parts,
        "pindex": int(s[S_PINDEX]),
        "cems": cems,
        "cquant": int(s[S_CQUANT]),
        "endpoints": [int(v) for v in s[S_ENDPOINTS:S_ENDPOINTS + nc]],
        "weights": [int(v) for v in s[S_WEIGHTS:S_WEIGHTS + nw]],
    }
