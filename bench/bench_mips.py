"""Full mip chain of a 4096x4096 RGBA float image: texcook vs OpenImageIO.

Both run single-threaded in the same process on the same image, each level
filtered from the level above (OpenImageIO's ImageBufAlgo.resize per level):
texcook box vs "box", lanczos vs "lanczos3", kaiser vs "blackman-harris"
(OpenImageIO has no Kaiser filter). Prints the best of --repeat runs and the
ratio; the machine is shared, so the ratio is the figure to read.

    python bench/bench_mips.py [--size 4096] [--repeat 3]
    python bench/bench_mips.py --design   # the measurements behind docs/mips.md
"""

import argparse
import time

import numpy as np

PAIRS = (("box", "box"), ("lanczos", "lanczos3"), ("kaiser", "blackman-harris"))



def _unassociated(oiio):
    """Read PNG alpha as stored: OpenImageIO premultiplies colour by default."""
    cfg = oiio.ImageSpec()
    cfg.attribute("oiio:UnassociatedAlpha", 1)
    return cfg

def oiio_chain(src_buf, filtername, sizes, oiio):
    cur = src_buf
    for w, h in sizes[1:]:
        cur = oiio.ImageBufAlgo.resize(cur, filtername=filtername, roi=oiio.ROI(0, w, 0, h, 0, 1, 0, 4), nthreads=1)
        if cur.has_error:
            raise RuntimeError(cur.geterror())
    return cur


def best_time(fn, repeat):
    best = float("inf")
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def _load_corpus():
    from pathlib import Path

    import OpenImageIO as oiio

    from texcook.colour import srgb_to_linear

    root = Path(__file__).resolve().parent.parent / "corpus"
    for path in sorted((root / "rgb").glob("*.png")) + sorted((root / "rgba").glob("*.png")):
        px = oiio.ImageBuf(str(path), 0, 0, _unassociated(oiio)).get_pixels(oiio.FLOAT).copy()
        px[..., :3] = srgb_to_linear(px[..., :3])
        yield path.name, np.ascontiguousarray(px, np.float32)


