"""The one registry of the KTX2 keys texcook writes: each key's name, what its
value holds, and the functions that write and read it.

Casing: texcook's own keys are "texcook." followed by the name in snake_case
(lower-case words joined by underscores), except a key that carries a glTF
property's value, which takes that property's glTF name as it is spelt there
(texcook.alphaCutoff is a material's alphaCutoff), so a viewer finds it under
the name it already knows. `check_name` holds the rule; tests/test_ktx2.py
checks every key against it, that every key a bake writes is here, and that
every key here is read where the registry says.

Keys the KTX 2.0 specification defines (KTX...) are listed too when texcook
writes them; their spelling is the specification's.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

PREFIX = "texcook."
_SNAKE = re.compile(r"[a-z][a-z0-9]*(_[a-z0-9]+)*")
_GLTF = re.compile(r"[a-z][a-zA-Z0-9]*")  # glTF's property names are lowerCamelCase


@dataclass(frozen=True)
class Key:
    name: str  # the key as stored
    value: str  # what the value holds: "text" (NUL-terminated UTF-8) or "json" (JSON text)
    schema: dict  # JSON schema of the value (of the decoded JSON for "json" keys)
    writers: tuple  # "module:function" of every writer
    readers: tuple  # "module:function" of every reader (a KTX key may be for other loaders only)
    about: str
    gltf: str = ""  # the glTF property whose value the key carries (its name then follows glTF's)
    spec: bool = False  # defined by the KTX 2.0 specification, not by texcook


def check_name(key: Key) -> str:
    """The key's name, or ValueError when it breaks the casing rule."""
    if key.spec:
        if not key.name.startswith("KTX"):
            raise ValueError(f"{key.name}: a KTX-defined key starts with KTX")
        return key.name
    if not key.name.startswith(PREFIX):
        raise ValueError(f"{key.name}: texcook's keys start with {PREFIX!r}")
    rest = key.name[len(PREFIX):]
    if key.gltf:
        if rest != key.gltf or not _GLTF.fullmatch(rest):
            raise ValueError(f"{key.name}: a key carrying glTF's {key.gltf} is named {PREFIX}{key.gltf}")
    elif not _SNAKE.fullmatch(rest):
        raise ValueError(f"{key.name}: texcook's keys are {PREFIX} and snake_case")
    return key.name


_TRANSFORM_STEP = {"type": "object", "required": ["name"], "properties": {"name": {"type": "string"}}}

COLOUR_SPACE = Key(
    "texcook.colour_space", "json",
    {"type": "object", "required": ["chosen", "reason", "source", "to_light"],
     "properties": {"chosen": {"enum": ["srgb", "linear"]}, "reason": {"type": "string"},
                    "source": {"type": "string"}, "to_light": {"type": "boolean"}}},
    writers=("texcook.plan:_plan",), readers=("texcook.pipeline:load_texture",),
    about="what --colour-space auto chose and why; to_light: sRGB colour stored in linear light; source linear "
          "and chosen srgb: linear data (--data --srgb) stored through the sRGB curve, read back as the data")
CONTENT = Key(
    "texcook.content", "text", {"enum": ["normal"]},
    writers=("texcook.plan:_plan",), readers=("texcook.pipeline:load_texture",),
    about="normal: a tangent-space normal map (X, Y in R, G), so `compare` adds the angular error")
ALPHA_CUTOFF = Key(
    "texcook.alphaCutoff", "text", {"type": "string", "pattern": "^[0-9.e+-]+$"},
    writers=("texcook.plan:_plan",), readers=("texcook.preview.source:load",),
    about="a cut-out's alpha-test cutoff (Python float repr), for viewers", gltf="alphaCutoff")
TRANSFORMS = Key(
    "texcook.transforms", "json", {"type": "array", "items": _TRANSFORM_STEP},
    writers=("texcook.transforms:forward", "texcook.transforms:record_format_step"),
    readers=("texcook.pipeline:load_texture",),
    about="the transform steps applied before encoding, in order, with what a reader needs to undo them")
SAT = Key(
    "texcook.sat", "json",
    {"type": "object", "required": ["version", "source", "offset"],
     "properties": {"version": {"const": 1}, "source": {"enum": ["float", "uint8", "uint16"]},
                    "offset": {"type": "array", "items": {"type": "string"}}}},
    writers=("texcook.sat:SummedAreaTable.to_ktx2",), readers=("texcook.sat:SummedAreaTable.from_ktx2",),
    about="a summed-area table's source kind and per-channel offset (float64 repr)")
SWIZZLE = Key(
    "KTXswizzle", "text", {"type": "string", "pattern": "^[rgba01]{4}$"},
    writers=("texcook.plan:_plan",), readers=("texcook.pipeline:load_texture",),
    about="how a loader spreads the stored channels (grey layouts, normal maps in ASTC)", spec=True)
WRITER = Key(
    "KTXwriter", "text", {"type": "string"},
    writers=("texcook.container.ktx2:write_ktx2",), readers=(),
    about="the program that wrote the file (for people and other tools; texcook does not read it)", spec=True)
ORIENTATION = Key(
    "KTXorientation", "text", {"enum": ["rd"]},
    writers=("texcook.container.ktx2:write_ktx2",), readers=(),
    about="texel order: rightwards, then down (for loaders; texcook writes and reads only this order)",
    spec=True)

KEYS: dict[str, Key] = {k.name: k for k in (COLOUR_SPACE, CONTENT, ALPHA_CUTOFF, TRANSFORMS, SAT, SWIZZLE,
                                             WRITER, ORIENTATION)}
for _k in KEYS.values():
    check_name(_k)
del _k


def conforms(value, schema) -> bool:
    """Whether a value (decoded JSON, or the text of a text key) fits a schema
    of the forms the registry uses: type, enum, const, pattern, required,
    properties, items."""
    types = {"object": dict, "array": list, "string": str, "boolean": bool}
    if "type" in schema and not isinstance(value, types[schema["type"]]):
        return False
    if "enum" in schema and value not in schema["enum"]:
        return False
    if "const" in schema and value != schema["const"]:
        return False
    if "pattern" in schema and not re.search(schema["pattern"], value):
        return False
    if isinstance(value, dict):
        if any(k not in value for k in schema.get("required", ())):
            return False
        if any(not conforms(value[k], s) for k, s in schema.get("properties", {}).items() if k in value):
            return False
    if isinstance(value, list) and "items" in schema:
        return all(conforms(v, schema["items"]) for v in value)
    return True
