"""Images in memory and on disk.

Inside texcook an image is float32 (H, W, C) pixels, C in 1..4, with a tag for the
colour space its values are encoded in and the alpha mode. Integer sources are
scaled exactly (v / 255 or v / 65535), so the original integers can be recovered
bit for bit (`integer_values`). OpenImageIO does all file reading and writing.

An integer image read from a file keeps the integers as read (`stored`) and
makes the float32 pixels only when something asks for them: the pipeline
converts the integers straight to linear RGBA through tables, and a 4096x4096
RGBA source then costs 64 MiB instead of 256.
"""

import contextlib
import os
from dataclasses import dataclass, field, replace

import numpy as np

from .errors import InputError, OutputError
from .fileio import check_memory, check_regular, seal, staged_path, texel_bytes

COLOUR_SPACES = ("srgb", "linear")
ALPHA_MODES = ("none", "straight", "premultiplied")
_INT_SCALE = {"uint8": 255.0, "uint16": 65535.0}


class _Pixels:
    """Image.pixels: the float32 values, made from `stored` (through a table of
    the v / max values) the first time they are read."""

    def __get__(self, image, owner=None):
        if image is None:
            return None  # the field's default: an image given only `stored`
        px = image.__dict__.get("_pixels")
        if px is None and image.stored is not None:
            from .colour import unit_table

            bits = 8 if image.stored.dtype == np.uint8 else 16
            px = unit_table(bits)[image.stored]
            image.__dict__["_pixels"] = px
        return px

    def __set__(self, image, value):
        image.__dict__["_pixels"] = value


class _SourceFacts:
    """What an Image and a Header both derive from their channels, alpha mode
    and source type."""

    @property
    def alpha_channel(self):
        """Index of the alpha channel, or None."""
        return None if self.alpha == "none" else self.channels - 1

    @property
    def is_float(self):
        return self.source_dtype in ("half", "float")


@dataclass(frozen=True)
class Image(_SourceFacts):
    pixels: np.ndarray = _Pixels()  # float32 (H, W, C)
    colour_space: str = "srgb"  # how colour channels are encoded: "srgb" or "linear"
    alpha: str = "none"  # "none", "straight" or "premultiplied"
    source_dtype: str = "uint8"  # uint8, uint16, half, float: what the file stored
    path: str = field(default=None, compare=False)
    # the integers as read (uint8/uint16 (H, W, C)) for an integer source, or None
    stored: np.ndarray = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        if self.stored is not None and self.__dict__.get("_pixels") is None:
            st = self.stored
            if not isinstance(st, np.ndarray) or st.dtype.name != self.source_dtype or st.ndim != 3:
                raise TypeError("Image.stored must be (H, W, C) integers of the source's type")
            if not 1 <= st.shape[2] <= 4:
                raise InputError(f"unsupported channel count {st.shape[2]} (1 to 4)", self.path)
        else:
            px = self.pixels
            if not isinstance(px, np.ndarray) or px.dtype != np.float32:
                raise TypeError("Image.pixels must be a float32 array")
            if px.ndim == 2:
                object.__setattr__(self, "pixels", px[:, :, None])
            elif px.ndim != 3:
                raise TypeError("Image.pixels must be (H, W) or (H, W, C)")
            if not 1 <= self.pixels.shape[2] <= 4:
                raise InputError(f"unsupported channel count {self.pixels.shape[2]} (1 to 4)", self.path)
        if self.colour_space not in COLOUR_SPACES:
            raise ValueError(f"colour_space must be one of {COLOUR_SPACES}")
        if self.alpha not in ALPHA_MODES:
            raise ValueError(f"alpha must be one of {ALPHA_MODES}")

    @property
    def shape(self):
        """(H, W, C) without making the float pixels."""
        px = self.__dict__.get("_pixels")
        return (self.stored if px is None else px).shape

    @property
    def height(self):
        return self.shape[0]

    @property
    def width(self):
        return self.shape[1]

    @property
    def channels(self):
        return self.shape[2]

    def integer_values(self):
        """The source's stored integers (uint8/uint16) for integer sources."""
        scale = _INT_SCALE.get(self.source_dtype)
        if scale is None:
            raise InputError("not an integer image", self.path)
        if self.stored is not None:
            return self.stored
        dtype = np.uint8 if self.source_dtype == "uint8" else np.uint16
        return np.rint(self.pixels.astype(np.float64) * scale).astype(dtype)

    def with_pixels(self, pixels, **changes):
        return replace(self, pixels=pixels, stored=None, **changes)

    @classmethod
    def from_array(cls, array, colour_space=None, alpha=None, path=None):
        """Wrap a NumPy array (uint8, uint16 or float). Defaults follow the file
        rules: integer data is sRGB, float data is linear; 2 and 4 channels carry
        straight alpha."""
        a = np.asarray(array)
        if a.ndim == 2:
            a = a[:, :, None]
        if a.dtype == np.uint8 or a.dtype == np.uint16:
            source = a.dtype.name
            px = (a.astype(np.float64) / _INT_SCALE[source]).astype(np.float32)
        elif np.issubdtype(a.dtype, np.floating):
            source = "half" if a.dtype == np.float16 else "float"
            px = a.astype(np.float32)
        else:
            raise InputError(f"unsupported pixel type {a.dtype}", path)
        if colour_space is None:
            colour_space = "linear" if source in ("half", "float") else "srgb"
        if alpha is None:
            alpha = "straight" if a.shape[2] in (2, 4) else "none"
        return cls(np.ascontiguousarray(px), colour_space, alpha, source, path)



