"""Batch in shared folders and against unlucky or hostile inputs: outputs stay
inside OUTDIR, the state never lies, one run per OUTDIR, workers end with the
parent, SIGTERM unwinds like SIGINT, nothing blocks, errors are one line, and
the files' notes reach stderr.

Every case here ran against the batch before these guarantees: each test
fails there (a hang shows as a timeout)."""

import fcntl
import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import texcook
from texcook import batch
from texcook.errors import OutputError, UsageError
from texcook.image import write_image
from texcook.recipe import Recipe

from conftest import interruptible
from test_batch import outputs, temporaries

# the tree of the texcook under test (subprocesses import the same one)
ROOT = Path(texcook.__file__).resolve().parent.parent
HERE = Path(__file__).resolve().parent
BC1 = Recipe.of(format="bc1", preset="fast")
ENV = dict(os.environ, PYTHONPATH=str(ROOT))


def png(path, rng, channels=3, size=8):
    path.parent.mkdir(parents=True, exist_ok=True)
    write_image(path, rng.integers(0, 256, (size, size, channels)).astype(np.uint8))
    return path


def texcook_cmd(*args, timeout=120, **kw):
    """The CLI as its own process (a hang ends as a failed test, not a stuck suite)."""
    try:
        proc = subprocess.run([sys.executable, "-m", "texcook.cli", *map(str, args)], env=ENV, capture_output=True,
                              text=True, timeout=timeout, **kw)
    except subprocess.TimeoutExpired:
        pytest.fail(f"texcook {' '.join(map(str, args))} did not finish in {timeout} s")
    return proc.returncode, proc.stdout, proc.stderr


def sha(path):
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def state(out):
    return json.loads((out / batch.STATE_NAME).read_text())["files"]


def vk_format(path):
    return int.from_bytes(Path(path).read_bytes()[12:16], "little")


# --- workers (module level: worker processes import them) ------------------------------

OTHER = b"other bytes"


def swapped_while_queued(job, threads, min_psnr):
    """The input is replaced after the batch hashed it and put back after the
    bake: what the worker baked is neither end's bytes."""
    original = Path(job.src).read_bytes()
    write_image(job.src, np.full((8, 8, 3), 17, np.uint8))
    try:
        return batch.bake_job(job, threads, min_psnr)
    finally:
        Path(job.src).write_bytes(original)


def changed_during_bake(job, threads, min_psnr):
    """The input changes once, just after the pipeline has read it."""
    from texcook import pipeline

    real = pipeline.bake_file

    def bake_then_edit(src, dst, recipe, **kw):
        summary = real(src, dst, recipe, **kw)
        flag = Path(src).with_suffix(".edited")
        if not flag.exists():
            flag.write_text("")
            write_image(src, np.full((8, 8, 3), 99, np.uint8))
        return summary

    pipeline.bake_file = bake_then_edit
    try:
        return batch.bake_job(job, threads, min_psnr)
    finally:
        pipeline.bake_file = real


def deleted_while_queued(job, threads, min_psnr):
    """The input is gone when the worker reads it, and back afterwards."""
    original = Path(job.src).read_bytes()
    os.unlink(job.src)
    try:
        return batch.bake_job(job, threads, min_psnr)
    finally:
        Path(job.src).write_bytes(original)


def slow_bake(job, threads, min_psnr):
    """A bake that takes a while."""
    time.sleep(1.5)
    return batch.bake_job(job, threads, min_psnr)


def _library_run(src, out, worker, workers):
    """A script running batch.run over `src` with this module's `worker`."""
    return (f"import sys; sys.path.insert(0, {str(HERE)!r})\n"
            f"from test_batch_untrusted import {worker}, BC1\nfrom texcook import batch\n"
            f"jobs = batch.plan([{str(src)!r}], {str(out)!r}, recipe=BC1)\n"
            f"batch.run(jobs, {str(out)!r}, workers={workers}, worker_fn={worker})\n")


def busy(job, threads, min_psnr):
    """Says which process works, then works for a minute (as a large bake would)."""
    Path(job.src).parent.parent.joinpath(f"busy-{os.getpid()}").write_text("")
    for _ in range(1200):
        time.sleep(0.05)
    return batch.bake_job(job, threads, min_psnr)


# --- outputs stay inside OUTDIR -------------------------------------------------------


