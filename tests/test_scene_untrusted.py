"""texcook scene against hostile or broken glTF models: nothing outside the
model's folder is read or copied, nothing blocks, and every problem is one
line naming the model and the object, found before any texture is baked."""

import base64
import json
import os
import signal
import tempfile
from pathlib import Path

import numpy as np
import pytest

from conftest import encoded_image
from texcook import scene
from texcook.errors import InputError

SECRET = b"\x89PNG-not-really: secret marker 7f3a"




PNG = encoded_image(np.random.default_rng(5).integers(0, 256, (8, 8, 3), dtype=np.uint8))


def gltf(images, buffers=(), views=(), textures=None, materials=None, **extra):
    """A glTF JSON dict: one opaque material per texture, one texture per image."""
    textures = [{"source": i} for i in range(len(images))] if textures is None else textures
    materials = ([{"name": f"m{t}", "pbrMetallicRoughness": {"baseColorTexture": {"index": t}}}
                  for t in range(len(textures))] if materials is None else materials)
    doc = {"asset": {"version": "2.0"}, "images": list(images), "textures": textures, "materials": materials}
    if buffers:
        doc["buffers"] = list(buffers)
    if views:
        doc["bufferViews"] = list(views)
    doc.update(extra)
    return doc


@pytest.fixture
def tree(tmp_path):
    """tmp/model (the model's folder), tmp/secret (outside it, holding a
    marker file and a PNG that must never be baked), tmp/out (OUTDIR)."""
    model = tmp_path / "model"
    secret = tmp_path / "secret"
    model.mkdir()
    secret.mkdir()
    (secret / "key.txt").write_bytes(SECRET)
    (secret / "outside.png").write_bytes(PNG)
    (secret / "data.bin").write_bytes(SECRET + b"\0" * 64)
    (model / "ok.png").write_bytes(PNG)
    return model, secret, tmp_path / "out"


def write(folder, doc, name="m.gltf"):
    path = Path(folder) / name
    path.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return path


@pytest.fixture
def no_hang():
    """Fail, rather than hang, a call that blocks for more than 20 s."""

    def alarm(signum, frame):
        raise TimeoutError("blocked: the FIFO or device was opened")

    old = signal.signal(signal.SIGALRM, alarm)
    signal.alarm(20)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, old)


def cli_limited(*args):
    """texcook in a child process with 2 GiB of address space and a minute:
    a regression that reads /dev/zero fails the test, not the machine."""
    import resource
    import subprocess
    import sys

    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30))

    proc = subprocess.run([sys.executable, "-c", "from texcook.cli import cli; cli(prog_name='texcook')",
                           *map(str, args)], capture_output=True, text=True, timeout=60, preexec_fn=limit)
    return proc.returncode, proc.stderr


def refused(model_path, out, *words):
    """bake_scene refuses with one line naming the model and `words`; nothing
    is baked or copied into `out`."""
    with pytest.raises(InputError) as err:
        scene.bake_scene(model_path, out, preset="fastest")
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(str(model_path) + ": "), msg
    for w in words:
        assert w in msg, msg
    assert not out.exists() or not any(p.is_file() for p in out.rglob("*")), list(out.rglob("*"))
    return msg


def no_secret_in(out):
    for p in Path(out).rglob("*"):
        if p.is_file():
            assert SECRET not in p.read_bytes(), p


# ----------------------------------------------------------------------------- uris that leave the folder


def test_an_absolute_image_uri_is_refused(tree):
    model, _, out = tree
    path = write(model, gltf([{"uri": "ok.png"}, {"uri": "/etc/passwd"}]))
    refused(path, out, "image 1 (/etc/passwd)", "absolute paths are not read")


def test_a_used_image_outside_the_folder_is_not_baked(tree):
    model, _, out = tree
    path = write(model, gltf([{"uri": "../secret/outside.png"}]))
    refused(path, out, "image 0 (../secret/outside.png)", "leaves the model's folder")


def test_an_unused_image_outside_the_folder_is_not_copied(tree):
    model, _, out = tree
    path = write(model, gltf([{"uri": "ok.png"}, {"uri": "../secret/key.txt"}], textures=[{"source": 0}]))
    refused(path, out, "image 1", "leaves the model's folder")
    no_secret_in(out)


def test_percent_encoded_dot_dot_is_decoded_then_refused(tree):
    model, _, out = tree
    path = write(model, gltf([{"uri": "..%2Fsecret%2Foutside.png"}]))
    refused(path, out, "image 0 (..%2Fsecret%2Foutside.png)", "leaves the model's folder")


