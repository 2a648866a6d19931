"""Many textures at once, for build scripts and baking farms.

    jobs = plan(["art/"], "build/tex", recipe=Recipe.of(format="bc1"))
    report = run(jobs, "build/tex", workers=8)

`plan` turns files, folders and globs (or a manifest's rules) into jobs whose
outputs mirror the input folders under OUTDIR. `run` bakes the jobs that are
not up to date, in worker processes or on a Dask cluster, and returns a report.

Incremental: OUTDIR holds a small state file recording, for each output baked
successfully, the sha256 of its input's bytes, the recipe's digest and
texcook's version; a job whose three still match (and whose output is still
there) is skipped. Only the process calling `run` writes the state, atomically.

Failures stay with their file: a worker returns a failure for a bad input
instead of raising, and a worker process that dies (killed, out of memory)
fails only the job it was running; the batch goes on with a fresh pool.
Outputs are written by `pipeline.bake_file`, all-or-nothing.

This module imports nothing heavy at load time: worker processes import it
before their thread limit is set, and numba reads that limit when imported.
"""

import glob as globmod
import hashlib
import json
import os
import re
import signal
import time
from collections import deque
from dataclasses import dataclass
from functools import lru_cache

from . import __version__
from .errors import InputError, TexcookError, UsageError

STATE_NAME = ".texcook-batch.json"
STATE_VERSION = 1
SAVE_EVERY = 2.0  # seconds between state saves while a batch runs
WORKER_DIED = "worker process died (killed, or out of memory)"
UP_TO_DATE = "up to date"
FAILED_BEFORE = "failed before, unchanged"
# OpenImageIO plugins that are not image file formats
_NOT_IMAGES = {"null", "term", "zfile"}


@dataclass(frozen=True)
class Job:
    """One texture to bake: absolute paths, and `name`, the output's path under
    OUTDIR (the key in the state file and the report)."""

    src: str
    dst: str
    name: str
    recipe: object  # texcook.recipe.Recipe


# --- inputs ---------------------------------------------------------------------------


_EXTENSIONS = None


def image_extensions():
    """File extensions (lower case, no dot) of the image formats OpenImageIO reads."""
    global _EXTENSIONS
    if _EXTENSIONS is None:
        import OpenImageIO

        exts = set()
        for entry in OpenImageIO.get_string_attribute("extension_list").split(";"):
            plugin, _, names = entry.partition(":")
            if plugin not in _NOT_IMAGES:
                exts.update(n.lower() for n in names.split(",") if n)
        _EXTENSIONS = frozenset(exts)
    return _EXTENSIONS


def _is_image(path):
    return os.path.splitext(path)[1][1:].lower() in image_extensions()


def _inside(path, folder):
    return folder is not None and (path == folder or path.startswith(folder + os.sep))


def _walk(folder, skip):
    """Image files under `folder`, sorted, leaving out hidden files and `skip`."""
    for root, dirs, files in os.walk(folder):
        dirs[:] = sorted(d for d in dirs if not d.startswith(".")
                         and not _inside(os.path.realpath(os.path.join(root, d)), skip))
        for name in sorted(files):
            if not name.startswith(".") and _is_image(name):
                yield os.path.join(root, name)


def _glob_base(pattern):
    """The folder part of a glob before its first wildcard."""
    parts = pattern.replace(os.sep, "/").split("/")
    fixed = []
    for part in parts[:-1]:
        if globmod.has_magic(part):
            break
        fixed.append(part)
    return "/".join(fixed) or "."


