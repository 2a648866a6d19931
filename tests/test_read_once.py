"""Work done once: a scene plans each bake once (scene.json's steps and the bake
read the same plan), and a batch worker reads an input's bytes once when the
run hashed them already, keeping the before/after check of a bake."""

import dataclasses
import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
from conftest import encoded_image
from test_scene import build

from texcook import batch, fileio, plan, scene
from texcook.recipe import Recipe

BC1 = Recipe.of(format="bc1", preset="fastest")


def _header_plans(monkeypatch):
    """Counts the plans made from an image's header (not the settling of one)."""
    made = []
    real = plan._plan

    def counted(header, recipe, output, container, sat, colour, dropped):
        if colour is None and dropped is None:
            made.append(header.path)
        return real(header, recipe, output, container, sat, colour, dropped)

    monkeypatch.setattr(plan, "_plan", counted)
    return made


def test_a_scene_plans_each_bake_once_and_bakes_that_plan(tmp_path, rng, monkeypatch):
    images = {"albedo": rng.integers(0, 256, (16, 16, 4), dtype=np.uint8),
              "orm": rng.integers(0, 256, (16, 16, 3), dtype=np.uint8)}
    model = build(tmp_path / "m.gltf", images, [("albedo", None), ("orm", None)],
                  [{"name": "m", "alphaMode": "MASK", "slots": {"baseColorTexture": 0, "occlusionTexture": 1}}])
    made = _header_plans(monkeypatch)
    report = scene.bake_scene(model, tmp_path / "out", preset="fastest", zstd=3)
    assert len(report["bakes"]) == 2
    assert len(made) == 2  # one plan per bake, not one for scene.json and another for the bake
    # the plan the steps were read from is the one that ran: its zstd level is the bake's
    for bake in report["bakes"]:
        data = (tmp_path / "out" / bake["output"]).read_bytes()
        assert int.from_bytes(data[44:48], "little") == 2  # KTX2 supercompressionScheme: Zstandard
    assert json.loads((tmp_path / "out" / "scene.json").read_text())["zstd"] == 3


def _reads(monkeypatch, path):
    """Counts whole-file reads of `path` through texcook.fileio."""
    reads = []
    real = fileio.read_bytes

    def counted(p, what="file"):
        if Path(p) == Path(path):
            reads.append(what)
        return real(p, what)

    monkeypatch.setattr(fileio, "read_bytes", counted)
    monkeypatch.setattr(batch, "read_bytes", counted)
    return reads


def _job(tmp_path, rng):
    src = tmp_path / "a.png"
    src.write_bytes(encoded_image(rng.integers(0, 256, (8, 8, 3), dtype=np.uint8)))
    (job,) = batch.plan([src], tmp_path / "out", recipe=BC1)
    (tmp_path / "out").mkdir()
    return job, src


def test_a_batch_worker_reads_an_input_hashed_by_the_run_once(tmp_path, rng, monkeypatch):
    job, src = _job(tmp_path, rng)
    sha = hashlib.sha256(src.read_bytes()).hexdigest()
    reads = _reads(monkeypatch, src)
    result = batch.bake_job(dataclasses.replace(job, sha256=sha))
    assert result["status"] == "baked" and result["sha256"] == sha
    assert reads == ["input"]  # the hash after the bake; the run's hash stands for the one before


def test_a_batch_worker_without_the_runs_hash_takes_its_own(tmp_path, rng, monkeypatch):
    job, src = _job(tmp_path, rng)
    reads = _reads(monkeypatch, src)
    result = batch.bake_job(job)
    assert reads == ["input", "input"]  # before and after the bake
    assert result["status"] == "baked" and result["sha256"] == hashlib.sha256(src.read_bytes()).hexdigest()


@pytest.mark.parametrize("changes", [1, 2])
def test_an_input_changed_since_the_runs_hash_is_baked_again_or_fails(tmp_path, rng, monkeypatch, changes):
    """The run's hash is the first bake's before-hash: bytes that differ from it
    after the bake are baked once more (from the bytes just hashed), and bytes
    that change again fail the job unrecorded."""
    job, src = _job(tmp_path, rng)
    sha = hashlib.sha256(src.read_bytes()).hexdigest()
    bakes = []
    real = batch._bake_once

    def bake_then_edit(job, threads, min_psnr):
        out = real(job, threads, min_psnr)
        bakes.append(1)
        if len(bakes) <= changes:
            src.write_bytes(encoded_image(rng.integers(0, 256, (8, 8, 3), dtype=np.uint8)))
        return out

    monkeypatch.setattr(batch, "_bake_once", bake_then_edit)
    result = batch.bake_job(dataclasses.replace(job, sha256=sha))
    assert len(bakes) == 2
    if changes == 1:
        assert result["status"] == "baked" and result["sha256"] == batch.file_sha256(src) != sha
    else:
        assert result["status"] == "failed" and batch.CHANGED_WHILE_BAKED in result["reason"]
        assert result["sha256"] is None


def test_a_run_hands_its_hash_to_the_worker(tmp_path, rng):
    job, src = _job(tmp_path, rng)
    report = batch.run([job], tmp_path / "out", workers=1, worker_fn=_hash_given)
    (entry,) = report["files"]
    assert entry["status"] == "baked" and entry["given"] == batch.file_sha256(src)


def _hash_given(job, threads, min_psnr):  # module level: worker processes import it
    return dict(batch.bake_job(job, threads, min_psnr), given=job.sha256)
