"""Reading a glTF model: the JSON (or GLB chunks), its buffers and its images.

A model is untrusted input (marketplaces, asset stores). Its JSON is checked
before anything is planned: indices in range, offsets and lengths that fit,
finite numbers, bounded nesting. Every file it names is resolved against the
real path of the model's folder and refused when it leaves that folder, names
anything but a regular file, or carries a scheme other than `data:`; every
read goes through texcook.fileio's guarded reader (memory budget, no FIFOs or
devices).
"""

from __future__ import annotations

import base64
import binascii
import json
import math
import os
import re
import struct
import urllib.parse
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError, UsageError
from ..fileio import atomic_write, check_memory, check_regular, read_bytes, read_prefix

SOURCE_MAGIC = {b"\x89PNG\r\n\x1a\n": ".png", b"\xff\xd8\xff": ".jpg"}  # what the source reader takes

# Deeper JSON than this is refused: real glTF nests about a dozen levels, and
# deeper structures would exhaust the recursion of the parser, copier or writer.
MAX_JSON_DEPTH = 64

ALPHA_MODES = ("OPAQUE", "MASK", "BLEND")
TEXTURE_SLOTS = (("pbrMetallicRoughness", "baseColorTexture"), ("pbrMetallicRoughness", "metallicRoughnessTexture"),
                 (None, "normalTexture"), (None, "occlusionTexture"), (None, "emissiveTexture"))


@dataclass
class Model:
    path: str
    kind: str  # "gltf" or "glb"
    gltf: object  # pygltflib.GLTF2
    blob: bytes | None  # a GLB's binary chunk
    doc: dict = field(default=None, repr=False)  # the JSON as parsed, checked by `_validate`

    @property
    def folder(self):
        return os.path.dirname(os.path.abspath(self.path))

    @property
    def root(self):
        """The real path of the model's folder: no file outside it is read."""
        return os.path.realpath(self.folder)


# ----------------------------------------------------------------------------- refusals


def _show_uri(uri):
    if uri is None:
        return None
    uri = str(uri)
    limit = 40 if uri.startswith("data:") else 200
    return uri if len(uri) <= limit else uri[:limit] + "..."


@dataclass(frozen=True)
class Refusal:
    """A buffer or image the scene will not read, and why."""

    what: str  # "image 3", "buffer 1"
    uri: str | None
    why: str

    def line(self):
        uri = _show_uri(self.uri)
        return f"{self.what} ({uri}): {self.why}" if uri else f"{self.what}: {self.why}"

    def to_dict(self):
        return {"what": self.what, "uri": _show_uri(self.uri), "why": self.why}


class RefusedResource(InputError):
    """InputError naming the model, with the refusal as data."""

    def __init__(self, model_path, what, uri, why):
        self.refusal = Refusal(what, uri, why)
        super().__init__(self.refusal.line(), model_path)


def refusals_error(model, refusals, shown=5) -> InputError:
    """One line for a scene stopped by `refusals` (the first few in full)."""
    lines = [r.line() for r in refusals[:shown]]
    more = f"; and {len(refusals) - shown} more" if len(refusals) > shown else ""
    return InputError("; ".join(lines) + more, model.path)


# ----------------------------------------------------------------------------- the model file


def _int(v):
    return isinstance(v, int) and not isinstance(v, bool)


