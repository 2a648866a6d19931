"""Property-based fuzzing of everything that reads files texcook did not make:
the KTX2 reader, the DDS reader (each followed by decoding every level, as
`texcook decode` does) and the image front end (OpenImageIO behind read_image).

Each case starts from a small valid file and damages it: truncation, byte
flips, hostile values written into header and index fields, and
supercompression bombs (a level whose stream expands far beyond what the index
declares). The property: the reader either returns data that fits what the
header declares, or raises the documented error (ContainerError / InputError);
nothing else escapes, no "out of memory" is hit (the memory budget is set to
64 MiB, and the process's peak memory may not grow by more than 512 MiB), and
every case ends.

The normal run is a few seconds. The long run (docs/reliability.md):

    TEXCOOK_FUZZ_EXAMPLES=34000 python -m pytest tests/test_fuzz.py -p no:cacheprovider

runs that many cases per test (three readers: about 100,000 in all), with a
random seed each time; the normal run is derandomized, so CI is repeatable.
"""

import os
import resource
import struct
import time
import zlib

import numpy as np
import pytest
import zstandard

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from texcook import codecs, formats  # noqa: E402
from texcook.container.dds import read_dds, write_dds  # noqa: E402
from texcook.container.ktx2 import FORMATS, etc1s_format, read_ktx2, read_texture, write_ktx2  # noqa: E402
from texcook.container.levels import level_dims  # noqa: E402
from texcook.errors import ContainerError, InputError  # noqa: E402
from texcook.fileio import set_max_memory  # noqa: E402
from texcook.image import read_image, write_image  # noqa: E402

LONG = int(os.environ.get("TEXCOOK_FUZZ_EXAMPLES", "0"))
BUDGET = 64 << 20
PEAK_GROWTH = 512 << 20

FUZZ = settings(
    max_examples=LONG or 60,
    derandomize=not LONG,
    deadline=None,
    database=None,
    suppress_health_check=list(HealthCheck),
)

STATS = {}  # test name -> [cases, accepted, refused]


@pytest.fixture(autouse=True)
def budget_and_peak(request):
    """A small memory budget for every case, and a check that the peak resident
    size did not grow by more than PEAK_GROWTH while the cases ran."""
    set_max_memory(BUDGET)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    t0 = time.perf_counter()
    yield
    set_max_memory(None)
    grown = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 - before
    assert grown < PEAK_GROWTH, f"peak memory grew by {grown >> 20} MiB"
    cases, ok, refused = STATS.get(request.node.name, [0, 0, 0])
    if LONG and cases:
        print(f"\nfuzz {request.node.name}: {cases} cases ({ok} read, {refused} refused) "
              f"in {time.perf_counter() - t0:.1f} s, peak growth {max(grown, 0) >> 20} MiB, 0 crashes")


def _count(name, accepted):
    row = STATS.setdefault(name, [0, 0, 0])
    row[0] += 1
    row[1 if accepted else 2] += 1
    if LONG and row[0] % 5000 == 0:  # progress, so a long run cut short still reports
        print(f"\n  {name}: {row[0]} cases passed ({row[1]} read, {row[2]} refused) at {time.strftime('%H:%M:%S')}",
              flush=True)


# ----------------------------------------------------------------------------- seeds


def _random_levels(rng, vk, w, h, n):
    fmt = FORMATS[vk]
    return [rng.integers(0, 256, fmt.level_size(*level_dims(w, h, i)), dtype=np.uint8).tobytes() for i in range(n)]


def _bomb(template, scheme, expands_to, content_size=True):
    """A one-level KTX2 whose index declares the template's small level size but
    whose stream expands to `expands_to` bytes of zeros."""
    raw = bytes(expands_to)
    if scheme == 2:
        blob = zstandard.ZstdCompressor(level=19, write_content_size=content_size).compress(raw)
    else:
        blob = zlib.compress(raw, 9)
    data = bytearray(template)
    (off, length, _ulen) = struct.unpack_from("<3Q", data, 80)
    struct.pack_into("<I", data, 44, scheme)
    del data[off:]
    data += blob
    struct.pack_into("<2Q", data, 80, off, len(blob))
    return bytes(data)


