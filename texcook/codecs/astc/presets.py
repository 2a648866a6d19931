"""ASTC encoder presets: one codecs._presets table per block-size class
(texels per block), as larger blocks have more modes and partition patterns to
search and fewer bits per texel to win back. The tables share their
columns, so one compiled search kernel reads the record of any of them
(`record(bw, bh, preset)`, read in the kernels as `prm.<column>`).

Columns hold integers; those marked x100 are fractions in hundredths (an
`early_out` of 3000 is 30.0).
"""

import numpy as np

from ...choices import PRESETS
from .._presets import PresetTable
from .mode_ranks import RANKS

COLUMNS = {
    "max_parts": "highest partition count tried (1..4)",
    "part_cands": "partition patterns kept from the k-means ranking per count (at most 64; 1024: every "
                  "pattern, none left out by the clustering)",
    "part_full": "of those, how many (closest to lines) get the full mode search",
    "dual": "0 no second weight plane; 1 the component whose plane takes the most off the block's line (the "
            "others' distance from their own line is least); 2 every component that varies; 3 the two best by that "
            "rule",
    "mode_cands": "(block mode, CEM family) pairs encoded for real per fit",
    "refine": "rounds re-deriving weights from the decoded endpoints, for the best pair of each fit",
    "scale_cems": "also try base+scale endpoints (CEM 6/10: 4 values instead of 6) and base+offset (CEM "
                  "9/13, where the colour range keeps their bits)",
    "early_out": "x100: stop adding partitions (and planes) once the weighted squared error per texel is "
                 "below this (sum over channels, 8-bit units)",
    "decim_iters": "least-squares steps when decimating weights onto a grid",
    "kmeans_iters": "Lloyd iterations of the clustering that ranks partitionings",
    "realign": "passes moving each grid weight one step up or down where the decoded error of the texels "
               "it reaches drops",
    "wq_scale": "the weight quantisation error of a range as estimated for ranking block modes, in percent "
                "of what uniform weights would suffer; endpoint re-fitting and realignment recover more of "
                "it the larger the block, so larger classes weigh it less and pick finer grids with fewer "
                "levels (one value per class)",
    "mode_share": "the block modes tried, as the share of wins (per 1000) they cover in mode_ranks.py's "
                  "ranking for the block size, most frequent first; 1000 tries every legal mode",
    "dual_corr": "x100: with dual 1, the second plane is tried only when the chosen component's largest "
                 "correlation with another is below this (200: always)",
    "sep_rank": "rank block modes by a separable least-squares estimate of each grid's decimation error "
                "(a few small matrix products shared by grids of one width) instead of decimating onto "
                "every grid; the encoded modes' grids are then decimated for real",
    "est_skip": "x100: a fit's mode candidates are not encoded once their estimate is above this many "
                "times the best error already encoded (0: always encoded)",
    "luma_cems": "also try luminance CEMs (0, 4) for partitions that are nearly but not exactly grey: two "
                 "colour values leave the most bits for the colour range",
    "fit_gain": "x100: a fit after the first (a second plane, more partitions) goes on to the mode search "
                "only when its texels' squared distance from their lines is below this share of the first "
                "fit's (0: always)",
    "cq_scale": "x100: the weight, per texel and weighted channel, of the colour range's quantisation error "
                "(the table's figure for the range a mode's leftover bits allow) in the mode estimate, "
                "against the grid's and the weights' errors (one value per class)",
    "plane_always": "1: the second plane is tried whatever the early-out; 0 in every row, the codec sets "
                    "it for normal maps, whose X and Y vary apart by construction",
    "angular_rounds": "with the angular objective (angular.py): refinement rounds, weights then endpoints",
    "wq_own": "with sep_rank: 1: a weight range's quantisation error in the mode estimate is that of the fit's "
              "own ideal weights (a two-colour block loses nothing to two levels) instead of the range's "
              "average; 2: the same with the endpoints refitted to the quantised weights (a noisy block's "
              "coarse ranges lose far less than at the fit's own endpoints)",
    "enough": "x1000: the block's search ends (no further candidate, plane or partition count) once the best "
              "error is at most this share of the block's own variation (weighted squared distance of its "
              "texels from their mean; 0: never)",
    "part_gain": "x100: a partition count above two is tried only when the count below it brought the best "
                 "error under this share of what one fewer partition left (0: always); above 100 the count's "
                 "own best is compared (what its encodings reached, or the line bound that ruled a fit out), "
                 "so a count that did worse than the one below stops the search, one that did a little "
                 "better does not",
    "done_err": "x100: the block's search ends (no further candidate, plane or partition count) once the "
                "weighted squared error per texel is at most this (0: never)",
    "done_planes": "1: done_err ends a normal map's block (plane_always) too, before Y's plane of its own; "
                   "0: not for normal maps",
    "est_resid": "with est_skip: a candidate's estimate is compared with the best error so far after adding "
                 "its fit's line residual (what the estimate leaves out: the texels' distance from their "
                 "lines), so fits far from lines encode fewer candidates",
    "mixed_cems": "1: with scale_cems, blocks of two or more colour partitions also try each colour partition "
                  "its own kind of endpoints (direct, base+scale, and with luma_cems luminance): for each count "
                  "of colour values saved, the kinds that miss least",
    "plane_early": "x100: as early_out, for the second plane only: it is tried while the weighted squared "
                   "error per texel is above this",
    "fit_gate": "x100: a candidate's encoding goes on past its refit (endpoint quantisation, realignment, the "
                "decode) only while the refit's float endpoints miss by at most this many times the best error "
                "already encoded: quantising them only adds to that (0: always)",
    "grey_early": "x100: for a wholly grey block (R = G = B in every texel) the early-outs early_out, "
                  "plane_early and done_err are this share of the row's: a grey partition costs a luminance "
                  "pair, a third of a colour one's values, so more partitions pay at errors where a colour "
                  "block's would not (100: the same)",
    "grey_fit": "an opaque grey block's one partition is fitted in one dimension on the block's own grid "
                "(search/grey.py) instead of by the search's one-partition fits: this many weight ranges, "
                "those with the least expected error, are encoded (0: the search's fits)",
    "grey_rounds": "with grey_fit: rounds of least-squares refit of the two luminances to each range's weights",
    "polish": "rounds refining the block's best encoding once its search ends, as `refine` does a fit's best: "
              "weights re-derived from its decoded endpoints, decimated and quantised, endpoints refitted (0: none)",
    "span_rank": "x10: a fit whose partitions' spans differ more than this many times ranks its grids decimated "
                 "for real (a step each) instead of by the separable estimate, which counts a narrow "
                 "partition's nearly free weights as fixed near 0 beside a wide one (0: never)",
    "grey_nudge": "with grey_fit: passes moving each of the best encoding's two luminances one colour level up or "
                  "down, the weights chosen again, while the block's error drops: a near-lossless block's values "
                  "land on the weight levels only where the endpoints leave them a whole step each (0: none)",
    "grey_also": "with grey_fit: 1: its encoding is one candidate beside the search's own one-partition fits, "
                 "which also reach the decimated grids; 0: in their place",
}

