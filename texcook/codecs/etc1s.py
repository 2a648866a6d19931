"""ETC1S: the block vocabulary of Basis Universal's BasisLZ (KHR_texture_basisu).

An ETC1S block is an ETC1 block restricted to differential mode, zero colour
deltas, equal tables and flip 0: one endpoint (R5, G5, B5, table) and 16
selectors for the whole block. Any ETC1 decoder reads it. The container
(texcook.container.basislz) stores a file's distinct endpoints and selector
patterns once, as codebooks, and codes each block as indices into them, so
the file is small when the blocks use few distinct ones. This codec picks
that vocabulary: it is vector quantisation of the blocks.

For each level (docs/etc.md, "ETC1S", says more):
1. every block's own best endpoint and selectors (the unconstrained fit);
   when their distinct endpoints and patterns fit the budget, that is the
   result;
2. the budget is spent where the image needs it: split trees of the
   endpoints and of the selector patterns (each split along the principal
   axis of the cluster of largest error) give the error left with any count
   of each; one rate picks the counts of every slice (split());
3. the endpoints are clustered by their tree and each cluster's endpoint
   fitted to all of its blocks' texels; blocks re-pick among nearby
   endpoints of the tree, endpoints are refitted, for prm.ep_rounds rounds;
4. the best selectors of each block for its endpoint are clustered the same
   way, each pattern set texel by texel to the selector of least error over
   its blocks; then rounds alternate: blocks re-pick endpoints (selectors
   fixed), endpoints are refitted to fixed selectors, blocks re-pick
   patterns, patterns are recomputed; in prm.full_rounds blocks search
   every endpoint (and pattern, with prm.full_patterns);
5. in raster order a block takes its left or upper neighbour's endpoint or
   pattern when the error that adds is small (the container codes repeats
   of a neighbour's almost for free).

Option `quality` (1..255, default 128) sets the budget in bits (budget()):
per level, a share of its blocks' worth of endpoints and a larger share of
patterns, rising geometrically with quality (every block its own fit at
255), and never more entries than the level's share (by block count) of the
file's 16128 of each over a full mip chain. Presets set how hard it searches
within it.

`etc1s-rgba` stores a colour block then an alpha block per 4x4 block; alpha
is coded as a grey ETC1S image (R = G = B; readers take G) with its own
codebook entries out of the same budget.
"""

from dataclasses import dataclass

import numpy as np

from .. import formats
from ..choices import DEFAULT_PRESET
from . import etc1_kernels as K1
from . import etc1s_kernels as K
from ._base import Codec, Option, image_to_blocks, run_chunked
from ._presets import PresetTable
from .etc1_tables import EXPAND5

SEARCH = PresetTable(
    "etc1s",
    columns={
        "fit_iters": "re-centring rounds of an endpoint fit, per table",
        "radius": "lattice radius (codes) around an endpoint fit's best, tables +-1",
        "ep_rounds": "rounds of re-picking and refitting endpoints before selectors are clustered",
        "sel_rounds": "rounds of re-picking endpoints and patterns with selectors fixed",
        "cands": "nearby codebook entries (split-tree neighbours) a block re-picks among",
        "coherence": "1: prefer a neighbour's endpoint or pattern when nearly as good",
        "refit_tables": "tables an endpoint refit to its blocks searches (the best at the mean's code)",
        "fit_tables": "tables a block's own fit searches (the best at the mean's code)",
        "full_rounds": "final rounds in which blocks re-pick among every endpoint",
        "full_patterns": "1: and among every selector pattern in those rounds (else the tree's neighbours)",
    },
    rows={
        #              fit_iters radius ep_rounds sel_rounds cands coherence refit_tables fit_tables full_rounds
        #              full_patterns
        "fastest":    (1,        0,     1,        1,         8,    1,        1,           2,         0,          0),
        "fast":       (2,        0,     2,        2,         12,   1,        2,           3,         1,          0),
        "medium":     (2,        1,     3,        3,         16,   1,        2,           8,         1,          0),
        "thorough":   (3,        1,     4,        4,         24,   1,        3,           8,         2,          1),
        "exhaustive": (3,        2,     6,        6,         32,   1,        8,           8,         3,          1),
    },
)

MAX_CODEBOOK = 16128  # distinct endpoints (and selector patterns) a BasisLZ file may hold
QUALITY = Option("quality", "int", 128, min=1, max=255,
                 help="vocabulary size: more distinct endpoints and selectors, larger file, higher PSNR")
