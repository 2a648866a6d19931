"""Tangent-space normal maps: the one place Z is rebuilt from X and Y.

A two-channel normal map (BC5, RG8, ASTC's X+Y) stores X and Y of a unit
vector on the positive hemisphere; a reader rebuilds Z = sqrt(1 - X^2 - Y^2).
The mip chain, the pipeline's view of a source, the metrics and the readers
texcook models all rebuild it this way.
"""

import numpy as np


def z_from_xy(x, y):
    """Z of unit vectors from X and Y in -1..1 (arrays of one dtype, which Z
    keeps); 0 where X^2 + Y^2 exceeds 1."""
    return np.sqrt(np.clip(1.0 - (x * x + y * y), 0.0, None))