def test_glob_climbing_out_after_a_wildcard_writes_nothing_outside(tmp_path, rng):
    png(tmp_path / "art" / "a" / "x.png", rng)
    png(tmp_path / "secret" / "s.png", rng)
    pattern = str(tmp_path / "art" / "*" / ".." / ".." / "secret" / "*.png")
    code, _, err = texcook_cmd("batch", pattern, "-o", tmp_path / "out", "-f", "bc1", "-j", "1")
    assert code == 2 and "outside the output folder" in err and len(err.strip().splitlines()) == 1, err
    assert sorted(p.name for p in (tmp_path / "secret").iterdir()) == ["s.png"]
    assert not (tmp_path / "out").exists() or outputs(tmp_path / "out") == []


def test_symlinked_folder_in_outdir_leading_out_is_not_written(tmp_path, rng):
    png(tmp_path / "art" / "sub" / "x.png", rng)
    png(tmp_path / "art" / "top.png", rng)
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "sub").symlink_to(tmp_path / "elsewhere")
    jobs = batch.plan([tmp_path / "art"], tmp_path / "out", recipe=BC1)
    files = {f["name"]: f for f in batch.run(jobs, tmp_path / "out", workers=1)["files"]}
    assert list((tmp_path / "elsewhere").iterdir()) == []
    assert files["sub/x.ktx2"]["status"] == "failed" and "leads outside" in files["sub/x.ktx2"]["reason"]
    assert files["top.ktx2"]["status"] == "baked"
    assert "sub/x.ktx2" not in state(tmp_path / "out")


def test_a_file_where_an_output_folder_should_be_fails_its_files_alone(tmp_path, rng):
    png(tmp_path / "art" / "sub" / "x.png", rng)
    png(tmp_path / "art" / "top.png", rng)
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "sub").write_text("a file of yours")
    code, out, err = texcook_cmd("batch", tmp_path / "art", "-o", tmp_path / "out", "-f", "bc1", "-j", "1")
    assert code == 1 and "internal error" not in err, err
    assert "sub/x.ktx2: cannot create its folder (File exists)" in err and out.startswith("batch: 1 baked")
    assert (tmp_path / "out" / "sub").read_text() == "a file of yours"
    with pytest.raises(OutputError, match="cannot create the output folder"):
        batch.run(batch.plan([tmp_path / "art"], tmp_path / "out" / "sub" / "o", recipe=BC1),
                  tmp_path / "out" / "sub" / "o")


@pytest.mark.parametrize("where", ["outdir itself", "inside outdir"])
def test_input_that_is_or_is_inside_outdir_is_refused(tmp_path, rng, where):
    png(tmp_path / "outer" / "src" / "a.png", rng)
    given = tmp_path / "outer" if where == "outdir itself" else tmp_path / "outer" / "src"
    code, out, err = texcook_cmd("batch", given, "-o", tmp_path / "outer", "-f", "bc1")
    said = "is the output folder" if where == "outdir itself" else "is inside the output folder"
    assert code == 2 and said in err and "outputs, not inputs" in err, (out, err)
    assert list((tmp_path / "outer").glob("*.ktx2")) == []


def test_nothing_to_bake_says_so_and_fails(tmp_path):
    (tmp_path / "empty").mkdir()
    (tmp_path / "empty" / "notes.txt").write_text("no images here")
    code, out, err = texcook_cmd("batch", tmp_path / "empty", "-o", tmp_path / "out", "-f", "bc1")
    assert code != 0 and "nothing to bake: no image file" in err and "0 baked" not in out


def test_report_to_a_missing_folder_is_refused_before_any_bake(tmp_path, rng):
    png(tmp_path / "art" / "a.png", rng)
    code, _, err = texcook_cmd("batch", tmp_path / "art", "-o", tmp_path / "out", "-f", "bc1",
                               "--report", tmp_path / "nowhere" / "r.json")
    assert code == 1 and "the report's folder does not exist" in err and not (tmp_path / "out").exists()


# --- the state records what was baked -------------------------------------------------


def test_input_swapped_while_queued_is_not_up_to_date_afterwards(tmp_path, rng):
    src = png(tmp_path / "art" / "a.png", rng)
    out = tmp_path / "out"
    jobs = batch.plan([tmp_path / "art"], out, recipe=BC1)
    report = batch.run(jobs, out, workers=1, worker_fn=swapped_while_queued)
    assert report["files"][0]["status"] == "baked"
    # the output holds the bytes that were there during the bake, not the original ones
    assert batch.why(jobs[0], state(out).get("a.ktx2"), batch.file_sha256(src)) == "changed"
    report = batch.run(jobs, out, workers=1)
    assert report["counts"]["baked"] == 1


