"""ASTC 2D block modes and the bit budget of a block.

The 11-bit block mode says the weight grid (W x H), the weight range and
whether there are two weight planes. What is left of the 128 bits after the
configuration fields and the weights holds the colour values, whose range is
not stored: it is the largest range whose encoding fits (the spec's "data size
determination"), so an encoder must use exactly that range.

Multi-partition CEM field: bits 23-24 select "all partitions share one CEM"
(0; the CEM in bits 25-28) or a base class 0..2 (selector - 1). Otherwise the
field, read as one number with bits 23-28 low and 3N-4 extra bits high, holds
the selector, then one class bit per partition, then a 2-bit mode per
partition; the extra bits sit just below the weights.
"""

import numpy as np

from ..._jit import jit_typed
from .quant import N_RANGES, RANGE_BITS, RANGE_QUINTS, RANGE_TRITS, ise_bits

VOID_EXTENT_MODE = 0x1FC  # bits 0-8 of a void-extent block


@jit_typed("UniTuple(int64, 5)(int64)")
def decode_block_mode(m):
    """11-bit 2D block mode -> (ok, grid_w, grid_h, wquant, dual). ok is 0 for
    reserved encodings and for void extent (check that first)."""
    m = m & 0x7FF
    if m & 3:
        rho = ((m >> 4) & 1) | ((m & 3) << 1)
        a = (m >> 5) & 3
        b = (m >> 7) & 3
        sel = (m >> 2) & 3
        if sel == 0:
            w, h = b + 4, a + 2
        elif sel == 1:
            w, h = b + 8, a + 2
        elif sel == 2:
            w, h = a + 2, b + 8
        elif (m >> 8) & 1:
            w, h = (b & 1) + 2, a + 2
        else:
            w, h = a + 2, (b & 1) + 6
        p = (m >> 9) & 1
        dual = (m >> 10) & 1
    else:
        rho = ((m >> 4) & 1) | (((m >> 2) & 3) << 1)
        a = (m >> 5) & 3
        p = (m >> 9) & 1
        dual = (m >> 10) & 1
        sel = (m >> 7) & 3
        if sel == 0:
            w, h = 12, a + 2
        elif sel == 1:
            w, h = a + 2, 12
        elif sel == 2:
            w, h = a + 6, ((m >> 9) & 3) + 6
            p = 0
            dual = 0
        elif a == 0:
            w, h = 6, 10
        elif a == 1:
            w, h = 10, 6
        else:
            return 0, 0, 0, 0, 0
    if rho < 2:
        return 0, 0, 0, 0, 0
    return 1, w, h, rho - 2 + 6 * p, dual


def _build_mode_table():
    table = np.full((13, 13, 12, 2), -1, np.int32)
    for m in range(2048):
        if (m & 0x1FF) == VOID_EXTENT_MODE:
            continue
        ok, w, h, q, d = decode_block_mode(m)
        if ok and table[w, h, q, d] < 0:
            table[w, h, q, d] = m
    return table


MODE_OF = _build_mode_table()
"""MODE_OF[grid_w, grid_h, wquant, dual] -> the 11-bit mode, -1 if none exists."""


@jit_typed("int64(int64, int64, int64, int64)")
def encode_block_mode(grid_w, grid_h, wquant, dual):
    """The 11-bit mode for a grid, weight range and plane count; -1 if none."""
    if grid_w < 0 or grid_w > 12 or grid_h < 0 or grid_h > 12 or wquant < 0 or wquant > 11:
        return -1
    return MODE_OF[grid_w, grid_h, wquant, 1 if dual else 0]


@jit_typed("int64(int64, int64, int64, int64)")
def weight_bits(grid_w, grid_h, wquant, dual):
    return ise_bits(grid_w * grid_h * (2 if dual else 1), wquant)


@jit_typed("int64(int64, int64)")
def extra_cem_bits(parts, same_cem):
    """CEM bits stored just below the weights."""
    if parts == 1 or same_cem:
        return 0
    return 3 * parts - 4


@jit_typed("int64(int64, int64, int64)")
def config_bits(parts, same_cem, dual):
    """Bits of block mode, partition count, partition index, CEM fields and CCS."""
    if parts == 1:
        bits = 17
    elif same_cem:
        bits = 29
    else:
        bits = 25 + 3 * parts
    return bits + (2 if dual else 0)


