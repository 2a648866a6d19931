"""BasisLZ supercompression of ETC1S blocks (KTX2 supercompressionScheme 1).

`pack` turns the ETC1S blocks of every level into BasisLZ global data (one
endpoint and one selector codebook for the whole file, four Huffman tables)
and one payload per level (its RGB slice, then its alpha slice); `unpack`
turns them back into the same blocks. Lossless both ways.

An ETC1S block is an ETC1 block in differential mode with zero colour deltas,
equal table codewords in both halves and the flip bit clear: its endpoint is
(R5, G5, B5, table) and its selectors are the 16 2-bit texel indices. The
writer takes the distinct endpoints and selectors as the codebooks, orders
them so consecutive entries differ little (the codebooks are sent as deltas),
predicts each block's endpoint from its neighbours, sends repeated selectors
through the history buffer and its runs, and builds every Huffman table from
the symbol counts of this file. The bit layout is the KTX 2.0 specification's
BasisLZ/ETC1S bitstream; the reader checks every count, length and code and
reports any problem as an InputError naming the file.
"""

from __future__ import annotations

import heapq
import struct

import numpy as np

from ..errors import InputError, UsageError
from ..formats import block_count
from . import basislz_kernels as K

MAX_CODEBOOK = 16128  # endpoints and selectors each (KTX-Software's encoder limit)
HISTORY_SIZE = 64  # selector history buffer entries the writer uses
HEADER = struct.Struct("<HHIIII")
IMAGE_DESC = struct.Struct("<5I")
PRED_SYMBOLS = K.PRED_REPEAT + 1

# ETC1 texel index (MSB << 1 | LSB: +a, +b, -a, -b) <-> BasisLZ selector value
# (-b, -a, +a, +b): the codebook orders selectors by their modifier.
_ETC1_TO_SEL = np.array([2, 3, 1, 0], np.uint8)
_SEL_TO_ETC1 = np.array([3, 2, 0, 1], np.uint8)

_ERRORS = {
    K.ERR_TRUNCATED: "truncated",
    K.ERR_TABLE_HEADER: "bad Huffman table header (code-length code count)",
    K.ERR_TABLE_LENGTHS: "bad Huffman table (code lengths overrun or repeat nothing)",
    K.ERR_NOT_PREFIX: "bad Huffman table (code lengths do not form a prefix code)",
    K.ERR_BAD_CODE: "bits that are no Huffman code",
    K.ERR_SELECTOR_HEADER: "selector codebook uses a global or hybrid codebook (reserved bits set)",
    K.ERR_PRED_NEIGHBOUR: "an endpoint predicted from a block outside the image",
    K.ERR_HISTORY_INDEX: "a selector history index past the history buffer",
    K.ERR_RUN_LENGTH: "a selector run longer than the image",
    K.ERR_ENDPOINT_INDEX: "an endpoint index past the codebook",
    K.ERR_SELECTOR_INDEX: "a selector index past the codebook",
    K.ERR_VLC: "a run length longer than 32 bits",
    K.ERR_EMPTY_TABLE: "an empty Huffman table",
}


# --------------------------------------------------------------------------- blocks <-> codebook keys


def _split(levels, width, height, alpha):
    """Per level and slice (RGB, then alpha): endpoint keys (R5 G5 B5 table in
    18 bits) and selector keys (the ETC1 selector bytes as a big-endian word)."""
    size = 16 if alpha else 8
    out = []
    for li, level in enumerate(levels):
        w, h = max(1, width >> li), max(1, height >> li)
        n = block_count(w, 4) * block_count(h, 4)
        raw = np.frombuffer(bytes(level), np.uint8)
        if raw.size != n * size:
            raise UsageError(f"BasisLZ: level {li} has {raw.size} bytes, expected {n * size} for {w}x{h}")
        raw = raw.reshape(n, size)
        slices = []
        for si in range(2 if alpha else 1):
            b = raw[:, 8 * si:8 * si + 8]
            t1, t2 = b[:, 3] >> 5, (b[:, 3] >> 2) & 7
            bad = ((b[:, 0] | b[:, 1] | b[:, 2]) & 7).astype(bool) | (t1 != t2) | ((b[:, 3] & 3) != 2)
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                what = "alpha" if si else "colour"
                raise UsageError(f"BasisLZ: level {li} block {i} ({what}) is not an ETC1S block "
                                 f"(bytes {b[i].tobytes().hex()}: needs differential mode, zero colour deltas, "
                                 "equal tables, flip 0)")
            ep = ((b[:, 0].astype(np.int64) >> 3) << 13) | ((b[:, 1].astype(np.int64) >> 3) << 8) \
                | ((b[:, 2].astype(np.int64) >> 3) << 3) | t1
            sel = b[:, 4:8].astype(np.int64)
            sel = (sel[:, 0] << 24) | (sel[:, 1] << 16) | (sel[:, 2] << 8) | sel[:, 3]
            slices.append((ep, sel, block_count(w, 4), block_count(h, 4)))
        out.append(slices)
    return out


