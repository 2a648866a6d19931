"""Publishing a scene: names for the baked textures, the rewritten model that
references them, scene.json, and the output folder they are moved into
together (`Stage`).

The model is rewritten on the JSON exactly as the reading side parsed it
(`Model.doc`), so every field, name, extras and extension the bake does not
change stays as it was, and no default the source left implicit is added.
"""

from __future__ import annotations

import contextlib
import copy
import math
import os
import re
import shutil
import signal
import stat
import struct
import tempfile
import threading
import time
import urllib.parse

import numpy as np

from ..container import table as containers
from ..errors import InputError, OutputError, UsageError
from ..fileio import TEMP_MARK, atomic_write, lock, read_prefix
from .model import image_desc, resolve_uri
from .plan import foreign_textures

# How the rewritten model points a texture at its baked image (docs/scene.md):
# DDS through MSFT_texture_dds; ASTC in KTX2 through EXT_texture_astc; any other
# KTX2 payload (BC, ETC, EAC, RGBA8) through texcook's own extension. The container
# table says which; these name them for readers of this module.
EXT_DDS = containers.get("dds").gltf["*"]
EXT_ASTC = containers.get("ktx2").gltf["astc"]
EXT_KTX2 = containers.get("ktx2").gltf["*"]
MIME_TYPES = {name: containers.get(name).mime for name in containers.SCENE_CONTAINERS}
SCENE_JSON = "scene.json"
FALLBACKS = ("keep", "drop")


def extension_for(container, fmt):
    return containers.get(container).gltf_extension(fmt)


def default_fallback(kind):
    """A GLB is the one file everyone downloads: source images kept in it are
    bytes every reader of the extension loads for nothing. A .gltf's fallback
    images are separate files that only a viewer without the extension
    fetches."""
    return "drop" if kind == "glb" else "keep"


# --- names -------------------------------------------------------------------------------

_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")


def _items(doc, key):
    items = doc.get(key)
    return items if isinstance(items, list) else []


def _stem(doc, index):
    image = _items(doc, "images")[index]
    raw = image.get("name") if isinstance(image.get("name"), str) else ""
    uri = image.get("uri")
    if not raw and isinstance(uri, str) and not uri.startswith("data:"):
        raw = os.path.splitext(os.path.basename(urllib.parse.unquote(uri)))[0]
    stem = _UNSAFE.sub("_", raw or "").strip("._")
    return stem or f"image{index}"


def _unique(name, taken):
    stem, ext = os.path.splitext(name)
    candidate, n = name, 2
    while candidate.lower() in taken:
        candidate = f"{stem}-{n}{ext}"
        n += 1
    taken.add(candidate.lower())
    return candidate


def name_outputs(doc, bakes, container, taken):
    """A name for each bake (its file in OUTDIR, or its image name in a GLB):
    the image's name, with the kind of use when the image is baked more than
    once."""
    count = {}
    for b in bakes:
        count[b.image] = count.get(b.image, 0) + 1
    for b in bakes:
        stem = _stem(doc, b.image)
        if count[b.image] > 1:
            stem += f".{b.kind}" if b.alpha == "none" else f".{b.alpha}"
        b.output = _unique(f"{stem}.{container}", taken)


def _relative(uri):
    """The path a copy keeps in OUTDIR: the uri's relative path when it is a
    plain one inside the folder, else its file name."""
    rel = os.path.normpath(urllib.parse.unquote(uri)).replace(os.sep, "/")
    parts = rel.split("/")
    if os.path.isabs(rel) or any(p in ("", ".", "..") for p in parts):
        rel = _UNSAFE.sub("_", os.path.basename(rel)).strip(".") or "resource"
    return rel


def name_copies(model, doc, taken, skip=()):
    """{uri: (real source path, name in OUTDIR)} for every buffer and image
    the model keeps in a file of its own, but the uris in `skip` (refused:
    they stay as they are, uncopied); one copy per source file."""
    copies, by_source = {}, {}
    for kind in ("buffers", "images"):
        for i, obj in enumerate(_items(doc, kind)):
            uri = obj.get("uri")
            if not isinstance(uri, str) or uri.startswith("data:") or uri in copies or uri in skip:
                continue
            src = resolve_uri(model, uri, f"{kind[:-1]} {i}")  # refuses anything outside the model's folder
            if src not in by_source:
                by_source[src] = _unique(_relative(uri), taken)
            copies[uri] = (src, by_source[src])
    return copies


