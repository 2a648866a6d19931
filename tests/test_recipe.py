"""Recipes: parts, flat construction, serialisation, hashing, and validation
that happens before any pixel is read."""

import json
import tomllib

import numpy as np
import pytest

from texcook.errors import UsageError
from texcook.recipe import SCHEMA_VERSION, Recipe


def _toml(d, prefix=""):
    """A tiny TOML writer for flat tables of plain values (enough for recipes)."""
    lines, tables = [], []
    for k, v in d.items():
        if isinstance(v, dict):
            tables.append((k, v))
        else:
            lines.append(f"{k} = {json.dumps(v)}")
    for k, v in tables:
        lines.append(f"[{prefix}{k}]")
        lines.append(_toml(v, prefix=f"{prefix}{k}."))
    return "\n".join(lines)


RECIPES = [
    Recipe(),
    Recipe.of(format="bc1", preset="thorough", weights=(0.3, 0.6, 0.1), srgb=True),
    Recipe.of(format="bc1a", alpha_cutoff=0.3, mip_filter="kaiser", kaiser_width=2.5, wrap="repeat,mirror"),
    Recipe.of(format="bc5", normal_map=True, mips=False, zstd=9, swizzle="grba"),
    Recipe.of(format="rgba16f", nan_to_zero=True, premultiply=True, sat=True, dds_dx10=True),
]


@pytest.mark.parametrize("recipe", RECIPES)
def test_round_trip_through_dict_json_and_toml(recipe):
    d = recipe.to_dict()
    assert d["version"] == SCHEMA_VERSION
    assert Recipe.from_dict(d) == recipe
    assert Recipe.from_dict(json.loads(json.dumps(d))) == recipe
    assert Recipe.from_dict(tomllib.loads(_toml(d))) == recipe
    assert hash(Recipe.from_dict(d)) == hash(recipe)
    assert Recipe.from_dict(d).digest() == recipe.digest()


def test_normalised_and_hashable():
    a = Recipe.of(format="etc1", weights=[1, 2, 1], wrap="repeat")
    b = Recipe.of(format="ETC1", weights=(1.0, 2.0, 1.0), wrap=("repeat", "repeat"))
    assert a == b and hash(a) == hash(b) and a.digest() == b.digest()
    assert a.mips.wrap == ("repeat", "repeat")
    assert Recipe.of(swizzle="rgba") == Recipe()  # the identity swizzle is no transform
    assert len({a, b, Recipe()}) == 2
    assert Recipe().digest() != a.digest()


def test_parts_are_what_a_reader_sees():
    r = Recipe.of(format="bc1a", alpha_cutoff=0.5, mips=False, zstd=3, preset="fast")
    assert r.source.alpha_cutoff == 0.5 and not r.mips.enabled
    assert (r.codec.format, r.codec.preset) == ("bc1a", "fast") and r.output.zstd == 3
    assert set(r.to_dict()) == {"version", "source", "mips", "codec", "output"}


@pytest.mark.parametrize("flat,needle", [
    (dict(format="bc4", weights=(1, 1, 1)), "bc4 has no option weights"),
    (dict(format="bc1", quality=100), "bc1 has no option quality"),
    (dict(format="etc1s", quality=0), "--quality"),
    (dict(format="bc1", weights=(1, 1)), "weights"),
    (dict(format="bc1", weights=(0, 0, 0)), "not all zero"),
    (dict(format="bc5", srgb=True), "no sRGB variant"),
    (dict(format="rgba16f", srgb=True), "no sRGB variant"),
    (dict(normal_map=True, srgb=True), "normal map"),
    (dict(format="webp"), "unknown format"),
    (dict(format="r32ui"), "no encoder"),
    (dict(preset="ludicrous"), "preset"),
    (dict(zstd=0), "zstd"),
    (dict(alpha_cutoff=1.5), "alpha_cutoff"),
    (dict(lanczos_a=0), "lanczos_a"),
    (dict(kaiser_width=-1.0), "kaiser_width"),
    (dict(mip_filter="gauss"), "--mip-filter"),
    (dict(wrap="spiral"), "wrap"),
    (dict(swizzle="rgbx"), "swizzle"),
    (dict(mips="yes"), "true or false"),
    (dict(colour="red"), "unknown recipe setting"),
])
def test_refused_when_made(flat, needle):
    with pytest.raises(UsageError, match=needle):
        Recipe.of(**flat)


@pytest.mark.parametrize("d,needle", [
    ({"version": 99}, "schema version"),
    ({"codec": {"format": "bc1", "quality": 3}}, "codec.quality"),
    ({"colour": {}}, "unknown recipe part"),
    ({"codec": {"format": "bc1", "options": {"bogus": 1}}}, "bc1 has no option bogus"),
    ({"codec": {"format": "bc1a", "options": {"alpha_threshold": 300}}}, "0..256"),
    ({"mips": "box"}, "must be a table"),
    ([], "table of settings"),
])
def test_from_dict_refuses_bad_input(d, needle):
    with pytest.raises(UsageError, match=needle):
        Recipe.from_dict(d)


