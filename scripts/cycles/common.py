"""What the comparison scripts share: Cycles' settings, reading an EXR's colour, writing a
Radiance .hdr (RGBE) in numpy, and writing an 8-bit PNG without an imaging library.

Blender 4.2's `Image.save()` of a float image to .hdr writes the values through the display
transform (sRGB-encoded: 2.0 is stored as 1.35, 400 as 12.75), so environment maps are written
here instead, as flat (uncompressed) scanlines, which every reader accepts.
"""

import struct
import zlib

import numpy as np


def configure_cycles(scene, spp, width, height, biased=False):
    """Cycles as the comparison needs it: CPU, fixed seed, every sample the same weight, no
    denoiser, Standard view, scene-linear float EXR output."""
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device = "CPU"
    c.samples = spp
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.seed = 0
    c.use_animated_seed = False
    if not biased:
        # Cycles' defaults clamp indirect light at 10, blur glossy paths and drop lights below a
        # threshold: all biased. The reference for an unbiased path tracer turns them off.
        c.sample_clamp_direct = 0.0
        c.sample_clamp_indirect = 0.0
        c.blur_glossy = 0.0
        c.light_sampling_threshold = 0.0
    scene.render.resolution_x = width
    scene.render.resolution_y = height
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = False
    vs = scene.view_settings
    vs.view_transform = "Standard"  # Blender 4.2 defaults to AgX
    vs.look = "None"
    vs.exposure = 0.0
    vs.gamma = 1.0
    scene.display_settings.display_device = "sRGB"
    s = scene.render.image_settings
    s.file_format = "OPEN_EXR"
    s.color_mode = "RGBA"
    s.color_depth = "32"
    s.exr_codec = "ZIP"


def read_rgb(path):
    """Linear RGB (H x W x 3, float64) from an EXR: Cycles' R, G, B or dofray's
    ViewLayer.Combined.R/G/B."""
    import OpenEXR

    with OpenEXR.File(path, separate_channels=True) as f:
        ch = f.channels()
        for prefix in ("", "ViewLayer.Combined.", "Combined."):
            if all(prefix + c in ch for c in "RGB"):
                return np.stack([ch[prefix + c].pixels.astype(np.float64) for c in "RGB"], -1)
        names = [n for n in ch if n.endswith(".R")]
        if names:
            p = names[0][:-1]
            return np.stack([ch[p + c].pixels.astype(np.float64) for c in "RGB"], -1)
    raise ValueError(f"{path}: no R, G, B channels")


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


def write_png(path, rgb8, scale=1):
    """An 8-bit RGB PNG of `rgb8` (H x W x 3 uint8), each pixel repeated `scale` times."""
    if scale > 1:
        rgb8 = np.repeat(np.repeat(rgb8, scale, 0), scale, 1)
    h, w, _ = rgb8.shape
    raw = b"".join(b"\x00" + rgb8[y].tobytes() for y in range(h))

    def chunk(tag, data):
        return (struct.pack(">I", len(data)) + tag + data
                + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF))

    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n")
        f.write(chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)))
        f.write(chunk(b"IDAT", zlib.compress(raw, 6)))
        f.write(chunk(b"IEND", b""))