# --- the rewritten model -------------------------------------------------------------------


def _glb_bytes(json_text, blob):
    chunk = json_text.encode("utf-8")
    chunk += b" " * (-len(chunk) % 4)
    parts = [struct.pack("<I", len(chunk)), b"JSON", chunk]
    if blob is not None:
        data = bytes(blob) + b"\0" * (-len(blob) % 4)
        parts += [struct.pack("<I", len(data)), b"BIN\0", data]
    body = b"".join(parts)
    return b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body


def _slot(material, slot):
    """The textureInfo object of a core slot in a material dict."""
    parent = material.get("pbrMetallicRoughness") if slot in ("baseColorTexture", "metallicRoughnessTexture") \
        else material
    return parent[slot]


def _walk_indices(value, key, fn):
    """Apply fn to every integer under `key` in a JSON tree (extras skipped:
    they are the application's, not glTF's); fn returns the new value."""
    stack = [value]
    while stack:
        v = stack.pop()
        if isinstance(v, dict):
            for k, item in v.items():
                if k == "extras":
                    continue
                if k == key and isinstance(item, int) and not isinstance(item, bool):
                    v[k] = fn(item)
                else:
                    stack.append(item)
        elif isinstance(v, list):
            stack.extend(v)


def _texture_images(texture):
    """Image indices a texture reads: its source and its extensions' sources."""
    out = []
    if isinstance(texture.get("source"), int):
        out.append(texture["source"])
    for ext in _extensions(texture).values():
        if isinstance(ext, dict) and isinstance(ext.get("source"), int) and not isinstance(ext["source"], bool):
            out.append(ext["source"])
    return out


def _extensions(obj):
    ext = obj.get("extensions")
    return ext if isinstance(ext, dict) else {}


def _renumber_images(doc, gone):
    images = _items(doc, "images")
    new = {}
    for i in range(len(images)):
        if i not in gone:
            new[i] = len(new)
    images[:] = [img for i, img in enumerate(images) if i not in gone]
    for tex in _items(doc, "textures"):
        if isinstance(tex.get("source"), int):
            tex["source"] = new[tex["source"]]
        for ext in _extensions(tex).values():
            if isinstance(ext, dict) and isinstance(ext.get("source"), int) and ext["source"] in new:
                ext["source"] = new[ext["source"]]
    return new


def _drop_views(doc, candidates, blob):
    """Remove the bufferViews in `candidates` that nothing reads any more, and
    their bytes from the GLB binary chunk `blob` (when given) where no other
    view reads them. Returns the new blob."""
    refs = {}

    def count(v):
        refs[v] = refs.get(v, 0) + 1
        return v

    _walk_indices(doc, "bufferView", count)
    views = _items(doc, "bufferViews")
    gone = {v for v in candidates if not refs.get(v) and 0 <= v < len(views)}
    if not gone:
        return blob
    if blob is not None:
        blob = _compact(views, gone, blob)
    new = {}
    for i in range(len(views)):
        if i not in gone:
            new[i] = len(new)
    doc["bufferViews"] = [v for i, v in enumerate(views) if i not in gone]
    _walk_indices(doc, "bufferView", lambda v: new.get(v, v))
    return blob


