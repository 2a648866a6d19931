"""BasisLZ kernels: the LSB-first bit reader and writer, canonical Huffman
lookup tables, the ETC1S codebooks' and slices' decoding, and the writer's
choice of symbols for a slice.

Every reader returns a status (0 = good, else one of the ERR_* codes that
texcook.container.basislz turns into a message) instead of raising: the
kernels never index outside their arrays and every loop is bounded by a
count the caller checked, so corrupt data ends in a status, not a hang.
"""

import numpy as np

from texcook._jit import jit
from texcook._jit import jit_inner as _inner

ERR_TRUNCATED = 1
ERR_TABLE_HEADER = 2
ERR_TABLE_LENGTHS = 3
ERR_NOT_PREFIX = 4
ERR_BAD_CODE = 5
ERR_SELECTOR_HEADER = 6
ERR_PRED_NEIGHBOUR = 7
ERR_HISTORY_INDEX = 8
ERR_RUN_LENGTH = 9
ERR_ENDPOINT_INDEX = 10
ERR_SELECTOR_INDEX = 11
ERR_VLC = 12
ERR_EMPTY_TABLE = 13

MAX_CODE_BITS = 16  # the longest Huffman code BasisLZ allows
# code-length codes are sent in this order (17..20 are runs, then lengths)
CODES_ORDER = np.array([17, 18, 19, 20, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1, 15, 16], dtype=np.int64)

PRED_REPEAT = 256  # endpoint prediction symbol: repeat the last group symbol
PRED_MIN_RUN = 3
SEL_RUN_MIN = 3
SEL_RUN_TOTAL = 64  # selector-run symbols; the last one is followed by a vlc7 count

# the writer's event kinds: a symbol of one of the four slice tables, or raw bits
EV_PRED, EV_DELTA, EV_SEL, EV_RUN, EV_RAW = 0, 1, 2, 3, 4


# ---------------------------------------------------------------- reading bits


@_inner
def peek(data, pos):
    """32 bits of `data` from bit `pos` (LSB first); zeros past the end."""
    i = pos >> 3
    n = data.shape[0]
    w = np.int64(0)
    for k in range(5):
        if i + k < n:
            w |= np.int64(data[i + k]) << (8 * k)
    return (w >> (pos & 7)) & 0xFFFFFFFF


@_inner
def build_lut(lengths, n):
    """Decoding table of a canonical code over symbols 0..n-1: entry (read bits
    masked to `bits`) -> symbol << 5 | code length, -1 for no code. Returns
    (status, bits, lut). Valid: a complete code, or one used symbol."""
    count = np.zeros(MAX_CODE_BITS + 1, np.int64)
    used = 0
    maxlen = 0
    for s in range(n):
        ln = lengths[s]
        if ln > MAX_CODE_BITS:
            return ERR_NOT_PREFIX, 0, np.zeros(1, np.int32)
        if ln:
            count[ln] += 1
            used += 1
            maxlen = max(maxlen, ln)
    if used == 0:
        return ERR_EMPTY_TABLE, 0, np.zeros(1, np.int32)
    kraft = np.int64(0)
    for ln in range(1, MAX_CODE_BITS + 1):
        kraft += count[ln] << (MAX_CODE_BITS - ln)
    if used > 1 and kraft != (1 << MAX_CODE_BITS):
        return ERR_NOT_PREFIX, 0, np.zeros(1, np.int32)
    bits = maxlen
    lut = np.full(1 << bits, -1, np.int32)
    nxt = np.zeros(MAX_CODE_BITS + 2, np.int64)
    code = np.int64(0)
    for ln in range(1, MAX_CODE_BITS + 1):
        code = (code + count[ln - 1]) << 1 if ln > 1 else 0
        nxt[ln] = code
    for s in range(n):
        ln = lengths[s]
        if ln == 0:
            continue
        c = nxt[ln]
        nxt[ln] += 1
        rev = np.int64(0)
        for k in range(ln):
            rev = (rev << 1) | ((c >> k) & 1)
        step = np.int64(1) << ln
        j = rev
        while j < (1 << bits):
            lut[j] = (s << 5) | ln
            j += step
    return 0, bits, lut


