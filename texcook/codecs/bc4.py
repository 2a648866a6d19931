"""BC4: one channel in 8-byte blocks (BC5 is two of them, BC3's alpha is one).

A BC4 block is 8 bytes: two 8-bit endpoints r0, r1 and sixteen 3-bit indices
(texel i at bit 3*i of the 48-bit little-endian field after the endpoints).

Decoding convention (checked bit for bit against texture2ddecoder):

    r0 > r1:  8 values r0, r1, ((7-i)*r0 + i*r1) // 7 for i = 1..6
    r0 <= r1: 6 values r0, r1, ((5-i)*r0 + i*r1) // 5 for i = 1..4, then 0 and 255

with truncating division, as for BC1. Both modes are searched: the 6-value
mode pays off when a block holds exact 0 or 255 next to other values.

Search (per preset, ``SEARCH``): the min/max endpoints of each mode, then
least-squares endpoints from the chosen indices, each followed by a search of
every endpoint pair within +-window of the candidate, all measured exactly
with the decoding above. ``exhaustive`` then scans every endpoint pair of
both modes, cutting pairs whose lower bound cannot beat the best so far, so
it returns the optimum (checked against brute force in the tests).
"""

from dataclasses import dataclass

import numpy as np

from .. import formats
from .._jit import jit, jit_inner
from ._base import Codec, run_chunked
from ._kernels import blank
from ._presets import PresetTable
from .bc1_kernels import NO, ZERO


# Constant arguments to jitted callees are NumPy scalars (see bc1): a Python
# literal would make numba compile the callee once per value.
YES = np.bool_(True)
TOP = np.int64(255)


SEARCH = PresetTable(
    "bc4",
    columns={
        "window": "endpoint pairs within +-window of each candidate are measured",
        "ls_iters": "least-squares refinement rounds",
        "six_value": "1: try the 6-value mode (with exact 0 and 255)",
        "full_scan": "1: measure every endpoint pair (with a lower-bound cut)",
    },
    rows={
        #              window  ls_iters  six_value  full_scan
        "fastest":    (0,      0,        1,         0),
        "fast":       (1,      1,        1,         0),
        "medium":     (2,      2,        1,         0),
        "thorough":   (4,      3,        1,         0),
        "exhaustive": (4,      3,        1,         1),
    },
)


@jit_inner
def palette(r0, r1, pal):
    """pal (8,) int64: the eight values the decoding above gives (r0, r1)."""
    pal[0] = r0
    pal[1] = r1
    if r0 > r1:
        for i in range(1, 7):
            pal[i + 1] = ((7 - i) * r0 + i * r1) // 7
    else:
        for i in range(1, 5):
            pal[i + 1] = ((5 - i) * r0 + i * r1) // 5
        pal[6] = 0
        pal[7] = 255


@jit_inner
def decode_single_block(d, o, out, ch):
    """Decode the 8 bytes d[o:o+8] into channel ch of out (16, 4)."""
    pal = np.empty(8, np.int64)
    palette(np.int64(d[o]), np.int64(d[o + 1]), pal)
    bits = np.int64(0)
    for k in range(6):
        bits |= np.int64(d[o + 2 + k]) << (8 * k)
    for i in range(16):
        out[i, ch] = pal[(bits >> (3 * i)) & 7]


# Palette entries in ascending value order, for each mode (the palette is
# monotone in its interpolation index): r1, the six interpolants down to r0;
# and 0, r0, the four interpolants, r1, 255.
_ASCENDING_8 = np.array([1, 7, 6, 5, 4, 3, 2, 0], np.int64)
_ASCENDING_6 = np.array([6, 0, 2, 3, 4, 5, 1, 7], np.int64)
_NEVER = np.int64(1 << 20)  # a threshold no doubled 8-bit value reaches


@jit_inner
def _eval(v, r0, r1, pal, idx):
    """Squared error of the block from (r0, r1) with nearest-value indices,
    the lowest index winning a tie (as a scan of the palette in index order
    would pick).

    pal (4, 8) int64 scratch: row 0 the palette; rows 1-3 its distinct values
    ascending, the index each stands for, and the doubled midpoint above each
    (nudged up one where the upper value's index loses a tie). A texel's entry
    is then the count of midpoints at or below twice its value: seven
    comparisons without branches instead of a search of eight entries."""
    palette(r0, r1, pal[0])
    order = _ASCENDING_8 if r0 > r1 else _ASCENDING_6
    # rows of pal indexed in place (a view per row would cost reference counts)
    m = 0
    for k in range(8):
        j = order[k]
        x = pal[0, j]
        if m > 0 and x == pal[1, m - 1]:
            if j < pal[2, m - 1]:
                pal[2, m - 1] = j
        else:
            pal[1, m] = x
            pal[2, m] = j
            m += 1
    for k in range(7):
        if k + 1 < m:
            pal[3, k] = pal[1, k] + pal[1, k + 1] + (0 if pal[2, k + 1] < pal[2, k] else 1)
        else:
            pal[3, k] = _NEVER
    t0, t1, t2, t3, t4, t5, t6 = pal[3, 0], pal[3, 1], pal[3, 2], pal[3, 3], pal[3, 4], pal[3, 5], pal[3, 6]
    err = 0
    for i in range(16):
        x2 = 2 * v[i]
        c = (np.int64(x2 >= t0) + (x2 >= t1) + (x2 >= t2) + (x2 >= t3) + (x2 >= t4) + (x2 >= t5)
             + (x2 >= t6))
        d = v[i] - pal[1, c]
        idx[i] = pal[2, c]
        err += d * d
    return err


