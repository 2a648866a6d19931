"""BC6H's fixed tables: the 14 modes with their header bit layouts, the 32
two-region partitions with their anchors, and the index weights.

Facts from the Khronos Data Format Specification ("BPTC") and the Direct3D 11
functional specification (BC6H). The partitions, their anchors and the index
weights are BC7's (the first 32 two-subset shapes, its 3- and 4-bit weights):
they are taken from codecs/bc7_tables.py, which writes them once.

Header layouts are written as the specification's tables read, bit 0 first:
`M2`/`M5` the 2 or 5 mode bits, `d0-4` the partition number, `rw0-9` bits 0..9
of the red base endpoint in order, `rw15-10` bits 15 down to 10 (modes 13 and
14 store the top bits of the base reversed), `gy4` one bit. Endpoints: w the
base (region 0, endpoint 0), x region 0 endpoint 1, y and z region 1; in
transformed modes x, y and z are signed deltas from w.
"""

import numpy as np

from .bc7_tables import ANCHOR2, PARTITION2, WEIGHTS

# (mode value, regions, transformed, base bits, delta bits r/g/b, header layout)
# in the order of the specification's mode numbers 1..14.
MODES = (
    (0, 2, 1, 10, (5, 5, 5),
     "M2 gy4 by4 bz4 rw0-9 gw0-9 bw0-9 rx0-4 gz4 gy0-3 gx0-4 bz0 gz0-3 bx0-4 bz1 by0-3 ry0-4 bz2 rz0-4 bz3 d0-4"),
    (1, 2, 1, 7, (6, 6, 6),
     "M2 gy5 gz4 gz5 rw0-6 bz0 bz1 by4 gw0-6 by5 bz2 gy4 bw0-6 bz3 bz5 bz4 rx0-5 gy0-3 gx0-5 gz0-3 bx0-5 by0-3 "
     "ry0-5 rz0-5 d0-4"),
    (2, 2, 1, 11, (5, 4, 4),
     "M5 rw0-9 gw0-9 bw0-9 rx0-4 rw10 gy0-3 gx0-3 gw10 bz0 gz0-3 bx0-3 bw10 bz1 by0-3 ry0-4 bz2 rz0-4 bz3 d0-4"),
    (6, 2, 1, 11, (4, 5, 4),
     "M5 rw0-9 gw0-9 bw0-9 rx0-3 rw10 gz4 gy0-3 gx0-4 gw10 gz0-3 bx0-3 bw10 bz1 by0-3 ry0-3 bz0 bz2 rz0-3 gy4 bz3 "
     "d0-4"),
    (10, 2, 1, 11, (4, 4, 5),
     "M5 rw0-9 gw0-9 bw0-9 rx0-3 rw10 by4 gy0-3 gx0-3 gw10 bz0 gz0-3 bx0-4 bw10 by0-3 ry0-3 bz1 bz2 rz0-3 bz4 bz3 "
     "d0-4"),
    (14, 2, 1, 9, (5, 5, 5),
     "M5 rw0-8 by4 gw0-8 gy4 bw0-8 bz4 rx0-4 gz4 gy0-3 gx0-4 bz0 gz0-3 bx0-4 bz1 by0-3 ry0-4 bz2 rz0-4 bz3 d0-4"),
    (18, 2, 1, 8, (6, 5, 5),
     "M5 rw0-7 gz4 by4 gw0-7 bz2 gy4 bw0-7 bz3 bz4 rx0-5 gy0-3 gx0-4 bz0 gz0-3 bx0-4 bz1 by0-3 ry0-5 rz0-5 d0-4"),
    (22, 2, 1, 8, (5, 6, 5),
     "M5 rw0-7 bz0 by4 gw0-7 gy5 gy4 bw0-7 gz5 bz4 rx0-4 gz4 gy0-3 gx0-5 gz0-3 bx0-4 bz1 by0-3 ry0-4 bz2 rz0-4 bz3 "
     "d0-4"),
    (26, 2, 1, 8, (5, 5, 6),
     "M5 rw0-7 bz1 by4 gw0-7 by5 gy4 bw0-7 bz5 bz4 rx0-4 gz4 gy0-3 gx0-4 bz0 gz0-3 bx0-5 by0-3 ry0-4 bz2 rz0-4 bz3 "
     "d0-4"),
    (30, 2, 0, 6, (6, 6, 6),
     "M5 rw0-5 gz4 bz0 bz1 by4 gw0-5 gy5 by5 bz2 gy4 bw0-5 gz5 bz3 bz5 bz4 rx0-5 gy0-3 gx0-5 gz0-3 bx0-5 by0-3 "
     "ry0-5 rz0-5 d0-4"),
    (3, 1, 0, 10, (10, 10, 10), "M5 rw0-9 gw0-9 bw0-9 rx0-9 gx0-9 bx0-9"),
    (7, 1, 1, 11, (9, 9, 9), "M5 rw0-9 gw0-9 bw0-9 rx0-8 rw10 gx0-8 gw10 bx0-8 bw10"),
    (11, 1, 1, 12, (8, 8, 8), "M5 rw0-9 gw0-9 bw0-9 rx0-7 rw11 rw10 gx0-7 gw11 gw10 bx0-7 bw11 bw10"),
    (15, 1, 1, 16, (4, 4, 4), "M5 rw0-9 gw0-9 bw0-9 rx0-3 rw15-10 gx0-3 gw15-10 bx0-3 bw15-10"),
)
NMODES = len(MODES)