@_inner
def decode_sym(data, pos, lut, bits):
    """(symbol or -1, new pos)."""
    e = lut[peek(data, pos) & ((1 << bits) - 1)]
    if e < 0:
        return -1, pos
    return e >> 5, pos + (e & 31)


@_inner
def read_vlc(data, pos, chunk):
    """A value sent in chunks of `chunk` bits each followed by a continue bit:
    (value or -1, new pos)."""
    v = np.int64(0)
    ofs = 0
    while True:
        s = peek(data, pos) & ((1 << (chunk + 1)) - 1)
        pos += chunk + 1
        v |= (s & ((1 << chunk) - 1)) << ofs
        ofs += chunk
        if (s >> chunk) == 0:
            return v, pos
        if ofs >= 32:
            return -1, pos


@_inner
def read_table(data, pos, lengths):
    """One compressed Huffman table: code lengths into `lengths` (zeroed
    first). Returns (status, pos, number of symbols)."""
    lengths[:] = 0
    nsyms = peek(data, pos) & 0x3FFF
    ncl = (peek(data, pos + 14) & 31)
    pos += 19
    if nsyms == 0:
        return ERR_EMPTY_TABLE, pos, 0
    if ncl < 1 or ncl > 21:
        return ERR_TABLE_HEADER, pos, 0
    cl = np.zeros(21, np.int64)
    for i in range(ncl):
        cl[CODES_ORDER[i]] = peek(data, pos) & 7
        pos += 3
    status, bits, lut = build_lut(cl, 21)
    if status:
        return status, pos, 0
    cur = 0
    while cur < nsyms:
        if pos > 8 * data.shape[0]:
            return ERR_TRUNCATED, pos, 0
        c, pos = decode_sym(data, pos, lut, bits)
        if c < 0:
            return ERR_BAD_CODE, pos, 0
        if c <= 16:
            lengths[cur] = c
            cur += 1
        elif c == 17:
            cur += (peek(data, pos) & 7) + 3
            pos += 3
        elif c == 18:
            cur += (peek(data, pos) & 127) + 11
            pos += 7
        else:
            if cur == 0 or lengths[cur - 1] == 0:
                return ERR_TABLE_LENGTHS, pos, 0
            if c == 19:
                run = (peek(data, pos) & 3) + 3
                pos += 2
            else:
                run = (peek(data, pos) & 127) + 7
                pos += 7
            if cur + run > nsyms:
                return ERR_TABLE_LENGTHS, pos, 0
            for _ in range(run):
                lengths[cur] = lengths[cur - 1]
                cur += 1
    if cur != nsyms:
        return ERR_TABLE_LENGTHS, pos, 0
    if pos > 8 * data.shape[0]:
        return ERR_TRUNCATED, pos, 0
    return 0, pos, nsyms


@_inner
def read_lut(data, pos):
    """(status, pos, bits, lut, number of symbols) of the table at `pos`."""
    lengths = np.zeros(1 << 14, np.int64)
    status, pos, n = read_table(data, pos, lengths)
    if status:
        return status, pos, 0, np.zeros(1, np.int32), 0
    status, bits, lut = build_lut(lengths, n)
    return status, pos, bits, lut, n


# ---------------------------------------------------------------- codebooks


