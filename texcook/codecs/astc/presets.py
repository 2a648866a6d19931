"""ASTC encoder presets: one table per block-size class (texels per block), as
larger blocks have more modes and partition patterns to search and fewer bits
per texel to win back.

Fields (see the search package for how the search uses each):

- max_parts: highest partition count tried (1..4).
- part_cands: partition patterns kept from the k-means ranking per count.
- part_full: of those, how many (closest to lines) get the full mode search.
- dual: 0 no second weight plane; 1 the most independent component; 2 every
  component that varies.
- mode_cands: (block mode, CEM family) pairs encoded for real per fit.
- refine: rounds re-deriving weights from the decoded endpoints, for the
  best pair of each fit.
- scale_cems: also try base+scale endpoints (CEM 6/10: 4 values instead of 6)
  and base+offset (CEM 9/13, where the colour range keeps their bits).
- early_out: stop adding partitions once the weighted squared error per texel
  is below this (sum over channels, 8-bit units).
- decim_iters: least-squares steps when decimating weights onto a grid.
- kmeans_iters: Lloyd iterations of the clustering that ranks partitionings.
- realign: passes moving each grid weight one step up or down where the
  decoded error of the texels it reaches drops.
- wq_scale: the weight quantisation error of a range as estimated for ranking
  block modes, in percent of what uniform weights would suffer. Endpoint
  re-fitting and realignment recover more of it the larger the block, so
  larger classes weigh it less and pick finer grids with fewer levels.
- mode_share: the block modes tried, as the share of wins (per 1000) they
  cover in mode_ranks.py's ranking for the block size, most frequent first;
  1000 tries every legal mode.
- sep_rank: rank block modes by a separable least-squares estimate of each
  grid's decimation error (a few small matrix products shared by grids of one
  width) instead of decimating onto every grid; the encoded modes' grids are
  then decimated for real.
- est_skip: a fit's mode candidates are not encoded once their estimate is
  above this many times the best error already encoded (0: always encoded).
- luma_cems: also try luminance CEMs (0, 4) for partitions that are nearly but
  not exactly grey: two colour values leave the most bits for the colour range.
- dual_corr: with dual 1, the second plane is tried only when the chosen
  component's largest correlation with another is below this (2.0: always).
- fit_gain: a fit after the first (a second plane, more partitions) goes on to
  the mode search only when its texels' squared distance from their lines is
  below this share of the first fit's (0: always).
- cq_scale: the weight, per texel and weighted channel, of the colour range's
  quantisation error (the table's figure for the range a mode's leftover bits
  allow) in the mode estimate, against the grid's and the weights' errors.
"""

from dataclasses import dataclass, replace

import numpy as np

from ...choices import PRESETS
from . import search as K
from .mode_ranks import RANKS


@dataclass(frozen=True)
class ASTCPreset:
    max_parts: int
    part_cands: int
    part_full: int
    dual: int
    mode_cands: int
    refine: int
    scale_cems: bool
    early_out: float
    decim_iters: int
    kmeans_iters: int
    realign: int
    wq_scale: int = 80
    mode_share: int = 1000
    dual_corr: float = 2.0
    sep_rank: bool = False
    est_skip: float = 0.0
    luma_cems: bool = False
    fit_gain: float = 0.0
    cq_scale: float = 0.3

    def vector(self):
        v = np.zeros(K.P_LEN, np.int64)
        v[K.P_MAX_PARTS] = self.max_parts
        v[K.P_PART_CANDS] = self.part_cands
        v[K.P_PART_FULL] = self.part_full
        v[K.P_DUAL] = self.dual
        v[K.P_MODE_CANDS] = self.mode_cands
        v[K.P_REFINE] = self.refine
        v[K.P_SCALE_CEMS] = self.scale_cems
        v[K.P_EARLY_OUT] = int(round(self.early_out * 100))
        v[K.P_DECIM_ITERS] = self.decim_iters
        v[K.P_KMEANS_ITERS] = self.kmeans_iters
        v[K.P_REALIGN] = self.realign
        v[K.P_WQ_SCALE] = self.wq_scale
        v[K.P_DUAL_CORR] = int(round(self.dual_corr * 100))
        v[K.P_SEP_RANK] = self.sep_rank
        v[K.P_EST_SKIP] = int(round(self.est_skip * 100))
        v[K.P_LUMA_CEMS] = self.luma_cems
        v[K.P_FIT_GAIN] = int(round(self.fit_gain * 100))
        v[K.P_CQ_SCALE] = int(round(self.cq_scale * 100))
        return v


P = ASTCPreset
# classes by texels per block: (upper bound, {preset: ASTCPreset})
# fields: max_parts, part_cands, part_full, dual, mode_cands, refine, scale_cems,
#         early_out, decim_iters, kmeans_iters, realign (then by name: mode_share,
#         dual_corr, sep_rank, est_skip, luma_cems, fit_gain); wq_scale and
#         cq_scale per class


