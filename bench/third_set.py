"""A third image set, for checking presets on images no tuning looked at:
scikit-image's sample images as its wheel ships them, read from the wheel
itself (no install), laid out like the corpus:

    pip download scikit-image --no-deps -d WHEELS
    python bench/third_set.py WHEELS/scikit_image-*.whl DIR    # writes DIR/rgb, DIR/rgba
    python bench/bench_astc_outside.py --set DIR --sizes 4x4 --presets medium --astcenc medium

256x256 centre crops (the whole image where it is smaller) of the photographs
(astronaut, chelsea, coffee, rocket, hubble_deep_field, retina,
motorcycle_left, ihc), the colour chart (color) and the grey textures (brick,
grass, gravel: one channel, written as RGB with R = G = B, as a roughness or
height map often arrives); the logo with its alpha in rgba/. Licences: the
wheel's skimage/data/README.txt.
"""

import argparse
import os
import sys
import tempfile
import zipfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from outside_set import write_images  # noqa: E402

RGB = ("astronaut.png", "chelsea.png", "coffee.png", "rocket.jpg", "hubble_deep_field.jpg", "retina.jpg",
       "motorcycle_left.png", "ihc.png", "color.png", "brick.png", "grass.png", "gravel.png")
RGBA = ("logo.png",)
SIZE = 256


def _crop(px):
    h, w = px.shape[:2]
    s = min(SIZE, h, w)
    y, x = (h - s) // 2, (w - s) // 2
    return px[y:y + s, x:x + s]


def images(wheel):
    """[(folder, name, uint8 pixels)] from the wheel's skimage/data."""
    from texcook.image import read_image

    out = []
    with zipfile.ZipFile(wheel) as zf, tempfile.TemporaryDirectory() as tmp:
        for names, folder, nch in ((RGB, "rgb", 3), (RGBA, "rgba", 4)):
            for name in names:
                path = zf.extract("skimage/data/" + name, tmp)
                px = _crop(read_image(path).integer_values().astype(np.uint8))
                if px.shape[2] == 1:
                    px = np.repeat(px, 3, axis=2)
                out.append((folder, os.path.splitext(name)[0] + ".png", np.ascontiguousarray(px[..., :nch])))
    return out


def write(wheel, directory):
    """Write the set under `directory` (made if missing); returns the paths."""
    return write_images(directory, images(wheel))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("wheel", help="a scikit-image wheel (pip download scikit-image --no-deps)")
    ap.add_argument("directory")
    args = ap.parse_args()
    for path in write(args.wheel, args.directory):
        print(path)


if __name__ == "__main__":
    main()
