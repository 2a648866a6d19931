"""Many textures at once, for build scripts and baking farms.

    jobs = plan(["art/"], "build/tex", recipe=Recipe.of(format="bc1"))
    report = run(jobs, "build/tex", workers=8)

`plan` turns files, folders and globs (or a manifest's rules) into jobs whose
outputs mirror the input folders under OUTDIR. `run` bakes the jobs that are
not up to date, in worker processes or on a Dask cluster, and returns a report.

Incremental: OUTDIR holds a small state file recording, for each output baked
successfully, the sha256 of the input bytes the worker baked (hashed in the
worker before and after the bake), the recipe's digest and texcook's version;
a job whose three still match (and whose output is still there) is skipped.
Only the process calling `run` writes the state, atomically, and only while it
holds the folder's lock (one run per OUTDIR at a time).

Outputs stay inside OUTDIR: output names never climb out of it, and every
output folder is checked by real path before anything is written there.

Failures stay with their file: a worker returns a failure for a bad input
instead of raising, and a worker process that dies (killed, out of memory)
fails only the job it was running; the batch goes on with a fresh pool.
Outputs are written by `pipeline.bake_file`, all-or-nothing. Workers end
with the process that started them, SIGKILL included.

This module imports nothing heavy at load time: worker processes import it
before their thread limit is set, and numba reads that limit when imported.
"""

import contextlib
import glob as globmod
import hashlib
import json
import os
import re
import signal
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass, field, replace
from functools import lru_cache

from . import __version__
from ._threads import stop_process_pool
from .choices import DEFAULT_CONTAINER
from .errors import InputError, OutputError, TexcookError, UsageError
from .fileio import (TEMP_MARK, TEMP_SUFFIX, check_regular, format_size, is_temp_name, lock, max_memory, read_bytes,
                     sweep_stale)

STATE_NAME = ".texcook-batch.json"
LOCK_NAME = ".texcook-batch.lock"  # flock'ed by the run that owns OUTDIR; the kernel drops it on death
STATE_VERSION = 1
SAVE_EVERY = 2.0  # seconds between state saves while a batch runs
WORKER_DIED = "worker process died (killed, or out of memory)"
UP_TO_DATE = "up to date"
FAILED_BEFORE = "failed before, unchanged"
CHANGED_WHILE_BAKED = "changed while it was being baked; it is baked again on the next run"
# A worker process's own footprint (Python, NumPy, numba, OpenImageIO, the kernels):
# a whole `texcook bake` of a 96x96 PNG peaks at 172 MiB resident, click and the
# command included; each worker also holds the working size of the input it bakes.
WORKER_BYTES = 160 << 20
# Names that say "tangent-space normal map" in most art pipelines.
_NORMAL_NAME = re.compile(r"([_\-.](n|nm|nrm|norm|normal|normals|normalmap)|^(normal|normals|normalmap))$",
                          re.IGNORECASE)
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
    # the input's sha256 when the run decided to bake it (None: not read yet):
    # the worker's first bake needs no hash of its own taken before it
    sha256: str | None = None


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


def _inside_output(given, skip):
    """UsageError when an input is the output folder or inside it: its files
    could not be told from outputs, and the folder walk leaves them out."""
    real = os.path.realpath(given)
    if _inside(real, skip):
        where = "is the output folder" if real == skip else f"is inside the output folder {skip}"
        raise UsageError(f"{where}, whose files are outputs, not inputs; choose an output folder outside "
                         "the inputs", given)


def collect(inputs, exclude=None):
    """(absolute source, path relative to its input) for every input file.

    A folder gives every image under it (relative to the folder); a glob gives
    the images it matches (relative to its folder part before the first
    wildcard); a file is taken whatever its extension (relative: its name), if
    it is a regular file. Files under `exclude` (the output folder) are left
    out, and an input that is that folder or inside it is refused; a file
    named twice is taken once. A glob match that is not under the glob's
    folder part (`..` after a wildcard) is refused: its output would leave the
    output folder."""
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
            _inside_output(given, skip)
            for path in _walk(given, skip):
                add(path, os.path.relpath(path, given))
        elif os.path.lexists(given):
            check_regular(given)  # a FIFO or a device is refused before anything reads it
            _inside_output(given, skip)
            add(given, os.path.basename(given))
        elif globmod.has_magic(given):
            base = _glob_base(given)
            if os.path.isdir(base):
                _inside_output(base, skip)
            matches = [p for p in sorted(globmod.glob(given, recursive=True))
                       if os.path.isfile(p) and _is_image(p)]
            if not matches:
                raise UsageError("matches no image file", given)
            for path in matches:
                rel = os.path.relpath(path, base)
                if rel == os.pardir or rel.startswith(os.pardir + os.sep) or os.path.isabs(rel):
                    raise UsageError(f"matches {path}, outside the pattern's folder {base} ('..' after a "
                                     "wildcard): its output would be written outside the output folder", given)
                add(path, rel)
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
    try:
        return re.compile("".join(out) + r"\Z")
    except re.error as exc:  # a class like [z-a]
        raise UsageError(f"bad pattern {pattern!r} ({exc})") from None


