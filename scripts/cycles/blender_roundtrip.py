"""Issue #25's acceptance check, end to end: a scene built in Blender goes through the add-on's
export and renders in dofray with Blender's framing, focus plane and blur size, and region means
within 3% of Cycles. Run by hand with Blender's Python module (`bpy` 4.2, numpy, OpenEXR; see
README.md in this folder):

    python scripts/cycles/blender_roundtrip.py DOFRAY_BIN [--out DIR] [--spp N] [--res WxH]
        [--threads N] [--reuse-cycles] [--tolerance 0.03] [--no-image-focus] [--no-adaptive]

The scene (built in code, 320x180 by default): a camera with depth of field focused on an
object (`dof.focus_object`, 65 mm f/1.2, sensor fit VERTICAL), an HDRI world (a sky gradient
with a bright sun blob, written in code as an OpenEXR file, strength 0.8, rotated 30 degrees),
a rectangular area light, an emissive ball, a glass ball, a diffuse floor of light and dark
strips running away from the camera (their edges are what the image-based focus and blur
measurements read), and diffuse and glossy objects from 2 m to 12 m, among them a card
parallel to the image plane (one depth: the blur-size test point).

It exports the scene with the add-on (`dofray_blender.export_scene`, the checkout's
blender/dofray_blender), renders it with dofray (the command line, `--mode dense`, EXR with its
Depth and CoC passes; again with seed 1 for the noise; in adaptive mode, the render engine's
default) and with Cycles (same size, same samples, Blackman-Harris 1.5 px, no clamp, no
denoiser: common.configure_cycles), casts Blender's own pinhole ray through every pixel centre
(`scene.ray_cast`), and checks:

  framing      Blender's depth map (its rays) against dofray's Depth pass: no pixel's depth
               differs by more than 1% (0.1% of pixels allowed), and per object the sub-pixel
               shift that best lays one on the other is at most 0.25 px (where
               world_to_camera_view puts each object's centre is printed)
  focus plane  (a) where dofray's CoC pass reaches 0 (the V of CoC against 1/depth) within 1%
               of Blender's focus distance (along the view axis to the focus object, as Cycles
               computes it); (b) in the images: along the floor, per image row, the disc blur
               that turns the floor's sharp picture (its strips' albedo seen through Blender's
               pinhole view, computed here without noise: floor_albedo_image) into dofray's
               (two seeds averaged) and Cycles' render, and the thin lens's V,
               c = s |1/D - 1/P|, fitted to all rows: P is the sharpest depth, within 1% (or
               2 of its bootstrap standard deviations over the rows) of Blender's
  blur size    dofray's CoC pass at the card's centre within 2% of the thin-lens CoC from
               Blender's camera (aperture f / N, pixels per unit from Blender's projection
               matrix, so any sensor fit; Cycles' lens model: thin_lens_coc); printed: the V's
               slope s from both images against the thin lens's A k
  region means mean linear RGB over rectangles (floor, glass, emitter surround, sky, the
               in-focus subject, a defocused object in front and one behind) dofray / Cycles
               within --tolerance (3%), with each ratio's 1-sigma noise (dofray's two seeds);
               printed, not judged: adaptive mode's ratios, and the sun's highlight on the
               glossy ball (a check of the dielectric Fresnel, README.md here)

It prints a table, writes OUT/roundtrip.json and the previews OUT/roundtrip.compare.png
(Cycles | dofray | log2 ratio, the rectangles drawn, one stop darker) and
OUT/roundtrip.passes.png (dofray's inverse Depth | CoC | the floor's albedo reference | the
floor pixels measured).
Exit status 0 when every check passes, 1 otherwise.
"""
import argparse
import json
import math
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
BLENDER_DIR = os.path.join(REPO, "blender")
sys.dont_write_bytecode = True  # no __pycache__ in the checkout


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("dofray", help="the dofray binary")
    p.add_argument("--out", default="/tmp/dofray-roundtrip", help="output folder")
    p.add_argument("--spp", type=int, default=128,
                   help="samples per pixel, Cycles and dofray alike (default 128)")
    p.add_argument("--res", default="320x180", help="WIDTHxHEIGHT (default 320x180)")
    p.add_argument("--threads", type=int, default=0, help="threads for both (0: all cores)")
    p.add_argument("--reuse-cycles", action="store_true",
                   help="keep OUT/cycles.exr when it was rendered with the same settings")
    p.add_argument("--tolerance", type=float, default=0.03,
                   help="region means: the largest |dofray / Cycles - 1| (default 0.03)")
    p.add_argument("--no-image-focus", dest="image_focus", action="store_false",
                   help="skip the focus and blur measured in the images")
    p.add_argument("--no-adaptive", dest="adaptive", action="store_false",
                   help="skip the render in dofray's adaptive mode (the render engine's "
                        "default), whose region means are printed but not judged")
    args = p.parse_args(argv)
    w, h = args.res.lower().split("x")
    args.width, args.height = int(w), int(h)
    args.dofray = os.path.abspath(args.dofray)
    args.out = os.path.abspath(args.out)
    return args


if __name__ == "__main__":
    ARGS = parse_args(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:])
    os.makedirs(ARGS.out, exist_ok=True)
    # Blender's user folders (preferences) in the output folder, never ~/.config/blender.
    os.environ.setdefault("BLENDER_USER_RESOURCES", os.path.join(ARGS.out, "blender-user"))

import bpy  # noqa: E402
import numpy as np  # noqa: E402
from mathutils import Vector  # noqa: E402

sys.path.insert(0, HERE)
from common import configure_cycles, read_rgb, write_png  # noqa: E402
import scenes  # noqa: E402

sys.path.insert(0, BLENDER_DIR)
import dofray_blender  # noqa: E402

# ---------------------------------------------------------------------------------------------
# The scene (Blender axes: Z up; the camera looks along +Y from 0.5 m above the floor)

LENS_MM = 65.0
F_STOP = 1.2
SENSOR_FIT = "VERTICAL"  # not AUTO: the export must turn the sensor height into dofray's width
SENSOR_HEIGHT_MM = 24.0
CAM_LOC = (0.0, 0.0, 0.5)
CAM_PITCH_DEG = 7.0  # looking down
WORLD_STRENGTH = 0.8
WORLD_ROTATION_DEG = 30.0
AREA = {"size": (1.0, 0.5), "power": 150.0, "location": (-1.8, 1.8, 2.6), "turn_deg": 20.0}
STRIP = 0.15  # floor strip width, metres
FLOOR_X0 = -6.0  # the floor's strips span x in [FLOOR_X0, -FLOOR_X0]
FLOOR_ALBEDO = (0.7, 0.12)  # light and dark strips (the first is light)

