"""The checks every container writer makes on the levels it is handed. The
geometry they check against (level sizes, the mip count) is texcook.formats'."""

from ..errors import UsageError
from ..formats import level_dims, max_levels


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
