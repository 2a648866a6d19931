"""Mip level geometry shared by the containers, and the checks every writer
makes on the levels it is handed."""

from ..errors import UsageError


def max_levels(width: int, height: int) -> int:
    """Length of a full mip chain: floor(log2(max dimension)) + 1."""
    return max(int(width), int(height), 1).bit_length()


def level_dims(width: int, height: int, level: int) -> tuple[int, int]:
    """Size of mip `level`: max(1, n >> level) per axis."""
    return max(1, width >> level), max(1, height >> level)


def check_levels(container, width, height, levels, level_size, name):
    """Raise UsageError unless the size fits the container (32-bit fields) and
    each level holds exactly level_size(w, h) bytes; returns the levels as bytes."""
    if not (isinstance(width, int) and isinstance(height, int)) or width < 1 or height < 1:
        raise UsageError(f"texture size {width}x{height} is invalid")
    if width > 0xFFFFFFFF or height > 0xFFFFFFFF:
        raise UsageError(f"texture size {width}x{height} is too large for {container}")
    levels = list(levels)
    n = len(levels)
    if not 1 <= n <= max_levels(width, height):
        raise UsageError(f"{n} mip levels for {width}x{height}: must be 1..{max_levels(width, height)}")
    out = []
    for i, data in enumerate(levels):
        data = data if isinstance(data, bytes) else memoryview(data).tobytes()
        w, h = level_dims(width, height, i)
        want = level_size(w, h)
        if len(data) != want:
            raise UsageError(f"mip level {i} ({w}x{h} {name}) has {len(data)} bytes, expected {want}")
        out.append(data)
    return out
