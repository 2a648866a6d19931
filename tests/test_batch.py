"""Batch baking: planning (folders, globs, manifests), incremental state, failure
isolation (corrupt inputs, dying workers, SIGINT), the report, and the Dask
backend giving the same bytes as the process pool.

The 1,000-texture acceptance run is behind TEXCOOK_LONG=1."""

import importlib.util
import json
import os
import signal
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pytest

from texcook import batch
from texcook.errors import InputError, UsageError
from texcook.fileio import is_temp_name, stage_bytes
from texcook.image import write_image
from texcook.recipe import Recipe

from conftest import interruptible

ROOT = Path(__file__).resolve().parent.parent
BC1 = Recipe.of(format="bc1", preset="fast")
SIZES = [(1, 1), (4, 4), (7, 13), (16, 16), (33, 17), (64, 64)]


def make_tree(folder, rng, count, corrupt=0, sizes=SIZES):
    """`count` good images (mixed sizes, channels, some constant) in a folder and a
    subfolder, and `corrupt` bad ones of several kinds. Returns (good, bad) paths."""
    good, bad = [], []
    for i in range(count):
        sub = folder / ("sub" if i % 3 == 0 else "") / ("deep" if i % 6 == 0 else "")
        sub.mkdir(parents=True, exist_ok=True)
        h, w = sizes[i % len(sizes)]
        channels = (3, 4, 1)[i % 3]
        px = rng.integers(0, 256, (h, w, channels)).astype(np.uint8)
        if i % 7 == 0:
            px[:] = 200  # constant
        path = sub / f"tex{i:04d}.png"
        write_image(path, px)
        good.append(path)
    for i in range(corrupt):
        path = folder / f"bad{i:03d}.png"
        kind = i % 4
        if kind == 0:  # truncated PNG
            path.write_bytes(good[i % len(good)].read_bytes()[:60])
        elif kind == 1:  # not an image at all
            path.write_bytes(b"this is not a png\n" * 3)
        elif kind == 2:  # empty
            path.write_bytes(b"")
        else:  # a valid PNG claiming 60000x60000 pixels from a few bytes
            path.write_bytes(hostile_png(60000, 60000))
        bad.append(path)
    return good, bad


def hostile_png(width, height):
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(bytes(100))) + chunk(b"IEND", b""))


def outputs(outdir):
    """Every file under outdir (relative), the state and lock files left out."""
    found = []
    for root, _, files in os.walk(outdir):
        for name in files:
            if name not in (batch.STATE_NAME, batch.LOCK_NAME):
                found.append(os.path.relpath(os.path.join(root, name), outdir))
    return sorted(found)


def temporaries(folder):
    return [os.path.join(r, n) for r, _, fs in os.walk(folder) for n in fs if is_temp_name(n)]


def by_name(report):
    return {f["name"]: f for f in report["files"]}


# --- workers for the dying-worker tests (module level: workers import them) -----------


def kill_on_marked(job, threads, min_psnr):
    """Kills its own process for inputs named kill*.png, every time, while it
    has a half-written temporary output (a kill cannot unwind)."""
    if os.path.basename(job.src).startswith("kill"):
        stage_bytes(job.dst, b"partial")  # held, as a writer holds it, until the kill
        os.kill(os.getpid(), signal.SIGKILL)
    return batch.bake_job(job, threads, min_psnr)


def kill_once(job, threads, min_psnr):
    """Kills its own process the first time it meets kill*.png (a marker file
    beside OUTDIR remembers), and logs every bake it completes."""
    folder = os.path.dirname(job.dst[: -len(job.name) - 1])
    if os.path.basename(job.src).startswith("kill"):
        try:
            fd = os.open(os.path.join(folder, "killed.marker"), os.O_CREAT | os.O_EXCL | os.O_WRONLY)
            os.close(fd)
            os.kill(os.getpid(), signal.SIGKILL)
        except FileExistsError:
            pass
    result = batch.bake_job(job, threads, min_psnr)
    with open(os.path.join(folder, "bakes.log"), "a") as log:
        log.write(job.name + "\n")
    return result