@jit
def decode_endpoints(data, n, out):
    """Endpoint codebook -> out[i] = (R5, G5, B5, table). Returns status."""
    pos = 0
    st, pos, b0, lut0, _n0 = read_lut(data, pos)
    if st:
        return st
    st, pos, b1, lut1, _n1 = read_lut(data, pos)
    if st:
        return st
    st, pos, b2, lut2, _n2 = read_lut(data, pos)
    if st:
        return st
    st, pos, bi, luti, _ni = read_lut(data, pos)
    if st:
        return st
    grey = peek(data, pos) & 1
    pos += 1
    prev = np.array([16, 16, 16], np.int64)
    inten = 0
    for i in range(n):
        d, pos = decode_sym(data, pos, luti, bi)
        if d < 0:
            return ERR_BAD_CODE
        inten = (inten + d) & 7
        out[i, 3] = inten
        for c in range(1 if grey else 3):
            p = prev[c]
            if p <= 9:
                d, pos = decode_sym(data, pos, lut0, b0)
            elif p <= 21:
                d, pos = decode_sym(data, pos, lut1, b1)
            else:
                d, pos = decode_sym(data, pos, lut2, b2)
            if d < 0:
                return ERR_BAD_CODE
            prev[c] = (p + d) & 31
            out[i, c] = prev[c]
        if grey:
            out[i, 1] = out[i, 0]
            out[i, 2] = out[i, 0]
        if pos > 8 * data.shape[0]:
            return ERR_TRUNCATED
    return 0


@jit
def decode_selectors(data, n, out):
    """Selector codebook -> out[i] = four row bytes (2 bits per texel, x = 0
    in the low bits). Returns status."""
    pos = 0
    head = peek(data, pos) & 7
    pos += 3
    if head & 3:
        return ERR_SELECTOR_HEADER
    if head & 4:  # stored raw
        for i in range(n):
            for j in range(4):
                out[i, j] = peek(data, pos) & 255
                pos += 8
        return ERR_TRUNCATED if pos > 8 * data.shape[0] else 0
    st, pos, bits, lut, _m = read_lut(data, pos)
    if st and not (st == ERR_EMPTY_TABLE and n <= 1):
        return st
    prev = np.zeros(4, np.int64)
    for j in range(4):
        prev[j] = peek(data, pos) & 255
        pos += 8
        if n:
            out[0, j] = prev[j]
    for i in range(1, n):
        for j in range(4):
            d, pos = decode_sym(data, pos, lut, bits)
            if d < 0:
                return ERR_BAD_CODE
            prev[j] = (prev[j] ^ d) & 255
            out[i, j] = prev[j]
        if pos > 8 * data.shape[0]:
            return ERR_TRUNCATED
    return 0


@jit
def decode_tables(data):
    """The four slice tables and the history size: (status, luts, bits,
    symbol counts, history size); luts concatenated, offsets in `offs`."""
    luts = np.zeros(0, np.int32)
    bits = np.zeros(4, np.int64)
    offs = np.zeros(5, np.int64)
    nsyms = np.zeros(4, np.int64)
    pos = 0
    for t in range(4):
        st, pos, b, lut, m = read_lut(data, pos)
        if st:
            return st, luts, offs, bits, nsyms, 0
        bits[t] = b
        nsyms[t] = m
        luts = np.concatenate((luts, lut))
        offs[t + 1] = luts.shape[0]
    hist = peek(data, pos) & 0x1FFF
    pos += 13
    if pos > 8 * data.shape[0]:
        return ERR_TRUNCATED, luts, offs, bits, nsyms, 0
    return 0, luts, offs, bits, nsyms, hist


# ---------------------------------------------------------------- slices


