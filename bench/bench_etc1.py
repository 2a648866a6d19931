"""ETC1 quality and speed on the corpus, against etcpak in the same process.

    python bench/bench_etc1.py [--presets fastest,medium] [--repeat 5] [--per-image]

PSNR: mean over corpus/rgb and corpus/rgba of each image's RGB PSNR, images
cropped to a multiple of 4, every bitstream decoded by texture2ddecoder.
Throughput: single-threaded megapixels per second, the numba kernels compiled
beforehand; best of --repeat rounds for etcpak, fastest and fast, one round for
the slower presets.
"""

import argparse
import glob
import os
import time

import numpy as np
import OpenImageIO as oiio
import texture2ddecoder

from texcook.codecs import get as get_codec
from texcook.codecs.etc1 import PRESETS
from texcook.metrics import psnr

ETC1 = get_codec("etc1")

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "corpus")


def load_corpus():
    images = []
    spec = oiio.ImageSpec()
    spec.attribute("oiio:UnassociatedAlpha", 1)
    for sub in ("rgb", "rgba"):
        for path in sorted(glob.glob(os.path.join(ROOT, sub, "*.png"))):
            # the file's own RGB, not premultiplied by alpha
            px = oiio.ImageBuf(path, 0, 0, spec).get_pixels(oiio.UINT8)
            h, w = px.shape[0] // 4 * 4, px.shape[1] // 4 * 4
            rgba = np.full((h, w, 4), 255, np.uint8)
            rgba[:, :, : min(4, px.shape[2])] = px[:h, :w, :4]
            images.append((os.path.basename(path), rgba))
    return images


def reference_decode(data, w, h):
    bgra = np.frombuffer(texture2ddecoder.decode_etc1(bytes(data), w, h), np.uint8)
    return bgra.reshape(h, w, 4)[:, :, [2, 1, 0, 3]]


def timed(encode, images):
    t0 = time.perf_counter()
    datas = [encode(img) for _, img in images]
    return time.perf_counter() - t0, datas


def score(datas, images):
    out = []
    for (_, img), data in zip(images, datas):
        h, w = img.shape[:2]
        out.append(psnr(reference_decode(data, w, h)[:, :, :3], img[:, :, :3]))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--presets", default=",".join(PRESETS))
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--per-image", action="store_true")
    args = ap.parse_args()
    images = load_corpus()
    presets = [p for p in args.presets.split(",") if p]

    import etcpak

    # compile before timing
    ETC1.encode(images[0][1][:8, :8].copy(), "fastest", threads=1)
    encoders = [("etcpak compress_etc1_rgb",
                 lambda img: etcpak.compress_etc1_rgb(img.tobytes(), img.shape[1], img.shape[0]))]
    for p in presets:
        encoders.append((f"texcook {p}", lambda img, p=p: ETC1.encode(img, p, threads=1)))
    # the machine is shared: run every encoder once per round, keep each one's
    # best time, so that all of them see the same background load
    best = [np.inf] * len(encoders)
    datas = [None] * len(encoders)
    for r in range(args.repeat):
        for k, (name, enc) in enumerate(encoders):
            slow = name.split()[-1] in ("medium", "thorough", "exhaustive")
            if r > 0 and slow:
                continue
            dt, datas[k] = timed(enc, images)
            best[k] = min(best[k], dt)
    mpix = sum(img.shape[0] * img.shape[1] for _, img in images) / 1e6
    rows = []
    for k, (name, _) in enumerate(encoders):
        per_image = score(datas[k], images)
        rows.append((name, float(np.mean(per_image)), mpix / best[k], per_image))
    ref = rows[0]
    print(f"{len(images)} images, {mpix:.2f} Mpix, single-threaded, best of {args.repeat} rounds")
    print("| encoder | RGB PSNR dB | vs etcpak dB | Mpix/s | vs etcpak speed |")
    print("|---|---|---|---|---|")
    for name, mean_db, speed, _ in rows:
        print(f"| {name} | {mean_db:.2f} | {mean_db - ref[1]:+.2f} | {speed:.3g} "
              f"| {speed / ref[2]:.3f}x |")
    if args.per_image:
        print("| image | " + " | ".join(r[0] for r in rows) + " |")
        for k, (nm, _) in enumerate(images):
            print(f"| {nm} | " + " | ".join(f"{r[3][k]:.2f}" for r in rows) + " |")


if __name__ == "__main__":
    main()
