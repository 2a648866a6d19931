"""Rate-distortion optimisation of encoded BC1, BC1A, BC3, BC4 and BC5 levels.

A block format spends a fixed number of bits on every block, but a KTX2 file
supercompressed with Zstandard is as small as its bytes are repetitive. This
stage runs after a level is encoded and makes the blocks more repetitive where
that costs little quality: walking the blocks in file order, it tries giving
each block the index bits, the endpoints, or the whole of one of the previous
WINDOW blocks (already settled), and keeps the replacement that lowers

    J = added squared error - lambda * bytes saved

when it is below zero, so every replacement adds at most lambda times the
bytes it is expected to save. Each candidate is measured exactly with the
format's own block decoder against the level's texels (padding texels of a
partial block count nothing).

The saving model (an estimate of Zstandard's gain, see docs/rdo.md): a field
copied from a block within the window becomes part of an LZ match, whose
bytes cost about nothing since the window (at most WINDOW * 16 bytes back) is
far within zstd's reach; each new match costs about MATCH_COST bytes (its
offset, length and literal-length codes), and none when it continues the match
that covers the bytes right before it at the same distance (a field copied
from the same block as the previous field). A match shorter than zstd's
shortest (3 bytes) saves nothing: BC4's 2-byte endpoints alone save only when
they continue a match. Literal bytes are counted at one byte each: index bits
are close to random, so entropy coding saves little on them.

A block holds one or two 8-byte halves, each measured on its own channels and
taking candidates from the same half of earlier blocks: BC1's colour block (4
bytes of endpoints, 4 of indices; RGB), BC4's single-channel block (2 bytes
of endpoints, 6 of indices). BC3 is BC4 alpha then BC1 colour; BC5 is X then
Y. Constraints: BC1A (and BC1 without opaque_black, as DDS writes it) never
changes which texels are transparent; BC3's colour half keeps c0 > c1, or c0
== c1 with every index 0 (texcook.codecs.bc3). The walk is sequential, so the
result does not depend on threads.
"""

import numpy as np

from ._jit import jit, jit_inner
from .codecs._base import image_to_blocks
from .codecs.bc1_kernels import decode_colour_block
from .codecs.bc4 import decode_single_block
from .formats import block_count

WINDOW = 64  # earlier blocks a block may copy from
MATCH_COST = 2.0  # bytes a new LZ match costs (offset, match and literal lengths)
MIN_MATCH = 3  # zstd's shortest match

# the kinds of half-block
COLOUR, SINGLE = 0, 1

# per format: (kind, byte offset, channel, keep transparency, BC3's c0 > c1 rule) of each half
_LAYOUT = {
    "bc1": ((COLOUR, 0, 0, 0, 0),),
    "bc1a": ((COLOUR, 0, 0, 1, 0),),
    "bc3": ((SINGLE, 0, 3, 0, 0), (COLOUR, 8, 0, 0, 1)),
    "bc4": ((SINGLE, 0, 0, 0, 0),),
    "bc5": ((SINGLE, 0, 0, 0, 0), (SINGLE, 8, 1, 0, 0)),
}
FORMATS = tuple(_LAYOUT)


def supports(format_name):
    return format_name in _LAYOUT


def layout(format_name, options=None):
    """The (halves, 5) int64 table of a format: BC1 without opaque_black (DDS)
    is held to BC1A's rule, since Direct3D reads 3-colour black as transparent."""
    rows = [list(r) for r in _LAYOUT[format_name]]
    if format_name == "bc1" and options is not None and options.get("opaque_black") is False:
        rows[0][3] = 1
    return np.array(rows, np.int64)


@jit_inner
def _error(cand, out, tex, weight, kind, ch, punch, pal):
    """Squared error of the 8-byte half-block `cand` against the block's texels
    (RGB for a colour half, channel ch for a single one), by the format's decoder."""
    z = np.int64(0)
    if kind == 0:
        decode_colour_block(cand, z, out, punch, pal)
        e = np.int64(0)
        for i in range(16):
            if weight[i]:
                for c in range(3):
                    d = np.int64(out[i, c]) - np.int64(tex[i, c])
                    e += d * d
        return e
    decode_single_block(cand, z, out, ch)
    e = np.int64(0)
    for i in range(16):
        if weight[i]:
            d = np.int64(out[i, ch]) - np.int64(tex[i, ch])
            e += d * d
    return e


@jit_inner
def _bc3_order_ok(cand):
    c0 = np.int64(cand[0]) | (np.int64(cand[1]) << 8)
    c1 = np.int64(cand[2]) | (np.int64(cand[3]) << 8)
    if c0 > c1:
        return True
    if c0 < c1:
        return False
    return cand[4] == 0 and cand[5] == 0 and cand[6] == 0 and cand[7] == 0