def collect(inputs, exclude=None):
    """(absolute source, path relative to its input) for every input file.

    A folder gives every image under it (relative to the folder); a glob gives
    the images it matches (relative to its folder part before the first
    wildcard); a file is taken whatever its extension (relative: its name).
    Files under `exclude` (the output folder) are left out; a file named twice
    is taken once."""
    skip = None if exclude is None else os.path.realpath(exclude)
    seen, out = set(), []

    def add(path, rel):
        real = os.path.realpath(path)
        if real in seen or _inside(real, skip):
            return
        seen.add(real)
        out.append((os.path.abspath(path), rel.replace(os.sep, "/")))

    for given in inputs:
        given = os.fspath(given)
        if os.path.isdir(given):
            for path in _walk(given, skip):
                add(path, os.path.relpath(path, given))
        elif os.path.exists(given):
            add(given, os.path.basename(given))
        elif globmod.has_magic(given):
            base = _glob_base(given)
            matches = [p for p in sorted(globmod.glob(given, recursive=True))
                       if os.path.isfile(p) and _is_image(p)]
            if not matches:
                raise UsageError("matches no image file", given)
            for path in matches:
                add(path, os.path.relpath(path, base))
        else:
            raise InputError("no such file or folder", given)
    return out


# --- manifest rules -------------------------------------------------------------------


@lru_cache(maxsize=256)
def _pattern_regex(pattern):
    """A glob over '/'-separated relative paths: `*` and `?` stay within a folder,
    `**/` spans any number of folders, `[...]` is a character class."""
    out, i = [], 0
    while i < len(pattern):
        c = pattern[i]
        if pattern.startswith("**/", i):
            out.append("(?:.*/)?")
            i += 3
            continue
        if pattern.startswith("**", i):
            out.append(".*")
            i += 2
            continue
        if c == "*":
            out.append("[^/]*")
        elif c == "?":
            out.append("[^/]")
        elif c == "[":
            end = pattern.find("]", i + 2)
            if end < 0:
                out.append(re.escape(c))
            else:
                body = pattern[i + 1:end]
                if body.startswith("!"):
                    body = "^" + body[1:]
                out.append("[" + body.replace("\\", "\\\\") + "]")
                i = end
        else:
            out.append(re.escape(c))
        i += 1
    return re.compile("".join(out) + r"\Z")


@dataclass(frozen=True)
class Rule:
    """Files whose relative path matches `pattern` are baked with `recipe` into
    `container` (None: the batch's). A pattern without '/' matches the file
    name in any folder. `recipe` None leaves the matching files out."""

    pattern: str
    recipe: object = None
    container: str = None

    def matches(self, rel):
        target = rel if "/" in self.pattern else rel.rsplit("/", 1)[-1]
        return _pattern_regex(self.pattern).match(target) is not None


@dataclass(frozen=True)
class Manifest:
    path: str
    inputs: tuple  # files, folders or globs, resolved against the manifest's folder
    rules: tuple
    container: str = None


_RULE_KEYS = {"match", "container", "skip"}


def _merge(defaults, table):
    """Recipe parts of a rule over the defaults, one part at a time."""
    from .recipe import _PARTS

    merged = {k: v for k, v in defaults.items() if k not in _RULE_KEYS}
    for key, value in table.items():
        if key in _RULE_KEYS:
            continue
        if key in _PARTS and isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = {**merged[key], **value}
        else:
            merged[key] = value
    return merged


def _check_container(value, where):
    from .recipe import CONTAINERS

    if value is not None and value not in CONTAINERS:
        raise UsageError(f"{where}: container must be one of {', '.join(CONTAINERS)}, not {value!r}")
    return value


