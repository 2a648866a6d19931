"""Symbolic block -> 128 bits, refusing anything a conformant decoder would not
read back as the same block.

Layout (little-endian bit numbers): block mode 0-10, partition count - 1 at
11-12; one partition: CEM 13-16, colour values from 17; several: partition
index 13-22, CEM field 23-28, colour values from 29. The weight stream runs
down from bit 127; below it sit the extra CEM bits, and below those the
dual-plane colour component (CCS). Void extent: bits 0-8 0x1FC, bit 9 0 (LDR),
bits 10-11 1, all extent coordinates all ones (a plain constant block), RGBA
UNORM16 at 64, 80, 96, 112.

The packer cannot see the block size, so a grid larger than the block is the
caller's error (the unpacker and decoder reject it).
"""

import numpy as np

from ..._jit import borrow, jit, jit_inner, jit_typed
from .bise import ise_words, or_bits, reverse64
from .modes import (VOID_EXTENT_MODE, cem_field_encode, cem_field_encode_split, colour_range,
                    config_bits, encode_block_mode)
from .quant import RANGE_LEVELS, ise_bits
from .symbolic import (KIND_NORMAL, KIND_VOID, S_CCS, S_CEM, S_CQUANT, S_DUAL, S_ENDPOINTS,
                       S_GRID_H, S_GRID_W, S_KIND, S_PARTS, S_PINDEX, S_VOID, S_WEIGHTS,
                       S_WQUANT)

PACK_ERRORS = {
    1: "block kind is not normal or void extent",
    2: "void-extent colour outside 0..65535",
    3: "no block mode for this grid, weight range and plane count",
    4: "weights outside 24..96 bits or more than 64 of them",
    5: "partition count outside 1..4, or two planes with 4 partitions",
    6: "partition index outside 0..1023 or colour component outside 0..3",
    7: "colour endpoint mode outside 0..15, or classes more than one apart",
    8: "colour values do not fit the bits left (more than 18, or under 13/5 bits each)",
    9: "colour range is not the largest the bits left allow",
    10: "a colour value is outside its range",
    11: "a weight value is outside its range",
}


@jit_inner(inline="always")
def _store(out, lo, hi):
    """The block's two words into its 16 bytes, little-endian."""
    for b in range(8):
        out[b] = np.uint8((lo >> (8 * b)) & 0xFF)
        out[8 + b] = np.uint8((hi >> (8 * b)) & 0xFF)