# Spheres: name -> (centre, radius). The subject is the focus object.
SPHERES = {
    "Subject": ((-0.1, 3.3, 0.22), 0.22),   # diffuse, in focus
    "Glossy": ((-0.42, 2.1, 0.18), 0.18),   # glossy dielectric, defocused in front
    "Glass": ((0.35, 2.8, 0.201), 0.2),     # 1 mm above the floor (no coincident faces)
    "Lamp": ((1.5, 5.5, 0.45), 0.12),       # emissive
    "Gold": ((0.55, 9.0, 0.25), 0.25),      # rough metal, defocused behind
}
CUBE = {"name": "Cube", "location": (-1.0, 6.0, 0.3), "size": 0.6, "turn_deg": 30.0}
# A card parallel to the image plane (all of it at one depth): the blur-size test point.
CARD = {"name": "Card", "location": (-0.2, 12.0, 0.45), "size": (1.2, 0.6)}


def to_json(o):
    """numpy scalars and arrays in roundtrip.json."""
    return o.tolist() if hasattr(o, "tolist") else str(o)


def log(msg):
    print(f"[roundtrip] {msg}", flush=True)


def principled(name, color, roughness=0.5, ior=1.45, strength=0.0, **kw):
    """scenes.py's Principled material; every material here has IOR 1.45 (not Blender's 1.5),
    so the export must carry the index of opaque materials too."""
    return scenes.principled(name, color, roughness, ior=ior, emission_strength=strength, **kw)


def link(name, mesh_data, mats):
    for m in mats:
        mesh_data.materials.append(m)
    o = bpy.data.objects.new(name, mesh_data)
    bpy.context.scene.collection.objects.link(o)
    return o


def sphere(name, centre, radius, mat):
    bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32, radius=radius,
                                         location=centre)
    o = bpy.context.object
    o.name = name
    for p in o.data.polygons:
        p.use_smooth = True
    o.data.materials.append(mat)
    return o


def strip_floor(light, dark):
    """A floor of strips STRIP wide running along +Y (away from the camera), alternately light
    and dark: their edges are sharp lines at every depth."""
    n = int(round(-2.0 * FLOOR_X0 / STRIP))
    xs = [FLOOR_X0 + i * STRIP for i in range(n + 1)]
    y0, y1 = -1.0, 40.0
    verts = [(x, y, 0.0) for x in xs for y in (y0, y1)]
    faces = [(2 * i, 2 * i + 2, 2 * i + 3, 2 * i + 1) for i in range(n)]
    me = bpy.data.meshes.new("Floor")
    me.from_pydata(verts, [], faces)
    me.update()
    o = link("Floor", me, [light, dark])
    for i, p in enumerate(me.polygons):
        p.material_index = i % 2
    return o


def write_sky_exr(path, width=256, height=128):
    """An equirectangular sky (row 0 the top, elevation +90 degrees): a blue gradient, a darker
    ground and a sun blob of radiance 300 (2.5 texels' radius, elevation 35 degrees), written
    as a float OpenEXR file with OpenEXR's own module."""
    import OpenEXR

    elev = (0.5 - (np.arange(height) + 0.5) / height) * math.pi
    t = np.sin(np.maximum(elev, 0.0))
    sky = np.stack([0.9 - 0.6 * t, 1.0 - 0.5 * t, 1.3 - 0.3 * t], -1)
    rows = np.where((elev > 0)[:, None], sky, [0.3, 0.25, 0.2])
    rgb = np.repeat(rows[:, None, :], width, axis=1)
    u = (np.arange(width) + 0.5) / width
    du = np.minimum(abs(u - 0.62), 1.0 - abs(u - 0.62)) * width
    dv = (elev - math.radians(35.0)) / math.pi * height
    rgb[du[None, :] ** 2 + dv[:, None] ** 2 <= 2.5 ** 2] = [300.0, 285.0, 255.0]
    rgb = rgb.astype(np.float32)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    channels = {c: np.ascontiguousarray(rgb[..., i]) for i, c in enumerate("RGB")}
    with OpenEXR.File(header, channels) as f:
        f.write(path)


def build_scene(out, width, height, spp):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    configure_cycles(scene, spp, width, height)

    light, dark = FLOOR_ALBEDO
    strip_floor(principled("FloorLight", (light,) * 3, 1.0),
                principled("FloorDark", (dark,) * 3, 1.0))
    mats = {
        "Subject": principled("Subject", (0.8, 0.25, 0.2), 1.0),
        "Glossy": principled("Glossy", (0.1, 0.3, 0.7), 0.2),
        "Glass": principled("Glass", (1.0, 1.0, 1.0), 0.0, transmission=1.0, ior=1.45),
        "Lamp": principled("Lamp", (0.0, 0.0, 0.0), 1.0, emission=(1.0, 0.6, 0.25),
                           strength=20.0),
        "Gold": principled("Gold", (0.95, 0.75, 0.4), 0.25, metallic=1.0),
    }
    for name, (c, r) in SPHERES.items():
        sphere(name, c, r, mats[name])
    bpy.ops.mesh.primitive_cube_add(size=CUBE["size"], location=CUBE["location"],
                                    rotation=(0.0, 0.0, math.radians(CUBE["turn_deg"])))
    cube = bpy.context.object
    cube.name = CUBE["name"]
    cube.data.materials.append(principled("CubeGreen", (0.2, 0.55, 0.25), 0.6))
    # The card: parallel to the image plane (the camera's pitch), so all of it is at one depth.
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=CARD["location"],
                                     rotation=(math.radians(90.0 - CAM_PITCH_DEG), 0.0, 0.0))
    card = bpy.context.object
    card.name = CARD["name"]
    card.scale = (CARD["size"][0], CARD["size"][1], 1.0)
    card.data.materials.append(principled("CardGrey", (0.75, 0.72, 0.65), 1.0))

    area_data = bpy.data.lights.new("Softbox", type="AREA")
    area_data.shape = "RECTANGLE"
    area_data.size, area_data.size_y = AREA["size"]
    area_data.energy = AREA["power"]
    area_data.color = (1.0, 0.95, 0.9)
    area = bpy.data.objects.new("Softbox", area_data)
    area.location = AREA["location"]
    scene.collection.objects.link(area)
    target = Vector(SPHERES["Subject"][0])
    area.rotation_euler = (target - area.location).to_track_quat("-Z", "Y").to_euler()
    area.rotation_euler.rotate_axis("Z", math.radians(AREA["turn_deg"]))

    cam_data = bpy.data.cameras.new("Camera")
    cam_data.lens = LENS_MM
    cam_data.sensor_fit = SENSOR_FIT
    cam_data.sensor_height = SENSOR_HEIGHT_MM
    cam_data.dof.use_dof = True
    cam_data.dof.aperture_fstop = F_STOP
    cam_data.dof.focus_object = bpy.data.objects["Subject"]
    cam = bpy.data.objects.new("Camera", cam_data)
    cam.location = CAM_LOC
    cam.rotation_euler = (math.radians(90.0 - CAM_PITCH_DEG), 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam

    sky = os.path.join(out, "sky.exr")
    write_sky_exr(sky)
    world = bpy.data.worlds.new("World")
    world.use_nodes = True
    nt = world.node_tree
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(sky)
    env.image.colorspace_settings.name = "Linear Rec.709"
    env.interpolation = "Linear"
    mapping = nt.nodes.new("ShaderNodeMapping")
    mapping.vector_type = "POINT"
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(WORLD_ROTATION_DEG))
    coord = nt.nodes.new("ShaderNodeTexCoord")
    nt.links.new(coord.outputs["Generated"], mapping.inputs["Vector"])
    nt.links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    nt.links.new(env.outputs["Color"], nt.nodes["Background"].inputs["Color"])
    nt.nodes["Background"].inputs["Strength"].default_value = WORLD_STRENGTH
    scene.world = world
    scene.frame_start = scene.frame_end = 1
    bpy.context.view_layer.update()
    return scene


