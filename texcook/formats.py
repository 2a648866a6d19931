"""The one table of texture format facts.

Every other module derives what it needs from here: the codec registry (which
module encodes a format), the KTX2 writer and reader (vkFormats and the DFD),
DDS (DXGI formats and FourCCs), the summed-area table (its 32-bit formats) and
`texcook formats`. Families with a parameter (ASTC's block sizes) are generated.

Facts come from the Vulkan format list, the Khronos Data Format Specification
(colour models, channel ids) and Microsoft's DXGI_FORMAT enumeration.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from .errors import UsageError

# Khronos Data Format colour models (khr_df.h).
MODEL_RGBSDA = 1
MODEL_BC1A = 128
MODEL_BC3 = 130
MODEL_BC4 = 131
MODEL_BC5 = 132
MODEL_BC6H = 133
MODEL_BC7 = 134  # khr_df.h KHR_DF_MODEL_BC7 (BPTC UNORM)
MODEL_ETC2 = 161
MODEL_ASTC = 162
MODEL_ETC1S = 163  # Basis Universal ETC1S, stored with BasisLZ supercompression (vkFormat 0)
MODEL_NAMES = {1: "RGBSDA", 128: "BC1A", 130: "BC3", 131: "BC4", 132: "BC5", 133: "BC6H", 134: "BC7",
               161: "ETC2", 162: "ASTC", 163: "ETC1S"}
# RGBSDA alpha; BC3 and ETC2 use the same id for their alpha samples.
CHANNEL_ALPHA = 15

# What encode takes, decode returns, and a texel stores.
SAMPLE_TYPES = ("unorm8", "float16", "float32", "uint32")

# How a format's quality is measured (texcook bench), on the 8-bit values as
# stored, straight alpha:
SCORINGS = {
    "rgb": "PSNR of R, G and B",
    "rgba": "PSNR of R, G, B and A",
    "alpha": "PSNR of a single channel, fed with the alpha of cut-out images",
    "normal": "PSNR of X and Y of normal maps, and the angular error of the normals with Z rebuilt",
    "hdr": "PSNR of log2 R, G and B of HDR images (metrics.log2_psnr), on the float values",
}


@dataclass(frozen=True)
class Format:
    name: str  # texcook's name: "bc1", "astc-6x6", "r32ui"
    family: str  # "uncompressed", "bc", "etc", "astc", "basis" (transcoded on load: ETC1S)
    vk_name: str  # Vulkan name stem, without VK_FORMAT_ and the numeric suffix
    vk_unorm: int  # the linear vkFormat (UNORM, SFLOAT or UINT)
    block_w: int
    block_h: int
    bytes_per_block: int
    channels: int  # channels the format stores (1..4)
    sample: str = "unorm8"
    vk_srgb: int = 0  # 0: no sRGB twin
    vk_snorm: int = 0  # a signed twin texcook reads but does not write
    dfd_model: int = MODEL_RGBSDA
    dfd_channels: tuple = ()  # block formats: channel id of each 64/128-bit sample
    dxgi: int = 0  # 0: DDS cannot hold it
    dxgi_srgb: int = 0
    fourcc: bytes = b""  # legacy DDS FourCC, when one exists
    codec_module: str = ""  # module whose CODECS dict holds the codec; "" = container only
    description: str = ""
    scoring: str = "rgba"  # a key of SCORINGS
    # A format stored in another's blocks (its vkFormat, DFD and DXGI are that
    # format's) and told apart by the transform it records under the KTX2 key
    # texcook.transforms: readers decode `stored_as` and undo `transform`
    # (none: blocks that format decodes as they are, as ETC1's in ETC2).
    stored_as: str = ""
    transform: str = ""
    # A format that shares another's DXGI code and FourCC (copied from it when
    # the table is built): DDS tells the two apart by its alpha flags.
    dds_alpha_of: str = ""
    # A float format without a sign (BC6H's UFLOAT): negative values clamp to 0.
    unsigned_float: bool = False
    # Other implementations, for `texcook bench` and the tests: the
    # texture2ddecoder function that decodes it to 8-bit BGRA (the independent
    # decoder; ASTC's takes the block size too) and the etcpak function that
    # encodes it from RGBA (a peer). "": none.
    t2d: str = ""
    etcpak: str = ""

    @property
    def is_float(self) -> bool:
        return self.sample in ("float16", "float32")

    @property
    def is_block_compressed(self) -> bool:
        return self.dfd_model != MODEL_RGBSDA

    @property
    def bits_per_texel(self) -> float:
        return 8.0 * self.bytes_per_block / (self.block_w * self.block_h)

    @property
    def linear_suffix(self) -> str:
        if self.unsigned_float:
            return "UFLOAT"
        return {"unorm8": "UNORM", "float16": "SFLOAT", "float32": "SFLOAT", "uint32": "UINT"}[self.sample]

    @property
    def has_srgb(self) -> bool:
        """Whether the format can be stored as sRGB-encoded values: an sRGB
        vkFormat twin, or (ETC1S, vkFormat 0) the DFD's transfer function."""
        return bool(self.vk_srgb) or self.dfd_model == MODEL_ETC1S

    @property
    def basislz(self) -> bool:
        """Stored BasisLZ-supercompressed (ETC1S): Zstandard cannot be applied on top."""
        return self.dfd_model == MODEL_ETC1S

    def vk_format(self, srgb: bool) -> int:
        if self.dfd_model == MODEL_ETC1S:
            return 0  # VK_FORMAT_UNDEFINED: sRGB or linear is only the DFD's transfer function
        if srgb and not self.vk_srgb:
            raise UsageError(f"format {self.name} has no sRGB variant; use --linear")
        return self.vk_srgb if srgb else self.vk_unorm

    def level_size(self, width: int, height: int) -> int:
        return level_size(width, height, self.block_w, self.block_h, self.bytes_per_block)

    def facts(self) -> dict:
        """JSON-able facts, for `texcook formats`."""
        return {
            "name": self.name,
            "family": self.family,
            "vk_format": {"unorm": self.vk_unorm, "srgb": self.vk_srgb or None, "snorm": self.vk_snorm or None},
            "vk_name": self.vk_name,
            "block": [self.block_w, self.block_h],
            "bytes_per_block": self.bytes_per_block,
            "bits_per_texel": round(self.bits_per_texel, 3),
            "channels": self.channels,
            "sample": self.sample,
            "dxgi": {"unorm": self.dxgi or None, "srgb": self.dxgi_srgb or None},
            "fourcc": self.fourcc.decode() if self.fourcc else None,
            "dfd_color_model": MODEL_NAMES[self.dfd_model],
            "encoder": bool(self.codec_module),
            "scoring": self.scoring,
            "description": self.description,
            "stored_as": self.stored_as or None,
            "transform": self.transform or None,
        }