def _ktx2_seeds():
    rng = np.random.default_rng(7)
    seeds = []
    # uncompressed, block and float formats; plain, zstd and zlib supercompression
    for vk, w, h, n in ((43, 5, 3, 3), (9, 4, 4, 1), (97, 3, 2, 2), (109, 2, 2, 2), (131, 8, 8, 4),
                        (137, 4, 8, 2), (139, 7, 5, 3), (141, 4, 4, 3), (147, 8, 4, 2)):
        levels = _random_levels(rng, vk, w, h, n)
        for z in (None, 3):
            seeds.append(write_ktx2(vk, w, h, levels, kv={"note": "fuzz"}, zstd_level=z))
    # ETC1S (BasisLZ global data and slices): an encoded image, since random blocks are not ETC1S
    px = rng.integers(0, 256, (9, 13, 4), dtype=np.uint8)
    for name in ("etc1s", "etc1s-rgba"):
        seeds.append(write_ktx2(etc1s_format(name, False), 13, 9, [codecs.get(name).encode(px)]))
    small = write_ktx2(109, 2, 2, _random_levels(rng, 109, 2, 2, 1), zstd_level=1)
    seeds.append(_bomb(small, 2, 16 << 20))  # frame says 16 MiB, index says 64 bytes
    seeds.append(_bomb(small, 2, 16 << 20, content_size=False))  # frame does not say
    seeds.append(_bomb(small, 3, 16 << 20))  # zlib
    return seeds


def _dds_seeds():
    rng = np.random.default_rng(8)
    seeds = []
    for name in ("bc1", "bc1a", "bc3", "bc4", "bc5", "rgba8", "rg8", "r8", "rgba16f", "rgba32f"):
        fmt = formats.get(name)
        for w, h, n in ((8, 8, 4), (5, 3, 2)):
            levels = [rng.integers(0, 256, fmt.level_size(*level_dims(w, h, i)), dtype=np.uint8).tobytes()
                      for i in range(n)]
            for dx10 in (False, True):
                seeds.append(write_dds(name, w, h, levels, srgb=False, dx10=dx10))
    return seeds


def _image_seeds(tmp):
    rng = np.random.default_rng(9)
    seeds = []
    px8 = rng.integers(0, 256, (6, 5, 4)).astype(np.uint8)
    for ext, px in ((".png", px8), (".png", px8[..., :1].astype(np.uint16) * 257), (".tga", px8),
                    (".tif", px8[..., :3]), (".jpg", px8[..., :3]), (".exr", rng.random((4, 3, 4)).astype(np.float16)),
                    (".hdr", rng.random((3, 4, 3)).astype(np.float32))):
        path = os.path.join(tmp, "seed" + ext)
        write_image(path, px)
        with open(path, "rb") as fh:
            seeds.append((ext, fh.read()))
    return seeds


KTX2_SEEDS = _ktx2_seeds()
DDS_SEEDS = _dds_seeds()

HOSTILE = (0, 1, 2, 3, 4, 0x7F, 0x80, 0xFF, 0x100, 0x7FFF, 0xFFFF, 0x10000, 30000, 65535, 1 << 20,
           0x7FFFFFFF, 0x80000000, 0xFFFFFFFF, 1 << 32, 1 << 40, (1 << 63) - 1, 1 << 63, (1 << 64) - 1)


def _mutation(header_end):
    """One damage to a file: a strategy of functions bytes -> bytes."""
    trunc = st.integers(0, 1 << 16).map(lambda cut: ("cut", cut))
    flip = st.tuples(st.integers(0, 1 << 16), st.integers(0, 255)).map(lambda t: ("set", t))
    field = st.tuples(st.integers(0, header_end), st.sampled_from((1, 2, 4, 8)),
                      st.one_of(st.sampled_from(HOSTILE), st.integers(0, (1 << 64) - 1))).map(lambda t: ("field", t))
    return st.one_of(trunc, flip, field)