# ---------------------------------------------------------------------------------------------
# Blender's own view: a pinhole ray through every pixel centre


def blender_rays(scene):
    """Blender's camera: eye, unit view axis, and the world directions through the pixel
    centres (H x W x 3), from the camera's view frame (which applies the sensor fit)."""
    cam = scene.camera
    w, h = dofray_blender.export.render_size(scene.render)
    tr, br, bl, tl = [np.array(v) for v in cam.data.view_frame(scene=scene)]
    x = ((np.arange(w) + 0.5) / w)[None, :, None]
    y = ((np.arange(h) + 0.5) / h)[:, None, None]
    local = tl + (tr - tl) * x + (bl - tl) * y
    rot = np.array(cam.matrix_world.to_3x3())
    d = local @ rot.T
    d /= np.linalg.norm(d, axis=2, keepdims=True)
    eye = np.array(cam.matrix_world.translation)
    axis = rot @ np.array([0.0, 0.0, -1.0])
    return eye, axis / np.linalg.norm(axis), d


def blender_depth_map(scene):
    """Blender's depth along the view axis (1e10 for a miss) and the object hit (-1: none) at
    every pixel centre, with scene.ray_cast; and the objects' names."""
    eye, axis, dirs = blender_rays(scene)
    h, w, _ = dirs.shape
    dg = bpy.context.evaluated_depsgraph_get()
    depth = np.full((h, w), 1e10)
    ids = np.full((h, w), -1, int)
    names = []
    origin = Vector(eye)
    for yy in range(h):
        for xx in range(w):
            hit, loc, _n, _i, obj, _m = scene.ray_cast(dg, origin, Vector(dirs[yy, xx]),
                                                       distance=1e4)
            if hit:
                depth[yy, xx] = float(np.dot(np.array(loc) - eye, axis))
                name = obj.original.name if obj.original else obj.name
                if name not in names:
                    names.append(name)
                ids[yy, xx] = names.index(name)
    return depth, ids, names


def blackman_harris(t):
    """The 4-term Blackman-Harris window at t in [0, 1] across its width."""
    t = 2.0 * math.pi * np.asarray(t, float)
    return 0.35875 - 0.48829 * np.cos(t) + 0.14128 * np.cos(2 * t) - 0.01168 * np.cos(3 * t)


def floor_albedo_image(scene, light, dark, n=12, filter_width=3.0):
    """The floor's strips as a pinhole camera at Blender's view sees them, without noise: per
    pixel, the base colour of the strip under n x n sub-sample rays (the floor plane z = 0 hit
    analytically, Blender's view frame as in blender_rays), weighted by the Blackman-Harris
    pixel filter of `filter_width` pixels both renderers use. The sharp reference the blur is
    measured against: a diffuse floor's radiance along a row is gain x albedo + offset."""
    cam = scene.camera
    w, h = dofray_blender.export.render_size(scene.render)
    tr, br, bl, tl = [np.array(v) for v in cam.data.view_frame(scene=scene)]
    rot = np.array(cam.matrix_world.to_3x3())
    eye = np.array(cam.matrix_world.translation)
    offs = ((np.arange(n) + 0.5) / n - 0.5) * filter_width
    wts = blackman_harris(offs / filter_width + 0.5)
    out = np.zeros((h, w))
    total = 0.0
    x = np.arange(w) + 0.5
    y = (np.arange(h) + 0.5)[:, None]
    for oy, wy in zip(offs, wts):
        for ox, wx in zip(offs, wts):
            u = ((x + ox) / w)[None, :, None]
            v = ((y + oy) / h)[..., None]
            d = (tl + (tr - tl) * u + (bl - tl) * v) @ rot.T
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.where(d[..., 2] < 0, -eye[2] / d[..., 2], np.inf)
            hit = np.isfinite(t)
            px = eye[0] + np.where(hit, t, 0.0) * d[..., 0]
            strip = np.floor((px - FLOOR_X0) / STRIP).astype(np.int64)
            alb = np.where(hit, np.where(strip % 2 == 0, light, dark), 0.0)
            out += wx * wy * alb
            total += wx * wy
    return out / total


def pixel_of(scene, point):
    """Blender's projection of a world point: (x, y) in pixels, x right, y down, continuous
    (pixel centres at +0.5), and its depth along the view axis."""
    from bpy_extras.object_utils import world_to_camera_view

    w, h = dofray_blender.export.render_size(scene.render)
    v = world_to_camera_view(scene, scene.camera, Vector(point))
    return float(v.x * w), float((1.0 - v.y) * h), float(v.z)


# ---------------------------------------------------------------------------------------------
# Renders


def read_channels(path):
    import OpenEXR

    with OpenEXR.File(path, separate_channels=True) as f:
        return {k: np.array(v.pixels, dtype=np.float64) for k, v in f.channels().items()}


def run_dofray(args, toml, exr, *flags):
    cmd = [args.dofray, "render", toml, "-o", exr, "--json", "--quiet", *flags]
    if args.threads:
        cmd += ["--threads", str(args.threads)]
    t0 = time.time()
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"dofray failed ({r.returncode}): {' '.join(cmd)}\n{r.stderr}")
    summary = json.loads(r.stdout) if r.stdout.strip() else {}
    log(f"dofray {' '.join(flags)}: {time.time() - t0:.1f} s")
    return summary, [l for l in r.stderr.splitlines() if l.strip()]


def render_cycles(scene, args, path):
    """Cycles at the scene's settings (configure_cycles), the same camera with depth of field;
    reused with --reuse-cycles when OUT/cycles.json says the same size, samples and Blender."""
    stamp = {"blender": bpy.app.version_string, "spp": args.spp, "width": args.width,
             "height": args.height}
    stamp_path = os.path.splitext(path)[0] + ".json"
    if args.reuse_cycles and os.path.isfile(path) and os.path.isfile(stamp_path):
        with open(stamp_path) as f:
            old = json.load(f)
        if {k: old.get(k) for k in ("blender", "spp", "width", "height")} == \
                {k: stamp[k] for k in ("blender", "spp", "width", "height")}:
            log(f"Cycles: reusing {path} ({old.get('seconds', 0):.1f} s when rendered)")
            return old.get("seconds")
    scene.render.engine = "CYCLES"
    if args.threads:
        scene.render.threads_mode = "FIXED"
        scene.render.threads = args.threads
    scene.render.filepath = path
    t0 = time.time()
    bpy.ops.render.render(write_still=True)
    stamp["seconds"] = time.time() - t0
    with open(stamp_path, "w") as f:
        json.dump(stamp, f)
    log(f"Cycles {args.spp} spp {args.width}x{args.height}: {stamp['seconds']:.1f} s")
    return stamp["seconds"]