# Every `thorough` row polishes its blocks' winners once (polish 1: the
# winner's endpoints refitted to its realigned weights, then its weights
# re-derived from the decoded endpoints: +0.02-0.06 dB for 0-9% of the time)
# and gives part of that back for speed: up to 36 texels 4 patterns fully
# searched, not 6 (5 at 4x4), 4x4 also skipping at 1.4x, 5x4 6 candidates,
# 6x5 skipping at 1.1x, 37-64 texels skipping at 1.25x (1.2x with
# span_rank, below); tuned on the corpus,
# checked outside (docs/astc.md, "Polishing the winner"). Every `thorough`
# row ranks the grids of a fit whose partitions' spans differ more than 8
# times decimated for real (span_rank 80: +0.00-0.004 dB on the corpus,
# +0.02-0.04 outside up to 64 texels, for 0-11% of the time; docs/astc.md,
# "Partitions of unequal spans"); `medium` would gain as much (10x10 and
# 12x12 outside +0.09) for 5-43% of its time and does not
# `exhaustive` (every class) ranks every partition pattern by its line fit
# instead of the clustering's best 64 (photo +0.04-0.14 dB, corpus 4x4 +0.10,
# for the same time), and estimates a weight range's error with the endpoints
# refitted to it (wq_own 2: noisy blocks take coarse ranges, `generated`
# +0.09-0.17 dB at 6x6 and 8x8; docs/astc.md, "`exhaustive`: every pattern,
# and the weight ranges' error refitted");
# `medium` and `thorough` (every class) stop encoding a candidate once its
# refit's float endpoints miss by more than 1.1x the best error encoded
# (fit_gate): 0.73-0.95x their time for at most 0.004 dB (docs/astc.md, "The
# fit gate"); `fast` gained too little from it, `exhaustive` keeps every
# candidate
def _like(table, **changes):
    """The rows of `table` (a PresetTable, or a dict of row tuples) with some
    presets' named columns changed, for a class that differs from another in
    a few columns only: _like(_ROWS_25, fast=dict(realign=0))."""
    if isinstance(table, dict):
        table = PresetTable("astc", COLUMNS, table)
    rows = {p: table.row(p) for p in PRESETS}
    return {p: row._replace(**changes.get(p, {})) for p, row in rows.items()}