def finite_pixels(image, nan_to_zero=False):
    """The float pixels, refused with a count when any is NaN or Inf, or with
    those replaced by 0 when `nan_to_zero`."""
    px = image.pixels
    bad = ~np.isfinite(px)
    if not bad.any():
        return px
    if not nan_to_zero:
        n = int(bad.sum())
        raise InputError(f"{n} NaN or Inf value(s) in the pixels; use --nan-to-zero to replace them with 0", image.path)
    return np.where(bad, np.float32(0.0), px)

@contextlib.contextmanager
def _quiet_stderr():
    """Image libraries print their own diagnostics to the C stderr; the error we
    raise already carries the message, so keep the user's terminal to one line."""
    try:
        saved = os.dup(2)
    except OSError:
        yield
        return
    try:
        with open(os.devnull, "wb") as devnull:
            os.dup2(devnull.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _oiio():
    import OpenImageIO

    return OpenImageIO


def _first_line(msg, fallback):
    msg = (msg or "").strip()
    for line in msg.splitlines():
        line = line.strip()
        if line:
            return line
    return fallback


def _clear_errors(oiio, obj=None):
    """Read and drop OpenImageIO's pending error messages (the object's and the
    global one): left pending, OpenImageIO prints them at exit. Returns them."""
    msgs = []
    if obj is not None:
        with contextlib.suppress(Exception):
            msgs.append(obj.geterror())
    with contextlib.suppress(Exception):
        msgs.append(oiio.geterror())
    return "\n".join(m for m in msgs if m)


# Integer pixel types OpenImageIO would scale by 1/(2^bits - 1): data stored in
# them usually holds 8- or 16-bit values and would come out black.
_WIDE_INTS = ("uint32", "int32", "uint64", "int64", "uint", "int")


def read_image(path) -> Image:
    """Read a PNG, TGA, TIFF, JPEG, EXR, HDR (anything OpenImageIO reads).
    Only a regular file is opened, and only when its declared size fits the
    memory budget (texcook.fileio)."""
    path = os.fspath(path)
    check_regular(path)
    if not os.access(path, os.R_OK):
        raise InputError("permission denied", path)
    oiio = _oiio()
    try:
        with _quiet_stderr():
            return _read_image(oiio, path, _config(oiio))
    except MemoryError:
        raise InputError("out of memory reading the image (lower --max-memory to refuse such files early)",
                         path) from None


@dataclass(frozen=True)
class Header(_SourceFacts):
    """What a file says of its image before any pixel is read: the facts a
    bake plan is made from (texcook.plan). An Image answers the same names."""

    width: int
    height: int
    channels: int
    source_dtype: str  # uint8, uint16, half, float: what the file stores
    colour_space: str  # as stored: "srgb" or "linear"
    alpha: str  # "none" or "straight"
    path: str = None


def header_of(image) -> Header:
    """The Header of an Image (or of a Header: itself)."""
    if isinstance(image, Header):
        return image
    return Header(image.width, image.height, image.channels, image.source_dtype, image.colour_space, image.alpha,
                  image.path)


def read_header(path) -> Header:
    """The Header of an image file, from its spec alone: no pixel is read, and
    a declared size beyond the memory budget is no refusal here (reading the
    pixels refuses it). Only a regular file is opened."""
    path = os.fspath(path)
    check_regular(path)
    if not os.access(path, os.R_OK):
        raise InputError("permission denied", path)
    oiio = _oiio()
    with _quiet_stderr():
        inp = _open(oiio, path, _config(oiio))
        try:
            header, _ = _header(inp.spec(), path)
        finally:
            inp.close()
            _clear_errors(oiio, inp)
    return header


def _config(oiio):
    # straight alpha as stored: by default OpenImageIO premultiplies PNG/TGA on read
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    return config


def _open(oiio, path, config):
    inp = oiio.ImageInput.open(path, config)
    if inp is None:
        msg = _clear_errors(oiio)
        if "could not find a format reader" in msg or "not a" in msg.lower():
            raise InputError("not an image file (no reader recognises it)", path)
        raise InputError(_first_line(msg, "cannot open image"), path)
    return inp


def _header(spec, path):
    """(Header, pixel type to read) of an opened file's spec, or InputError."""
    nch = spec.nchannels
    if not 1 <= nch <= 4:
        raise InputError(f"unsupported channel count {nch} (1 to 4)", path)
    if spec.width < 1 or spec.height < 1:
        raise InputError("image has no pixels", path)
    if spec.deep:
        raise InputError("deep images are not supported", path)
    base = str(spec.format)
    if base in _WIDE_INTS:
        raise InputError(f"{base} pixels are not supported: scaled to 0..1 they would read as near black; "
                         "save the image as 8-bit, 16-bit or float", path)
    if base in ("uint8", "int8"):
        source, req = "uint8", "uint8"
    elif base in ("uint16", "int16"):
        source, req = "uint16", "uint16"
    elif base == "half":
        source, req = "half", "float"
    else:  # float and double are read as float
        source, req = "float", "float"
    space_attr = spec.get_string_attribute("oiio:ColorSpace").lower()
    if source in _INT_SCALE:
        colour_space = "linear" if space_attr.startswith("lin") else "srgb"
    else:
        colour_space = "srgb" if "srgb" in space_attr else "linear"
    # 2 and 4 channels are grey+alpha and RGBA by convention, whatever the file names them
    alpha = "straight" if nch in (2, 4) else "none"
    return Header(spec.width, spec.height, nch, source, colour_space, alpha, path), req


def _read_image(oiio, path, config):
    inp = _open(oiio, path, config)
    try:
        spec = inp.spec()
        header, req = _header(spec, path)
        nch = header.channels
        check_memory(texel_bytes(spec.width, spec.height, nch), f"a {spec.width}x{spec.height} {nch}-channel image",
                     path)
        data = inp.read_image(0, 0, 0, nch, req)
        if data is None or inp.has_error:
            reason = _first_line(_clear_errors(oiio, inp), "unknown error")
            raise InputError(f"truncated or corrupt image ({reason})", path)
    finally:
        inp.close()
        _clear_errors(oiio, inp)
    data = np.asarray(data).reshape(spec.height, spec.width, nch)
    if header.source_dtype in _INT_SCALE:
        # the integers as read; float pixels only if something asks for them
        return Image(None, header.colour_space, header.alpha, header.source_dtype, path,
                     stored=np.ascontiguousarray(data))
    px = np.ascontiguousarray(data, dtype=np.float32)
    return Image(px, header.colour_space, header.alpha, header.source_dtype, path)


def write_image(path, pixels, colour_space=None):
    """Write uint8/uint16/float pixels (H, W, C) to PNG, TGA, TIFF, EXR, HDR...
    by extension, atomically. Float data to an 8-bit format is clamped and rounded
    (NaN written as 0). Alpha is written straight (not premultiplied). colour_space
    defaults to linear for float files and sRGB for integer ones."""
    write_images([(path, pixels)], colour_space)


def write_images(items, colour_space=None):
    """Write several (path, pixels) images all or nothing: each is written to a
    private temporary, checked, and only when all are good are they renamed
    into place (texcook.fileio.staged_path)."""
    oiio = _oiio()
    with contextlib.ExitStack() as stack:
        staged = [_stage_image(oiio, stack, os.fspath(path), pixels, colour_space) for path, pixels in items]
        for s in staged:
            s.commit()


def _stage_image(oiio, stack, path, pixels, colour_space):
    px = np.asarray(pixels)
    if px.ndim == 2:
        px = px[:, :, None]
    h, w, c = px.shape
    ext = os.path.splitext(path)[1].lower()
    if ext in (".exr", ".hdr"):
        fmt = "half" if ext == ".exr" and px.dtype == np.float16 else "float"
        px = px.astype(np.float32)
    elif px.dtype == np.uint16 and ext in (".png", ".tif", ".tiff"):
        fmt = "uint16"
    else:
        if px.dtype != np.uint8:
            # NaN has no 8-bit value: it is written as 0, and +-Inf clamp like any value out of range
            px = np.nan_to_num(px.astype(np.float32), nan=0.0, posinf=1.0, neginf=0.0)
            px = np.rint(np.clip(px, 0.0, 1.0) * 255.0).astype(np.uint8)
        fmt = "uint8"
    if ext == ".hdr" and c not in (3,):
        px = np.concatenate([px[:, :, :1]] * 3, axis=2) if c == 1 else px[:, :, :3]
        c = 3
    names = {1: ("Y",), 2: ("Y", "A"), 3: ("R", "G", "B"), 4: ("R", "G", "B", "A")}[c]
    spec = oiio.ImageSpec(w, h, c, fmt)
    spec.channelnames = names
    if c in (2, 4):
        spec.alpha_channel = c - 1
    if colour_space is None:
        colour_space = "linear" if fmt in ("half", "float") else "srgb"
    spec.attribute("oiio:ColorSpace", "srgb_rec709_scene" if colour_space == "srgb" else "lin_rec709_scene")
    spec.attribute("oiio:UnassociatedAlpha", 1)
    staged, tmp = stack.enter_context(staged_path(path))
    if ext in _JPEG:
        _check_room_for_jpeg(tmp, path, w, h, c)
    with _quiet_stderr():
        out = oiio.ImageOutput.create(tmp)
        if out is None:
            _clear_errors(oiio)
            raise OutputError(f"cannot write this file type ({ext or 'no extension'})", path)
        ok = False
        try:
            ok = out.open(tmp, spec) and out.write_image(np.ascontiguousarray(px))
        finally:
            ok = out.close() and ok and not out.has_error
            err = _clear_errors(oiio, out)
    if not ok:
        # name the user's file, not the private temporary
        reason = _first_line(err.replace(tmp, path), "cannot write image")
        raise OutputError(f"cannot write the image ({reason})", path)
    seal(staged)
    _check_written(oiio, tmp, path, w, h)
    return staged


# libjpeg's default error handler ends the process (exit 1, no message) when a
# write fails, so a JPEG is written only when the disk has room for the largest
# file it could be: measured noise needs 1.3 bytes per texel for grey and 0.5 for
# colour; 2 bytes per texel per stored channel leaves a margin.
_JPEG = (".jpg", ".jpeg", ".jpe", ".jif", ".jfif")


def _check_room_for_jpeg(tmp, path, w, h, c):
    need = w * h * min(c, 3) * 2 + (64 << 10)
    try:
        st = os.statvfs(os.path.dirname(tmp))
    except OSError:
        return
    free = st.f_bavail * st.f_frsize
    if free < need:
        raise OutputError(f"not enough free space to write this JPEG safely ({free} bytes free, up to {need} "
                          "needed); the output was not written", path)


def _check_written(oiio, tmp, path, w, h):
    """Read the written file back: some writers report success on a full disk
    and leave a truncated file."""
    with _quiet_stderr():
        inp = oiio.ImageInput.open(tmp)
        ok = False
        if inp is not None:
            try:
                spec = inp.spec()
                ok = (spec.width, spec.height) == (w, h) and inp.read_image(0, 0, 0, spec.nchannels, "float") is not None
                ok = ok and not inp.has_error
            finally:
                inp.close()
        _clear_errors(oiio, inp)
    if not ok:
        raise OutputError("the written image does not read back (is the disk full?); the output was not written",
                          path)
