"""BC1/BC3/BC4/BC5 quality and speed against the peers installed here.

    python bench/bench_bc.py [--formats bc1,bc3,bc4,bc5] [--presets fastest,fast,...] [--corpus DIR]

Quality: every image decoded by texture2ddecoder (not our decoder), images
cropped to a multiple of 4. BC1: mean per-image RGB PSNR on corpus rgb/ and
rgba/; BC5: mean per-image PSNR of R and G on normal/ (plus mean angular error
in degrees); BC4 and BC3: PSNR of the alpha of rgba/ over the whole set
(pooled squared error, since one image comes back exactly; BC4 encodes the
alpha from the red channel). Speed:
single-threaded megapixels per second, best of --reps runs per image (one for
the slowest presets), the peers timed in the same process after an untimed
warm-up call. Prints one table.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from texcook import codecs  # noqa: E402
from texcook.metrics import mse, normal_angular_error, psnr  # noqa: E402


def load(folder):
    """Corpus images as RGBA uint8 with straight alpha (as stored in the file),
    cropped to a multiple of 4."""
    from texcook.image import read_image
    from texcook.pipeline import _to_rgba

    out = []
    for p in sorted(folder.glob("*.png")):
        img = read_image(p)
        px = np.rint(_to_rgba(img.pixels, False) * 255.0).astype(np.uint8)
        h, w = px.shape[0] // 4 * 4, px.shape[1] // 4 * 4
        out.append((p.name, np.ascontiguousarray(px[:h, :w])))
    return out


def t2d_decode(fmt, data, w, h):
    import texture2ddecoder as t2d

    fn = {"bc1": t2d.decode_bc1, "bc3": t2d.decode_bc3, "bc4": t2d.decode_bc4, "bc5": t2d.decode_bc5}[fmt]
    bgra = np.frombuffer(fn(bytes(data), w, h), np.uint8).reshape(h, w, 4)
    return bgra[:, :, [2, 1, 0, 3]]


def timed(fn, reps):
    best = 1e30
    res = None
    for _ in range(reps):
        t = time.perf_counter()
        res = fn()
        best = min(best, time.perf_counter() - t)
    return res, best


# ---- peers ----------------------------------------------------------------

def peers(fmt):
    out = []
    try:
        import quicktex
        import quicktex.s3tc.bc1 as qb1
        import quicktex.s3tc.bc3 as qb3
        import quicktex.s3tc.bc4 as qb4
        import quicktex.s3tc.bc5 as qb5

        def qt(enc):
            def run(img):
                h, w = img.shape[:2]
                tex = quicktex.RawTexture.frombytes(img.tobytes(), w, h)
                return enc.encode(tex).tobytes()
            return run

        if fmt == "bc1":
            for lvl in (0, 5, 10, 18):
                out.append((f"quicktex {lvl}", qt(qb1.BC1Encoder(lvl))))
        elif fmt == "bc3":
            out.append(("quicktex 5", qt(qb3.BC3Encoder(5))))
        elif fmt == "bc4":
            out.append(("quicktex", qt(qb4.BC4Encoder(3))))  # channel 3: alpha
        elif fmt == "bc5":
            out.append(("quicktex", qt(qb5.BC5Encoder(0, 1))))
    except ImportError:
        pass
    try:
        import etcpak

        def ep(fn):
            def run(img):
                h, w = img.shape[:2]
                return fn(img.tobytes(), w, h)
            return run

        if fmt == "bc1":
            out.append(("etcpak", ep(etcpak.compress_bc1)))
        elif fmt == "bc3":
            out.append(("etcpak", ep(etcpak.compress_bc3)))
        elif fmt == "bc5":
            out.append(("etcpak", ep(etcpak.compress_bc5)))
    except ImportError:
        pass
    return out


# ---- measures --------------------------------------------------------------

def measure(fmt, images, encode, reps):
    """(mean PSNR, mean angular error or None, Mpix/s)."""
    ps = []
    angs = []
    secs = 0.0
    pix = 0
    for _, img in images:
        h, w = img.shape[:2]
        src = img
        if fmt == "bc4":
            src = np.ascontiguousarray(np.repeat(img[:, :, 3:4], 4, axis=2))
        data, t = timed(lambda: encode(src), reps)
        secs += t
        pix += w * h
        dec = t2d_decode(fmt, data, w, h)
        if fmt == "bc1":
            ps.append(psnr(img[:, :, :3], dec[:, :, :3]))
        elif fmt == "bc5":
            ps.append(psnr(img[:, :, :2], dec[:, :, :2]))
            angs.append(normal_angular_error(img[:, :, :2], dec[:, :, :2])[0])
        elif fmt in ("bc3", "bc4"):
            got = dec[:, :, 0] if fmt == "bc4" else dec[:, :, 3]
            ps.append(mse(img[:, :, 3], got))
    if fmt in ("bc3", "bc4"):
        # one alpha image is reproduced exactly by every encoder (infinite PSNR):
        # alpha is scored on the whole set's pooled squared error instead
        q = float(10.0 * np.log10(255.0**2 / max(np.mean(ps), 1e-12)))
    else:
        q = float(np.mean(ps))
    return q, (float(np.mean(angs)) if angs else None), pix / secs / 1e6


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--formats", default="bc1,bc3,bc4,bc5")
    ap.add_argument("--presets", default="fastest,fast,medium,thorough,exhaustive")
    ap.add_argument("--corpus", default=str(ROOT / "corpus"))
    ap.add_argument("--reps", type=int, default=3, help="timing runs per image (best kept)")
    ap.add_argument("--no-peers", action="store_true")
    args = ap.parse_args(argv)
    corpus = Path(args.corpus)
    sets = {
        "bc1": load(corpus / "rgb") + load(corpus / "rgba"),
        "bc3": load(corpus / "rgba"),
        "bc4": load(corpus / "rgba"),
        "bc5": load(corpus / "normal"),
    }
    what = {"bc1": "RGB", "bc3": "alpha", "bc4": "alpha", "bc5": "RG (normal/)"}
    rows = []
    for fmt in args.formats.split(","):
        images = sets[fmt]
        codec = codecs.get(fmt)
        # compile outside the timings
        codec.encode(images[0][1][:8, :8], "fastest", threads=1)
        for preset in args.presets.split(","):
            reps = 1 if preset in ("thorough", "exhaustive") else args.reps
            p, a, mp = measure(fmt, images, lambda im: codec.encode(im, preset, threads=1), reps)
            rows.append((fmt, what[fmt], f"texcook {preset}", p, a, mp))
            print(rows[-1], file=sys.stderr, flush=True)
        if not args.no_peers:
            for name, fn in peers(fmt):
                slow = name.endswith(" 18") or name.endswith(" 10")
                # an untimed first call, as texcook gets its compile: a peer's
                # first encode in a process pays one-off set-up costs
                src = images[0][1][:64, :64]
                fn(np.ascontiguousarray(np.repeat(src[:, :, 3:4], 4, axis=2)) if fmt == "bc4" else src.copy())
                p, a, mp = measure(fmt, images, fn, 1 if slow else args.reps)
                rows.append((fmt, what[fmt], name, p, a, mp))
                print(rows[-1], file=sys.stderr, flush=True)
    print("| format | measured on | encoder | PSNR dB | mean angle deg | Mpix/s |")
    print("|---|---|---|---|---|---|")
    for fmt, on, name, p, a, mp in rows:
        ang = f"{a:.3f}" if a is not None else ""
        print(f"| {fmt} | {on} | {name} | {p:.2f} | {ang} | {mp:.3g} |")


if __name__ == "__main__":
    main()
