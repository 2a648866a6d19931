"""Triangles in perspective: project, cover, interpolate, differentiate.

The camera sits at the origin looking down +z (x right, y up), with a vertical
field of view and square pixels. A view-space point (X, Y, Z) lands on pixel
coordinates

    sx = (X f / (a Z) + 1) W / 2,    sy = (1 - Y f / Z) H / 2,

f = 1 / tan(fov / 2), a = W / H; pixel (i, j) covers [i, i + 1) x [j, j + 1)
and is sampled at its centre. Screen-space barycentrics are affine in (sx, sy),
and so are u/w, v/w and 1/w (w = Z): they are interpolated linearly and u, v
recovered per pixel by one division, which is what perspective-correct
interpolation means. The derivatives of u = (u/w) / (1/w) follow from the
quotient rule on those affine functions, exactly at the pixel centre.

A triangle's setup is one row of 18 float64 numbers: the barycentric planes
(b_k = A_k sx + B_k sy + C_k for k = 0, 1, 2) and, per vertex, 1/w, u/w, v/w.
The rasteriser (pixel centres) and the reference (any sub-pixel position) read
the same rows.
"""

import math

import numpy as np
from numba import prange

from .._jit import jit
from ..errors import UsageError

GBUF_CHANNELS = 6  # per pixel: u, v, du/dx, dv/dx, du/dy, dv/dy
# Frame kernels hand rows to threads in STRIPES interleaved sets (row y goes to set
# y % STRIPES): the work per row varies a lot (sky above the plane, the expensive
# horizon), and whole blocks of rows per thread would leave one thread idle.
STRIPES = 32
_NEAR = 1e-6  # vertices must be in front of the camera: no clipping is done
# A pixel centre on an edge two triangles share can round to just outside both;
# this much slack covers it (twice, and the depth test keeps one).
_EDGE_SLACK = -1e-9


def projection(fov_y, width, height):
    """(f / a, f): the scale of X / Z and Y / Z to normalised device units."""
    f = 1.0 / math.tan(fov_y / 2.0)
    return f * height / width, f


def to_screen(points, fov_y, width, height):
    """View-space points (..., 3) -> pixel coordinates (..., 2) and w = Z."""
    p = np.asarray(points, np.float64)
    fx, fy = projection(fov_y, width, height)
    z = p[..., 2]
    sx = (p[..., 0] * fx / z + 1.0) * (width / 2.0)
    sy = (1.0 - p[..., 1] * fy / z) * (height / 2.0)
    return np.stack([sx, sy], axis=-1), z


def triangle_setup(positions, uvs, fov_y, width, height):
    """Per triangle, the 18-number setup row (see the module docstring) and
    the covered pixel rectangle (x0, y0, x1, y1), half-open. `positions` is
    (T, 3, 3) view space, `uvs` (T, 3, 2). Degenerate triangles (zero screen
    area) are dropped."""
    pos = np.asarray(positions, np.float64).reshape(-1, 3, 3)
    uv = np.asarray(uvs, np.float64).reshape(-1, 3, 2)
    if pos.shape[0] != uv.shape[0]:
        raise UsageError("every triangle needs three positions and three texture coordinates")
    if np.any(pos[..., 2] <= _NEAR):
        raise UsageError("scene geometry must lie in front of the camera (z > 0)")
    screen, w = to_screen(pos, fov_y, width, height)
    rows, boxes = [], []
    for (p0, p1, p2), ws, uvt in zip(screen, w, uv):
        area = (p1[0] - p0[0]) * (p2[1] - p0[1]) - (p1[1] - p0[1]) * (p2[0] - p0[0])
        if abs(area) < 1e-12:
            continue
        planes = []
        for a, b in ((p1, p2), (p2, p0), (p0, p1)):
            # Edge function of the edge opposite the vertex, over twice the area:
            # 1 at that vertex, 0 on the edge.
            planes += [(a[1] - b[1]) / area, (b[0] - a[0]) / area, (a[0] * b[1] - a[1] * b[0]) / area]
        q = 1.0 / ws
        rows.append(planes + list(q) + list(uvt[:, 0] * q) + list(uvt[:, 1] * q))
        lo = np.floor(np.min([p0, p1, p2], axis=0) - 0.5)
        hi = np.ceil(np.max([p0, p1, p2], axis=0) + 0.5)
        boxes.append([
            int(np.clip(lo[0], 0, width)), int(np.clip(lo[1], 0, height)),
            int(np.clip(hi[0], 0, width)), int(np.clip(hi[1], 0, height)),
        ])
    setup = np.array(rows, np.float64).reshape(-1, 18)
    return np.ascontiguousarray(setup), np.array(boxes, np.int64).reshape(-1, 4)