def _etc1_to_rows(words):
    """ETC1 selector words -> (n, 4) BasisLZ row bytes."""
    words = np.asarray(words, np.int64)
    msb, lsb = words >> 16, words & 0xFFFF
    rows = np.zeros((words.size, 4), np.int64)
    for y in range(4):
        for x in range(4):
            k = x * 4 + y
            idx = (((msb >> k) & 1) << 1) | ((lsb >> k) & 1)
            rows[:, y] |= _ETC1_TO_SEL[idx].astype(np.int64) << (2 * x)
    return rows


def _rows_to_etc1(rows):
    """(n, 4) BasisLZ row bytes -> (n, 4) ETC1 selector bytes 4..7."""
    rows = np.asarray(rows, np.int64)
    msb = np.zeros(rows.shape[0], np.int64)
    lsb = np.zeros(rows.shape[0], np.int64)
    for y in range(4):
        for x in range(4):
            idx = _SEL_TO_ETC1[(rows[:, y] >> (2 * x)) & 3].astype(np.int64)
            k = x * 4 + y
            msb |= (idx >> 1) << k
            lsb |= (idx & 1) << k
    return np.stack([msb >> 8, msb & 255, lsb >> 8, lsb & 255], axis=1).astype(np.uint8)


# --------------------------------------------------------------------------- Huffman codes


def _huffman_lengths(counts, limit):
    """Code lengths of an optimal prefix code over the symbols with a count,
    none longer than `limit`; one used symbol gets length 1 (the code 0)."""
    counts = np.asarray(counts, np.int64)
    used = np.flatnonzero(counts)
    lengths = np.zeros(counts.size, np.int64)
    if used.size == 0:
        return lengths
    if used.size == 1:
        lengths[used[0]] = 1
        return lengths
    weights = counts[used].copy()
    m = used.size
    while True:
        heap = [(int(c), i) for i, c in enumerate(weights)]
        heapq.heapify(heap)
        parent = np.zeros(2 * m - 1, np.int64)
        node = m
        while len(heap) > 1:
            c1, a = heapq.heappop(heap)
            c2, b = heapq.heappop(heap)
            parent[a] = parent[b] = node
            heapq.heappush(heap, (c1 + c2, node))
            node += 1
        depth = np.zeros(2 * m - 1, np.int64)
        for i in range(2 * m - 3, -1, -1):  # parents are made after their children
            depth[i] = depth[parent[i]] + 1
        if depth[:m].max() <= limit:
            lengths[used] = depth[:m]
            return lengths
        weights = (weights + 1) >> 1  # flatten the counts until the code fits


def _canonical(lengths):
    """Bit-reversed canonical codes (written LSB first, read MSB first)."""
    lengths = np.asarray(lengths, np.int64)
    codes = np.zeros(lengths.size, np.int64)
    code = 0
    prev = 0
    for s in np.lexsort((np.arange(lengths.size), lengths)):
        ln = int(lengths[s])
        if ln == 0:
            continue
        code <<= ln - prev
        prev = ln
        rev = int(format(code, f"0{ln}b")[::-1], 2)
        codes[s] = rev
        code += 1
    return codes


class _Table:
    """One Huffman table built from symbol counts (a table nothing uses still
    gets one symbol: readers require every table)."""

    def __init__(self, counts, limit=K.MAX_CODE_BITS):
        counts = np.asarray(counts, np.int64)
        if not counts.any():
            counts = counts.copy()
            counts[0] = 1
        self.lengths = _huffman_lengths(counts, limit)
        self.codes = _canonical(self.lengths)

    def bits(self, symbols):
        symbols = np.asarray(symbols, np.int64)
        return self.codes[symbols], self.lengths[symbols]


