"""The LDR colour endpoint modes' decoding: unquantised colour values of one
partition -> its two RGBA endpoints (the spec's decode_endpoints, with blue
contraction and the swap of direct modes).

A module of its own, apart from the block decoder (texcook.codecs.astc.decode),
because the encoder's search measures its candidates through it: a first
encode then compiles these kernels without the block decoder's (unpacking,
partition hashing and infill, about 4 s of a cold bake that never decodes).
"""

from ..._jit import jit_typed


@jit_typed("UniTuple(int64, 2)(int64, int64)")
def _bit_transfer_signed(a, b):
    """The spec's bit_transfer_signed: returns the new (a, b)."""
    b = (b >> 1) | (a & 0x80)
    a = (a >> 1) & 0x3F
    if a & 0x20:
        a -= 0x40
    return a, b


@jit_typed("int64(int64)")
def _clamp8(v):
    return 0 if v < 0 else (255 if v > 255 else v)


@jit_typed("boolean(int64, int64[::1], int64[::1], int64[::1])")
def decode_endpoints(cem, v, e0, e1):
    """Unquantised colour values v (0..255) of one partition -> RGBA endpoints
    e0, e1. Returns False for HDR modes (the caller paints the error colour)."""
    if cem == 0:
        for c in range(3):
            e0[c] = v[0]
            e1[c] = v[1]
        e0[3] = 255
        e1[3] = 255
    elif cem == 1:
        l0 = (v[0] >> 2) | (v[1] & 0xC0)
        l1 = min(l0 + (v[1] & 0x3F), 255)
        for c in range(3):
            e0[c] = l0
            e1[c] = l1
        e0[3] = 255
        e1[3] = 255
    elif cem == 4:
        for c in range(3):
            e0[c] = v[0]
            e1[c] = v[1]
        e0[3] = v[2]
        e1[3] = v[3]
    elif cem == 5:
        d0, b0 = _bit_transfer_signed(v[1], v[0])
        d1, b1 = _bit_transfer_signed(v[3], v[2])
        for c in range(3):
            e0[c] = b0
            e1[c] = _clamp8(b0 + d0)
        e0[3] = b1
        e1[3] = _clamp8(b1 + d1)
    elif cem == 6 or cem == 10:
        for c in range(3):
            e0[c] = (v[c] * v[3]) >> 8
            e1[c] = v[c]
        if cem == 6:
            e0[3] = 255
            e1[3] = 255
        else:
            e0[3] = v[4]
            e1[3] = v[5]
    elif cem == 8 or cem == 12:
        a0 = v[6] if cem == 12 else 255
        a1 = v[7] if cem == 12 else 255
        if v[1] + v[3] + v[5] >= v[0] + v[2] + v[4]:
            e0[0], e0[1], e0[2], e0[3] = v[0], v[2], v[4], a0
            e1[0], e1[1], e1[2], e1[3] = v[1], v[3], v[5], a1
        else:  # swapped and blue-contracted
            e0[0], e0[1], e0[2], e0[3] = (v[1] + v[5]) >> 1, (v[3] + v[5]) >> 1, v[5], a1
            e1[0], e1[1], e1[2], e1[3] = (v[0] + v[4]) >> 1, (v[2] + v[4]) >> 1, v[4], a0
    elif cem == 9 or cem == 13:
        dr, br = _bit_transfer_signed(v[1], v[0])
        dg, bg = _bit_transfer_signed(v[3], v[2])
        db, bb = _bit_transfer_signed(v[5], v[4])
        if cem == 13:
            da, ba = _bit_transfer_signed(v[7], v[6])
        else:
            da, ba = 0, 255
        if dr + dg + db >= 0:
            e0[0], e0[1], e0[2], e0[3] = br, bg, bb, ba
            e1[0], e1[1], e1[2], e1[3] = br + dr, bg + dg, bb + db, ba + da
        else:
            r1, g1, b1 = br + dr, bg + dg, bb + db
            e0[0], e0[1], e0[2], e0[3] = (r1 + b1) >> 1, (g1 + b1) >> 1, b1, ba + da
            e1[0], e1[1], e1[2], e1[3] = (br + bb) >> 1, (bg + bb) >> 1, bb, ba
        for c in range(4):
            e0[c] = _clamp8(e0[c])
            e1[c] = _clamp8(e1[c])
    else:
        return False
    return True