@jit
def decode_slice(data, nbx, nby, luts, offs, bits, n_ep, n_sel, hist_size, ep_out, sel_out):
    """One slice -> ep_out, sel_out (codebook indices, raster order).
    Returns (status, block index where it failed)."""
    lp = luts[offs[0]:offs[1]]
    ld = luts[offs[1]:offs[2]]
    ls = luts[offs[2]:offs[3]]
    lr = luts[offs[3]:offs[4]]
    bp, bd, bs, br = bits[0], bits[1], bits[2], bits[3]
    total = nbx * nby
    ep_rows = np.zeros((2, nbx), np.int64)  # endpoint indices of this row and the one above
    pred_bits = np.zeros((nbx + 1) >> 1, np.int64)  # an even row's group symbols, for the odd row below
    history = np.zeros(max(hist_size, 1), np.int64)
    rover = hist_size // 2
    run_sym = n_sel + hist_size
    sel_run = 0
    cur = np.int64(0)
    prev_sym = np.int64(0)
    pred_run = 0
    prev_ep = np.int64(0)
    nbits = 8 * data.shape[0]
    pos = np.int64(0)
    for y in range(nby):
        row = y & 1
        for x in range(nbx):
            b = y * nbx + x
            if (x & 1) == 0:
                if row == 0:
                    if pred_run:
                        pred_run -= 1
                        cur = prev_sym
                    else:
                        s, pos = decode_sym(data, pos, lp, bp)
                        if s < 0:
                            return ERR_BAD_CODE, b
                        if s == PRED_REPEAT:
                            v, pos = read_vlc(data, pos, 4)
                            if v < 0:
                                return ERR_VLC, b
                            pred_run = v + PRED_MIN_RUN - 1
                            cur = prev_sym
                        else:
                            cur = s
                            prev_sym = s
                    pred_bits[x >> 1] = (cur >> 4) & 255
                else:
                    cur = pred_bits[x >> 1]
            pred = cur & 3
            cur >>= 2
            if pred == 0:
                if x == 0:
                    return ERR_PRED_NEIGHBOUR, b
                e = prev_ep
            elif pred == 1:
                if y == 0:
                    return ERR_PRED_NEIGHBOUR, b
                e = ep_rows[row ^ 1, x]
            elif pred == 2:
                if x == 0 or y == 0:
                    return ERR_PRED_NEIGHBOUR, b
                e = ep_rows[row ^ 1, x - 1]
            else:
                d, pos = decode_sym(data, pos, ld, bd)
                if d < 0:
                    return ERR_BAD_CODE, b
                e = prev_ep + d
                if e >= n_ep:
                    e -= n_ep
            if e >= n_ep:
                return ERR_ENDPOINT_INDEX, b
            ep_rows[row, x] = e
            prev_ep = e
            ep_out[b] = e
            if sel_run > 0:
                sel_run -= 1
                s = n_sel
            else:
                s, pos = decode_sym(data, pos, ls, bs)
                if s < 0:
                    return ERR_BAD_CODE, b
                if s == run_sym:
                    r, pos = decode_sym(data, pos, lr, br)
                    if r < 0:
                        return ERR_BAD_CODE, b
                    if r == SEL_RUN_TOTAL - 1:
                        v, pos = read_vlc(data, pos, 7)
                        if v < 0:
                            return ERR_VLC, b
                        sel_run = v + SEL_RUN_MIN
                    else:
                        sel_run = r + SEL_RUN_MIN
                    if sel_run > total:
                        return ERR_RUN_LENGTH, b
                    s = n_sel
                    sel_run -= 1
            if s >= n_sel:
                h = s - n_sel
                if h >= hist_size:
                    return ERR_HISTORY_INDEX, b
                sel = history[h]
                if h:
                    t = history[h >> 1]
                    history[h >> 1] = sel
                    history[h] = t
            else:
                sel = s
                if hist_size:
                    history[rover] = sel
                    rover += 1
                    if rover == hist_size:
                        rover = hist_size // 2
            if sel >= n_sel:
                return ERR_SELECTOR_INDEX, b
            sel_out[b] = sel
            if pos > nbits:
                return ERR_TRUNCATED, b
    return 0, 0


# ---------------------------------------------------------------- writing