@jit_inner
def _keep_if_better(v, x, y, pal, tidx, st, bidx):
    """Measure the pair (x, y); when it beats st[0], record it and its indices."""
    e = _eval(v, x, y, pal, tidx)
    if e < st[0]:
        st[0] = e
        st[1] = x
        st[2] = y
        for i in range(16):
            bidx[i] = tidx[i]


@jit_inner
def _window(v, a, b, win, six, pal, tidx, st, bidx):
    """Measure every pair within +-win of (a, b) in the mode the pair's order
    selects; st = [best error, best r0, best r1]."""
    for da in range(-win, win + 1):
        x = a + da
        if x < 0 or x > 255:
            continue
        for db in range(-win, win + 1):
            y = b + db
            if y < 0 or y > 255:
                continue
            # 8-value mode needs r0 > r1; 6-value r0 <= r1
            if six:
                if x > y:
                    continue
            elif x <= y:
                continue
            _keep_if_better(v, x, y, pal, tidx, st, bidx)


@jit_inner
def _full_scan(v, six, pal, tidx, st, bidx):
    """Every endpoint pair of one mode, skipping pairs whose error cannot beat
    the best so far: texels outside [lo, hi] cost at least their distance to it
    (in the 6-value mode only the part not covered by 0 or 255)."""
    for lo in range(256):
        for hi in range(lo + 1 if not six else lo, 256):
            bound = 0
            for i in range(16):
                x = v[i]
                if x > hi:
                    d = x - hi
                    if six and 255 - x < d:
                        d = 255 - x
                elif x < lo:
                    d = lo - x
                    if six and x < d:
                        d = x
                else:
                    d = 0
                bound += d * d
            if bound >= st[0]:
                continue
            if six:
                x, y = lo, hi
            else:
                x, y = hi, lo
            _keep_if_better(v, x, y, pal, tidx, st, bidx)


@jit_inner
def _ls(v, idx, six, r01):
    """Least-squares (r0, r1) from the indices; False if singular. In the
    6-value mode texels on the fixed 0 / 255 entries are left out."""
    aa = bb = ab = ax = bx = 0.0
    for i in range(16):
        s = idx[i]
        if six:
            if s >= 6:
                continue
            al = 1.0 if s == 0 else (0.0 if s == 1 else (6 - s) / 5.0)
        else:
            al = 1.0 if s == 0 else (0.0 if s == 1 else (8 - s) / 7.0)
        be = 1.0 - al
        aa += al * al
        bb += be * be
        ab += al * be
        ax += al * v[i]
        bx += be * v[i]
    det = aa * bb - ab * ab
    if abs(det) < 1e-9:
        return False
    r01[0] = (ax * bb - bx * ab) / det
    r01[1] = (bx * aa - ax * ab) / det
    return True