@pytest.mark.parametrize("used", [True, False], ids=["used", "unused"])
def test_an_image_symlink_out_of_the_folder_is_refused(tree, used):
    model, secret, out = tree
    os.symlink(secret / "outside.png", model / "link.png")
    textures = [{"source": 0}, {"source": 1}] if used else [{"source": 0}]
    path = write(model, gltf([{"uri": "ok.png"}, {"uri": "link.png"}], textures=textures))
    refused(path, out, "image 1 (link.png)", "a symlink that leads out of the model's folder")


@pytest.mark.parametrize("used", [True, False], ids=["used", "unused"])
def test_a_buffer_symlink_out_of_the_folder_is_refused(tree, used):
    model, secret, out = tree
    os.symlink(secret / "data.bin", model / "data.bin")
    if used:  # the image lives in the linked buffer
        (secret / "data.bin").write_bytes(PNG)
        images = [{"bufferView": 0, "mimeType": "image/png"}]
        views = [{"buffer": 0, "byteLength": len(PNG)}]
    else:  # geometry only: the rewritten model would take a copy
        images, views = [{"uri": "ok.png"}], [{"buffer": 0, "byteLength": 16}]
    path = write(model, gltf(images, buffers=[{"uri": "data.bin", "byteLength": len(PNG)}], views=views))
    refused(path, out, "buffer 0 (data.bin)", "a symlink that leads out of the model's folder")
    no_secret_in(out)


def test_a_linked_folder_does_not_carry_a_path_out(tree):
    model, secret, out = tree
    os.symlink(secret, model / "tex")
    path = write(model, gltf([{"uri": "tex/outside.png"}]))
    refused(path, out, "image 0 (tex/outside.png)", "a symlink that leads out")


@pytest.mark.parametrize("uri, words", [
    ("file:///etc/passwd", "file:// uris are not read"),
    ("http://example.com/a.png", "http:// uris are not fetched"),
    ("https://example.com/a.png", "https:// uris are not fetched"),
])
def test_uris_with_a_scheme_are_not_read_or_fetched(tree, uri, words):
    model, _, out = tree
    path = write(model, gltf([{"uri": uri}]))
    msg = refused(path, out, "image 0", words)
    assert "no such file" not in msg


# ----------------------------------------------------------------------------- files that would block


@pytest.mark.parametrize("kind", ["fifo", "dev-zero-link", "folder"])
@pytest.mark.parametrize("role", ["image", "buffer"])
def test_non_regular_files_are_refused_at_once(tree, no_hang, kind, role):
    model, _, out = tree
    if kind == "fifo":
        os.mkfifo(model / "x.dat")
        why = "is a pipe (FIFO), not a regular file"
    elif kind == "folder":
        (model / "x.dat").mkdir()
        why = "is a directory"
    else:
        os.symlink("/dev/zero", model / "x.dat")
        why = "a symlink that leads out of the model's folder"
    if role == "image":
        doc = gltf([{"uri": "x.dat"}])
    else:
        doc = gltf([{"bufferView": 0, "mimeType": "image/png"}], buffers=[{"uri": "x.dat", "byteLength": 64}],
                   views=[{"buffer": 0, "byteLength": 64}])
    if kind == "dev-zero-link":
        code, stderr = cli_limited("scene", write(model, doc), "-o", out)
        assert code == 1 and f"{role} 0 (x.dat): {why}" in stderr and stderr.count("\n") == 1, stderr
    else:
        refused(write(model, doc), out, f"{role} 0 (x.dat)", why)


def test_dev_zero_by_absolute_uri_is_refused(tree):
    model, _, out = tree
    doc = gltf([{"uri": "ok.png"}], buffers=[{"uri": "/dev/zero", "byteLength": 1 << 30}],
               views=[{"buffer": 0, "byteLength": 16}])
    code, stderr = cli_limited("scene", write(model, doc), "-o", out)
    assert code == 1 and "buffer 0 (/dev/zero): absolute paths are not read" in stderr, stderr
    assert not out.exists()


def test_the_model_itself_as_a_fifo_is_refused(tmp_path, no_hang):
    os.mkfifo(tmp_path / "m.gltf")
    with pytest.raises(InputError, match="is a pipe"):
        scene.load_model(tmp_path / "m.gltf")


# ----------------------------------------------------------------------------- broken JSON and GLB


