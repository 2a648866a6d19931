"""One pool of worker threads for the whole process, shared by every stage that
splits its work (colour conversion, mip filtering, block encoding).

Work is split into chunks that write disjoint parts of the output, so the
result is the same bytes for any thread count. The kernels are jitted with
nogil, so the threads run in parallel.
"""

import itertools
import os
import threading
from concurrent.futures import ThreadPoolExecutor

from .errors import UsageError

_pool = None
_pool_size = 0
_lock = threading.Lock()
_local = threading.local()


def cpu_threads(threads):
    """The thread count to use: every core for None."""
    if threads is None:
        return os.cpu_count() or 1
    if threads < 1:
        raise UsageError(f"threads must be at least 1, not {threads}")
    return int(threads)


def _get_pool(workers):
    global _pool, _pool_size
    with _lock:
        if _pool is None or _pool_size < workers:
            if _pool is not None:
                _pool.shutdown(wait=False)
            _pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="texcook")
            _pool_size = workers
        return _pool


def split(n, threads, min_chunk):
    """Chunk bounds [(a, b), ...] over range(n): a few chunks per thread, each at
    least min_chunk long, so chunks of unequal cost even out."""
    threads = cpu_threads(threads)
    chunks = max(1, min(threads * 4, n // max(1, min_chunk)))
    if threads == 1:
        chunks = 1
    step, extra = divmod(n, chunks)
    bounds, a = [], 0
    for i in range(chunks):
        b = a + step + (1 if i < extra else 0)
        if b > a:
            bounds.append((a, b))
        a = b
    return bounds


def parallel_for(fn, n, threads=None, min_chunk=1):
    """Call fn(a, b) over chunks of range(n) on at most `threads` threads: the
    calling thread and threads - 1 of the shared pool. Returns when all are
    done and re-raises the first error."""
    bounds = split(n, threads, min_chunk)
    counter = itertools.count()

    def take(stop):
        # each worker takes the next chunk until none is left
        while not stop:
            i = next(counter)
            if i >= len(bounds):
                return
            fn(*bounds[i])

    run_workers(take, min(cpu_threads(threads), len(bounds)))


def run_workers(work, workers):
    """Run work(stop) on the calling thread and on workers - 1 threads of the
    shared pool; `stop` is a list that is non-empty once any of them failed
    (or the caller was interrupted), so a worker takes no new piece of work
    after that. Returns when every worker is done and re-raises the first
    error. Inside a worker (of this or any other call) it runs work here
    alone: waiting on the pool from the pool could wait for ever."""
    stop = []
    if workers <= 1 or getattr(_local, "in_pool", False):
        work(stop)
        return

    def worker():
        _local.in_pool = True
        try:
            work(stop)
        except BaseException:
            stop.append(True)
            raise
        finally:
            _local.in_pool = False

    # the caller works too: one thread fewer to wake, and no idle thread waiting
    pool = _get_pool(workers - 1)
    futures = [pool.submit(worker) for _ in range(workers - 1)]
    error = None
    try:
        worker()
    except BaseException as exc:  # the pool's workers still write into the caller's arrays: wait for them
        error = exc
    try:
        for f in futures:
            try:
                f.result()
            except Exception as exc:
                error = error or exc
    except BaseException:  # interrupted while waiting
        stop.append(True)
        raise
    if error is not None:
        raise error


def stop_process_pool(pool):
    """Stop a concurrent.futures process pool's workers now (a run stopped by
    Ctrl-C or an error): queued work is cancelled and running workers are
    terminated (SIGTERM, which lets them unwind) and waited for."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in processes:
        if proc.is_alive():
            proc.terminate()
    for proc in processes:
        proc.join(5)
