"""Summed-area tables: the sum of any axis-aligned rectangle from four lookups.

Layout: `table[y, x, c]` is the sum of channel c over source texels
[0, x] x [0, y] (inclusive corner, same size as the image, no padding row).
Queries use half-open rectangles like Python slices: box_sum(x0, y0, x1, y1)
covers columns x0 .. x1-1 and rows y0 .. y1-1, so the whole image is
box_sum(0, 0, W, H) and one texel is box_sum(x, y, x + 1, y + 1).

Exactness:
- 8-bit sources are summed in uint32 with wraparound. Rectangle sums are
  differences of table entries, so they come out right modulo 2^32, which is
  the true sum whenever it is below 2^32: for 8-bit data every rectangle of up
  to 16,843,009 texels (4096 x 4096 is 16,777,216).
- 16-bit sources are summed in uint64 in memory (always exact). A KTX2 file
  holds 32-bit words, so a stored 16-bit table is the same sums modulo 2^32:
  exact for rectangles whose true sum is below 2^32 (at least 65,537 texels).
- Float sources have their per-channel mean subtracted first and are summed
  in float64; the mean is kept as `offset` and added back by the queries.
  Centred values keep the partial sums near zero instead of growing with the
  area, which is where float sums lose their low bits.
"""

import json

import numpy as np

from . import formats
from ._jit import jit
from .container import ktx2_keys as keys
from .errors import ContainerError, InputError, UsageError

KV_KEY = keys.SAT.name


def _stored_sample(source):
    """What a table of this source is stored as: float sums or uint32 sums."""
    return "float32" if source == "float" else "uint32"


@jit
def _sat_int(src, out):
    """Integer SAT; `out`'s dtype sets the arithmetic (uint32 wraps mod 2^32).
    Per row: a running sum along x (sequential), then the row above added in
    a separate loop that has no dependency and vectorises."""
    h, w, c = src.shape
    for y in range(h):
        s = src[y]
        o = out[y]
        for k in range(c):
            o[0, k] = s[0, k]
        for x in range(1, w):
            for k in range(c):
                o[x, k] = o[x - 1, k] + s[x, k]  # stored in the table dtype: wraps for uint32
        if y > 0:
            p = out[y - 1]
            for x in range(w):
                for k in range(c):
                    o[x, k] += p[x, k]
    return out


@jit
def _sat_float(src, offset, out):
    """float64 SAT of (src - offset), laid out like _sat_int."""
    h, w, c = src.shape
    for y in range(h):
        s = src[y]
        o = out[y]
        for k in range(c):
            o[0, k] = np.float64(s[0, k]) - offset[k]
        for x in range(1, w):
            for k in range(c):
                o[x, k] = o[x - 1, k] + (np.float64(s[x, k]) - offset[k])
        if y > 0:
            p = out[y - 1]
            for x in range(w):
                for k in range(c):
                    o[x, k] += p[x, k]
    return out