def load_manifest(path):
    """Read a TOML manifest: `inputs`, `container`, `[defaults]` (recipe parts every
    rule starts from) and `[[rules]]` (`match` pattern, recipe parts, optional
    `container`, `skip = true` to leave files out). First matching rule wins."""
    import tomllib

    from .recipe import Recipe

    path = os.fspath(path)
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except OSError as exc:
        raise InputError(f"cannot read manifest ({exc.strerror})", path) from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise UsageError(f"not a readable manifest ({str(exc).splitlines()[0]})", path) from None
    unknown = sorted(set(data) - {"inputs", "container", "defaults", "rules"})
    if unknown:
        raise UsageError(f"unknown manifest key(s) {', '.join(unknown)}; "
                         "keys are inputs, container, defaults, rules", path)
    here = os.path.dirname(os.path.abspath(path))
    inputs = data.get("inputs", ["."])
    if isinstance(inputs, str):
        inputs = [inputs]
    if not isinstance(inputs, list) or not all(isinstance(i, str) for i in inputs):
        raise UsageError("inputs must be a list of paths", path)
    defaults = data.get("defaults", {})
    rules_data = data.get("rules", [])
    if not isinstance(defaults, dict):
        raise UsageError("[defaults] must be a table of recipe parts", path)
    if not isinstance(rules_data, list) or not rules_data:
        raise UsageError("a manifest needs at least one [[rules]] table", path)
    container = _check_container(data.get("container"), path)
    rules = []
    for i, table in enumerate(rules_data, 1):
        where = f"{path}: rule {i}"
        if not isinstance(table, dict) or not isinstance(table.get("match"), str):
            raise UsageError(f"{where}: needs a match = \"pattern\"")
        if table.get("skip"):
            rules.append(Rule(table["match"]))
            continue
        try:
            recipe = Recipe.from_dict(_merge(defaults, table))
        except UsageError as exc:
            raise UsageError(f"{where} ({table['match']}): {exc}") from None
        rules.append(Rule(table["match"], recipe, _check_container(table.get("container"), where)))
    return Manifest(path, tuple(os.path.join(here, i) for i in inputs), tuple(rules), container)


# --- planning -------------------------------------------------------------------------


def plan(inputs, outdir, recipe=None, rules=None, container=None):
    """Jobs for every input: with `recipe` each file is baked with it; with
    `rules` (a Manifest or a list of Rule) the first rule matching the file's
    relative path gives its recipe (files no rule matches are left out).
    `container` ("ktx2" default, or "dds") is the extension of the outputs a
    rule does not set. Every recipe is checked against its container here,
    before any file is read."""
    from .recipe import Recipe

    if (recipe is None) == (rules is None):
        raise UsageError("give either a recipe or rules")
    if isinstance(rules, Manifest):
        container = container or rules.container
        rules = rules.rules
    container = _check_container(container, "--container") or "ktx2"
    if recipe is not None:
        if not isinstance(recipe, Recipe):
            raise UsageError("recipe must be a texcook.recipe.Recipe")
        rules = [Rule("**", recipe)]
    outdir = os.path.abspath(os.fspath(outdir))
    jobs, by_output, checked = [], {}, set()
    for src, rel in collect(inputs, exclude=outdir):
        rule = next((r for r in rules if r.matches(rel)), None)
        if rule is None or rule.recipe is None:
            continue
        kind = rule.container or container
        if (rule.recipe, kind) not in checked:
            rule.recipe.check_container(kind)
            checked.add((rule.recipe, kind))
        name = os.path.splitext(rel)[0] + "." + kind
        if name in by_output:
            raise UsageError(f"{by_output[name]} and {src} would both be baked to {name}")
        by_output[name] = src
        jobs.append(Job(src, os.path.join(outdir, *name.split("/")), name, rule.recipe))
    return jobs


# --- incremental state ----------------------------------------------------------------


def state_path(outdir):
    return os.path.join(os.fspath(outdir), STATE_NAME)


def load_state(outdir):
    """{output name: entry} from the last runs; empty when there is none or it is
    unreadable (everything is then baked again, which is safe)."""
    try:
        with open(state_path(outdir), "rb") as fh:
            data = json.load(fh)
    except (OSError, ValueError):
        return {}
    if not isinstance(data, dict) or data.get("version") != STATE_VERSION or not isinstance(data.get("files"), dict):
        return {}
    return data["files"]


def save_state(outdir, files):
    from .fileio import atomic_write

    data = {"version": STATE_VERSION, "files": files}
    atomic_write(state_path(outdir), (json.dumps(data, indent=1, sort_keys=True) + "\n").encode())


def file_sha256(path):
    """sha256 of a file's bytes, or None when it cannot be read (the bake then
    reports why)."""
    h = hashlib.sha256()
    try:
        with open(path, "rb") as fh:
            for chunk in iter(lambda: fh.read(1 << 20), b""):
                h.update(chunk)
    except OSError:
        return None
    return h.hexdigest()


