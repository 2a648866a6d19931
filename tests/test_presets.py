"""Codec parameter tables (texcook.codecs._presets): every codec covers every
preset name, and a table's columns are the fields its kernels read."""

import numpy as np
import pytest

from texcook.choices import PRESETS
from texcook.codecs._presets import PresetTable


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