def _compact(views, gone, blob):
    """Cut from buffer 0 the bytes only the views in `gone` read, in whole
    multiples of 4 so that every remaining view keeps its alignment."""
    on0 = [(i, v) for i, v in enumerate(views) if v.get("buffer") == 0]
    kept = sorted((v.get("byteOffset", 0), v.get("byteOffset", 0) + v["byteLength"]) for i, v in on0
                  if i not in gone)
    cut = []
    for i, v in on0:
        if i not in gone:
            continue
        start, end = v.get("byteOffset", 0), v.get("byteOffset", 0) + v["byteLength"]
        for a, b in kept:  # subtract every kept range from [start, end)
            if b <= start or a >= end:
                continue
            if a <= start:
                start = max(start, b)
            else:
                cut.append((start, a))
                start = max(start, b)
            if start >= end:
                break
        if start < end:
            cut.append((start, end))
    spans = []
    for a, b in sorted(cut):
        if spans and a <= spans[-1][1]:
            spans[-1] = (spans[-1][0], max(spans[-1][1], b))
        else:
            spans.append((a, b))
    spans = [(a, a + (b - a) // 4 * 4) for a, b in spans if b - a >= 4]
    if not spans:
        return blob

    def shift(offset):
        return offset - sum(min(b, offset) - a for a, b in spans if a < offset)

    out = bytearray()
    pos = 0
    for a, b in spans:
        out += blob[pos:a]
        pos = b
    out += blob[pos:]
    for i, v in on0:
        if i not in gone and v.get("byteOffset", 0):
            v["byteOffset"] = shift(v["byteOffset"])
    return out


def rewrite_model(model, bakes, baked, container, fallback, unserved, copies):
    """The rewritten model: (JSON dict, GLB binary chunk or None, texture_of,
    image_of).

    `baked` holds each bake's file bytes, or None for a bake that failed;
    `unserved` the textures some use of which is not baked (those texture
    objects stay as they are: their unbaked uses keep reading them);
    `copies` maps a resource uri to its (source, name in OUTDIR).

    Each baked texture becomes an image (a file in OUTDIR for .gltf, a
    bufferView in the binary chunk for .glb), named in an extension of a
    texture: a texture keeps its index for its first bake when every use of
    it is baked and no material extension reads it; other (texture, bake)
    pairs get copies of the texture. With fallback "drop" those textures lose
    their `source`, the extension becomes required, and source images no
    texture reads any more are removed with their bytes. texture_of maps
    (texture, bake index) to the texture a slot now reads; image_of a bake
    index to its image."""
    doc = copy.deepcopy(model.doc)
    glb = model.kind == "glb"
    blob = bytearray(model.blob) if glb and model.blob is not None else None
    had_images = "images" in doc
    images = doc.setdefault("images", [])
    textures = doc.get("textures", [])
    materials = doc.get("materials", [])
    source_textures = copy.deepcopy(textures)
    foreign = foreign_textures(model.gltf)
    used, required = [], []
    image_of, ext_of = {}, {}
    for bi, b in enumerate(bakes):
        if baked[bi] is None:
            continue
        ext_of[bi] = extension_for(container, b.recipe.codec.format)
        if ext_of[bi] not in used:
            used.append(ext_of[bi])
        images.append({"name": os.path.splitext(b.output)[0]})
        image_of[bi] = len(images) - 1
    in_place = set()
    texture_of = {}
    for bi, b in enumerate(bakes):
        if bi not in image_of:
            continue
        for u in b.uses:
            key = (u.texture, bi)
            if key not in texture_of:
                if u.texture in foreign or u.texture in unserved or u.texture in in_place:
                    textures.append(copy.deepcopy(source_textures[u.texture]))
                    index = len(textures) - 1
                else:
                    in_place.add(u.texture)
                    index = u.texture
                tex = textures[index]
                tex["extensions"] = dict(_extensions(tex))
                tex["extensions"][ext_of[bi]] = {"source": image_of[bi]}
                if fallback == "drop":
                    tex.pop("source", None)
                    if ext_of[bi] not in required:
                        required.append(ext_of[bi])
                texture_of[key] = index
            _slot(materials[u.material], u.slot)["index"] = texture_of[key]
    if fallback == "drop":
        read = {i for tex in textures for i in _texture_images(tex)}
        gone = {b.image for bi, b in enumerate(bakes) if bi in image_of} - read
        if gone:
            views = {images[i]["bufferView"] for i in gone if isinstance(images[i].get("bufferView"), int)}
            new = _renumber_images(doc, gone)
            image_of = {bi: new[i] for bi, i in image_of.items()}
            # the binary chunk is compacted only where no extension addresses it by offset
            compact = glb and "EXT_meshopt_compression" not in (doc.get("extensionsUsed") or [])
            kept = _drop_views(doc, views, blob if compact else None)
            if compact:
                blob = kept
            if glb and doc.get("buffers") and doc["buffers"][0].get("uri") is None and blob is not None:
                doc["buffers"][0]["byteLength"] = len(blob)
    for kind in ("buffers", "images"):
        for obj in _items(doc, kind):
            uri = obj.get("uri")
            if isinstance(uri, str) and uri in copies:
                obj["uri"] = urllib.parse.quote(copies[uri][1])
    if glb and image_of:
        buffers = doc.setdefault("buffers", [])
        views = doc.setdefault("bufferViews", [])
        if not buffers or buffers[0].get("uri") is not None:
            # the GLB binary chunk must be buffer 0: move the others up
            for view in views:
                _walk_indices(view, "buffer", lambda v: v + 1)
            buffers.insert(0, {"byteLength": 0})
            blob = bytearray()
        for bi, index in image_of.items():
            data = baked[bi]
            blob += b"\0" * (-len(blob) % 4)
            views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)})
            blob += data
            images[index]["bufferView"] = len(views) - 1
            images[index]["mimeType"] = MIME_TYPES[container]
        buffers[0]["byteLength"] = len(blob)
    else:
        for bi, index in image_of.items():
            images[index]["uri"] = urllib.parse.quote(bakes[bi].output)
    if not doc["images"] and not had_images:
        del doc["images"]
    for key, names in (("extensionsUsed", used), ("extensionsRequired", required)):
        have = doc.get(key) or []
        extra = [e for e in names if e not in have]
        if extra:
            doc[key] = list(have) + extra
    return doc, (bytes(blob) if blob is not None else None), texture_of, image_of


