import numpy as np
import pytest

from texcook.errors import InputError
from texcook.image import Image, read_image, write_image


@pytest.mark.parametrize("channels", [1, 2, 3, 4])
@pytest.mark.parametrize("ext,dtype", [
    (".png", np.uint8), (".png", np.uint16), (".tga", np.uint8), (".tif", np.uint8),
    (".tif", np.uint16), (".exr", np.float32),
])
def test_lossless_formats_round_trip(tmp_path, rng, ext, dtype, channels):
    shape = (5, 7, channels)
    if dtype == np.float32:
        px = (rng.random(shape) * 100).astype(np.float32)
    else:
        px = rng.integers(0, np.iinfo(dtype).max + 1, shape).astype(dtype)
    path = tmp_path / f"x{ext}"
    write_image(path, px)
    img = read_image(path)
    assert img.channels == channels and (img.width, img.height) == (7, 5)
    assert img.alpha == ("straight" if channels in (2, 4) else "none")
    if dtype == np.float32:
        assert img.source_dtype == "float" and img.colour_space == "linear"
        assert np.array_equal(img.pixels, px)
    else:
        assert img.source_dtype == np.dtype(dtype).name and img.colour_space == "srgb"
        assert np.array_equal(img.integer_values(), px)


def test_half_exr_and_hdr_keep_values_above_one(tmp_path):
    px = np.array([[[0.25, 1.5, 1000.0]]], np.float32)
    write_image(tmp_path / "h.exr", px.astype(np.float16))
    img = read_image(tmp_path / "h.exr")
    assert img.source_dtype == "half" and np.allclose(img.pixels, px)
    rgbe = np.array([[[1.5, 2.0, 3.0]]], np.float32)  # RGBE shares one exponent per texel
    write_image(tmp_path / "r.hdr", rgbe)
    img = read_image(tmp_path / "r.hdr")
    assert img.is_float and np.allclose(img.pixels, rgbe, rtol=0.01)


def test_jpeg_reads_as_8bit_srgb(tmp_path):
    px = np.full((16, 16, 3), 100, np.uint8)
    write_image(tmp_path / "j.jpg", px)
    img = read_image(tmp_path / "j.jpg")
    assert img.source_dtype == "uint8" and img.colour_space == "srgb"
    assert np.abs(img.integer_values().astype(int) - 100).max() <= 2


def test_corpus_images_read(corpus):
    img = read_image(corpus / "rgb" / "ldr-rgb-10.png")
    assert (img.width, img.height) == (127, 128)
    hdr = read_image(corpus / "hdr" / "hdr-rgb-00.hdr")
    assert hdr.is_float and hdr.colour_space == "linear"


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        read_image(tmp_path / "nope.png")


def test_not_an_image(tmp_path):
    p = tmp_path / "notes.png"
    p.write_text("this is not a picture")
    with pytest.raises(InputError, match="not an image|cannot open|corrupt"):
        read_image(p)


def test_truncated_png(tmp_path, corpus):
    data = (corpus / "rgb" / "ldr-rgb-01.png").read_bytes()
    p = tmp_path / "cut.png"
    p.write_bytes(data[: len(data) // 3])
    with pytest.raises(InputError, match="truncated or corrupt") as err:
        read_image(p)
    assert str(p) in str(err.value) and "\n" not in str(err.value)


def test_unsupported_channel_count(tmp_path, rng):
    p = tmp_path / "five.tif"
    write_image_raw(p, rng.integers(0, 255, (4, 4, 5)).astype(np.uint8))
    with pytest.raises(InputError, match="unsupported channel count 5"):
        read_image(p)


def write_image_raw(path, px):
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(px.shape[1], px.shape[0], px.shape[2], "uint8"))
    out.write_image(px)
    out.close()


def test_from_array_defaults():
    img = Image.from_array(np.zeros((2, 3, 4), np.uint8))
    assert img.colour_space == "srgb" and img.alpha == "straight" and img.alpha_channel == 3
    img = Image.from_array(np.zeros((2, 3), np.float32))
    assert img.colour_space == "linear" and img.channels == 1 and img.alpha_channel is None