def _colour_ranges():
    """COLOUR_RANGE[bits_left, ncolour] for 0..128 bits and 0..18 values: the
    largest range whose encoding of ncolour values fits, -1 where a block is
    illegal (fewer than 2 values, or fewer bits than ceil(13 * ncolour / 5),
    the cost of the smallest usable range)."""
    n = np.arange(19)[None, :, None]
    r = np.arange(N_RANGES)[None, None, :]
    bits = (n * RANGE_BITS[r] + (8 * n * RANGE_TRITS[r] + 4) // 5 + (7 * n * RANGE_QUINTS[r] + 2) // 3)
    left = np.arange(129)[:, None, None]
    fits = bits <= left
    top = np.where(fits.any(axis=2), N_RANGES - 1 - np.argmax(fits[..., ::-1], axis=2), -1)
    nv, lf = n[..., 0], left[..., 0]
    return np.ascontiguousarray(np.where((nv >= 2) & (lf >= (13 * nv + 4) // 5), top, -1), np.int64)


COLOUR_RANGE = _colour_ranges()


@jit_typed("int64(int64, int64)")
def colour_range(ncolour, bits_left):
    """The colour range index a block must use for `ncolour` values in `bits_left`
    bits (0..128), or -1 when the block is illegal (COLOUR_RANGE: a table, as
    the packer and the decoder ask for every block)."""
    if ncolour > 18 or ncolour < 0 or bits_left < 0 or bits_left > 128:
        return -1
    return COLOUR_RANGE[bits_left, ncolour]


@jit_typed("boolean(int64, int64, int64, int64, int64, int64)")
def mode_is_legal(grid_w, grid_h, wquant, dual, bw, bh):
    """Grid fits the block, at most 64 weights, weight ISE of 24..96 bits."""
    if grid_w > bw or grid_h > bh:
        return False
    n = grid_w * grid_h * (2 if dual else 1)
    if n > 64:
        return False
    wb = ise_bits(n, wquant)
    return 24 <= wb <= 96


@jit_typed("UniTuple(int64, 3)(int64[::1], int64)")
def cem_field_encode_split(cems, parts):
    """The per-partition form of the CEM field (class bits and modes), which
    identical CEMs may use too, at the cost of 3N-4 colour bits."""
    lo = 3
    hi = 0
    for i in range(parts):
        c = cems[i] >> 2
        lo = min(lo, c)
        hi = max(hi, c)
    if hi - lo > 1:
        return -1, 0, 0
    base = min(lo, 2)  # selector 1..3 names base class 0..2
    field = base + 1
    for i in range(parts):
        field |= ((cems[i] >> 2) - base) << (2 + i)
        field |= (cems[i] & 3) << (2 + parts + 2 * i)
    return field & 0x3F, field >> 6, 3 * parts - 4


@jit_typed("UniTuple(int64, 3)(int64[::1], int64)")
def cem_field_encode(cems, parts):
    """(low6, extra, n_extra) for a multi-partition block: bits 23-28 and the
    extra bits below the weights. Identical CEMs share one field; low6 = -1 if
    the CEMs cannot share a field (their classes differ by more than one)."""
    same = True
    for i in range(parts):
        if cems[i] != cems[0]:
            same = False
    if same:
        return cems[0] << 2, 0, 0
    return cem_field_encode_split(cems, parts)


@jit_typed("void(int64, int64, int64[::1])")
def cem_field_decode(field, parts, cems):
    """Fill cems[0:parts] from the whole CEM field (bits 23-28 | extra << 6)."""
    sel = field & 3
    if sel == 0:
        for i in range(parts):
            cems[i] = (field >> 2) & 0xF
        return
    base = sel - 1
    for i in range(parts):
        cls = base + ((field >> (2 + i)) & 1)
        cems[i] = (cls << 2) | ((field >> (2 + parts + 2 * i)) & 3)


# columns of a block_modes() row
BM_MODE, BM_GRID_W, BM_GRID_H, BM_WQUANT, BM_DUAL, BM_WEIGHT_BITS = range(6)
BM_COLUMNS = 6

_BLOCK_MODES = {}


def block_modes(bw, bh):
    """int32 (M, 6): every legal (grid, weight range, planes) of a bw x bh block,
    columns BM_MODE (11-bit mode), BM_GRID_W, BM_GRID_H, BM_WQUANT, BM_DUAL,
    BM_WEIGHT_BITS; sorted by weight bits, then grid size. The colour bits left
    for a choice of partitions and CEMs are
    128 - BM_WEIGHT_BITS - config_bits(parts, same_cem, dual)."""
    key = (int(bw), int(bh))
    if key not in _BLOCK_MODES:
        rows = []
        for (w, h, q, d), m in np.ndenumerate(MODE_OF):
            if m >= 0 and mode_is_legal(w, h, q, d, key[0], key[1]):
                rows.append((int(m), w, h, q, d, int(weight_bits(w, h, q, d))))
        rows.sort(key=lambda r: (r[BM_WEIGHT_BITS], r[BM_GRID_W] * r[BM_GRID_H], r[BM_GRID_W],
                                 r[BM_WQUANT], r[BM_DUAL]))
        arr = np.array(rows, np.int32).reshape(-1, BM_COLUMNS)
        arr.setflags(write=False)
        _BLOCK_MODES[key] = arr
    return _BLOCK_MODES[key]