# ---------------------------------------------------------------------------------------------
# Pictures


def srgb8(img):
    x = np.clip(np.nan_to_num(img), 0.0, 1.0)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
    return (s * 255.0 + 0.5).astype(np.uint8)


def grey8(v, lo, hi):
    t = np.clip((np.asarray(v, float) - lo) / max(hi - lo, 1e-12), 0.0, 1.0)
    return np.repeat((t * 255.0 + 0.5).astype(np.uint8)[..., None], 3, axis=2)


def box_blur(a, k=5):
    pad = k // 2
    p = np.pad(a, ((pad, pad), (pad, pad)), mode="edge")
    c = np.pad(np.cumsum(np.cumsum(p, 0), 1), ((1, 0), (1, 0)))
    return (c[k:, k:] - c[:-k, k:] - c[k:, :-k] + c[:-k, :-k]) / (k * k)


def ratio8(cyc, dof):
    """log2(dofray / Cycles) of 5x5-blurred luminance: white equal, red dofray brighter, blue
    darker, full colour at one stop (as compare.py)."""
    a, b = box_blur(cyc.mean(2)), box_blur(dof.mean(2))
    t = np.clip(np.log2((b + 1e-6) / (a + 1e-6)), -1.0, 1.0)
    rgb = np.ones(a.shape + (3,))
    pos, neg = np.clip(t, 0, 1), np.clip(-t, 0, 1)
    rgb[..., 1] -= pos + neg
    rgb[..., 2] -= pos
    rgb[..., 0] -= neg
    return (np.clip(rgb, 0, 1) * 255 + 0.5).astype(np.uint8)


def draw_rects(img8, rects, colour=(255, 0, 255)):
    out = img8.copy()
    for (x0, y0, x1, y1) in rects:
        out[y0, x0:x1] = colour
        out[y1 - 1, x0:x1] = colour
        out[y0:y1, x0] = colour
        out[y0:y1, x1 - 1] = colour
    return out


def side_by_side(path, panels, scale=1):
    h = panels[0].shape[0]
    gap = np.full((h, 4, 3), 255, np.uint8)
    row = [panels[0]]
    for p in panels[1:]:
        row += [gap, p]
    write_png(path, np.concatenate(row, 1), scale)


# ---------------------------------------------------------------------------------------------
# Measurements


def bilinear(img, x, y):
    """img sampled at continuous pixel coordinates (x right, y down, pixel centres at +0.5),
    clamped at the borders."""
    h, w = img.shape
    fx, fy = np.asarray(x, float) - 0.5, np.asarray(y, float) - 0.5
    x0 = np.clip(np.floor(fx).astype(int), 0, w - 1)
    y0 = np.clip(np.floor(fy).astype(int), 0, h - 1)
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    tx, ty = np.clip(fx - x0, 0.0, 1.0), np.clip(fy - y0, 0.0, 1.0)
    top = img[y0, x0] * (1 - tx) + img[y0, x1] * tx
    bot = img[y1, x0] * (1 - tx) + img[y1, x1] * tx
    return top * (1 - ty) + bot * ty


def dilate(mask, r):
    """Binary dilation by a (2r+1)^2 square."""
    out = mask.copy()
    for _ in range(int(r)):
        m = out.copy()
        m[1:, :] |= out[:-1, :]
        m[:-1, :] |= out[1:, :]
        m[:, 1:] |= out[:, :-1]
        m[:, :-1] |= out[:, 1:]
        out = m
    return out


def shift_between(ref, img, box, search=2.0):
    """The shift (dx, dy), pixels, that best lays `ref` (Blender's inverse depth) on `img`
    (dofray's) inside box = (x0, y0, x1, y1): img(p) ~ ref(p - d), least squares, ref sampled
    bilinearly; a coarse grid then a fine one."""
    x0, y0, x1, y1 = box
    ys, xs = np.mgrid[y0:y1, x0:x1] + 0.5
    target = img[y0:y1, x0:x1]

    def sse(dx, dy):
        return float(((bilinear(ref, xs - dx, ys - dy) - target) ** 2).sum())

    best = (0.0, 0.0)
    for step, span in ((0.1, search), (0.01, 0.1)):
        grid = np.arange(-span, span + step / 2, step)
        cands = [(best[0] + a, best[1] + b) for a in grid for b in grid]
        best = min(cands, key=lambda d: sse(*d))
    return best


def disc_kernel(diameter, size):
    """A disc of `diameter` pixels, each pixel weighted by its covered area (8x8 subsamples),
    normalised, centred in a size x size array (size odd)."""
    c = size // 2
    sub = (np.arange(8) + 0.5) / 8 - 0.5
    yy, xx = np.mgrid[-c:c + 1, -c:c + 1].astype(float)
    px = xx[..., None, None] + sub[None, None, None, :]
    py = yy[..., None, None] + sub[None, None, :, None]
    r = max(diameter, 1e-3) / 2
    k = ((px ** 2 + py ** 2) <= r * r).mean(axis=(2, 3))
    if k.sum() == 0:
        k[c, c] = 1.0
    return k / k.sum()


def convolve(img, kernel):
    """2D convolution (FFT, edges padded by reflection)."""
    kh, kw = kernel.shape
    ph, pw = kh // 2, kw // 2
    p = np.pad(img, ((ph, ph), (pw, pw)), mode="reflect")
    H, W = p.shape
    K = np.zeros((H, W))
    K[:kh, :kw] = kernel
    K = np.roll(K, (-ph, -pw), axis=(0, 1))
    out = np.real(np.fft.ifft2(np.fft.fft2(p) * np.fft.fft2(K)))
    return out[ph:ph + img.shape[0], pw:pw + img.shape[1]]


def blur_residuals(sharp, blurred, mask, diameters, min_pixels=40):
    """For each image row with at least `min_pixels` of `mask`: how well `sharp` convolved
    with a disc of each of `diameters` (pixels) explains `blurred` over the row's mask pixels,
    allowing a gain and an offset (the reference is an albedo; the renders' light differs from
    row to row): the residual sum of squares of the linear fit blurred ~ g (sharp * disc) + o,
    per diameter. Returns (rows, residuals[len(rows), len(diameters)])."""
    size = 2 * int(math.ceil(max(diameters) / 2 + 1)) + 1
    conv = np.stack([convolve(sharp, disc_kernel(d, size)) for d in diameters])
    rows, out = [], []
    for y in range(sharp.shape[0]):
        m = mask[y]
        if m.sum() < min_pixels:
            continue
        b = blurred[y, m] - blurred[y, m].mean()
        a = conv[:, y, m]
        a = a - a.mean(axis=1, keepdims=True)
        saa = np.maximum((a * a).sum(axis=1), 1e-300)
        sab = (a * b).sum(axis=1)
        rows.append(y)
        out.append((b * b).sum() - sab * sab / saa)
    return np.array(rows), np.array(out)