def _number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _glb_chunks(data, path):
    """(JSON chunk bytes, BIN chunk bytes or None), every length checked."""
    if len(data) < 12 or data[:4] != b"glTF":
        raise InputError("not a GLB file (no glTF header)", path)
    version, length = struct.unpack_from("<II", data, 4)
    if version != 2:
        raise InputError(f"GLB container version {version} is not 2", path)
    if length != len(data):
        raise InputError(f"the GLB header says {length} bytes, the file has {len(data)}", path)
    chunks, pos = [], 12
    while pos < length:
        if pos + 8 > length:
            raise InputError(f"GLB chunk {len(chunks)} is cut short at byte {pos}", path)
        size, kind = struct.unpack_from("<I4s", data, pos)
        if pos + 8 + size > length:
            raise InputError(f"GLB chunk {len(chunks)} declares {size} bytes, only {length - pos - 8} follow", path)
        chunks.append((kind, data[pos + 8: pos + 8 + size]))
        pos += 8 + size
    if not chunks or chunks[0][0] != b"JSON":
        raise InputError("GLB file has no JSON chunk first", path)
    # a BIN chunk may only follow the JSON one; other chunk types are ignored (glTF 2.0, 4.4.3)
    bins = [c for k, c in chunks[1:] if k == b"BIN\0"]
    if len(bins) > 1 or (bins and chunks[1][0] != b"BIN\0") or any(k == b"JSON" for k, _ in chunks[1:]):
        raise InputError("GLB chunks out of order (one JSON chunk, then at most one BIN chunk)", path)
    return chunks[0][1].rstrip(b" \0\t\r\n"), (bins[0] if bins else None)


def _json_path(parts):
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out or "the root"


def _first_problem(doc, with_path):
    """(what is wrong, where) for the first value nested too deeply or not
    finite; None when there is none. Without `with_path` the place is not
    tracked (the fast pass over every value of a large model)."""
    stack = [(doc, 1, ())]
    while stack:
        value, depth, where = stack.pop()
        if depth > MAX_JSON_DEPTH:
            return f"the JSON nests deeper than {MAX_JSON_DEPTH} levels (at {{}})", where
        items = value.items() if isinstance(value, dict) else enumerate(value)
        for k, v in items:
            if isinstance(v, (dict, list)):
                stack.append((v, depth + 1, where + (k,) if with_path else where))
            elif isinstance(v, float) and not math.isfinite(v):
                shown = "NaN" if v != v else ("Infinity" if v > 0 else "-Infinity")
                return f"{{}} is {shown}; glTF numbers are finite", where + (k,) if with_path else where
    return None


def _check_tree(doc, path):
    """Bounded nesting and finite numbers, walked without recursion; the
    place of a problem is found by a second walk."""
    if _first_problem(doc, False) is not None:
        text, where = _first_problem(doc, True)
        raise InputError(text.format(_json_path(where)), path)


def _parse_json(raw, path):
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"the JSON is not UTF-8 (byte {exc.start})", path) from None
    try:
        doc = json.loads(text)
    except RecursionError:
        raise InputError(f"the JSON nests deeper than {MAX_JSON_DEPTH} levels", path) from None
    except ValueError as exc:
        raise InputError(f"not valid JSON ({str(exc).splitlines()[0][:120]})", path) from None
    if not isinstance(doc, dict):
        kind = ("a list" if isinstance(doc, list) else "a string" if isinstance(doc, str) else
                "null" if doc is None else "true or false" if isinstance(doc, bool) else "a number")
        raise InputError(f"the JSON root is {kind}, not an object: not a glTF model", path)
    _check_tree(doc, path)
    asset = doc.get("asset")
    if not isinstance(asset, dict):
        raise InputError("not a glTF model (no asset object)", path)
    version = asset.get("version")
    if not isinstance(version, str) or not version.startswith("2."):
        raise InputError(f"glTF version {version or 'unknown'} is not 2.x", path)
    return text, doc


def load_model(path) -> Model:
    """Read and check a .gltf or .glb model (see `_validate`)."""
    import pygltflib

    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext not in (".gltf", ".glb"):
        raise UsageError(f"a scene is a .gltf or .glb model, not {ext or 'a file without extension'}", path)
    data = read_bytes(path, "glTF model")
    blob = None
    if ext == ".glb":
        raw, blob = _glb_chunks(data, path)
    else:
        raw = data
    del data
    text, doc = _parse_json(raw, path)
    _validate(doc, blob, path)
    try:
        gltf = pygltflib.GLTF2.gltf_from_json(text)
    except Exception as exc:  # noqa: BLE001  the library's parser meets untrusted JSON: any failure is the file's
        raise InputError(f"not a readable glTF model ({type(exc).__name__}: {str(exc).splitlines()[0][:120]})",
                         path) from None
    return Model(path, ext[1:], gltf, blob, doc)