@jit_typed("int64(int32[::1], uint8[::1], int64[::1])")
def _pack_into(s, out, cems):
    """pack_block with its scratch passed in: cems (4,)."""
    for i in range(16):
        out[i] = 0
    kind = s[S_KIND]
    if kind == KIND_VOID:
        for c in range(4):
            if s[S_VOID + c] < 0 or s[S_VOID + c] > 0xFFFF:
                return 2
        # bits 0-63: the mode, reserved bits 10-11 set, all extent coordinates
        # all ones (no extent); then RGBA as UNORM16
        lo = np.int64(-1) << 16 | VOID_EXTENT_MODE | (3 << 10) | 0xF000
        hi = np.int64(0)
        for c in range(4):
            hi |= np.int64(s[S_VOID + c]) << (16 * c)
        _store(out, lo, hi)
        return 0
    if kind != KIND_NORMAL:
        return 1
    gw = np.int64(s[S_GRID_W])
    gh = np.int64(s[S_GRID_H])
    wq = np.int64(s[S_WQUANT])
    dual = np.int64(s[S_DUAL])
    parts = np.int64(s[S_PARTS])
    mode = encode_block_mode(gw, gh, wq, dual)
    if mode < 0 or dual < 0 or dual > 1:
        return 3
    nw = gw * gh * (dual + 1)
    wbits = ise_bits(nw, wq)
    if nw > 64 or wbits < 24 or wbits > 96:
        return 4
    if parts < 1 or parts > 4 or (dual and parts == 4):
        return 5
    pindex = np.int64(s[S_PINDEX])
    ccs = np.int64(s[S_CCS])
    if pindex < 0 or pindex > 1023 or ccs < 0 or ccs > 3:
        return 6
    same = True
    ncol = 0
    for p in range(parts):
        cems[p] = s[S_CEM + p]
        if cems[p] < 0 or cems[p] > 15:
            return 7
        if cems[p] != cems[0]:
            same = False
        ncol += 2 * ((cems[p] >> 2) + 1)
    low6 = 0
    extra = 0
    nextra = 0
    if parts > 1:
        low6, extra, nextra = cem_field_encode(cems, parts)
        if low6 < 0:
            return 7
    cr = colour_range(ncol, 128 - config_bits(parts, same, dual) - wbits)
    if parts > 1 and same and cr != s[S_CQUANT]:
        # identical CEMs stored in the per-partition form leave fewer colour
        # bits; a block with that smaller range is stored that way
        cr_split = colour_range(ncol, 128 - config_bits(parts, False, dual) - wbits)
        if cr_split == s[S_CQUANT]:
            cr = cr_split
            low6, extra, nextra = cem_field_encode_split(cems, parts)
    if cr < 0:
        return 8
    if cr != s[S_CQUANT]:
        return 9
    for i in range(ncol):
        v = s[S_ENDPOINTS + i]
        if v < 0 or v >= RANGE_LEVELS[cr]:
            return 10
    for i in range(nw):
        v = s[S_WEIGHTS + i]
        if v < 0 or v >= RANGE_LEVELS[wq]:
            return 11

    if parts == 1:
        config = mode | (cems[0] << 13)
        colour_start = 17
    else:
        config = mode | ((parts - 1) << 11) | (pindex << 13) | (low6 << 23)
        colour_start = 29
    # the block as two words (bits 0-63, 64-127), stored once
    lo, hi, _ = ise_words(s[S_ENDPOINTS:S_ENDPOINTS + ncol], ncol, cr, colour_start, config, np.int64(0))
    # the weight stream runs down from bit 127: written upward, then reversed
    wlo, whi, _ = ise_words(s[S_WEIGHTS:S_WEIGHTS + nw], nw, wq, 0, np.int64(0), np.int64(0))
    lo |= reverse64(whi)
    hi |= reverse64(wlo)
    # extra CEM bits just below the weights, the CCS below those
    below = 128 - wbits - nextra
    if dual:
        below -= 2
        extra = ccs | (extra << 2)
        nextra += 2
    if nextra > 0:
        lo, hi = or_bits(lo, hi, below, nextra, extra)
    _store(out, lo, hi)
    return 0


@jit_typed("int64(int32[::1], uint8[::1])")
def pack_block(s, out):
    """Pack one symbolic block s (int32[SYM_LEN]) into out (uint8[16]).
    Returns 0, or an error code (PACK_ERRORS) with out left all zero."""
    return _pack_into(s, out, np.zeros(4, np.int64))


@jit
def encode_symbolic_blocks(sym, out):
    """Pack sym (n, SYM_LEN) int32 into out (n, 16) uint8. Returns -1 when every
    block packed, else the index of the first block that did not (its bytes,
    and those of any other failing block, are zero)."""
    first_bad = -1
    s = np.zeros(sym.shape[1], np.int32)  # a writable copy: sym may be read-only
    cems = np.zeros(4, np.int64)
    # views without reference counts (_jit.borrow): one block is little work
    own = (s, cems, out)
    (s, cems, out) = borrow(own)
    for i in range(sym.shape[0]):
        for k in range(sym.shape[1]):
            s[k] = sym[i, k]
        if _pack_into(s, out[i], cems) != 0 and first_bad < 0:
            first_bad = i
    return first_bad + 0 * len(own)  # `own` used last: the arrays live until here


def pack(sym):
    """Python entry: (n, SYM_LEN) or (SYM_LEN,) -> bytes; ValueError names the
    first block that cannot be packed and why."""
    arr = np.ascontiguousarray(np.atleast_2d(sym), dtype=np.int32)
    out = np.zeros((arr.shape[0], 16), np.uint8)
    bad = encode_symbolic_blocks(arr, out)
    if bad >= 0:
        code = pack_block(arr[bad], np.zeros(16, np.uint8))
        raise ValueError(f"ASTC block {bad}: {PACK_ERRORS[int(code)]}")
    return out.tobytes()
