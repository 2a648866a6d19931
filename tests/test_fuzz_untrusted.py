"""Property-based fuzzing of the files that scene, batch and preview read but
did not make: glTF JSON, GLB chunks, batch manifests, batch state files and a
preview's scene.json.

Each case starts from a small valid file and damages it: values anywhere in the
JSON tree replaced by hostile ones (negative, huge and non-integer indices,
NaN, escaping uris, wrong types, deep nesting), keys deleted, GLB chunk lengths
and bytes changed, TOML rules with bad patterns. The property: the command
either succeeds or raises texcook's documented error (a TexcookError, one line
naming the file); nothing else escapes, every case ends within a time limit,
nothing is read from outside the model's folder (a secret file beside it never
reaches an output) and nothing is written outside the output folder.

The normal run takes a few seconds per test and is derandomized. The long run:

    TEXCOOK_FUZZ_EXAMPLES=20000 python -m pytest tests/test_fuzz_untrusted.py -p no:cacheprovider

runs that many cases per test (five tests: 100,000 in all) with a random seed.
"""

import base64
import copy
import json
import os
import shutil
import signal
import struct
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from conftest import encoded_image  # noqa: E402
from texcook.errors import TexcookError  # noqa: E402
from texcook.fileio import set_max_memory  # noqa: E402

LONG = int(os.environ.get("TEXCOOK_FUZZ_EXAMPLES", "0"))
CASE_SECONDS = 30  # one case (a tiny model, a handful of 8x8 bakes) takes well under a second
SECRET = b"texcook-fuzz-secret-\x00\x01never-read"

FUZZ = settings(
    max_examples=LONG or 40,
    derandomize=not LONG,
    deadline=None,
    database=None,
    suppress_health_check=list(HealthCheck),
)


@pytest.fixture(autouse=True)
def small_budget():
    set_max_memory(64 << 20)
    yield
    set_max_memory(None)


@contextmanager
def time_limit(seconds=CASE_SECONDS):
    """Fail a case that blocks (a FIFO read, an endless loop) instead of hanging the run."""

    def expired(signum, frame):
        raise AssertionError(f"a case ran longer than {seconds} s")

    old = signal.signal(signal.SIGALRM, expired)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def expect_clean(fn):
    """Run fn: success, or a TexcookError with a one-line message."""
    with time_limit():
        try:
            return fn()
        except TexcookError as exc:
            assert "\n" not in str(exc)
            return None


# ----------------------------------------------------------------------------- mutations

HOSTILE = st.one_of(
    st.sampled_from([None, -1, -(2**31), 2**31, 2**63, 0, 1, 7, 1e308, -0.0, 0.5, "", "x", [], {}, True,
                     "../secret.bin", "..%2Fsecret.bin", "/etc/passwd", "file:///etc/passwd",
                     "http://example.invalid/a.png", "data:image/png;base64,@@@", "data:,", "sub/../../secret.bin",
                     "/dev/zero", "fifo.png", "secret-link.png", "%00", "a\nb"]),
    st.integers(-5, 40),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=6),
    st.lists(st.integers(-2, 9), max_size=4),
)


def paths_of(tree, prefix=()):
    """Every path (tuple of keys/indices) to a value in a JSON tree."""
    out = [prefix]
    if isinstance(tree, dict):
        for k, v in tree.items():
            out += paths_of(v, prefix + (k,))
    elif isinstance(tree, list):
        for i, v in enumerate(tree):
            out += paths_of(v, prefix + (i,))
    return out


DEEP = "\x00deep:"  # a marker dumps() turns into that many nested lists (kept flat while mutating)


@st.composite
def mutated(draw, base):
    """A copy of the JSON tree `base` with one to three values replaced,
    deleted or nested deeply."""
    tree = copy.deepcopy(base)
    for _ in range(draw(st.integers(1, 3))):
        paths = [p for p in paths_of(tree) if p]
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent = tree
        for k in path[:-1]:
            parent = parent[k]
        action = draw(st.sampled_from(["replace", "replace", "replace", "delete", "deep"]))
        if action == "delete" and isinstance(parent, dict):
            del parent[path[-1]]
        elif action == "deep":
            parent[path[-1]] = f"{DEEP}{draw(st.sampled_from([50, 5000, 100000]))}"
        else:
            parent[path[-1]] = draw(HOSTILE)
    return tree