# --- planning -------------------------------------------------------------------------


def test_plan_mirrors_folders_globs_and_files(tmp_path, rng):
    src = tmp_path / "art"
    good, _ = make_tree(src, rng, 7)
    (src / "notes.txt").write_text("not an image")
    (src / ".hidden.png").write_bytes(good[0].read_bytes())
    out = tmp_path / "out"
    jobs = batch.plan([src], out, recipe=BC1)
    names = sorted(j.name for j in jobs)
    assert names == sorted(os.path.relpath(p, src).replace(os.sep, "/")[:-4] + ".ktx2" for p in good)
    assert all(j.dst == str(out / j.name) for j in jobs)
    # a glob is relative to its folder part; a file to its name; dds by container
    jobs = batch.plan([str(src / "sub" / "**" / "*.png"), good[1]], out, recipe=BC1, container="dds")
    assert {j.name for j in jobs} == {"deep/tex0000.dds", "tex0003.dds", "deep/tex0006.dds", os.path.basename(good[1])[:-4] + ".dds"}
    # the same file named twice is baked once
    assert len(batch.plan([good[1], good[1], src], out, recipe=BC1)) == len(good)


def test_plan_refuses_collisions_missing_inputs_and_bad_containers(tmp_path, rng):
    good, _ = make_tree(tmp_path / "a", rng, 2)
    other = tmp_path / "b"
    other.mkdir()
    (other / good[1].name).write_bytes(good[1].read_bytes())
    with pytest.raises(UsageError, match="would both be baked"):
        batch.plan([good[1], other / good[1].name], tmp_path / "out", recipe=BC1)
    with pytest.raises(InputError, match="no such file"):
        batch.plan([tmp_path / "missing.png"], tmp_path / "out", recipe=BC1)
    with pytest.raises(UsageError, match="matches no image"):
        batch.plan([str(tmp_path / "*.exr")], tmp_path / "out", recipe=BC1)
    with pytest.raises(UsageError, match="zstd"):
        batch.plan([good[1]], tmp_path / "out", recipe=BC1.replace(zstd=3), container="dds")


def test_plan_leaves_out_the_output_folder(tmp_path, rng):
    good, _ = make_tree(tmp_path, rng, 3)
    out = tmp_path / "out"
    out.mkdir()
    (out / "old.png").write_bytes(good[1].read_bytes())
    assert len(batch.plan([tmp_path], out, recipe=BC1)) == 3


@pytest.mark.parametrize("pattern, path, hit", [
    ("*.png", "a/b/c.png", True), ("*_n.png", "a/rock_n.png", True), ("*_n.png", "a/rock.png", False),
    ("ui/*.png", "ui/a.png", True), ("ui/*.png", "ui/x/a.png", False), ("ui/**", "ui/x/a.png", True),
    ("**/n/*.tga", "n/a.tga", True), ("**/n/*.tga", "x/y/n/a.tga", True), ("tex?.png", "tex1.png", True),
    ("tex[0-4].png", "tex5.png", False), ("tex[!0-4].png", "tex5.png", True), ("**", "a/b", True),
])
def test_rule_patterns(pattern, path, hit):
    assert batch.Rule(pattern, BC1).matches(path) is hit


MANIFEST = """
container = "ktx2"
inputs = ["art"]

[defaults]
codec = { format = "bc1", preset = "fast" }
mips = { filter = "kaiser" }

[[rules]]
match = "*_n.png"
source = { normal_map = true }
codec = { format = "bc5" }
container = "dds"

[[rules]]
match = "ui/**"
mips = { enabled = false }

[[rules]]
match = "*.tif"
skip = true

[[rules]]
match = "sub/**"
codec = { preset = "thorough" }
"""


