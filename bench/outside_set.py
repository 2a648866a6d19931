"""A second image set for `texcook bench`, outside the bundled corpus the
presets were tuned on, laid out like the corpus so each scoring takes its own
folder:

    python bench/outside_set.py DIR      # writes DIR/rgb, DIR/rgba, DIR/normal, DIR/hdr
    texcook bench DIR --formats bc1,bc5 --presets fastest,fast

Same pixels every run (fixed seeds; matplotlib's sample data as shipped):

- rgb/: matplotlib's photograph (grace, 512x512), the fault elevation map
  through a colour map (dem-colour, 403x344), two PBR-like base colours
  (256x256, generated).
- rgba/: the photograph cut out by a soft-edged ellipse, the present and the
  logo drawings (RGBA as shipped: 128x128, and 512x128 of 542x130), two
  cut-outs of base colour with soft-edged painted alpha (256x256, generated).
- normal/: tangent-space normals (X in R, Y in G, Z in B) of the elevation map
  (256x256 crop) and of a generated height field of bevelled tiles with bumps.
- hdr/: linear float RGB in Radiance .hdr files, as the corpus's (an EXR
  carries the date it was written): the photograph's middle 256x256 under an
  exposure ramp of eight stops, and a generated sky with a sun over a lit
  base colour (values up to about 60).

The photographs, the elevation map and the generated colours and cut-outs are
those of bench/bench_astc_outside.py (its `photo` and `generated` sets,
imported), so an ASTC figure measured there is on the same pixels.
"""

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_astc_outside import _base_colour, _smooth_field, generated, photo  # noqa: E402

SEED = 3030


def _sample(name):
    import matplotlib.cbook as cb

    return cb.get_sample_data(name, asfileobj=False)


def _normals(height, strength):
    """Unit normals of a height field (central differences), 8-bit XYZ."""
    gy, gx = np.gradient(height * strength)
    n = np.stack([-gx, -gy, np.ones_like(height)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return np.clip(np.rint(n * 127.5 + 127.5), 0, 255).astype(np.uint8)


def _tiles(rng, n):
    """Height of bevelled square tiles (bevel 4 texels) with a few round bumps
    and fine noise, as a painted surface detail map has."""
    yy, xx = np.mgrid[0:n, 0:n].astype(np.float64)
    size = 64
    edge = np.minimum(np.minimum(yy % size, size - 1 - yy % size), np.minimum(xx % size, size - 1 - xx % size))
    h = np.clip(edge / 4.0, 0, 1)
    for _ in range(10):
        cy, cx, r = rng.uniform(0, n), rng.uniform(0, n), rng.uniform(6, 20)
        d = np.sqrt((yy - cy) ** 2 + (xx - cx) ** 2) / r
        h += 0.6 * np.clip(1 - d * d, 0, None)
    h += 0.3 * _smooth_field(rng, n, n, 12) + rng.normal(0, 0.01, (n, n))
    return h


def _sky(rng, n):
    """Linear HDR: a sky gradient with a sun disc above a base colour lit by the
    sun through a soft shadow field."""
    yy, xx = np.mgrid[0:n, 0:n] / n
    out = np.zeros((n, n, 3), np.float64)
    horizon = 0.4
    sky = yy < horizon
    t = (yy / horizon)[..., None]
    out = np.where(sky[..., None], np.array([0.25, 0.45, 1.2]) * (1 - t) + np.array([1.4, 1.3, 1.1]) * t, out)
    sun = np.sqrt((yy - 0.22) ** 2 + (xx - 0.7) ** 2)
    out += (np.clip(1 - sun / 0.04, 0, 1) * 60.0 + np.exp(-sun / 0.05) * 4.0)[..., None] * np.array([1, 0.9, 0.7])
    ground = (_base_colour(rng, n, n, 2.0) / 255.0) ** 2.2
    light = 0.15 + 3.0 * (_smooth_field(rng, n, n, 6) > 0.45)
    return np.where(sky[..., None], out, ground * light[..., None]).astype(np.float32)


def images():
    """[(folder, file name, pixels)]: uint8 RGB/RGBA, float32 RGB for hdr/."""
    from PIL import Image

    from texcook.colour import srgb_to_linear

    rng = np.random.default_rng(SEED)
    shot = {name: img for name, _, img in photo()}
    made = {name: img for name, _, img in generated()}
    logo = np.asarray(Image.open(_sample("logo2.png")).convert("RGBA"))[:128, :512]
    dem = np.load(_sample("jacksboro_fault_dem.npz"))["elevation"].astype(np.float64)[:256, :256]
    grace = shot["grace"][128:384, 128:384, :3].astype(np.float32) / 255.0
    ramp = np.exp2(np.linspace(-3.0, 5.0, grace.shape[1], dtype=np.float32))[None, :, None]
    out = [("rgb", "grace.png", shot["grace"][..., :3]), ("rgb", "dem-colour.png", shot["dem-colour"][..., :3]),
           ("rgb", "pbr-base-a.png", made["pbr-base-a"][..., :3]),
           ("rgb", "pbr-base-b.png", made["pbr-base-b"][..., :3]),
           ("rgba", "grace-cutout.png", shot["grace-cutout"]), ("rgba", "present.png", shot["drawing"]),
           ("rgba", "logo.png", np.ascontiguousarray(logo)),
           ("rgba", "cutout-blobs.png", made["cutout-blobs"]), ("rgba", "cutout-leaves.png", made["cutout-leaves"]),
           # the elevation in metres over texels of about 10 m: a slope of 1 stays under 45 degrees
           ("normal", "normal-dem.png", _normals(dem, 0.1)),
           ("normal", "normal-tiles.png", _normals(_tiles(rng, 256), 3.0)),
           ("hdr", "grace-exposure.hdr", np.ascontiguousarray(srgb_to_linear(grace) * ramp, np.float32)),
           ("hdr", "sky.hdr", _sky(rng, 256))]
    return [(folder, name, np.ascontiguousarray(px)) for folder, name, px in out]


def write_images(directory, items):
    """Write [(folder, name, pixels)] under `directory` (made if missing), as
    the corpus is laid out; returns the paths."""
    from texcook.image import write_image

    paths = []
    for folder, name, px in items:
        os.makedirs(os.path.join(directory, folder), exist_ok=True)
        path = os.path.join(directory, folder, name)
        write_image(path, px)
        paths.append(path)
    return paths


def write(directory):
    """Write the set under `directory` (made if missing); returns the paths."""
    return write_images(directory, images())


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("directory")
    args = ap.parse_args()
    for path in write(args.directory):
        print(path)


if __name__ == "__main__":
    main()