_UNCOMPRESSED = "texcook.codecs.uncompressed"

_TABLE = [
    Format("r8", "uncompressed", "R8", 9, 1, 1, 1, 1, vk_srgb=15, dxgi=61,
           codec_module=_UNCOMPRESSED, description="8-bit red", scoring="alpha"),
    Format("rg8", "uncompressed", "R8G8", 16, 1, 1, 2, 2, vk_srgb=22, dxgi=49,
           codec_module=_UNCOMPRESSED, description="8-bit red-green", scoring="normal"),
    Format("rgba8", "uncompressed", "R8G8B8A8", 37, 1, 1, 4, 4, vk_srgb=43, dxgi=28, dxgi_srgb=29,
           codec_module=_UNCOMPRESSED, description="8-bit RGBA"),
    Format("rgba16f", "uncompressed", "R16G16B16A16", 97, 1, 1, 8, 4, sample="float16", dxgi=10,
           codec_module=_UNCOMPRESSED, description="16-bit float RGBA"),
    Format("rgba32f", "uncompressed", "R32G32B32A32", 109, 1, 1, 16, 4, sample="float32", dxgi=2,
           codec_module=_UNCOMPRESSED, description="32-bit float RGBA"),
    # 32-bit integer and float formats that only summed-area tables use.
    Format("r32ui", "uncompressed", "R32", 98, 1, 1, 4, 1, sample="uint32", dxgi=42),
    Format("rg32ui", "uncompressed", "R32G32", 101, 1, 1, 8, 2, sample="uint32", dxgi=17),
    Format("rgb32ui", "uncompressed", "R32G32B32", 104, 1, 1, 12, 3, sample="uint32", dxgi=7),
    Format("rgba32ui", "uncompressed", "R32G32B32A32", 107, 1, 1, 16, 4, sample="uint32", dxgi=3),
    Format("r32f", "uncompressed", "R32", 100, 1, 1, 4, 1, sample="float32", dxgi=41),
    Format("rg32f", "uncompressed", "R32G32", 103, 1, 1, 8, 2, sample="float32", dxgi=16),
    Format("rgb32f", "uncompressed", "R32G32B32", 106, 1, 1, 12, 3, sample="float32", dxgi=6),
    Format("bc1", "bc", "BC1_RGB", 131, 4, 4, 8, 3, vk_srgb=132, dfd_model=MODEL_BC1A, dfd_channels=(0,),
           dxgi=71, dxgi_srgb=72, fourcc=b"DXT1", codec_module="texcook.codecs.bc1",
           description="BC1 (DXT1) RGB, 4 bits per texel", scoring="rgb", t2d="decode_bc1", etcpak="compress_bc1"),
    Format("bc1a", "bc", "BC1_RGBA", 133, 4, 4, 8, 4, vk_srgb=134, dfd_model=MODEL_BC1A, dfd_channels=(1,),
           dds_alpha_of="bc1", codec_module="texcook.codecs.bc1",
           description="BC1 (DXT1) RGB with 1-bit alpha, 4 bits per texel", t2d="decode_bc1"),
    Format("bc3", "bc", "BC3", 137, 4, 4, 16, 4, vk_srgb=138, dfd_model=MODEL_BC3,
           dfd_channels=(CHANNEL_ALPHA, 0), dxgi=77, dxgi_srgb=78, fourcc=b"DXT5",
           codec_module="texcook.codecs.bc3",
           description="BC3 (DXT5) RGB + interpolated alpha, 8 bits per texel",
           t2d="decode_bc3", etcpak="compress_bc3"),
    Format("bc4", "bc", "BC4", 139, 4, 4, 8, 1, vk_snorm=140, dfd_model=MODEL_BC4, dfd_channels=(0,),
           dxgi=80, fourcc=b"ATI1", codec_module="texcook.codecs.bc4",
           description="BC4 one channel (red), 4 bits per texel", scoring="alpha",
           t2d="decode_bc4", etcpak="compress_bc4"),
    Format("bc5", "bc", "BC5", 141, 4, 4, 16, 2, vk_snorm=142, dfd_model=MODEL_BC5, dfd_channels=(0, 1),
           dxgi=83, fourcc=b"ATI2", codec_module="texcook.codecs.bc5",
           description="BC5 two channels (red, green), 8 bits per texel", scoring="normal",
           t2d="decode_bc5", etcpak="compress_bc5"),
    Format("bc7", "bc", "BC7", 145, 4, 4, 16, 4, vk_srgb=146, dfd_model=MODEL_BC7, dfd_channels=(0,),
           dxgi=98, dxgi_srgb=99, codec_module="texcook.codecs.bc7",
           description="BC7 (BPTC) RGBA in eight modes, 8 bits per texel", t2d="decode_bc7", etcpak="compress_bc7"),
    # ETC1 blocks are ETC2 RGB blocks that decode the same: written with etc2's
    # vkFormat and DFD, read back as etc2 (no transform to undo)
    Format("etc1", "etc", "ETC2_R8G8B8", 147, 4, 4, 8, 3, vk_srgb=148, dfd_model=MODEL_ETC2, dfd_channels=(2,),
           codec_module="texcook.codecs.etc1", description="ETC1 RGB (stored as ETC2_R8G8B8)", scoring="rgb",
           stored_as="etc2", t2d="decode_etc1", etcpak="compress_etc1_rgb"),
    Format("etc2", "etc", "ETC2_R8G8B8", 147, 4, 4, 8, 3, vk_srgb=148, dfd_model=MODEL_ETC2, dfd_channels=(2,),
           codec_module="texcook.codecs.etc2", description="ETC2 RGB (ETC1 modes plus T, H and planar), 4 bits per texel",
           scoring="rgb", t2d="decode_etc2", etcpak="compress_etc2_rgb"),
    # one 64-bit sample per channel id, both over the whole block (KTX-Software's createDFDCompressed)
    Format("etc2a1", "etc", "ETC2_R8G8B8A1", 149, 4, 4, 8, 4, vk_srgb=150, dfd_model=MODEL_ETC2,
           dfd_channels=(2, CHANNEL_ALPHA), codec_module="texcook.codecs.etc2",
           description="ETC2 RGB with punch-through (1-bit) alpha, 4 bits per texel", t2d="decode_etc2a1"),
    # EAC: ETC2 model channel ids RED 0, GREEN 1 (KDF khr_df.h); texcook writes UNSIGNED, reads SIGNED too
    Format("eac-r11", "etc", "EAC_R11", 153, 4, 4, 8, 1, vk_snorm=154, dfd_model=MODEL_ETC2, dfd_channels=(0,),
           codec_module="texcook.codecs.eac", description="EAC R11 one channel (red), 4 bits per texel",
           scoring="alpha", t2d="decode_eacr", etcpak="compress_eac_r"),
    Format("eac-rg11", "etc", "EAC_R11G11", 155, 4, 4, 16, 2, vk_snorm=156, dfd_model=MODEL_ETC2,
           dfd_channels=(0, 1), codec_module="texcook.codecs.eac",
           description="EAC RG11 two channels (red, green), 8 bits per texel", scoring="normal",
           t2d="decode_eacrg", etcpak="compress_eac_rg"),
    # RGBA ETC2: the EAC alpha block (ALPHA 15) then the ETC2 colour block (COLOR 2)
    Format("etc2a8", "etc", "ETC2_R8G8B8A8", 151, 4, 4, 16, 4, vk_srgb=152, dfd_model=MODEL_ETC2,
           dfd_channels=(CHANNEL_ALPHA, 2), codec_module="texcook.codecs.etc2a8",
           description="ETC2 RGB + EAC alpha, 8 bits per texel", t2d="decode_etc2a8", etcpak="compress_etc2_rgba"),
    # BC6H: half-float RGB in 128-bit blocks, unsigned (UFLOAT) and signed (SFLOAT)
    Format("bc6h", "bc", "BC6H", 143, 4, 4, 16, 3, sample="float16", unsigned_float=True, dfd_model=MODEL_BC6H,
           dfd_channels=(0,), dxgi=95, codec_module="texcook.codecs.bc6h",
           description="BC6H unsigned half-float RGB (HDR), 8 bits per texel", scoring="hdr"),
    Format("bc6h-sf", "bc", "BC6H", 144, 4, 4, 16, 3, sample="float16", dfd_model=MODEL_BC6H,
           dfd_channels=(0,), dxgi=96, codec_module="texcook.codecs.bc6h",
           description="BC6H signed half-float RGB (HDR), 8 bits per texel", scoring="hdr"),
    # Scaled YCoCg-DXT5: BC3 blocks holding Co, Cg (scaled per block, the scale in
    # blue) and Y in alpha. No sRGB twin: the sampler must not decode chroma as sRGB.
    Format("bc3-ycocg", "bc", "BC3", 137, 4, 4, 16, 3, dfd_model=MODEL_BC3,
           dfd_channels=(CHANNEL_ALPHA, 0), codec_module="texcook.codecs.ycocg", stored_as="bc3",
           transform="ycocg", description="BC3 holding scaled YCoCg (RGB), 8 bits per texel", scoring="rgb",
           t2d="decode_bc3"),
    # ETC1S (Basis Universal): ETC1 blocks restricted to one colour and table per
    # block, stored only in KTX2 with BasisLZ supercompression, vkFormat 0; told
    # apart by the DFD's colour model and sample count. etc1s-rgba: the colour
    # block then the alpha block (its decoded G is the alpha).
    Format("etc1s", "basis", "UNDEFINED", 0, 4, 4, 8, 3, dfd_model=MODEL_ETC1S, dfd_channels=(0,),
           codec_module="texcook.codecs.etc1s", description="Basis Universal ETC1S RGB in KTX2 BasisLZ, under 4 bits per texel", scoring="rgb",
           t2d="decode_etc1"),
    Format("etc1s-rgba", "basis", "UNDEFINED", 0, 4, 4, 16, 4, dfd_model=MODEL_ETC1S,
           dfd_channels=(0, CHANNEL_ALPHA), codec_module="texcook.codecs.etc1s",
           description="Basis Universal ETC1S RGB + ETC1S alpha in KTX2 BasisLZ, under 8 bits per texel"),
]

