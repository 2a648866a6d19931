"""Whole-bake figures: `texcook bake` as a user runs it (one process per bake),
against nvcompress where it does the same job, plus start-up, peak memory and
what a second thread buys.

    python bench/bench_bake.py [--repeat 3] [--skip-cold] [--only peers,startup,memory,threads]

- a 2048x2048 photograph-like texture built from the corpus (nine 256x256
  photographs upscaled to 512x512 with OpenImageIO's default filter and
  tiled 4x4, written to a temporary PNG);
- `texcook bake --format bc1 --preset fast` (full mip chain) against
  `nvcompress -bc1`, and `--preset fastest` against `nvcompress -bc1 -fast`,
  warm numba cache, best of --repeat runs of the whole process; level-0 PSNR
  (RGB, against the source) of both, each decoded by texcook's BC1 decoder;
- warm-cache 256x256 bakes (rgba8, bc1) and cold-cache ones (bc1, etc1: a
  fresh NUMBA_CACHE_DIR, so every kernel the bake needs is compiled), also
  with TEXCOOK_COMPILE_BESIDE=0 (no helper process compiling the mip chain's
  kernels beside the codec's);
- peak resident memory of a 4096x4096 RGBA rgba8 bake with mips, against the
  size of level 0 as float32 RGBA;
- 1 and 2 threads for the encoders, the colour conversion (the texture, and
  the texture with an alpha ramp) and the mip chain with each filter on the
  2048x2048 texture, and the chain as a bake of an 8-bit source builds it
  (level 1 filtered from the stored values, colour decoding included),
  in-process, best of --repeat, with the process's CPU
  time and the load average when each row began: other jobs on the cores take
  the second thread's core away, which the first control row shows; the
  second shows what a second thread gives a pass that only writes memory.

nvcompress is NVIDIA Texture Tools' command-line tool; Debian packages it as
`libnvtt-bin` (apt-get install libnvtt-bin), used here only as a peer. Without
it the comparison rows are skipped.
"""

import argparse
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
CORPUS = ROOT / "corpus"


def texcook_cmd():
    exe = shutil.which("texcook")
    return [exe] if exe else [sys.executable, "-m", "texcook.cli"]


def make_photo(path, size=2048):
    """The 2048x2048 photograph-like RGB texture (see the module docstring)."""
    import OpenImageIO as oiio

    from texcook.image import write_image

    srcs = sorted((CORPUS / "rgb").glob("ldr-rgb-0[1-9].png"))
    tile = size // 4
    tiles = []
    for p in srcs:
        buf = oiio.ImageBufAlgo.resize(oiio.ImageBuf(str(p)), roi=oiio.ROI(0, tile, 0, tile, 0, 1, 0, 3))
        tiles.append(np.asarray(buf.get_pixels(oiio.UINT8)))
    rows = []
    for y in range(4):
        row = []
        for x in range(4):
            k = y * 4 + x
            t = tiles[k % len(tiles)]
            row.append(t if k < len(tiles) else t[:, ::-1])  # mirrored repeats
        rows.append(np.concatenate(row, axis=1))
    write_image(path, np.ascontiguousarray(np.concatenate(rows, axis=0)))