def test_manifest_rules_first_match_wins_over_defaults(tmp_path, rng):
    art = tmp_path / "art"
    for rel in ["rock_n.png", "ui/button.png", "ui/icon_n.png", "sub/a.png", "top.png", "skip.tif"]:
        (art / rel).parent.mkdir(parents=True, exist_ok=True)
        write_image(art / rel, rng.integers(0, 256, (8, 8, 3)).astype(np.uint8))
    (tmp_path / "textures.toml").write_text(MANIFEST)
    manifest = batch.load_manifest(tmp_path / "textures.toml")
    jobs = {j.name: j.recipe for j in batch.plan(manifest.inputs, tmp_path / "out", rules=manifest)}
    # top.png matches no rule: left out
    assert sorted(jobs) == ["rock_n.dds", "sub/a.ktx2", "ui/button.ktx2", "ui/icon_n.dds"]
    assert jobs["rock_n.dds"] == Recipe.of(format="bc5", preset="fast", normal_map=True, mip_filter="kaiser")
    assert jobs["ui/button.ktx2"] == Recipe.of(format="bc1", preset="fast", mips=False, mip_filter="kaiser")
    assert jobs["sub/a.ktx2"] == Recipe.of(format="bc1", preset="thorough", mip_filter="kaiser")


@pytest.mark.parametrize("text, message", [
    ("[[rules]]\nmatch = '*'\ncodec = { format = 'nope' }\n", "rule 1"),
    ("[[rules]]\ncodec = { format = 'bc1' }\n", "match"),
    ("[defaults]\n", "at least one"),
    ("inputz = []\n[[rules]]\nmatch='*'\n", "unknown manifest key"),
    ("[[rules]]\nmatch = '*'\ncontainer = 'png'\n", "container"),
    ("[[rules]\n", "not a readable manifest"),
])
def test_bad_manifests_are_usage_errors(tmp_path, text, message):
    path = tmp_path / "m.toml"
    path.write_text(text)
    with pytest.raises(UsageError, match=message):
        batch.load_manifest(path)


def test_why_and_the_state_file(tmp_path):
    src, out = tmp_path / "a.png", tmp_path / "out"
    write_image(src, np.zeros((4, 4, 3), np.uint8))
    out.mkdir()
    (job,) = batch.plan([src], out, recipe=BC1)
    sha = batch.file_sha256(src)
    (out / "a.ktx2").write_bytes(b"12345")
    entry = {"sha256": sha, "recipe": BC1.digest(), "texcook": batch.__version__, "bytes": 5}
    assert batch.why(job, entry, sha) == batch.UP_TO_DATE
    assert batch.why(job, entry, sha, force=True) == "forced"
    assert batch.why(job, None, sha) == "new"
    assert batch.why(job, dict(entry, texcook="0.0.1"), sha) == "texcook changed"
    assert batch.why(job, dict(entry, recipe="0" * 16), sha) == "recipe changed"
    assert batch.why(job, entry, "f" * 64) == "changed"
    assert batch.why(job, dict(entry, bytes=6), sha) == "output changed"
    assert batch.why(job, entry, sha, min_psnr=30) == "PSNR not measured"
    assert batch.why(job, dict(entry, psnr=31.0), sha, min_psnr=30) == batch.UP_TO_DATE
    assert batch.why(job, {k: v for k, v in entry.items() if k != "bytes"} | {"failed": "x"}, sha) == batch.FAILED_BEFORE
    (out / "a.ktx2").unlink()
    assert batch.why(job, entry, sha) == "output missing"
    # the state round-trips; an unreadable or foreign one counts as none (everything bakes again)
    batch.save_state(out, {"a.ktx2": entry})
    assert batch.load_state(out) == {"a.ktx2": entry}
    assert not temporaries(out)
    for text in ["{not json", '{"version": 99, "files": {}}', "[]"]:
        (out / batch.STATE_NAME).write_text(text)
        assert batch.load_state(out) == {}


# --- the batch through the command line ------------------------------------------------