def model_bytes(model, doc, blob):
    """The rewritten model file: a GLB's JSON compact; a .gltf's laid out as
    the source was (indented, or on one line as many exporters write it)."""
    import json

    if model.kind == "glb":
        return _glb_bytes(json.dumps(doc, ensure_ascii=False, separators=(",", ":")), blob)
    try:
        indented = b"\n" in read_prefix(model.path, 4096, "glTF model")[0].strip()
    except InputError:
        indented = True
    if indented:
        return (json.dumps(doc, ensure_ascii=False, indent=2) + "\n").encode("utf-8")
    return json.dumps(doc, ensure_ascii=False, separators=(",", ":")).encode("utf-8")


# --- scene.json --------------------------------------------------------------------------


def level0_psnr(result, channels):
    """PSNR of level 0 over the channels the uses read (from a pipeline.compare
    result): an occlusion texture is judged on R, not on what a format happens
    to store in G and B."""
    from ..metrics import psnr_from_mse

    per = result["levels"][0]["channels"]
    mses = [0.0 if math.isinf(per[c]) else 10.0 ** (-per[c] / 10.0) for c in channels.upper() if c in per]
    return {"channels": "".join(c for c in channels.upper() if c in per),
            "psnr": psnr_from_mse(sum(mses) / len(mses), 1.0) if mses else math.nan}


def _finite(x):
    """JSON has no infinity: an exact level 0 (lossless) is written as the string "inf"."""
    if isinstance(x, float) and not np.isfinite(x):
        return "inf" if x > 0 else "-inf"
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_finite(v) for v in x]
    return x


