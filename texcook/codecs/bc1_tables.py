"""BC1's fixed tables, computed once at import: the best endpoint pair for
each single colour, the nearest 5- and 6-bit levels, and the index weights."""

import numpy as np


def _single_tables():
    """For each 8-bit value: the (hi, lo) endpoint levels whose interpolant
    (2*hi + lo) // 3 (4-colour) or (hi + lo) // 2 (3-colour) is nearest.
    Shape (2 modes, 2 widths [5-bit, 6-bit], 256, 2)."""
    tab = np.zeros((2, 2, 256, 2), np.int64)
    v = np.arange(256)[:, None, None]
    for wi, bits in enumerate((5, 6)):
        lv = np.arange(1 << bits)
        e = (lv << (8 - bits)) | (lv >> (2 * bits - 8))
        for mi, val in enumerate(((2 * e[:, None] + e[None, :]) // 3, (e[:, None] + e[None, :]) // 2)):
            # ties go to the pair with the smallest spread: the most robust to
            # other decoders' rounding
            cost = np.abs(val[None] - v) * 1024 + np.abs(e[:, None] - e[None, :])[None]
            flat = cost.reshape(256, -1).argmin(axis=1)
            tab[mi, wi, :, 0] = flat // lv.size
            tab[mi, wi, :, 1] = flat % lv.size
    return tab


SINGLE = _single_tables()


def _flat_errors():
    """The squared error of SINGLE's pair for each 8-bit value: (mode, width, value)."""
    err = np.zeros((2, 2, 256), np.int64)
    v = np.arange(256)
    for wi, bits in enumerate((5, 6)):
        for mi in range(2):
            hi, lo = ((SINGLE[mi, wi, :, k] << (8 - bits)) | (SINGLE[mi, wi, :, k] >> (2 * bits - 8)) for k in (0, 1))
            val = (2 * hi + lo) // 3 if mi == 0 else (hi + lo) // 2
            err[mi, wi] = (val - v) ** 2
    return err


FLAT_ERR = _flat_errors()


def _level_tables():
    """Nearest 5- and 6-bit level (after bit replication) for every 8-bit value."""
    v = np.arange(256)
    out = []
    for bits in (5, 6):
        lv = np.arange(1 << bits)
        e = (lv << (8 - bits)) | (lv >> (2 * bits - 8))
        out.append(np.abs(e[None, :] - v[:, None]).argmin(axis=1).astype(np.int64))
    return out[0], out[1]


Q5, Q6 = _level_tables()

# index -> weight of c0, in thirds (4-colour) and halves (3-colour; 3 is black)
W4 = np.array([3.0, 0.0, 2.0, 1.0])
W3 = np.array([2.0, 0.0, 1.0, 0.0])