def test_cli_corrupt_files_fail_alone_then_incremental(tmp_path, rng, cli_run):
    src, out = tmp_path / "src", tmp_path / "out"
    good, bad = make_tree(src, rng, 24, corrupt=4)
    report_path = tmp_path / "report.json"
    t0 = time.perf_counter()
    code, stdout, stderr = cli_run("batch", src, "-o", out, "-f", "bc1", "--preset", "fast", "-j", "2",
                                   "--report", report_path)
    first = time.perf_counter() - t0
    assert code == 1
    assert stdout.strip().startswith("batch: 24 baked, 0 skipped, 4 failed")
    report = json.loads(report_path.read_text())
    failed = [f for f in report["files"] if f["status"] == "failed"]
    assert sorted(f["input"] for f in failed) == sorted(str(p) for p in bad)
    for f in failed:
        assert f["reason"].startswith(f["input"] + ": ") and "\n" not in f["reason"]
        assert f"texcook: failed: {f['reason']}" in stderr
    assert any("end of file" in f["reason"] for f in failed)
    assert any("not an image file" in f["reason"] for f in failed)
    assert any("malicious header" in f["reason"] for f in failed)
    assert outputs(out) == sorted(os.path.relpath(p, src)[:-4] + ".ktx2" for p in good)
    assert not temporaries(out)
    baked = [f for f in report["files"] if f["status"] == "baked"]
    assert all(f["bytes"] == os.path.getsize(f["output"]) and f["recipe"] == BC1.digest() for f in baked)
    stamps = {p: os.stat(out / p).st_mtime_ns for p in outputs(out)}

    # second run: the good ones are up to date
    t0 = time.perf_counter()
    code, stdout, _ = cli_run("batch", src, "-o", out, "-f", "bc1", "--preset", "fast", "--report", report_path)
    second = time.perf_counter() - t0
    assert code == 1 and stdout.startswith("batch: 0 baked, 24 skipped, 4 failed")
    assert second < first
    assert {p: os.stat(out / p).st_mtime_ns for p in outputs(out)} == stamps
    report = json.loads(report_path.read_text())
    # the refused inputs are not read again until they change: same reasons, no bake
    assert sorted(f["reason"] for f in report["files"] if f["status"] == "failed") == sorted(f["reason"] for f in failed)
    assert {f["why"] for f in report["files"] if f["status"] == "failed"} == {batch.FAILED_BEFORE}

    # change one input's bytes (touch alone keeps them: content decides): exactly it rebakes
    for p in bad:
        p.unlink()
    write_image(good[5], rng.integers(0, 256, (9, 9, 3)).astype(np.uint8))
    os.utime(good[6])
    code, stdout, _ = cli_run("batch", src, "-o", out, "-f", "bc1", "--preset", "fast", "--dry-run")
    assert code == 0
    assert f"changed: {good[5]} -> " in stdout and stdout.count("up to date: ") == 23
    code, stdout, _ = cli_run("batch", src, "-o", out, "-f", "bc1", "--preset", "fast", "--report", report_path)
    assert code == 0 and stdout.startswith("batch: 1 baked, 23 skipped, 0 failed")
    changed = [f["input"] for f in json.loads(report_path.read_text())["files"] if f["status"] == "baked"]
    assert changed == [str(good[5])]

    # a changed recipe rebakes everything; a deleted output comes back
    (out / outputs(out)[0]).unlink()
    code, stdout, _ = cli_run("batch", src, "-o", out, "-f", "bc1", "--preset", "medium", "--dry-run")
    assert stdout.count("recipe changed: ") == 24
    code, stdout, _ = cli_run("batch", src, "-o", out, "-f", "bc1", "--preset", "fast", "--dry-run")
    assert stdout.count("output missing: ") == 1 and stdout.count("up to date: ") == 23
    code, stdout, _ = cli_run("batch", src, "-o", out, "-f", "bc1", "--preset", "medium")
    assert code == 0 and stdout.startswith("batch: 24 baked, 0 skipped")
    state = json.loads((out / batch.STATE_NAME).read_text())
    assert {state["files"][name]["recipe"] for name in outputs(out)} == {Recipe.of(format="bc1").digest()}


