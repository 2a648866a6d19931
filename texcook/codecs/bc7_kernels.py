"""BC7 kernels: the symbolic block, its bits, the decoder.

A block's symbolic form is an int64 row of SYM_LEN slots (named below): mode,
partition, rotation, index selector, the stored endpoint channels (without
p-bit), the p-bits and both index sets, one index per texel. `pack` turns a
symbolic block into its 16 bytes and `unpack` reads it back; the decoder and
the encoder's search (bc7_search) meet only here. A symbolic block is packed
as it stands: the anchor rule (an anchor texel's index has its top bit 0) is
the encoder's to establish first (`normalise_anchors`), and `pack` leaves it
to the caller to keep every field within its width.
"""

import numpy as np

from .._jit import jit, jit_inner
from ._kernels import get_bits
from .bc7_tables import (AB, ANCHOR, CB, EPB, EXPAND, IB, IB2, ISB, MODES, NS, PB, RB, SPB, SUBSET,
                         WEIGHTS)

S_MODE = 0  # 0..7, or 8: the reserved encoding (byte 0 is zero)
S_PART = 1
S_ROT = 2
S_ISEL = 3
S_EP = 4  # 24 slots: S_EP + (subset * 2 + endpoint) * 4 + channel (R, G, B, A)
S_P = 28  # 6 slots: S_P + subset * 2 + endpoint (a shared p-bit is in both)
S_IDX = 34  # 16 primary indices
S_IDX2 = 50  # 16 secondary indices (modes 4 and 5)
SYM_LEN = 66
RESERVED = 8


@jit_inner
def anchor_of(ns, part, texel):
    """True when `texel` is the anchor of its subset (its index has one bit fewer)."""
    s = SUBSET[ns - 1, part, texel]
    return ANCHOR[ns - 1, part, s] == texel


@jit_inner
def index_sets(mode, isel):
    """(colour slot, alpha slot, colour index bits, alpha index bits) of a mode:
    where the indices that interpolate R, G, B and those for A live."""
    ib = MODES[mode, IB]
    ib2 = MODES[mode, IB2]
    if ib2 == 0:
        return S_IDX, S_IDX, ib, ib
    if isel == 1:
        return S_IDX2, S_IDX, ib2, ib
    return S_IDX, S_IDX2, ib, ib2


@jit_inner
def endpoint_value(sym, mode, s, e, c):
    """Endpoint channel expanded to 8 bits (p-bit appended, top bits replicated)."""
    q = sym[S_EP + (s * 2 + e) * 4 + c]
    bits = MODES[mode, AB] if c == 3 else MODES[mode, CB]
    if MODES[mode, EPB] or MODES[mode, SPB]:
        return EXPAND[bits, sym[S_P + s * 2 + e], q]
    return EXPAND[bits, 2, q]


@jit_inner
def decode_sym(sym, out):
    """The 16 texels of a symbolic block into out (16, 4) uint8."""
    mode = sym[S_MODE]
    if mode == RESERVED:
        for i in range(16):
            for c in range(4):
                out[i, c] = 0
        return
    ns = MODES[mode, NS]
    part = sym[S_PART]
    cslot, aslot, cbits, abits = index_sets(mode, sym[S_ISEL])
    has_alpha = MODES[mode, AB] > 0
    for i in range(16):
        s = SUBSET[ns - 1, part, i]
        for c in range(4):
            if c == 3 and not has_alpha:
                out[i, c] = 255
                continue
            if c == 3:
                wt = WEIGHTS[abits, sym[aslot + i]]
            else:
                wt = WEIGHTS[cbits, sym[cslot + i]]
            e0 = endpoint_value(sym, mode, s, 0, c)
            e1 = endpoint_value(sym, mode, s, 1, c)
            out[i, c] = ((64 - wt) * e0 + wt * e1 + 32) >> 6
    rot = sym[S_ROT]
    if rot:
        for i in range(16):
            t = out[i, 3]
            out[i, 3] = out[i, rot - 1]
            out[i, rot - 1] = t


# --------------------------------------------------------------------------
# bits: fields in increasing bit order from bit 0 of byte 0


@jit_inner
def unpack(d, sym):
    """16 bytes -> symbolic block (sym filled; reserved blocks get S_MODE 8)."""
    for k in range(SYM_LEN):
        sym[k] = 0
    mode = 0
    while mode < 8 and not (d[0] >> mode) & 1:
        mode += 1
    sym[S_MODE] = mode
    if mode == RESERVED:
        return
    pos = mode + 1
    ns = MODES[mode, NS]
    sym[S_PART] = get_bits(d, pos, MODES[mode, PB])
    pos += MODES[mode, PB]
    sym[S_ROT] = get_bits(d, pos, MODES[mode, RB])
    pos += MODES[mode, RB]
    sym[S_ISEL] = get_bits(d, pos, MODES[mode, ISB])
    pos += MODES[mode, ISB]
    nch = 4 if MODES[mode, AB] else 3
    for c in range(nch):
        bits = MODES[mode, AB] if c == 3 else MODES[mode, CB]
        for s in range(ns):
            for e in range(2):
                sym[S_EP + (s * 2 + e) * 4 + c] = get_bits(d, pos, bits)
                pos += bits
    if MODES[mode, EPB]:
        for s in range(ns):
            for e in range(2):
                sym[S_P + s * 2 + e] = get_bits(d, pos, 1)
                pos += 1
    if MODES[mode, SPB]:
        for s in range(ns):
            p = get_bits(d, pos, 1)
            pos += 1
            sym[S_P + s * 2] = p
            sym[S_P + s * 2 + 1] = p
    part = sym[S_PART]
    ib = MODES[mode, IB]
    for i in range(16):
        n = ib - 1 if anchor_of(ns, part, i) else ib
        sym[S_IDX + i] = get_bits(d, pos, n)
        pos += n
    ib2 = MODES[mode, IB2]
    if ib2:
        for i in range(16):
            n = ib2 - 1 if i == 0 else ib2
            sym[S_IDX2 + i] = get_bits(d, pos, n)
            pos += n