class _Bits:
    """Collects (value, bit count) pairs; LSB first."""

    def __init__(self):
        self.vals = []
        self.nbs = []

    def put(self, value, n):
        self.vals.append(np.array([value], np.int64))
        self.nbs.append(np.array([n], np.int8))

    def put_arrays(self, vals, nbs):
        self.vals.append(np.asarray(vals, np.int64))
        self.nbs.append(np.asarray(nbs, np.int8))

    def sym(self, table, symbols):
        self.put_arrays(*table.bits(symbols))

    def table(self, table):
        """The table's code lengths, run-length and Huffman coded."""
        lengths = table.lengths
        nsyms = int(np.flatnonzero(lengths)[-1]) + 1
        syms, extra = _rle_lengths(lengths[:nsyms])
        cl = _Table(np.bincount(syms, minlength=21), limit=7)
        order_lengths = cl.lengths[K.CODES_ORDER]
        ncl = max(1, int(np.flatnonzero(order_lengths)[-1]) + 1 if order_lengths.any() else 1)
        self.put(nsyms, 14)
        self.put(ncl, 5)
        self.put_arrays(order_lengths[:ncl], np.full(ncl, 3))
        codes, lens = cl.bits(syms)
        ev = np.zeros(2 * len(syms), np.int64)
        nb = np.zeros(2 * len(syms), np.int64)
        ev[0::2], nb[0::2] = codes, lens
        ev[1::2] = [e for e, _ in extra]
        nb[1::2] = [n for _, n in extra]
        self.put_arrays(ev, nb)

    def bytes(self) -> bytes:
        if not self.vals:
            return b""
        return K.write_bits(np.concatenate(self.vals), np.concatenate(self.nbs).astype(np.int64)).tobytes()


def _rle_lengths(lengths):
    """Code lengths -> code-length symbols (0..16 lengths, 17/18 zero runs,
    19/20 repeats of the previous length) and each one's (extra bits, count)."""
    syms, extra = [], []
    i, n = 0, len(lengths)
    while i < n:
        v = int(lengths[i])
        j = i
        while j < n and lengths[j] == v:
            j += 1
        run = j - i
        if v == 0:
            while run >= 11:
                k = min(run, 138)
                syms.append(18), extra.append((k - 11, 7))
                run -= k
            if run >= 3:
                syms.append(17), extra.append((run - 3, 3))
                run = 0
            for _ in range(run):
                syms.append(0), extra.append((0, 0))
        else:
            syms.append(v), extra.append((0, 0))
            run -= 1
            while run >= 7:
                k = min(run, 134)
                syms.append(20), extra.append((k - 7, 7))
                run -= k
            if run >= 3:
                syms.append(19), extra.append((run - 3, 2))
                run = 0
            for _ in range(run):
                syms.append(v), extra.append((0, 0))
        i = j
    return np.array(syms, np.int64), extra


# --------------------------------------------------------------------------- writer


