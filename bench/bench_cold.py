"""What a first bake of each format spends compiling kernels: the source of
each codec's `compile_seconds` (docs/performance.md, "First use").

    python bench/bench_cold.py [FORMAT ...] [--after-prepare]

For each format, `texcook bake corpus/rgb/ldr-rgb-00.png -f FORMAT` (256x256)
as its own process into a fresh NUMBA_CACHE_DIR (cold), then again with that
cache (warm). Printed per format: wall time, the bake process's own CPU time,
and the CPU time of the helpers it starts to compile beside it (texcook._beside:
the mip chain's kernels, and for ASTC part of the search's and the packing's
when a core is idle), cold and warm, and cold minus warm. On a machine shared
with other work the wall time stretches with the load; the bake's own CPU
time is what an idle machine would wait (the helpers run on the other core).
--after-prepare: `texcook prepare FORMAT` into the fresh cache first, so the
"cold" bake shows what is left to compile after it, and how long it took.
The bakes run the texcook of the tree this script is in: to compare two
trees, run each one's own script, in turns.
"""

import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
SOURCE = ROOT / "corpus" / "rgb" / "ldr-rgb-00.png"
FORMATS = ("rgba8", "bc1", "bc3", "bc4", "bc5", "bc3-ycocg", "bc6h", "bc7", "etc1", "etc2", "eac-r11", "eac-rg11",
           "etc2a8", "astc-6x6")

# runs the CLI in-process, then writes its own and its reaped children's CPU seconds
CHILD = """
import json, resource, sys
from texcook.cli import cli
try:
    cli.main(sys.argv[2:], standalone_mode=False)
finally:
    own, helpers = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    with open(sys.argv[1], "w") as f:
        json.dump([own.ru_utime + own.ru_stime, helpers.ru_utime + helpers.ru_stime], f)
"""


def run(args, cache, tmp):
    """(wall, own CPU, helpers' CPU) seconds of one texcook command."""
    figures = os.path.join(tmp, "cpu.json")
    t = time.perf_counter()
    # run from this tree's root: `-c` puts the working folder first on the path, so the bake is this tree's
    # texcook wherever the benchmark was started from (another tree's, to compare, is that tree's script)
    subprocess.run([sys.executable, "-c", CHILD, figures, *args], env=dict(os.environ, NUMBA_CACHE_DIR=cache),
                   cwd=ROOT, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t
    with open(figures) as f:
        return (wall, *json.load(f))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("formats", nargs="*", default=FORMATS)
    ap.add_argument("--after-prepare", action="store_true")
    opts = ap.parse_args()
    print("| format | cold wall s | warm wall s | cold CPU s (helper) | warm CPU s | compiling: wall s | CPU s |"
          + (" prepare wall s (CPU) |" if opts.after_prepare else "") + " load |")
    print("|---" * (9 if opts.after_prepare else 8) + "|")
    for fmt in opts.formats:
        with tempfile.TemporaryDirectory() as tmp:
            cache, out = os.path.join(tmp, "cache"), os.path.join(tmp, "out.ktx2")
            bake = ["bake", str(SOURCE), "-o", out, "-f", fmt]
            load = os.getloadavg()[0]
            prepared = run(["prepare", fmt], cache, tmp) if opts.after_prepare else None
            cold = run(bake, cache, tmp)
            warm = run(bake, cache, tmp)
        row = (f"| {fmt} | {cold[0]:.2f} | {warm[0]:.2f} | {cold[1]:.2f} ({cold[2]:.2f}) | {warm[1]:.2f} | "
               f"{cold[0] - warm[0]:.1f} | {cold[1] - warm[1]:.1f} |")
        if prepared:
            row += f" {prepared[0]:.1f} ({prepared[1] + prepared[2]:.1f}) |"
        print(row + f" {load:.1f} |", flush=True)


if __name__ == "__main__":
    main()