# columns:    max_parts part_cands part_full dual mode_cands refine scale_cems early_out decim_iters
#             kmeans_iters realign wq_scale mode_share dual_corr sep_rank est_skip luma_cems fit_gain
#             cq_scale plane_always angular_rounds wq_own enough part_gain done_err done_planes
#             est_resid mixed_cems plane_early fit_gate grey_early grey_fit grey_rounds polish span_rank
#             grey_nudge grey_also
# the rows up to 25 texels, which 4x4, 5x4 and 5x5 change a few columns of
_ROWS_25 = PresetTable("astc", COLUMNS, {
    # one real encoding per fit at `fast`; a second plane for most blocks that
    # vary apart while they are above 10 per texel (a smooth colour's noise in
    # one channel is what it holds: +0.4 dB outside the corpus), but more
    # partitions only above 60 per texel and later fits only where they come
    # 20% closer to lines (corpus 0.84x the time for 0.08 dB; outside only
    # 0.94x, 4x4 has its own row below: docs/astc.md, "`medium` up to 36
    # texels and `fast` up to 25");
    # `medium` skips a candidate whose estimate plus its fit's line residual
    # is over 1.4 times the best error encoded (est_resid) and adds no
    # partition below 5 per texel (0.82-0.93x for 0.002-0.008 dB), and to reach
    # astcenc `medium`'s speed on the corpus encodes 5 candidates, adds nothing
    # below 10 per texel and gates at 1.05x (0.87x for 0.018 dB); `thorough`
    # skips within 1.5x with up to 12 candidates, gives the two
    # components that leave the line most a plane of their own (dual 3, not every one: 0.83x
    # at 4x4), keeps 64 patterns, tries a third partition unless the second's
    # own best was 5% over one partition's (part_gain above 100) and ranks
    # weight ranges with the endpoints refitted (wq_own 2): tuned at 5x5 on
    # the corpus, 0.85x -> 0.91x astcenc `thorough`'s speed, +0.017 -> +0.025
    # dB (outside, checked: 0.87x -> 1.12x, -0.047 -> +0.022 dB): docs/astc.md,
    # "`thorough` at astcenc `thorough`'s speed"; it searches a wholly grey
    # block to a tenth of the early-outs (grey_early, as 4x4 `medium` below:
    # "Grey blocks")
    "fastest":    (2, 4, 1, 0, 1, 0, 1, 4000, 1, 0, 1, 80, 900, 200, 1, 150, 0, 0, 40, 0, 1, 0, 0, 0, 0, 0, 0, 1, 4000, 0, 100, 0, 0, 0, 0, 0, 0),
    "fast":       (2, 4, 1, 1, 1, 0, 1, 6000, 2, 0, 1, 80, 950, 95, 1, 110, 0, 80, 40, 0, 2, 1, 0, 0, 0, 0, 0, 1, 1000, 0, 100, 0, 0, 0, 0, 0, 0),
    "medium":     (3, 16, 3, 1, 5, 0, 1, 1000, 4, 2, 2, 80, 1000, 200, 1, 140, 1, 0, 40, 0, 3, 1, 0, 95, 0, 1, 1, 1, 200, 105, 100, 0, 0, 0, 0, 0, 0),
    "thorough":   (3, 64, 4, 3, 12, 0, 1, 500, 3, 3, 2, 80, 1000, 200, 1, 150, 1, 0, 40, 0, 4, 2, 0, 105, 0, 1, 1, 1, 100, 105, 10, 0, 0, 1, 80, 0, 0),
    "exhaustive": (4, 1024, 32, 2, 32, 0, 1, 0, 8, 4, 4, 80, 1000, 200, 1, 300, 1, 0, 40, 0, 6, 2, 0, 0, 0, 1, 0, 1, 0, 0, 100, 0, 0, 0, 0, 0, 0),
})
# `thorough` from 5x4 to 10x6 but 8x8: an opaque grey block's one partition
# fitted in one dimension beside the search's own fits (which reach the
# decimated grids), its two luminances then moved a level either way while
# that helps: on the grey corpus (tuned) 5x5, 6x6 and 8x5 `thorough` were
# 0.19, 0.04 and 0.14 dB under astcenc `thorough` (near-lossless smooth grey,
# where astcenc's endpoints leave every value a weight level and ours missed
# by one), now +0.05, +0.20, +0.05 at 1.28-1.89x its speed (+0.04-0.24 dB
# over the code before from 5x4 to 10x6; 8x8 -0.01 and 6% slower, left
# out); scikit-image's samples, checked, +0.00-0.06 dB; colour sets the same
# bytes (docs/astc.md, "Near-lossless grey: the fit beside the search, the
# luminances nudged"); 4x4 `medium` and `thorough` nudge their grey fits too
# (grey corpus +0.45 and +0.12 dB for 15% and 0% of the time; `fastest`
# and `fast` would gain +1.1 dB for 2.4x their time there and do not)
_GREY_BESIDE = dict(grey_fit=1, grey_rounds=2, grey_nudge=2, grey_also=1)
# 4x4: as up to 25 texels, but `fast` realigns no weights, a fixed cost of
# every encoding that kept it under astcenc `fastest`'s speed outside the
# corpus (0.95x -> 1.13x there, 1.39x -> 1.55x on the corpus, for 0.16 dB on
# each, still 0.12-0.44 dB above astcenc; 5x4 and 5x5 keep it: without it 5x5
# fell under astcenc `fastest`); `medium` gives back part of the up-to-25
# row's saving, which outside the corpus kept astcenc `medium`'s PSNR by 0.001
# dB only: partitions end at 9 per texel (not 10) and the fit gate is at 1.07x
# (not 1.05x), the least saving that keeps 1.08x astcenc `medium`'s speed on
# the corpus (1.11x -> 1.08x; outside +0.001 -> +0.007 dB at 1.66x):
# docs/astc.md, "`medium` up to 36 texels and `fast` up to 25"; `thorough`
# fully searches 5 patterns (not 6) with 6 candidates and ranks weight ranges
# by the fit's own weights (wq_own 1): corpus 0.65x -> 1.0x astcenc
# `thorough`'s speed, +0.078 -> +0.067 dB (tuned; outside, checked: 0.74x ->
# 1.57x, +0.024 -> +0.006 dB), later (after decimation's over-relaxed steps)
# 5 candidates, not 6 (corpus, tuned: 0.98-1.00x -> 1.04x, 40.314 -> 40.304
# dB against 40.244; outside, checked: 1.53x -> 1.59x, 46.335 -> 46.325
# against 46.311; scikit-image's set 49.163 -> 49.152 against 49.124), and
# with polish 4 patterns and a skip at 1.4x (the note above `exhaustive`'s);
# `fastest`
# realigns nothing either and adds no partition below 80 per texel, or it
# would be slower than `fast` (corpus 0.80x `fast`'s time, was 0.96x, 38.43
# -> 38.16 dB; outside, checked, 0.75x, was 0.93x: "`fastest` below `fast`");
# `medium` searches a wholly grey block to a tenth of the early-outs, as
# `thorough` does up to 36 texels (grey_early): nearly lossless grey textures take two or three
# luminance partitions there (grey versions of the corpus and outside images,
# tuned: `medium` 56.60 -> 58.62 dB against astcenc `medium`'s 58.22 at 1.0x
# its speed; scikit-image's grey textures, checked: 52.53 -> 55.05 against
# 55.37; colour images unchanged): docs/astc.md, "Grey blocks"; every
# preset but `exhaustive` fits an opaque grey block's one partition in one
# dimension on the full grid (grey_fit, grey_rounds: grey corpus and outside
# images, tuned, `fastest` 53.61 -> 56.27 dB at 1.25-1.38x astcenc `fastest`'s
# speed, was 0.76x; scikit-image's grey textures, checked, 51.84 -> 52.68
# against 52.47), and `thorough` searches grey blocks to 3% of the early-outs
# (59.96 -> 61.41 dB against astcenc `thorough`'s 61.06; checked 56.25 ->
# 56.47 against 56.36): "A grey block's one partition in one dimension"
UP_TO_16 = PresetTable("astc", COLUMNS, _like(
    _ROWS_25,
    fastest=dict(early_out=8000, realign=0, grey_fit=1, grey_rounds=1),
    fast=dict(realign=0, grey_fit=1, grey_rounds=2),
    medium=dict(early_out=900, fit_gate=107, grey_early=10, grey_fit=1, grey_rounds=1, grey_nudge=2),
    thorough=dict(wq_own=1, mode_cands=5, part_full=4, est_skip=140, grey_early=3, grey_fit=1, grey_rounds=2,
                  grey_nudge=2),
))
# 5x4 (17-20 texels): as up to 25, but `medium` keeps 32 partition patterns
# from the clustering's ranking (not 16) and skips candidates at 1.5x (not
# 1.4x): the up-to-25 row was 0.04-0.1 dB under astcenc `medium` outside the
# corpus (tuned there: 44.172 -> 44.255 dB against 44.211, 1.75x -> 1.57x
# astcenc `medium`'s speed; corpus, checked: 38.087 -> 38.128 against
# 37.989, 1.24x -> 1.07x; scikit-image's set, checked: 46.09 -> 46.12
# against 45.95, 1.59x -> 1.44x): docs/astc.md, "Every size against astcenc";
# `thorough` searches grey blocks to 3% of the early-outs, as at 4x4 (grey
# corpus and outside images 54.38 -> 54.66 dB against astcenc's 54.72;
# scikit-image grey, checked, 51.31 -> 51.34 against 51.43; 5x5 to 6x6 gained
# 0.00-0.07 there and keep 10): docs/astc.md, "Grey blocks"; `fastest` gives
# the component that leaves the line most a plane of its own under a
# correlation of 0.95 (as `fast`) and adds no partition below 60 per texel:
# outside it was under astcenc `fastest`'s PSNR at 0.86x its speed (41.57
# against 42.17 dB, dominated), now 42.25 at 0.85x; corpus 36.69 -> 37.15
# against 37.02 at 1.23x its speed; scikit-image's set 44.17 -> 44.34 against
# 43.83; still 0.92x `fast`'s time on the corpus: "`fastest` below `fast`";
# later `fast` realigns no weights and tries a second plane above 30 per
# texel (not 10) and partitions above 80 (not 60), and `fastest` realigns
# none, ends at 80 too and tries its plane above 60 (not 40), or `texcook
# bench` found it outranked by `fast` on the corpus (outside, tuned: `fast`
# 0.69x -> 0.92x astcenc `fastest`'s speed, 43.04 -> 42.55 dB against 42.17;
# `fastest` 0.87x -> 1.01x, 42.26 -> 41.99; corpus, checked: `fast` 1.12x -> 1.35x, 37.39 ->
# 37.12 against 37.02; scikit-image's, checked: `fast` 0.69x -> 0.82-0.92x,
# 44.87 -> 44.59 against 43.83): still under astcenc `fastest`'s speed
# outside, by the per-block floor: docs/astc.md, "`fast` at astcenc
# `fastest`'s speed from 5x4 to 6x5"; then `fast` and `fastest` fit an
# opaque grey block's one partition in one dimension on the full grid, as
# 4x4 does (`fast` with one round of refitted luminances, `fastest` none, so
# that it stays the faster): grey corpus, tuned, `fast` 51.17 -> 51.76 dB at
# 0.44x astcenc `fastest`'s time (was 1.01x), `fastest` 49.48 -> 49.77 at
# 0.30x; scikit-image's samples, checked, `fast` 44.59 -> 44.66 at 1.00x
# its time (was 1.14x), `fastest` 44.01 -> 43.94 at 0.83x; colour sets the
# same to 0.001 dB; from 5x5 up the full grid leaves too few weight levels
# (5x5 `fast` -0.7 dB there, 8x8 -6.3): docs/astc.md, "A grey block's one
# partition in one dimension"; and `fast` adds partitions only above 100 per
# texel (not 80), after the packer's and the call's fixed costs came down
# (outside, tuned: about 4% of the time, 0.97-0.99x astcenc `fastest`'s
# speed after, 42.553 -> 42.519 dB against 42.165; corpus, checked: 37.122 -> 37.099 against
# 37.017, 1.41x -> 1.47x; scikit-image's, checked: 44.659 -> 44.647 against
# 43.834; grey corpus the same): docs/astc.md, "5x4 `fast`: the whole
# encode's fixed costs, and the grey fit"; `thorough` skips candidates at
# 1.4x, as 4x4's does (not 1.5x): on the corpus it had come to 0.98-1.01x
# astcenc `thorough`'s speed (corpus, tuned: 38.299 -> 38.289 dB against
# 38.226, 1.01x -> 1.05x in one run; outside, checked: 44.559 -> 44.549
# against 44.517, 1.28x -> 1.36x; scikit-image's 46.828 -> 46.821 against
# 46.677; grey corpus 55.120 -> 55.104 against 54.717): docs/astc.md, "A run
# of blocks' first fits at once"
UP_TO_20 = PresetTable("astc", COLUMNS, _like(
    _ROWS_25,
    fastest=dict(dual=1, dual_corr=95, early_out=8000, plane_early=6000, realign=0, grey_fit=1, grey_rounds=0),
    fast=dict(realign=0, plane_early=3000, early_out=10000, grey_fit=1, grey_rounds=1),
    medium=dict(part_cands=32, est_skip=150),
    thorough=dict(grey_early=3, mode_cands=6, est_skip=140, **_GREY_BESIDE),
))
# 5x5: as up to 25, but `fast` realigns no weights and tries a second plane
# above 20 per texel (not 10), and `fastest` realigns none, the least that
# brought `fast` to astcenc `fastest`'s speed outside the corpus (tuned there:
# 0.85x -> 1.07x, 41.51 -> 41.28 dB against 40.31; `fastest` 1.08x -> 1.20x,
# 40.16 -> 39.97; corpus, checked: `fast` 1.43x -> 1.55x, 35.45 -> 35.22
# against 35.16; scikit-image's, checked: 0.81x -> 1.03x, 42.57 -> 42.29
# against 41.67): docs/astc.md, "`fast` at astcenc `fastest`'s speed from 5x4
# to 6x5"
UP_TO_25 = PresetTable("astc", COLUMNS, _like(_ROWS_25, fastest=dict(realign=0),
                                             fast=dict(realign=0, plane_early=2000), thorough=_GREY_BESIDE))