@dataclass(frozen=True)
class Rule:
    """Files whose relative path matches `pattern` (or any of a tuple of
    patterns) are baked with `recipe` into `container` (None: the batch's). A
    pattern without '/' matches the file name in any folder. `recipe` None
    leaves the matching files out. `label` names the rule in notes."""

    pattern: object  # str, or a tuple of str
    recipe: object = None
    container: str = None
    label: str = field(default=None, compare=False)

    @property
    def patterns(self):
        return (self.pattern,) if isinstance(self.pattern, str) else tuple(self.pattern)

    def matches(self, rel):
        name = rel.rsplit("/", 1)[-1]
        return any(_pattern_regex(p).match(rel if "/" in p else name) is not None for p in self.patterns)


@dataclass(frozen=True)
class Manifest:
    path: str
    inputs: tuple  # files, folders or globs, resolved against the manifest's folder
    rules: tuple
    container: str = None


_RULE_KEYS = {"match", "container", "skip", "use"}
_MANIFEST_KEYS = ("inputs", "container", "target", "defaults", "rules")
USES = ("colour", "data", "normal")


def _merge(defaults, table):
    """Recipe parts of a rule over the defaults, one part at a time."""
    from .recipe import PARTS

    merged = {k: v for k, v in defaults.items() if k not in _RULE_KEYS}
    for key, value in table.items():
        if key in _RULE_KEYS:
            continue
        if key in PARTS and isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = {**merged[key], **value}
        else:
            merged[key] = value
    return merged


def use_parts(use, target="desktop"):
    """The recipe parts a scene gives a texture of this use: `colour` (sRGB
    where the format has it), `data` (linear), `normal` (a tangent-space
    normal map: linear, renormalised mips); the format is the scene's for the
    target (desktop: bc1, bc1, bc5)."""
    from . import formats
    from .scene.plan import choose_format

    fmt = choose_format(target, use)
    srgb = use == "colour" and formats.get(fmt).has_srgb
    return {"source": {"normal_map": use == "normal"},
            "output": {"colour_space": "srgb" if srgb else "linear"},
            "codec": {"format": fmt}}


def _check_container(value, where):
    from .choices import CONTAINERS

    if value is not None and value not in CONTAINERS:
        raise UsageError(f"{where}: container must be one of {', '.join(CONTAINERS)}, not {value!r}")
    return value


def _rule_patterns(table, where):
    match = table.get("match") if isinstance(table, dict) else None
    if isinstance(match, str):
        match = [match]
    if not isinstance(match, list) or not match or not all(isinstance(m, str) and m for m in match):
        raise UsageError(f"{where}: needs a match = \"pattern\" (or a list of patterns)")
    for pattern in match:
        try:
            _pattern_regex(pattern)
        except UsageError as exc:
            raise UsageError(f"{where}: {exc}") from None
    return match[0] if len(match) == 1 else tuple(match)