@_inner
def _group_options(ep, nbx, nby, x, y, opts):
    """Prediction choices of block (x, y) into opts; returns their count.
    A block outside the slice takes any (its bits are never read)."""
    if x >= nbx or y >= nby:
        for k in range(4):
            opts[k] = k
        return 4
    e = ep[y * nbx + x]
    n = 0
    if y > 0 and ep[(y - 1) * nbx + x] == e:
        opts[n] = 1
        n += 1
    if x > 0 and ep[y * nbx + x - 1] == e:
        opts[n] = 0
        n += 1
    if x > 0 and y > 0 and ep[(y - 1) * nbx + x - 1] == e:
        opts[n] = 2
        n += 1
    if n == 0:
        opts[0] = 3
        n = 1
    return n


@jit
def group_symbols(ep, nbx, nby, weight):
    """The endpoint-prediction symbol of every 2x2 group (even rows' groups in
    raster order): among the predictions each block allows, the symbol of
    highest `weight` (first found on ties: upper before left before
    upper-left, so flat areas repeat one symbol, the first column's too)."""
    gx = (nbx + 1) >> 1
    gy = (nby + 1) >> 1
    out = np.zeros(gx * gy, np.int64)
    opts = np.zeros((4, 4), np.int64)
    cnt = np.zeros(4, np.int64)
    for j in range(gy):
        for i in range(gx):
            for k in range(4):
                cnt[k] = _group_options(ep, nbx, nby, 2 * i + (k & 1), 2 * j + (k >> 1), opts[k])
            best = -1
            best_w = -1.0
            for a in range(cnt[0]):
                for b in range(cnt[1]):
                    for c in range(cnt[2]):
                        for d in range(cnt[3]):
                            s = opts[0, a] | (opts[1, b] << 2) | (opts[2, c] << 4) | (opts[3, d] << 6)
                            if weight[s] > best_w:
                                best_w = weight[s]
                                best = s
            out[j * gx + i] = best
    return out


@_inner
def _emit(kind, val, nb, n, k, v, b):
    kind[n] = k
    val[n] = v
    nb[n] = b
    return n + 1


@_inner
def _emit_vlc(kind, val, nb, n, v, chunk):
    while True:
        c = v & ((1 << chunk) - 1)
        v >>= chunk
        if v:
            n = _emit(kind, val, nb, n, EV_RAW, c | (1 << chunk), chunk + 1)
        else:
            return _emit(kind, val, nb, n, EV_RAW, c, chunk + 1)


