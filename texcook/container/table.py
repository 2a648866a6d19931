"""The one table of texture containers, as texcook.formats is of formats.

A row says what a container is (name, extensions, magic), what it can hold
(mip levels, key/values, Zstandard, a recorded colour space, which formats),
the defaults a codec takes when writing into it, where a glTF model points at
it, and which module reads, writes and describes it. Every other module asks
the row; none branches on a container's name.

Each container module offers the same three functions, which the row calls:

    write_texture(texture: Stored, output) -> bytes     (output: a recipe's Output)
    read_texture(data, path) -> Stored                  (levels as stored)
    describe_head(head, file_size, path) -> dict        (`texcook info`: header only)
    HEADER_BYTES                                        (the leading bytes describe_head needs first)

This module imports only the format table, so the command line can offer the
containers' names as choices without loading the containers.
"""

from __future__ import annotations

import importlib
import os
from dataclasses import dataclass, field
from typing import Callable

from .. import formats
from ..errors import UsageError


@dataclass
class Stored:
    """A texture as a container holds it: what its writer takes and its reader gives."""

    format: str | None  # texcook's format name; None when texcook has no decoder for it
    srgb: bool  # the stored values are sRGB-encoded (False where the container cannot say)
    width: int
    height: int
    levels: list  # bytes per level, base first
    kv: dict = field(default_factory=dict)  # key -> text value (containers with key/values)
    label: str = ""  # how messages name what is stored ("vkFormat 140")


@dataclass(frozen=True)
class Container:
    name: str  # "ktx2": what recipes, manifests and --container say
    title: str  # how messages name it: "KTX2", "DDS", ".astc"
    extensions: tuple  # file name endings, the first the one texcook writes
    magic: bytes  # the file's first bytes
    module: str  # the module with write_texture, read_texture and describe_head
    mips: bool  # holds a mip chain (else level 0 only)
    key_values: bool  # holds key/value metadata (KTXswizzle, texcook.* keys)
    zstd: bool  # levels may be Zstandard-supercompressed
    srgb: bool  # records whether the values are sRGB-encoded
    holds: Callable  # Format -> the container can hold it
    holds_srgb: Callable  # Format -> the container can hold its sRGB variant
    refusal: str  # a format it cannot hold: the message, with {format} and {can}
    # codec options whose defaults differ when writing into this container
    codec_defaults: dict = field(default_factory=dict)
    mime: str = ""  # glTF image mimeType; "" when a model cannot point at this container
    gltf: dict = field(default_factory=dict)  # format family ("*": any other) -> glTF extension
    # the glTF extensions above whose readers rebuild a normal's Z from a
    # two-channel format (X, Y); other readers sample Z from B as stored
    gltf_rebuilds_z: tuple = ()

    @property
    def extension(self) -> str:
        return self.extensions[0]

    @property
    def in_scenes(self) -> bool:
        return bool(self.gltf)

    def gltf_extension(self, format_name) -> str:
        """The glTF extension a model points at this container's `format_name` through."""
        return self.gltf.get(formats.get(format_name).family, self.gltf["*"])

    def rebuilds_z(self, format_name) -> bool:
        """A glTF reader of `format_name` in this container rebuilds a normal's Z."""
        return self.gltf_extension(format_name) in self.gltf_rebuilds_z

    def can_hold(self) -> list:
        """Names of the encodable formats this container holds."""
        return [f for f in formats.encodable() if self.holds(formats.get(f))]

    def check_format(self, format_name, srgb=False, path=None):
        """UsageError unless the container holds the format (None: whichever
        uncompressed one the source resolves to), and its sRGB variant when asked."""
        if format_name is None:
            if not any(self.holds(f) for f in formats.FORMATS.values() if f.family == "uncompressed"):
                raise UsageError(self.refusal.format(format="uncompressed", can=", ".join(self.can_hold())),
                                 path)
            return None
        fmt = formats.get(format_name)
        if not self.holds(fmt):
            raise UsageError(self.refusal.format(format=fmt.name, can=", ".join(self.can_hold())), path)
        if srgb and not self.holds_srgb(fmt):
            raise UsageError(f"format {fmt.name} has no sRGB variant in {self.title}; use --linear", path)
        return fmt

    def check_recipe(self, recipe, path=None):
        """UsageError unless what the recipe asks of its output fits this container."""
        if recipe.transform.renormalize is not None and not self.key_values:
            raise UsageError(f"--renormalize stores its scale and bias as KTX2 key/values; {self.title} has no "
                             "place for them", path)
        fmt = self.check_format(recipe.codec.format, recipe.output.colour_space == "srgb", path)
        if recipe.output.zstd is not None and not self.zstd:
            raise UsageError(f"--zstd applies to KTX2 output, not {self.title}", path)
        if recipe.output.zstd is not None and fmt is not None and fmt.basislz:
            raise UsageError(f"--zstd does not apply to {fmt.name}: its levels are BasisLZ-supercompressed already",
                             path)

    def _module(self):
        return importlib.import_module(self.module)

    def write(self, texture: Stored, output) -> bytes:
        """The file's bytes; `output` is the recipe's Output (zstd level, DDS header style)."""
        return self._module().write_texture(texture, output)

    def read(self, data, path=None) -> Stored:
        return self._module().read_texture(data, path)

    def describe_head(self, head, file_size, path) -> dict:
        return self._module().describe_head(head, file_size, path)