def describe(model, bakes, results, texture_of, image_of, not_baked, settings, files):
    """scene.json: one entry per bake, one per (texture, bake) pair naming
    its bake by id, and the uses not baked. Every entry has a bounded size,
    so the file grows linearly with the textures.

    `results` holds per bake (summary, psnr) or None when it was not baked;
    `files` says whether baked textures are files in OUTDIR (not in a GLB)."""
    out_bakes, entries = [], []
    for bi, b in enumerate(bakes):
        if results[bi] is None:
            continue
        summary, db = results[bi]
        by_texture = {}
        for u in b.uses:
            by_texture.setdefault(u.texture, []).append(u)
        bake = {
            "id": bi,
            "name": b.output,
            "image": image_of[bi],
            "source": image_desc(model, b.image),
            "recipe": b.recipe.to_dict(),
            "steps": b.steps,
            "bytes": summary["bytes"],
            "format": summary["format"],
            "colour_space": summary["colour_space"],
            "width": summary["width"],
            "height": summary["height"],
            "levels": summary["levels"],
            "psnr": db["psnr"],
            "psnr_channels": db["channels"],
            "extension": extension_for(settings["container"], b.recipe.codec.format),
            "notes": list(dict.fromkeys(b.notes + summary["notes"])),
            "textures": sorted(by_texture),
        }
        if files:
            bake["output"] = b.output
        out_bakes.append(bake)
        for t, uses in sorted(by_texture.items()):
            entry = {"texture": t, "output_texture": texture_of[(t, bi)], "bake": bi}
            name = model.doc["textures"][t].get("name")
            if name is not None:
                entry["name"] = name
            if files:
                entry["output"] = b.output  # preview finds a file's sampler by this name
            entry["sampler"] = uses[0].sampler.to_dict()
            if b.alpha == "mask":
                entry["alphaCutoff"] = b.cutoff
            entry["uses"] = [u.to_dict() for u in uses]
            entries.append(entry)
    return dict(settings, model=model.path, bakes=out_bakes, textures=entries, not_baked=not_baked)


# --- the output folder: outputs made in a stage, moved in together ---------------------

# Present in OUTDIR only if texcook was killed while moving a scene's outputs in.
INCOMPLETE = "scene.incomplete"
_STAGE_PREFIX = ".scene" + TEMP_MARK


def check_outdir(model, outdir):
    """Refuse an OUTDIR that is the model's own folder, by real path or by
    identity (a symlink, `//`, `./x/..`, a bind mount), or not a folder."""
    same = os.path.realpath(outdir) == model.root
    if not same:
        with contextlib.suppress(OSError):
            same = os.path.samefile(outdir, model.folder)
    if same:
        raise UsageError("the output folder is the model's own: the rewritten model and its files would "
                         "replace the originals; choose another -o", outdir)
    if os.path.lexists(outdir) and not os.path.isdir(outdir):
        raise UsageError("the output must be a folder", outdir)


def _inside(path, root):
    return os.path.commonpath([path, root]) == root


def check_targets(outdir, names, source_ids):
    """Refuse a name in OUTDIR that would land outside it (through a
    symlinked subfolder), on a folder, or on one of the model's own files
    (`source_ids`: their (st_dev, st_ino))."""
    root = os.path.realpath(outdir)
    for rel in names:
        real = _real_target(root, rel)
        if not _inside(real, root):
            raise OutputError(f"{rel} would be written outside the output folder (to {real})", outdir)
        if os.path.lexists(real):
            st = os.stat(real) if os.path.exists(real) else os.lstat(real)
            if stat.S_ISDIR(st.st_mode):
                raise OutputError("is a folder: the output of that name cannot replace it", real)
            if (st.st_dev, st.st_ino) in source_ids:
                raise UsageError("is one of the model's own files: the output of that name would replace "
                                 "it; choose another -o", real)


def _identities(paths):
    out = set()
    for p in paths:
        with contextlib.suppress(OSError):
            st = os.stat(p)
            out.add((st.st_dev, st.st_ino))
    return out


def _real_target(outdir_real, rel):
    """The real path `rel` in OUTDIR names: through its nearest existing
    folder, so a symlinked subfolder shows where a write would land."""
    target = os.path.join(outdir_real, rel)
    head, tail = os.path.dirname(target), [os.path.basename(target)]
    while not os.path.isdir(head):
        head, part = os.path.split(head)
        tail.insert(0, part)
    return os.path.join(os.path.realpath(head), *tail)


