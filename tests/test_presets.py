"""Codec parameter tables (texcook.codecs._presets): every codec covers every
preset name, and a table's columns are the fields its kernels read."""

import ast
from pathlib import Path

import pytest

from texcook import codecs
from texcook.choices import DEFAULT_PRESET, PRESETS
from texcook.codecs._presets import PresetTable

CODECS_DIR = Path(codecs.__file__).parent


def _table(rows, columns=("a", "b")):
    return PresetTable("t", {c: "" for c in columns}, rows)


def test_table_rows_and_records():
    t = _table({p: (i, i % 2 == 0) for i, p in enumerate(PRESETS)})
    assert t.presets == PRESETS and t.columns == ("a", "b")
    assert t.row("medium") == (2, 1) and t.row("medium").b == 1
    rec = t.record("fast")
    assert rec.shape == (1,) and rec.dtype.names == ("a", "b") and rec.dtype == t.dtype
    assert (int(rec[0]["a"]), int(rec[0]["b"])) == (1, 0)
    # tables with the same columns share their record type (one compiled kernel)
    assert _table({p: (0, 0) for p in PRESETS}).dtype == t.dtype


@pytest.mark.parametrize("rows", [
    {p: (0, 0) for p in PRESETS[:-1]},  # a preset missing
    dict({p: (0, 0) for p in PRESETS}, slow=(0, 0)),  # an unknown one
    dict({p: (0, 0) for p in PRESETS}, fast=(0,)),  # a value short
    dict({p: (0, 0) for p in PRESETS}, fast=(0, 0.5)),  # not an integer
])
def test_table_refuses_incomplete_rows(rows):
    with pytest.raises(ValueError):
        _table(rows)


def _searching_codecs():
    return [n for n in codecs.names() if codecs.get(n).is_block_compressed]


@pytest.mark.parametrize("name", _searching_codecs())
def test_every_codec_covers_every_preset(name):
    codec = codecs.get(name)
    assert tuple(codec.presets) == PRESETS and DEFAULT_PRESET in PRESETS
    assert codec.preset_tables, f"{name} declares no preset table"
    for table in codec.preset_tables:
        assert table.presets == PRESETS
        for preset in PRESETS:
            assert len(table.record(preset).dtype.names) == len(table.columns)


def _fields_read(path):
    """Fields read from a preset record (`prm.x`) or row (`TABLE.row(p).x`) in one file."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if not isinstance(node, ast.Attribute):
            continue
        v = node.value
        on_record = isinstance(v, ast.Name) and v.id == "prm"
        on_row = isinstance(v, ast.Call) and isinstance(v.func, ast.Attribute) and v.func.attr == "row"
        if on_record or on_row:
            out.add(node.attr)
    return out


def _tables():
    seen = {}
    for name in _searching_codecs():
        for table in codecs.get(name).preset_tables:
            seen[table.name] = table
    return sorted(seen.values(), key=lambda t: t.name)


@pytest.mark.parametrize("table", _tables(), ids=lambda t: t.name)
def test_columns_are_what_the_kernels_read(table):
    files = sorted(CODECS_DIR.glob(f"{table.name}*.py")) + sorted((CODECS_DIR / table.name).glob("**/*.py"))
    # a file named after a longer table name is that table's (etc1s_kernels.py is not etc1's)
    longer = [t.name for t in _tables() if t.name != table.name and t.name.startswith(table.name)]
    files = [f for f in files if not any(f.name.startswith(n) for n in longer)]
    assert files, f"no source file named after table {table.name}"
    read = set().union(*(_fields_read(f) for f in files))
    assert read - set(table.columns) == set(), "fields read that the table lacks"
    assert set(table.columns) - read == set(), "columns no kernel reads"