_TABLE = (
    Container(
        "ktx2", "KTX2", (".ktx2",), b"\xabKTX 20\xbb\r\n\x1a\n", "texcook.container.ktx2",
        mips=True, key_values=True, zstd=True, srgb=True,
        holds=lambda f: True,
        holds_srgb=lambda f: f.has_srgb,
        refusal="format {format} cannot be written to KTX2; use one of {can}",
        mime="image/ktx2",
        # ASTC and Basis Universal through the Khronos extensions; any other payload through texcook's own
        gltf={"astc": "EXT_texture_astc", "basis": "KHR_texture_basisu", "*": "TEXCOOK_texture_ktx2"},
        gltf_rebuilds_z=("TEXCOOK_texture_ktx2",),  # docs/scene.md: its readers rebuild Z
    ),
    Container(
        "dds", "DDS", (".dds",), b"DDS ", "texcook.container.dds",
        mips=True, key_values=False, zstd=False, srgb=True,
        holds=lambda f: bool(f.dxgi),
        holds_srgb=lambda f: bool(f.dxgi_srgb),
        refusal="format {format} cannot be written to DDS; use one of {can}",
        # Direct3D has only BC1 with alpha: it reads the 3-colour mode's black as
        # transparent, so plain BC1 must not use it as an opaque colour
        codec_defaults={"opaque_black": False},
        mime="image/vnd-ms.dds",
        gltf={"*": "MSFT_texture_dds"},
    ),
    Container(
        "astc", ".astc", (".astc",), b"\x13\xab\xa1\x5c", "texcook.container.astcfile",
        mips=False, key_values=False, zstd=False, srgb=False,
        holds=lambda f: f.family == "astc",
        holds_srgb=lambda f: True,  # sRGB-encoded values are stored; the file cannot say so
        refusal="a .astc file holds ASTC blocks, not {format} (use --format astc-NxM)",
    ),
)

CONTAINERS: dict[str, Container] = {c.name: c for c in _TABLE}
DEFAULT = "ktx2"  # what a bake writes when nothing names a container
NAMES = tuple(CONTAINERS)
SCENE_CONTAINERS = tuple(c.name for c in _TABLE if c.in_scenes)  # a glTF model can point at these
EXTENSIONS = tuple(e for c in _TABLE for e in c.extensions)
EXTENSION_LIST = ", ".join(EXTENSIONS[:-1]) + " or " + EXTENSIONS[-1]  # for messages and help


def get(name) -> Container:
    box = CONTAINERS.get(name)
    if box is None:
        raise UsageError(f"output must end in {EXTENSION_LIST}, not {name!r}")
    return box


def of_path(path):
    """The container a file name's extension names, or None (an image)."""
    ext = os.path.splitext(os.fspath(path))[1].lower()
    return next((c for c in _TABLE if ext in c.extensions), None)


def for_output(path) -> Container:
    """The container of an output file, or UsageError naming the extensions."""
    box = of_path(path)
    if box is None:
        ext = os.path.splitext(os.fspath(path))[1].lower()
        raise UsageError(f"output must end in {EXTENSION_LIST}, not {ext or 'no extension'!r}", path)
    return box


def describe_file(path) -> dict:
    """`texcook info`: the summary of a texture file, from its header and
    metadata only (no level is read), whichever container its magic names."""
    from ..errors import ContainerError
    from ..fileio import read_prefix

    head, size = read_prefix(path, max(c._module().HEADER_BYTES for c in _TABLE), "texture")
    for box in _TABLE:
        if head.startswith(box.magic):
            return box.describe_head(head, size, path)
    titles = [c.title for c in _TABLE]
    raise ContainerError(f"not a {', '.join(titles[:-1])} or {titles[-1]} file (unknown identifier)", path)
