"""A Radiance .hdr (RGBE) writer in numpy.

Blender 4.2's `Image.save()` of a float image to .hdr writes the values through the display
transform (sRGB-encoded: 2.0 is stored as 1.35, 400 as 12.75), so the environment maps are
written here instead, flat (uncompressed) scanlines, which every reader accepts.
"""

import numpy as np


def write_hdr(path, rgb):
    """rgb: H x W x 3 linear floats, row 0 the top of the image (the file's first scanline,
    Blender's v = 1). Returns the values as a reader will decode them."""
    rgb = np.maximum(np.asarray(rgb, dtype=np.float64), 0.0)
    h, w, _ = rgb.shape
    m = rgb.max(axis=2)
    mant, exp = np.frexp(m)
    keep = m > 1e-32
    scale = np.where(keep, mant * 256.0 / np.where(keep, m, 1.0), 0.0)
    out = np.zeros((h, w, 4), np.uint8)
    out[..., :3] = np.clip(np.floor(rgb * scale[..., None]), 0, 255).astype(np.uint8)
    out[..., 3] = np.where(keep, exp + 128, 0).astype(np.uint8)
    with open(path, "wb") as f:
        f.write(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n")
        f.write(f"-Y {h} +X {w}\n".encode())
        f.write(out.tobytes())
    e = out[..., 3].astype(np.float64)
    factor = np.where(out[..., 3] > 0, np.ldexp(1.0, (e - 136).astype(int)), 0.0)
    return out[..., :3].astype(np.float64) * factor[..., None] * (out[..., 3:] > 0)