# a few entries cost little beside what having none of them would lose
MIN_VOCABULARY = 8
# (quality, share of the level's blocks as endpoints, as selector patterns):
# the level's budget is that many entries' worth of ENTRY_BITS, interpolated
# between these points on a log scale; at 255 every block may keep its own fit
BUDGET_POINTS = ((1, 0.002, 0.03), (64, 0.005, 0.1), (128, 0.01, 0.3), (192, 0.04, 0.7), (255, 1.0, 1.0))
# what an endpoint and a selector pattern roughly cost in a BasisLZ file (its
# codebook entry and the wider indices of its blocks), in bits: the budget is
# spent on whichever buys more error per bit (split()). Measured: 25-110 bits
# an endpoint (more where few endpoints let neighbours predict most blocks),
# 20-30 a pattern; (16, 32) gave 0.2 dB less at equal size than these
ENTRY_BITS = (32.0, 32.0)
# coherence: the error a block accepts per part (endpoint or pattern) taken
# from a neighbour, as (256ths of its own error, plus a constant)
SLACK = (24, 64)


def budget(blocks, quality, share, slices=1):
    """(endpoints, selector patterns, bits) for one level of `blocks` blocks
    over its `slices` slices: the counts are hard limits (the level's blocks,
    and its `share` of the file's 16128), bits what its entries may cost
    (ENTRY_BITS each) at this quality, never less than MIN_VOCABULARY of
    each per slice."""
    qs = [p[0] for p in BUDGET_POINTS]
    frac = [2.0 ** np.interp(quality, qs, [np.log2(p[col]) for p in BUDGET_POINTS]) for col in (1, 2)]
    counts = [max(MIN_VOCABULARY, int(np.ceil(blocks * f))) for f in frac]
    cap = max(slices, min(slices * blocks, int(share)))
    return cap, cap, slices * (ENTRY_BITS[0] * counts[0] + ENTRY_BITS[1] * counts[1])