class SummedAreaTable:
    """A summed-area table over an (H, W) or (H, W, C) image."""

    def __init__(self, table, offset, source, channels_given):
        self.table = table  # (H, W, C): uint32 (mod 2^32), uint64, or float64
        self.offset = np.asarray(offset, np.float64)  # (C,), added back per texel
        self.source = source  # "uint8" | "uint16" | "float"
        self._squeeze = not channels_given

    @property
    def height(self):
        return self.table.shape[0]

    @property
    def width(self):
        return self.table.shape[1]

    @property
    def channels(self):
        return self.table.shape[2]

    @classmethod
    def build(cls, pixels):
        """Build from the source's stored values: uint8 / uint16 exactly, or
        float with the mean offset."""
        arr = np.asarray(pixels)
        channels_given = arr.ndim == 3
        if arr.ndim == 2:
            arr = arr[:, :, None]
        if arr.ndim != 3 or arr.shape[0] < 1 or arr.shape[1] < 1 or arr.shape[2] < 1:
            raise UsageError(f"a summed-area table needs an (H, W) or (H, W, C) image, got shape {np.shape(pixels)}")
        if arr.shape[2] > 4:
            raise UsageError(f"a summed-area table holds at most 4 channels, the image has {arr.shape[2]}")
        arr = np.ascontiguousarray(arr)
        h, w, c = arr.shape
        if arr.dtype == np.uint8:
            table = _sat_int(arr, np.empty((h, w, c), np.uint32))
            return cls(table, np.zeros(c), "uint8", channels_given)
        if arr.dtype == np.uint16:
            table = _sat_int(arr, np.empty((h, w, c), np.uint64))
            return cls(table, np.zeros(c), "uint16", channels_given)
        if arr.dtype.kind == "f":
            if not np.isfinite(arr).all():
                raise UsageError("a summed-area table cannot hold NaN or Inf values")
            src = arr if arr.dtype in (np.float32, np.float64) else arr.astype(np.float32)
            # The offset only has to be close to the mean: a float64 mean is
            # plenty, and it is stored exactly, so queries undo it exactly.
            offset = src.reshape(-1, c).mean(axis=0, dtype=np.float64)
            table = _sat_float(src, offset, np.empty((h, w, c), np.float64))
            return cls(table, offset, "float", channels_given)
        raise UsageError(f"summed-area tables take uint8, uint16 or float pixels, not {arr.dtype}")

    # -- queries ------------------------------------------------------------

    def _corners(self, x0, y0, x1, y1):
        x0, y0, x1, y1 = (np.asarray(v, np.int64) for v in (x0, y0, x1, y1))
        if np.any(x0 < 0) or np.any(y0 < 0) or np.any(x1 > self.width) or np.any(y1 > self.height):
            raise UsageError(f"rectangle outside the {self.width}x{self.height} table")
        if np.any(x1 <= x0) or np.any(y1 <= y0):
            raise UsageError("empty rectangle: need x0 < x1 and y0 < y1 (ends are exclusive)")
        t = self.table

        def at(y, x):
            # S(-1, x) = S(y, -1) = 0: the table has no padding row/column.
            valid = (y >= 0) & (x >= 0)
            v = t[np.maximum(y, 0), np.maximum(x, 0)]
            return np.where(valid[..., None], v, np.zeros((), t.dtype))

        return at(y1 - 1, x1 - 1), at(y0 - 1, x1 - 1), at(y1 - 1, x0 - 1), at(y0 - 1, x0 - 1)

    def _raw_sum(self, x0, y0, x1, y1):
        a, b, c, d = self._corners(x0, y0, x1, y1)
        if self.table.dtype == np.uint32:
            # Modular difference: exact whenever the true sum is below 2^32.
            a, b, c, d = (v.astype(np.int64) for v in (a, b, c, d))
            return (a - b - c + d) % (1 << 32)
        if self.table.dtype == np.uint64:
            return a - b - c + d  # uint64 wraps, the true sum is always < 2^64
        return (a - b) - (c - d)

    def box_sum(self, x0, y0, x1, y1):
        """Per-channel sum over columns x0..x1-1, rows y0..y1-1 (arrays allowed:
        the result gains their shape in front of the channel axis). Integer
        tables give exact integers (int64 / uint64); float tables float64."""
        s = self._raw_sum(x0, y0, x1, y1)
        if self.source == "float":
            area = ((np.asarray(x1, np.int64) - x0) * (np.asarray(y1, np.int64) - y0)).astype(np.float64)
            s = s + area[..., None] * self.offset
        return s[..., 0] if self._squeeze else s

    def box_mean(self, x0, y0, x1, y1):
        """Per-channel mean over the same half-open rectangle, float64."""
        area = ((np.asarray(x1, np.int64) - x0) * (np.asarray(y1, np.int64) - y0)).astype(np.float64)
        s = self._raw_sum(x0, y0, x1, y1)
        if self.source == "float":
            m = s / area[..., None] + self.offset
        else:
            m = s.astype(np.float64) / area[..., None]
        return m[..., 0] if self._squeeze else m

    # -- KTX2 ---------------------------------------------------------------

    def to_ktx2(self):
        """(vkFormat, [level bytes], key/values) for write_ktx2. Integer tables
        are stored as R32*_UINT (sums mod 2^32), float tables as R32*_SFLOAT
        (the centred float64 sums rounded to float32) with the offset in the
        key/value data."""
        vk = formats.find(_stored_sample(self.source), self.channels).vk_unorm
        if self.source == "float":
            try:
                with np.errstate(over="raise"):
                    data = self.table.astype("<f4").tobytes()
            except FloatingPointError:
                # values near the float32 maximum of one sign add up past it: Inf is not a sum
                raise InputError("the summed-area table's sums go beyond the float32 range (+-3.4e38); "
                                 "it cannot be stored") from None
        else:
            data = (self.table & np.uint64(0xFFFFFFFF) if self.table.dtype == np.uint64 else self.table)
            data = data.astype("<u4").tobytes()
        meta = {
            "version": 1,
            "source": self.source,
            "layout": "table[y][x] = sum over [0,x]x[0,y] inclusive, origin top-left",
            "sums": "float32 of (value - offset)" if self.source == "float" else "uint32 modulo 2^32",
            # repr round-trips a float64 exactly.
            "offset": [repr(float(v)) for v in self.offset],
            "channels_given": not self._squeeze,
        }
        return vk, [data], {KV_KEY: json.dumps(meta, sort_keys=True)}

    @classmethod
    def from_ktx2(cls, ktx):
        """A table from a read_ktx2 result written by to_ktx2."""
        name = getattr(ktx, "name", "<ktx2>")
        text = ktx.text(KV_KEY) if hasattr(ktx, "text") else None
        if text is None:
            raise ContainerError(f"not a summed-area table (no {KV_KEY} key)", path=name)
        try:
            meta = json.loads(text)
            source = meta["source"]
            offset = np.array([float(v) for v in meta["offset"]], np.float64)
        except (ValueError, KeyError, TypeError) as exc:
            raise ContainerError(f"bad {KV_KEY} value: {exc}", path=name) from None
        vk = ktx.vk_format
        if source not in ("float", "uint8", "uint16"):
            raise ContainerError(f"unknown summed-area table source {source!r}", path=name)
        dtype = "<f4" if source == "float" else "<u4"
        fmt, kind = formats.by_vk_format(vk)
        channels = fmt.channels if fmt is not None and kind == "linear" else None
        if fmt is None or fmt.sample != _stored_sample(source) or fmt.family != "uncompressed" \
                or channels != len(offset):
            raise ContainerError(f"vkFormat {vk} does not fit a {source} summed-area table", path=name)
        w, h = ktx.width, ktx.height
        raw = ktx.levels[0]
        if len(raw) != w * h * channels * 4:
            raise ContainerError("summed-area table level has the wrong size", path=name)
        arr = np.frombuffer(raw, dtype).reshape(h, w, channels)
        table = arr.astype(np.float64) if source == "float" else arr.astype(np.uint32)
        return cls(table, offset, source, bool(meta.get("channels_given", True)))