def dumps(tree):
    """JSON text, with each deep-nesting marker written out as nested lists."""
    text = json.dumps(tree, allow_nan=True)
    for n in (50, 5000, 100000):
        text = text.replace(json.dumps(f"{DEEP}{n}"), "[" * n + "0" + "]" * n)
    return text


# ----------------------------------------------------------------------------- a valid model



def base_model():
    """(glTF JSON tree, binary buffer bytes, {file name: bytes}): one quad, a
    base colour with alpha (MASK), a normal map, an occlusion map, a sampler."""
    rng = np.random.default_rng(7)
    colour = rng.integers(0, 256, (8, 8, 4), dtype=np.uint8)
    colour[..., 3] = np.where(rng.random((8, 8)) < 0.5, 0, 255)
    normal = np.full((8, 8, 3), (128, 128, 255), np.uint8)
    grey = rng.integers(0, 256, (8, 8, 3), dtype=np.uint8)
    pos = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32).tobytes()
    uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32).tobytes()
    idx = np.array([0, 1, 2, 0, 2, 3], np.uint16).tobytes()
    grey_png = encoded_image(grey)
    blob = pos + uv + idx + b"\0\0" + grey_png
    blob += b"\0" * (-len(blob) % 4)
    tree = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2, "material": 0}]}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
            {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"},
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 48},
            {"buffer": 0, "byteOffset": 48, "byteLength": 32},
            {"buffer": 0, "byteOffset": 80, "byteLength": 12},
            {"buffer": 0, "byteOffset": 96, "byteLength": len(grey_png)},
        ],
        "buffers": [{"byteLength": len(blob), "uri": "model.bin"}],
        "images": [{"uri": "colour.png"}, {"uri": "normal.png"}, {"bufferView": 3, "mimeType": "image/png"},
                   {"uri": "data:image/png;base64," + base64.b64encode(grey_png).decode()}],
        "samplers": [{"magFilter": 9729, "minFilter": 9987, "wrapS": 33071, "wrapT": 10497, "name": "s"}],
        "textures": [{"source": 0, "sampler": 0}, {"source": 1}, {"source": 2, "sampler": 0}, {"source": 3}],
        "materials": [{
            "name": "m",
            "alphaMode": "MASK",
            "alphaCutoff": 0.4,
            "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "baseColorFactor": [1, 1, 1, 1],
                                     "metallicRoughnessTexture": {"index": 3}},
            "normalTexture": {"index": 1},
            "occlusionTexture": {"index": 2},
        }],
    }
    files = {"colour.png": encoded_image(colour), "normal.png": encoded_image(normal), "model.bin": blob}
    return tree, blob, files


BASE = None


def base():
    global BASE
    if BASE is None:
        BASE = base_model()
    return BASE


def glb_bytes(text, blob):
    chunk = text.encode("utf-8")
    chunk += b" " * (-len(chunk) % 4)
    parts = [struct.pack("<I", len(chunk)), b"JSON", chunk]
    if blob is not None:
        parts += [struct.pack("<I", len(blob)), b"BIN\0", blob]
    body = b"".join(parts)
    return b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body


def lay_out(root, files):
    """The model's folder with its files, a secret beside the folder, a symlink
    out of it, and a FIFO in it."""
    if root.exists():
        shutil.rmtree(root)
    folder = root / "model"
    folder.mkdir(parents=True)
    (root / "secret.bin").write_bytes(SECRET)
    (root / "secret.png").write_bytes(SECRET)
    for name, data in files.items():
        (folder / name).write_bytes(data)
    os.symlink(root / "secret.png", folder / "secret-link.png")
    os.mkfifo(folder / "fifo.png")
    return folder


def outputs_clean(root, out):
    """Nothing of the secret reached an output, and nothing was written
    outside the output folder."""
    for dirpath, _, names in os.walk(out):
        for name in names:
            p = os.path.join(dirpath, name)
            if os.path.isfile(p) and not os.path.islink(p):
                assert SECRET not in Path(p).read_bytes(), f"{p} holds a file from outside the model's folder"
    allowed = {"model", "secret.bin", "secret.png", "out"}
    assert set(os.listdir(root)) <= allowed, f"written outside the output folder: {set(os.listdir(root)) - allowed}"