# inlined into its runs: a call per block costs about a fifth of fastest's time
@jit_inner(inline="always")
def encode_single_block(blk, ch, prm, out, o, scr):
    """Encode channel ch of blk (16, 4) uint8 into out[o:o+8]; prm: a SEARCH record."""
    v, pal, tidx, bidx, st, r01 = scr
    lo = TOP
    hi = ZERO
    lo6 = TOP
    hi6 = ZERO
    for i in range(16):
        x = np.int64(blk[i, ch])
        v[i] = x
        lo = min(lo, x)
        hi = max(hi, x)
    if prm.six_value != 0:
        # the 6-value mode's range leaves out exact 0 and 255 (its own loop:
        # without it the loop above has no branch)
        for i in range(16):
            if v[i] != 0 and v[i] != 255:
                lo6 = min(lo6, v[i])
                hi6 = max(hi6, v[i])
        if lo6 > hi6:  # only 0s and 255s
            lo6 = ZERO
            hi6 = ZERO
    win = prm.window
    st[0] = 1 << 40
    st[1] = 0
    st[2] = 0
    if lo == hi:
        # one value: both endpoints on it, every index 0
        st[0] = 0
        st[1] = lo
        st[2] = lo
        for i in range(16):
            bidx[i] = 0
    elif win == 0 and prm.ls_iters == 0 and prm.full_scan == 0:
        # a search of the block's extremes: in the 8-value mode, and in the
        # 6-value mode (exact 0 and 255) where the block holds either
        st[1] = hi
        st[2] = lo
        e8 = _eval(v, hi, lo, pal, bidx)
        if prm.six_value != 0 and (lo == 0 or hi == 255):
            if _eval(v, lo6, hi6, pal, tidx) < e8:
                st[1] = lo6
                st[2] = hi6
                for i in range(16):
                    bidx[i] = tidx[i]
    else:
        _window(v, hi, lo, win, NO, pal, tidx, st, bidx)
        if prm.six_value != 0:
            _window(v, lo6, hi6, win, YES, pal, tidx, st, bidx)
        if prm.full_scan != 0:
            _full_scan(v, NO, pal, tidx, st, bidx)
            if prm.six_value != 0:
                _full_scan(v, YES, pal, tidx, st, bidx)
        # least-squares rounds from each mode's extremes (none without rounds)
        for mode in range((2 if prm.six_value != 0 else 1) if prm.ls_iters > 0 else 0):
            six = mode == 1
            a, b = (lo6, hi6) if six else (hi, lo)
            # indices of this mode's extremes start the refinement
            _eval(v, a, b, pal, tidx)
            for _ in range(prm.ls_iters):
                if not _ls(v, tidx, six, r01):
                    break
                a = min(TOP, max(ZERO, np.int64(r01[0] + 0.5)))
                b = min(TOP, max(ZERO, np.int64(r01[1] + 0.5)))
                before = st[0]
                _window(v, a, b, max(win, 1), six, pal, tidx, st, bidx)
                if st[0] >= before:
                    break
                _eval(v, st[1], st[2], pal, tidx)
    out[o] = st[1]
    out[o + 1] = st[2]
    bits = np.int64(0)
    for i in range(16):
        bits |= bidx[i] << (3 * i)
    for k in range(6):
        out[o + 2 + k] = (bits >> (8 * k)) & 255


@jit_inner
def single_scratch():
    return (np.zeros(16, np.int64), np.zeros((4, 8), np.int64), np.zeros(16, np.int64),
            np.zeros(16, np.int64), np.zeros(3, np.int64), np.zeros(2))


@jit
def encode_single_run(blocks, out, rec, ch0, nch):
    """Channels ch0 .. ch0+nch-1 of each block into out[b, 8*c:8*c+8], c = 0 .. nch-1
    (BC4: channel 0; BC5: 0 and 1; BC3's alpha: channel 3 at byte 0); rec:
    SEARCH.record(preset)."""
    prm = rec[0]
    scr = single_scratch()
    for b in range(blocks.shape[0]):
        for c in range(nch):
            encode_single_block(blocks[b], ch0 + c, prm, out[b], 8 * c, scr)


@jit
def decode_run(data, out, nch):
    """Blocks of nch BC4 channels (8 bytes each) into channels 0 .. nch-1 of out;
    the others read 0, alpha 255."""
    for b in range(data.shape[0]):
        blank(out[b])
        for c in range(nch):
            decode_single_block(data[b], 8 * c, out[b], c)


# blocks per kernel call of the whole-image path, at least: at about 30 ns a
# block, a call's own cost in Python matters (one call for a 256x256 level)
QUICK_RUN = 4096


def reads_image(preset):
    """True where the preset's search is the extremes alone (no window, rounds
    or scan): bc4_quick runs it on the image itself, vectorised across blocks."""
    p = SEARCH.row(preset)
    return p.window == 0 and p.ls_iters == 0 and p.full_scan == 0


def fastest_blocks(rgba, n, threads, preset, first, count):
    """(n, 8 * count) BC4 blocks of channels first .. first + count - 1 of an
    image (h, width, 4) uint8 by the extremes-only search (reads_image), read
    from the image itself. first, count: np.int64."""
    from .bc4_quick import fastest_image

    h, w = rgba.shape[:2]
    out = np.empty((n, 8 * int(count)), np.uint8)
    run_chunked(fastest_image, np.arange(n, dtype=np.int64), out, threads, rgba.reshape(h, w * 4).view(np.uint32),
                SEARCH.record(preset), first, count, min_chunk=QUICK_RUN)
    return out


@dataclass(frozen=True)
class BC4Codec(Codec):
    compile_seconds = 3  # CPU s a first 256x256 bake spends compiling (docs/performance.md)
    preset_tables = (SEARCH,)

    def _encode(self, rgba, preset, threads, options):
        if not reads_image(preset) or options.get("angular"):
            return super()._encode(rgba, preset, threads, options)
        # the blocks are read from the image: gathering them first would cost
        # about as much as encoding them
        n = self.blocks_x(rgba.shape[1]) * self.blocks_y(rgba.shape[0])
        return fastest_blocks(rgba, n, threads, preset, ZERO, np.int64(self.channels)).tobytes()

    def _encode_blocks(self, blocks, out, preset, threads):
        run_chunked(encode_single_run, blocks, out, threads, SEARCH.record(preset), ZERO, self.channels)

    def _decode_blocks(self, data, out):
        decode_run(data, out, self.channels)


CODECS = {"bc4": BC4Codec(formats.get("bc4"))}