@jit_inner
def _add(lo, hi, pos, v, n):
    """(lo, hi, pos) with the n-bit value v written at bit pos of the 128-bit
    (lo, hi) pair: whole words, not bit by bit."""
    u = np.uint64(v)
    if pos < 64:
        lo |= u << np.uint64(pos)
        if pos + n > 64:
            hi |= u >> np.uint64(64 - pos)
    else:
        hi |= u << np.uint64(pos - 64)
    return lo, hi, pos + n


@jit_inner
def pack(sym, d):
    """Symbolic block -> 16 bytes in d (anchors' top index bits must be 0)."""
    lo = np.uint64(0)
    hi = np.uint64(0)
    mode = sym[S_MODE]
    ns = MODES[mode, NS]
    lo, hi, pos = _add(lo, hi, 0, np.int64(1) << mode, mode + 1)
    lo, hi, pos = _add(lo, hi, pos, sym[S_PART], MODES[mode, PB])
    lo, hi, pos = _add(lo, hi, pos, sym[S_ROT], MODES[mode, RB])
    lo, hi, pos = _add(lo, hi, pos, sym[S_ISEL], MODES[mode, ISB])
    nch = 4 if MODES[mode, AB] else 3
    for c in range(nch):
        bits = MODES[mode, AB] if c == 3 else MODES[mode, CB]
        for s in range(ns):
            for e in range(2):
                lo, hi, pos = _add(lo, hi, pos, sym[S_EP + (s * 2 + e) * 4 + c], bits)
    if MODES[mode, EPB]:
        for s in range(ns):
            for e in range(2):
                lo, hi, pos = _add(lo, hi, pos, sym[S_P + s * 2 + e], 1)
    if MODES[mode, SPB]:
        for s in range(ns):
            lo, hi, pos = _add(lo, hi, pos, sym[S_P + s * 2], 1)
    part = sym[S_PART]
    ib = MODES[mode, IB]
    for i in range(16):
        n = ib - 1 if anchor_of(ns, part, i) else ib
        lo, hi, pos = _add(lo, hi, pos, sym[S_IDX + i], n)
    ib2 = MODES[mode, IB2]
    if ib2:
        for i in range(16):
            n = ib2 - 1 if i == 0 else ib2
            lo, hi, pos = _add(lo, hi, pos, sym[S_IDX2 + i], n)
    for k in range(8):
        d[k] = np.uint8((lo >> np.uint64(8 * k)) & np.uint64(255))
        d[8 + k] = np.uint8((hi >> np.uint64(8 * k)) & np.uint64(255))


@jit_inner
def normalise_anchors(sym):
    """Make every anchor index's top bit 0, as the bits require: where it is 1,
    swap that subset's endpoints (the channels the index set interpolates, and
    per-endpoint p-bits) and mirror its indices. The decoded texels are the same."""
    mode = sym[S_MODE]
    ns = MODES[mode, NS]
    part = sym[S_PART]
    cslot, aslot, cbits, abits = index_sets(mode, sym[S_ISEL])
    nsets = 2 if cslot != aslot else 1
    for k in range(nsets):
        slot = cslot if k == 0 else aslot
        bits = cbits if k == 0 else abits
        c0 = 0 if nsets == 1 or k == 0 else 3
        c1 = 4 if nsets == 1 else (3 if k == 0 else 4)
        top = np.int64(1) << (bits - 1)
        last = (np.int64(1) << bits) - 1
        for s in range(ns):
            a = ANCHOR[ns - 1, part, s]
            if sym[slot + a] & top:
                for i in range(16):
                    if SUBSET[ns - 1, part, i] == s:
                        sym[slot + i] = last - sym[slot + i]
                for c in range(c0, c1):
                    j0 = S_EP + (s * 2) * 4 + c
                    t = sym[j0]
                    sym[j0] = sym[j0 + 4]
                    sym[j0 + 4] = t
                if MODES[mode, EPB]:
                    t = sym[S_P + s * 2]
                    sym[S_P + s * 2] = sym[S_P + s * 2 + 1]
                    sym[S_P + s * 2 + 1] = t


# --------------------------------------------------------------------------
# runs over many blocks (the codec's decoder, and the tests' view of the bits)


@jit
def decode_run(data, out):
    sym = np.zeros(SYM_LEN, np.int64)
    for b in range(data.shape[0]):
        unpack(data[b], sym)
        decode_sym(sym, out[b])


@jit
def unpack_run(data, syms):
    for b in range(data.shape[0]):
        unpack(data[b], syms[b])


@jit
def pack_run(syms, data):
    for b in range(syms.shape[0]):
        pack(syms[b], data[b])


@jit
def normalise_run(syms):
    for b in range(syms.shape[0]):
        normalise_anchors(syms[b])


@jit
def decode_sym_run(syms, out):
    for b in range(syms.shape[0]):
        decode_sym(syms[b], out[b])