def load_manifest(path):
    """Read a TOML manifest: `inputs`, `container`, `target`, `[defaults]`
    (recipe parts every rule starts from) and `[[rules]]` (`match` pattern or
    list of patterns, optional `use` = colour, data or normal, recipe parts,
    optional `container`, `skip = true` to leave files out). First matching
    rule wins; a rule's settings are its own parts over its use over the
    defaults."""
    import tomllib

    from .choices import SCENE_TARGETS
    from .recipe import Recipe

    path = os.fspath(path)
    raw = read_bytes(path, "manifest")  # a regular file only: a FIFO would block
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise UsageError(f"not a readable manifest ({str(exc).splitlines()[0]})", path) from None
    except RecursionError:
        raise UsageError("not a readable manifest (nested too deeply)", path) from None
    unknown = sorted(set(data) - set(_MANIFEST_KEYS))
    if unknown:
        raise UsageError(f"unknown manifest key(s) {', '.join(unknown)}; "
                         f"keys are {', '.join(_MANIFEST_KEYS)}", path)
    here = os.path.dirname(os.path.abspath(path))
    inputs = data.get("inputs", ["."])
    if isinstance(inputs, str):
        inputs = [inputs]
    if not isinstance(inputs, list) or not all(isinstance(i, str) for i in inputs):
        raise UsageError("inputs must be a list of paths", path)
    target = data.get("target", "desktop")
    if target not in SCENE_TARGETS:
        raise UsageError(f"target must be one of {', '.join(SCENE_TARGETS)}, not {target!r}", path)
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
        pattern = _rule_patterns(table, where)
        label = f"rule {i} (match = {table['match']!r})"
        if table.get("skip"):
            rules.append(Rule(pattern, label=label))
            continue
        use = table.get("use")
        if use is not None and use not in USES:
            raise UsageError(f"{where}: use must be one of {', '.join(USES)}, not {use!r}")
        start = defaults if use is None else _merge(defaults, use_parts(use, target))
        try:
            recipe = Recipe.from_dict(_merge(start, table))
        except UsageError as exc:
            raise UsageError(f"{where} ({table['match']}): {exc}") from None
        rules.append(Rule(pattern, recipe, _check_container(table.get("container"), where), label))
    return Manifest(path, tuple(os.path.join(here, i) for i in inputs), tuple(rules), container)


# --- planning -------------------------------------------------------------------------


class Jobs(list):
    """The jobs of a plan (a list), with `notes`: what the planning found worth
    saying (manifest rules that matched no file)."""

    notes = ()


def _safe_name(name, src):
    """An output name must stay under OUTDIR: relative, no '..' or empty part."""
    parts = name.split("/")
    if name.startswith("/") or any(p in ("", ".", "..") for p in parts):
        raise UsageError(f"would be baked to {name!r}, outside the output folder", src)
    return parts


def plan(inputs, outdir, recipe=None, rules=None, container=None):
    """Jobs for every input: with `recipe` each file is baked with it; with
    `rules` (a Manifest or a list of Rule) the first rule matching the file's
    relative path gives its recipe (files no rule matches are left out).
    `container` (choices.DEFAULT_CONTAINER, or another in container.table) is the extension of the outputs a
    rule does not set. Every recipe is checked against its container here,
    before any file is read. Returns a `Jobs` list; UsageError when there is
    nothing to bake (no image file, or none that a rule bakes)."""
    from .recipe import Recipe

    if (recipe is None) == (rules is None):
        raise UsageError("give either a recipe or rules")
    if isinstance(rules, Manifest):
        container = container or rules.container
        rules = rules.rules
    container = _check_container(container, "--container") or DEFAULT_CONTAINER
    if recipe is not None:
        if not isinstance(recipe, Recipe):
            raise UsageError("recipe must be a texcook.recipe.Recipe")
        rules = [Rule("**", recipe)]
    outdir = os.path.abspath(os.fspath(outdir))
    jobs, by_output, checked = Jobs(), {}, set()
    found = collect(inputs, exclude=outdir)
    matched = set()
    for src, rel in found:
        rule = next((r for r in rules if r.matches(rel)), None)
        if rule is not None:
            matched.add(id(rule))
        if rule is None or rule.recipe is None:
            continue
        kind = rule.container or container
        if (rule.recipe, kind) not in checked:
            rule.recipe.check_container(kind)
            checked.add((rule.recipe, kind))
        name = os.path.splitext(rel)[0] + "." + kind
        parts = _safe_name(name, src)
        if name in by_output:
            raise UsageError(f"{by_output[name]} and {src} would both be baked to {name}")
        by_output[name] = src
        jobs.append(Job(src, os.path.join(outdir, *parts), name, rule.recipe))
    jobs.notes = tuple(f"{r.label or repr(r.pattern)} matches no file" for r in rules if id(r) not in matched)
    if not jobs:
        where = ", ".join(os.fspath(i) for i in inputs)
        if not found:
            raise UsageError(f"nothing to bake: no image file in {where}")
        raise UsageError(f"nothing to bake: none of the {len(found)} file(s) in {where} matches a rule that "
                         "bakes it" + "".join(f"; {n}" for n in jobs.notes))
    return jobs