# ASTC 2D block sizes in vkFormat order: UNORM 157 + 2i, sRGB 158 + 2i.
ASTC_BLOCK_SIZES = ((4, 4), (5, 4), (5, 5), (6, 5), (6, 6), (8, 5), (8, 6), (8, 8),
                    (10, 5), (10, 6), (10, 8), (10, 10), (12, 10), (12, 12))
_TABLE += [
    Format(f"astc-{bw}x{bh}", "astc", f"ASTC_{bw}x{bh}", 157 + 2 * i, bw, bh, 16, 4, vk_srgb=158 + 2 * i,
           dfd_model=MODEL_ASTC, dfd_channels=(0,), codec_module="texcook.codecs.astc",
           description=f"ASTC {bw}x{bh} LDR, {128 / (bw * bh):.2f} bits per texel", t2d="decode_astc")
    for i, (bw, bh) in enumerate(ASTC_BLOCK_SIZES)
]


def _dds_codes_shared(table):
    """A format with `dds_alpha_of` takes that format's DXGI codes and FourCC."""
    by_name = {f.name: f for f in table}
    return [replace(f, dxgi=by_name[f.dds_alpha_of].dxgi, dxgi_srgb=by_name[f.dds_alpha_of].dxgi_srgb,
                    fourcc=by_name[f.dds_alpha_of].fourcc) if f.dds_alpha_of else f for f in table]