def _class(wq_scale, cq_scale, presets):
    """A class's presets with the weights its mode estimate gives the weight
    grid's and the colour range's quantisation errors: one value each per
    class (they follow the block size, not the preset)."""
    return {name: replace(p, wq_scale=wq_scale, cq_scale=cq_scale) for name, p in presets.items()}


_UP_TO_25 = _class(80, 0.4, {
    "fastest": P(2, 4, 1, 0, 1, 0, True, 40.0, 1, 0, 1, sep_rank=True, mode_share=900,
                 est_skip=1.5),
    # one real encoding per fit; a second plane for most blocks that vary
    # apart, but later fits only where they come well closer to lines
    "fast": P(2, 4, 1, 1, 1, 0, True, 30.0, 2, 0, 1, sep_rank=True, mode_share=950,
              dual_corr=0.95, est_skip=1.1, fit_gain=0.7),
    "medium": P(3, 16, 2, 1, 3, 1, True, 3.0, 2, 2, 2, luma_cems=True),
    "thorough": P(4, 32, 3, 2, 6, 2, True, 1.0, 3, 3, 2, luma_cems=True),
    "exhaustive": P(4, 64, 16, 2, 12, 3, True, 0.0, 12, 4, 4, luma_cems=True),
})
_UP_TO_64 = _class(40, 0.3, {
    "fastest": P(2, 4, 1, 0, 1, 0, True, 40.0, 1, 0, 1, sep_rank=True, mode_share=900,
                 est_skip=1.5),
    "fast": P(2, 4, 1, 1, 2, 0, True, 30.0, 2, 0, 1, sep_rank=True, mode_share=950,
              dual_corr=0.95, est_skip=1.25, fit_gain=0.8),
    "medium": P(3, 16, 2, 1, 3, 1, True, 5.0, 2, 2, 2, luma_cems=True),
    "thorough": P(4, 32, 4, 2, 6, 2, True, 2.0, 8, 3, 2, luma_cems=True),
    "exhaustive": P(4, 64, 32, 2, 12, 3, True, 0.0, 12, 4, 4, luma_cems=True),
})
# 6x5 and 6x6: as up to 64 texels, but `fast` encodes a second candidate only
# when it is estimated below what is already encoded, and more partitions and
# planes only for blocks further from lines (docs/astc.md has the sweep)
_UP_TO_36 = dict(_UP_TO_64, fast=replace(_UP_TO_64["fast"], early_out=50.0, est_skip=0.9, fit_gain=0.7))
_UP_TO_144 = _class(20, 0.3, {
    "fastest": P(2, 4, 1, 0, 1, 0, True, 30.0, 1, 0, 1, sep_rank=True, mode_share=900,
                 est_skip=1.5),
    "fast": P(2, 4, 1, 1, 2, 0, True, 15.0, 2, 0, 1, sep_rank=True,
              dual_corr=0.9, est_skip=1.5),
    "medium": P(3, 16, 2, 1, 3, 1, True, 8.0, 2, 2, 2, luma_cems=True),
    "thorough": P(4, 32, 4, 2, 6, 2, True, 3.0, 8, 3, 2, luma_cems=True),
    "exhaustive": P(4, 64, 32, 2, 12, 3, True, 0.0, 12, 4, 4, luma_cems=True),
})
TABLE = ((25, _UP_TO_25), (36, _UP_TO_36), (64, _UP_TO_64), (144, _UP_TO_144))


def preset_for(bw, bh, name):
    texels = bw * bh
    for bound, presets in TABLE:
        if texels <= bound:
            return presets[name]
    return TABLE[-1][1][name]


_MASKS = {}


def mode_mask(bw, bh, name):
    """int64 per row of the search's mode table: 1 for the modes preset `name`
    tries at this block size."""
    return share_mask(bw, bh, preset_for(bw, bh, name).mode_share)


def share_mask(bw, bh, share):
    """1 for the ranked modes until `share` (per 1000) of the wins is covered,
    and at least one single-plane mode; every mode when the share is 1000 or
    the size has no ranking."""
    key = (bw, bh, share)
    if key not in _MASKS:
        tb = K.tables(bw, bh)
        modes, dims = tb["modes"], tb["g_dims"]
        ranks = RANKS.get((bw, bh))
        if share >= 1000 or not ranks:
            mask = np.ones(modes.shape[0], np.int64)
        else:
            keep = {r[:4] for r in ranks[:rows_read(ranks, share)]}
            mask = np.array([(int(dims[g, 0]), int(dims[g, 1]), int(wq), int(dual)) in keep
                             for g, wq, dual, _ in modes], np.int64)
        _MASKS[key] = mask
    return _MASKS[key]


def rows_read(ranks, share):
    """How many of a size's ranked modes (mode_ranks.py) a mask of `share` (per
    1000, below 1000) tries: until the wins they cover reach the share and one
    of them has a single plane (or every row)."""
    single = False
    for n, (_, _, _, dual, cum) in enumerate(ranks, 1):
        single = single or not dual
        if cum >= share and single:
            return n
    return len(ranks)


def shares_read(bw, bh):
    """The mode shares below 1000 the presets give block size bw x bh."""
    return sorted({preset_for(bw, bh, name).mode_share for name in PRESETS} - {1000})