def design():
    """Figures for the design choices: frequency response of the filters at 2:1,
    cascaded vs direct-from-level-0 chains, and what clamping does to the mean."""
    from texcook.mips import build_chain, chain_sizes, resample, tap_table

    print("Filters at 2:1 (response H at f cycles per source texel; output Nyquist is 1/4)")
    print(f"{'filter':<24}{'taps':>5}{'min H f<=1/8':>14}{'H(1/4)':>8}{'max|H| f>=3/8':>15}{'step overshoot':>16}")
    f = np.linspace(0.0, 0.5, 4001)
    rows = [("box", {}), ("triangle", {}), ("lanczos", dict(lanczos_a=2)), ("lanczos", {}), ("lanczos", dict(lanczos_a=4))]
    rows += [("kaiser", dict(kaiser_width=w, kaiser_alpha=a)) for w, a in ((2, 4), (3, 2), (3, 4), (3, 6), (4, 4))]
    for name, opts in rows:
        idx, wts = tap_table(64, 32, name, "repeat", **opts)
        taps = wts[10].astype(np.float64)
        j = idx[10].astype(np.float64)
        j = np.where(j < j[0], j + 64, j)  # undo the wrap: contiguous source positions
        offsets = j + 0.5 - 21.0
        h = (taps[None, :] * np.cos(2 * np.pi * f[:, None] * offsets[None, :])).sum(axis=1)
        step = np.cumsum(taps)
        overshoot = max(step.max() - 1.0, -step.min())
        label = name + ("" if not opts else " " + ",".join(f"{k.split('_')[1]}={v}" for k, v in opts.items()))
        print(f"{label:<24}{len(taps):>5}{h[f <= 0.125].min():>14.4f}{h[np.argmin(abs(f - 0.25))]:>8.4f}"
              f"{np.abs(h[f >= 0.375]).max():>15.4f}{overshoot:>16.4f}")

    print("\nCascaded chain (each level from the one above) against each level filtered from level 0")
    print(f"{'filter':<10}{'worst PSNR dB':>14}{'mean PSNR dB':>14}   (linear light, peak 1, corpus rgb+rgba)")
    corpus = list(_load_corpus())
    for name in ("box", "triangle", "lanczos", "kaiser"):
        psnrs = []
        for _, img in corpus:
            cascade = build_chain(img, filter=name, clamp=False, ldr=False)
            for k, (w, h) in enumerate(chain_sizes(img.shape[1], img.shape[0])[1:], 1):
                if w * h < 16:
                    continue
                direct = resample(img, w, h, filter=name)
                mse = float(np.mean((cascade[k].astype(np.float64) - direct) ** 2))
                psnrs.append(99.0 if mse == 0 else 10 * np.log10(1.0 / mse))
        print(f"{name:<10}{min(psnrs):>14.1f}{np.mean(psnrs):>14.1f}")
    n = 1024
    img = np.random.default_rng(3).random((n, n, 4), dtype=np.float32)
    for name in ("box", "lanczos", "kaiser"):
        t = time.perf_counter()
        build_chain(img, filter=name)
        t_cascade = time.perf_counter() - t
        t = time.perf_counter()
        for w, h in chain_sizes(n, n)[1:]:
            resample(img, w, h, filter=name)
        t_direct = time.perf_counter() - t
        print(f"{name:<10} {n}x{n} RGBA chain: cascaded {t_cascade:.3f} s, from level 0 {t_direct:.3f} s")

    print("\nWorst change of a level's mean against level 0 (percent of the channel mean, channels with mean >= 0.01)")
    print(f"{'filter':<10}{'unclamped':>10}{'clamped':>10}   image of the clamped worst")
    for name in ("box", "triangle", "lanczos", "kaiser"):
        worst = {True: (0.0, ""), False: (0.0, "")}
        for fname, img in corpus:
            for clamp in (True, False):
                levels = build_chain(img, filter=name, clamp=clamp)
                m0 = levels[0].reshape(-1, img.shape[2]).astype(np.float64).mean(axis=0)
                ok = m0 >= 0.01
                for lv in levels[1:]:
                    m = lv.reshape(-1, img.shape[2]).astype(np.float64).mean(axis=0)
                    rel = float(np.max(np.abs(m[ok] / m0[ok] - 1.0))) * 100
                    if rel > worst[clamp][0]:
                        worst[clamp] = (rel, fname)
        print(f"{name:<10}{worst[False][0]:>9.3f}%{worst[True][0]:>9.3f}%   {worst[True][1]}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=4096)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--design", action="store_true", help="print the design measurements instead")
    args = parser.parse_args()
    if args.design:
        design()
        return

    import OpenImageIO as oiio

    from texcook.mips import build_chain, chain_sizes

    oiio.attribute("threads", 1)
    n = args.size
    rng = np.random.default_rng(7)
    # Smooth structure plus noise: a realistic mix of low and high frequencies.
    y, x = np.mgrid[0:n, 0:n].astype(np.float32) / n
    base = 0.5 + 0.25 * np.sin(2 * np.pi * (7 * x + 3 * y))[..., None]
    img = np.clip(base + 0.25 * rng.standard_normal((n, n, 4), dtype=np.float32), 0.0, 1.0).astype(np.float32)
    img = np.ascontiguousarray(img)
    sizes = chain_sizes(n, n)

    spec = oiio.ImageSpec(n, n, 4, oiio.FLOAT)
    src_buf = oiio.ImageBuf(spec)
    src_buf.set_pixels(oiio.ROI(), img)

    build_chain(img[:64, :64], filter="box")  # load / compile the kernels outside the timing
    for f in ("lanczos", "kaiser"):
        build_chain(img[:64, :64], filter=f)

    print(f"{n}x{n} RGBA float32, {len(sizes) - 1} levels below level 0, single-threaded, best of {args.repeat}")
    print(f"{'texcook':<10} {'seconds':>8}   {'OpenImageIO':<16} {'seconds':>8}   {'speed-up':>8}")
    for ours, theirs in PAIRS:
        t_ours = best_time(lambda: build_chain(img, filter=ours), args.repeat)
        t_oiio = best_time(lambda: oiio_chain(src_buf, theirs, sizes, oiio), args.repeat)
        print(f"{ours:<10} {t_ours:8.3f}   {theirs:<16} {t_oiio:8.3f}   {t_oiio / t_ours:7.1f}x")


if __name__ == "__main__":
    main()
