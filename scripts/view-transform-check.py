"""dofray's PNG view transforms against Blender's, on the same linear image.

Renders a scene once to EXR and, for each view (Standard, AgX with and without looks, Khronos
PBR Neutral, view exposure and gamma), to PNG with the same settings (dofray renders are
deterministic: the PNG's linear colour is the EXR's). Blender then saves the EXR's beauty as a
PNG through the same view settings (Image.save_render, dither off), and the two PNGs are
compared code value by code value.

    python scripts/view-transform-check.py DOFRAY_BIN [--scene scenes/interior.toml]
        [--width 160] [--spp 4] [--out DIR] [--json FILE]

Needs a Python with Blender 4.2's `bpy`, numpy and OpenEXR (see scripts/blender-addon-test.sh).
Exit status 1 when any view's mean difference exceeds --max-mean (1 code value, issue #25's
criterion).
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np
import OpenEXR

import bpy

# (name, dofray flags, Blender view settings)
CASES = [
    ("standard", [], dict(view_transform="Standard")),
    ("agx", ["--view", "agx"], dict(view_transform="AgX")),
    ("agx-high-contrast", ["--view", "agx", "--look", "high-contrast"],
     dict(view_transform="AgX", look="AgX - High Contrast")),
    ("agx-very-low-contrast", ["--view", "agx", "--look", "very-low-contrast"],
     dict(view_transform="AgX", look="AgX - Very Low Contrast")),
    ("agx-greyscale", ["--view", "agx", "--look", "greyscale"],
     dict(view_transform="AgX", look="AgX - Greyscale")),
    ("agx-exposure-gamma", ["--view", "agx", "--view-exposure", "1.5", "--view-gamma", "1.3"],
     dict(view_transform="AgX", exposure=1.5, gamma=1.3)),
    ("pbr-neutral", ["--view", "khronos-pbr-neutral"], dict(view_transform="Khronos PBR Neutral")),
    ("standard-exposure", ["--view-exposure", "-1"], dict(view_transform="Standard", exposure=-1.0)),
]


def read_beauty(path):
    with OpenEXR.File(path, separate_channels=True) as f:
        channels = f.channels()
        rgb = [np.array(channels[f"ViewLayer.Combined.{c}"].pixels) for c in "RGB"]
    return np.stack(rgb, -1).astype(np.float32)


def blender_png(linear, settings, path):
    h, w, _ = linear.shape
    img = bpy.data.images.new("view-check", w, h, float_buffer=True, alpha=True)
    px = np.ones((h, w, 4), np.float32)
    px[..., :3] = linear
    img.pixels.foreach_set(px[::-1].ravel())
    scene = bpy.context.scene
    scene.render.dither_intensity = 0.0
    vs = scene.view_settings
    vs.view_transform = settings["view_transform"]
    vs.look = settings.get("look", "None")
    vs.exposure = settings.get("exposure", 0.0)
    vs.gamma = settings.get("gamma", 1.0)
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_depth = "8"
    scene.render.image_settings.color_mode = "RGB"
    img.save_render(path, scene=scene)
    bpy.data.images.remove(img)
    return read_png(path)


def read_png(path):
    img = bpy.data.images.load(path)
    img.colorspace_settings.name = "Non-Color"  # the code values as stored
    a = np.array(img.pixels[:], np.float32).reshape(img.size[1], img.size[0], img.channels)
    bpy.data.images.remove(img)
    return np.round(a[::-1, :, :3] * 255).astype(np.int32)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dofray")
    ap.add_argument("--scene", default=os.path.join(os.path.dirname(__file__), "..", "scenes", "interior.toml"))
    ap.add_argument("--width", type=int, default=160)
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--out", default=None)
    ap.add_argument("--json", default=None)
    ap.add_argument("--max-mean", type=float, default=1.0)
    args = ap.parse_args()
    out = args.out or tempfile.mkdtemp(prefix="dofray-view-check-")
    os.makedirs(out, exist_ok=True)
    base = [args.dofray, "render", args.scene, "--width", str(args.width), "--spp", str(args.spp),
            "--progress", "none"]
    exr = os.path.join(out, "linear.exr")
    subprocess.run(base + ["-o", exr], check=True)
    linear = read_beauty(exr)
    print(f"{os.path.basename(args.scene)} at {linear.shape[1]}x{linear.shape[0]}: "
          f"linear max {linear.max():.2f}, {100 * (linear > 1).any(-1).mean():.1f}% of pixels above 1")
    results, failed = [], False
    for name, flags, settings in CASES:
        png = os.path.join(out, f"dofray-{name}.png")
        subprocess.run(base + ["-o", png] + flags, check=True)
        ours = read_png(png)
        theirs = blender_png(linear, settings, os.path.join(out, f"blender-{name}.png"))
        d = np.abs(ours - theirs)
        row = dict(view=name, mean=float(d.mean()), max=int(d.max()),
                   within_1=float((d <= 1).mean()))
        results.append(row)
        ok = row["mean"] <= args.max_mean
        failed |= not ok
        print(f"  {name:24s} mean |diff| {row['mean']:.3f} code values, max {row['max']:3d}, "
              f"{100 * row['within_1']:.2f}% within 1  {'ok' if ok else 'FAIL'}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=2)
    print(f"images in {out}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