# --- incremental state ----------------------------------------------------------------


def state_path(outdir):
    return os.path.join(os.fspath(outdir), STATE_NAME)


def _valid_entry(entry):
    """A state entry as `run` writes it; anything else is treated as absent."""
    if not isinstance(entry, dict):
        return False
    if not all(isinstance(entry.get(k), str) for k in ("sha256", "recipe", "texcook")):
        return False
    if "failed" in entry:
        budget = entry.get("max_memory")
        return isinstance(entry["failed"], str) and (budget is None or type(budget) is int)
    size = entry.get("bytes")
    if not isinstance(size, int) or isinstance(size, bool) or size < 0:
        return False
    psnr = entry.get("psnr")
    return psnr is None or (isinstance(psnr, (int, float)) and not isinstance(psnr, bool)
                            and isinstance(entry.get("levels"), list))


def load_state(outdir, notes=None):
    """{output name: entry} from the last runs; empty when there is none or it is
    unreadable (everything is then baked again, which is safe). A state file
    that is not a regular file (a FIFO, a device) is refused (InputError). An
    unreadable file or a malformed entry is treated as absent, with a line in
    `notes` (a list) when given."""
    path = state_path(outdir)
    if not os.path.lexists(path):
        return {}
    raw = read_bytes(path, "batch state")
    say = notes.append if notes is not None else (lambda text: None)
    try:
        data = json.loads(raw)
    except (ValueError, RecursionError):  # UnicodeDecodeError is a ValueError
        say(f"{path}: unreadable batch state, ignored: every file is baked again")
        return {}
    if not isinstance(data, dict) or data.get("version") != STATE_VERSION or not isinstance(data.get("files"), dict):
        say(f"{path}: not a batch state of this texcook, ignored: every file is baked again")
        return {}
    files = {name: entry for name, entry in data["files"].items() if _valid_entry(entry)}
    bad = len(data["files"]) - len(files)
    if bad:
        say(f"{path}: {bad} malformed entr{'y' if bad == 1 else 'ies'} ignored: "
            f"{'that file is' if bad == 1 else 'those files are'} baked again")
    return files


def save_state(outdir, files):
    from .fileio import atomic_write

    data = {"version": STATE_VERSION, "files": files}
    atomic_write(state_path(outdir), (json.dumps(data, indent=1, sort_keys=True) + "\n").encode())


@contextlib.contextmanager
def folder_lock(outdir):
    """Hold OUTDIR's batch lock (an exclusive flock on LOCK_NAME in it) for the
    block: one run per OUTDIR at a time, so the state always describes the
    outputs beside it. The kernel drops the lock when the holder dies, even by
    SIGKILL, so a killed run never leaves OUTDIR locked. OutputError at once
    when another run holds it."""
    path = os.path.join(os.fspath(outdir), LOCK_NAME)
    try:
        fd = lock(path, wait=False, create=True)
    except OSError as exc:
        raise OutputError(f"cannot lock the batch folder ({exc.strerror})", path) from None
    if fd is None:
        raise OutputError("another texcook batch is writing to this folder; run again when it has "
                          "finished, or choose another output folder", outdir)
    try:
        yield
    finally:
        os.close(fd)


def file_sha256(path):
    """sha256 of a regular file's bytes, or None when it cannot be read (the
    bake then reports why). Read through texcook.fileio: a FIFO or device is
    never opened for reading."""
    try:
        return hashlib.sha256(read_bytes(path, "input")).hexdigest()
    except InputError:
        return None


def why(job, entry, sha, force=False, min_psnr=None, digest=None):
    """Why the job runs ("new", "changed", "recipe changed", "texcook changed",
    "memory budget changed", "output missing", "output changed", "PSNR not
    measured", "forced"), or why
    it does not: UP_TO_DATE, or FAILED_BEFORE (the input was refused and
    nothing that decides the outcome has changed since). `digest`: the job's
    recipe digest, when the caller has it already."""
    if force:
        return "forced"
    if not isinstance(entry, dict):
        return "new"
    if entry.get("texcook") != __version__:
        return "texcook changed"
    if entry.get("recipe") != (digest or job.recipe.digest()):
        return "recipe changed"
    if sha is None or entry.get("sha256") != sha:
        return "changed"
    if entry.get("failed"):
        if entry.get("max_memory", max_memory()) != max_memory():
            return "memory budget changed"  # a refusal may have been the budget's
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