def bake(model_path, out):
    from texcook.scene import bake_scene

    return bake_scene(str(model_path), str(out), preset="fastest", threads=1)


# ----------------------------------------------------------------------------- scene


@FUZZ
@given(data=st.data())
def test_scene_survives_hostile_gltf_json(tmp_path_factory, data):
    tree, _, files = base()
    bad = data.draw(mutated(tree))
    root = tmp_path_factory.mktemp("gltf")
    folder = lay_out(root, files)
    (folder / "model.gltf").write_text(dumps(bad))
    expect_clean(lambda: bake(folder / "model.gltf", root / "out"))
    outputs_clean(root, root / "out")


@FUZZ
@given(data=st.data())
def test_scene_survives_hostile_glb(tmp_path_factory, data):
    tree, blob, files = base()
    tree = copy.deepcopy(tree)
    tree["buffers"] = [{"byteLength": len(blob)}]
    bad = data.draw(st.one_of(st.just(tree), mutated(tree)))
    raw = bytearray(glb_bytes(dumps(bad), blob))
    kind = data.draw(st.sampled_from(["none", "truncate", "length", "flip", "chunk"]))
    if kind == "truncate":
        del raw[data.draw(st.integers(0, len(raw) - 1)):]
    elif kind == "length":
        at = data.draw(st.sampled_from([8, 12, 20 + len(dumps(bad).encode()) + (-len(dumps(bad).encode()) % 4)]))
        at = min(at, len(raw) - 4)
        raw[at:at + 4] = struct.pack("<I", data.draw(st.sampled_from([0, 1, 3, 2**31, 2**32 - 1, len(raw) * 2])))
    elif kind == "flip":
        for _ in range(data.draw(st.integers(1, 8))):
            raw[data.draw(st.integers(0, len(raw) - 1))] ^= 1 << data.draw(st.integers(0, 7))
    elif kind == "chunk":
        raw[16:20] = data.draw(st.sampled_from([b"BIN\0", b"JSOX", b"\0\0\0\0"]))
    root = tmp_path_factory.mktemp("glb")
    folder = lay_out(root, {k: v for k, v in files.items() if k != "model.bin"})
    (folder / "model.glb").write_bytes(bytes(raw))
    expect_clean(lambda: bake(folder / "model.glb", root / "out"))
    outputs_clean(root, root / "out")


# ----------------------------------------------------------------------------- batch

PATTERNS = ["*.png", "**/*.png", "[z-a].png", "[", "**", "../*", "*/../../*", "a{b,c}", "\\", "*_n.png", "",
            "/abs/*.png", "[!]", "***"]


@st.composite
def manifest_text(draw):
    """A manifest: valid rules and hostile ones, as TOML text."""
    lines = []
    if draw(st.booleans()):
        lines.append(f"inputs = {json.dumps(draw(st.sampled_from([['art'], ['.'], ['../'], 'art', ['art/*'], [1]])))}")
    if draw(st.booleans()):
        lines.append(f"container = {json.dumps(draw(st.sampled_from(['ktx2', 'dds', 'astc', 'zip', ''])))}")
    if draw(st.booleans()):
        lines.append("[defaults]")
        lines.append(f"codec = {{ format = {json.dumps(draw(st.sampled_from(['bc1', 'rgba8', 'nope', 'etc1'])))} }}")
    for _ in range(draw(st.integers(0, 3))):
        lines.append("[[rules]]")
        lines.append(f"match = {json.dumps(draw(st.sampled_from(PATTERNS)))}")
        extra = draw(st.sampled_from(["", "skip = true", "source = { normal_map = true }", "mips = { enabled = 3 }",
                                      'codec = { preset = "nope" }', "container = 7", 'use = "normal"', 'use = 5',
                                      "x = [[[[[[[[[[[[[[[[1]]]]]]]]]]]]]]]]"]))
        if extra:
            lines.append(extra)
    text = "\n".join(lines) + "\n"
    if draw(st.integers(0, 9)) == 0:
        text = "a = " + "[" * 5000 + "]" * 5000 + "\n"
    return text