class Stage:
    """A private folder in OUTDIR (created when missing) where a scene's
    outputs are made, locked while it lives; `publish` moves them into OUTDIR
    together, `close` removes what was not published (and an OUTDIR this run
    created, if it is empty)."""

    def __init__(self, outdir):
        self.outdir = outdir
        self.made = []  # folders this run created, outermost first
        head = os.path.abspath(outdir)
        while not os.path.isdir(head):
            self.made.insert(0, head)
            head = os.path.dirname(head)
        try:
            os.makedirs(outdir, exist_ok=True)
            self._sweep()
            self.path = tempfile.mkdtemp(prefix=_STAGE_PREFIX, dir=outdir)
            self._fd = lock(self.path)  # a later run's sweep leaves a live stage alone
        except OSError as exc:
            if getattr(self, "path", None):
                shutil.rmtree(self.path, ignore_errors=True)
            self._remove_made()
            raise OutputError(f"cannot write here ({exc.strerror})", outdir) from None
        self.published = False

    def _sweep(self):
        """Remove stages that a killed run left: no live run holds their lock,
        and none is younger than a minute (one just made may not be locked yet)."""
        for name in os.listdir(self.outdir):
            if not name.startswith(_STAGE_PREFIX):
                continue
            full = os.path.join(self.outdir, name)
            with contextlib.suppress(OSError):
                st = os.lstat(full)
                if not stat.S_ISDIR(st.st_mode) or time.time() - st.st_mtime < 60:
                    continue
                fd = lock(full, wait=False)
                if fd is None:  # a live run holds it
                    continue
                try:
                    shutil.rmtree(full, ignore_errors=True)
                finally:
                    os.close(fd)

    def file(self, name):
        path = os.path.join(self.path, "files", name)
        os.makedirs(os.path.dirname(path), exist_ok=True)
        return path

    def _remove_made(self):
        for d in reversed(self.made):
            with contextlib.suppress(OSError):
                os.rmdir(d)

    def close(self):
        shutil.rmtree(self.path, ignore_errors=True)
        os.close(self._fd)
        if not self.published:
            self._remove_made()

    def publish(self, items):
        """Move each (name in OUTDIR, staged file) into place. Whatever it
        replaces is set aside and put back if a move fails; an interrupt waits
        until the moves are done; a marker names OUTDIR incomplete while they
        run, in case the process is killed."""
        backup = os.path.join(self.path, "replaced")
        os.makedirs(backup, exist_ok=True)
        marker = os.path.join(self.outdir, INCOMPLETE)
        moved, made = [], []
        fd = lock(self.outdir)  # two runs publishing into one OUTDIR take turns
        try:
            self._moves(items, backup, marker, moved, made)
            with contextlib.suppress(OSError):
                os.fsync(fd)  # the renames themselves on disk
        finally:
            os.close(fd)

    def _moves(self, items, backup, marker, moved, made):
        with _signals_deferred():
            try:
                atomic_write(marker, b"texcook scene was stopped while moving its outputs into this folder: "
                                     b"the files here may mix two runs. Run it again.\n")
                for k, (rel, staged) in enumerate(items):
                    target = os.path.join(self.outdir, rel)
                    parent = os.path.dirname(target)
                    missing = []
                    while not os.path.isdir(parent):
                        missing.insert(0, parent)
                        parent = os.path.dirname(parent)
                    for d in missing:
                        os.mkdir(d)
                        made.append(d)
                    old = None
                    if os.path.lexists(target):
                        old = os.path.join(backup, str(k))
                        os.replace(target, old)
                    moved.append((target, old))
                    os.replace(staged, target)
                os.unlink(marker)
                self.published = True
            except BaseException:
                for target, old in reversed(moved):
                    with contextlib.suppress(OSError):
                        if old is not None:
                            os.replace(old, target)
                        else:
                            os.unlink(target)
                for d in reversed(made):
                    with contextlib.suppress(OSError):
                        os.rmdir(d)
                with contextlib.suppress(OSError):
                    os.unlink(marker)
                raise


@contextlib.contextmanager
def _signals_deferred():
    """SIGINT and SIGTERM wait until the block ends, then act as they would
    have (only the main thread can set handlers; elsewhere nothing changes)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught = []
    old = {s: signal.signal(s, lambda n, _f: caught.append(n)) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)
        for s in dict.fromkeys(caught):
            signal.raise_signal(s)