def test_input_changed_during_the_bake_is_baked_again_from_its_new_bytes(tmp_path, rng):
    src = png(tmp_path / "art" / "a.png", rng)
    out = tmp_path / "out"
    jobs = batch.plan([tmp_path / "art"], out, recipe=BC1)
    batch.run(jobs, out, workers=1, worker_fn=changed_during_bake)
    assert state(out)["a.ktx2"]["sha256"] == sha(src)
    fresh = tmp_path / "fresh.ktx2"
    from texcook.pipeline import bake_file

    bake_file(src, fresh, BC1, threads=1)
    assert (out / "a.ktx2").read_bytes() == fresh.read_bytes()
    assert batch.run(jobs, out, workers=1)["counts"]["skipped"] == 1


def test_input_deleted_and_restored_is_retried_without_force(tmp_path, rng):
    png(tmp_path / "art" / "a.png", rng)
    out = tmp_path / "out"
    jobs = batch.plan([tmp_path / "art"], out, recipe=BC1)
    first = batch.run(jobs, out, workers=1, worker_fn=deleted_while_queued)
    assert first["files"][0]["status"] == "failed" and "no such file" in first["files"][0]["reason"]
    again = batch.run(jobs, out, workers=1)
    assert again["files"][0]["why"] != batch.FAILED_BEFORE and again["counts"]["baked"] == 1


# --- one run per OUTDIR ---------------------------------------------------------------


def test_second_run_on_a_locked_outdir_is_refused_in_one_line(tmp_path, rng):
    png(tmp_path / "art" / "a.png", rng)
    out = tmp_path / "out"
    out.mkdir()
    fd = os.open(out / batch.LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o666)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        code, _, err = texcook_cmd("batch", tmp_path / "art", "-o", out, "-f", "bc1", "-j", "1")
    finally:
        os.close(fd)
    assert code == 1 and "another texcook batch is writing to this folder" in err
    assert len(err.strip().splitlines()) == 1 and outputs(out) == []
    # the lock is gone with its holder: the next run bakes
    code, _, _ = texcook_cmd("batch", tmp_path / "art", "-o", out, "-f", "bc1", "-j", "1")
    assert code == 0 and outputs(out) == ["a.ktx2"]


