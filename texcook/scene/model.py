"""Reading a glTF model: the JSON (or GLB chunks), its buffers and its images.

Every file a model names is untrusted input: it is resolved against the
model's folder and read through texcook.fileio's guarded reader.
"""

from __future__ import annotations

import base64
import os
import struct
import urllib.parse
from dataclasses import dataclass

import numpy as np

from ..errors import InputError, UsageError

SOURCE_MAGIC = {b"\x89PNG\r\n\x1a\n": ".png", b"\xff\xd8\xff": ".jpg"}  # what the source reader takes

@dataclass
class Model:
    path: str
    kind: str  # "gltf" or "glb"
    gltf: object  # pygltflib.GLTF2
    blob: bytes | None  # a GLB's binary chunk

    @property
    def folder(self):
        return os.path.dirname(os.path.abspath(self.path))


def load_model(path) -> Model:
    import pygltflib

    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext not in (".gltf", ".glb"):
        raise UsageError(f"a scene is a .gltf or .glb model, not {ext or 'a file without extension'}", path)
    if not os.path.isfile(path):
        raise InputError("no such file", path)
    try:
        if ext == ".glb":
            with open(path, "rb") as fh:
                data = fh.read()
            if data[:4] != b"glTF":
                raise InputError("not a GLB file (no glTF header)", path)
            gltf = pygltflib.GLTF2.load_from_bytes(data)
            if gltf is None:
                raise InputError("GLB file has no JSON chunk", path)
            blob = gltf.binary_blob()
        else:
            gltf = pygltflib.GLTF2.load_json(path)
            blob = None
    except InputError:
        raise
    except (OSError, ValueError, KeyError, TypeError, struct.error) as exc:
        raise InputError(f"not a readable glTF model ({type(exc).__name__}: {str(exc).splitlines()[0][:120]})",
                         path) from None
    version = str(getattr(gltf.asset, "version", "") or "")
    if not version.startswith("2."):
        raise InputError(f"glTF version {version or 'unknown'} is not 2.x", path)
    return Model(path, ext[1:], gltf, bytes(blob) if blob is not None else None)


def _data_uri(uri):
    head, _, payload = uri.partition(",")
    if ";base64" in head:
        return base64.b64decode(payload)
    return urllib.parse.unquote_to_bytes(payload)


def _file_uri(model, uri):
    """The path of an external resource named by a relative URI."""
    return os.path.join(model.folder, urllib.parse.unquote(uri))


def _buffer_data(model, index):
    buffers = model.gltf.buffers or []
    if not 0 <= index < len(buffers):
        raise InputError(f"buffer {index} does not exist", model.path)
    uri = buffers[index].uri
    if uri is None:
        if model.blob is None or index != 0:
            raise InputError(f"buffer {index} has no data (no uri, no GLB binary chunk)", model.path)
        return model.blob
    if uri.startswith("data:"):
        return _data_uri(uri)
    path = _file_uri(model, uri)
    try:
        with open(path, "rb") as fh:
            return fh.read()
    except OSError as exc:
        raise InputError(f"cannot read buffer {index} ({exc.strerror})", path) from None


def image_bytes(model, index):
    """(bytes, None) for an embedded image, (None, path) for an external file."""
    image = model.gltf.images[index]
    if image.uri is not None:
        if image.uri.startswith("data:"):
            return _data_uri(image.uri), None
        return None, _file_uri(model, image.uri)
    if image.bufferView is None:
        raise InputError(f"image {index} has neither a uri nor a bufferView", model.path)
    view = model.gltf.bufferViews[image.bufferView]
    data = _buffer_data(model, view.buffer)
    start = view.byteOffset or 0
    return data[start: start + view.byteLength], None


def _sniff(data):
    """The file extension of a PNG or JPEG, else None."""
    for magic, ext in SOURCE_MAGIC.items():
        if data.startswith(magic):
            return ext
    return None


@dataclass
class ImageSource:
    index: int
    path: str | None  # a file the pipeline can read; None when it cannot be baked
    desc: dict  # how the model stores it
    why: str = ""  # why it cannot be baked
    has_alpha: bool | None = None
    binary_alpha: bool | None = None


def _alpha_facts(path):
    """(has an alpha channel, alpha is two-level 0/1)."""
    from ..image import read_image

    image = read_image(path)
    if image.alpha_channel is None:
        return False, False
    a = image.pixels[..., image.alpha_channel]
    return True, bool(np.all((a == 0.0) | (a == 1.0)))


def _image_desc(model, index):
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


def extract_images(model, workdir, images):
    """ImageSource for each image index in `images`: external files are read in
    place, embedded ones (bufferView, data URI) are written to `workdir`."""
    sources = {}
    n = len(model.gltf.images or [])
    for i in sorted(images):
        if not 0 <= i < n:
            raise InputError(f"a texture names image {i}, which does not exist", model.path)
        desc = _image_desc(model, i)
        data, path = image_bytes(model, i)
        if data is None:
            if not os.path.isfile(path):
                raise InputError(f"image {i}: no such file", path)
            with open(path, "rb") as fh:
                data = fh.read(16)
        ext = _sniff(data)
        if ext is None:
            sources[i] = ImageSource(i, None, desc, f"image {i} is not PNG or JPEG")
            continue
        if path is None:
            path = os.path.join(workdir, f"image{i}{ext}")
            with open(path, "wb") as fh:
                fh.write(data)
        sources[i] = ImageSource(i, path, desc)
    return sources