def test_up_to_date_run_never_loads_numba(tmp_path, rng):
    """What makes a no-op run cheap: recipes are checked and files skipped
    without loading the compiler or a kernel."""
    src, out = tmp_path / "src", tmp_path / "out"
    make_tree(src, rng, 12)
    args = ["batch", str(src), "-o", str(out), "-f", "bc1", "--preset", "fast"]
    probe = ("import sys\nfrom texcook.cli import main\nsys.argv = ['texcook'] + sys.argv[1:]\n"
             "try:\n    main()\nexcept SystemExit as e:\n    code = e.code\n"
             "print('numba loaded' if 'numba' in sys.modules else 'numba not loaded', code)")
    runs = [subprocess.run([sys.executable, "-c", probe, *args], cwd=ROOT, capture_output=True, text=True,
                           timeout=300) for _ in range(2)]
    assert runs[0].stdout.startswith("batch: 12 baked"), runs[0].stderr  # in worker processes
    assert runs[1].stdout.startswith("batch: 0 baked, 12 skipped") and "numba not loaded 0" in runs[1].stdout


def test_cli_min_psnr_measures_every_level(tmp_path, rng, cli_run):
    src, out = tmp_path / "src", tmp_path / "out"
    src.mkdir()
    write_image(src / "flat.png", np.full((16, 16, 3), 90, np.uint8))
    write_image(src / "noise.png", rng.integers(0, 256, (16, 16, 3)).astype(np.uint8))
    report_path = tmp_path / "r.json"
    code, stdout, stderr = cli_run("batch", src, "-o", out, "-f", "bc1", "--min-psnr", "40", "-j", "1",
                                   "--report", report_path)
    assert code == 1 and "1 below 40.0 dB" in stdout
    files = by_name(json.loads(report_path.read_text()))
    assert [row["level"] for row in files["noise.ktx2"]["levels"]] == [0, 1, 2, 3, 4]
    assert files["noise.ktx2"]["passed"] is False and files["noise.ktx2"]["psnr"] < 40
    assert files["flat.ktx2"]["passed"] is True
    assert "below --min-psnr" in stderr and "noise.ktx2" in stderr
    # the file that passed is recorded with its PSNR; the other runs again
    code, stdout, _ = cli_run("batch", src, "-o", out, "-f", "bc1", "--min-psnr", "40", "--dry-run")
    assert "up to date: " + str(src / "flat.png") in stdout and "new: " + str(src / "noise.png") in stdout


def test_dry_run_reads_each_plan_from_headers_alone(tmp_path, rng, cli_run, monkeypatch):
    """--dry-run gives each file to bake its bake plan, made in the parent from
    the header: a line naming format, colour space, levels and the steps that
    run, and the plan itself in the report. No pixel is read (the pixel reader
    fails here), so a file over the memory budget still plans, and a file with
    no readable header is reported as the bake would fail it."""
    from texcook import image
    from texcook.plan import plan_bake

    def no_pixels(*args):
        raise AssertionError("a dry run read pixels")

    src, out = tmp_path / "src", tmp_path / "out"
    src.mkdir()
    write_image(src / "colour.png", rng.integers(0, 256, (40, 24, 3)).astype(np.uint8))
    write_image(src / "mask.png", rng.integers(0, 256, (16, 16, 1)).astype(np.uint8), colour_space="linear")
    write_image(src / "huge.png", np.full((2048, 2048, 3), 90, np.uint8))  # a few kB, 12 MB of pixels
    (src / "junk.png").write_bytes(b"this is not a png\n")
    code, _, stderr = cli_run("--max-memory", "4M", "bake", src / "huge.png", "-o", tmp_path / "huge.ktx2")
    assert code == 1 and "memory" in stderr  # a bake refuses it before reading its pixels
    monkeypatch.setattr(image, "_read_image", no_pixels)
    report_path = tmp_path / "r.json"
    code, stdout, stderr = cli_run("--max-memory", "4M", "batch", src, "-o", out, "-f", "bc4", "--preset", "fast",
                                   "--dry-run", "--report", report_path)
    assert code == 1 and not out.exists()  # junk.png would fail; nothing is written
    files = by_name(json.loads(report_path.read_text()))
    for name in ("colour.ktx2", "mask.ktx2", "huge.ktx2"):
        entry = files[name]
        assert entry["status"] == "would bake", entry.get("reason")
        assert entry["plan"] == plan_bake(entry["input"], Recipe.of(format="bc4", preset="fast"), entry["output"],
                                          "ktx2").to_dict()
    assert files["colour.ktx2"]["plan"]["levels"][0] == [24, 40]
    assert len(files["huge.ktx2"]["plan"]["levels"]) == 12
    lines = {line.split(" -> ")[0]: line for line in stdout.splitlines() if " -> " in line}
    # bc4 has no sRGB variant: an sRGB source is stored linear, its values kept as data (no decode step)
    assert lines[f"new: {src / 'colour.png'}"].endswith(
        "colour.ktx2: bc4 linear, 6 levels, mips box clamp,clamp")
    assert lines[f"new: {src / 'huge.png'}"].endswith("huge.ktx2: bc4 linear, 12 levels, mips box clamp,clamp")
    assert lines[f"new: {src / 'junk.png'}"].endswith("junk.ktx2: would fail")
    assert files["junk.ktx2"]["status"] == "failed" and "plan" not in files["junk.ktx2"]
    assert stderr.count("texcook: failed: ") == 1 and f"failed: {src / 'junk.png'}: not an image file" in stderr
    assert stdout.rstrip().endswith("dry run: 3 to bake, 0 up to date, 1 failing")