def why(job, entry, sha, force=False, min_psnr=None, digest=None):
    """Why the job runs ("new", "changed", "recipe changed", "texcook changed",
    "output missing", "output changed", "PSNR not measured", "forced"), or why
    it does not: UP_TO_DATE, or FAILED_BEFORE (the input was refused and
    nothing that decides the outcome has changed since). `digest`: the job's
    recipe digest, when the caller has it already."""
    if force:
        return "forced"
    if entry is None:
        return "new"
    if entry.get("texcook") != __version__:
        return "texcook changed"
    if entry.get("recipe") != (digest or job.recipe.digest()):
        return "recipe changed"
    if sha is None or entry.get("sha256") != sha:
        return "changed"
    if entry.get("failed"):
        return FAILED_BEFORE
    try:
        size = os.path.getsize(job.dst)
    except OSError:
        return "output missing"
    if size != entry.get("bytes"):
        return "output changed"
    if min_psnr is not None and entry.get("psnr") is None:
        return "PSNR not measured"
    return UP_TO_DATE


# --- the work one job does (in a worker) ----------------------------------------------


def _init_worker(threads):
    """Process-pool worker start: a thread limit before numba loads, and SIGINT
    left to the parent (which stops the workers itself); SIGTERM unwinds so a
    temporary output file is removed."""
    os.environ["NUMBA_NUM_THREADS"] = str(threads)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _exit_on_term)


def _exit_on_term(signum, frame):
    raise SystemExit(128 + signum)


def _limit_threads(threads):
    import numba

    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))


def _one_line(exc):
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def measure_psnr(job, fmt, threads=1):
    """PSNR per level of the baked output against the same recipe baked
    uncompressed (so every mip level has a reference)."""
    import dataclasses
    import tempfile

    from . import formats
    from .pipeline import bake_file, compare
    from .recipe import CodecSettings

    ref_format = "rgba16f" if formats.get(fmt).is_float else "rgba8"
    recipe = job.recipe
    ref = dataclasses.replace(recipe, codec=CodecSettings(format=ref_format, preset=recipe.codec.preset),
                              output=dataclasses.replace(recipe.output, sat=False, zstd=None, dds_dx10=False))
    with tempfile.TemporaryDirectory(prefix="texcook-psnr-") as tmp:
        ref_path = os.path.join(tmp, "reference.ktx2")
        bake_file(job.src, ref_path, ref, threads=threads)
        result = compare(ref_path, job.dst)
    return [{"level": row["level"], "psnr": row["psnr"]} for row in result["levels"]]


def bake_job(job, threads=1, min_psnr=None):
    """Bake one job; never raises for a bad input. Returns a dict: status "baked"
    or "failed" (with a one-line reason), bytes, seconds, notes, and per-level
    PSNR when `min_psnr` is given."""
    t0 = time.perf_counter()
    _limit_threads(threads)
    try:
        from .pipeline import bake_file

        summary = bake_file(job.src, job.dst, job.recipe, threads=threads)
        out = {"status": "baked", "bytes": summary["bytes"], "format": summary["format"],
               "notes": summary["notes"]}
        if min_psnr is not None:
            out["levels"] = measure_psnr(job, summary["format"], threads)
            out["psnr"] = min(row["psnr"] for row in out["levels"])
    except (InputError, UsageError) as exc:  # the input itself: the same bytes fail the same way
        out = {"status": "failed", "reason": _reason(job, exc), "refused": True}
    except TexcookError as exc:  # an output error: may pass another time
        out = {"status": "failed", "reason": _reason(job, exc)}
    except MemoryError:
        out = {"status": "failed", "reason": f"{job.src}: out of memory"}
    except Exception as exc:  # a bug or an unforeseen library error: still this file's alone
        out = {"status": "failed", "reason": f"{job.src}: internal error: {type(exc).__name__}: {_one_line(exc)}"}
    out["seconds"] = round(time.perf_counter() - t0, 4)
    return out