def _init_worker(threads, parent=None, budget=None):
    """Process-pool worker start: a thread limit before numba loads, the
    parent's memory budget (`--max-memory` is set in the parent only), and
    SIGINT left to the parent (which stops the workers itself); SIGTERM unwinds
    so a temporary output file is removed. The worker ends with its parent
    (`parent`: its pid), however the parent ends."""
    os.environ["NUMBA_NUM_THREADS"] = str(threads)
    if budget is not None:
        from .fileio import set_max_memory

        set_max_memory(budget)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _exit_on_term)
    if parent is not None:
        _die_with_parent(parent)


def _exit_on_term(signum, frame):
    raise SystemExit(128 + signum)


PARENT_POLL = 0.25  # seconds between checks that the parent still lives
PARENT_GRACE = 2.0  # seconds a worker gets to unwind after its parent died


def _die_with_parent(parent):
    """On Linux the kernel sends SIGTERM when the parent dies (PR_SET_PDEATHSIG);
    everywhere a watcher thread sees the worker re-parented and sends SIGTERM
    itself. Either way the worker unwinds (its temporary output removed) and,
    if a long kernel call keeps it from unwinding, ends PARENT_GRACE later."""
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, signal.SIGTERM, 0, 0, 0)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass

    def watch():
        while os.getppid() == parent:
            time.sleep(PARENT_POLL)
        with contextlib.suppress(OSError):
            os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(PARENT_GRACE)
        os._exit(128 + signal.SIGTERM)

    threading.Thread(target=watch, name="texcook-parent-watch", daemon=True).start()


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
    or "failed" (with a one-line reason), sha256 (of the input bytes baked, or
    None when they are not known), bytes, seconds, notes, colour_space, and
    per-level PSNR when `min_psnr` is given.

    The input is hashed before and after the bake: when the two differ the
    input changed while it was read, and it is baked once more; when it keeps
    changing the job fails (and is not recorded, so the next run bakes it).
    The hash before the first bake is job.sha256 when the run took it (taken
    earlier still, so the two hashes span the bake all the same), and the hash
    after a bake is the one before the next: in the usual case the input's
    bytes are read once here."""
    t0 = time.perf_counter()
    _limit_threads(threads)
    before = job.sha256 if job.sha256 is not None else file_sha256(job.src)
    sha = None
    for _ in range(2):
        out = _bake_once(job, threads, min_psnr)
        after = file_sha256(job.src)
        if before == after:
            sha = after
            break
        before = after  # changed since it was hashed: the next bake starts from these bytes
    else:
        out = {"status": "failed", "reason": f"{job.src}: {CHANGED_WHILE_BAKED}"}
    out["sha256"] = sha
    if out["sha256"] is None:
        out.pop("refused", None)  # a refusal is recorded only for bytes known to have been refused
    out["seconds"] = round(time.perf_counter() - t0, 4)
    return out


def _bake_once(job, threads, min_psnr):
    try:
        from .pipeline import bake_file

        summary = bake_file(job.src, job.dst, job.recipe, threads=threads)
        out = {"status": "baked", "bytes": summary["bytes"], "format": summary["format"],
               "colour_space": summary["colour_space"], "notes": summary["notes"]}
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
                                              initargs=(threads, os.getpid(), max_memory()))
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
            stop_process_pool(pool)


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
                                   env={"NUMBA_NUM_THREADS": str(threads),
                                        "TEXCOOK_MAX_MEMORY": str(max_memory())})
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


def _sweep_temporaries(todo):
    """Remove the temporaries of this batch's outputs that no live writer holds:
    what a worker killed outright (SIGKILL, out of memory) left. Only names
    texcook gives its temporaries (`.NAME.texcook-XXXXXXXX.tmp`, NAME one of
    the outputs) are looked at, and texcook.fileio removes only those whose
    writer's lock the kernel has dropped: never a user's file."""
    by_folder = {}
    for job in todo:
        by_folder.setdefault(os.path.dirname(job.dst), set()).add(os.path.basename(job.dst))
    for folder, outputs in by_folder.items():
        try:
            names = os.listdir(folder)
        except OSError:
            continue
        stale = {name[1:name.rindex(TEMP_MARK)] for name in names
                 if name.endswith(TEMP_SUFFIX) and is_temp_name(name) and name.startswith(".")}
        for output in sorted(stale & outputs):
            sweep_stale(os.path.join(folder, output))


def worker_budget(jobs, requested):
    """(workers, note): at most `requested`, and as many as the memory budget
    (texcook.fileio.max_memory) holds at WORKER_BYTES each plus the working size
    (texels x 4 channels x 4 bytes) of the largest input, read from the image
    headers; note says why when the count was lowered (else None)."""
    if requested <= 1:
        return requested, None
    largest, where = 0, None
    for job in jobs:
        size = _declared_bytes(job.src)
        if size > largest:
            largest, where = size, job.src
    budget = max_memory()
    each = WORKER_BYTES + largest
    fits = max(1, budget // each)
    if fits >= requested:
        return requested, None
    big = f" plus {format_size(largest)} for the largest input ({where})" if where else ""
    return fits, (f"{requested} workers lowered to {fits}: each needs about {format_size(WORKER_BYTES)}{big}, "
                  f"within the {format_size(budget)} memory budget (--max-memory)")


def _declared_bytes(path):
    """The working size an image's header declares, or 0 when it cannot be read
    (the bake then says why)."""
    from .fileio import texel_bytes
    from .image import read_header

    try:
        header = read_header(path)
        return texel_bytes(header.width, header.height, 4)
    except Exception:  # any header a reader cannot make sense of: the bake reports it
        return 0


# --- the batch ------------------------------------------------------------------------


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM stopped the batch; `report` holds what finished (already
    recorded in the state file), `signum` the signal."""

    def __init__(self, report, signum=signal.SIGINT):
        super().__init__("batch interrupted")
        self.report = report
        self.signum = signum


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where SIGINT would raise KeyboardInterrupt."""

    signum = signal.SIGTERM


@contextlib.contextmanager
def sigterm_as_interrupt():
    """Within the block, SIGTERM (what CI cancellation and `timeout` send) raises
    Terminated, so it unwinds like Ctrl-C: workers stopped, what finished
    recorded. Only in the main thread (elsewhere signals cannot be caught)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        signal.signal(signal.SIGTERM, signal.SIG_IGN)  # one unwind; a second SIGTERM waits for it
        raise Terminated()

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _outside(folder, root):
    """True when `folder` (or its nearest existing ancestor) is not inside the
    real path `root`: a symlink leads out of OUTDIR."""
    probe = folder
    while not os.path.lexists(probe):
        probe = os.path.dirname(probe)
    return not _inside(os.path.realpath(probe), root)