def make_rgba(path, size=4096):
    """A 4096x4096 RGBA texture: the photograph upscaled, alpha a diagonal ramp."""
    import OpenImageIO as oiio

    from texcook.image import write_image

    with tempfile.TemporaryDirectory() as tmp:
        small = os.path.join(tmp, "p.png")
        make_photo(small, size // 2)
        buf = oiio.ImageBufAlgo.resize(oiio.ImageBuf(small), roi=oiio.ROI(0, size, 0, size, 0, 1, 0, 3))
        rgb = np.asarray(buf.get_pixels(oiio.UINT8))
    a = ((np.add.outer(np.arange(size), np.arange(size)) // 16) % 256).astype(np.uint8)
    write_image(path, np.ascontiguousarray(np.dstack([rgb, a])))


# Linux carries a process's peak resident size across exec, and a child made by
# fork or vfork starts from its parent's: timed straight from this process
# (which holds the test images) every child would report this process's peak.
# So each command runs as the grandchild of a small launcher, whose own peak
# (about 10 MiB) is all a fresh fork can inherit, and the launcher reports it.
_LAUNCHER = """import os, sys, time
start = time.perf_counter()
pid = os.fork()
if pid == 0:
    os.execvp(sys.argv[2], sys.argv[2:])
_, status, usage = os.wait4(pid, 0)
elapsed = time.perf_counter() - start
with open(sys.argv[1], "w") as f:
    f.write(f"{elapsed} {usage.ru_maxrss} {usage.ru_utime + usage.ru_stime}")
sys.exit(os.waitstatus_to_exitcode(status))
"""


def run(cmd, env=None):
    """(wall seconds, peak resident KiB, CPU seconds) of one process; raises if
    it fails. CPU time (user + system) is the steadier figure on a busy machine.
    All three are the command's own, taken by the launcher."""
    env = dict(os.environ if env is None else env)
    # an installed package keeps its compiled bytecode; timing every run's
    # recompilation of the sources (about 0.05 s) would not be what users see
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    with tempfile.NamedTemporaryFile("r", suffix=".usage") as usage:
        proc = subprocess.run([sys.executable, "-c", _LAUNCHER, usage.name, *map(str, cmd)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
        if proc.returncode != 0:
            err = proc.stderr.decode(errors="replace").strip()
            raise RuntimeError(f"{' '.join(map(str, cmd))} failed: {err}")
        elapsed, kib, cpu = usage.read().split()
    return float(elapsed), int(kib), float(cpu)


def best(cmd, repeat, env=None):
    """(best wall seconds, best CPU seconds) of `repeat` runs."""
    runs = [run(cmd, env) for _ in range(repeat)]
    return min(r[0] for r in runs), min(r[2] for r in runs)


def level0_psnr(texture, source):
    from texcook import metrics
    from texcook.image import read_image
    from texcook.pipeline import load_texture

    ref = read_image(source).integer_values()[..., :3]
    got = load_texture(texture).levels[0][..., :3]
    return metrics.psnr(got, ref, 255.0)


def bake_cmd(src, dst, fmt, *extra):
    return texcook_cmd() + ["bake", str(src), "-o", str(dst), "--format", fmt, *extra]


def against_nvcompress(tmp, photo, repeat, rows):
    nv = shutil.which("nvcompress")
    pairs = (("fast", ["-bc1"]), ("fastest", ["-bc1", "-fast"]))
    for preset, nv_args in pairs:
        ours = tmp / f"photo-{preset}.ktx2"
        run(bake_cmd(photo, ours, "bc1", "--preset", preset))  # warm the cache
        t_ours, cpu_ours = best(bake_cmd(photo, ours, "bc1", "--preset", preset), repeat)
        row = {"what": f"2048x2048 bc1 --preset {preset}, mips", "texcook s": t_ours, "cpu s": cpu_ours,
               "texcook PSNR": level0_psnr(ours, photo)}
        if nv:
            theirs = tmp / f"photo-nv-{preset}.dds"
            cmd = [nv, "-nocuda", *nv_args, str(photo), str(theirs)]
            row["peer"] = "nvcompress " + " ".join(nv_args)
            row["peer s"], row["peer cpu s"] = best(cmd, repeat)
            row["peer PSNR"] = level0_psnr(theirs, photo)
            row["ratio"] = t_ours / row["peer s"]
        rows.append(row)


def startup(tmp, repeat, cold, rows):
    small = CORPUS / "rgb" / "ldr-rgb-01.png"
    out = tmp / "small.ktx2"
    for fmt in ("rgba8", "bc1"):
        run(bake_cmd(small, out, fmt))
        wall, cpu = best(bake_cmd(small, out, fmt), repeat)
        rows.append({"what": f"256x256 {fmt}, warm cache", "texcook s": wall, "cpu s": cpu})
    if cold:
        for fmt in ("bc1", "etc1"):
            # as a user runs it, and without the helper that compiles the
            # chain's kernels beside the codec's (what a one-core machine gets)
            for helper in ("1", "0"):
                runs = []
                for _ in range(min(repeat, 2)):
                    env = dict(os.environ, NUMBA_CACHE_DIR=tempfile.mkdtemp(dir=tmp), TEXCOOK_COMPILE_BESIDE=helper)
                    runs.append(run(bake_cmd(small, out, fmt), env))
                rows.append({"what": f"256x256 {fmt}, cold cache" + ("" if helper == "1" else ", no helper"),
                             "texcook s": min(r[0] for r in runs), "cpu s": min(r[2] for r in runs)})


def memory(tmp, rows):
    big = tmp / "rgba4096.png"
    make_rgba(big)
    out = tmp / "big.ktx2"
    run(bake_cmd(big, out, "rgba8"))  # warm
    _, kib, _ = run(bake_cmd(big, out, "rgba8"))
    level0 = 4096 * 4096 * 4 * 4
    rows.append({"what": "4096x4096 RGBA rgba8, mips: peak RSS", "MiB": kib / 1024,
                 "x level 0 float32": kib * 1024 / level0})


def threads(photo, repeat, rows):
    from texcook import codecs
    from texcook.colour import StoredRGBA, quantize, to_linear_rgba
    from texcook.image import read_image
    from texcook.mips import build_chain

    stored = read_image(photo).stored
    h, w, _ = stored.shape
    ramp = ((np.add.outer(np.arange(h), np.arange(w)) // 16) % 256).astype(np.uint8)
    stored_rgba = np.ascontiguousarray(np.dstack([stored, ramp]))  # the photograph with an alpha ramp
    linear = to_linear_rgba(stored, True, None)
    level0 = quantize(linear, True)

    def timed(fn):
        """Best (wall, CPU) of `repeat` runs on 1 and on 2 threads, taken in
        turn so that both see the same machine. CPU time is the whole
        process's user + system time: about the wall time when only one core
        worked, up to twice it when two did."""
        fn(1)  # compile or load
        fn(2)
        runs = {1: [], 2: []}
        for _ in range(repeat):
            for n in (1, 2):
                runs[n].append(_clock(fn, n))
        return min(runs[1]), min(runs[2])

    jobs = [
        ("colour: sRGB 8-bit RGB -> linear RGBA", lambda n: to_linear_rgba(stored, True, None, threads=n)),
        ("colour: sRGB 8-bit RGBA -> linear RGBA", lambda n: to_linear_rgba(stored_rgba, True, 3, threads=n)),
        ("colour: linear -> sRGB 8-bit", lambda n: quantize(linear, True, threads=n)),
    ]
    for f in ("box", "triangle", "lanczos", "kaiser"):
        # as a bake of an 8-bit source builds it: its values are known to be in [0, 1]
        jobs.append((f"mips: {f} chain", lambda n, f=f: build_chain(linear, filter=f, alpha_channel=3, threads=n,
                                                                     unit_range=True)))
    for f in ("box", "lanczos"):
        # what a bake of the 8-bit texture runs: its level 0 is encoded from the stored values
        jobs.append((f"colour + mips: {f} chain from 8-bit sRGB",
                     lambda n, f=f: build_chain(StoredRGBA(stored, True, None), filter=f, alpha_channel=3, threads=n)))
    for fmt, preset in (("bc1", "fast"), ("bc1", "fastest"), ("bc3", "fast"), ("etc1", "fastest")):
        codec = codecs.get(fmt)
        jobs.append((f"encode {fmt} {preset}", lambda n, c=codec, p=preset: c.encode(level0, p, threads=n)))
    # controls: what a second thread can give on this machine right now, to
    # work that only computes and to work that only writes memory
    jobs.append(("control: independent busy loops", _busy_loops))
    jobs.append(("control: fill 64 MiB of fresh memory", _fill_fresh))
    for name, fn in jobs:
        load = os.getloadavg()[0]
        (t1, c1), (t2, c2) = timed(fn)
        what = name if name.startswith("control") else f"2048x2048 {name}"
        rows.append({"what": what, "1 thread ms": t1 * 1e3, "1 thread cpu ms": c1 * 1e3, "2 threads ms": t2 * 1e3,
                     "2 threads cpu ms": c2 * 1e3, "speed-up": t1 / t2, "load": load})


def _burn(k):
    s = 0.0
    for i in range(k):
        s += (i % 7) * 0.5
    return s


_jitted = {}


def _busy_loops(n):
    """Two independent nogil loops, on n threads of the shared pool."""
    from texcook._jit import jit
    from texcook._threads import parallel_for

    burn = _jitted.setdefault("burn", jit(_burn, cache=False))
    parallel_for(lambda a, b: [burn(50_000_000) for _ in range(a, b)], 2, n)


def _fill(out, v):
    for i in range(out.shape[0]):
        out[i] = v


def _fill_fresh(n):
    """A 2048x2048 float32 RGBA array (what the sRGB decode writes) allocated
    and filled in chunks of rows on n threads: the memory-bound floor of a
    pass that writes a new full-size level."""
    from texcook._jit import jit
    from texcook._threads import parallel_for

    fill = _jitted.setdefault("fill", jit(_fill, cache=False))
    out = np.empty((2048, 2048 * 4), np.float32)
    parallel_for(lambda a, b: fill(out[a:b].reshape(-1), np.float32(0.5)), 2048, n, 8)


def _clock(fn, n):
    """(wall, CPU of the whole process) seconds of fn(n)."""
    t, c = time.perf_counter(), time.process_time()
    fn(n)
    return time.perf_counter() - t, time.process_time() - c


def show(rows):
    for r in rows:
        parts = [f"{r['what']:<48}"]
        for k, v in r.items():
            if k == "what":
                continue
            parts.append(f"{k} {v:.1f}" if k == "load" else f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}")
        print("  ".join(parts), flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--skip-cold", action="store_true")
    ap.add_argument("--only", default="peers,startup,memory,threads", help="sections to run, comma-separated")
    args = ap.parse_args()
    print(f"{os.cpu_count()} cores; texcook: {' '.join(texcook_cmd())}; nvcompress: {shutil.which('nvcompress')}")
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = pathlib.Path(tmpdir)
        photo = tmp / "photo2048.png"
        make_photo(photo)
        sections = {
            "peers": ("whole process, warm cache, best of runs",
                      lambda rows: against_nvcompress(tmp, photo, args.repeat, rows)),
            "startup": ("start-up", lambda rows: startup(tmp, args.repeat, not args.skip_cold, rows)),
            "memory": ("peak memory", lambda rows: memory(tmp, rows)),
            "threads": ("threads (in-process)", lambda rows: threads(photo, args.repeat, rows)),
        }
        for key in args.only.split(","):
            title, fn = sections[key]
            print(f"\n{title}")
            rows = []
            fn(rows)
            show(rows)


if __name__ == "__main__":
    main()