def load_error(path):
    with pytest.raises(InputError) as err:
        scene.load_model(path)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(str(path) + ": "), msg
    return msg.split(": ", 1)[1]


def test_bad_base64_names_the_model_and_the_image_not_a_temporary(tree):
    model, _, out = tree
    path = write(model, gltf([{"uri": "data:image/png;base64,iVBORw0KGgo@@@@not base64"}]))
    msg = refused(path, out, "image 0 (data:image/png;base64,", "not valid base64")
    assert tempfile.gettempdir() not in msg.split(": ", 1)[1]


def test_bad_base64_in_a_buffer(tree):
    model, _, out = tree
    doc = gltf([{"bufferView": 0, "mimeType": "image/png"}],
               buffers=[{"uri": "data:application/octet-stream;base64,AAAA*AAA", "byteLength": 6}],
               views=[{"buffer": 0, "byteLength": 6}])
    refused(write(model, doc), out, "buffer 0", "not valid base64")


def test_deep_json_is_one_line(tree, cli_run):
    model, _, out = tree
    deep = 100_000
    path = write(model, '{"asset": {"version": "2.0"}, "extras": ' + "[" * deep + "]" * deep + "}")
    code, stdout, stderr = cli_run("scene", path, "-o", out)
    assert code == 1 and stderr.count("\n") == 1, stderr
    assert "nests deeper than" in stderr and str(path) in stderr


def test_moderately_deep_json_is_refused_before_it_can_break_the_writer(tree):
    model, _, _ = tree
    path = write(model, '{"asset": {"version": "2.0"}, "extras": ' + "[" * 500 + "]" * 500 + "}")
    assert "nests deeper than" in load_error(path)


def test_a_root_that_is_a_list(tree, cli_run):
    model, _, out = tree
    path = write(model, "[]")
    code, _, stderr = cli_run("scene", path, "-o", out)
    assert code == 1 and "the JSON root is a list, not an object" in stderr and str(path) in stderr


def test_bad_utf8(tree):
    model, _, _ = tree
    path = model / "m.gltf"
    path.write_bytes(b'{"asset": {"version": "2.0", "generator": "\xff\xfe"}}')
    assert "not UTF-8" in load_error(path)


def test_not_gltf(tree):
    model, _, _ = tree
    assert "no asset" in load_error(write(model, {"hello": 1}))


def glb(json_bytes, bin_bytes=None, lie=None):
    import struct

    json_bytes += b" " * (-len(json_bytes) % 4)
    body = struct.pack("<I4s", len(json_bytes), b"JSON") + json_bytes
    if bin_bytes is not None:
        n = len(bin_bytes) if lie is None else lie
        body += struct.pack("<I4s", n, b"BIN\0") + bin_bytes
    return b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body


def test_glb_chunk_lengths_that_lie(tree):
    model, _, _ = tree
    doc = json.dumps(gltf([{"uri": "ok.png"}], buffers=[{"byteLength": 8}])).encode()
    path = model / "m.glb"
    path.write_bytes(glb(doc, b"\0" * 8, lie=1 << 20))
    assert "GLB chunk 1 declares 1048576 bytes, only 8 follow" in load_error(path)
    path.write_bytes(glb(doc, b"\0" * 8)[:-4])  # the header's total length lies too
    assert "the GLB header says" in load_error(path)


def test_a_glb_buffer_shorter_than_its_byte_length(tree):
    model, _, _ = tree
    doc = json.dumps(gltf([{"uri": "ok.png"}], buffers=[{"byteLength": 64}])).encode()
    path = model / "m.glb"
    path.write_bytes(glb(doc, b"\0" * 8))
    assert "buffer 0 holds 8 bytes in the GLB binary chunk, less than its byteLength 64" in load_error(path)


# ----------------------------------------------------------------------------- indices, offsets, numbers


def embedded(views, buffer_length=len(PNG), image_view=0):
    return gltf([{"bufferView": image_view, "mimeType": "image/png"}],
                buffers=[{"uri": "b.bin", "byteLength": buffer_length}], views=views)