def test_dry_run_line_follows_the_plan(tmp_path, rng, cli_run):
    """The line says what the plan says: the steps that run (here sRGB decoding
    and zstd), none that it skips (the mips), and only jobs to run are planned."""
    src, out = tmp_path / "src", tmp_path / "out"
    src.mkdir()
    write_image(src / "a.png", rng.integers(0, 256, (8, 8, 4)).astype(np.uint8))
    recipe = tmp_path / "r.json"
    recipe.write_text(json.dumps(Recipe.of(format="rgba8", zstd=3, mips=False).to_dict()))
    code, stdout, _ = cli_run("batch", src, "-o", out, "--recipe", recipe, "--dry-run")
    assert code == 0
    assert stdout.splitlines()[0] == f"new: {src / 'a.png'} -> {out / 'a.ktx2'}: rgba8 srgb, 1 level, decode, zstd level 3"
    assert cli_run("batch", src, "-o", out, "--recipe", recipe)[0] == 0
    code, stdout, _ = cli_run("batch", src, "-o", out, "--recipe", recipe, "--dry-run", "--report", tmp_path / "p.json")
    assert stdout.splitlines()[0] == f"up to date: {src / 'a.png'} -> {out / 'a.ktx2'}"
    assert "plan" not in json.loads((tmp_path / "p.json").read_text())["files"][0]


def test_cli_usage_errors(tmp_path, cli_run):
    assert cli_run("batch", "-o", tmp_path / "out")[0] == 2
    assert cli_run("batch", tmp_path, "-o", tmp_path / "out", "--dask", "remote")[0] == 2
    assert cli_run("batch", tmp_path, "-o", tmp_path / "out", "-f", "nope")[0] == 2
    (tmp_path / "m.toml").write_text("[[rules]]\nmatch='*'\n")
    code, _, stderr = cli_run("batch", "--manifest", tmp_path / "m.toml", "-f", "bc1", "-o", tmp_path / "out")
    assert code == 2 and "--manifest" in stderr


def test_recipe_that_does_not_fit_an_image_fails_that_image(tmp_path, rng):
    src, out = tmp_path / "src", tmp_path / "out"
    src.mkdir()
    write_image(src / "opaque.png", rng.integers(0, 256, (8, 8, 3)).astype(np.uint8))
    write_image(src / "cutout.png", rng.integers(0, 256, (8, 8, 4)).astype(np.uint8))
    jobs = batch.plan([src], out, recipe=BC1.replace(alpha_cutoff=0.5))
    files = by_name(batch.run(jobs, out, workers=1))
    assert files["cutout.ktx2"]["status"] == "baked"
    assert files["opaque.ktx2"]["status"] == "failed"
    assert files["opaque.ktx2"]["reason"] == f"{src / 'opaque.png'}: --alpha-cutoff needs a source with an alpha channel"
    assert outputs(out) == ["cutout.ktx2"]