# 37-64 texels: `fast` and `medium` end a block's search at 30 per texel
# (astcenc's own stop at 8x8 `medium` is about twice that): flat colour with
# a little noise stops after one encoding; `thorough` tries up to three
# partitions while above 5 per texel and counts the line residual in its
# candidate skip (est_resid); `thorough` also gives the two components
# that leave the line most a plane of their own (dual 3), tries a third partition unless the
# second's own best was 5% over one partition's (part_gain above 100), ranks
# weight ranges with the endpoints refitted (wq_own 2) and skips within 1.5x
# with 12 candidates: tuned at 8x8 on the corpus, 0.65x -> 0.85x astcenc
# `thorough`'s speed, +0.05 -> +0.02 dB (outside, checked: 0.44x -> 0.67x,
# +0.015 -> +0.009 dB; docs/astc.md, "`thorough` at astcenc `thorough`'s
# speed"); later its partitions end at 8 per texel (not 5) and its second
# plane at 3 (not 2): 8x8 corpus 0.86x -> 0.89x astcenc `thorough`'s speed for
# the same PSNR (tuned), outside 0.60x -> 0.77x for -0.002 dB (checked; 8x5,
# 8x6, 10x5, 10x6 the same way, at most -0.004 dB); with decimation's over-relaxed steps
# (search/grid.py) `thorough` takes 5 of them, not 8, here, at 6x5, 6x6 and
# above 64 texels (8x8 corpus 0.87x -> 0.96x astcenc `thorough`'s speed,
# same PSNR; outside 0.78x -> 0.87x; docs/astc.md, "Decimation's steps
# over-relaxed"), and then skips candidates at 1.4x, not 1.5x (8x8 corpus,
# tuned: 0.99x -> 1.10x, 29.207 -> 29.203 dB against 29.182; outside,
# checked: 0.86x -> 0.95x, 37.670 -> 37.663 against 37.657; 8x5, 8x6, 10x5,
# 10x6 +7-10% speed for 0.003-0.008 dB, and 8x6 outside, 0.04 dB under
# astcenc `thorough` either way, is no longer also slower); with polish
# 1.25x (the note above `exhaustive`'s), with span_rank 1.2x (10x6 outside
# 0.98x -> 1.04x astcenc `thorough`'s speed, +0.079 dB over it; corpus 1.16x,
# +0.069; 8x5 corpus 0.97x -> 1.02x, -0.003 dB)
_ROWS_64 = {
    "fastest":    (2, 4, 1, 0, 1, 0, 1, 4000, 1, 0, 1, 40, 900, 200, 1, 150, 0, 0, 30, 0, 1, 1, 0, 0, 0, 0, 0, 1, 4000, 0, 100, 0, 0, 0, 0, 0, 0),
    "fast":       (2, 4, 1, 1, 2, 0, 1, 3000, 2, 0, 1, 40, 950, 95, 1, 125, 0, 80, 30, 0, 2, 1, 50, 0, 3000, 0, 0, 1, 3000, 0, 100, 0, 0, 0, 0, 0, 0),
    "medium":     (3, 16, 3, 1, 6, 0, 1, 500, 8, 2, 2, 40, 1000, 200, 1, 130, 1, 0, 30, 0, 3, 1, 0, 95, 3000, 1, 1, 1, 500, 110, 100, 0, 0, 0, 0, 0, 0),
    "thorough":   (3, 32, 6, 3, 12, 0, 1, 800, 5, 3, 2, 40, 1000, 200, 1, 120, 1, 0, 30, 0, 4, 2, 0, 105, 0, 1, 1, 1, 300, 110, 100, 0, 0, 1, 80, 0, 0),
    "exhaustive": (4, 1024, 32, 2, 32, 0, 1, 0, 8, 4, 4, 40, 1000, 200, 1, 300, 1, 0, 30, 0, 6, 2, 0, 0, 0, 1, 0, 1, 0, 0, 100, 0, 0, 0, 0, 0, 0),
}
# 10x5 and 10x6: the rows above, `thorough` with the grey fit beside the
# search (_GREY_BESIDE; the other 37-64 texel classes change a few columns)
UP_TO_60 = PresetTable("astc", COLUMNS, _like(_ROWS_64, thorough=_GREY_BESIDE))
# 8x6: as 10x5 and 10x6, but `thorough` keeps 64 partition patterns from the
# clustering (not 32): outside the corpus it was 0.004 dB over astcenc
# `thorough` (under it in drawings, as 6x5 `medium` was), now +0.038 at 1.12x
# its speed (tuned there); corpus +0.061 -> +0.068 at 1.03x, scikit-image's
# samples 39.123 -> 39.121 against 38.906 at 1.25x (checked); at 8x8 and
# 10x6 it cost 5% for 0.005-0.014 dB
UP_TO_48 = PresetTable("astc", COLUMNS, _like(UP_TO_60, thorough=dict(part_cands=64)))
# 8x8: as 10x6 without the grey fit beside the search (_GREY_BESIDE's note),
# and `thorough` ends a block's search at 6 per texel as well
# (astcenc `thorough`'s limit at 8x8 is about 14, at 8x6 6): 0.96x -> 1.06x
# astcenc `thorough`'s speed outside the corpus, +0.059 -> +0.041 dB (corpus
# 1.06x -> 1.16x, +0.069 -> +0.055); at 8x6 it took 0.03 dB outside; a
# wholly grey block ends at 30% of it (grey corpus 36.324 -> 36.466 dB against
# astcenc's 36.392, 1.90x -> 1.54x its speed)
UP_TO_64 = PresetTable("astc", COLUMNS, _like(_ROWS_64, thorough=dict(done_err=600, grey_early=30)))
# 6x5 and 6x6: as up to 64 texels, but `fast` encodes a second candidate only
# when it is estimated below what is already encoded, more partitions and
# planes only for blocks further from lines, and stops at a smaller share of
# the block's variation; `medium` decimates with fewer passes and ends a
# block's search at a smaller error per texel, `fast` at 30, and `medium`
# adds a fit's line residual to its candidates' estimates (est_resid;
# docs/astc.md has the sweeps), skips at 1.2x, ends at 10 per texel and gates
# at 1.05x (outside the corpus 0.95x -> 1.27x astcenc `medium`'s speed for
# 0.05 dB; at 6x5 it was 0.08 dB under astcenc `medium` there, in drawings
# that want more partition patterns: 6x5 has a table of its own below);
# `thorough` keeps four partitions but tries a third (fourth) only where the
# count below's own best came within 15% of the best before it (part_gain
# above 100), gives the two components that leave the line most a plane of their own
# (dual 3), keeps 64 patterns, skips within 1.2x with 16 candidates, the line
# residual counted in, and ranks weight ranges with the endpoints refitted
# (wq_own 2): tuned at 6x6 on the corpus, 0.45x -> 0.84x astcenc
# `thorough`'s speed, +0.06 -> +0.005 dB (outside, checked: 0.38x -> 1.03x,
# +0.01 -> +0.06 dB; docs/astc.md, "`thorough` at astcenc `thorough`'s
# speed"), and searches a wholly grey block to a tenth of the early-outs
# (grey_early: "Grey blocks"); later, as up to 64 texels, its partitions end
# at 8 per texel and its second plane at 3 (6x6 corpus 0.85x -> 0.88x, -0.002
# dB, tuned; outside 1.03x -> 1.14x, -0.004 dB, checked; 6x5 the same way);
# `fast` adds no partition below 100 per texel (not 50): outside the corpus
# it was at 0.97-1.00x astcenc `fastest`'s time, now 0.97x that, for 0.008
# dB (tuned there); corpus -0.009 dB, 0.96x (checked; 6x5 the same way:
# docs/astc.md, "6x6 and 6x5 `fast`: partitions from 100 per texel")
UP_TO_36 = PresetTable("astc", COLUMNS, _like(dict(
    _ROWS_64,
    fast=(2, 4, 1, 1, 2, 0, 1, 10000, 2, 0, 1, 40, 950, 95, 1, 90, 0, 70, 30, 0, 2, 1, 20, 0, 3000, 0, 0, 1, 5000, 0, 100, 0, 0, 0, 0, 0, 0),
    medium=(3, 16, 3, 1, 6, 0, 1, 500, 4, 2, 2, 40, 1000, 200, 1, 120, 1, 0, 30, 0, 3, 1, 0, 95, 1000, 1, 1, 1, 500, 105, 100, 0, 0, 0, 0, 0, 0),
    thorough=(4, 64, 4, 3, 16, 0, 1, 800, 5, 2, 2, 40, 1000, 200, 1, 120, 1, 0, 30, 0, 3, 2, 0, 115, 0, 1, 1, 1, 300, 105, 10, 0, 0, 1, 80, 0, 0),
), thorough=_GREY_BESIDE))
# 6x5: as 6x6, but `medium` keeps 64 partition patterns from the clustering's
# ranking (not 16) and skips candidates at 1.1x (not 1.2x): the up-to-36 row
# was under astcenc `medium` outside the corpus, in the drawings (tuned there:
# -0.084 -> +0.026 dB, 1.62x -> 1.33x astcenc `medium`'s speed; corpus,
# checked: +0.015 -> +0.042 dB, 1.41x -> 1.11x): docs/astc.md, "Every size
# against astcenc"; later `fast` encodes one candidate (not 2) and `fastest`
# realigns no weights and ends at 60 per texel (not 40): outside, tuned,
# `fast` 0.96x -> 1.02x astcenc `fastest`'s speed (1.05x run alone), 40.15 ->
# 40.12 dB against 39.29 (`fastest` 1.03x -> 1.21x, 39.69 -> 39.49); corpus,
# checked: `fast` 1.34x -> 1.58x, 33.83 -> 33.68 against 33.61;
# scikit-image's, checked: 0.91x -> 1.00x, 40.79 -> 40.71 against 40.07
# (docs/astc.md, "`fast` at astcenc `fastest`'s speed from 5x4 to 6x5");
# `thorough` tries a second plane down to 1 per texel (not 3): on
# scikit-image's samples it was 0.002 dB over astcenc `thorough`, losing 0.6
# dB on `retina`, whose blocks at 2-3 per texel astcenc halves with a plane
# of their own (42.599 -> 42.756 dB against 42.597, 1.25x -> 1.17x its
# speed; outside, checked, +0.001 at 1.34x; corpus +0.005 at 1.04x); from
# 6x6 to 10x6 it gained 0.06-0.12 dB there for 6% of the time, which 8x5's
# corpus margin (1.00x) has not (docs/astc.md, "6x5 `thorough`: the second
# plane down to 1 per texel")
UP_TO_30 = PresetTable("astc", COLUMNS, _like(UP_TO_36, fastest=dict(realign=0, early_out=6000),
                                             fast=dict(mode_cands=1),
                                             medium=dict(part_cands=64, est_skip=110),
                                             thorough=dict(est_skip=110, plane_early=100)))
