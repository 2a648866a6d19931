"""BC4 and BC5 `fastest` against quicktex (and etcpak) on the bundled corpus and
on images outside it, single thread, CPU time of the thread (time.thread_time:
the machine is shared), each encoder's best of --repeat runs per image.

    python bench/bench_bc45.py [--set corpus|photo|both] [--repeat N] [--per-image]

- corpus: BC4 on the alpha of corpus/rgba (as `texcook bench` scores it),
  BC5 on corpus/normal.
- photo: from matplotlib's sample data, none of it in the corpus: BC4 on the
  alpha of the photograph cut out by a soft-edged ellipse, of the RGBA
  drawing and of the logo, on the photograph's luminance and on two
  elevation maps as 8-bit height; BC5 on tangent-space normal maps made from
  those elevation maps and from the photograph's luminance as a bump map.

Speed is the whole encode call as a user makes it (texcook's codec.encode on
an RGBA array; quicktex's encoder on a RawTexture made from the same bytes,
as `texcook bench` times it), summed over the set; `x quicktex` is quicktex's
time over ours. PSNR is the mean of each image's PSNR over the channels the
format stores (BC4: one, BC5: X and Y), or the pooled PSNR of the set where an
image comes back exactly, as `texcook bench` reports it.
"""

import argparse
import glob
import os
import time

import numpy as np
from PIL import Image

from texcook import codecs
from texcook.bench import etcpak_encoder
from texcook.metrics import psnr

CORPUS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "corpus")


def _crop(img):
    h, w = img.shape[0] // 4 * 4, img.shape[1] // 4 * 4
    return np.ascontiguousarray(img[:h, :w])


def _plane(v):
    """One 8-bit channel in all four, as `texcook bench` feeds BC4."""
    v = np.clip(np.asarray(v, np.float64) + 0.5, 0, 255).astype(np.uint8)
    return _crop(np.repeat(v[..., None], 4, axis=2))


def _normals(height, strength):
    """A tangent-space normal map (X, Y in R, G; Z in B) of a height field."""
    gy, gx = np.gradient(np.asarray(height, np.float64) * strength)
    n = np.stack([-gx, -gy, np.ones_like(gx)], axis=2)
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    out = np.full(n.shape[:2] + (4,), 255, np.uint8)
    out[..., :3] = np.clip((n * 0.5 + 0.5) * 255 + 0.5, 0, 255)
    return _crop(out)


def _unit(x):
    x = np.asarray(x, np.float64)
    return (x - x.min()) / (x.max() - x.min())


def corpus():
    def load(path):
        return np.asarray(Image.open(path).convert("RGBA"))

    bc4 = [(os.path.basename(p), _plane(load(p)[..., 3])) for p in sorted(glob.glob(f"{CORPUS}/rgba/*.png"))]
    bc5 = [(os.path.basename(p), _crop(load(p))) for p in sorted(glob.glob(f"{CORPUS}/normal/*.png"))]
    return bc4, bc5


def photo():
    import matplotlib.cbook as cb

    def sample(name):
        return cb.get_sample_data(name, asfileobj=False)

    grace = np.asarray(Image.open(sample("grace_hopper.jpg")).convert("RGB"), np.float64)
    luma = grace @ np.array([0.299, 0.587, 0.114])
    h, w = luma.shape
    yy, xx = np.mgrid[0:h, 0:w]
    r = np.sqrt(((yy - h * 0.45) / (h * 0.4)) ** 2 + ((xx - w * 0.5) / (w * 0.3)) ** 2)
    ellipse = np.clip((1 - r) * 12, 0, 1) * 255
    drawing = np.asarray(Image.open(sample("Minduka_Present_Blue_Pack.png")).convert("RGBA"))
    logo = np.asarray(Image.open(sample("logo2.png")).convert("RGBA"))
    dem = _unit(np.load(sample("jacksboro_fault_dem.npz"))["elevation"])
    topo = np.load(sample("topobathy.npz"))["topo"]
    # four times larger, bilinear: a smooth height field of a useful size
    topo = np.asarray(Image.fromarray(_unit(topo).astype(np.float32)).resize(
        (topo.shape[1] * 4, topo.shape[0] * 4), Image.BILINEAR), np.float64)
    bc4 = [("grace-cutout alpha", _plane(ellipse)), ("drawing alpha", _plane(drawing[..., 3])),
           ("logo alpha", _plane(logo[..., 3])), ("grace luminance", _plane(luma)),
           ("dem height", _plane(dem * 255)), ("topobathy height", _plane(topo * 255))]
    bc5 = [("dem normals", _normals(dem, 60.0)), ("topobathy normals", _normals(topo, 40.0)),
           ("grace bump normals", _normals(luma / 255, 4.0))]
    return bc4, bc5


