"""Codec parameters, declared once per codec: a table whose rows are the
presets and whose columns are named integer fields.

    SEARCH = PresetTable(
        "bc4",
        columns={
            "window": "endpoint pairs within +-window of each candidate are measured",
            "ls_iters": "least-squares refinement rounds",
        },
        rows={
            #              window  ls_iters
            "fastest":    (0,      0),
            "fast":       (1,      1),
            "medium":     (2,      2),
            "thorough":   (4,      3),
            "exhaustive": (4,      3),
        },
    )

The table checks when it is made that it has a row for every name of
`texcook.choices.PRESETS` and no other, and that every row has one integer
(or bool, stored as 0/1) per column; a mistake fails at import.

Reading it:

- `SEARCH.row(preset)`: the row as a named tuple, for Python code
  (`SEARCH.row("fast").window`).
- `SEARCH.record(preset)`: the row as a one-element NumPy structured array
  (a recarray) with one int64 field per column (dtype `SEARCH.dtype`). A kernel takes it
  and reads the named slots of its record, `prm = rec[0]` then `prm.window`:
  numba types the record by its fields, so one compiled kernel serves every
  preset and no slot is numbered by hand. A record passed on to helpers is a
  pointer, without reference counting.
- `SEARCH.columns`, `SEARCH.presets` (in the order of choices.PRESETS),
  `SEARCH.name`.

Tables made with the same columns (say one per block size) share their
dtype, so their records are read by the same compiled kernels.

Kernels name the record they read `prm` (and Python code reads `.row(...)`);
tests/test_presets.py checks, for the source files named after the table
(`<name>*.py`, or the package `<name>/`), that the fields read are the
table's columns and every column is read.
"""

from collections import namedtuple

import numpy as np

from ..choices import PRESETS
from ..errors import UsageError


class PresetTable:
    def __init__(self, name, columns, rows):
        self.name = name
        self.columns = tuple(columns)
        self.docs = dict(columns)
        missing = [p for p in PRESETS if p not in rows]
        extra = [p for p in rows if p not in PRESETS]
        if missing or extra:
            raise ValueError(f"{name} presets: missing {missing}, unknown {extra}")
        self.presets = PRESETS
        self._tuple = namedtuple(f"{name.replace('-', '_')}_preset", self.columns)
        self.dtype = np.dtype([(c, np.int64) for c in self.columns])
        self._rows = {}
        for preset in PRESETS:
            values = tuple(rows[preset])
            if len(values) != len(self.columns):
                raise ValueError(f"{name} preset {preset}: {len(values)} values for "
                                 f"{len(self.columns)} columns {self.columns}")
            for c, v in zip(self.columns, values):
                if not isinstance(v, (bool, int, np.integer)):
                    raise ValueError(f"{name} preset {preset}: {c} must be an integer, not {v!r}")
            self._rows[preset] = self._tuple(*(int(v) for v in values))

    def row(self, preset):
        """The row of `preset` as a named tuple of ints."""
        try:
            return self._rows[preset]
        except KeyError:
            raise UsageError(f"unknown preset {preset!r}; choose one of {', '.join(PRESETS)}") from None

    def record(self, preset):
        """The row of `preset` as a one-element structured array for kernels
        (a NumPy recarray: numba types it as the plain array, and with the
        kernels run as Python its element reads fields as attributes too)."""
        return np.array([tuple(self.row(preset))], self.dtype).view(np.recarray)

    def __repr__(self):
        return f"PresetTable({self.name!r}, columns={self.columns})"