# --- dying workers ---------------------------------------------------------------------


def test_worker_that_dies_fails_only_its_file(tmp_path, rng):
    src, out = tmp_path / "src", tmp_path / "out"
    good, _ = make_tree(src, rng, 10)
    write_image(src / "kill_me.png", rng.integers(0, 256, (8, 8, 3)).astype(np.uint8))
    jobs = batch.plan([src], out, recipe=BC1)
    seen = []
    report = batch.run(jobs, out, workers=2, worker_fn=kill_on_marked,
                       progress=lambda entry, count: seen.append((entry["name"], entry["status"], count)))
    files = by_name(report)
    assert sorted(seen) == sorted((f["name"], f["status"], 11) for f in report["files"])
    assert files["kill_me.ktx2"]["status"] == "failed"
    assert files["kill_me.ktx2"]["reason"].endswith(batch.WORKER_DIED)
    assert report["counts"] == {"baked": 10, "skipped": 0, "failed": 1} and not report["ok"]
    assert len(outputs(out)) == 10 and not temporaries(out)


@pytest.mark.parametrize("backend", ["processes", "dask"])
def test_killed_worker_still_finishes_every_file_once(tmp_path, rng, backend):
    if backend == "dask":
        pytest.importorskip("distributed")
    src, out = tmp_path / "src", tmp_path / "out"
    make_tree(src, rng, 12)
    write_image(src / "kill_me.png", rng.integers(0, 256, (8, 8, 3)).astype(np.uint8))
    jobs = batch.plan([src], out, recipe=BC1)
    report = batch.run(jobs, out, workers=2, backend=backend, worker_fn=kill_once)
    assert (tmp_path / "killed.marker").exists()
    assert report["counts"] == {"baked": 13, "skipped": 0, "failed": 0}, report["files"]
    assert len(report["files"]) == 13 and len(outputs(out)) == 13 and not temporaries(out)
    # every file's bake completed; with worker processes a job that finished on a
    # surviving worker just as the pool broke may run again (same bytes, renamed
    # atomically), so the log holds each name at least once
    log = (tmp_path / "bakes.log").read_text().split()
    assert set(log) == {j.name for j in jobs}
    if backend == "dask":
        assert sorted(log) == sorted(j.name for j in jobs)


# --- Dask -----------------------------------------------------------------------------


def test_dask_local_gives_the_same_bytes(tmp_path, rng, cli_run):
    pytest.importorskip("distributed")
    src = tmp_path / "src"
    make_tree(src, rng, 12, corrupt=2)
    code, stdout, _ = cli_run("batch", src, "-o", tmp_path / "p", "-f", "bc1", "-j", "2")
    assert code == 1 and "12 baked" in stdout
    report = tmp_path / "dask.json"
    code, stdout, _ = cli_run("batch", src, "-o", tmp_path / "d", "-f", "bc1", "--dask", "local:2", "--report", report)
    assert code == 1 and stdout.startswith("batch: 12 baked, 0 skipped, 2 failed")
    assert json.loads(report.read_text())["backend"] == "dask"
    names = outputs(tmp_path / "p")
    assert names == outputs(tmp_path / "d") and len(names) == 12
    for name in names:
        assert (tmp_path / "p" / name).read_bytes() == (tmp_path / "d" / name).read_bytes()
    # the state is the same too: the process backend sees the Dask bake as up to date
    code, stdout, _ = cli_run("batch", src, "-o", tmp_path / "d", "-f", "bc1", "--dry-run")
    assert stdout.count("up to date: ") == 12


# --- SIGINT ----------------------------------------------------------------------------


