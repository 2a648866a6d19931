"""The container table: every row is what its module does, and every format a
container says it holds goes through its writer and back through its reader."""

import os

import numpy as np
import pytest

from texcook import codecs, formats
from texcook.container import table
from texcook.container.table import CONTAINERS, Stored
from texcook.errors import UsageError
from texcook.recipe import Recipe

OUTPUT = Recipe().output  # no zstd, legacy DDS headers where they can say enough
W, H = 9, 7  # partial blocks on both axes, three levels


def _levels(fmt, count, rng):
    out = []
    for i in range(count):
        raw = rng.integers(0, 256, fmt.level_size(*formats.level_dims(W, H, i)), dtype=np.uint8)
        if fmt.dfd_model == formats.MODEL_ETC1S:
            # BasisLZ holds only ETC1S blocks: differential, zero deltas, equal tables, flip 0
            b = raw.reshape(-1, 8)
            b[:, :3] &= 0xF8
            b[:, 3] = ((b[:, 3] & 7) << 5) | ((b[:, 3] & 7) << 2) | 2
        out.append(raw.tobytes())
    return out


def _cases():
    for box in CONTAINERS.values():
        for name in formats.encodable():
            fmt = formats.get(name)
            if not box.holds(fmt):
                continue
            for srgb in (False, True):
                if srgb and not (fmt.vk_srgb and box.holds_srgb(fmt)):
                    continue
                yield pytest.param(box.name, name, srgb, id=f"{box.name}-{name}-{'srgb' if srgb else 'linear'}")


@pytest.mark.parametrize("container, name, srgb", list(_cases()))
def test_every_format_a_container_holds_round_trips(container, name, srgb, tmp_path):
    box, fmt = CONTAINERS[container], formats.get(name)
    rng = np.random.default_rng(sum(map(ord, container + name)) + srgb)
    levels = _levels(fmt, formats.max_levels(W, H) if box.mips else 1, rng)
    kv = {"texcook.content": "normal"} if box.key_values else {}
    data = box.write(Stored(name, srgb, W, H, levels, kv), OUTPUT)
    assert data.startswith(box.magic)
    back = box.read(data, "x" + box.extension)
    # a format stored in another's blocks reads as that one (its transform key tells it apart)
    assert back.format == (fmt.stored_as or name)
    assert (back.width, back.height, back.levels) == (W, H, levels)
    assert back.srgb == (srgb and box.srgb)
    assert {k: back.kv[k] for k in kv} == kv
    path = tmp_path / ("t" + box.extension)
    path.write_bytes(data)
    desc = table.describe_file(str(path))
    assert (desc["container"], desc["width"], desc["height"], desc["levels"]) == (container, W, H, len(levels))


@pytest.mark.parametrize("container", list(CONTAINERS))
def test_row(container):
    box = CONTAINERS[container]
    assert table.get(container) is box
    for ext in box.extensions:
        assert ext.startswith(".") and table.of_path("a/b" + ext.upper()) is box
        assert table.for_output("b" + ext) is box
    assert box.extension in table.EXTENSIONS
    # every encodable format is either held or refused with the row's message
    for name in formats.encodable():
        if box.holds(formats.get(name)):
            assert box.check_format(name) is formats.get(name)
        else:
            with pytest.raises(UsageError):
                box.check_format(name)
    assert box.can_hold(), f"{container} holds no format texcook encodes"
    # codec defaults name options a codec declares
    declared = {o.name for n in codecs.names() for o in codecs.get(n).options}
    assert set(box.codec_defaults) <= declared
    # a model points at it only with a MIME type and an extension for every family
    assert bool(box.mime) == box.in_scenes
    if box.in_scenes:
        assert "*" in box.gltf and set(box.gltf) - {"*"} <= {f.family for f in formats.FORMATS.values()}
        assert container in table.SCENE_CONTAINERS


def test_names_and_extensions_are_the_tables():
    from texcook import choices, pipeline

    assert table.NAMES == tuple(CONTAINERS) and pipeline.TEXTURE_EXTENSIONS == table.EXTENSIONS
    assert set(choices.CONTAINERS) == set(table.NAMES)
    with pytest.raises(UsageError, match=r"\.ktx2, \.dds or \.astc"):
        table.for_output("x.png")
    assert table.of_path("x.png") is None


def test_what_a_container_cannot_hold_is_refused_before_pixels():
    # the checks a recipe meets for each container come from its row
    for box in CONTAINERS.values():
        recipe = Recipe.of(format="bc1") if box.holds(formats.get("bc1")) else Recipe.of(format="astc-4x4")
        box.check_recipe(recipe)
        if not box.zstd:
            with pytest.raises(UsageError, match=f"not {box.title}"):
                box.check_recipe(recipe.replace(zstd=5))
        if not box.key_values:
            with pytest.raises(UsageError, match="no place"):
                box.check_recipe(recipe.replace(renormalize="texture", normal_map=True))


def test_a_file_of_no_container_is_named(tmp_path):
    from texcook.errors import ContainerError

    path = tmp_path / "x.bin"
    path.write_bytes(os.urandom(200).replace(b"D", b"d"))
    with pytest.raises(ContainerError, match="not a KTX2, DDS or .astc file"):
        table.describe_file(str(path))


def test_no_module_outside_the_table_branches_on_a_container_name():
    import pathlib
    import re

    import texcook

    names = "|".join(CONTAINERS)
    exts = "|".join(re.escape(e) for e in table.EXTENSIONS)
    # a format's family may be called "astc" too: `family == "astc"` is not about containers
    branch = re.compile(rf"""(?<!family )[!=]=\s*["']({names})["']|["']({names})["']\s*[!=]=|["']({exts})["']""")
    root = pathlib.Path(texcook.__file__).parent
    found = []
    for path in sorted(root.rglob("*.py")):
        if path.parent.name == "container":
            continue
        for i, line in enumerate(path.read_text().splitlines(), 1):
            if branch.search(line.split("#")[0]):
                found.append(f"{path.relative_to(root)}:{i}: {line.strip()}")
    assert not found, "\n".join(found)