def fit_blur_v(inv_depth, residuals, diameters, s_guess, x_range, boot=0, seed=0):
    """The thin lens's V fitted to an image: the blur diameter of a row at inverse depth x is
    c = s |x - x0|; (x0, s) minimise the rows' residuals (blur_residuals) summed, each row's
    residual taken at its model c (interpolated between diameters). Coarse-to-fine grid
    search. With boot > 0, also the standard deviations of x0 and s over `boot` bootstrap
    resamplings of the rows. Returns (x0, s, sd_x0, sd_s)."""
    d = np.asarray(diameters, float)
    r = residuals / np.maximum(residuals.min(axis=1, keepdims=True), 1e-300)

    def total(x0, s, idx):
        c = np.clip(s * np.abs(inv_depth[idx] - x0), d[0], d[-1])
        t = (c - d[0]) / (d[1] - d[0])
        i = np.minimum(t.astype(int), len(d) - 2)
        f = t - i
        rr = r[idx, i] * (1 - f) + r[idx, i + 1] * f
        return float(rr.sum())

    def search(idx):
        lo, hi = x_range
        xs = np.linspace(lo, hi, 61)
        ss = np.linspace(0.4 * s_guess, 1.6 * s_guess, 61)
        for _ in range(4):
            best = min(((x, s) for x in xs for s in ss), key=lambda p: total(p[0], p[1], idx))
            dx, ds = (xs[1] - xs[0]) * 2, (ss[1] - ss[0]) * 2
            xs = np.linspace(best[0] - dx, best[0] + dx, 21)
            ss = np.linspace(best[1] - ds, best[1] + ds, 21)
        return best

    all_rows = np.arange(len(inv_depth))
    x0, s = search(all_rows)
    sd_x, sd_s = float("nan"), float("nan")
    if boot:
        rng = np.random.default_rng(seed)
        samples = [search(rng.integers(0, len(all_rows), len(all_rows))) for _ in range(boot)]
        sd_x, sd_s = (float(v) for v in np.std(np.array(samples), axis=0))
    return float(x0), float(s), sd_x, sd_s


def fit_v(x, c, free_offset=False):
    """Least-squares V: c = s |x - x0| (+ b): returns (x0, s, b, rms)."""
    x, c = np.asarray(x, float), np.asarray(c, float)

    def solve(x0):
        t = np.abs(x - x0)
        A = np.stack([t, np.ones_like(t)], 1) if free_offset else t[:, None]
        coef, *_ = np.linalg.lstsq(A, c, rcond=None)
        r = float(((A @ coef - c) ** 2).sum())
        return r, float(coef[0]), float(coef[1]) if free_offset else 0.0

    lo, hi = float(x.min()), float(x.max())
    grid = np.linspace(lo, hi, 401)
    best = min(grid, key=lambda x0: solve(x0)[0])
    step = (hi - lo) / 400
    for _ in range(3):
        grid = np.linspace(best - step, best + step, 41)
        best = min(grid, key=lambda x0: solve(x0)[0])
        step /= 20
    r, s, b = solve(best)
    return float(best), s, b, math.sqrt(r / len(x))


def blender_lens(scene, depsgraph):
    """What Blender's camera says, computed here from Blender's own data (not through the
    add-on): the focus distance as Cycles computes it (along the view axis to the focus
    object's origin), the aperture diameter f / N (metres), and k, the pixels one unit spans
    at unit distance, from Blender's projection matrix (so any sensor fit)."""
    cam = scene.camera
    w, h = dofray_blender.export.render_size(scene.render)
    axis = (cam.matrix_world.to_3x3() @ Vector((0.0, 0.0, -1.0))).normalized()
    target = cam.data.dof.focus_object.matrix_world.translation
    focus = abs(axis.dot(target - cam.matrix_world.translation))
    proj = cam.calc_matrix_camera(depsgraph, x=w, y=h, scale_x=scene.render.pixel_aspect_x,
                                  scale_y=scene.render.pixel_aspect_y)
    k = 0.5 * w * proj[0][0]
    focal_m = cam.data.lens / 1000.0
    return {"focus_distance": focus, "aperture_m": focal_m / cam.data.dof.aperture_fstop,
            "k_px": k, "focal_m": focal_m,
            "hfov_deg": math.degrees(2.0 * math.atan(1.0 / proj[0][0]))}


def thin_lens_coc(lens, depth):
    """Blender's thin-lens CoC diameter in pixels of a point at `depth` along the view axis:
    Cycles' camera (a lens of diameter A = f / N, every ray through the point on the plane in
    focus that the pixel images; the field of view fixed by focal length and sensor) blurs it
    to A k |1/P - 1/D|. The textbook thin lens whose sensor moves to focus (image distance
    P f / (P - f)) magnifies that by P / (P - f): returned second."""
    a, k, p = lens["aperture_m"], lens["k_px"], lens["focus_distance"]
    c = a * k * abs(1.0 / p - 1.0 / depth)
    return c, c * p / (p - lens["focal_m"])


def rect_around(cx, cy, hx, hy, w, h):
    x0, x1 = int(round(cx - hx)), int(round(cx + hx))
    y0, y1 = int(round(cy - hy)), int(round(cy + hy))
    return max(0, x0), max(0, y0), min(w, x1), min(h, y1)


def regions(scene, w, h, lens):
    """The rectangles (x0, y0, x1, y1; x1, y1 excluded) whose means are compared, placed from
    Blender's projection of the objects, and what each should show."""
    def disc(name, f):
        c, r = SPHERES[name]
        x, y, z = pixel_of(scene, c)
        rp = r / z * lens["k_px"]
        return rect_around(x, y, f * rp, f * rp, w, h)

    sx, sy, sz = pixel_of(scene, SPHERES["Subject"][0])
    card_x, card_y, card_z = pixel_of(scene, CARD["location"])
    card_hx = 0.35 * CARD["size"][0] / card_z * lens["k_px"]
    card_hy = 0.3 * CARD["size"][1] / card_z * lens["k_px"]
    # The floor in front, between the glossy ball and the glass ball's caustic.
    fx, fy, _ = pixel_of(scene, (0.1, 1.9, 0.0))
    return {
        "floor": (rect_around(fx, fy, 0.05 * w, 0.05 * h, w, h), "Floor"),
        "subject (in focus)": (disc("Subject", 0.5), "Subject"),
        "glass": (disc("Glass", 0.5), "Glass"),
        "emitter surround": (disc("Lamp", 2.5), None),
        "sky": ((8, 1, w - 8, max(4, int(0.07 * h))), -1),
        "defocused near (glossy)": (disc("Glossy", 0.5), "Glossy"),
        "defocused far (card)": (rect_around(card_x, card_y, card_hx, card_hy, w, h), "Card"),
    }