_TABLE = _dds_codes_shared(_TABLE)
FORMATS: dict[str, Format] = {f.name: f for f in _TABLE}
_BY_VK: dict[int, tuple[Format, str]] = {}
for _f in _TABLE:
    if _f.stored_as or not _f.vk_unorm:
        continue  # its vkFormat reads as the format it is stored as; 0 (ETC1S) names no format
    _BY_VK[_f.vk_unorm] = (_f, "linear")
    if _f.vk_srgb:
        _BY_VK[_f.vk_srgb] = (_f, "srgb")
    if _f.vk_snorm:
        _BY_VK[_f.vk_snorm] = (_f, "snorm")
del _f


def get(name) -> Format:
    fmt = FORMATS.get(str(name).lower())
    if fmt is None:
        raise UsageError(f"unknown format {name!r}; known: {', '.join(encodable())}")
    return fmt


def encodable() -> list[str]:
    """Names of the formats texcook can bake to (those with a codec)."""
    return [f.name for f in _TABLE if f.codec_module]


def by_vk_format(vk: int):
    """(Format, "linear" | "srgb" | "snorm") for a vkFormat, or (None, None)."""
    return _BY_VK.get(vk, (None, None))


def by_dxgi(dxgi: int):
    """(Format, srgb) for a DXGI format, or (None, False). A code two formats
    share reads as the one without `dds_alpha_of`; the DDS reader tells the
    other apart from the header's alpha flags."""
    for f in _TABLE:
        if dxgi and f.dxgi == dxgi and not f.dds_alpha_of:
            return f, False
        if dxgi and f.dxgi_srgb == dxgi and not f.dds_alpha_of:
            return f, True
    return None, False


def find(sample: str, channels: int) -> Format:
    """The uncompressed format storing `channels` channels of `sample` values
    (the summed-area table's choice)."""
    for f in _TABLE:
        if f.family == "uncompressed" and f.sample == sample and f.channels == channels:
            return f
    raise UsageError(f"no format stores {channels} channel(s) of {sample}")


# --- texture geometry: the one place each rule is written ---------------------------


def block_count(texels: int, block: int) -> int:
    """Blocks that cover `texels` texels along one axis (a partial block counts)."""
    return -(-texels // block)


def level_size(width: int, height: int, block_w: int, block_h: int, bytes_per_block: int) -> int:
    """Bytes of one level: whole blocks across and down, row-major, no padding."""
    return block_count(width, block_w) * block_count(height, block_h) * bytes_per_block


def level_dims(width: int, height: int, level: int) -> tuple[int, int]:
    """Size of mip `level`: max(1, n >> level) per axis (the Vulkan and D3D rule)."""
    return max(1, width >> level), max(1, height >> level)


def max_levels(width: int, height: int) -> int:
    """Length of a full mip chain, down to 1x1: floor(log2(max dimension)) + 1."""
    return max(int(width), int(height), 1).bit_length()