@jit_inner
def _gain(what, elen, run, dist, match_cost, min_match):
    """Bytes saved by copying the endpoints (what 1), the indices (2) or both
    (3) of the half-block at `dist` bytes back; `run` is the distance of the
    match covering the bytes right before the endpoints (0: literal)."""
    ilen = 8 - elen
    if what == 1:
        if run == dist:
            return float(elen)
        return elen - match_cost if elen >= min_match else 0.0
    if what == 2:
        return ilen - match_cost
    if run == dist:
        return 8.0
    return 8.0 - match_cost


@jit
def walk(data, texels, weight, spec, lam, window, match_cost, min_match, stats):
    """Replace fields of data (n, bytes per block) in place, in block order.
    texels (n, 16, 4) uint8; weight (n, 16) uint8 (0: padding); spec as
    `layout`. stats (3,) float64 gets: halves changed, bytes saved (by the
    model), squared error added."""
    n, bpb = data.shape
    halves = spec.shape[0]
    cand = np.empty(8, np.uint8)
    cur = np.empty(8, np.uint8)
    out = np.empty((16, 4), np.uint8)
    ref = np.empty(16, np.uint8)
    pal = np.empty((4, 3), np.int64)
    run = np.int64(0)
    for b in range(n):
        tex = texels[b]
        wt = weight[b]
        for s in range(halves):
            kind, off, ch = spec[s, 0], spec[s, 1], spec[s, 2]
            keep_alpha, strict = spec[s, 3] != 0, spec[s, 4] != 0
            elen = 4 if kind == 0 else 2
            for k in range(8):
                cur[k] = data[b, off + k]
            d0 = _error(cur, out, tex, wt, kind, ch, keep_alpha, pal)
            if keep_alpha:
                for i in range(16):
                    ref[i] = out[i, 3]
            best_j = float(d0)
            best_w, best_what, best_gain, best_d = -1, 0, 0.0, d0
            for w in range(b - 1, max(0, b - window) - 1, -1):
                dist = np.int64((b - w) * bpb)
                for what in range(1, 4):
                    gain = _gain(what, elen, run, dist, match_cost, min_match)
                    if gain <= 0.0 or -lam * gain >= best_j:
                        continue  # even an exact candidate could not win
                    same = True
                    for k in range(8):
                        take = (what & 1) if k < elen else (what & 2)
                        v = data[w, off + k] if take else cur[k]
                        cand[k] = v
                        if v != cur[k]:
                            same = False
                    if same:
                        continue  # the block has these bytes already
                    if strict and not _bc3_order_ok(cand):
                        continue
                    d = _error(cand, out, tex, wt, kind, ch, keep_alpha, pal)
                    j = d - lam * gain
                    if j >= best_j:
                        continue
                    if keep_alpha:
                        moved = False
                        for i in range(16):
                            if out[i, 3] != ref[i]:
                                moved = True
                        if moved:
                            continue
                    best_j, best_w, best_what, best_gain, best_d = j, w, what, gain, d
            if best_w >= 0:
                for k in range(8):
                    take = (best_what & 1) if k < elen else (best_what & 2)
                    if take:
                        data[b, off + k] = data[best_w, off + k]
                stats[0] += 1.0
                stats[1] += best_gain
                stats[2] += float(best_d - d0)
            run = np.int64((b - best_w) * bpb) if best_w >= 0 and (best_what & 2) else np.int64(0)


def block_weights(height, width):
    """(n, 16) uint8: 1 for the texels of each 4x4 block inside the level, 0 for padding."""
    inside = np.zeros((block_count(height, 4) * 4, block_count(width, 4) * 4, 1), np.uint8)
    inside[:height, :width] = 1
    return image_to_blocks(inside, 4, 4)[..., 0].copy()


def optimise(format_name, data, rgba, lam, options=None, window=WINDOW, stats=None):
    """The level's encoded bytes `data` (of `format_name`) with RDO at lambda
    `lam` (squared error per byte; 0: `data` as it is), measured against the
    texels `rgba` (H, W, 4) uint8 the level was encoded from. `stats`, a dict,
    receives what changed: halves, saved (model bytes), added (squared error)."""
    if not lam or not supports(format_name):
        return data
    h, w = rgba.shape[:2]
    bpb = 8 * len(_LAYOUT[format_name])
    blocks = np.frombuffer(data, np.uint8).reshape(-1, bpb).copy()
    texels = image_to_blocks(rgba, 4, 4)
    counts = np.zeros(3)
    walk(blocks, texels, block_weights(h, w), layout(format_name, options), np.float64(lam), np.int64(window),
         np.float64(MATCH_COST), np.int64(MIN_MATCH), counts)
    if stats is not None:
        stats["halves"] = stats.get("halves", 0) + int(counts[0])
        stats["saved"] = stats.get("saved", 0.0) + float(counts[1])
        stats["added"] = stats.get("added", 0.0) + float(counts[2])
    return blocks.tobytes()