def _apply(data, ops):
    data = bytearray(data)
    for kind, arg in ops:
        if not data:
            break
        if kind == "cut":
            del data[arg % (len(data) + 1):]
        elif kind == "set":
            pos, value = arg
            data[pos % len(data)] = value
        else:
            pos, size, value = arg
            pos = pos % len(data)
            chunk = (value & ((1 << (8 * size)) - 1)).to_bytes(size, "little")
            data[pos:pos + size] = chunk[: len(data) - pos]
    return bytes(data)


def _decode_all(codec, width, height, levels):
    for i, level in enumerate(levels):
        w, h = level_dims(width, height, i)
        px = codec.decode(level, w, h)
        assert px.shape[:2] == (h, w)


# ----------------------------------------------------------------------------- KTX2


@FUZZ
@given(seed=st.sampled_from(range(len(KTX2_SEEDS))),
       ops=st.lists(_mutation(80 + 24 * 4 + 64), min_size=0, max_size=4))
def test_ktx2_reader(seed, ops):
    data = _apply(KTX2_SEEDS[seed], ops)
    try:
        ktx = read_ktx2(data, "fuzz.ktx2")
        header = read_ktx2(data, "fuzz.ktx2", load_levels=False)
    except ContainerError as exc:
        assert "out of memory" not in str(exc), exc
        assert str(exc).startswith("fuzz.ktx2: ") and "\n" not in str(exc)
        _count("test_ktx2_reader", False)
        return
    assert len(ktx.levels) == len(header.level_index)
    for i, level in enumerate(ktx.levels):
        assert len(level) == ktx.format.level_size(*ktx.level_dims(i))
    # the format as the reader names it (ETC1S has vkFormat 0 and is named by its DFD)
    name = read_texture(data, "fuzz.ktx2").format
    if name is not None and name in codecs.names():
        _decode_all(codecs.get(name), ktx.width, ktx.height, ktx.levels)
    _count("test_ktx2_reader", True)


def test_ktx2_bombs_are_refused_within_the_declared_size():
    """The three bomb seeds, undamaged: each is refused without producing more
    than the declared 64 bytes (peak memory checked by the fixture)."""
    for data in KTX2_SEEDS[-3:]:
        with pytest.raises(ContainerError, match="expands|corrupt"):
            read_ktx2(data, "bomb.ktx2")


# ----------------------------------------------------------------------------- DDS


@FUZZ
@given(seed=st.sampled_from(range(len(DDS_SEEDS))), ops=st.lists(_mutation(148), min_size=0, max_size=4))
def test_dds_reader(seed, ops):
    data = _apply(DDS_SEEDS[seed], ops)
    try:
        name, width, height, levels, _srgb = read_dds(data, "fuzz.dds")
    except ContainerError as exc:
        assert "out of memory" not in str(exc), exc
        assert str(exc).startswith("fuzz.dds: ") and "\n" not in str(exc)
        _count("test_dds_reader", False)
        return
    _decode_all(codecs.get(name), width, height, levels)
    _count("test_dds_reader", True)


# ----------------------------------------------------------------------------- images


@pytest.fixture(scope="module")
def image_seeds(tmp_path_factory):
    return _image_seeds(str(tmp_path_factory.mktemp("seeds")))


@pytest.fixture(scope="module")
def scratch(tmp_path_factory):
    return tmp_path_factory.mktemp("fuzz")


