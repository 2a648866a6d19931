"""Slow, readable references for the codec and stage tests.

Each function follows the specification or the plain definition, one value,
texel or block at a time where that is clearer, and imports nothing from
texcook (but the names of the symbolic ASTC record's slots): a test holds
texcook's fast code to these. Where a definition has a choice (a filter's
default width, a rounding rule), the choice is the one docs/ documents,
restated here.

Sections: block layout, sRGB, filters and resampling, alpha coverage,
summed-area tables, KTX2 layout, BC1, BC4, ETC1, YCoCg, renormalisation,
normal angles, ASTC values, partitions and symbolic blocks, BC6H."""

import math

import numpy as np

# ------------------------------------------------------------------ block layout


def image_blocks(img, bw, bh):
    """(h, w, c) with whole blocks -> (n, bw*bh, c): blocks in row order, texels
    in row order within a block."""
    h, w, c = img.shape
    out = np.empty((h // bh * (w // bw), bw * bh, c), img.dtype)
    for by in range(h // bh):
        for bx in range(w // bw):
            for y in range(bh):
                for x in range(bw):
                    out[by * (w // bw) + bx, y * bw + x] = img[by * bh + y, bx * bw + x]
    return out


def blocks_image(blocks, bw, bh, nbx):
    """The inverse of image_blocks, for nbx blocks per row."""
    n, _, c = blocks.shape
    img = np.empty((n // nbx * bh, nbx * bw, c), blocks.dtype)
    for k in range(n):
        by, bx = divmod(k, nbx)
        for t in range(bw * bh):
            y, x = divmod(t, bw)
            img[by * bh + y, bx * bw + x] = blocks[k, t]
    return img


def block_row(blocks):
    """(n, 16, c) 4x4 blocks side by side -> a (4, 4n, c) image."""
    return blocks_image(np.asarray(blocks).reshape(len(blocks), 16, -1), 4, 4, len(blocks))


# ------------------------------------------------------------------ sRGB (IEC 61966-2-1)


def _each(fn, x):
    """fn on every value, in Python floats (C's pow, as the standard's formula)."""
    x = np.asarray(x, np.float64)
    return np.array([fn(v) for v in x.ravel().tolist()], np.float64).reshape(x.shape)


def _decode_1(v):
    return v / 12.92 if v <= 0.04045 else ((v + 0.055) / 1.055) ** 2.4


def _encode_1(v):
    return v * 12.92 if v <= 0.0031308 else 1.055 * v ** (1.0 / 2.4) - 0.055


def srgb_to_linear(x):
    """sRGB-encoded 0..1 -> linear light (float64)."""
    return _each(_decode_1, x)


def linear_to_srgb(x):
    """Linear light 0..1 -> sRGB encoding (float64)."""
    return _each(_encode_1, x)


def sampler_rgba(unit, srgb, alpha_channel):
    """float32 (h, w, c) values in 0..1 as a sampler reads them, float32 RGBA:
    the sRGB curve decoded on colour channels only (alpha never), grey copied
    to R, G and B, a missing alpha 1."""
    unit = np.asarray(unit, np.float32)
    h, w, c = unit.shape
    out = np.ones((h, w, 4), np.float32)
    for ch in range(c):
        v = unit[..., ch]
        if srgb and ch != alpha_channel:
            v = srgb_to_linear(v).astype(np.float32)
        if c <= 2:
            if ch == 0:
                out[..., 0] = out[..., 1] = out[..., 2] = v
            else:
                out[..., 3] = v
        else:
            out[..., ch] = v
    return out


# ------------------------------------------------------------------ filters (docs/mips.md)

LANCZOS_A = 3
KAISER_WIDTH = 3.0
KAISER_ALPHA = 4.0


def sinc(x):
    return 1.0 if x == 0 else math.sin(math.pi * x) / (math.pi * x)


def bessel_i0(x):
    """The modified Bessel function of order 0, by its power series."""
    total, term, k = 1.0, 1.0, 0
    while term > 1e-17 * total:
        k += 1
        term *= (x / (2 * k)) ** 2
        total += term
    return total


def filter_weight(name, x, lanczos_a=LANCZOS_A, kaiser_width=KAISER_WIDTH, kaiser_alpha=KAISER_ALPHA):
    """The filter's value at x destination texels from the output texel's centre."""
    if name == "triangle":
        return max(0.0, 1.0 - abs(x))
    if name == "lanczos":
        return sinc(x) * sinc(x / lanczos_a) if abs(x) < lanczos_a else 0.0
    if name == "kaiser":
        if abs(x) >= kaiser_width:
            return 0.0
        return sinc(x) * bessel_i0(kaiser_alpha * math.sqrt(1 - (x / kaiser_width) ** 2)) / bessel_i0(kaiser_alpha)
    raise ValueError(name)


def filter_radius(name, lanczos_a=LANCZOS_A, kaiser_width=KAISER_WIDTH, **_):
    return {"box": 0.5, "triangle": 1.0, "lanczos": float(lanczos_a), "kaiser": float(kaiser_width)}[name]


def resample_weights_1d(n, m, filter, wrap, **opts):
    """Dense (m, n) matrix taking n texels to m, one output texel at a time:
    the filter sampled at the source texel centres (box: the exact overlap of
    each source texel with the output texel's footprint), taps outside the
    image folded back by the wrap mode (clamp and mirror reflect, repeat wraps),
    each row normalised to sum 1."""
    s = n / m
    radius = filter_radius(filter, **opts)
    mat = np.zeros((m, n))
    for i in range(m):
        c = (i + 0.5) * s
        row = {}
        for j in range(int(np.floor(c - radius * s)) - 2, int(np.ceil(c + radius * s)) + 3):
            if filter == "box":
                wgt = max(0.0, min(j + 1, c + s / 2) - max(j, c - s / 2))
            else:
                wgt = filter_weight(filter, (j + 0.5 - c) / s, **opts)
            if wrap == "repeat":
                jj = j % n
            else:
                k = j % (2 * n)
                jj = k if k < n else 2 * n - 1 - k
            row[jj] = row.get(jj, 0.0) + wgt
        total = sum(row.values())
        for jj, wgt in row.items():
            mat[i, jj] = wgt / total
    return mat


def resample(img, out_w, out_h, filter, wrap, **opts):
    """(h, w, c) -> (out_h, out_w, c) in float64, by the dense matrices;
    wrap is (horizontal, vertical)."""
    h, w, _ = img.shape
    my = resample_weights_1d(h, out_h, filter, wrap[1], **opts)
    mx = resample_weights_1d(w, out_w, filter, wrap[0], **opts)
    return np.einsum("ij,jkc,lk->ilc", my, img.astype(np.float64), mx)


# ------------------------------------------------------------------ alpha coverage


def coverage(alpha, cutoff):
    """The share of texels whose alpha is above the cutoff (what alpha testing keeps)."""
    a = np.asarray(alpha, np.float64).ravel()
    return np.count_nonzero(a > cutoff) / a.size


def best_reachable_coverage_error(alpha, cutoff, target):
    """The closest to `target` that scaling alpha (clamped at 1) can bring the
    coverage: tries a scale on each side of every value where a texel crosses
    the cutoff, and 0 and 1."""
    a = np.asarray(alpha, np.float64).ravel()
    candidates = [1.0, 0.0]
    for v in np.unique(a[a > 0]):
        s = cutoff / v
        candidates += [s * (1 - 1e-9), s * (1 + 1e-9)]
    return min(abs(coverage(np.minimum(a * s, 1.0), cutoff) - target) for s in candidates)


# ------------------------------------------------------------------ summed-area tables


def summed_area(img):
    """S[y, x] = the sum of img[0..y, 0..x] (inclusive), per channel, exact in int64
    for integers and float64 for floats, built by the recurrence."""
    img = np.asarray(img)
    acc = np.int64 if img.dtype.kind in "ui" else np.float64
    h, w = img.shape[:2]
    s = np.zeros(img.shape, acc)
    for y in range(h):
        row = np.zeros(img.shape[2:], acc)
        for x in range(w):
            row = row + img[y, x].astype(acc)
            s[y, x] = row + (s[y - 1, x] if y else 0)
    return s


def box_sum(img, x0, y0, x1, y1):
    """The sum of the texels in [x0, x1) x [y0, y1) per channel (int64 or float64)."""
    block = np.asarray(img)[y0:y1, x0:x1]
    acc = np.int64 if block.dtype.kind in "ui" else np.float64
    return block.reshape(block.shape[0] * block.shape[1], -1).astype(acc).sum(axis=0).reshape(block.shape[2:])


def box_mean(img, x0, y0, x1, y1):
    return box_sum(img, x0, y0, x1, y1) / ((x1 - x0) * (y1 - y0))


# ------------------------------------------------------------------ KTX2 layout


def ktx2_layout(dfd_samples, block_bytes, kvd_len, supercompressed, lengths):
    """Where a KTX2 file puts its sections, as `ktx validate` checks them: the
    level index after the 80-byte header, the DFD (one basic block of
    `dfd_samples` samples) and key/values right after it, then the levels
    smallest first, each aligned to lcm(block size, 4) unless supercompressed.
    -> (dfd offset, dfd length, kvd offset, {level: offset})."""
    n = len(lengths)
    dfd_off = 80 + 24 * n
    dfd_len = 4 + 24 + 16 * dfd_samples
    kvd_off = dfd_off + dfd_len
    align = 1 if supercompressed else math.lcm(block_bytes, 4)
    pos = -(-(kvd_off + kvd_len) // align) * align
    offsets = {}
    for i in reversed(range(n)):
        offsets[i] = pos
        pos = -(-(pos + lengths[i]) // align) * align
    return dfd_off, dfd_len, kvd_off, offsets


# ------------------------------------------------------------------ BC1


def rgb565(c):
    """A 16-bit 5:6:5 colour -> 8-bit [r, g, b] by bit replication."""
    r, g, b = c >> 11, (c >> 5) & 63, c & 31
    return [(r << 3) | (r >> 2), (g << 2) | (g >> 4), (b << 3) | (b >> 2)]


def bc1_palette(c0, c1):
    """The four RGB entries; in 3-colour mode (c0 <= c1) the last is black
    (transparent black in BC1A)."""
    a, b = rgb565(c0), rgb565(c1)
    if c0 > c1:
        return [a, b, [(2 * x + y) // 3 for x, y in zip(a, b)], [(x + 2 * y) // 3 for x, y in zip(a, b)]]
    return [a, b, [(x + y) // 2 for x, y in zip(a, b)], [0, 0, 0]]


def bc1_decode_block(b):
    """One 8-byte block -> (16 RGB texels, four-colour mode?, the 32 index bits)."""
    c0 = int(b[0]) | int(b[1]) << 8
    c1 = int(b[2]) | int(b[3]) << 8
    bits = int.from_bytes(bytes(b[4:8]), "little")
    pal = bc1_palette(c0, c1)
    return [pal[(bits >> (2 * i)) & 3] for i in range(16)], c0 > c1, bits


def bc1_best_flat_error(colour):
    """Smallest per-texel squared error any BC1 block gives a flat colour, by
    brute force over every endpoint pair per channel (both modes, and black)."""
    best4 = best3 = 0
    for c, v in enumerate(colour):
        bits = 6 if c == 1 else 5
        lv = np.arange(1 << bits)
        e = (lv << (8 - bits)) | (lv >> (2 * bits - 8))
        best4 += int(np.min((((2 * e[:, None] + e[None, :]) // 3) - int(v)) ** 2))
        best3 += int(np.min((((e[:, None] + e[None, :]) // 2) - int(v)) ** 2))
    return min(best4, best3, sum(int(v) ** 2 for v in colour))


# ------------------------------------------------------------------ BC4 (and BC3 alpha, BC5)


def bc4_palette(r0, r1):
    """The eight values of a block with endpoints r0, r1: six interpolated when
    r0 > r1, else four interpolated then 0 and 255."""
    if r0 > r1:
        return [r0, r1] + [((7 - i) * r0 + i * r1) // 7 for i in range(1, 7)]
    return [r0, r1] + [((5 - i) * r0 + i * r1) // 5 for i in range(1, 5)] + [0, 255]


def bc4_decode_block(b):
    """One 8-byte block -> its 16 values."""
    pal = bc4_palette(int(b[0]), int(b[1]))
    bits = int.from_bytes(bytes(b[2:8]), "little")
    return [pal[(bits >> (3 * i)) & 7] for i in range(16)]


def bc4_best_error(vals):
    """Smallest squared error of one BC4 block over all 65536 endpoint pairs."""
    best = None
    for r0 in range(256):
        for r1 in range(256):
            pal = np.array(bc4_palette(r0, r1))
            err = int(np.min((pal[None, :] - np.asarray(vals, int)[:, None]) ** 2, axis=1).sum())
            best = err if best is None else min(best, err)
    return best


# ------------------------------------------------------------------ ETC1

ETC1_TABLES = [(2, 8), (5, 17), (9, 29), (13, 42), (18, 60), (24, 80), (33, 106), (47, 183)]


def etc1_decode_block(b):
    """One 8-byte block (big-endian 64-bit word) -> (4, 4, 3) RGB."""
    word = int.from_bytes(bytes(b), "big")

    def bits(hi, lo):
        return (word >> lo) & ((1 << (hi - lo + 1)) - 1)

    diff, flip = bits(33, 33), bits(32, 32)
    tables = (bits(39, 37), bits(36, 34))
    bases = [[], []]
    for hi in (63, 55, 47):  # R, G, B
        if diff:
            c5 = bits(hi, hi - 4)
            d = bits(hi - 5, hi - 7)
            d = d - 8 if d >= 4 else d
            for half, v in enumerate((c5, (c5 + d) & 31)):
                bases[half].append((v << 3) | (v >> 2))
        else:
            for half, v in enumerate((bits(hi, hi - 3), bits(hi - 4, hi - 7))):
                bases[half].append(v * 17)
    out = np.zeros((4, 4, 3), np.int64)
    for x in range(4):
        for y in range(4):
            k = 4 * x + y  # texels are numbered down the columns
            half = (y >= 2) if flip else (x >= 2)
            a, b_ = ETC1_TABLES[tables[half]]
            mod = {0: a, 1: b_, 2: -a, 3: -b_}[(bits(16 + k, 16 + k) << 1) | bits(k, k)]
            out[y, x] = np.clip(np.array(bases[half]) + mod, 0, 255)
    return out


def _etc1_best_flat(rgb, expansions):
    best = None
    for expand in expansions:
        for a, b in ETC1_TABLES:
            for m in (a, b, -a, -b):
                vals = np.clip(expand + m, 0, 255)
                e = sum(int(np.min((vals - int(v)) ** 2)) for v in rgb)
                best = e if best is None else min(best, e)
    return best


def etc1_best_flat_error(rgb):
    """Smallest per-texel squared RGB error any ETC1 block gives a flat colour,
    by brute force over every base code and modifier of either mode (both
    halves may share a base, so one base suffices)."""
    return _etc1_best_flat(rgb, (np.arange(16) * 17, np.array([(c << 3) | (c >> 2) for c in range(32)])))


def etc1_best_flat_error_4bit(rgb):
    """The same, with the individual mode's 4-bit bases only."""
    return _etc1_best_flat(rgb, (np.arange(16) * 17,))


# ------------------------------------------------------------------ YCoCg


def ycocg(rgb):
    """RGB -> (Y, Co, Cg), float64: Y = R/4 + G/2 + B/4, Co = (R - B)/2,
    Cg = -R/4 + G/2 - B/4."""
    r, g, b = (rgb[..., i].astype(np.float64) for i in range(3))
    return np.stack([r / 4 + g / 2 + b / 4, r / 2 - b / 2, -r / 4 + g / 2 - b / 4], axis=-1)


def ycocg_r(rgb):
    """Integer RGB -> YCoCg-R by lifting (shifts round towards minus infinity)."""
    r, g, b = (rgb[..., i].astype(np.int64) for i in range(3))
    co = r - b
    t = b + np.floor_divide(co, 2)
    cg = g - t
    y = t + np.floor_divide(cg, 2)
    return np.stack([y, co, cg], axis=-1)


def ycocg_scaled_rgb(layout):
    """Scaled-YCoCg texels in 0..255 codes (R = Co*s + 128, G = Cg*s + 128,
    B = (s - 1)*8, A = Y) -> the RGB the shader's reconstruction gives, in
    codes, unrounded (float64): R = Y + Co - Cg, G = Y + Cg, B = Y - Co - Cg."""
    px = np.asarray(layout, np.float64)
    out = np.empty(px.shape[:-1] + (3,), np.float64)
    for idx in np.ndindex(px.shape[:-1]):
        r, g, b, a = (float(v) for v in px[idx])
        s = b / 8 + 1
        co, cg = (r - 128) / s, (g - 128) / s
        out[idx] = (a + co - cg, a + cg, a - co - cg)
    return out


# ------------------------------------------------------------------ renormalisation


def renormalise(levels, mode):
    """Min/max histogram stretch per channel over all levels ("texture") or per
    level ("level"): v -> (v - lo) / (hi - lo). A channel with no range keeps
    scale 1 and bias 0. Returns (stretched levels, [(scale, bias) per group])."""
    groups = [list(range(len(levels)))] if mode == "texture" else [[i] for i in range(len(levels))]
    out = [None] * len(levels)
    params = []
    for group in groups:
        c = levels[group[0]].shape[-1]
        scale, bias = [1.0] * c, [0.0] * c
        for ch in range(c):
            values = [float(v) for i in group for v in levels[i][..., ch].ravel().tolist()]
            lo, hi = min(values), max(values)
            if hi - lo > 1e-7:
                scale[ch], bias[ch] = hi - lo, lo
        for i in group:
            out[i] = (levels[i].astype(np.float64) - bias) / scale
        params.append((scale, bias))
    return out, params


def renormalise_inverse(px, scale, bias):
    """What a shader does to a stretched texel: stored * scale + bias."""
    return np.asarray(px, np.float64) * scale + bias


# ------------------------------------------------------------------ normal angles


def percentile(values, p):
    """The p-th percentile by linear interpolation between the sorted values
    (rank p/100 * (n - 1))."""
    v = sorted(float(x) for x in np.ravel(values))
    rank = p / 100 * (len(v) - 1)
    lo = math.floor(rank)
    hi = min(lo + 1, len(v) - 1)
    return v[lo] + (v[hi] - v[lo]) * (rank - lo)


def normal_angles(a, b):
    """Degrees between the normals of two unorm8 normal maps, each read from X
    and Y with Z rebuilt as sqrt(1 - x^2 - y^2) (0 past the rim)."""

    def unit(px):
        x = px[..., 0] / 255.0 * 2 - 1
        y = px[..., 1] / 255.0 * 2 - 1
        z = np.sqrt(np.maximum(0.0, 1 - x * x - y * y))
        v = np.stack([x, y, z], axis=-1)
        return v / np.linalg.norm(v, axis=-1, keepdims=True)

    return np.degrees(np.arccos(np.clip((unit(a) * unit(b)).sum(-1), -1, 1)))


# ------------------------------------------------------------------ ASTC symbolic blocks
# ASTC values and partitions, from the Khronos Data Format Specification's
# ASTC chapter. A stored value of a trit or quint range is (D << n) | m: the
# trit or quint D above the n plain bits m (bit a the lowest of m).

ASTC_RANGES = [2, 3, 4, 5, 6, 8, 10, 12, 16, 20, 24, 32, 40, 48, 64, 80, 96, 128, 160, 192, 256]


def _range_shape(levels):
    """(3 for trits / 5 for quints / 1, plain bits n) of a range."""
    levels = int(levels)
    for base in (3, 5, 1):
        if levels % base == 0 and bin(levels // base).count("1") == 1:
            return base, (levels // base).bit_length() - 1
    raise ValueError(levels)


def _replicate(v, n, width):
    """Bit replication of an n-bit value to `width` bits."""
    out, have = 0, 0
    while have < width:
        out, have = (out << n) | v, have + n
    return out >> (have - width)


def _bit(m, name):
    return (m >> "abcdef".index(name)) & 1


# The spec's B patterns (most significant bit first) and C per range.
_COLOUR_B = {6: ("000000000", 204), 10: ("000000000", 113), 12: ("b000b0bb0", 93), 20: ("b0000bb00", 54),
             24: ("cb000cbcb", 44), 40: ("cb0000cbc", 26), 48: ("dcb000dcb", 22), 80: ("dcb0000dc", 13),
             96: ("edcb000ed", 11), 160: ("edcb0000e", 6), 192: ("fedcb000f", 5)}
_WEIGHT_B = {6: ("0000000", 50), 10: ("0000000", 28), 12: ("b000b0b", 23), 20: ("b0000b0", 13),
             24: ("cb000cb", 11)}


def _unquantise_tq(levels, value, table, width):
    """A trit/quint value: unq = D * C + B, XOR A, then the top bit of A over unq >> 2."""
    _, n = _range_shape(levels)
    d, m = value >> n, value & ((1 << n) - 1)
    big_a = (1 << width) - 1 if m & 1 else 0
    pattern, c = table[levels]
    big_b = sum(_bit(m, ch) << (width - 1 - k) for k, ch in enumerate(pattern) if ch != "0")
    unq = (d * c + big_b) ^ big_a
    return (big_a & (1 << (width - 2))) | (unq >> 2)


def astc_colour_value(levels, value):
    """A stored colour endpoint value of a range of `levels` -> 0..255."""
    base, n = _range_shape(levels)
    if base == 1:
        return _replicate(value, n, 8)
    return _unquantise_tq(levels, value, _COLOUR_B, 9)


def astc_weight_value(levels, value):
    """A stored weight of a range of `levels` -> 0..64."""
    base, n = _range_shape(levels)
    if base == 1:
        w = _replicate(value, n, 6)
    elif levels == 3:
        w = (0, 32, 63)[value]
    elif levels == 5:
        w = (0, 16, 32, 47, 63)[value]
    else:
        w = _unquantise_tq(levels, value, _WEIGHT_B, 7)
    return w + 1 if w > 32 else w


def _hash52(p):
    m = 0xFFFFFFFF
    p ^= p >> 15
    p = (p - (p << 17)) & m
    p = (p + (p << 7)) & m
    p = (p + (p << 4)) & m
    p ^= p >> 5
    p = (p + (p << 16)) & m
    p ^= p >> 7
    p ^= p >> 3
    p = (p ^ (p << 6)) & m
    p ^= p >> 17
    return p


def astc_partition(seed, x, y, count, texels):
    """The partition (0..count-1) of texel (x, y) for a partition index `seed`
    (2D blocks: z = 0); blocks of fewer than 31 texels double x and y."""
    if texels < 31:
        x, y = x << 1, y << 1
    seed += (count - 1) * 1024
    rnum = _hash52(seed)
    s = [(rnum >> sh) & 0xF for sh in (0, 4, 8, 12, 16, 20, 24, 28, 18, 22, 26)]
    s.append(((rnum >> 30) | (rnum << 2)) & 0xF)
    s = [v * v for v in s]
    if seed & 1:
        sh1, sh2 = (4 if seed & 2 else 5), (6 if count == 3 else 5)
    else:
        sh1, sh2 = (6 if count == 3 else 5), (4 if seed & 2 else 5)
    sh3 = sh1 if seed & 0x10 else sh2
    s = [v >> sh for v, sh in zip(s, (sh1, sh2, sh1, sh2, sh1, sh2, sh1, sh2, sh3, sh3, sh3, sh3))]
    a = (s[0] * x + s[1] * y + (rnum >> 14)) & 0x3F
    b = (s[2] * x + s[3] * y + (rnum >> 10)) & 0x3F
    c = (s[4] * x + s[5] * y + (rnum >> 6)) & 0x3F if count >= 3 else 0
    d = (s[6] * x + s[7] * y + (rnum >> 2)) & 0x3F if count >= 4 else 0
    if a >= b and a >= c and a >= d:
        return 0
    if b >= c and b >= d:
        return 1
    return 2 if c >= d else 3


# A decoder of texcook's symbolic ASTC blocks written from the specification,
# to check what the encoder's search claims. The one thing it takes from
# texcook is the symbolic record's slot names: the interface being decoded.


def _blue_contract(r, g, b, a):
    return [(r + b) >> 1, (g + b) >> 1, b, a]


def astc_endpoints(cem, v):
    """Unquantised colour values (0..255) -> two RGBA endpoints (LDR modes)."""
    if cem == 0:
        return [v[0]] * 3 + [255], [v[1]] * 3 + [255]
    if cem == 4:
        return [v[0]] * 3 + [v[2]], [v[1]] * 3 + [v[3]]
    if cem in (6, 10):
        a0, a1 = (v[4], v[5]) if cem == 10 else (255, 255)
        return [(v[c] * v[3]) >> 8 for c in range(3)] + [a0], [v[0], v[1], v[2], a1]
    if cem in (8, 12):
        a0, a1 = (v[6], v[7]) if cem == 12 else (255, 255)
        if v[1] + v[3] + v[5] >= v[0] + v[2] + v[4]:
            return [v[0], v[2], v[4], a0], [v[1], v[3], v[5], a1]
        return _blue_contract(v[1], v[3], v[5], a1), _blue_contract(v[0], v[2], v[4], a0)
    raise ValueError(f"CEM {cem} not covered by this reference")


def astc_infill(grid, gw, gh, bw, bh):
    """The weight grid's bilinear infill to the block's texels (spec 23.15)."""
    ds = (1024 + bw // 2) // (bw - 1)
    dt = (1024 + bh // 2) // (bh - 1)
    out = np.zeros(bw * bh, np.int64)
    for y in range(bh):
        for x in range(bw):
            gs = (ds * x * (gw - 1) + 32) >> 6
            gt = (dt * y * (gh - 1) + 32) >> 6
            js, fs, jt, ft = gs >> 4, gs & 15, gt >> 4, gt & 15
            w11 = (fs * ft + 8) >> 4
            w10, w01, w00 = ft - w11, fs - w11, 16 - fs - ft + w11

            def p(i, j):
                return grid[j * gw + i] if i < gw and j < gh else 0

            out[y * bw + x] = (p(js, jt) * w00 + p(js + 1, jt) * w01 + p(js, jt + 1) * w10
                               + p(js + 1, jt + 1) * w11 + 8) >> 4
    return out


def astc_decode_symbolic(row, bw, bh, srgb=False):
    """uint8 (bw*bh, 4) for one symbolic block."""
    from texcook.codecs.astc import symbolic as S

    row = np.asarray(row).astype(np.int64)
    nt = bw * bh
    if row[S.S_KIND] == S.KIND_VOID:
        return np.tile((row[S.S_VOID:S.S_VOID + 4] >> 8).astype(np.uint8), (nt, 1))
    gw, gh, wq = row[S.S_GRID_W], row[S.S_GRID_H], row[S.S_WQUANT]
    dual, ccs, parts = row[S.S_DUAL], row[S.S_CCS], row[S.S_PARTS]
    cq = row[S.S_CQUANT]
    planes = 2 if dual else 1
    wvals = [astc_weight_value(ASTC_RANGES[wq], int(v)) for v in row[S.S_WEIGHTS:S.S_WEIGHTS + gw * gh * planes]]
    tw = [astc_infill(wvals[k::planes], gw, gh, bw, bh) for k in range(planes)]
    labels = [astc_partition(int(row[S.S_PINDEX]), t % bw, t // bw, int(parts), nt) if parts > 1 else 0
              for t in range(nt)]
    eps = []
    off = 0
    for p in range(parts):
        cem = row[S.S_CEM + p]
        n = 2 * ((cem >> 2) + 1)
        v = [astc_colour_value(ASTC_RANGES[cq], int(c)) for c in row[S.S_ENDPOINTS + off:S.S_ENDPOINTS + off + n]]
        eps.append(astc_endpoints(cem, v))
        off += n
    out = np.zeros((nt, 4), np.uint8)
    for t in range(nt):
        e0, e1 = eps[labels[t]]
        for c in range(4):
            w = tw[1][t] if dual and c == ccs else tw[0][t]
            a = (e0[c] << 8) | 0x80 if srgb else e0[c] * 257
            b = (e1[c] << 8) | 0x80 if srgb else e1[c] * 257
            out[t, c] = ((a * (64 - w) + b * w + 32) >> 6) >> 8
    return out


# ------------------------------------------------------------------ BC6H (KDF "BPTC", D3D11 BC6H)

# Per mode number 1..14: (mode bits value, regions, transformed, base bits, delta
# bits r/g/b, header fields in order from bit 0, as the specification's tables:
# (name, first bit, last bit), a field read from its first to its last bit).
_BC6H_BITS = {
    1: "gy4 by4 bz4 rw0:9 gw0:9 bw0:9 rx0:4 gz4 gy0:3 gx0:4 bz0 gz0:3 bx0:4 bz1 by0:3 ry0:4 bz2 rz0:4 bz3",
    2: "gy5 gz4 gz5 rw0:6 bz0 bz1 by4 gw0:6 by5 bz2 gy4 bw0:6 bz3 bz5 bz4 rx0:5 gy0:3 gx0:5 gz0:3 bx0:5 by0:3 "
       "ry0:5 rz0:5",
    3: "rw0:9 gw0:9 bw0:9 rx0:4 rw10 gy0:3 gx0:3 gw10 bz0 gz0:3 bx0:3 bw10 bz1 by0:3 ry0:4 bz2 rz0:4 bz3",
    4: "rw0:9 gw0:9 bw0:9 rx0:3 rw10 gz4 gy0:3 gx0:4 gw10 gz0:3 bx0:3 bw10 bz1 by0:3 ry0:3 bz0 bz2 rz0:3 gy4 bz3",
    5: "rw0:9 gw0:9 bw0:9 rx0:3 rw10 by4 gy0:3 gx0:3 gw10 bz0 gz0:3 bx0:4 bw10 by0:3 ry0:3 bz1 bz2 rz0:3 bz4 bz3",
    6: "rw0:8 by4 gw0:8 gy4 bw0:8 bz4 rx0:4 gz4 gy0:3 gx0:4 bz0 gz0:3 bx0:4 bz1 by0:3 ry0:4 bz2 rz0:4 bz3",
    7: "rw0:7 gz4 by4 gw0:7 bz2 gy4 bw0:7 bz3 bz4 rx0:5 gy0:3 gx0:4 bz0 gz0:3 bx0:4 bz1 by0:3 ry0:5 rz0:5",
    8: "rw0:7 bz0 by4 gw0:7 gy5 gy4 bw0:7 gz5 bz4 rx0:4 gz4 gy0:3 gx0:5 gz0:3 bx0:4 bz1 by0:3 ry0:4 bz2 rz0:4 bz3",
    9: "rw0:7 bz1 by4 gw0:7 by5 gy4 bw0:7 bz5 bz4 rx0:4 gz4 gy0:3 gx0:4 bz0 gz0:3 bx0:5 by0:3 ry0:4 bz2 rz0:4 bz3",
    10: "rw0:5 gz4 bz0 bz1 by4 gw0:5 gy5 by5 bz2 gy4 bw0:5 gz5 bz3 bz5 bz4 rx0:5 gy0:3 gx0:5 gz0:3 bx0:5 by0:3 "
        "ry0:5 rz0:5",
    11: "rw0:9 gw0:9 bw0:9 rx0:9 gx0:9 bx0:9",
    12: "rw0:9 gw0:9 bw0:9 rx0:8 rw10 gx0:8 gw10 bx0:8 bw10",
    13: "rw0:9 gw0:9 bw0:9 rx0:7 rw11 rw10 gx0:7 gw11 gw10 bx0:7 bw11 bw10",
    14: "rw0:9 gw0:9 bw0:9 rx0:3 rw15:10 gx0:3 gw15:10 bx0:3 bw15:10",
}
BC6H_MODES = {  # mode number: (mode bits value, regions, transformed, base bits, (delta bits r, g, b))
    1: (0b00, 2, True, 10, (5, 5, 5)), 2: (0b01, 2, True, 7, (6, 6, 6)),
    3: (0b00010, 2, True, 11, (5, 4, 4)), 4: (0b00110, 2, True, 11, (4, 5, 4)),
    5: (0b01010, 2, True, 11, (4, 4, 5)), 6: (0b01110, 2, True, 9, (5, 5, 5)),
    7: (0b10010, 2, True, 8, (6, 5, 5)), 8: (0b10110, 2, True, 8, (5, 6, 5)),
    9: (0b11010, 2, True, 8, (5, 5, 6)), 10: (0b11110, 2, False, 6, (6, 6, 6)),
    11: (0b00011, 1, False, 10, (10, 10, 10)), 12: (0b00111, 1, True, 11, (9, 9, 9)),
    13: (0b01011, 1, True, 12, (8, 8, 8)), 14: (0b01111, 1, True, 16, (4, 4, 4)),
}
# region of each texel for the 32 two-region shapes (BC7's first 32), rows of the 4x4 block
BC6H_SHAPES = [
    "0011001100110011", "0001000100010001", "0111011101110111", "0001001100110111",
    "0000000100010011", "0011011101111111", "0001001101111111", "0000000100110111",
    "0000000000010011", "0011011111111111", "0000000101111111", "0000000000010111",
    "0001011111111111", "0000000011111111", "0000111111111111", "0000000000001111",
    "0000100011101111", "0111000100000000", "0000000010001110", "0111001100010000",
    "0011000100000000", "0000100011001110", "0000000010001100", "0111001100110001",
    "0011000100010000", "0000100010001100", "0110011001100110", "0011011001101100",
    "0001011111101000", "0000111111110000", "0111000110001110", "0011100110011100",
]
BC6H_ANCHOR2 = [15] * 16 + [15, 2, 8, 2, 2, 8, 8, 15, 2, 8, 2, 2, 8, 8, 2, 2]


def _bc6h_unquantize(c, bits, signed):
    if not signed:
        if bits >= 15 or c == 0:
            return c
        if c == (1 << bits) - 1:
            return 0xFFFF
        return ((c << 16) + 0x8000) >> bits
    if bits >= 16:
        return c
    s, m = (c < 0), abs(c)
    if m == 0:
        u = 0
    elif m >= (1 << (bits - 1)) - 1:
        u = 0x7FFF
    else:
        u = ((m << 15) + 0x4000) >> (bits - 1)
    return -u if s else u


def _sext(v, bits):
    v &= (1 << bits) - 1
    return v - (1 << bits) if v >> (bits - 1) else v


def bc6h_endpoints(b, signed):
    """16 bytes -> (mode number 1..14 or None when reserved, shape, endpoint
    codes (2 * regions, 3) after the transform and sign extension, bit
    position of the indices)."""
    x = int.from_bytes(bytes(b), "little")
    mode_bits = x & 3 if x & 3 < 2 else x & 31
    num = [k for k, m in BC6H_MODES.items() if m[0] == mode_bits]
    if not num:
        return None, 0, None, 0
    num = num[0]
    _, regions, transformed, base, delta = BC6H_MODES[num]
    pos = 2 if num <= 2 else 5
    ep = {}
    for tok in _BC6H_BITS[num].split():
        name, span = tok[:2], tok[2:]
        first, _, last = span.partition(":")
        first, last = int(first), int(last or first)
        step = 1 if last >= first else -1
        for k in range(first, last + step, step):
            ep[name] = ep.get(name, 0) | (((x >> pos) & 1) << k)
            pos += 1
    shape = 0
    if regions == 2:
        shape = (x >> pos) & 31
        pos += 5
    names = "wxyz"[: 2 * regions]
    e = np.zeros((2 * regions, 3), np.int64)
    for ci, ch in enumerate("rgb"):
        w = ep.get(ch + "w", 0)
        e[0, ci] = _sext(w, base) if signed else w
        for k, n in enumerate(names[1:], 1):
            v = ep.get(ch + n, 0)
            if transformed:
                v = (e[0, ci] + _sext(v, delta[ci])) & ((1 << base) - 1)
            e[k, ci] = _sext(v, base) if signed else v
    return num, shape, e, pos


def bc6h_decode_block(b, signed):
    """16 bytes -> (16, 3) uint16 half-float bit patterns, one texel and
    channel at a time as the specification reads it."""
    out = np.zeros((16, 3), np.uint16)
    num, shape, e, pos = bc6h_endpoints(b, signed)
    if num is None:
        return out  # reserved mode numbers decode to 0
    x = int.from_bytes(bytes(b), "little")
    _, regions, _, base, _ = BC6H_MODES[num]
    u = [[_bc6h_unquantize(int(e[k, ci]), base, signed) for ci in range(3)] for k in range(2 * regions)]
    weights = [0, 9, 18, 27, 37, 46, 55, 64] if regions == 2 else \
        [0, 4, 9, 13, 17, 21, 26, 30, 34, 38, 43, 47, 51, 55, 60, 64]
    ib = 3 if regions == 2 else 4
    for t in range(16):
        s = int(BC6H_SHAPES[shape][t]) if regions == 2 else 0
        n = ib - 1 if t == 0 or (regions == 2 and t == BC6H_ANCHOR2[shape]) else ib
        idx = (x >> pos) & ((1 << n) - 1)
        pos += n
        w = weights[idx]
        for ci in range(3):
            v = (u[2 * s][ci] * (64 - w) + u[2 * s + 1][ci] * w + 32) >> 6
            if not signed:
                out[t, ci] = (v * 31) >> 6
            elif v < 0:
                out[t, ci] = 0x8000 | (((-v) * 31) >> 5)
            else:
                out[t, ci] = (v * 31) >> 5
    return out