def scale_uv(setup, gbuf, factor):
    """Scale texture coordinates by `factor` in a setup and a G-buffer (both
    are linear in them), in place."""
    setup[:, 12:18] *= factor
    gbuf *= factor


@jit
def _barycentrics(s, x, y):
    b0 = s[0] * x + s[1] * y + s[2]
    b1 = s[3] * x + s[4] * y + s[5]
    b2 = s[6] * x + s[7] * y + s[8]
    return b0, b1, b2


@jit
def hit(setup, x, y):
    """The nearest triangle covering the screen point (x, y) and its u, v:
    (index or -1, u, v). Brute force over the triangles: scenes are small."""
    best, bq, bu, bv = -1, 0.0, 0.0, 0.0
    for t in range(setup.shape[0]):
        s = setup[t]
        b0, b1, b2 = _barycentrics(s, x, y)
        if b0 < _EDGE_SLACK or b1 < _EDGE_SLACK or b2 < _EDGE_SLACK:
            continue
        q = b0 * s[9] + b1 * s[10] + b2 * s[11]
        if q > bq:
            best, bq = t, q
            bu = (b0 * s[12] + b1 * s[13] + b2 * s[14]) / q
            bv = (b0 * s[15] + b1 * s[16] + b2 * s[17]) / q
    return best, bu, bv


@jit(parallel=True)
def _raster(setup, boxes, gbuf, tri):
    """Fill the G-buffer (u, v and their x/y derivatives) and the triangle id
    of the nearest surface at every pixel centre; rows run in parallel."""
    height, width = tri.shape
    for stripe in prange(STRIPES):
        for y in range(stripe, height, STRIPES):
            depth = np.zeros(width)  # 1/w of the nearest surface so far; 0 is empty
            py = y + 0.5
            for t in range(setup.shape[0]):
                if y < boxes[t, 1] or y >= boxes[t, 3]:
                    continue
                s = setup[t]
                for x in range(boxes[t, 0], boxes[t, 2]):
                    px = x + 0.5
                    b0, b1, b2 = _barycentrics(s, px, py)
                    if b0 < _EDGE_SLACK or b1 < _EDGE_SLACK or b2 < _EDGE_SLACK:
                        continue
                    q = b0 * s[9] + b1 * s[10] + b2 * s[11]
                    if q <= depth[x]:
                        continue
                    depth[x] = q
                    tri[y, x] = t
                    uq = b0 * s[12] + b1 * s[13] + b2 * s[14]
                    vq = b0 * s[15] + b1 * s[16] + b2 * s[17]
                    # d/dx of an interpolated attribute is sum_k dA_k * attr_k
                    qx = s[0] * s[9] + s[3] * s[10] + s[6] * s[11]
                    qy = s[1] * s[9] + s[4] * s[10] + s[7] * s[11]
                    uqx = s[0] * s[12] + s[3] * s[13] + s[6] * s[14]
                    uqy = s[1] * s[12] + s[4] * s[13] + s[7] * s[14]
                    vqx = s[0] * s[15] + s[3] * s[16] + s[6] * s[17]
                    vqy = s[1] * s[15] + s[4] * s[16] + s[7] * s[17]
                    u = uq / q
                    v = vq / q
                    g = gbuf[y, x]
                    g[0] = u
                    g[1] = v
                    g[2] = (uqx - u * qx) / q
                    g[3] = (vqx - v * qx) / q
                    g[4] = (uqy - u * qy) / q
                    g[5] = (vqy - v * qy) / q
    return gbuf


def rasterise(setup, boxes, width, height):
    """(G-buffer float64 (H, W, 6): u, v, du/dx, dv/dx, du/dy, dv/dy; triangle id
    int32 (H, W), -1 where empty)."""
    gbuf = np.zeros((height, width, GBUF_CHANNELS), np.float64)
    tri = np.full((height, width), -1, np.int32)
    if setup.shape[0]:
        _raster(setup, boxes, gbuf, tri)
    return gbuf, tri