def region_table(rects, cyc, dof, dof2):
    """Per rectangle: mean linear RGB of Cycles and dofray, their ratio (of the RGB mean and
    per channel), and the ratio's 1-sigma noise: dofray's per-pixel noise from two seeds
    ((a - b)^2 / 2 is the variance of one pixel), Cycles' assumed the same."""
    out = {}
    for name, (x0, y0, x1, y1) in rects.items():
        c = cyc[y0:y1, x0:x1].reshape(-1, 3)
        d = dof[y0:y1, x0:x1].reshape(-1, 3)
        d2 = dof2[y0:y1, x0:x1].reshape(-1, 3)
        n = len(c)
        var = ((d.mean(1) - d2.mean(1)) ** 2 / 2.0).sum() / n ** 2
        cm, dm = c.mean(0), d.mean(0)
        out[name] = {
            "rect": [x0, y0, x1, y1],
            "pixels": n,
            "cycles_rgb": cm.tolist(),
            "dofray_rgb": dm.tolist(),
            "ratio": float(dm.mean() / cm.mean()),
            "ratio_rgb": (dm / np.maximum(cm, 1e-12)).tolist(),
            "noise": float(math.sqrt(2.0 * var) / cm.mean()),
        }
    return out


def sun_highlight(scene, ids, names, cycl, dof, dof2, half=4):
    """Not judged: the sun's highlight on the glossy ball (a dielectric of roughness 0.2,
    IOR 1.45), where a Schlick approximation of the dielectric Fresnel would be 10% low
    (README.md here): a (2 half + 1)^2 window on Cycles' brightest pixel of the ball,
    and the angle of incidence there (between the view ray and the ball's normal: the
    mirror direction's, so the half-vector's, angle at the highlight's peak)."""
    m = ids == names.index("Glossy")
    lum = np.where(m, cycl.mean(2), -1.0)
    y, x = (int(v) for v in np.unravel_index(int(lum.argmax()), lum.shape))
    h, w = m.shape
    rect = (max(0, x - half), max(0, y - half), min(w, x + half + 1), min(h, y + half + 1))
    row = region_table({"sun highlight on the glossy ball": rect}, cycl, dof, dof2)
    eye, _axis, dirs = blender_rays(scene)
    d = Vector(dirs[y, x])
    hit, loc, normal, *_ = scene.ray_cast(bpy.context.evaluated_depsgraph_get(), Vector(eye), d)
    v = row["sun highlight on the glossy ball"]
    v["pixel"] = [int(x), int(y)]
    v["incidence_deg"] = math.degrees(math.acos(max(-1.0, min(1.0, -d.dot(normal))))) \
        if hit else None
    return row


# ---------------------------------------------------------------------------------------------
# The check


def measure_framing(bdepth, ids, names, ddepth):
    """Blender's depth map (its own rays) against dofray's Depth pass: the pixels whose depths
    differ by more than 1%, and per object the sub-pixel shift that best lays Blender's inverse
    depth on dofray's around it (0, 0 when dofray frames it as Blender does)."""
    h, w = bdepth.shape
    valid = (bdepth < 1e9) | (ddepth < 1e9)
    differ = valid & (np.abs(ddepth - bdepth) > 0.01 * np.minimum(bdepth, ddepth))
    inv_b = np.where(bdepth < 1e9, 1.0 / bdepth, 0.0)
    inv_d = np.where(ddepth < 1e9, 1.0 / ddepth, 0.0)
    objects = {}
    for i, name in enumerate(names):
        if name == "Floor":
            continue
        m = ids == i
        if m.sum() < 20:
            continue
        ys, xs = np.nonzero(m)
        box = (max(0, xs.min() - 4), max(0, ys.min() - 4), min(w, xs.max() + 5),
               min(h, ys.max() + 5))
        dx, dy = shift_between(inv_b, inv_d, box)
        objects[name] = {"pixels": int(m.sum()), "shift_px": [dx, dy]}
    return {"pixels_depth_differs_1pct": int(differ.sum()),
            "fraction_depth_differs_1pct": float(differ.mean()),
            "median_relative_depth_difference": float(np.median(
                np.abs(ddepth - bdepth)[bdepth < 1e9] / bdepth[bdepth < 1e9])),
            "objects": objects}


def measure_focus_from_images(bdepth, ids, names, sharp, renders, coc_max, s_guess, boot):
    """The V of blur against inverse depth along the floor (module docstring), per render:
    `sharp` is the floor's albedo as a pinhole sees it (floor_albedo_image), `renders` the
    depth-of-field images. Returns ({name: the fit}, the floor pixels used)."""
    floor = ids == names.index("Floor")
    margin = int(math.ceil(coc_max)) + 3
    mask = ~dilate(~floor, margin)
    mask[:, :margin] = False
    mask[:, -margin:] = False
    diameters = np.arange(0.0, coc_max + 4.0, 0.25)
    out = {}
    for name, img in renders.items():
        rows, res = blur_residuals(sharp, img, mask, diameters)
        inv = np.array([np.median(1.0 / bdepth[y, mask[y]]) for y in rows])
        x0, s, sd_x, sd_s = fit_blur_v(inv, res, diameters, s_guess,
                                       (float(inv.min()), float(inv.max())), boot=boot)
        out[name] = {"rows": len(rows), "depth_range": [float(1 / inv.max()),
                                                        float(1 / inv.min())],
                     "focus_distance": 1.0 / x0, "focus_sd": sd_x / x0 ** 2,
                     "slope_px": s, "slope_sd": sd_s}
    return out, mask


class Options:
    """What roundtrip() needs (the command line's flags; the test passes its own)."""

    def __init__(self, dofray, out, width=320, height=180, spp=128, threads=0,
                 reuse_cycles=False, tolerance=0.03, image_focus=True, adaptive=True):
        self.dofray, self.out = dofray, out
        self.width, self.height, self.spp, self.threads = width, height, spp, threads
        self.reuse_cycles, self.tolerance = reuse_cycles, tolerance
        self.image_focus, self.adaptive = image_focus, adaptive