def _reason(job, exc):
    """One line that names a file: the error's own, or else the input."""
    return _one_line(exc) if exc.path else f"{job.src}: {_one_line(exc)}"


def _failed(job, reason):
    return {"status": "failed", "reason": f"{job.src}: {reason}", "seconds": 0.0}


# --- backends: each yields (job, result) as jobs finish -------------------------------


def _run_processes(todo, workers, threads, min_psnr, worker_fn):
    """A spawn-context process pool. When a worker dies, every job that was in
    flight in that pool is run again alone in a fresh pool: the one that dies
    alone is the one that failed."""
    import concurrent.futures as cf
    import multiprocessing
    from concurrent.futures.process import BrokenProcessPool

    ctx = multiprocessing.get_context("spawn")
    queue, suspects = deque(todo), deque()
    inflight = {}  # future -> (job, ran alone)
    pool = None
    try:
        while queue or suspects or inflight:
            if pool is None:
                pool = cf.ProcessPoolExecutor(workers, mp_context=ctx, initializer=_init_worker,
                                              initargs=(threads,))
            alone = bool(suspects)
            source, limit = (suspects, 1) if alone else (queue, workers)
            while source and len(inflight) < limit:
                job = source.popleft()
                inflight[pool.submit(worker_fn, job, threads, min_psnr)] = (job, alone)
            done, _ = cf.wait(inflight, return_when=cf.FIRST_COMPLETED)
            broken = []
            for fut in done:
                job, was_alone = inflight.pop(fut)
                exc = fut.exception()
                if exc is None:
                    yield job, fut.result()
                elif isinstance(exc, BrokenProcessPool):
                    broken.append((job, was_alone))
                else:  # the result could not come back (pickling): this job's failure
                    yield job, _failed(job, f"internal error: {type(exc).__name__}: {_one_line(exc)}")
            if not broken:
                continue
            # the pool is gone: every job still in flight shares its fate
            pool.shutdown(wait=True, cancel_futures=True)
            pool = None
            for fut, (job, was_alone) in list(inflight.items()):
                if fut.done() and not fut.cancelled() and fut.exception() is None:
                    yield job, fut.result()
                else:
                    broken.append((job, was_alone))
            inflight.clear()
            for job, was_alone in broken:
                if was_alone:
                    yield job, _failed(job, WORKER_DIED)
                else:
                    suspects.append(job)
        if pool is not None:
            pool.shutdown(wait=True)
            pool = None
    finally:
        if pool is not None:
            # stopped early (SIGINT, an error in the caller): stop the workers now;
            # SIGTERM unwinds them, so no temporary output is left
            processes = list((getattr(pool, "_processes", None) or {}).values())
            pool.shutdown(wait=False, cancel_futures=True)
            for proc in processes:
                if proc.is_alive():
                    proc.terminate()
            for proc in processes:
                proc.join(5)


def _run_dask(todo, scheduler, workers, threads, min_psnr, worker_fn):
    """Jobs as tasks on a dask.distributed cluster: `scheduler` is an address, or
    None for a LocalCluster of `workers` processes on loopback. The scheduler
    runs a lost worker's tasks again elsewhere; a task that keeps killing its
    worker ends as KilledWorker and fails its file."""
    try:
        from distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise UsageError("the Dask backend needs dask.distributed: pip install 'texcook[dist]'") from None
    import logging
    import uuid

    cluster = None
    client = None
    futures = {}
    try:
        if scheduler is None:
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   host="127.0.0.1", dashboard_address=None, silence_logs=logging.ERROR,
                                   env={"NUMBA_NUM_THREADS": str(threads)})
            client = Client(cluster)
        else:
            try:
                client = Client(scheduler, timeout="20s")
            except (OSError, TimeoutError) as exc:
                raise UsageError(f"cannot reach the Dask scheduler {scheduler} ({_one_line(exc)})") from None
        batch = uuid.uuid4().hex[:8]
        for i, job in enumerate(todo):
            fut = client.submit(worker_fn, job, threads, min_psnr, key=f"texcook-bake-{batch}-{i}", pure=False)
            futures[fut] = job
        for fut in as_completed(list(futures)):
            job = futures.pop(fut)
            if fut.status == "finished":
                yield job, fut.result()
                continue
            if fut.status == "cancelled":  # the scheduler dropped it (restarted, or lost the client)
                yield job, _failed(job, "cancelled by the Dask scheduler")
                continue
            exc = fut.exception()
            if type(exc).__name__ == "KilledWorker":
                yield job, _failed(job, WORKER_DIED)
            else:
                yield job, _failed(job, f"internal error: {type(exc).__name__}: {_one_line(exc)}")
    finally:
        if client is not None:
            if futures:
                client.cancel(list(futures))
            client.close()
        if cluster is not None:
            cluster.close()