# ----------------------------------------------------------------------------- checks before any work


def _validate(doc, blob, path):
    """Refuse, with one line naming the object, what would otherwise fail
    after work was done or silently read other data."""

    def bad(msg):
        raise InputError(msg, path)

    def array(name, what):
        items = doc.get(name, [])
        if not isinstance(items, list):
            bad(f"{name} is not a list")
        for i, item in enumerate(items):
            if not isinstance(item, dict):
                bad(f"{what} {i} is not an object")
        return items

    def index(obj, key, what, target, items, required=False):
        if key not in obj:
            if required:
                bad(f"{what} has no {key}")
            return None
        v = obj[key]
        if not _int(v) or v < 0:
            bad(f"{what} has {key} {json.dumps(v)[:40]}, not an index (an integer from 0)")
        if v >= len(items):
            bad(f"{what} names {target} {v}, which does not exist")
        return v

    def size(obj, key, what, required=False, minimum=0):
        if key not in obj:
            if required:
                bad(f"{what} has no {key}")
            return 0
        v = obj[key]
        if not _int(v) or v < minimum:
            bad(f"{what} has {key} {json.dumps(v)[:40]}, not an integer from {minimum}")
        return v

    def uri(obj, what):
        v = obj.get("uri")
        if v is not None and not isinstance(v, str):
            bad(f"{what} has a uri that is not a string")
        return v

    buffers = array("buffers", "buffer")
    views = array("bufferViews", "bufferView")
    images = array("images", "image")
    textures = array("textures", "texture")
    samplers = array("samplers", "sampler")
    materials = array("materials", "material")
    for i, b in enumerate(buffers):
        size(b, "byteLength", f"buffer {i}", required=True, minimum=1)
        if uri(b, f"buffer {i}") is None and not (i == 0 and blob is not None):
            bad(f"buffer {i} has no data (no uri, and it is not a GLB's binary chunk)")
    if blob is not None and buffers and buffers[0].get("uri") is None and len(blob) < buffers[0]["byteLength"]:
        bad(f"buffer 0 holds {len(blob)} bytes in the GLB binary chunk, less than its byteLength "
            f"{buffers[0]['byteLength']}")
    for i, v in enumerate(views):
        what = f"bufferView {i}"
        b = index(v, "buffer", what, "buffer", buffers, required=True)
        start = size(v, "byteOffset", what)
        length = size(v, "byteLength", what, required=True, minimum=1)
        if start + length > buffers[b]["byteLength"]:
            bad(f"{what} (bytes {start} to {start + length}) ends past buffer {b}'s byteLength "
                f"{buffers[b]['byteLength']}")
    for i, im in enumerate(images):
        what = f"image {i}"
        has_uri = uri(im, what) is not None
        has_view = index(im, "bufferView", what, "bufferView", views) is not None
        if has_uri == has_view:
            bad(f"{what} has {'both a uri and' if has_uri else 'neither a uri nor'} a bufferView")
    for i, t in enumerate(textures):
        index(t, "source", f"texture {i}", "image", images)
        index(t, "sampler", f"texture {i}", "sampler", samplers)
    from .plan import FILTER_NAMES, NO_MIPMAP_FILTERS, WRAP_MODES

    allowed = {"magFilter": NO_MIPMAP_FILTERS, "minFilter": tuple(FILTER_NAMES), "wrapS": tuple(WRAP_MODES),
               "wrapT": tuple(WRAP_MODES)}
    for i, s in enumerate(samplers):
        for key, values in allowed.items():
            if key in s and s[key] not in values:
                bad(f"sampler {i} has {key} {json.dumps(s[key])[:40]}; glTF allows {', '.join(map(str, values))}")
    for i, m in enumerate(materials):
        what = f"material {i}"
        mode = m.get("alphaMode", "OPAQUE")
        if mode not in ALPHA_MODES:
            bad(f"{what} has alphaMode {json.dumps(mode)[:40]}; glTF has {', '.join(ALPHA_MODES)}")
        cutoff = m.get("alphaCutoff", 0.5)
        if not _number(cutoff) or cutoff < 0:
            bad(f"{what} has alphaCutoff {json.dumps(cutoff)[:40]}, not a number from 0")
        pbr = m.get("pbrMetallicRoughness", {})
        if not isinstance(pbr, dict):
            bad(f"{what} has a pbrMetallicRoughness that is not an object")
        factor = pbr.get("baseColorFactor", [1, 1, 1, 1])
        if not (isinstance(factor, list) and len(factor) == 4 and all(_number(f) and 0 <= f <= 1 for f in factor)):
            bad(f"{what} has baseColorFactor {json.dumps(factor)[:60]}, not four numbers from 0 to 1")
        for parent, slot in TEXTURE_SLOTS:
            info = (pbr if parent else m).get(slot)
            if info is None:
                continue
            if not isinstance(info, dict):
                bad(f"{what} {slot} is not an object")
            index(info, "index", f"{what} {slot}", "texture", textures, required=True)