def roundtrip(args):
    """Builds the scene, exports it with the add-on, renders it with dofray and Cycles and
    measures (module docstring). Returns the result (what roundtrip.json holds); writes its
    files into args.out. The add-on must be registered."""
    t_start = time.time()
    out = args.out
    os.makedirs(out, exist_ok=True)
    scene = build_scene(out, args.width, args.height, args.spp)
    scene.dofray.spp = args.spp  # In-Focus Samples stays 0: dofray's default (aa = spp)
    w, h = args.width, args.height
    toml = os.path.join(out, "roundtrip.toml")
    info = dofray_blender.export_scene(bpy.context, toml, animation=False)
    for warn in info["warnings"]:
        log(f"export warning: {warn}")
    data = info["data"]
    dg = bpy.context.evaluated_depsgraph_get()
    lens = blender_lens(scene, dg)
    result = {"blender": bpy.app.version_string, "width": w, "height": h, "spp": args.spp,
              "scene_file": data, "export_warnings": info["warnings"], "blender_lens": lens,
              "checks": {}}
    checks = result["checks"]

    # The export's own numbers against Blender's.
    cyc = scene.cycles
    checks["filter_width"] = {
        "cycles_filter_width": cyc.filter_width,
        "dofray_pixel_filter_width": data["render"]["pixel_filter_width"],
        "pass": data["render"]["pixel_filter"] == "blackman-harris"
        and abs(data["render"]["pixel_filter_width"] - 2.0 * cyc.filter_width) < 1e-6}
    hfov_dofray = math.degrees(2.0 * math.atan(data["camera"]["sensor_width_mm"]
                                               / (2.0 * data["camera"]["focal_length_mm"])))
    checks["field_of_view"] = {"blender_hfov_deg": lens["hfov_deg"],
                               "dofray_hfov_deg": hfov_dofray,
                               "pass": abs(hfov_dofray - lens["hfov_deg"]) < 1e-3}

    t0 = time.time()
    bdepth, ids, names = blender_depth_map(scene)
    log(f"Blender's rays through {w}x{h} pixel centres: {time.time() - t0:.1f} s")

    exr = {k: os.path.join(out, f"{k}.exr") for k in ("dofray", "dofray_seed1", "adaptive",
                                                      "cycles")}
    summary, stderr = run_dofray(args, toml, exr["dofray"], "--mode", "dense")
    result["dofray_seconds"] = summary.get("seconds")
    result["dofray_warnings"] = stderr + summary.get("warnings", [])
    run_dofray(args, toml, exr["dofray_seed1"], "--mode", "dense", "--seed", "1")
    if args.adaptive:
        summary, _ = run_dofray(args, toml, exr["adaptive"], "--mode", "adaptive")
        result["adaptive_seconds"] = summary.get("seconds")
    result["cycles_seconds"] = render_cycles(scene, args, exr["cycles"])

    ch = read_channels(exr["dofray"])
    ddepth, coc = ch["ViewLayer.Depth.Z"], ch["ViewLayer.CoC.X"]
    dof, dof2 = read_rgb(exr["dofray"]), read_rgb(exr["dofray_seed1"])
    cycl = read_rgb(exr["cycles"])

    # Framing. First, that the rays through the view frame are Blender's projection: hit
    # points seen through pixel centres project back onto those centres.
    fr = measure_framing(bdepth, ids, names, ddepth)
    eye, axis, dirs = blender_rays(scene)
    hit_y, hit_x = np.nonzero(bdepth < 1e9)
    pick = np.linspace(0, len(hit_y) - 1, 25).astype(int)
    err = 0.0
    for yy, xx in zip(hit_y[pick], hit_x[pick]):
        p = eye + dirs[yy, xx] * bdepth[yy, xx] / float(np.dot(dirs[yy, xx], axis))
        px, py, _ = pixel_of(scene, p)
        err = max(err, math.hypot(px - (xx + 0.5), py - (yy + 0.5)))
    fr["blender_rays_reprojection_px"] = err
    for name, o in fr["objects"].items():
        c = SPHERES[name][0] if name in SPHERES else \
            (CUBE["location"] if name == CUBE["name"] else CARD["location"])
        o["blender_centre_px"] = list(pixel_of(scene, c)[:2])
    worst = max(math.hypot(*o["shift_px"]) for o in fr["objects"].values())
    fr["worst_shift_px"] = worst
    fr["pass"] = worst <= 0.25 and fr["fraction_depth_differs_1pct"] < 0.001 and err < 1e-3
    checks["framing"] = fr

    # Focus plane: dofray's CoC pass, then (optionally) the images.
    P = lens["focus_distance"]
    ok = ddepth < 1e9
    sub = np.flatnonzero(ok.ravel())[::7]
    x0, s_pass, _, rms = fit_v(1.0 / ddepth.ravel()[sub], coc.ravel()[sub])
    focus = {"blender_focus_distance": P, "exported_focus_distance":
             data["camera"]["focus_distance"], "coc_pass_focus_distance": 1.0 / x0,
             "coc_pass_fit_rms_px": rms}
    focus["coc_pass_error"] = focus["coc_pass_focus_distance"] / P - 1.0
    focus["pass"] = abs(focus["coc_pass_error"]) <= 0.01
    s_thin = lens["aperture_m"] * lens["k_px"]
    coc_max = float(coc[ok].max()) if ok.any() else 8.0
    floor_mask = albedo = None
    if args.image_focus:
        t0 = time.time()
        albedo = floor_albedo_image(scene, *FLOOR_ALBEDO)
        # dofray's two seeds averaged (less noise; this measures blur, not light).
        img, floor_mask = measure_focus_from_images(bdepth, ids, names, albedo,
                                                    {"dofray": 0.5 * (dof.mean(2) + dof2.mean(2)),
                                                     "cycles": cycl.mean(2)},
                                                    min(coc_max, 16.0), s_thin, boot=40)
        log(f"blur along the floor measured in {time.time() - t0:.1f} s")
        for v in img.values():
            v["focus_error"] = v["focus_distance"] / P - 1.0
            v["slope_error"] = v["slope_px"] / s_thin - 1.0
            # Within 1%, or within 2 sigma of it (the measurement's own noise).
            v["pass"] = abs(v["focus_error"]) <= max(0.01, 2.0 * v["focus_sd"] / P)
        focus["images"] = img
        focus["slope_dofray_over_cycles"] = img["dofray"]["slope_px"] / img["cycles"]["slope_px"]
        focus["pass"] = focus["pass"] and all(v["pass"] for v in img.values())
    checks["focus_plane"] = focus

    # Blur size at the card's centre.
    cx, cy, cz = pixel_of(scene, CARD["location"])
    thin, textbook = thin_lens_coc(lens, cz)
    got = float(bilinear(coc, cx, cy))
    blur = {"test_point": "card centre", "pixel": [cx, cy], "blender_depth": cz,
            "dofray_depth": float(bilinear(ddepth, cx, cy)), "dofray_coc_px": got,
            "thin_lens_coc_px": thin, "textbook_thin_lens_coc_px": textbook,
            "error": got / thin - 1.0, "error_vs_textbook": got / textbook - 1.0,
            "thin_lens_slope_px": s_thin, "coc_pass_slope_px": s_pass}
    blur["pass"] = abs(blur["error"]) <= 0.02
    checks["blur_size"] = blur

    # Region means.
    rects = regions(scene, w, h, lens)
    table = region_table({k: v[0] for k, v in rects.items()}, cycl, dof, dof2)
    adaptive = read_rgb(exr["adaptive"]) if args.adaptive else None
    for name, (r, what) in rects.items():
        x0_, y0_, x1_, y1_ = r
        win = ids[y0_:y1_, x0_:x1_]
        v = table[name]
        if what is not None:
            idx = -1 if what == -1 else names.index(what)
            v["coverage"] = float((win == idx).mean())
        v["pass"] = abs(v["ratio"] - 1.0) <= args.tolerance
        if adaptive is not None:
            am = adaptive[y0_:y1_, x0_:x1_].reshape(-1, 3).mean(0)
            v["adaptive_rgb"] = am.tolist()
            v["adaptive_ratio"] = float(am.mean() / np.mean(v["cycles_rgb"]))
    checks["region_means"] = {"tolerance": args.tolerance, "regions": table,
                              "pass": all(v["pass"] for v in table.values())}
    checks["region_means"]["diagnostic"] = sun_highlight(scene, ids, names, cycl, dof, dof2)

    # Pictures.
    scale = 0.5  # one stop down: the floor's light strips are above 1
    rect_list = [v["rect"] for v in table.values()]
    side_by_side(os.path.join(out, "roundtrip.compare.png"),
                 [draw_rects(srgb8(cycl * scale), rect_list),
                  draw_rects(srgb8(dof * scale), rect_list), ratio8(cycl, dof)], 2)
    depth_vis = np.where(ddepth < 1e9, 1.0 / np.maximum(ddepth, 1e-6), 0.0)
    panels = [grey8(depth_vis, 0.0, depth_vis.max()), grey8(coc, 0.0, max(coc_max, 1e-6))]
    if floor_mask is not None:
        mask_vis = srgb8(dof * scale)
        mask_vis[~floor_mask] = (mask_vis[~floor_mask] * 0.3).astype(np.uint8)
        panels = panels + [grey8(albedo, 0.0, 1.0), mask_vis]
    side_by_side(os.path.join(out, "roundtrip.passes.png"), panels, 2)

    result["pass"] = all(c["pass"] for c in checks.values())
    result["seconds"] = time.time() - t_start
    with open(os.path.join(out, "roundtrip.json"), "w") as f:
        json.dump(result, f, indent=2, default=to_json)
    return result