@pytest.mark.parametrize("doc, words", [
    (embedded([{"buffer": 0, "byteLength": 8}], image_view=3), "image 0 names bufferView 3, which does not exist"),
    (embedded([{"buffer": 7, "byteLength": 8}]), "bufferView 0 names buffer 7, which does not exist"),
    (embedded([{"buffer": 0}]), "bufferView 0 has no byteLength"),
    (embedded([{"buffer": 0, "byteLength": 8}], image_view=-1), "image 0 has bufferView -1, not an index"),
    (embedded([{"buffer": -1, "byteLength": 8}]), "bufferView 0 has buffer -1, not an index"),
    (embedded([{"buffer": 0, "byteOffset": -8, "byteLength": 8}]), "bufferView 0 has byteOffset -8, not an integer"),
    (embedded([{"buffer": 0, "byteOffset": 1.5, "byteLength": 8}]), "bufferView 0 has byteOffset 1.5"),
    (embedded([{"buffer": 0, "byteOffset": 64, "byteLength": len(PNG)}]),
     f"bufferView 0 (bytes 64 to {64 + len(PNG)}) ends past buffer 0's byteLength {len(PNG)}"),
    (gltf([{"uri": "ok.png"}], buffers=[{"uri": "b.bin"}]), "buffer 0 has no byteLength"),
    (gltf([{"uri": "ok.png"}], textures=[{"source": 4}]), "texture 0 names image 4, which does not exist"),
    (gltf([{"uri": "ok.png"}], textures=[{"source": 0, "sampler": 2}]),
     "texture 0 names sampler 2, which does not exist"),
    (gltf([{"uri": "ok.png"}], materials=[{"pbrMetallicRoughness": {"baseColorTexture": {"index": -1}}}]),
     "material 0 baseColorTexture has index -1"),
    (gltf([{"uri": "ok.png"}], materials=[{"alphaMode": "MASK", "alphaCutoff": -0.5}]),
     "material 0 has alphaCutoff -0.5"),
    (gltf([{"uri": "ok.png"}], materials=[{"pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1]}}]),
     "material 0 has baseColorFactor [1, 1, 1], not four numbers"),
    (gltf([{"uri": "ok.png"}], samplers=[{"minFilter": 1234}]), "sampler 0 has minFilter 1234"),
], ids=["view-range", "buffer-range", "no-byteLength", "negative-view", "negative-buffer", "negative-offset",
        "float-offset", "past-the-buffer", "buffer-no-byteLength", "source-range", "sampler-range",
        "negative-texture", "negative-cutoff", "factor-shape", "min-filter"])
def test_indices_and_offsets_are_checked_before_any_work(tree, doc, words):
    model, _, _ = tree
    (model / "b.bin").write_bytes(PNG)
    assert words in load_error(write(model, doc))


@pytest.mark.parametrize("value", ["NaN", "Infinity", "-Infinity", "1e400"])
def test_a_cutoff_that_is_not_finite_is_refused_before_any_bake(tree, value, cli_run):
    model, _, out = tree
    text = json.dumps(gltf([{"uri": "ok.png"}], materials=[
        {"alphaMode": "MASK", "alphaCutoff": 12345, "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]))
    path = write(model, text.replace("12345", value))
    code, _, stderr = cli_run("scene", path, "-o", out, "--preset", "fastest")
    assert code == 1 and "materials[0].alphaCutoff is" in stderr and "finite" in stderr, stderr
    assert not out.exists()


def test_a_buffer_file_shorter_than_its_byte_length(tree):
    model, _, out = tree
    (model / "b.bin").write_bytes(PNG)
    doc = gltf([{"bufferView": 0, "mimeType": "image/png"}], buffers=[{"uri": "b.bin", "byteLength": 4096}],
               views=[{"buffer": 0, "byteLength": len(PNG)}])
    refused(write(model, doc), out, f"buffer 0 (b.bin): holds {len(PNG)} bytes, less than its byteLength 4096")


# ----------------------------------------------------------------------------- before any bake


@pytest.fixture
def bakes_started(monkeypatch):
    """The sources pipeline.bake_file was called with (a bake that started)."""
    from texcook import pipeline

    started = []
    real = pipeline.bake_file

    def watch(src, *args, **kwargs):
        started.append(src)
        return real(src, *args, **kwargs)

    monkeypatch.setattr(pipeline, "bake_file", watch)
    return started


def test_a_truncated_jpeg_is_found_before_any_bake(tree, bakes_started):
    model, _, out = tree
    jpg = encoded_image(np.random.default_rng(7).integers(0, 256, (64, 64, 3), dtype=np.uint8), ".jpg")
    (model / "cut.jpg").write_bytes(jpg[: len(jpg) // 2])
    # image 0 (good) is baked first in the plan's order: it must not be started
    path = write(model, gltf([{"uri": "ok.png"}, {"uri": "cut.jpg"}]))
    refused(path, out, "image 1 (cut.jpg)", "Premature end of JPEG file")
    assert bakes_started == []


def test_a_missing_buffer_is_found_before_any_bake(tree, bakes_started):
    model, _, out = tree
    doc = gltf([{"uri": "ok.png"}], buffers=[{"uri": "geometry.bin", "byteLength": 16}],
               views=[{"buffer": 0, "byteLength": 16}])
    refused(write(model, doc), out, "buffer 0 (geometry.bin): no such file")
    assert bakes_started == []


def test_the_watch_sees_bakes(tree, bakes_started):
    model, _, out = tree
    scene.bake_scene(write(model, gltf([{"uri": "ok.png"}])), out, preset="fastest")
    assert bakes_started == [os.path.realpath(model / "ok.png")]


def test_every_refusal_is_returned_as_data(tree):
    """read_sources reports each problem, not the first only; the images it
    could read are sources, the refused ones say why."""
    model, secret, _ = tree
    doc = gltf([{"uri": "ok.png"}, {"uri": "../secret/outside.png"}, {"uri": "http://x/y.png"},
                {"uri": "gone.png"}, {"uri": "/etc/passwd"}],
               buffers=[{"uri": "../secret/data.bin", "byteLength": 8}], views=[{"buffer": 0, "byteLength": 8}],
               textures=[{"source": i} for i in range(4)])
    m = scene.load_model(write(model, doc))
    with tempfile.TemporaryDirectory() as work:
        sources, refusals = scene.read_sources(m, work, {0, 1, 2, 3})
    assert sources[0].path == os.path.realpath(model / "ok.png") and sources[0].why == ""
    assert [s.path for i, s in sorted(sources.items()) if i] == [None, None, None]
    assert "leaves the model's folder" in sources[1].why
    got = {r.what: (r.uri, r.why) for r in refusals}
    assert got == {
        "image 1": ("../secret/outside.png", "leaves the model's folder"),
        "image 2": ("http://x/y.png", "http:// uris are not fetched"),
        "image 3": ("gone.png", "no such file"),
        "buffer 0": ("../secret/data.bin", "leaves the model's folder"),
        "image 4": ("/etc/passwd", "absolute paths are not read"),
    }


def test_nothing_outside_the_folder_is_opened(tree, monkeypatch, cli_run):
    """Every file opened during a scene with hostile uris is inside the
    model's folder (or texcook's own working files): os.open is watched."""
    model, secret, out = tree
    os.symlink(secret / "key.txt", model / "key.png")
    doc = gltf([{"uri": "ok.png"}, {"uri": "key.png"}, {"uri": "..%2fsecret/key.txt"}, {"uri": str(secret)}],
               buffers=[{"uri": "../secret/data.bin", "byteLength": 8}], views=[{"buffer": 0, "byteLength": 8}])
    path = write(model, doc)
    opened = []
    real_open = os.open

    def watch(p, *args, **kwargs):
        opened.append(os.path.realpath(os.fsdecode(p)) if not isinstance(p, int) else p)
        return real_open(p, *args, **kwargs)

    monkeypatch.setattr(os, "open", watch)
    code, _, stderr = cli_run("scene", path, "-o", out)
    monkeypatch.undo()
    assert code == 1 and str(path) in stderr
    assert not [p for p in opened if isinstance(p, str) and p.startswith(str(secret.resolve()))]
    no_secret_in(out)


def test_a_good_model_with_a_relative_subfolder_still_bakes(tree):
    """The checks refuse only what leaves the folder: a subfolder, `./`, a
    `..` that comes back in and percent-encoded names are read as before."""
    model, _, out = tree
    (model / "tex").mkdir()
    (model / "tex" / "a b.png").write_bytes(PNG)
    (model / "b.bin").write_bytes(PNG)
    doc = gltf([{"uri": "tex/a%20b.png"}, {"uri": "./ok.png"}, {"uri": "tex/../ok.png"},
                {"bufferView": 0, "mimeType": "image/png"},
                {"uri": "data:image/png;base64," + base64.b64encode(PNG).decode()}],
               buffers=[{"uri": "b.bin", "byteLength": len(PNG)}], views=[{"buffer": 0, "byteLength": len(PNG)}])
    report = scene.bake_scene(write(model, doc), out, preset="fastest")
    assert len(list(out.glob("*.ktx2"))) == 5 and not report["not_baked"]
    assert (out / "tex" / "a b.png").read_bytes() == PNG and (out / "b.bin").read_bytes() == PNG
