"""The surfaces a texture is shown on, in view space (camera at the origin,
looking down +z, y up), as triangles with texture coordinates.

- plane: a ground plane seen from just above at a grazing angle, from the
  bottom of the frame (magnified twice) to far minification near the
  horizon: where mip selection, anisotropy and alpha coverage show.
- tunnel: four walls of a square tunnel running away from the camera: every
  direction of anisotropy at once, and magnification at the edges.
- quad: the texture once on a tilted square, mostly in front of the camera.

`texels_per_pixel_min` says how the texture coordinates are scaled: the plane
and the tunnel repeat the texture so that the nearest covered pixel's larger
footprint axis spans that many level-0 texels (None keeps the quad's 0..1
coordinates).
"""

import math
from dataclasses import dataclass

import numpy as np

from ..errors import UsageError


@dataclass(frozen=True)
class Scene:
    name: str
    positions: np.ndarray  # (T, 3, 3) view space
    uvs: np.ndarray  # (T, 3, 2); v runs down the image (row 0 at v = 0)
    fov_y: float  # radians
    texels_per_pixel_min: float = None


def _pitch(points, degrees):
    """Rotate world points so that a camera pitched down by `degrees` looks down +z."""
    a = math.radians(degrees)
    c, s = math.cos(a), math.sin(a)
    p = np.asarray(points, np.float64)
    y = p[..., 1] * c + p[..., 2] * s
    z = -p[..., 1] * s + p[..., 2] * c
    return np.stack([p[..., 0], y, z], axis=-1)


def _quad(corners, uv):
    """Two triangles from four corners in order (and their texture coordinates)."""
    c = np.asarray(corners, np.float64)
    t = np.asarray(uv, np.float64)
    return np.stack([c[[0, 1, 2]], c[[0, 2, 3]]]), np.stack([t[[0, 1, 2]], t[[0, 2, 3]]])


def plane():
    near, far, half = 1.0, 40.0, 40.0
    corners = [(-half, -1.0, near), (half, -1.0, near), (half, -1.0, far), (-half, -1.0, far)]
    # u along x, v along depth (away from the camera), one unit per world unit
    uv = [(-half, -near), (half, -near), (half, -far), (-half, -far)]
    pos, tex = _quad(_pitch(corners, 10.0), uv)
    return Scene("plane", pos, tex, math.radians(40.0), 0.5)


def tunnel():
    near, far, r = 0.3, 30.0, 1.0
    walls = [
        ((-r, -r), (r, -r)),  # floor
        ((r, -r), (r, r)),  # right
        ((r, r), (-r, r)),  # ceiling
        ((-r, r), (-r, -r)),  # left
    ]
    pos, tex = [], []
    for (x0, y0), (x1, y1) in walls:
        corners = [(x0, y0, near), (x1, y1, near), (x1, y1, far), (x0, y0, far)]
        uv = [(0.0, -near), (2 * r, -near), (2 * r, -far), (0.0, -far)]
        p, t = _quad(corners, uv)
        pos.append(p)
        tex.append(t)
    return Scene("tunnel", np.concatenate(pos), np.concatenate(tex), math.radians(70.0), 1.0)


def quad():
    a, b = math.radians(45.0), math.radians(-15.0)
    # unit square turned about y by a, then about x by b, centred 2.2 ahead
    square = np.array([(-1.0, 1.0, 0.0), (1.0, 1.0, 0.0), (1.0, -1.0, 0.0), (-1.0, -1.0, 0.0)])
    ry = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
    rx = np.array([[1, 0, 0], [0, math.cos(b), -math.sin(b)], [0, math.sin(b), math.cos(b)]])
    corners = square @ ry.T @ rx.T + np.array([0.0, 0.0, 2.2])
    pos, tex = _quad(corners, [(0, 0), (1, 0), (1, 1), (0, 1)])
    return Scene("quad", pos, tex, math.radians(60.0), None)


SCENES = {"plane": plane, "tunnel": tunnel, "quad": quad}


def get(name):
    if name not in SCENES:
        raise UsageError(f"unknown scene {name!r}; choose one of {', '.join(SCENES)}")
    return SCENES[name]()