# ----------------------------------------------------------------------------- files the model names

_SCHEME = re.compile(r"([A-Za-z][A-Za-z0-9+.-]*):")


def _inside(path, root):
    return os.path.commonpath([path, root]) == root


def _confine(model, joined, what, uri):
    """The real path of `joined` (a path under the model's folder), refused
    unless it is a regular file inside the folder's real path."""
    root = model.root
    real = os.path.realpath(joined)
    if not _inside(real, root):
        if _inside(os.path.normpath(joined), root):
            raise RefusedResource(model.path, what, uri, "a symlink that leads out of the model's folder")
        raise RefusedResource(model.path, what, uri, "leaves the model's folder")
    try:
        check_regular(real)  # stat only: a FIFO or device is refused before anything can block
    except InputError as err:
        raise RefusedResource(model.path, what, uri, err.message) from None
    return real


def resolve_uri(model, uri, what) -> str:
    """The real path of the file a buffer's or image's `uri` names: decoded
    (percent-encoding) and resolved against the model's real folder. Refused
    (RefusedResource, naming the model, `what` and the uri) when it has a
    scheme (data: uris are not files), is absolute, leaves the folder (`..`,
    a symlink out) or is not a regular file."""
    def refuse(why):
        raise RefusedResource(model.path, what, uri, why)

    if not isinstance(uri, str) or not uri:
        refuse("the uri is empty")
    m = _SCHEME.match(uri)
    if m:
        scheme = m.group(1).lower()
        if scheme in ("http", "https"):
            refuse(f"{scheme}:// uris are not fetched")
        if scheme == "file":
            refuse("file:// uris are not read")
        if scheme == "data":
            refuse("a data: uri is not a file")
        if len(scheme) > 1:
            refuse(f"{scheme}: uris are not read")
        refuse("absolute paths are not read")  # a drive letter: C:/...
    try:
        rel = urllib.parse.unquote(uri, errors="strict")
    except UnicodeDecodeError:
        refuse("its percent-encoding is not UTF-8")
    if "\0" in rel:
        refuse("it holds a NUL character")
    if rel.startswith(("/", "\\")) or os.path.isabs(rel):
        refuse("absolute paths are not read")
    return _confine(model, os.path.join(model.root, rel), what, uri)