def default_workers():
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def _sweep_temporaries(folders, since):
    """Remove temporary outputs that a worker killed outright (SIGKILL, out of
    memory) could not clean up: those this batch's folders got since it began."""
    for folder in folders:
        try:
            names = os.listdir(folder)
        except OSError:
            continue
        for name in names:
            if name.startswith(".texcook-") and name.endswith(".tmp"):
                path = os.path.join(folder, name)
                try:
                    if os.path.getmtime(path) >= since:
                        os.unlink(path)
                except OSError:
                    pass


# --- the batch ------------------------------------------------------------------------


class Interrupted(KeyboardInterrupt):
    """SIGINT stopped the batch; `report` holds what finished (already recorded
    in the state file)."""

    def __init__(self, report):
        super().__init__("batch interrupted")
        self.report = report


def run(jobs, outdir, workers=None, backend="processes", scheduler=None, force=False, dry_run=False,
        min_psnr=None, progress=None, worker_fn=bake_job):
    """Bake the jobs that are not up to date and return a report (a dict).

    workers: processes (or LocalCluster workers) [default: every core]; each
    gets cores // workers numba threads (at least one). backend: "processes" or
    "dask" (with `scheduler` an address like tcp://host:8786, or None for a
    LocalCluster on loopback). force: bake everything. dry_run: bake nothing,
    say what would run and why. min_psnr: measure PSNR per level and count a
    file below it as failing. progress: called as progress(entry, count) after
    each job that ran, `count` being how many run in all. worker_fn: the
    function a worker calls, (job, threads, min_psnr) -> result like bake_job's.

    On SIGINT (KeyboardInterrupt) what finished is recorded and Interrupted is
    raised with the partial report."""
    if backend not in ("processes", "dask"):
        raise UsageError(f"unknown backend {backend!r}; choose processes or dask")
    if workers is not None and workers < 1:
        raise UsageError("workers must be at least 1")
    jobs = list(jobs)
    names = [job.name for job in jobs]
    if len(set(names)) != len(names):
        raise UsageError("two jobs write the same output")
    outdir = os.fspath(outdir)
    t0 = time.time()
    files = load_state(outdir)
    entries, todo, digests = [], [], {}
    for job in jobs:
        sha = file_sha256(job.src)
        if job.recipe not in digests:  # jobs share a few recipes; a digest serialises one
            digests[job.recipe] = job.recipe.digest()
        digest = digests[job.recipe]
        reason = why(job, files.get(job.name), sha, force, min_psnr, digest)
        entry = {"input": job.src, "output": job.dst, "name": job.name, "recipe": digest,
                 "why": reason, "sha256": sha}
        if reason == FAILED_BEFORE:
            entry.update(status="failed", reason=files[job.name]["failed"], seconds=0.0)
        elif reason == UP_TO_DATE:
            old = files[job.name]
            entry.update(status="skipped", bytes=old.get("bytes"), seconds=0.0)
            if old.get("psnr") is not None:
                entry.update(psnr=old["psnr"], levels=old.get("levels"))
        else:
            entry["status"] = "would bake" if dry_run else "pending"
            todo.append((job, entry))
        entries.append(entry)
    workers = min(workers or default_workers(), max(len(todo), 1))
    threads = max(1, default_workers() // workers)
    report = {"texcook": __version__, "outdir": os.path.abspath(outdir), "backend": backend,
              "workers": None if scheduler else workers,  # a remote cluster's are its own
              "dry_run": dry_run, "min_psnr": min_psnr, "ran": 0, "files": entries}
    if dry_run or not todo:
        return _finish(report, t0)

    os.makedirs(outdir, exist_ok=True)
    for job, _ in todo:
        os.makedirs(os.path.dirname(job.dst), exist_ok=True)
    by_name = {job.name: entry for job, entry in todo}
    if backend == "dask":
        stream = _run_dask([j for j, _ in todo], scheduler, workers, 1, min_psnr, worker_fn)
    else:
        stream = _run_processes([j for j, _ in todo], workers, threads, min_psnr, worker_fn)
    last_save = time.monotonic()
    folders = {os.path.dirname(j.dst) for j, _ in todo}
    try:
        for job, result in stream:
            entry = by_name[job.name]
            refused = result.pop("refused", False)
            entry.update(result)
            if result["status"] == "baked":
                entry["passed"] = min_psnr is None or result["psnr"] >= min_psnr
                if entry["passed"]:
                    files[job.name] = _state_entry(job, entry)
                else:
                    files.pop(job.name, None)
            elif refused:
                files[job.name] = _state_entry(job, entry)
            else:
                files.pop(job.name, None)
            report["ran"] += 1
            if progress is not None:
                progress(entry, len(todo))
            if time.monotonic() - last_save >= SAVE_EVERY:
                save_state(outdir, files)
                last_save = time.monotonic()
    except KeyboardInterrupt:
        stream.close()
        save_state(outdir, files)
        _sweep_temporaries(folders, t0)
        for entry in entries:
            if entry["status"] == "pending":
                entry["status"] = "interrupted"
        raise Interrupted(_finish(report, t0)) from None
    save_state(outdir, files)
    _sweep_temporaries(folders, t0)
    return _finish(report, t0)


def _state_entry(job, entry):
    out = {"input": job.src, "sha256": entry["sha256"], "recipe": entry["recipe"], "texcook": __version__}
    if entry["status"] == "failed":
        out["failed"] = entry["reason"]
        return out
    out["bytes"] = entry["bytes"]
    if entry.get("psnr") is not None:
        out.update(psnr=entry["psnr"], levels=entry["levels"])
    return out


def _finish(report, t0):
    counts = {"baked": 0, "skipped": 0, "failed": 0, "below_min_psnr": 0, "would bake": 0, "interrupted": 0}
    for entry in report["files"]:
        counts[entry["status"]] = counts.get(entry["status"], 0) + 1
        if report["min_psnr"] is not None and entry["status"] == "skipped":
            entry["passed"] = entry.get("psnr") is not None and entry["psnr"] >= report["min_psnr"]
        if entry.get("passed") is False:
            counts["below_min_psnr"] += 1
    report["counts"] = {k: v for k, v in counts.items() if v or k in ("baked", "skipped", "failed")}
    report["seconds"] = round(time.time() - t0, 3)
    report["ok"] = counts["failed"] == 0 and counts["below_min_psnr"] == 0 and counts["interrupted"] == 0
    return report


def summary_line(report):
    """One line for people: counts, time and rate."""
    c = report["counts"]
    secs = report["seconds"]
    if report["dry_run"]:
        return f"dry run: {c.get('would bake', 0)} to bake, {c['skipped']} up to date"
    ran = report["ran"]
    rate = f", {ran / secs:.1f} files/s" if ran and secs > 0 else ""
    below = f", {c['below_min_psnr']} below {report['min_psnr']} dB" if report["min_psnr"] is not None else ""
    stopped = f", {c['interrupted']} not run (interrupted)" if c.get("interrupted") else ""
    return (f"batch: {c['baked']} baked, {c['skipped']} skipped, {c['failed']} failed{below}{stopped} "
            f"in {secs:.1f} s{rate}")
