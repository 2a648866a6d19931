"""Batch throughput: N textures baked by one `texcook batch` against N
`texcook bake` calls in a shell loop (start-up paid once per file).

    python bench/bench_batch.py              # 200 textures of 256x256 to bc1
    python bench/bench_batch.py --count 50 --size 512 --format bc4

Prints both wall times, the ratio, and checks the two give the same bytes.
"""

import argparse
import os
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from texcook.image import write_image  # noqa: E402


def make_sources(folder, count, size, seed=7):
    """Smooth gradients with noise and a few shapes: texture-like, not all noise."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size].astype(np.float32) / size
    paths = []
    for i in range(count):
        a, b, c = rng.uniform(0.5, 6.0, 3)
        rgb = np.stack([np.sin(a * x + b * y), np.cos(b * x - c * y), np.sin(c * (x + y))], -1) * 0.4 + 0.5
        rgb += rng.normal(0.0, 0.04, rgb.shape)
        cx, cy, r = rng.uniform(0.2, 0.8, 3) * (1, 1, 0.3)
        rgb[(x - cx) ** 2 + (y - cy) ** 2 < r * r] = rng.uniform(0, 1, 3)
        path = folder / f"tex{i:04d}.png"
        write_image(path, np.clip(rgb * 255 + 0.5, 0, 255).astype(np.uint8))
        paths.append(path)
    return paths


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--count", type=int, default=200)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--format", default="bc1")
    ap.add_argument("--jobs", type=int, default=None, help="texcook batch --jobs [default: all cores]")
    args = ap.parse_args()
    texcook = [sys.executable, "-m", "texcook.cli"]
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    with tempfile.TemporaryDirectory(prefix="texcook-bench-batch-") as tmp:
        tmp = Path(tmp)
        src, loop_out, batch_out = tmp / "src", tmp / "loop", tmp / "batch"
        for d in (src, loop_out, batch_out):
            d.mkdir()
        paths = make_sources(src, args.count, args.size)
        # warm the kernel cache so neither side pays a cold compile
        subprocess.run(texcook + ["bake", str(paths[0]), "-o", str(tmp / "warm.ktx2"), "-f", args.format],
                       env=env, check=True, capture_output=True)

        bake = " ".join(shlex.quote(a) for a in texcook)
        script = (f'for f in {shlex.quote(str(src))}/*.png; do n=$(basename "$f" .png); '
                  f'{bake} bake "$f" -o {shlex.quote(str(loop_out))}/"$n".ktx2 -f {args.format} >/dev/null || exit 1; done')
        t0 = time.perf_counter()
        subprocess.run(["bash", "-c", script], env=env, check=True)
        loop = time.perf_counter() - t0

        cmd = texcook + ["batch", str(src), "-o", str(batch_out), "-f", args.format]
        if args.jobs:
            cmd += ["--jobs", str(args.jobs)]
        t0 = time.perf_counter()
        done = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True)
        batched = time.perf_counter() - t0

        t0 = time.perf_counter()
        again = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True)
        rerun = time.perf_counter() - t0

        same = all((loop_out / p.name).read_bytes() == (batch_out / p.name).read_bytes()
                   for p in sorted(batch_out.glob("*.ktx2")))
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
        print(f"{args.count} textures {args.size}x{args.size} to {args.format} on {cores} cores "
              f"(load average {os.getloadavg()[0]:.1f})")
        print(f"shell loop of texcook bake: {loop:.1f} s ({loop / args.count * 1000:.0f} ms/file)")
        print(f"texcook batch:              {batched:.1f} s ({batched / args.count * 1000:.0f} ms/file)  "
              f"{done.stdout.strip()}")
        print(f"texcook batch again:        {rerun:.2f} s  {again.stdout.strip()}")
        print(f"speed-up: {loop / batched:.1f}x; identical outputs: {same}")


if __name__ == "__main__":
    main()