def read_resource(model, real, what, uri=None) -> bytes:
    """The bytes of a file `resolve_uri` returned, checked again at the time
    of reading (it may have been swapped for a symlink meanwhile)."""
    real = _confine(model, real, what, uri or real)
    try:
        return read_bytes(real, what)
    except InputError as err:
        raise RefusedResource(model.path, what, uri or real, err.message) from None


def resource_bytes(model, uri, what) -> bytes:
    """The bytes of the file `uri` names (see `resolve_uri`), read within the
    memory budget."""
    return read_resource(model, resolve_uri(model, uri, what), what, uri)


def external_resources(model):
    """(what, uri) for every buffer and image stored in a file of its own."""
    for kind, items in (("buffer", model.gltf.buffers), ("image", model.gltf.images)):
        for i, obj in enumerate(items or []):
            if obj.uri is not None and not obj.uri.startswith("data:"):
                yield f"{kind} {i}", obj.uri


def _data_uri(model, uri, what):
    head, comma, payload = uri.partition(",")
    if not comma:
        raise RefusedResource(model.path, what, uri, "the data: uri has no comma")
    if ";base64" in head:
        try:
            return base64.b64decode(re.sub(r"[ \t\r\n]+", "", payload), validate=True)
        except (binascii.Error, ValueError):
            raise RefusedResource(model.path, what, uri, "the data: uri is not valid base64") from None
    return urllib.parse.unquote_to_bytes(payload)


def _buffer_data(model, index, cache=None):
    """Buffer `index`'s bytes (at least its byteLength)."""
    if cache is not None and index in cache:
        return cache[index]
    buf = model.gltf.buffers[index]
    what = f"buffer {index}"
    if buf.uri is None:
        data = model.blob  # checked by `_validate`: buffer 0 of a GLB
    elif buf.uri.startswith("data:"):
        data = _data_uri(model, buf.uri, what)
    else:
        data = resource_bytes(model, buf.uri, what)
    if len(data) < buf.byteLength:
        raise RefusedResource(model.path, what, buf.uri, f"holds {len(data)} bytes, less than its byteLength "
                                                         f"{buf.byteLength}")
    if cache is not None:
        cache[index] = data
    return data


def image_bytes(model, index, cache=None):
    """(bytes, None) for an embedded image, (None, real path) for an external
    file inside the model's folder."""
    image = model.gltf.images[index]
    what = f"image {index}"
    if image.uri is not None:
        if image.uri.startswith("data:"):
            return _data_uri(model, image.uri, what), None
        return None, resolve_uri(model, image.uri, what)
    view = model.gltf.bufferViews[image.bufferView]
    data = _buffer_data(model, view.buffer, cache)
    start = view.byteOffset or 0
    return data[start: start + view.byteLength], None


def _sniff(data):
    """The file extension of a PNG or JPEG, else None."""
    for magic, ext in SOURCE_MAGIC.items():
        if data.startswith(magic):
            return ext
    return None


# ----------------------------------------------------------------------------- sources


@dataclass
class ImageSource:
    index: int
    path: str | None  # a file the pipeline can read; None when it cannot be baked
    desc: dict  # how the model stores it
    why: str = ""  # why it cannot be baked
    has_alpha: bool | None = None
    binary_alpha: bool | None = None


def _alpha_of(image):
    """(has an alpha channel, alpha is two-level 0/1), from the stored
    integers where there are some."""
    ch = image.alpha_channel
    if ch is None:
        return False, False
    if image.stored is not None:
        a, top = image.stored[..., ch], np.iinfo(image.stored.dtype).max
    else:
        a, top = image.pixels[..., ch], 1.0
    return True, bool(np.all((a == 0) | (a == top)))


def alpha_facts(path):
    """(has an alpha channel, alpha is two-level 0/1)."""
    from ..image import read_image

    return _alpha_of(read_image(path))


