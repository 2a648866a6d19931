"""BC7's fixed tables (Khronos Data Format Specification, "BPTC"): the mode
parameters, the 2- and 3-subset partitions with their anchor texels, the
index weights, and tables computed once at import for the encoder.

The partition and anchor tables were checked entry by entry against the KDF
text (bptc.txt): its bold marks in the 3-subset table, partition 1, also mark
texel 15 and in the 2-subset table, partition 35, texel 2 instead of 8; the
anchor tables, which the decoding formula uses, say 3/8 and 8, and that is
what is written here (and what every decoder we test against reads)."""

import numpy as np


def _grid(text):
    """Partitions written as 16 digits each (texel x + 4y, row-major), four to a
    line followed by their numbers -> int64 (64, 16)."""
    rows = [t for t in text.split() if len(t) == 16 and t.isdigit()]
    assert len(rows) == 64
    return np.array([[int(ch) for ch in r] for r in rows], np.int64)


# Mode parameters, one row per mode (KDF table "Mode-dependent BPTC parameters").
# NS subsets, PB partition bits, RB rotation bits, ISB index-selection bits, CB
# colour bits and AB alpha bits per channel and endpoint, EPB 1: a p-bit per
# endpoint, SPB 1: a p-bit per subset, IB / IB2 primary / secondary index bits.
NS, PB, RB, ISB, CB, AB, EPB, SPB, IB, IB2 = range(10)
MODES = np.array([
    # NS PB RB ISB CB AB EPB SPB IB IB2
    (3, 4, 0, 0, 4, 0, 1, 0, 3, 0),  # 0
    (2, 6, 0, 0, 6, 0, 0, 1, 3, 0),  # 1
    (3, 6, 0, 0, 5, 0, 0, 0, 2, 0),  # 2
    (2, 6, 0, 0, 7, 0, 1, 0, 2, 0),  # 3
    (1, 0, 2, 1, 5, 6, 0, 0, 2, 3),  # 4
    (1, 0, 2, 0, 7, 8, 0, 0, 2, 2),  # 5
    (1, 0, 0, 0, 7, 7, 1, 0, 4, 0),  # 6
    (2, 6, 0, 0, 5, 5, 1, 0, 2, 0),  # 7
], np.int64)

# Interpolation weights (out of 64) for 2-, 3- and 4-bit indices: WEIGHTS[bits][index].
WEIGHTS = np.zeros((5, 16), np.int64)
WEIGHTS[2, :4] = (0, 21, 43, 64)
WEIGHTS[3, :8] = (0, 9, 18, 27, 37, 46, 55, 64)
WEIGHTS[4, :16] = (0, 4, 9, 13, 17, 21, 26, 30, 34, 38, 43, 47, 51, 55, 60, 64)

PARTITION2 = _grid("""
    0011001100110011 0001000100010001 0111011101110111 0001001100110111  0-3
    0000000100010011 0011011101111111 0001001101111111 0000000100110111  4-7
    0000000000010011 0011011111111111 0000000101111111 0000000000010111  8-11
    0001011111111111 0000000011111111 0000111111111111 0000000000001111  12-15
    0000100011101111 0111000100000000 0000000010001110 0111001100010000  16-19
    0011000100000000 0000100011001110 0000000010001100 0111001100110001  20-23
    0011000100010000 0000100010001100 0110011001100110 0011011001101100  24-27
    0001011111101000 0000111111110000 0111000110001110 0011100110011100  28-31
    0101010101010101 0000111100001111 0101101001011010 0011001111001100  32-35
    0011110000111100 0101010110101010 0110100101101001 0101101010100101  36-39
    0111001111001110 0001001111001000 0011001001001100 0011101111011100  40-43
    0110100110010110 0011110011000011 0110011010011001 0000011001100000  44-47
    0100111001000000 0010011100100000 0000001001110010 0000010011100100  48-51
    0110110010010011 0011011011001001 0110001110011100 0011100111000110  52-55
    0110110011001001 0110001100111001 0111111010000001 0001100011100111  56-59
    0000111100110011 0011001111110000 0010001011101110 0100010001110111  60-63
""")

PARTITION3 = _grid("""
    0011001102212222 0001001122112221 0000200122112211 0222002200110111  0-3
    0000000011221122 0011001100220022 0022002211111111 0011001122112211  4-7
    0000000011112222 0000111111112222 0000111122222222 0012001200120012  8-11
    0112011201120112 0122012201220122 0011011211221222 0011200122002220  12-15
    0001001101121122 0111001120012200 0000112211221122 0022002200221111  16-19
    0111011102220222 0001000122212221 0000001101220122 0000110022102210  20-23
    0122012200110000 0012001211222222 0110122112210110 0000011012211221  24-27
    0022110211020022 0110011020022222 0011012201220011 0000200022112221  28-31
    0000000211221222 0222002200120011 0011001200220222 0120012001200120  32-35
    0000111122220000 0120120120120120 0120201212010120 0011220011220011  36-39
    0011112222000011 0101010122222222 0000000021212121 0022112200221122  40-43
    0022001100220011 0220122102201221 0101222222220101 0000212121212121  44-47
    0101010101012222 0222011102220111 0002111200021112 0000211221122112  48-51
    0222011101110222 0002111211120002 0110011001102222 0000000021122112  52-55
    0110011022222222 0022001100110022 0022112211220022 0000000000002112  56-59
    0002000100020001 0222122202221222 0101222222222222 0111201122012220  60-63
""")