def pack(levels, width: int, height: int, alpha: bool):
    """ETC1S blocks of each level (base first; with alpha: per 4x4 block the
    colour block then the alpha block) -> (global data, [payload per level])."""
    if not levels:
        raise UsageError("BasisLZ: no levels to write")
    split = _split(levels, width, height, alpha)
    all_ep = np.concatenate([s[0] for lv in split for s in lv])
    all_sel = np.concatenate([s[1] for lv in split for s in lv])
    ep_keys, ep_inv = np.unique(all_ep, return_inverse=True)
    sel_keys, sel_inv = np.unique(all_sel, return_inverse=True)
    if ep_keys.size > MAX_CODEBOOK or sel_keys.size > MAX_CODEBOOK:
        raise UsageError(f"BasisLZ: {ep_keys.size} distinct endpoints and {sel_keys.size} distinct selectors; "
                         f"at most {MAX_CODEBOOK} of each fit the codebooks")
    ep_cb = np.stack([(ep_keys >> 13) & 31, (ep_keys >> 8) & 31, (ep_keys >> 3) & 31, ep_keys & 7], axis=1)
    sel_cb = _etc1_to_rows(sel_keys)
    ep_order = K.chain_order(ep_cb, 0, np.array([16, 16, 16, 0], np.int64))
    sel_order = K.chain_order(sel_cb, 1, sel_cb[0])
    ep_rank = np.empty_like(ep_order)
    ep_rank[ep_order] = np.arange(ep_order.size)
    sel_rank = np.empty_like(sel_order)
    sel_rank[sel_order] = np.arange(sel_order.size)
    ep_cb, sel_cb = ep_cb[ep_order], sel_cb[sel_order]
    n_ep, n_sel = ep_cb.shape[0], sel_cb.shape[0]

    # each slice's codebook indices, then its symbols
    slices = []
    pos = 0
    for lv in split:
        for ep, _sel, nbx, nby in lv:
            n = ep.size
            slices.append((ep_rank[ep_inv[pos:pos + n]], sel_rank[sel_inv[pos:pos + n]], nbx, nby))
            pos += n
    weight = np.zeros(PRED_SYMBOLS, np.float64)
    groups = [K.group_symbols(ep, nbx, nby, weight) for ep, _s, nbx, nby in slices]
    # second pass: where blocks allow several predictions, the symbols the first pass used most
    weight = np.bincount(np.concatenate(groups), minlength=PRED_SYMBOLS).astype(np.float64)
    groups = [K.group_symbols(ep, nbx, nby, weight) for ep, _s, nbx, nby in slices]
    events = [K.slice_events(ep, sel, nbx, nby, g, n_ep, n_sel, HISTORY_SIZE)
              for (ep, sel, nbx, nby), g in zip(slices, groups)]
    sizes = (PRED_SYMBOLS, n_ep, n_sel + HISTORY_SIZE + 1, K.SEL_RUN_TOTAL)
    counts = [np.zeros(s, np.int64) for s in sizes]
    for kind, val, _nb in events:
        for t in range(4):
            counts[t] += np.bincount(val[kind == t], minlength=sizes[t])
    tables = [_Table(c) for c in counts]

    payloads_rgb_alpha = []
    for kind, val, nb in events:
        vals = val.copy()
        nbs = nb.astype(np.int64)
        for t in range(4):
            m = kind == t
            vals[m], nbs[m] = tables[t].bits(val[m])
        data = K.write_bits(vals, nbs).tobytes()
        payloads_rgb_alpha.append(data or b"\0")
    endpoints = _endpoint_data(ep_cb)
    selectors = _selector_data(sel_cb)
    tb = _Bits()
    for t in tables:
        tb.table(t)
    tb.put(HISTORY_SIZE, 13)
    table_data = tb.bytes()

    per = 2 if alpha else 1
    descs = []
    payloads = []
    for li in range(len(levels)):
        parts = payloads_rgb_alpha[per * li:per * li + per]
        rgb = parts[0]
        a = parts[1] if alpha else b""
        descs.append(IMAGE_DESC.pack(0, 0, len(rgb), len(rgb) if alpha else 0, len(a)))
        payloads.append(rgb + a)
    head = HEADER.pack(n_ep, n_sel, len(endpoints), len(selectors), len(table_data), 0)
    return head + b"".join(descs) + endpoints + selectors + table_data, payloads


def _endpoint_data(cb):
    """Endpoint codebook: DPCM of the table index and of each colour channel,
    the colour table chosen by the previous value's range."""
    cb = np.asarray(cb, np.int64)
    grey = bool(np.all((cb[:, 0] == cb[:, 1]) & (cb[:, 1] == cb[:, 2])))
    nch = 1 if grey else 3
    prev = np.vstack([np.full((1, 4), 16, np.int64), cb])[:-1]
    prev[0, 3] = 0
    inten = (cb[:, 3] - prev[:, 3]) & 7
    delta = (cb[:, :nch] - prev[:, :nch]) & 31
    which = np.where(prev[:, :nch] <= 9, 0, np.where(prev[:, :nch] <= 21, 1, 2))
    colour = [_Table(np.bincount(delta[which == k], minlength=32)) for k in range(3)]
    inten_t = _Table(np.bincount(inten, minlength=8))
    out = _Bits()
    for t in colour + [inten_t]:
        out.table(t)
    out.put(int(grey), 1)
    n = cb.shape[0]
    vals = np.zeros((n, 1 + nch), np.int64)
    nbs = np.zeros((n, 1 + nch), np.int64)
    vals[:, 0], nbs[:, 0] = inten_t.bits(inten)
    for c in range(nch):
        for k in range(3):
            m = which[:, c] == k
            vals[m, 1 + c], nbs[m, 1 + c] = colour[k].bits(delta[m, c])
    out.put_arrays(vals.ravel(), nbs.ravel())
    return out.bytes()