def image_desc(model, index):
    image = model.gltf.images[index]
    desc = {"image": index}
    if image.name:
        desc["name"] = image.name
    if image.uri is not None:
        if image.uri.startswith("data:"):
            desc["data_uri"] = True
        else:
            desc["uri"] = image.uri
    if image.bufferView is not None:
        desc["bufferView"] = image.bufferView
    if image.mimeType:
        desc["mimeType"] = image.mimeType
    return desc


def _read_source(model, workdir, i, cache):
    """The ImageSource of image `i`, decoded once to prove it can be baked;
    RefusedResource when it cannot be read or decoded."""
    from ..image import read_image

    desc = image_desc(model, i)
    what, uri = f"image {i}", model.gltf.images[i].uri
    data, path = image_bytes(model, i, cache)
    if data is None:
        try:
            data = read_prefix(path, 16, "image")[0]
        except InputError as err:
            raise RefusedResource(model.path, what, uri, err.message) from None
    ext = _sniff(data)
    if ext is None:  # another format (KTX2, WebP...): left to the model as it is, not an error
        return ImageSource(i, None, desc, f"image {i} is not PNG or JPEG")
    if path is None:
        path = os.path.join(workdir, f"image{i}{ext}")
        atomic_write(path, data)
        shown = what
    else:
        shown = path
    try:
        image = read_image(path)
    except InputError as err:
        # an embedded image's temporary file means nothing to the user: name the image
        raise RefusedResource(model.path, what, uri, err.message.replace(path, shown)) from None
    has_alpha, binary = _alpha_of(image)
    return ImageSource(i, path, desc, has_alpha=has_alpha, binary_alpha=binary)


def read_sources(model, workdir, images):
    """Read and check everything a scene needs before any bake.

    Returns (sources, refusals): an ImageSource for each image index in
    `images` (external files are read in place, embedded ones written to
    `workdir`), each decoded once; and a Refusal for each buffer or image that
    cannot be read: those the images need, and every other file the model
    names (the rewritten model takes copies of them). A source that cannot be
    baked has path None and says why; a refused one also has a Refusal.
    Formats other than PNG and JPEG are not refused: their uses are not baked."""
    sources, refusals, seen = {}, [], set()

    def refused(err):
        if err.refusal.what not in seen:
            seen.add(err.refusal.what)
            refusals.append(err.refusal)

    cache = {}
    n = len(model.gltf.images or [])
    for i in sorted(images):
        if not 0 <= i < n:
            raise InputError(f"a texture names image {i}, which does not exist", model.path)
        try:
            sources[i] = _read_source(model, workdir, i, cache)
        except RefusedResource as err:
            refused(err)
            sources[i] = ImageSource(i, None, image_desc(model, i), err.refusal.line())
        if sources[i].path is not None:  # read whole; another format is checked below, as a copy
            seen.add(f"image {i}")
    seen.update(f"buffer {b}" for b in cache)
    cache.clear()
    for what, uri in external_resources(model):
        if what in seen:
            continue
        try:
            real = resolve_uri(model, uri, what)
            if not os.access(real, os.R_OK):
                raise RefusedResource(model.path, what, uri, "cannot read (permission denied)")
            nbytes = os.stat(real).st_size
            check_memory(nbytes, f"copying this {nbytes}-byte file", real)
            kind, i = what.split()
            if kind == "buffer" and nbytes < model.gltf.buffers[int(i)].byteLength:
                raise RefusedResource(model.path, what, uri, f"holds {nbytes} bytes, less than its byteLength "
                                                             f"{model.gltf.buffers[int(i)].byteLength}")
        except RefusedResource as err:
            refused(err)
        except InputError as err:
            refused(RefusedResource(model.path, what, uri, err.message))
        except OSError as exc:
            refused(RefusedResource(model.path, what, uri, f"cannot read ({exc.strerror})"))
        seen.add(what)
    return sources, refusals


def extract_images(model, workdir, images):
    """The sources alone of `read_sources` (refused ones have path None)."""
    return read_sources(model, workdir, images)[0]
