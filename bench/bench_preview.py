"""texcook preview: time per frame of every filter and its PSNR against the
supersampled reference, at 512x512 on the plane scene (grazing angle).

Times are the fastest of --repeat runs after a warm-up (compiled kernels
loaded), whole frame: rasterise + filter + shade; `s/frame` is wall time and
`cpu s` the CPU time of all threads (what the frame costs when the machine is
shared: on an idle 2-core machine the wall time approaches half of it). Targets: trilinear under 0.2 s and EWA
under 2 s per 512x512 frame on the 2-core development machine.

    python bench/bench_preview.py [TEXTURE ...] [--size 512x512] [--scene plane] [--repeat 3]

Without TEXTURE: a high-frequency checkerboard (64x64, 2-texel squares) and
corpus/rgb/ldr-rgb-03.png.
"""

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def checkerboard(directory):
    from texcook.image import write_image

    y, x = np.mgrid[0:64, 0:64]
    c = (((x // 2) + (y // 2)) % 2 * 255).astype(np.uint8)
    path = os.path.join(directory, "checker-64-2.png")
    write_image(path, np.stack([c, c, c], axis=-1))
    return path


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("textures", nargs="*")
    ap.add_argument("--size", default="512x512")
    ap.add_argument("--scene", default="plane")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    from texcook.preview import render

    with tempfile.TemporaryDirectory() as tmp:
        textures = args.textures or [checkerboard(tmp), str(ROOT / "corpus" / "rgb" / "ldr-rgb-03.png")]
        for path in textures:
            render(path, scene=args.scene, filter="all", size="64x64")  # warm-up: load compiled kernels
            t0 = time.perf_counter()
            result = render(path, scene=args.scene, filter="all", size=args.size, runs=args.repeat)
            total = time.perf_counter() - t0
            print(f"{os.path.basename(path)}  {args.scene} {args.size}  (raster {result.raster_seconds * 1000:.1f} ms, "
                  f"reference {result.reference.seconds:.2f} s, whole run {total:.1f} s)")
            print(f"  {'filter':<10} {'s/frame':>8} {'cpu s':>8} {'PSNR dB':>8} {'blur dB':>8} {'alias dB':>9}")
            for row in result.rows:
                print(f"  {row['filter']:<10} {row['seconds']:>8.3f} {row['cpu_seconds']:>8.3f} {row['psnr']:>8.2f} "
                      f"{row['blur_db']:>8.2f} {row['alias_db']:>9.2f}")


if __name__ == "__main__":
    main()