SETS = {"corpus": corpus, "photo": photo}


def encoders(fmt):
    import quicktex
    import quicktex.s3tc.bc4 as qb4
    import quicktex.s3tc.bc5 as qb5

    codec = codecs.get(fmt)
    enc = qb4.BC4Encoder(0) if fmt == "bc4" else qb5.BC5Encoder(0, 1)

    def qt(img):
        return enc.encode(quicktex.RawTexture.frombytes(img.tobytes(), img.shape[1], img.shape[0])).tobytes()

    out = [("texcook fastest", lambda img: codec.encode(img, "fastest", threads=1)), ("quicktex", qt)]
    run = etcpak_encoder(fmt)
    if run is not None:
        out.append(("etcpak", lambda img: bytes(run(img))))
    return codec, out


def set_psnr(scores, errors):
    """The mean of the images' PSNRs, or where an image came back exactly (an
    infinite PSNR) the PSNR of the set's pooled squared error, as `texcook
    bench` reports it."""
    if all(np.isfinite(scores)):
        return float(np.mean(scores))
    se, n = map(sum, zip(*errors))
    return float(10 * np.log10(255.0 ** 2 * n / se))


def measure(fmt, images, repeat):
    """{encoder: (seconds, [psnr per image], set psnr)}."""
    codec, encs = encoders(fmt)
    chans = [0] if fmt == "bc4" else [0, 1]
    for _, enc in encs:
        enc(images[0][1][:8, :8].copy())  # load or compile, untimed
    best = {name: [np.inf] * len(images) for name, _ in encs}
    scores = {}
    for _ in range(max(1, repeat)):
        for name, enc in encs:
            s, e = [], []
            for k, (_, img) in enumerate(images):
                t0 = time.thread_time()
                data = enc(img)
                best[name][k] = min(best[name][k], time.thread_time() - t0)
                dec = codec.decode(data, img.shape[1], img.shape[0])
                s.append(psnr(img[..., chans], dec[..., chans]))
                diff = img[..., chans].astype(np.int64) - dec[..., chans]
                e.append((int((diff * diff).sum()), diff.size))
            scores[name] = s, set_psnr(s, e)
    return {name: (sum(best[name]), *scores[name]) for name, _ in encs}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--set", default="both", choices=["both", *SETS])
    ap.add_argument("--repeat", type=int, default=20)
    ap.add_argument("--per-image", action="store_true", help="also print each image's PSNR")
    args = ap.parse_args()
    for name in SETS if args.set == "both" else [args.set]:
        bc4, bc5 = SETS[name]()
        for fmt, images in (("bc4", bc4), ("bc5", bc5)):
            mpix = sum(img.shape[0] * img.shape[1] for _, img in images) / 1e6
            print(f"\n{name} {fmt}: " + ", ".join(n for n, _ in images) + f" ({mpix:.2f} Mpix)")
            print("| encoder | PSNR dB | Mpix/s 1 thread | x quicktex |")
            print("|---|---|---|---|")
            res = measure(fmt, images, args.repeat)
            ref = res["quicktex"][0]
            for enc, (t, s, total) in res.items():
                print(f"| {enc} | {total:.4f} | {mpix / t:.0f} | {ref / t:.2f} |", flush=True)
                if args.per_image:
                    print("    " + "  ".join(f"{n} {v:.3f}" for (n, _), v in zip(images, s)))


if __name__ == "__main__":
    main()