def _make_folders(todo, outdir):
    """Create the output folders. Returns (job, entry, reason) for the jobs
    whose folder cannot be made, or leads outside OUTDIR by real path (a
    symlink inside it): those fail instead."""
    root = os.path.realpath(outdir)
    refused = {}
    for job, _ in todo:
        folder = os.path.dirname(job.dst)
        if folder in refused:
            continue
        refused[folder] = None
        try:
            if not _outside(folder, root):
                os.makedirs(folder, exist_ok=True)
            if _outside(folder, root):
                refused[folder] = "its folder leads outside the output folder (a symlink); not written"
        except OSError as exc:  # a file where a folder should be, no permission
            refused[folder] = f"cannot create its folder ({exc.strerror or exc})"
    return [(job, entry, refused[os.path.dirname(job.dst)]) for job, entry in todo
            if refused[os.path.dirname(job.dst)]]


def run(jobs, outdir, workers=None, backend="processes", scheduler=None, force=False, dry_run=False,
        min_psnr=None, progress=None, worker_fn=bake_job, notify=None):
    """Bake the jobs that are not up to date and return a report (a dict).

    workers: processes (or LocalCluster workers) [default: every core], lowered
    to what the memory budget holds (`worker_budget`); each gets cores //
    workers numba threads (at least one). backend: "processes" or "dask" (with
    `scheduler` an address like tcp://host:8786, or None for a LocalCluster on
    loopback). force: bake everything. dry_run: bake nothing, say what would
    run and why, with each such file's bake plan (entry["plan"], from its
    header; `dry_run_line` puts it in words). min_psnr: measure PSNR per level and count a file below it as
    failing. progress: called as progress(entry, count) after each job that
    ran, `count` being how many run in all. worker_fn: the function a worker
    calls, (job, threads, min_psnr) -> result like bake_job's. notify: called
    with each batch-wide note as it arises (a malformed state, fewer workers);
    they are in report["messages"] too, and the files' notes collapsed in
    report["notes"].

    Unless dry_run, the run holds OUTDIR's lock throughout (`folder_lock`):
    OutputError at once when another run holds it. On SIGINT or SIGTERM what
    finished is recorded and Interrupted is raised with the partial report."""
    if backend not in ("processes", "dask"):
        raise UsageError(f"unknown backend {backend!r}; choose processes or dask")
    if workers is not None and workers < 1:
        raise UsageError("workers must be at least 1")
    jobs = list(jobs)
    names = [job.name for job in jobs]
    if len(set(names)) != len(names):
        raise UsageError("two jobs write the same output")
    outdir = os.fspath(outdir)
    with sigterm_as_interrupt(), contextlib.ExitStack() as held:
        if not dry_run:
            try:
                os.makedirs(outdir, exist_ok=True)
            except OSError as exc:
                raise OutputError(f"cannot create the output folder ({exc.strerror or exc})", outdir) from None
            held.enter_context(folder_lock(outdir))
        return _run_locked(jobs, outdir, workers, backend, scheduler, force, dry_run, min_psnr, progress,
                           worker_fn, notify)