# 8x5: as up to 64 texels, but `fast` keeps 8 partition patterns (not 4): the
# up-to-64 row was 0.012 dB under astcenc `fastest` on the corpus (tuned there:
# +0.024 dB at 1.79x its speed, was 1.92x; outside, checked: 1.07-1.08x, was
# 1.08-1.09x); `medium` keeps 64 (not 16), as 6x5 (outside, tuned: -0.007 ->
# +0.077 dB at 1.52x astcenc `medium`'s speed, was 1.8x; corpus, checked:
# +0.072 -> +0.095 dB at 1.17x, was 1.45x): docs/astc.md, "Every size against
# astcenc"
# `thorough` fully searches 5 partition patterns (not 6): it ran at 1.00-1.01x
# astcenc `thorough`'s speed on the corpus (tuned there: 1.01x -> 1.13x,
# 32.322 -> 32.305 dB against 32.258; outside, checked, 1.21x -> 1.30x,
# 40.050 -> 40.033 against 39.996; scikit-image's 1.20x -> 1.34x, 40.271 ->
# 40.258 against 40.195; grey corpus 1.76x -> 1.93x, 41.078 -> 41.056
# against 41.025)
UP_TO_40 = PresetTable("astc", COLUMNS, _like(UP_TO_60, fast=dict(part_cands=8), medium=dict(part_cands=64),
                                             thorough=dict(part_full=5)))