def _fix_png_crcs(data):
    """Recompute every chunk CRC, so a changed IHDR field reaches the decoder
    as a hostile value rather than as a checksum error."""
    data = bytearray(data)
    pos = 8
    while pos + 12 <= len(data):
        (length,) = struct.unpack_from(">I", data, pos)
        end = pos + 8 + length
        if end + 4 > len(data):
            break
        struct.pack_into(">I", data, end, zlib.crc32(data[pos + 4:end]) & 0xFFFFFFFF)
        pos = end + 4
    return bytes(data)


@FUZZ
@given(seed=st.integers(0, 6), ops=st.lists(_mutation(64), min_size=0, max_size=4), fix_crc=st.booleans())
def test_image_reader(image_seeds, scratch, seed, ops, fix_crc):
    ext, original = image_seeds[seed]
    data = _apply(original, ops)
    if ext == ".png" and fix_crc:
        data = _fix_png_crcs(data)
    path = scratch / f"case{ext}"
    path.write_bytes(data)
    try:
        img = read_image(path)
    except InputError as exc:
        assert "out of memory" not in str(exc), exc
        assert str(exc).startswith(str(path)) and "\n" not in str(exc)
        _count("test_image_reader", False)
        return
    assert img.pixels.dtype == np.float32 and 1 <= img.channels <= 4
    assert img.pixels.nbytes <= BUDGET
    _count("test_image_reader", True)


def test_png_declaring_a_huge_size_is_refused_before_reading(image_seeds, scratch):
    """30000x30000 in IHDR (valid CRC) is refused from the header; so is a real
    2100x2100 PNG (17 KB of zeros) that needs more than the 64 MiB budget."""
    ext, png = image_seeds[0]
    data = bytearray(png)
    struct.pack_into(">II", data, 16, 30000, 30000)
    path = scratch / "huge.png"
    path.write_bytes(_fix_png_crcs(data))
    with pytest.raises(InputError, match="huge.png: .*(header|budget)"):
        read_image(path)
    big = scratch / "big.png"
    set_max_memory(None)
    write_image(big, np.zeros((2100, 2100, 4), np.uint8))
    set_max_memory(BUDGET)
    with pytest.raises(InputError, match="2100x2100 4-channel image needs 67.3M, more than the 64.0M memory budget"):
        read_image(big)


def test_seeds_are_valid(image_seeds):
    """The fuzzing starts from files the readers accept."""
    for data in KTX2_SEEDS[:-3]:
        read_ktx2(data)
    for data in DDS_SEEDS:
        read_dds(data)
    assert len(image_seeds) == 7 and all(len(d) > 16 for _, d in image_seeds)


@FUZZ
@given(seed=st.sampled_from(range(len(KTX2_SEEDS))), ops=st.lists(_mutation(80 + 24 * 4 + 64), max_size=3))
def test_ktx2_describe_from_the_metadata_alone(seed, ops):
    """`texcook info` reads only the first metadata_end() bytes: it must accept
    and refuse exactly what reading the whole file does, and say the same."""
    from texcook.container.ktx2 import describe, metadata_end

    data = _apply(KTX2_SEEDS[seed], ops)
    prefix = data[: metadata_end(data[:148], len(data))]
    results = []
    for blob, size in ((data, None), (prefix, len(data))):
        try:
            results.append(describe(read_ktx2(blob, "f.ktx2", load_levels=False, file_size=size)))
        except ContainerError as exc:
            results.append(str(exc))
    assert results[0] == results[1]


@FUZZ
@given(seed=st.sampled_from(range(len(DDS_SEEDS))), ops=st.lists(_mutation(148), max_size=3))
def test_dds_describe_from_the_header_alone(seed, ops):
    from texcook.container.dds import HEADER_BYTES, describe_dds, parse_dds

    data = _apply(DDS_SEEDS[seed], ops)
    results = []
    for blob, size in ((data, None), (data[:HEADER_BYTES], len(data))):
        try:
            results.append(describe_dds(parse_dds(blob, "f.dds", file_size=size)))
        except ContainerError as exc:
            results.append(str(exc))
    assert results[0] == results[1]