def _run_locked(jobs, outdir, workers, backend, scheduler, force, dry_run, min_psnr, progress, worker_fn,
                notify):
    t0 = time.time()
    messages = []

    def say(text):
        messages.append(text)
        if notify is not None:
            notify(text)

    state_notes = []
    files = load_state(outdir, state_notes)
    for text in state_notes:
        say(text)
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
        elif dry_run:
            _dry_plan(job, entry)
        else:
            entry["status"] = "pending"
            todo.append((replace(job, sha256=sha), entry))
        entries.append(entry)
    workers = min(workers or default_workers(), max(len(todo), 1))
    if todo and not dry_run and scheduler is None:
        workers, lowered = worker_budget([j for j, _ in todo], workers)
        if lowered:
            say(lowered)
    threads = max(1, default_workers() // workers)
    report = {"texcook": __version__, "outdir": os.path.abspath(outdir), "backend": backend,
              "workers": None if scheduler else workers,  # a remote cluster's are its own
              "dry_run": dry_run, "min_psnr": min_psnr, "ran": 0, "files": entries, "messages": messages}
    if dry_run or not todo:
        return _finish(report, t0)

    for job, entry, reason in _make_folders(todo, outdir):
        entry.update(status="failed", seconds=0.0, reason=f"{job.dst}: {reason}")
        files.pop(job.name, None)
        todo.remove((job, entry))
    by_name = {job.name: entry for job, entry in todo}
    if backend == "dask":
        stream = _run_dask([j for j, _ in todo], scheduler, workers, 1, min_psnr, worker_fn)
    else:
        stream = _run_processes([j for j, _ in todo], workers, threads, min_psnr, worker_fn)
    last_save = time.monotonic()
    try:
        for job, result in stream:
            entry = by_name[job.name]
            refused = result.pop("refused", False)
            entry.update(result)
            if result["status"] == "baked":
                _name_note(job, entry)
                entry["passed"] = min_psnr is None or result["psnr"] >= min_psnr
                if entry["passed"] and entry["sha256"] is not None:
                    files[job.name] = _state_entry(job, entry)
                else:
                    files.pop(job.name, None)
            elif refused and entry["sha256"] is not None:
                files[job.name] = _state_entry(job, entry)
            else:
                files.pop(job.name, None)
            report["ran"] += 1
            if progress is not None:
                progress(entry, len(todo))
            if time.monotonic() - last_save >= SAVE_EVERY:
                save_state(outdir, files)
                last_save = time.monotonic()
    except KeyboardInterrupt as stop:
        stream.close()
        save_state(outdir, files)
        _sweep_temporaries([j for j, _ in todo])
        for entry in entries:
            if entry["status"] == "pending":
                entry["status"] = "interrupted"
        raise Interrupted(_finish(report, t0), getattr(stop, "signum", signal.SIGINT)) from None
    save_state(outdir, files)
    _sweep_temporaries([j for j, _ in todo])
    return _finish(report, t0)


def _dry_plan(job, entry):
    """A dry run's entry for a job to run: the plan its bake would follow
    (entry["plan"], BakePlan.to_dict), made from the file's header alone, or
    the failure a bake would meet when the header cannot be read or the
    recipe cannot bake this source."""
    try:
        from .pipeline import container_of, sat_path_of
        from .plan import plan_bake

        # The output's folder may not exist yet (a dry run creates none), so not
        # pipeline.plan_file, which insists on it; the same plan otherwise.
        plan = plan_bake(job.src, job.recipe, job.dst, container_of(job.dst), sat_path_of(job.dst, job.recipe))
    except TexcookError as exc:
        entry.update(status="failed", reason=_reason(job, exc), seconds=0.0)
    except Exception as exc:  # a library error on one header is still this file's alone
        entry.update(_failed(job, f"internal error: {type(exc).__name__}: {_one_line(exc)}"))
    else:
        entry.update(status="would bake", plan=plan.to_dict())


def dry_run_line(entry):
    """One line of a dry run: why the file would (or would not) be baked and,
    for one that would be, what its plan does (format, colour space, levels,
    the steps that run), every word from the plan."""
    line = f"{entry['why']}: {entry['input']} -> {entry['output']}"
    plan = entry.get("plan")
    if plan is None:
        return line + (": would fail" if entry["status"] == "failed" and entry["why"] != FAILED_BEFORE else "")
    space = plan["colour_space"]["chosen"] or "colour space from the pixels"
    levels = len(plan["levels"])
    steps = []
    for step, why in plan["steps"]["ran"].items():
        if step == "srgb":
            continue  # said by the colour space
        if step == "mips":
            steps.append(f"mips {plan['chain']['filter']} {','.join(plan['chain']['wrap'])}")
        elif step in ("transform", "zstd"):
            steps.append(f"{step} {why}")
        else:
            steps.append(step)
    return f"{line}: {plan['format']} {space}, {levels} level{'s' if levels != 1 else ''}" + (
        f", {', '.join(steps)}" if steps else "")


def _name_note(job, entry):
    """A file named like a normal map but baked as colour: worth a note, since
    its mips and colour space are then wrong for vectors."""
    stem = os.path.splitext(job.name.rsplit("/", 1)[-1])[0]
    if job.recipe.source.normal_map or not _NORMAL_NAME.search(stem):
        return
    space = "sRGB colour" if entry.get("colour_space") == "srgb" else "colour"
    entry["notes"] = list(entry.get("notes") or []) + [
        f"named like a normal map but baked as {space} (a manifest rule with use = \"normal\" bakes it as one)"]


def _state_entry(job, entry):
    out = {"input": job.src, "sha256": entry["sha256"], "recipe": entry["recipe"], "texcook": __version__}
    if entry["status"] == "failed":
        out.update(failed=entry["reason"], max_memory=max_memory())
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
    report["notes"] = collapse_notes(report["files"])
    report["seconds"] = round(time.time() - t0, 3)
    report["ok"] = counts["failed"] == 0 and counts["below_min_psnr"] == 0 and counts["interrupted"] == 0
    return report


def collapse_notes(entries):
    """The files' notes, one per distinct text: [{"note", "files" (how many),
    "input" (the first)}], most frequent first."""
    seen = {}
    for entry in entries:
        for note in entry.get("notes") or ():
            row = seen.setdefault(note, {"note": note, "files": 0, "input": entry["input"]})
            row["files"] += 1
    return sorted(seen.values(), key=lambda row: -row["files"])


def summary_line(report):
    """One line for people: counts, time and rate."""
    c = report["counts"]
    secs = report["seconds"]
    if report["dry_run"]:
        failing = f", {c['failed']} failing" if c["failed"] else ""
        return f"dry run: {c.get('would bake', 0)} to bake, {c['skipped']} up to date{failing}"
    ran = report["ran"]
    rate = f", {ran / secs:.1f} files/s" if ran and secs > 0 else ""
    below = f", {c['below_min_psnr']} below {report['min_psnr']} dB" if report["min_psnr"] is not None else ""
    stopped = f", {c['interrupted']} not run (interrupted)" if c.get("interrupted") else ""
    return (f"batch: {c['baked']} baked, {c['skipped']} skipped, {c['failed']} failed{below}{stopped} "
            f"in {secs:.1f} s{rate}")