def main(args):
    dofray_blender.register()
    result = roundtrip(args)
    result["command"] = " ".join([sys.executable] + sys.argv)
    with open(os.path.join(args.out, "roundtrip.json"), "w") as f:
        json.dump(result, f, indent=2, default=to_json)
    report(result)
    return 0 if result["pass"] else 1


def yes(ok):
    return "PASS" if ok else "FAIL"


def report(r):
    c = r["checks"]
    print()
    print(f"dofray vs Blender {r['blender']} / Cycles, {r['width']}x{r['height']}, "
          f"{r['spp']} spp (dofray dense {r['dofray_seconds']:.1f} s, Cycles "
          f"{r['cycles_seconds'] or 0:.1f} s)")
    f = c["filter_width"]
    print(f"pixel filter: Cycles Blackman-Harris {f['cycles_filter_width']:g} px -> dofray "
          f"width {f['dofray_pixel_filter_width']:g}  {yes(f['pass'])}")
    v = c["field_of_view"]
    print(f"field of view: Blender {v['blender_hfov_deg']:.4f} deg, dofray "
          f"{v['dofray_hfov_deg']:.4f} deg  {yes(v['pass'])}")
    fr = c["framing"]
    print(f"framing: {fr['pixels_depth_differs_1pct']} pixels whose depth differs by > 1% "
          f"({100 * fr['fraction_depth_differs_1pct']:.3f}%), median relative depth "
          f"difference {fr['median_relative_depth_difference']:.1e}; worst object shift "
          f"{fr['worst_shift_px']:.2f} px (<= 0.25); Blender's rays reproject onto their "
          f"pixel centres within {fr['blender_rays_reprojection_px']:.1e} px  {yes(fr['pass'])}")
    for name, o in fr["objects"].items():
        print(f"    {name:8s} centre at ({o['blender_centre_px'][0]:6.1f}, "
              f"{o['blender_centre_px'][1]:6.1f}) px: shift ({o['shift_px'][0]:+.2f}, "
              f"{o['shift_px'][1]:+.2f}) px")
    fo = c["focus_plane"]
    print(f"focus plane: Blender {fo['blender_focus_distance']:.4f} m (exported "
          f"{fo['exported_focus_distance']:.4f}); dofray's CoC pass reaches 0 at "
          f"{fo['coc_pass_focus_distance']:.4f} m ({100 * fo['coc_pass_error']:+.3f}%, "
          f"<= 1%)  {yes(fo['pass'])}")
    for name, v in fo.get("images", {}).items():
        name = "dofray's (seeds 0 and 1)" if name == "dofray" else "Cycles'"
        print(f"    sharpest depth in {name} image (floor, {v['rows']} rows, "
              f"{v['depth_range'][0]:.2f}-{v['depth_range'][1]:.1f} m): "
              f"{v['focus_distance']:.3f} +- {v['focus_sd']:.3f} m "
              f"({100 * v['focus_error']:+.2f}%); blur slope {v['slope_px']:.2f} +- "
              f"{v['slope_sd']:.2f} px m ({100 * v['slope_error']:+.1f}% of the thin lens's)  "
              f"{yes(v['pass'])}")
    if "slope_dofray_over_cycles" in fo:
        print(f"    blur slope dofray / Cycles: {fo['slope_dofray_over_cycles']:.3f}")
    b = c["blur_size"]
    print(f"blur size at the {b['test_point']} (depth {b['blender_depth']:.3f} m, dofray "
          f"{b['dofray_depth']:.3f}): dofray CoC {b['dofray_coc_px']:.3f} px, thin lens "
          f"{b['thin_lens_coc_px']:.3f} px ({100 * b['error']:+.2f}%, <= 2%)  "
          f"{yes(b['pass'])}; textbook thin lens (sensor moved to focus) "
          f"{b['textbook_thin_lens_coc_px']:.3f} px ({100 * b['error_vs_textbook']:+.2f}%)")
    rm = c["region_means"]
    print(f"region means (mean linear RGB, dofray / Cycles, within "
          f"{100 * rm['tolerance']:.0f}%; noise = 1 sigma of the ratio):")
    print(f"    {'region':26s} {'Cycles':>8s} {'dofray':>8s} {'ratio':>7s} {'noise':>6s}  "
          f"{'R':>6s} {'G':>6s} {'B':>6s}  {'adaptive':>8s}")
    for name, v in rm["regions"].items():
        cm = sum(v["cycles_rgb"]) / 3
        dm = sum(v["dofray_rgb"]) / 3
        rr = " ".join(f"{x:6.3f}" for x in v["ratio_rgb"])
        ad = f"{v['adaptive_ratio']:8.4f}" if "adaptive_ratio" in v else f"{'-':>8s}"
        print(f"    {name:26s} {cm:8.4f} {dm:8.4f} {v['ratio']:7.4f} "
              f"{100 * v['noise']:5.1f}%  {rr}  {ad}  {yes(v['pass'])}")
    for name, v in rm.get("diagnostic", {}).items():
        inc = f", incidence {v['incidence_deg']:.0f} deg" if v.get("incidence_deg") else ""
        print(f"    not judged: {name} (9x9 px at {tuple(v['pixel'])}{inc}): Cycles "
              f"{sum(v['cycles_rgb']) / 3:.3f}, dofray {sum(v['dofray_rgb']) / 3:.3f}, ratio "
              f"{v['ratio']:.3f} +- {v['noise']:.3f} (dielectric Fresnel)")
    print(f"all: {yes(r['pass'])} ({r['seconds']:.0f} s)")


if __name__ == "__main__":
    try:
        code = main(ARGS)
    except BaseException:
        import traceback

        traceback.print_exc()
        code = 1
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)  # bpy 4.2 can crash in the interpreter's exit (README.md)