def split(curves, caps, bits):
    """How many endpoints and patterns each slice gets: curves[i] = (endpoint
    curve, pattern curve) of slice i, each the error left with j entries
    (curve[j]). One rate lam for all: each count minimises error + lam * its
    ENTRY_BITS * count (at least MIN_VOCABULARY where the curve reaches it),
    lam the least whose total fits `bits`; within caps."""
    def pick(lam):
        out = []
        for pair in curves:
            got = []
            for kind, curve in enumerate(pair):
                j = np.arange(curve.shape[0])
                cost = curve + lam * ENTRY_BITS[kind] * j
                cost[0] = np.inf
                got.append(max(min(MIN_VOCABULARY, curve.shape[0] - 1), int(np.argmin(cost))))
            out.append(got)
        return out

    def spent(counts):
        return sum(ENTRY_BITS[0] * e + ENTRY_BITS[1] * s for e, s in counts)

    lo, hi = 0.0, 1.0
    while spent(pick(hi)) > bits and hi < 1e15:
        hi *= 4.0
    if spent(pick(lo)) > bits:
        for _ in range(48):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if spent(pick(mid)) > bits else (lo, mid)
        lo = hi
    counts = pick(lo)
    out = []
    for kind in range(2):
        want = [c[kind] for c in counts]
        # within the cap, shared in proportion when the slices ask for more
        if sum(want) > caps[kind]:
            want = [max(1, w * caps[kind] // sum(want)) for w in want]
        out.append(want)
    return [(out[0][i], out[1][i]) for i in range(len(curves))]


class _Chain:
    """The mip chain an encoder is fed, level 0 first: each level's share of
    the codebook limit is its blocks over the chain's (a full chain from the
    first level's size), less two entries per level kept for the least of one
    endpoint and pattern each slice has, so the whole file stays within it."""

    def __init__(self, block_w, block_h):
        self.block = (block_w, block_h)
        self.base = None
        self.level = 0

    def share(self, width, height):
        if self.base is None or (width, height) != formats.level_dims(*self.base, self.level):
            self.base, self.level = (width, height), 0
        self.level += 1
        levels = formats.max_levels(*self.base)
        blocks = [self._blocks(*formats.level_dims(*self.base, i)) for i in range(levels)]
        return (MAX_CODEBOOK - 2 * levels) * self._blocks(width, height) / sum(blocks)

    def _blocks(self, w, h):
        return formats.block_count(w, self.block[0]) * formats.block_count(h, self.block[1])


def fit(blocks, rec, threads):
    """Every block's own best endpoint, selectors and error."""
    n = blocks.shape[0]
    eps = np.zeros((n, 4), np.int64)
    pats = np.zeros((n, 16), np.int64)
    errs = np.zeros(n, np.int64)
    run_chunked(K.fit_blocks, blocks, eps, threads, rec, also=(pats, errs))
    return eps, pats, errs


def distinct(rows):
    """(distinct rows, index of each row among them), rows of small ints
    (endpoints: 5-bit codes and a table; patterns: 16 selectors of 2 bits)
    packed into one int64 key each (np.unique over rows is far slower)."""
    bits = 5 if rows.shape[1] == 4 else 2
    keys = np.zeros(rows.shape[0], np.int64)
    for c in range(rows.shape[1]):
        keys = (keys << bits) | rows[:, c]
    _, first, inv = np.unique(keys, return_index=True, return_inverse=True)
    return rows[first], inv.reshape(-1).astype(np.int64)


def _tree(feat, wt, k, want):
    """Split-tree clusters of feat: (count, cluster of each point, candidates,
    their counts, the error curve: tree_vq's)."""
    n = feat.shape[0]
    k = max(1, min(k, n))
    order = np.zeros(n, np.int64)
    start = np.zeros(k + 1, np.int64)
    node_of = np.zeros(k, np.int64)
    parent = np.zeros(2 * k, np.int64)
    child = np.zeros((2 * k, 2), np.int64)
    curve = np.zeros(k + 1)
    m = K.tree_vq(np.ascontiguousarray(feat), np.ascontiguousarray(wt, np.float64), k, order, start, node_of,
                  parent, child, curve)
    assign = np.zeros(n, np.int64)
    assign[order] = np.repeat(np.arange(m, dtype=np.int64), np.diff(start[:m + 1]))
    cand = np.zeros((m, max(1, want)), np.int64)
    ncand = np.zeros(m, np.int64)
    K.tree_candidates(m, node_of, parent, child, want, cand, ncand)
    return m, assign, cand, ncand, curve


def curves(own, caps):
    """(endpoint curve, pattern curve) of one slice from its own fit: the
    error (estimated from the features the quantiser clusters) left with j
    endpoints or patterns, j up to caps."""
    eps0, pats0, _ = own
    n = eps0.shape[0]
    feat = np.zeros((n, 4))
    K.endpoint_features(eps0, pats0, feat)
    # a base off by D costs 16 |D|^2 over a block's texels (endpoint_features)
    ce = 16.0 * _tree(feat, np.ones(n), caps[0], 1)[4]
    sfeat = np.zeros((n, 16))
    wt = np.zeros(n)
    K.selector_features(pats0, np.arange(n, dtype=np.int64), eps0, sfeat, wt)
    return ce, _tree(sfeat, wt, caps[1], 1)[4]


def _by_table(eps):
    """The endpoints by table, then by the sum of their expanded base:
    (order, those sums in that order, where each table starts (9))."""
    sums = EXPAND5[eps[:, 0]] + EXPAND5[eps[:, 1]] + EXPAND5[eps[:, 2]]
    order = np.lexsort((sums, eps[:, 3])).astype(np.int64)
    start = np.searchsorted(eps[order, 3], np.arange(9)).astype(np.int64)
    return order, sums[order].astype(np.float64), start


def _grouped(assign, m):
    order = np.zeros(assign.shape[0], np.int64)
    start = np.zeros(m + 1, np.int64)
    K.group(assign, m, order, start)
    return order, start


def quantise(blocks, own, nbx, limits, rec, threads):
    """Endpoints (e, 4), patterns (s, 16) and each block's indices into them,
    using at most limits = (endpoints, patterns) distinct ones. own: fit()'s
    result for these blocks."""
    prm = rec[0]
    eps0, pats0, errs = own
    n = blocks.shape[0]
    ue, ie = distinct(eps0)
    us, is_ = distinct(pats0)
    if ue.shape[0] <= limits[0] and us.shape[0] <= limits[1]:
        return ue, us, ie, is_
    # endpoints
    feat = np.zeros((n, 4))
    K.endpoint_features(eps0, pats0, feat)
    m, bep, cand, ncand, _ = _tree(feat, np.ones(n), limits[0], prm.cands)
    eps = np.zeros((m, 4), np.int64)
    order, start = _grouped(bep, m)
    K.refit_endpoints(blocks, order, start, m, rec, eps, np.ones(m, np.bool_))
    for _ in range(prm.ep_rounds):
        was = bep.copy()
        run_chunked(K.assign_endpoints, blocks, bep, threads, eps, cand, ncand, also=(errs,))
        moved = was != bep
        if not moved.any():
            break
        dirty = np.zeros(m, np.bool_)
        dirty[was[moved]] = True
        dirty[bep[moved]] = True
        order, start = _grouped(bep, m)
        K.refit_endpoints(blocks, order, start, m, rec, eps, dirty)
    # selector patterns
    best = np.zeros((n, 16), np.int64)
    run_chunked(K.best_patterns, blocks, best, threads, eps, also=(bep,))
    sfeat = np.zeros((n, 16))
    wt = np.zeros(n)
    K.selector_features(best, bep, eps, sfeat, wt)
    ms, bsel, scand, nscand, _ = _tree(sfeat, wt, limits[1], prm.cands)
    pats = np.zeros((ms, 16), np.int64)
    order, start = _grouped(bsel, ms)
    K.update_patterns(blocks, order, start, ms, bep, eps, pats)
    for _ in range(prm.sel_rounds):
        run_chunked(K.assign_endpoints_fixed, blocks, bep, threads, eps, cand, ncand, pats, also=(bsel, errs))
        order, start = _grouped(bep, m)
        K.refit_endpoints_fixed(blocks, order, start, m, pats, bsel, eps)
        run_chunked(K.assign_selectors, blocks, bsel, threads, pats, scand, nscand, eps, also=(bep, errs))
        order, start = _grouped(bsel, ms)
        K.update_patterns(blocks, order, start, ms, bep, eps, pats)
    for _ in range(prm.full_rounds):
        # every entry, not only the tree's neighbours: the last moves of blocks whose best lies elsewhere
        near = _by_table(eps)
        run_chunked(K.assign_all, blocks, bep, threads, eps, pats, 0, *near, also=(bsel, errs))
        order, start = _grouped(bep, m)
        K.refit_endpoints_fixed(blocks, order, start, m, pats, bsel, eps)
        if prm.full_patterns:
            run_chunked(K.assign_all, blocks, bep, threads, eps, pats, 1, *near, also=(bsel, errs))
        else:
            run_chunked(K.assign_selectors, blocks, bsel, threads, pats, scand, nscand, eps, also=(bep, errs))
        order, start = _grouped(bsel, ms)
        K.update_patterns(blocks, order, start, ms, bep, eps, pats)
    run_chunked(K.assign_selectors, blocks, bsel, threads, pats, scand, nscand, eps, also=(bep, errs))
    if prm.coherence:
        K.coherence(blocks, nbx, bep, bsel, eps, pats, np.array(SLACK, np.int64), errs)
    return eps, pats, bep, bsel


def pack(vocab):
    """quantise()'s result as ETC1S block bytes (n, 8)."""
    eps, pats, bep, bsel = vocab
    out = np.zeros((bep.shape[0], 8), np.uint8)
    K.pack_etc1s(eps, pats, bep, bsel, out)
    return out


@dataclass(frozen=True)
class ETC1SCodec(Codec):
    compile_seconds = 17  # CPU s a first 256x256 bake spends compiling (docs/performance.md)
    options = (QUALITY,)
    preset_tables = (SEARCH,)

    def encoder(self, preset=DEFAULT_PRESET, threads=None, **options):
        """encode(rgba) -> bytes for each level of a texture, level 0 first:
        the levels share the file's codebook limit (see _Chain)."""
        self.check_preset(preset)
        options = self.check_options(options)
        chain = _Chain(self.block_w, self.block_h)

        def encode(rgba):
            rgba = self.check_input(rgba)
            share = chain.share(rgba.shape[1], rgba.shape[0])
            return self._encode_level(rgba, preset, threads, options["quality"], share)

        return encode

    def _encode_level(self, rgba, preset, threads, quality, share):
        blocks = image_to_blocks(rgba, self.block_w, self.block_h, threads)
        nbx = self.blocks_x(rgba.shape[1])
        rec = SEARCH.record(preset)
        # the colour slice, and with alpha the alpha slice as a grey image
        slices = [np.ascontiguousarray(blocks[:, :, :3])]
        if self.bytes_per_block == 16:
            slices.append(np.ascontiguousarray(blocks[:, :, [3, 3, 3]]))
        *caps, bits = budget(blocks.shape[0], quality, share, len(slices))
        owns = [fit(s, rec, threads) for s in slices]
        need = [(distinct(own[0])[0].shape[0], distinct(own[1])[0].shape[0]) for own in owns]
        spent = sum(ENTRY_BITS[0] * e + ENTRY_BITS[1] * p for e, p in need)
        if spent <= bits and sum(e for e, _ in need) <= caps[0] and sum(p for _, p in need) <= caps[1]:
            limits = need  # every block keeps its own fit
        else:
            # an alpha texel's error counts once in RGBA, its grey slice's three times
            weights = (1.0, 1.0 / 3.0)
            limits = split([tuple(w * c for c in curves(own, caps)) for w, own in zip(weights, owns)], caps, bits)
        out = np.zeros((blocks.shape[0], self.bytes_per_block), np.uint8)
        for i, (px, own, lim) in enumerate(zip(slices, owns, limits)):
            out[:, 8 * i:8 * i + 8] = pack(quantise(px, own, nbx, lim, rec, threads))
        return out.tobytes()

    def _decode_blocks(self, data, out):
        K1.decode_blocks(np.ascontiguousarray(data[:, :8]), out)
        if self.bytes_per_block == 16:
            alpha = np.zeros_like(out)
            K1.decode_blocks(np.ascontiguousarray(data[:, 8:]), alpha)
            out[:, :, 3] = alpha[:, :, 1]  # readers take the alpha block's green


CODECS = {name: ETC1SCodec(formats.get(name)) for name in ("etc1s", "etc1s-rgba")}