def _selector_data(cb):
    """Selector codebook: the first entry raw, then XOR deltas Huffman coded,
    or every entry raw when that is smaller."""
    cb = np.asarray(cb, np.int64)
    raw = _Bits()
    raw.put(4, 3)
    raw.put_arrays(cb.ravel(), np.full(cb.size, 8))
    delta = (cb[1:] ^ cb[:-1]).ravel()
    t = _Table(np.bincount(delta, minlength=256))
    coded = _Bits()
    coded.put(0, 3)
    coded.table(t)
    coded.put_arrays(cb[0], np.full(4, 8))
    coded.sym(t, delta)
    a, b = raw.bytes(), coded.bytes()
    return a if len(a) < len(b) else b


# --------------------------------------------------------------------------- reader


def unpack(global_data, level_payloads, width: int, height: int, alpha: bool, name) -> list:
    """BasisLZ global data and each level's payload -> ETC1S blocks per level
    (the form `pack` takes). Any inconsistency is an InputError naming `name`."""

    def fail(msg):
        raise InputError(f"BasisLZ: {msg}", path=name)

    gd = bytes(global_data)
    n = len(level_payloads)
    if len(gd) < HEADER.size:
        fail(f"global data of {len(gd)} bytes is shorter than its {HEADER.size}-byte header")
    n_ep, n_sel, ep_len, sel_len, tab_len, ext_len = HEADER.unpack_from(gd, 0)
    want = HEADER.size + IMAGE_DESC.size * n + ep_len + sel_len + tab_len + ext_len
    if want != len(gd):
        fail(f"global data is {len(gd)} bytes but its header and {n} image(s) need {want}")
    if ext_len:
        fail(f"extendedByteLength {ext_len} must be 0 for ETC1S")
    if n_ep == 0 or n_sel == 0:
        fail(f"endpointCount {n_ep} and selectorCount {n_sel} must both be at least 1")
    pos = HEADER.size + IMAGE_DESC.size * n
    sections = []
    for length in (ep_len, sel_len, tab_len):
        sections.append(np.frombuffer(gd, np.uint8, length, pos))
        pos += length

    ep_cb = np.zeros((n_ep, 4), np.int64)
    status = K.decode_endpoints(sections[0], n_ep, ep_cb)
    if status:
        fail(f"endpoint codebook: {_ERRORS[status]}")
    sel_cb = np.zeros((n_sel, 4), np.int64)
    status = K.decode_selectors(sections[1], n_sel, sel_cb)
    if status:
        fail(f"selector codebook: {_ERRORS[status]}")
    status, luts, offs, bits, nsyms, hist = K.decode_tables(sections[2])
    if status:
        fail(f"slice Huffman tables: {_ERRORS[status]}")
    if hist == 0:
        fail("selector history buffer size is 0")
    ep_bytes = np.zeros((n_ep, 4), np.uint8)
    ep_bytes[:, :3] = ep_cb[:, :3] << 3
    ep_bytes[:, 3] = (ep_cb[:, 3] << 5) | (ep_cb[:, 3] << 2) | 2
    sel_bytes = _rows_to_etc1(sel_cb)

    out = []
    for li in range(n):
        flags, rgb_off, rgb_len, a_off, a_len = IMAGE_DESC.unpack_from(gd, HEADER.size + IMAGE_DESC.size * li)
        payload = bytes(level_payloads[li])
        if flags:
            fail(f"level {li} imageFlags 0x{flags:x}: only I-frames of a still image are supported")
        spans = [("RGB", rgb_off, rgb_len)]
        if alpha:
            spans.append(("alpha", a_off, a_len))
        elif a_off or a_len:
            fail(f"level {li} has an alpha slice ({a_len} bytes at {a_off}) but the DFD has one sample")
        w, h = max(1, width >> li), max(1, height >> li)
        nbx, nby = block_count(w, 4), block_count(h, 4)
        parts = []
        for what, off, length in spans:
            if length == 0:
                fail(f"level {li} {what} slice is empty")
            if off + length > len(payload):
                fail(f"level {li} {what} slice ({length} bytes at {off}) overruns the level's {len(payload)} bytes")
            data = np.frombuffer(payload, np.uint8, length, off)
            ep_idx = np.zeros(nbx * nby, np.int64)
            sel_idx = np.zeros(nbx * nby, np.int64)
            status, block = K.decode_slice(data, nbx, nby, luts, offs, bits, n_ep, n_sel, hist, ep_idx, sel_idx)
            if status:
                fail(f"level {li} {what} slice, block {block}: {_ERRORS[status]}")
            parts.append(np.concatenate([ep_bytes[ep_idx], sel_bytes[sel_idx]], axis=1))
        out.append(np.concatenate(parts, axis=1).tobytes())
    return out
