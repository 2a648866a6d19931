"""128 bits -> symbolic block, with every illegal encoding the spec lists
mapped to S_KIND = KIND_ERROR.

Symbolic blocks describe LDR content: an HDR void-extent block (which LDR
decoding turns into the error colour) unpacks as an error block. HDR colour
endpoint modes are kept as they are: only their partition decodes to the error
colour. A void extent with real (not all-ones) coordinates unpacks to the same
constant colour; the coordinates are not kept.
"""

import numpy as np

from ..._jit import jit, jit_typed
from .bise import bit_reverse_into, ise_decode, read_bits
from .modes import VOID_EXTENT_MODE, cem_field_decode, colour_range, config_bits, decode_block_mode
from .quant import ise_bits
from .symbolic import (KIND_ERROR, KIND_NORMAL, KIND_VOID, S_CCS, S_CEM, S_CQUANT, S_DUAL,
                       S_ENDPOINTS, S_GRID_H, S_GRID_W, S_KIND, S_PARTS, S_PINDEX, S_VOID,
                       S_WEIGHTS, S_WQUANT, SYM_LEN)


@jit_typed("void(int32[::1])")
def _error(s):
    for i in range(SYM_LEN):
        s[i] = 0
    s[S_KIND] = KIND_ERROR


@jit_typed("void(uint8[::1], int32[::1], int64, int64)")
def unpack_block(blk, s, bw, bh):
    """Fill s (int32[SYM_LEN]) from the 16 bytes blk of a bw x bh block."""
    for i in range(SYM_LEN):
        s[i] = 0
    mode = read_bits(blk, 0, 11)
    if (mode & 0x1FF) == VOID_EXTENT_MODE:
        if mode & 0x200 or read_bits(blk, 10, 2) != 3:
            _error(s)
            return
        low_s = read_bits(blk, 12, 13)
        high_s = read_bits(blk, 25, 13)
        low_t = read_bits(blk, 38, 13)
        high_t = read_bits(blk, 51, 13)
        all_ones = low_s == 0x1FFF and high_s == 0x1FFF and low_t == 0x1FFF and high_t == 0x1FFF
        if not all_ones and (low_s >= high_s or low_t >= high_t):
            _error(s)
            return
        s[S_KIND] = KIND_VOID
        for c in range(4):
            s[S_VOID + c] = read_bits(blk, 64 + 16 * c, 16)
        return
    ok, gw, gh, wq, dual = decode_block_mode(mode)
    if not ok or gw > bw or gh > bh:
        _error(s)
        return
    nw = gw * gh * (dual + 1)
    wbits = ise_bits(nw, wq)
    parts = read_bits(blk, 11, 2) + 1
    if nw > 64 or wbits < 24 or wbits > 96 or (dual and parts == 4):
        _error(s)
        return
    cems = np.zeros(4, np.int64)
    nextra = 0
    same = True
    if parts == 1:
        cems[0] = read_bits(blk, 13, 4)
    else:
        s[S_PINDEX] = read_bits(blk, 13, 10)
        field = read_bits(blk, 23, 6)
        if field & 3:
            same = False
            nextra = 3 * parts - 4
            field |= read_bits(blk, 128 - wbits - nextra, nextra) << 6
        cem_field_decode(field, parts, cems)
    ncol = 0
    for p in range(parts):
        ncol += 2 * ((cems[p] >> 2) + 1)
    cr = colour_range(ncol, 128 - config_bits(parts, same, dual) - wbits)
    if cr < 0:
        _error(s)
        return
    s[S_KIND] = KIND_NORMAL
    s[S_GRID_W] = gw
    s[S_GRID_H] = gh
    s[S_WQUANT] = wq
    s[S_DUAL] = dual
    s[S_PARTS] = parts
    for p in range(parts):
        s[S_CEM + p] = cems[p]
    s[S_CQUANT] = cr
    ise_decode(blk, 17 if parts == 1 else 29, ncol, cr, s[S_ENDPOINTS:S_ENDPOINTS + ncol])
    rev = np.zeros(16, np.uint8)
    bit_reverse_into(blk, rev)
    ise_decode(rev, 0, nw, wq, s[S_WEIGHTS:S_WEIGHTS + nw])
    if dual:
        s[S_CCS] = read_bits(blk, 128 - wbits - nextra - 2, 2)


@jit
def unpack_blocks(data, sym, bw, bh):
    """data uint8 (n, 16) -> sym int32 (n, SYM_LEN)."""
    blk = np.zeros(16, np.uint8)  # a writable copy: data may be a read-only buffer
    for i in range(data.shape[0]):
        for k in range(16):
            blk[k] = data[i, k]
        unpack_block(blk, sym[i], bw, bh)


def unpack(data, bw, bh):
    """Python entry: bytes (a multiple of 16) -> int32 (n, SYM_LEN)."""
    buf = np.frombuffer(bytes(data), np.uint8).reshape(-1, 16)
    sym = np.zeros((buf.shape[0], SYM_LEN), np.int32)
    unpack_blocks(buf, sym, np.int64(bw), np.int64(bh))
    return sym