def test_sigint_keeps_what_finished_and_resumes(tmp_path, rng):
    src, out = tmp_path / "src", tmp_path / "out"
    make_tree(src, rng, 40, sizes=[(96, 96), (64, 128)])
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-m", "texcook.cli", "batch", str(src), "-o", str(out), "-f", "bc1",
           "--preset", "thorough", "-j", "1"]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=interruptible)
    deadline = time.monotonic() + 120
    while not (out.exists() and len(outputs(out)) >= 3):
        assert time.monotonic() < deadline and proc.poll() is None
        time.sleep(0.02)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    assert "interrupted" in stderr
    done = outputs(out)
    assert 0 < len(done) < 40 and not temporaries(out)
    state = json.loads((out / batch.STATE_NAME).read_text())["files"]
    assert 0 < len(state) and set(state) <= set(done)
    # the next run bakes only what was not recorded
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith(f"batch: {40 - len(state)} baked, {len(state)} skipped, 0 failed")
    assert len(outputs(out)) == 40 and not temporaries(out)


# --- the acceptance run ----------------------------------------------------------------


@pytest.mark.skipif(not os.environ.get("TEXCOOK_LONG"), reason="set TEXCOOK_LONG=1 for the 1,000-texture run")
def test_thousand_textures_acceptance(tmp_path, rng):
    """Each run is a whole `texcook batch` process, start-up included."""
    src, out = tmp_path / "src", tmp_path / "out"
    good, bad = make_tree(src, rng, 990, corrupt=10,
                          sizes=[(1, 1), (7, 13), (32, 32), (64, 64), (100, 60), (128, 128), (256, 256)])
    report_path = tmp_path / "r.json"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-m", "texcook.cli", "batch", str(src), "-o", str(out), "-f", "bc1",
           "--report", str(report_path)]

    def timed():
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=3000)
        return time.perf_counter() - t0, proc

    first, proc = timed()
    assert proc.returncode == 1 and proc.stdout.startswith("batch: 990 baked, 0 skipped, 10 failed"), proc.stdout
    assert len(outputs(out)) == 990 and not temporaries(out)
    failed = [f for f in json.loads(report_path.read_text())["files"] if f["status"] == "failed"]
    assert sorted(f["input"] for f in failed) == sorted(str(p) for p in bad) and all(f["reason"] for f in failed)
    assert proc.stderr.count("texcook: failed: ") == 10
    second, proc = timed()
    assert proc.returncode == 1 and proc.stdout.startswith("batch: 0 baked, 990 skipped, 10 failed"), proc.stdout
    # the same through the library, as a build system calls it: no process start-up
    t0 = time.perf_counter()
    report = batch.run(batch.plan([src], out, recipe=Recipe.of(format="bc1")), out)
    second_api = time.perf_counter() - t0
    assert report["counts"] == {"baked": 0, "skipped": 990, "failed": 10}
    write_image(good[123], rng.integers(0, 256, (20, 20, 3)).astype(np.uint8))
    third, proc = timed()
    assert proc.stdout.startswith("batch: 1 baked, 989 skipped, 10 failed"), proc.stdout
    baked = [f["input"] for f in json.loads(report_path.read_text())["files"] if f["status"] == "baked"]
    assert baked == [str(good[123])]
    print(f"\nfirst run {first:.1f} s; second, all skipped: {second:.2f} s = {100 * second / first:.1f}% "
          f"as a command, {second_api:.2f} s = {100 * second_api / first:.1f}% through batch.run; "
          f"one changed {third:.1f} s (load average {os.getloadavg()[0]:.1f})")
    assert second < 0.05 * first and second_api < 0.05 * first
    if importlib.util.find_spec("distributed") is None:
        return
    cmd = [sys.executable, "-m", "texcook.cli", "batch", str(src), "-o", str(tmp_path / "dask"), "-f", "bc1",
           "--dask", "local:2"]
    took, proc = timed()
    assert proc.stdout.startswith("batch: 990 baked, 0 skipped, 10 failed"), proc.stdout
    names = outputs(out)
    assert names == outputs(tmp_path / "dask")
    assert all((out / n).read_bytes() == (tmp_path / "dask" / n).read_bytes() for n in names)
    print(f"--dask local:2: {took:.1f} s, {len(names)} outputs byte-identical")
