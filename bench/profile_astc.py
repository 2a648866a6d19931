"""Where the ASTC search spends its time: a sampling profile by function.

    python bench/profile_astc.py [--size 6x6] [--preset fast] [--seconds 5] [--set corpus|photo|generated|FOLDER]
                                 [--field column=value ...]

numba's compiled code has no symbols a profiler can read. This compiles the
search afresh (a temporary numba cache, so the code is made in this process),
writes the address of every function in the kernel's library to
/tmp/perf-PID.map (the file `perf` reads for code made at run time), then runs
the search over the corpus's blocks while `perf record` (Linux perf, for this
tool only) samples the process, and prints the share of samples per function.
A helper numba inlined counts in its caller's share.
"""

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time

os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="texcook-profile-")

import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_astc import crop, load_corpus  # noqa: E402
from bench_astc_outside import SETS  # noqa: E402

from texcook.codecs._base import image_to_blocks  # noqa: E402
from texcook.codecs.astc import presets, search  # noqa: E402


def write_perf_map(dispatcher):
    """Every function of the dispatcher's compiled library into perf's map for
    this process; a function's size is taken as the gap to the next one."""
    library = dispatcher.overloads[dispatcher.signatures[0]].library
    names = re.findall(r'^define [^@]*@"?([^"(]+)', library.get_llvm_str(), re.M)
    found = sorted((library.get_pointer_to_function(n), n) for n in names)
    found = [(a, n) for a, n in found if a]
    with open(f"/tmp/perf-{os.getpid()}.map", "w") as f:
        for k, (address, name) in enumerate(found):
            size = found[k + 1][0] - address if k + 1 < len(found) else 0x10000
            short = re.sub(r"^_ZN.*?search\d+|B\d+.*$", "", name)  # drop the mangling
            f.write(f"{address:x} {size:x} {short}\n")
    return len(found)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="6x6")
    ap.add_argument("--preset", default="fast")
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--field", action="append", default=[], help="column=value: the preset's record with "
                    "this column changed (repeatable), to see what a part of the search costs")
    ap.add_argument("--set", default="corpus", help=f"the images: {', '.join(sorted(SETS))} (bench_astc_outside's "
                    "sets) or a folder laid out like the corpus")
    args = ap.parse_args()
    if shutil.which("perf") is None:
        sys.exit("profile_astc: needs Linux perf (Debian: linux-perf)")
    bw, bh = (int(v) for v in args.size.split("x"))
    images = SETS[args.set]() if args.set in SETS else load_corpus(args.set)
    blocks = np.concatenate([image_to_blocks(crop(img, bw, bh), bw, bh) for _, _, img in images])
    rec = presets.record(bw, bh, args.preset)
    for field in args.field:
        name, value = field.split("=")
        rec[name] = int(value)
    call = (blocks, np.zeros((blocks.shape[0], search.SYM_LEN), np.int32), rec,
            presets.mode_mask(bw, bh, args.preset), np.ones(4), np.int64(0), search.kernel_tables(bw, bh))
    t0 = time.perf_counter()
    search.search(*[a[:4] if i < 2 else a for i, a in enumerate(call)])
    print(f"compiled in {time.perf_counter() - t0:.1f} s; {write_perf_map(search.search_kernel)} functions mapped")
    data = os.path.join(os.environ["NUMBA_CACHE_DIR"], "perf.data")
    done = threading.Event()

    def run():
        while not done.is_set():
            search.search(*call)

    worker = threading.Thread(target=run)
    worker.start()
    time.sleep(0.5)
    subprocess.run(["perf", "record", "-q", "-F", "2000", "-p", str(os.getpid()), "-o", data, "--",
                    "sleep", str(args.seconds)], check=True, stdout=subprocess.DEVNULL)
    done.set()
    worker.join()
    report = subprocess.run(["perf", "report", "-i", data, "--no-children", "--sort", "symbol",
                             "--stdio", "-q"], capture_output=True, text=True, check=True).stdout
    for line in report.splitlines()[:25]:
        if line.strip():
            print(line.rstrip()[:100])
    os.remove(f"/tmp/perf-{os.getpid()}.map")
    shutil.rmtree(os.environ["NUMBA_CACHE_DIR"], ignore_errors=True)


if __name__ == "__main__":
    main()
