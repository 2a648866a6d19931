"""Compiling the kernels of formats ahead of time: `texcook prepare`.

A kernel compiles into numba's disk cache the first time it runs, so a first
bake of a format waits for its codec's kernels (seconds to a minute, the
codec's `compile_seconds`). Preparing runs each named format's encoder, with
every preset and every on/off option, and its decoder on a small sample, so
that every kernel they reach is compiled and saved; and one small default
bake, for the colour and mip kernels every bake runs. numba compiles one
function at a time per process, so the work is split by codec module (the
unit whose kernels a codec compiles) over processes, one per core, the
slowest modules first, each followed by its codec's compile_beside job where
it has one (ASTC: what the search's kernel calls), which another process runs
meanwhile; they share the cache on disk, under its locks (texcook._jit).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

from . import codecs
from ._threads import stop_process_pool
from .errors import UsageError


@dataclass
class Prepared:
    module: str  # the codec module, e.g. texcook.codecs.bc1
    formats: list  # the named formats it encodes
    seconds: float  # wall time of its job in its worker process
    cpu_seconds: float  # that process's CPU time for the job
    beside: bool = False  # the job compiling part of the module's kernels beside its own job


def jobs(format_names=None):
    """{codec module: [format names]} of the formats named (None or ["all"]:
    every encodable format), slowest to compile first by the codecs' declared
    figures. An unknown format is a UsageError."""
    names = list(format_names or ["all"])
    if names == ["all"]:
        names = codecs.names()
    out = {}
    for n in names:
        fmt = codecs.get(n).format  # a UsageError for an unknown format or one without an encoder here
        out.setdefault(fmt.codec_module, [])
        if fmt.name not in out[fmt.codec_module]:
            out[fmt.codec_module].append(fmt.name)
    order = sorted(out, key=lambda m: -codecs.get(out[m][0]).compile_seconds)
    return {m: out[m] for m in order}


def _sample(codec):
    """Two blocks by two of noise, the values each kind of input takes (signed
    floats for a signed HDR format), so no search is skipped as it would be
    for flat blocks."""
    import numpy as np

    rng = np.random.default_rng(7)
    shape = (2 * codec.block_h, 2 * codec.block_w, 4)
    if codec.float_input:
        low = 0.0 if codec.format.unsigned_float else -2.0
        return rng.uniform(low, 4.0, shape).astype(np.float32)
    return rng.integers(0, 256, shape, dtype=np.uint8)


def _variants(codec):
    """The option sets a bake may call the encoder with that reach other
    kernels: the defaults, and each on/off option turned the other way."""
    out = [{}]
    for option in codec.options:
        if option.type == "bool":
            out.append({option.name: not option.default})
    return out


def prepare_module(names):
    """Run the encoders of `names` (formats of one codec module) with every
    preset and option variant, and their decoders, in this process: their
    kernels end up in the disk cache."""
    for name in names:
        codec = codecs.get(name)
        sample = _sample(codec)
        h, w = sample.shape[:2]
        for preset in codec.presets:
            for options in _variants(codec):
                try:
                    data = codec.encode(sample, preset, threads=1, **options)
                except UsageError:  # an option that needs another one set (angular without normal_map)
                    continue
        for kwargs in ({}, {"srgb": True}) if codec.srgb_decode else ({},):
            codec.decode(data, w, h, **kwargs)


def _timed(fn, *args):
    """fn(*args) in a worker process: (wall, CPU) seconds it took there."""
    wall, cpu = time.perf_counter(), time.process_time()
    fn(*args)
    return time.perf_counter() - wall, time.process_time() - cpu


def job_list(format_names=None):
    """[(module, formats, beside)] in the order prepare() submits them: each
    codec module's job (jobs()), right after it the job of its first format's
    compile_beside where it has one (beside: that (function, arguments), else
    None), which the next free process runs meanwhile, then BAKE's."""
    out = []
    for module, names in dict(jobs(format_names), **{BAKE: []}).items():
        out.append((module, names, None))
        beside = codecs.get(names[0]).compile_beside if names else None
        if beside is not None:
            out.append((module, names, beside))
    return out


BAKE = "texcook.pipeline"  # the job that compiles a bake's own kernels


def prepare_bake():
    """A default bake of a small 8-bit RGBA PNG to rgba8 in this process: the
    colour conversion, the mip chain and the container's kernels, which every
    first bake compiles besides its codec's."""
    import tempfile

    import numpy as np

    from .image import write_image
    from .pipeline import bake_file
    from .recipe import Recipe

    os.environ["TEXCOOK_COMPILE_BESIDE"] = "0"  # this is the process compiling beside the others
    with tempfile.TemporaryDirectory() as tmp:
        src = os.path.join(tmp, "sample.png")
        write_image(src, np.random.default_rng(7).integers(0, 256, (64, 64, 4), dtype=np.uint8))
        bake_file(src, os.path.join(tmp, "sample.ktx2"), Recipe.of(format="rgba8"))


def prepare(format_names=None, processes=None, done=None, started=None):
    """Compile the kernels of the formats named (None or ["all"]: every one)
    into the disk cache, one codec module per job on `processes` worker
    processes (default one per core). `started(jobs, processes)` is called
    before the work starts ({module: formats}, with BAKE's job), `done(Prepared)`
    as each job finishes. Returns ([Prepared] in the order they finished,
    total wall seconds)."""
    import concurrent.futures as cf
    import multiprocessing

    todo = job_list(format_names)  # the bake's own kernels last: about a second
    start = time.perf_counter()
    workers = max(1, min(processes or os.cpu_count() or 1, len(todo)))
    if started is not None:
        started({module: names for module, names, _ in todo}, workers)
    # spawn: a worker must not inherit a half-loaded numba or the thread pool
    pool = cf.ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"))
    out = []
    try:
        futures = {}
        for job in todo:
            module, names, beside = job
            # a codec's compile_beside is (function, arguments); else the module's or the bake's own job
            fn, args = beside or ((prepare_module, (names,)) if names else (prepare_bake, ()))
            futures[pool.submit(_timed, fn, *args)] = job
        for fut in cf.as_completed(futures):
            wall, cpu = fut.result()
            module, names, beside = futures[fut]
            out.append(Prepared(module, names, wall, cpu, beside is not None))
            if done is not None:
                done(out[-1])
        pool.shutdown(wait=True)
    finally:
        # stopped early (Ctrl-C, a failed job): stop the workers now
        stop_process_pool(pool)
    return out, time.perf_counter() - start