# header slot kinds: a mode bit, a partition bit, or endpoint e (0 w, 1 x,
# 2 y, 3 z) channel c as field 2 + 3 * e + c
F_MODE, F_PART = 0, 1
_ENDPOINT = {"w": 0, "x": 1, "y": 2, "z": 3}
_CHANNEL = {"r": 0, "g": 1, "b": 2}


def _layout(text):
    """[(field, bit)] for each header bit, bit 0 first."""
    out = []
    for tok in text.split():
        if tok[0] == "M":
            out += [(F_MODE, b) for b in range(int(tok[1:]))]
            continue
        if tok[0] == "d":
            field, span = F_PART, tok[1:]
        else:
            field, span = 2 + 3 * _ENDPOINT[tok[1]] + _CHANNEL[tok[0]], tok[2:]
        lo, _, hi = span.partition("-")
        lo, hi = int(lo), int(hi or lo)
        step = 1 if hi >= lo else -1
        out += [(field, b) for b in range(lo, hi + step, step)]
    return out


def _tables():
    info = np.zeros((NMODES, 8), np.int64)  # value, regions, transformed, base, dr, dg, db, header bits
    layout = np.full((NMODES, 82, 2), -1, np.int64)
    for i, (value, regions, transformed, base, delta, text) in enumerate(MODES):
        slots = _layout(text)
        header = 82 if regions == 2 else 65
        if len(slots) != header:
            raise AssertionError(f"BC6H mode {i + 1}: {len(slots)} header bits, not {header}")
        # every field bit exactly once, as many as the mode stores
        want = {(F_MODE, b) for b in range(2 if value < 2 else 5)}
        want |= {(F_PART, b) for b in range(5 if regions == 2 else 0)}
        for e in range(2 * regions):
            for c in range(3):
                bits = base if e == 0 else delta[c]
                want |= {(2 + 3 * e + c, b) for b in range(bits)}
        if sorted(slots) != sorted(want):
            raise AssertionError(f"BC6H mode {i + 1}: header fields do not match its precisions")
        info[i] = (value, regions, transformed, base, *delta, header)
        layout[i, :header] = slots
    return info, layout


MODE_INFO, LAYOUT = _tables()
# columns of MODE_INFO
I_VALUE, I_REGIONS, I_TRANSFORMED, I_BASE, I_DELTA, I_HEADER = 0, 1, 2, 3, 4, 7


def _mode_of_value():
    """The mode (0..13) of each 5-bit value of the block's low bits, -1 for the
    reserved ones. Values whose low two bits are 00 or 01 are modes 1 and 2
    (two mode bits); the others read five."""
    out = np.full(32, -1, np.int64)
    for v in range(32):
        key = v & 3 if v & 3 < 2 else v
        for i in range(NMODES):
            if MODE_INFO[i, I_VALUE] == key:
                out[v] = i
    return out


MODE_OF_VALUE = _mode_of_value()

# The 32 two-region shapes: PARTITIONS[part, t] is the region of texel t
# (row-major), ANCHORS[part] the anchor texel of region 1 (region 0's is texel 0).
PARTITIONS = PARTITION2[:32].copy()
ANCHORS = ANCHOR2[:32].copy()

# index weights out of 64: 3-bit (two regions) and 4-bit (one region)
WEIGHTS3 = WEIGHTS[3, :8].copy()
WEIGHTS4 = WEIGHTS[4, :16].copy()

HALF_MAX = 0x7BFF  # 65504, the largest finite half float