@jit
def slice_events(ep, sel, nbx, nby, groups, n_ep, n_sel, hist_size):
    """The symbols of one slice in stream order, as (kind, value, raw bit
    count) triples: kind EV_PRED/EV_DELTA/EV_SEL/EV_RUN names the table, EV_RAW
    raw bits."""
    total = nbx * nby
    cap = 16 * total + 64
    kind = np.zeros(cap, np.int8)
    val = np.zeros(cap, np.int64)
    nb = np.zeros(cap, np.int8)
    n = 0
    gx = (nbx + 1) >> 1
    ng = groups.shape[0]
    history = np.zeros(max(hist_size, 1), np.int64)
    valid = np.zeros(max(hist_size, 1), np.bool_)  # entries the decoder has been sent
    rover = hist_size // 2
    prev_sym = 0
    pred_run = 0
    sel_run = 0
    prev_ep = 0
    cur = 0
    for y in range(nby):
        for x in range(nbx):
            b = y * nbx + x
            if (x & 1) == 0:
                g = (y >> 1) * gx + (x >> 1)
                cur = groups[g]
                if (y & 1) == 0:
                    if pred_run:
                        pred_run -= 1
                    else:
                        s = groups[g]
                        run = 1
                        while g + run < ng and groups[g + run] == s:
                            run += 1
                        if s == prev_sym and run >= PRED_MIN_RUN:
                            n = _emit(kind, val, nb, n, EV_PRED, PRED_REPEAT, 0)
                            n = _emit_vlc(kind, val, nb, n, run - PRED_MIN_RUN, 4)
                            pred_run = run - 1
                        else:
                            n = _emit(kind, val, nb, n, EV_PRED, s, 0)
                            prev_sym = s
                else:
                    cur >>= 4
            pred = cur & 3
            cur >>= 2
            e = ep[b]
            if pred == 3:
                d = e - prev_ep
                if d < 0:
                    d += n_ep
                n = _emit(kind, val, nb, n, EV_DELTA, d, 0)
            prev_ep = e
            s = sel[b]
            if sel_run:
                sel_run -= 1
                continue
            if hist_size and valid[0] and history[0] == s:
                run = 1
                while b + run < total and sel[b + run] == s:
                    run += 1
                if run >= SEL_RUN_MIN:
                    n = _emit(kind, val, nb, n, EV_SEL, n_sel + hist_size, 0)
                    r = run - SEL_RUN_MIN
                    if r < SEL_RUN_TOTAL - 1:
                        n = _emit(kind, val, nb, n, EV_RUN, r, 0)
                    else:
                        n = _emit(kind, val, nb, n, EV_RUN, SEL_RUN_TOTAL - 1, 0)
                        n = _emit_vlc(kind, val, nb, n, r, 7)
                    sel_run = run - 1
                    continue
            h = -1
            for k in range(hist_size):
                if valid[k] and history[k] == s:
                    h = k
                    break
            if h >= 0:
                n = _emit(kind, val, nb, n, EV_SEL, n_sel + h, 0)
                if h:
                    t = history[h >> 1]
                    history[h >> 1] = history[h]
                    history[h] = t
                    tv = valid[h >> 1]
                    valid[h >> 1] = valid[h]
                    valid[h] = tv
            else:
                n = _emit(kind, val, nb, n, EV_SEL, s, 0)
                if hist_size:
                    history[rover] = s
                    valid[rover] = True
                    rover += 1
                    if rover == hist_size:
                        rover = hist_size // 2
    return kind[:n], val[:n], nb[:n]


@jit
def write_bits(val, nb):
    """Pack (value, bit count) pairs LSB first into bytes."""
    total = 0
    for i in range(nb.shape[0]):
        total += nb[i]
    out = np.zeros((total + 7) >> 3, np.uint8)
    pos = 0
    for i in range(nb.shape[0]):
        v = val[i]
        for k in range(nb[i]):
            if (v >> k) & 1:
                out[(pos + k) >> 3] |= np.uint8(1 << ((pos + k) & 7))
        pos += nb[i]
    return out


# a changed selector row byte costs a delta symbol other than 0; then its changed bits
_BYTE_COST = np.array([0 if x == 0 else 8 + bin(x).count("1") for x in range(256)], np.int64)


@_inner
def _distance(a, b, mode):
    if mode == 0:  # endpoints: colour distance, a table change costs like a few steps
        d = abs(a[0] - b[0]) + abs(a[1] - b[1]) + abs(a[2] - b[2])
        return d + (4 if a[3] != b[3] else 0)
    return (_BYTE_COST[(a[0] ^ b[0]) & 255] + _BYTE_COST[(a[1] ^ b[1]) & 255]
            + _BYTE_COST[(a[2] ^ b[2]) & 255] + _BYTE_COST[(a[3] ^ b[3]) & 255])


@jit
def chain_order(feat, mode, start):
    """A greedy nearest-neighbour order of the rows of `feat` (distance by
    `mode`), from the row nearest `start`: consecutive codebook entries then
    differ little, which is what the codebooks' delta coding wants."""
    n = feat.shape[0]
    order = np.zeros(n, np.int64)
    done = np.zeros(n, np.bool_)
    cur = 0
    best = 1 << 40
    for i in range(n):
        d = _distance(start, feat[i], mode)
        if d < best:
            best = d
            cur = i
    for k in range(n):
        order[k] = cur
        done[cur] = True
        nxt = -1
        best = 1 << 40
        for i in range(n):
            if not done[i]:
                d = _distance(feat[cur], feat[i], mode)
                if d < best:
                    best = d
                    nxt = i
                    if d == 0:
                        break
        cur = nxt
    return order
