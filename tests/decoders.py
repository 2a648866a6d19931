"""Other implementations, wrapped once for every test that checks texcook's
bytes against them: texture2ddecoder and astc-encoder-py (astcenc) as
independent decoders, quicktex and etcpak as peer encoders.

Every decoder here returns straight RGBA uint8, (h, w, 4) for an image or
(n, bw*bh, 4) for a row of blocks, whatever order the library uses."""

import numpy as np

from reference import image_blocks


def block_size(fmt):
    """(bw, bh) of a format name: 4x4 for BCn and ETC1, NxM for astc-NxM."""
    if fmt.startswith("astc-"):
        bw, bh = fmt[5:].split("x")
        return int(bw), int(bh)
    return 4, 4


# --------------------------------------------------------------- texture2ddecoder


def t2d(fmt, data, w, h):
    """texture2ddecoder's decode of a level (the function the format table
    names: texcook.bench.independent_decoder). For BC1 it never decodes
    transparency (BC1A's black index comes back opaque), and for ASTC it
    rounds the 16-bit result where the spec takes the top byte (up to one step
    off) and has no sRGB decode."""
    from texcook.bench import independent_decoder

    return independent_decoder(fmt)(data, w, h)


def t2d_eac_signed(fmt, data, w, h):
    """texture2ddecoder's decode of an eac-r11 / eac-rg11 level read as the
    SIGNED variant: each value v as (v + 1023) >> 3. It reads a base codeword
    of -128 as -128 (the spec: as -127)."""
    import texture2ddecoder

    name = {"eac-r11": "decode_eacr_signed", "eac-rg11": "decode_eacrg_signed"}[fmt]
    bgra = getattr(texture2ddecoder, name)(bytes(data), w, h)
    return np.frombuffer(bgra, np.uint8).reshape(h, w, 4)[..., [2, 1, 0, 3]]


def t2d_bc6h(data, w, h):
    """texture2ddecoder's decode_bc6 of an unsigned BC6H level -> (h, w, 3)
    uint8: it decodes as BC6H_UFLOAT and turns each half into
    clamp(round(255 * value), 0, 255), so it checks values in 0..1 at 8-bit
    resolution only. Unlike the specification it does not unquantise an
    endpoint code of all ones to 0xFFFF, and it reads some codes whose top
    bit alone is set differently: blocks with such codes are not comparable."""
    import texture2ddecoder

    bgra = texture2ddecoder.decode_bc6(bytes(data), w, h)
    return np.frombuffer(bgra, np.uint8).reshape(h, w, 4)[..., [2, 1, 0]]


def half_to_unorm8(half):
    """Half floats -> uint8 as texture2ddecoder's BC6H decode rounds them."""
    f = np.asarray(half, np.float16).astype(np.float32)
    return np.clip(np.floor(f * np.float32(255.0) + np.float32(0.5)), 0, 255).astype(np.uint8)


# --------------------------------------------------------------- astcenc


def _astcenc_context(bw, bh, srgb, flags, quality=0):
    import astc_encoder as A

    prof = A.ASTCProfile.LDR_SRGB if srgb else A.ASTCProfile.LDR
    return A.ASTCContext(A.ASTCConfig(prof, bw, bh, 1, quality, flags), 1)


def astcenc_decode(data, bw, bh, w, h, srgb=False, unorm8=False):
    """astcenc's decompressor on an ASTC level -> (h, w, 4). Without `unorm8`
    8-bit texels come from its float decode (rounded); with it, from the
    spec's decode_unorm8 path (the top byte of the 16-bit result)."""
    import astc_encoder as A

    flags = A.ASTCConfigFlags.DECOMPRESS_ONLY
    if unorm8:
        flags |= A.ASTCConfigFlags.USE_DECODE_UNORM8
    out = A.ASTCImage(A.ASTCType.U8, w, h, 1)
    _astcenc_context(bw, bh, srgb, flags).decompress(bytes(data), out, A.ASTCSwizzle.from_str("RGBA"))
    return np.frombuffer(out.data, np.uint8).reshape(h, w, 4)


def astcenc_blocks(data, bw, bh, srgb):
    """astcenc's decode_unorm8 texels of a row of blocks -> (n, bw*bh, 4)."""
    n = len(data) // 16
    return image_blocks(astcenc_decode(data, bw, bh, n * bw, bh, srgb, unorm8=True), bw, bh)


def astcenc_error_texels(data, bw, bh, srgb):
    """(n, bw*bh) bool: texels astcenc decodes to its error value (NaN in its
    float output; its 8-bit output does not paint them magenta)."""
    import astc_encoder as A

    n = len(data) // 16
    ctx = _astcenc_context(bw, bh, srgb, A.ASTCConfigFlags.DECOMPRESS_ONLY)
    img = ctx.decompress(bytes(data), A.ASTCImage(A.ASTCType.F16, n * bw, bh, 1), A.ASTCSwizzle())
    f = np.frombuffer(img.data, np.float16).reshape(bh, n * bw, 4)
    return image_blocks(np.isnan(f).any(-1)[..., None], bw, bh)[..., 0]


def astcenc_encode(rgba, bw, bh, quality, srgb=False):
    """astcenc's compressor at a quality (0..100) -> the ASTC blocks."""
    import astc_encoder as A

    h, w = rgba.shape[:2]
    img = A.ASTCImage(A.ASTCType.U8, w, h, 1, np.ascontiguousarray(rgba).tobytes())
    return _astcenc_context(bw, bh, srgb, 0, quality).compress(img, A.ASTCSwizzle())


# --------------------------------------------------------------- one entry point


def decode(fmt, data, w, h, srgb=False):
    """An independent decode of one level of `fmt` -> RGBA uint8 (h, w, 4):
    astcenc for ASTC (it knows sRGB), texture2ddecoder for the rest."""
    if fmt.startswith("astc-"):
        return astcenc_decode(data, *block_size(fmt), w, h, srgb)
    return t2d(fmt, data, w, h)


# --------------------------------------------------------------- peer encoders


def quicktex_encode(fmt, img, *args, **kw):
    """quicktex's bc1/bc3/bc4/bc5 encoder (constructor arguments as quicktex
    takes them) on an RGBA uint8 image -> the blocks."""
    import importlib

    import quicktex

    mod = importlib.import_module(f"quicktex.s3tc.{fmt}")
    encoder = getattr(mod, f"{fmt.upper()}Encoder")(*args, **kw)
    h, w = img.shape[:2]
    return encoder.encode(quicktex.RawTexture.frombytes(np.ascontiguousarray(img).tobytes(), w, h)).tobytes()


def etcpak_encode(fmt, img):
    """etcpak's encoder of a format (the function the format table names:
    texcook.bench.etcpak_encoder) on an RGBA uint8 image -> the blocks."""
    from texcook.bench import etcpak_encoder

    return bytes(etcpak_encoder(fmt)(np.ascontiguousarray(img)))