def test_two_runs_at_once_never_record_one_recipe_against_the_others_output(tmp_path, rng):
    """A slow run (bc1) is overtaken by a fast one (bc3) on the same OUTDIR: without
    the lock the slow run records bc1 against outputs the fast one wrote."""
    for i in range(8):
        png(tmp_path / "art" / f"t{i}.png", rng, size=16)
    out = tmp_path / "out"
    slow = subprocess.Popen([sys.executable, "-c", _library_run(tmp_path / "art", out, "slow_bake", workers=1)],
                            env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while not (out.exists() and outputs(out)):
            assert time.monotonic() < deadline and slow.poll() is None, slow.stderr and slow.stderr.read()
            time.sleep(0.05)
        code, _, err = texcook_cmd("batch", tmp_path / "art", "-o", out, "-f", "bc3", "--preset", "fast", "-j", "1")
        assert code == 1 and "another texcook batch is writing to this folder" in err, err
    finally:
        slow.communicate(timeout=120)
    assert slow.returncode == 0
    files = state(out)
    assert len(files) == 8 and {e["recipe"] for e in files.values()} == {BC1.digest()}
    for name in files:
        assert vk_format(out / name) in (131, 132), name  # bc1, as recorded


# --- workers end with the parent; SIGTERM like SIGINT ----------------------------------


def _alive(pid):
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs /proc")
def test_workers_die_with_a_parent_killed_by_sigkill(tmp_path, rng):
    for i in range(4):
        png(tmp_path / "art" / f"t{i}.png", rng)
    script = _library_run(tmp_path / "art", tmp_path / "out", "busy", workers=2)
    parent = subprocess.Popen([sys.executable, "-c", script], env=ENV, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while len(list(tmp_path.glob("busy-*"))) < 2:
            assert time.monotonic() < deadline and parent.poll() is None, "the workers never started"
            time.sleep(0.05)
        workers = [int(p.name.split("-")[1]) for p in tmp_path.glob("busy-*")]
        parent.kill()
        parent.wait(10)
        deadline = time.monotonic() + 10
        while any(_alive(pid) for pid in workers) and time.monotonic() < deadline:
            time.sleep(0.05)
        alive = [pid for pid in workers if _alive(pid)]
    finally:
        for pid in workers if "workers" in dir() else []:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)
    assert alive == [], "workers outlived their killed parent"


def test_sigterm_records_what_finished_and_exits_143(tmp_path, rng):
    src, out = tmp_path / "src", tmp_path / "out"
    for i in range(30):
        png(src / f"t{i:02d}.png", rng, size=96)
    cmd = [sys.executable, "-m", "texcook.cli", "batch", str(src), "-o", str(out), "-f", "bc1",
           "--preset", "thorough", "-j", "1"]
    proc = subprocess.Popen(cmd, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=interruptible)
    deadline = time.monotonic() + 120
    while not (out.exists() and len(outputs(out)) >= 2):
        assert time.monotonic() < deadline and proc.poll() is None
        time.sleep(0.02)
    proc.send_signal(signal.SIGTERM)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 143, (stdout, stderr)
    assert "terminated (SIGTERM)" in stderr and "what finished is recorded" in stderr
    done = outputs(out)
    assert 0 < len(done) < 30 and not temporaries(out)
    assert 0 < len(state(out)) and set(state(out)) <= set(done)


def test_workers_are_bounded_by_memory_and_the_cli_says_so(tmp_path, rng):
    for i in range(4):
        png(tmp_path / "art" / f"t{i}.png", rng)
    report = tmp_path / "r.json"
    code, _, err = texcook_cmd("--max-memory", "400M", "batch", tmp_path / "art", "-o", tmp_path / "out", "-f", "bc1",
                               "-j", "4", "--report", report)
    assert code == 0, err
    assert "4 workers lowered to 2" in err and "memory budget" in err
    assert json.loads(report.read_text())["workers"] == 2
    # the largest input's working size counts too
    assert batch.worker_budget(batch.plan([tmp_path / "art"], tmp_path / "o2", recipe=BC1), 4)[0] >= 2
    png(tmp_path / "art" / "big.png", rng, size=2048)  # 64M declared: 224M a worker
    jobs = batch.plan([tmp_path / "art"], tmp_path / "o2", recipe=BC1)
    from texcook import fileio

    fileio.set_max_memory("500M")
    try:
        workers, note = batch.worker_budget(jobs, 4)
    finally:
        fileio.set_max_memory(None)
    assert workers == 2 and "big.png" in note


def test_workers_keep_the_memory_budget_and_a_refusal_by_it_is_not_final(tmp_path):
    """--max-memory is set in the parent; the workers refuse by the same budget,
    and what the budget refused is retried once the budget changes."""
    art = tmp_path / "art"
    art.mkdir()
    write_image(art / "flat.png", np.full((64, 64, 4), 90, np.uint8))  # a small file declaring 64K
    args = ["batch", art, "-o", tmp_path / "out", "-f", "bc1", "-j", "1"]
    code, _, err = texcook_cmd("--max-memory", "16K", *args)
    assert code == 1 and "more than the 16.0K memory budget" in err, err
    code, out, err = texcook_cmd(*args)
    assert code == 0 and out.startswith("batch: 1 baked"), (out, err)


# --- nothing blocks -------------------------------------------------------------------


@pytest.mark.parametrize("what", ["named input", "input in a folder", "state file", "manifest", "dev zero"])
def test_fifos_and_devices_are_refused_at_once(tmp_path, rng, what):
    art, out = tmp_path / "art", tmp_path / "out"
    png(art / "a.png", rng)
    args = [art, "-o", out, "-f", "bc1", "-j", "1"]
    if what == "named input":
        os.mkfifo(tmp_path / "pipe.png")
        args = [tmp_path / "pipe.png"] + args[1:]
    elif what == "input in a folder":
        os.mkfifo(art / "pipe.png")
    elif what == "state file":
        out.mkdir()
        os.mkfifo(out / batch.STATE_NAME)
    elif what == "manifest":
        os.mkfifo(tmp_path / "m.toml")
        args = ["--manifest", tmp_path / "m.toml", art, "-o", out]
    else:
        args = ["/dev/zero"] + args[1:]
    code, stdout, err = texcook_cmd("batch", *args, timeout=60)
    assert code != 0
    if what == "input in a folder":  # that file fails alone
        assert "pipe.png: is a pipe (FIFO)" in err and stdout.startswith("batch: 1 baked, 0 skipped, 1 failed")
    else:
        assert "not a regular file" in err and len(err.strip().splitlines()) == 1, err


# --- one line, never an internal error ------------------------------------------------


def _deep_json(n=100000):
    return "[" * n + "]" * n


@pytest.mark.parametrize("kind, text, message", [
    ("manifest", "a = " + "[" * 100000 + "]" * 100000 + "\n", "nested too deeply"),
    ("manifest", "[[rules]]\nmatch = 'tex[z-a].png'\n", "rule 1: bad pattern"),
    ("recipe.json", _deep_json(), "nested too deeply"),
    ("recipe.toml", "a = " + "[" * 100000 + "]" * 100000 + "\n", "nested too deeply"),
], ids=["deep manifest", "bad class in a rule", "deep json recipe", "deep toml recipe"])
def test_hostile_manifests_and_recipes_are_one_line_usage_errors(tmp_path, rng, kind, text, message):
    png(tmp_path / "art" / "a.png", rng)
    if kind == "manifest":
        (tmp_path / "m.toml").write_text(text)
        args = ["--manifest", tmp_path / "m.toml", tmp_path / "art"]
    else:
        path = tmp_path / kind
        path.write_text(text)
        args = ["--recipe", path, tmp_path / "art"]
    code, _, err = texcook_cmd("batch", *args, "-o", tmp_path / "out")
    assert code == 2 and message in err and "internal error" not in err, err
    assert len(err.strip().splitlines()) == 1


def test_bad_rule_pattern_from_python_is_a_usage_error():
    with pytest.raises(UsageError, match="bad pattern"):
        batch.Rule("[z-a]", BC1).matches("a")


@pytest.mark.parametrize("damage", ["deep", "list root", "entry"])
def test_damaged_state_is_ignored_where_damaged_and_said(tmp_path, rng, damage):
    art, out = tmp_path / "art", tmp_path / "out"
    png(art / "a.png", rng)
    png(art / "b.png", rng)
    assert texcook_cmd("batch", art, "-o", out, "-f", "bc1", "-j", "1")[0] == 0
    path = out / batch.STATE_NAME
    if damage == "deep":
        path.write_text(_deep_json())
    elif damage == "list root":
        path.write_text("[]")
    else:
        data = json.loads(path.read_text())
        data["files"]["a.ktx2"] = ["not", "an", "entry"]
        data["files"]["b.ktx2"]["bytes"] = "many"
        path.write_text(json.dumps(data))
        png(art / "c.png", rng)
    code, stdout, err = texcook_cmd("batch", art, "-o", out, "-f", "bc1", "-j", "1")
    assert code == 0 and "internal error" not in err, err
    if damage == "entry":
        assert "2 malformed entries ignored" in err and stdout.startswith("batch: 3 baked, 0 skipped")
    else:
        assert "ignored: every file is baked again" in err and stdout.startswith("batch: 2 baked, 0 skipped")
    assert texcook_cmd("batch", art, "-o", out, "-f", "bc1")[1].startswith("batch: 0 baked")


def test_malformed_entry_from_python_is_new_not_a_crash(tmp_path, rng):
    png(tmp_path / "a.png", rng)
    (job,) = batch.plan([tmp_path / "a.png"], tmp_path / "out", recipe=BC1)
    assert batch.why(job, ["junk"], "0" * 64) == "new"


# --- manifests say what matched nothing -----------------------------------------------


def test_rules_matching_nothing_are_reported(tmp_path, rng):
    png(tmp_path / "art" / "a.png", rng)
    (tmp_path / "m.toml").write_text("inputs = ['art']\n[defaults]\ncodec = { format = 'bc1', preset = 'fast' }\n"
                                     "[[rules]]\nmatch = '*.tga'\n[[rules]]\nmatch = '*.png'\n")
    code, _, err = texcook_cmd("batch", "--manifest", tmp_path / "m.toml", "-o", tmp_path / "out", "-j", "1")
    assert code == 0 and "rule 1 (match = '*.tga') matches no file" in err
    (tmp_path / "none.toml").write_text("inputs = ['art']\n[[rules]]\nmatch = '*.tga'\n")
    code, out, err = texcook_cmd("batch", "--manifest", tmp_path / "none.toml", "-o", tmp_path / "out2")
    assert code != 0 and "nothing to bake" in err and "matches no file" in err


# --- temporaries: only texcook's -----------------------------------------------------


def test_sweep_never_removes_a_users_file(tmp_path, rng):
    png(tmp_path / "art" / "a.png", rng)
    out = tmp_path / "out"
    out.mkdir()
    mine = out / ".texcook-notes.tmp"
    mine.write_text("a user's file")
    future = time.time() + 3600
    os.utime(mine, (future, future))
    batch.run(batch.plan([tmp_path / "art"], out, recipe=BC1), out, workers=1)
    assert mine.read_text() == "a user's file"


# --- notes, use rules, progress -------------------------------------------------------


def test_notes_are_printed_collapsed_and_quiet_hides_them(tmp_path, rng):
    for i in range(3):
        png(tmp_path / "art" / f"t{i}.png", rng, channels=4)
    png(tmp_path / "art" / "rock_n.png", rng)
    args = ["batch", tmp_path / "art", "-o", tmp_path / "out", "-f", "bc1", "--preset", "fast", "-j", "1"]
    code, _, err = texcook_cmd(*args)
    assert code == 0
    assert "texcook: note: 3 files: bc1 has no alpha: the source's alpha is dropped" in err
    assert err.count("has no alpha") == 1
    assert f"texcook: note: {tmp_path / 'art' / 'rock_n.png'}: named like a normal map but baked as sRGB colour" in err
    code, _, err = texcook_cmd(*args, "--force", "--quiet")
    assert code == 0 and err == ""


USE_MANIFEST = """
inputs = ["art"]
[defaults]
codec = { format = "bc1", preset = "fast" }

[[rules]]
match = ["**/*_n.png", "*_normal.*"]
use = "normal"

[[rules]]
match = "data/**"
use = "data"

[[rules]]
match = "mask_*.png"
use = "data"
codec = { format = "bc4" }

[[rules]]
match = "*"
use = "colour"
"""


def test_manifest_use_gives_the_scene_recipe_for_each_use(tmp_path, rng):
    for rel in ["rock_n.png", "wall_normal.tga", "data/rough.png", "mask_a.png", "albedo.png"]:
        png(tmp_path / "art" / rel, rng)
    (tmp_path / "m.toml").write_text(USE_MANIFEST)
    manifest = batch.load_manifest(tmp_path / "m.toml")
    jobs = {j.name: j.recipe for j in batch.plan(manifest.inputs, tmp_path / "out", rules=manifest)}
    normal = Recipe.of(format="bc5", preset="fast", normal_map=True, colour_space="linear")
    assert jobs["rock_n.ktx2"] == normal and jobs["wall_normal.ktx2"] == normal
    assert jobs["data/rough.ktx2"] == Recipe.of(format="bc1", preset="fast", colour_space="linear")
    assert jobs["mask_a.ktx2"] == Recipe.of(format="bc4", preset="fast", colour_space="linear")  # the rule's own codec wins
    assert jobs["albedo.ktx2"] == Recipe.of(format="bc1", preset="fast", colour_space="srgb")
    code, _, err = texcook_cmd("batch", "--manifest", tmp_path / "m.toml", "-o", tmp_path / "out", "-j", "1")
    assert code == 0, err
    assert vk_format(tmp_path / "out" / "rock_n.ktx2") == 141 and "named like a normal map" not in err
    assert vk_format(tmp_path / "out" / "albedo.ktx2") == 132
    (tmp_path / "bad.toml").write_text("[[rules]]\nmatch = '*'\nuse = 'shiny'\n")
    with pytest.raises(UsageError, match="use must be one of colour, data, normal"):
        batch.load_manifest(tmp_path / "bad.toml")


def test_progress_advances_per_file_on_a_terminal_and_is_quiet_when_piped(tmp_path, rng):
    import pty
    import struct
    import termios

    for i in range(3):
        png(tmp_path / "art" / f"t{i}.png", rng)
    code, _, err = texcook_cmd("batch", tmp_path / "art", "-o", tmp_path / "piped", "-f", "bc1", "-j", "1")
    assert code == 0 and "\r" not in err and "file/s" not in err and "it/s" not in err
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))  # a terminal 100 columns wide
    proc = subprocess.Popen([sys.executable, "-m", "texcook.cli", "batch", str(tmp_path / "art"), "-o",
                             str(tmp_path / "tty"), "-f", "bc1", "-j", "1"], env=ENV, stdout=subprocess.PIPE,
                            stderr=slave, stdin=subprocess.DEVNULL)
    os.close(slave)
    seen = b""
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:
            break
        if not chunk:
            break
        seen += chunk
    os.close(master)
    assert proc.wait(120) == 0
    text = seen.decode(errors="replace")
    assert all(f"{n}/3" in text for n in (1, 2, 3)), text