def art_folder(root):
    art = root / "art"
    (art / "sub").mkdir(parents=True)
    img = encoded_image(np.full((8, 8, 3), 90, np.uint8))
    (art / "a.png").write_bytes(img)
    (art / "sub" / "b_n.png").write_bytes(img)
    return art


@FUZZ
@given(text=manifest_text())
def test_batch_survives_hostile_manifests(tmp_path_factory, text):
    from texcook import batch

    root = tmp_path_factory.mktemp("manifest")
    art_folder(root)
    (root / "m.toml").write_text(text)
    out = root / "out"

    def run():
        rules = batch.load_manifest(str(root / "m.toml"))
        jobs = batch.plan(rules.inputs, str(out), rules=rules)
        return batch.run(jobs, str(out), workers=1, dry_run=True)

    expect_clean(run)
    assert set(os.listdir(root)) <= {"art", "m.toml", "out"}


def valid_state():
    return {"version": 1, "files": {"a.ktx2": {"input": "a.png", "sha256": "0" * 64, "recipe": {}, "status": "ok",
                                               "output_sha256": "1" * 64}}}


@FUZZ
@given(data=st.data())
def test_batch_survives_hostile_state_files(tmp_path_factory, data):
    from texcook import batch
    from texcook.recipe import Recipe

    root = tmp_path_factory.mktemp("state")
    art = art_folder(root)
    out = root / "out"
    out.mkdir()
    state = data.draw(st.one_of(mutated(valid_state()), st.sampled_from([[], 3, "x", None])))
    text = dumps(state)
    if data.draw(st.integers(0, 5)) == 0:
        text = text[: data.draw(st.integers(0, len(text)))]
    (out / batch.STATE_NAME).write_text(text)

    def run():
        jobs = batch.plan([str(art)], str(out), recipe=Recipe.of(format="rgba8", mips=False))
        return batch.run(jobs, str(out), workers=1, dry_run=data.draw(st.booleans()))

    expect_clean(run)
    assert set(os.listdir(root)) <= {"art", "out"}


# ----------------------------------------------------------------------------- preview


def valid_scene_json():
    return {"textures": [{"output": "t.ktx2", "texture": 0,
                          "sampler": {"index": 0, "minFilter": 9987, "magFilter": 9729, "wrapS": 33071, "wrapT": 10497},
                          "recipe": {"source": {"alpha_cutoff": 0.5}}}]}


PREVIEW_TEXTURE = None


def preview_texture(root):
    """A small baked texture (made once, copied per case)."""
    global PREVIEW_TEXTURE
    if PREVIEW_TEXTURE is None:
        from texcook.pipeline import bake_file
        from texcook.recipe import Recipe

        src = root / "t.png"
        px = np.zeros((16, 16, 4), np.uint8)
        px[..., :3] = 200
        px[4:12, 4:12, 3] = 255
        src.write_bytes(encoded_image(px))
        bake_file(str(src), str(root / "t.ktx2"), Recipe.of(format="rgba8"), threads=1)
        PREVIEW_TEXTURE = (root / "t.ktx2").read_bytes()
    return PREVIEW_TEXTURE


@FUZZ
@given(data=st.data())
def test_preview_survives_hostile_scene_json(tmp_path_factory, data):
    from texcook.preview import render

    root = tmp_path_factory.mktemp("preview")
    (root / "t.ktx2").write_bytes(preview_texture(root))
    doc = data.draw(st.one_of(mutated(valid_scene_json()), st.sampled_from([[], 3, "x", None, [valid_scene_json()]])))
    (root / "scene.json").write_text(dumps(doc))
    expect_clean(lambda: render(str(root / "t.ktx2"), size="16x16", runs=1))


def test_the_secret_is_caught(tmp_path):
    """The check that nothing outside the model's folder reaches an output can fail."""
    root = tmp_path
    folder = lay_out(root, {})
    (root / "out").mkdir()
    (root / "out" / "x.bin").write_bytes(SECRET)
    with pytest.raises(AssertionError):
        outputs_clean(root, root / "out")
    (root / "out" / "x.bin").unlink()
    (root / "stray.ktx2").write_bytes(b"x")
    with pytest.raises(AssertionError):
        outputs_clean(root, root / "out")
    assert folder.is_dir()