# 65-100 texels (10x8, 10x10): astcenc `fastest` and `medium` end
# smooth blocks early, where these sizes spent 2-3x their time outside the
# corpus; `fast` ends a block's search at 30 per texel or 5% of its variation,
# encodes one candidate, and tries a second plane only under a correlation of
# 0.7 and later fits only 20% closer to lines (outside 0.49x -> 1.13x astcenc
# `fastest`'s speed at 10x10, tuned there; corpus +0.16 dB at 3.3x, checked);
# `medium` ends at 30 per texel (not 15), encodes 4 candidates (not 6) within
# 1.15x (not 1.3x) of the best (outside 12x12 0.67x -> 1.13x astcenc `medium`'s
# speed, tuned there; corpus +0.13-0.16 dB at 2.1-2.5x, checked): docs/astc.md,
# "Every size against astcenc"; `fastest` ends its blocks as `fast` does
# (corpus 0.91x `fast`'s time at 10x10, was 0.95x; outside, checked, 0.87x);
# `thorough` ends a block's search at 30 per texel as astcenc `thorough` ends
# its at about 33 at 10x10 (its dB limit for the size), encodes 12 candidates
# (not 24) within 1.25x (not 1.5x) of the best with the fit's line residual
# counted in, and tries a third (fourth) partition only where the count
# below's own best came within 15% of the one before (part_gain): 10x10
# 0.47x -> 1.10x astcenc `thorough`'s speed on the corpus, 0.23x -> 1.17x
# outside, +0.11 and +0.04 dB over it (both sets measured while choosing;
# scikit-image's, checked: docs/astc.md, "`thorough` above 64 texels"); a
# wholly grey block ends at 30% of that (grey_early: at the colour blocks'
# limit the grey corpus fell 0.14 dB, under astcenc `thorough`)
UP_TO_100 = PresetTable("astc", COLUMNS, {
    "fastest":    (2, 4, 1, 0, 1, 0, 1, 3000, 1, 0, 1, 20, 900, 200, 1, 150, 0, 0, 30, 0, 1, 1, 50, 0, 3000, 0, 0, 1, 3000, 0, 100, 0, 0, 0, 0, 0, 0),
    "fast":       (2, 4, 1, 1, 1, 0, 1, 1500, 2, 0, 1, 20, 1000, 70, 1, 150, 0, 80, 30, 0, 2, 1, 50, 0, 3000, 0, 0, 1, 1500, 0, 100, 0, 0, 0, 0, 0, 0),
    "medium":     (3, 16, 3, 1, 4, 0, 1, 800, 8, 2, 2, 20, 1000, 200, 1, 115, 1, 0, 30, 0, 3, 1, 0, 95, 3000, 1, 0, 1, 800, 110, 100, 0, 0, 0, 0, 0, 0),
    "thorough":   (4, 32, 6, 2, 12, 0, 1, 300, 5, 3, 2, 20, 1000, 200, 1, 125, 1, 0, 30, 0, 4, 1, 0, 115, 3000, 1, 1, 1, 300, 110, 30, 0, 0, 1, 80, 0, 0),
    "exhaustive": (4, 1024, 32, 2, 32, 0, 1, 0, 8, 4, 4, 20, 1000, 200, 1, 300, 1, 0, 30, 0, 6, 2, 0, 0, 0, 1, 0, 1, 0, 0, 100, 0, 0, 0, 0, 0, 0),
})
# 10x8: as up to 100, but `thorough` ends its blocks at 20 per texel
# (astcenc `thorough`'s limit at 10x8 is about 22): at 30 it was 0.011 dB
# under astcenc `thorough` outside the corpus; at 25 +0.008 there but 0.052
# under it on scikit-image's samples (checked), at 20 +0.026 and +0.078
UP_TO_80 = PresetTable("astc", COLUMNS, _like(UP_TO_100, thorough=dict(done_err=2000)))
# 12x10 and 12x12: as up to 100, but `fast` tries no second partition (with
# them it stayed at 0.85x astcenc `fastest`'s speed outside the corpus at
# 12x12, 1.0x at 12x10, where astcenc `fastest`'s large blocks cost least);
# the second plane as before, under 0.9 (outside 12x12 0.37x -> 1.14x, tuned
# there, +1.36 dB; corpus +0.13 dB at 4.6x, checked; without partitions
# 10x10 and 10x8 fell under astcenc `fastest` on the corpus); `fastest` no
# second partition either, or it would take 1.45x `fast`'s time (corpus 12x12
# 0.65x, 24.17 -> 23.64 dB; outside, checked, 0.69x); `thorough` ends its
# blocks at 50 per texel (astcenc `thorough`'s limit is about 46 at 12x10, 65
# at 12x12; at 30 12x12 outside was 0.93x its speed, at 50 1.10x, +0.075 dB)
UP_TO_144 = PresetTable("astc", COLUMNS, _like(
    UP_TO_100,
    fastest=dict(max_parts=1),
    fast=dict(max_parts=1, dual_corr=90, fit_gain=0),
    thorough=dict(done_err=5000),
))
# classes by texels per block: (upper bound, table)
CLASSES = ((16, UP_TO_16), (20, UP_TO_20), (25, UP_TO_25), (30, UP_TO_30), (36, UP_TO_36), (40, UP_TO_40),
           (48, UP_TO_48), (60, UP_TO_60), (64, UP_TO_64), (80, UP_TO_80), (100, UP_TO_100), (144, UP_TO_144))


def table_for(bw, bh):
    """The preset table of block size bw x bh."""
    texels = bw * bh
    for bound, table in CLASSES:
        if texels <= bound:
            return table
    return CLASSES[-1][1]


def record(bw, bh, name):
    """The search kernel's record (prm) of preset `name` at block size bw x bh."""
    return table_for(bw, bh).record(name)


_MASKS = {}


def mode_mask(bw, bh, name):
    """int64 per row of the search's mode table: 1 for the modes preset `name`
    tries at this block size."""
    return share_mask(bw, bh, table_for(bw, bh).row(name).mode_share)


def share_mask(bw, bh, share):
    """1 for the ranked modes until `share` (per 1000) of the wins is covered,
    and at least one single-plane mode; every mode when the share is 1000 or
    the size has no ranking."""
    key = (bw, bh, share)
    if key not in _MASKS:
        from .search import tables

        tb = tables(bw, bh)
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
    return sorted({table_for(bw, bh).row(name).mode_share for name in PRESETS} - {1000})