def test_container_checks():
    Recipe.of(format="bc1").check_container("dds")
    Recipe.of(format="rgba8").check_container("dds")  # DDS holds the uncompressed formats too
    with pytest.raises(UsageError, match="cannot be written to DDS"):
        Recipe.of(format="etc1").check_container("dds", "x.dds")
    with pytest.raises(UsageError, match="zstd"):
        Recipe.of(format="bc1", zstd=3).check_container("dds")
    with pytest.raises(UsageError, match="sRGB"):
        Recipe.of(format="r8", srgb=True).check_container("dds")
    with pytest.raises(UsageError, match="ktx2, .dds or .astc"):
        Recipe().check_container("png")


def test_options_declared_by_every_codec_are_checked():
    """Every codec refuses an option it does not declare, the same way."""
    import numpy as np

    from texcook import codecs

    px8 = np.zeros((4, 4, 4), np.uint8)
    pxf = np.zeros((4, 4, 4), np.float32)
    for name in codecs.names():
        codec = codecs.get(name)
        with pytest.raises(UsageError, match=f"{name} has no option bogus"):
            codec.encode(pxf if codec.float_input else px8, "fastest", bogus=1)


def test_every_field_is_declared_once_as_a_setting():
    """Each part's field is a setting with its flat name, flags, help and
    default (codec.options are each codec's own); Recipe.of reaches it by the
    flat name, and the declared default is the part's."""
    from dataclasses import fields

    from texcook.recipe import PARTS, SETTINGS

    declared = {(s.part, s.key): s for s in SETTINGS.values() if s.part}
    for part, cls in PARTS.items():
        for f in fields(cls):
            if (part, f.name) == ("codec", "options"):
                continue
            s = declared.pop((part, f.name))
            assert s.help and f.default == s.default, s.name
            assert getattr(Recipe.of(**{s.name: s.default}), part) == getattr(Recipe(), part), s.name
    assert declared == {}
    # the shorthands: colour space, and the codec options a command line names
    assert {s.name for s in SETTINGS.values() if s.part is None} == {"srgb", "linear", "weights", "normal_metric",
                                                                     "quality"}


@pytest.mark.parametrize("flat,line", [
    (dict(mip_filter="gauss"), "mips.filter (--mip-filter) must be one of box, triangle, lanczos, kaiser, not 'gauss'"),
    (dict(lanczos_a=9), "mips.lanczos_a (--lanczos-a) must be within 1..8, not 9"),
    (dict(zstd=2.5), "output.zstd (--zstd) must be an integer, not 2.5"),
    (dict(weights="1,x"), "--weights must be numbers separated by commas, like 1,2,1, not '1,x'"),
    (dict(wrap=3), "mips.wrap (--wrap) must be one or two of clamp, repeat, mirror (x,y), not 3"),
])
def test_a_bad_value_is_named_as_a_file_and_the_command_line_name_it(flat, line):
    with pytest.raises(UsageError) as caught:
        Recipe.of(**flat)
    assert str(caught.value) == line
    part, rest = line.split(".", 1) if "." in line.split()[0] else (None, None)
    if part:  # the same value in a recipe file: the same line
        key = rest.split(" ", 1)[0]
        with pytest.raises(UsageError) as caught:
            Recipe.from_dict({part: {key: next(iter(flat.values()))}})
        assert str(caught.value) == line


def test_a_bake_checks_no_setting_again_per_level(monkeypatch, rng):
    """Settings are checked when the recipe is made: baking its 6 levels
    checks no recipe setting again and the codec's preset and options once."""
    from texcook.codecs._base import Codec
    from texcook.image import Image
    from texcook.pipeline import bake
    from texcook.recipe import Setting

    recipe = Recipe.of(format="bc1", preset="fastest", weights=(1, 2, 1), mip_filter="kaiser", wrap="repeat")
    image = Image.from_array(rng.random((32, 32, 3), dtype=np.float32))
    calls = {"setting": 0, "preset": 0, "options": 0}
    for cls, name, key in ((Setting, "check", "setting"), (Codec, "check_preset", "preset"),
                           (Codec, "check_options", "options")):
        def counted(self, *args, _was=getattr(cls, name), _key=key):
            calls[_key] += 1
            return _was(self, *args)

        monkeypatch.setattr(cls, name, counted)
    baked = bake(image, recipe)
    assert len(baked.levels) == 6
    assert calls == {"setting": 0, "preset": 1, "options": 1}