# Anchor texel of subset 1 (two subsets), of subsets 1 and 2 (three subsets);
# subset 0's anchor is texel 0.
ANCHOR2 = np.array([
    15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15,  # 0-15
    15,  2,  8,  2,  2,  8,  8, 15,  2,  8,  2,  2,  8,  8,  2,  2,  # 16-31
    15, 15,  6,  8,  2,  8, 15, 15,  2,  8,  2,  2,  2, 15, 15,  6,  # 32-47
     6,  2,  6,  8, 15, 15,  2,  2, 15, 15, 15, 15, 15,  2,  2, 15,  # 48-63
], np.int64)

ANCHOR3_2 = np.array([
     3,  3, 15, 15,  8,  3, 15, 15,  8,  8,  6,  6,  6,  5,  3,  3,  # 0-15
     3,  3,  8, 15,  3,  3,  6, 10,  5,  8,  8,  6,  8,  5, 15, 15,  # 16-31
     8, 15,  3,  5,  6, 10,  8, 15, 15,  3, 15,  5, 15, 15, 15, 15,  # 32-47
     3, 15,  5,  5,  5,  8,  5, 10,  5, 10,  8, 13, 15, 12,  3,  3,  # 48-63
], np.int64)

ANCHOR3_3 = np.array([
    15,  8,  8,  3, 15, 15,  3,  8, 15, 15, 15, 15, 15, 15, 15,  8,  # 0-15
    15,  8, 15,  3, 15,  8, 15,  8,  3, 15,  6, 10, 15, 15, 10,  8,  # 16-31
    15,  3, 15, 10, 10,  8,  9, 10,  6, 15,  8, 15,  3,  6,  6,  8,  # 32-47
    15,  3, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15,  3, 15, 15,  8,  # 48-63
], np.int64)


def _subsets():
    """SUBSET[ns - 1, part, texel]: the subset of each texel (one subset: all 0)."""
    out = np.zeros((3, 64, 16), np.int64)
    out[1] = PARTITION2
    out[2] = PARTITION3
    return out


def _anchors():
    """ANCHOR[ns - 1, part, subset]: the anchor texel of each subset."""
    out = np.zeros((3, 64, 3), np.int64)
    out[1, :, 1] = ANCHOR2
    out[2, :, 1] = ANCHOR3_2
    out[2, :, 2] = ANCHOR3_3
    return out


SUBSET = _subsets()
ANCHOR = _anchors()


# --- encoder tables ------------------------------------------------------------------
#
# An endpoint channel of `bits` stored bits, with a p-bit p appended or none,
# expands to 8 bits by replicating its top bits. EXPAND[bits, k, q] is that
# value for stored q (k = p for a p-bit, k = 2 without one) and NEAREST[bits, k, v]
# the q whose expansion is nearest the 8-bit value v (the lower on ties).

def _quant_tables():
    expand = np.zeros((9, 3, 256), np.int64)
    nearest = np.zeros((9, 3, 256), np.int64)
    v = np.arange(256)
    for bits in range(4, 9):
        q = np.arange(1 << bits)
        for k in range(3):
            if k == 2:
                n, stored = bits, q
            else:
                n, stored = bits + 1, (q << 1) | k
            if n > 8:
                continue
            e = stored << (8 - n)
            e = e | (e >> n)
            expand[bits, k, :q.size] = e
            nearest[bits, k] = np.abs(e[None, :] - v[:, None]).argmin(axis=1)
    return expand, nearest


EXPAND, NEAREST = _quant_tables()


def _single_colour():
    """SINGLE[v] = (a, b): mode 5's 7-bit colour endpoints whose index-1 value
    (43 a' + 21 b' + 32) >> 6, on the expansions a', b', is v. Every 8-bit value
    has such a pair, so a constant colour encodes exactly (mode 5's 8-bit
    alpha endpoints hold alpha as is)."""
    e = EXPAND[7, 2, :128]
    val = (43 * e[:, None] + 21 * e[None, :] + 32) >> 6
    out = np.zeros((256, 2), np.int64)
    for v in range(256):
        a, b = np.argwhere(val == v)[0]
        out[v] = a, b
    return out


SINGLE = _single_colour()



def _nibbles():
    """NIBBLE[ns - 1, part, s, y]: the texels of row y in subset s as a 4-bit
    pattern (bit x); COUNT[ns - 1, part, s]: how many texels the subset has."""
    nib = np.zeros((3, 64, 3, 4), np.int64)
    for ns in (1, 2, 3):
        for s in range(ns):
            inside = (SUBSET[ns - 1] == s).reshape(64, 4, 4)
            nib[ns - 1, :, s] = (inside * (1 << np.arange(4))).sum(axis=2)
    count = np.zeros((3, 64, 3))
    for ns in (1, 2, 3):
        for s in range(ns):
            count[ns - 1, :, s] = (SUBSET[ns - 1] == s).sum(axis=1)
    return nib, count


NIBBLE, COUNT = _nibbles()
