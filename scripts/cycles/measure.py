"""Measures how Cycles turns Blender's light settings into radiance, against closed forms: a
white-ish Lambertian plane (Diffuse BSDF, albedo 0.8) at z = 0, seen straight down by an
orthographic camera, lit by one light at a time; every pixel is compared with
L = albedo / pi * E(x, y) for the irradiance E a hypothesis predicts. Run by hand (README.md).

    /path/to/venv/bin/python scripts/cycles/measure.py --out /tmp/cycles-measure [--spp 512]

Prints, per case, measured / predicted over the pixels where the prediction is not small, for
each hypothesis (1.000 = the hypothesis is what Cycles does).
"""

import argparse
import math
import os
import sys

import bpy
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from common import configure_cycles, read_rgb, write_hdr  # noqa: E402

ROWS = []
ALBEDO = 0.8
RES = 64
HALF = 2.0  # the camera sees x, y in [-HALF, HALF]


def setup(spp):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    configure_cycles(scene, spp, RES, RES)
    w = bpy.data.worlds.new("World")
    w.use_nodes = True
    w.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.world = w
    m = bpy.data.materials.new("Lambert")
    m.use_nodes = True
    nt = m.node_tree
    nt.nodes.remove(nt.nodes["Principled BSDF"])
    d = nt.nodes.new("ShaderNodeBsdfDiffuse")
    d.inputs["Color"].default_value = (ALBEDO, ALBEDO, ALBEDO, 1.0)
    d.inputs["Roughness"].default_value = 0.0
    nt.links.new(d.outputs["BSDF"], nt.nodes["Material Output"].inputs["Surface"])
    bpy.ops.mesh.primitive_plane_add(size=40.0, location=(0, 0, 0))
    bpy.context.object.data.materials.append(m)
    cam = bpy.data.cameras.new("Cam")
    cam.type = "ORTHO"
    cam.ortho_scale = 2 * HALF
    o = bpy.data.objects.new("Cam", cam)
    o.location = (0, 0, 10)
    scene.collection.objects.link(o)
    scene.camera = o
    return scene


def light(kind, location, energy, rotation=(0.0, 0.0, 0.0), **props):
    data = bpy.data.lights.new("L", type=kind)
    data.energy = energy
    for k, v in props.items():
        setattr(data, k, v)
    o = bpy.data.objects.new("L", data)
    o.location = location
    o.rotation_euler = rotation
    o.visible_camera = False
    bpy.context.scene.collection.objects.link(o)
    return o


def emitter(size, height, strength, facing_down=True):
    m = bpy.data.materials.new("Emit")
    m.use_nodes = True
    b = m.node_tree.nodes["Principled BSDF"]
    b.inputs["Base Color"].default_value = (0, 0, 0, 1)
    b.inputs["Emission Color"].default_value = (1, 1, 1, 1)
    b.inputs["Emission Strength"].default_value = strength
    b.inputs["Specular IOR Level"].default_value = 0.0
    rot = (math.pi, 0, 0) if facing_down else (0, 0, 0)
    bpy.ops.mesh.primitive_plane_add(size=size, location=(0, 0, height), rotation=rot)
    o = bpy.context.object
    o.data.materials.append(m)
    o.visible_camera = False
    return o


def render(out, name):
    """Renders the scene; returns its linear RGB (H x W x 3)."""
    path = os.path.join(out, name + ".exr")
    bpy.context.scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    return read_rgb(path)


def grid():
    c = (np.arange(RES) + 0.5) / RES * 2 * HALF - HALF
    x, y = np.meshgrid(c, -c)  # row 0 is the top of the image: +y
    return x, y


def e_point(x, y, h, intensity):
    d2 = x * x + y * y + h * h
    cos_surf = h / np.sqrt(d2)
    return intensity * cos_surf / d2


def e_area(x, y, h, radiance, shape, size, n=96):
    """Irradiance on the plane from a one-sided Lambertian emitter at height h facing down, by
    a midpoint rule over the emitter."""
    u = ((np.arange(n) + 0.5) / n - 0.5) * size
    lx, ly = np.meshgrid(u, u)
    keep = np.ones_like(lx, bool) if shape == "rect" else (lx * lx + ly * ly <= (size / 2) ** 2)
    lx, ly = lx[keep], ly[keep]
    da = (size / n) ** 2
    e = np.zeros_like(x)
    for px, py in zip(lx, ly):
        d2 = (x - px) ** 2 + (y - py) ** 2 + h * h
        e += radiance * (h * h) / (d2 * d2) * da  # cos at both ends = h / d
    return e


def smoothstep(t):
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3 - 2 * t)


def compare(measured, hyps):
    """measured / predicted for each hypothesis over the pixels it predicts to be lit."""
    out = {}
    for name, e in hyps.items():
        pred = ALBEDO / math.pi * e
        mask = pred > 0.2 * pred.max()
        out[name] = float(measured[mask].sum() / pred[mask].sum())
    return out


def cases():
    x, y = grid()
    h = 2.0
    P = 100.0
    d2 = x * x + y * y + h * h
    cos_axis = h / np.sqrt(d2)  # angle from a downward axis
    yield ("point 100 W, r = 0, h = 2",
           lambda: light("POINT", (0, 0, h), P, shadow_soft_size=0.0),
           {"I = P/(4 pi)": e_point(x, y, h, P / (4 * math.pi)),
            "I = P/pi": e_point(x, y, h, P / math.pi)})
    yield ("spot 100 W, r = 0, size 120, blend 0, down",
           lambda: light("SPOT", (0, 0, h), P, shadow_soft_size=0.0,
                         spot_size=math.radians(120), spot_blend=0.0),
           {"I = P/(4 pi) in cone": e_point(x, y, h, P / (4 * math.pi)) * (cos_axis > 0.5),
            "I = P/(4 pi) x cos(axis)": e_point(x, y, h, P / (4 * math.pi)) * cos_axis
            * (cos_axis > 0.5)})
    cos_half = math.cos(math.radians(30))
    blend = 0.6
    yield ("spot 100 W, r = 0, size 60, blend 0.6, down",
           lambda: light("SPOT", (0, 0, h), P, shadow_soft_size=0.0,
                         spot_size=math.radians(60), spot_blend=blend),
           {"smoothstep in cos: ((cos a - cos h)/((1 - cos h) blend))":
            e_point(x, y, h, P / (4 * math.pi))
            * smoothstep((cos_axis - cos_half) / ((1 - cos_half) * blend)),
            "glTF export: inner = outer (1 - blend), t^2 in cos":
            e_point(x, y, h, P / (4 * math.pi))
            * np.clip((cos_axis - cos_half) / (math.cos(math.radians(30 * (1 - blend)))
                                              - cos_half), 0, 1) ** 2})
    yield ("sun 3, angle 0, down",
           lambda: light("SUN", (0, 0, 5), 3.0, angle=0.0),
           {"E = S": np.full_like(x, 3.0)})
    yield ("sun 3, angle 0, 60 deg from zenith",
           lambda: light("SUN", (0, 0, 5), 3.0, rotation=(math.radians(60), 0, 0), angle=0.0),
           {"E = S cos(60)": np.full_like(x, 1.5)})
    yield ("sun 3, angle 10 deg, down",
           lambda: light("SUN", (0, 0, 5), 3.0, angle=math.radians(10)),
           {"E = S": np.full_like(x, 3.0)})
    for shape, bshape in (("rect", "SQUARE"), ("disk", "DISK")):
        yield (f"area {shape} 1 m, 100 W, h = 2",
               lambda bshape=bshape: light("AREA", (0, 0, h), P, shape=bshape, size=1.0),
               {"L = P/(pi A)": e_area(x, y, h, P / (math.pi * (1.0 if shape == "rect" else
                                                               math.pi / 4)), shape, 1.0),
                "L = P/(4 pi A)": e_area(x, y, h, P / (4 * math.pi * (1.0 if shape == "rect"
                                                                      else math.pi / 4)),
                                         shape, 1.0)})
    r = 0.6
    h1 = 1.0
    d2_1 = x * x + y * y + h1 * h1
    yield ("point 100 W, r = 0.6, soft falloff on, h = 1",
           lambda: light("POINT", (0, 0, h1), P, shadow_soft_size=r, use_soft_falloff=True),
           {"point: I/d^2": e_point(x, y, h1, P / (4 * math.pi)),
            "I cos / (d^2 + r^2)": P / (4 * math.pi) * (h1 / np.sqrt(d2_1)) / (d2_1 + r * r)})
    yield ("point 100 W, r = 0.6, soft falloff off (sphere), h = 1",
           lambda: light("POINT", (0, 0, h1), P, shadow_soft_size=r, use_soft_falloff=False),
           {"sphere = point: I cos/d^2": e_point(x, y, h1, P / (4 * math.pi))})
    yield ("emissive square 1 m, strength 10, h = 2",
           lambda: emitter(1.0, h, 10.0),
           {"L = strength": e_area(x, y, h, 10.0, "rect", 1.0)})
    yield ("emissive square 1 m, strength 10, h = 2, facing away (back side down)",
           lambda: emitter(1.0, h, 10.0, facing_down=False),
           {"L = strength (two-sided)": e_area(x, y, h, 10.0, "rect", 1.0)})


def world_case(out):
    """A uniform world of colour 1, strength 0.5 over the plane: E = pi * 0.5."""
    scene = setup(ARGS.spp)
    bg = scene.world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (1, 1, 1, 1)
    bg.inputs["Strength"].default_value = 0.5
    m = render(out, "world")
    ROWS.append(f"| world colour 1, strength 0.5 | radiance = colour x strength | "
                f"{m.mean() / (ALBEDO * 0.5):.4f} |")


def emission_seen(out):
    """The camera looks at an emissive plane of strength 5: the pixels are its radiance."""
    scene = setup(ARGS.spp)
    o = emitter(10.0, 1.0, 5.0)
    o.rotation_euler = (0, 0, 0)
    o.visible_camera = True
    m = render(out, "emission")
    ROWS.append(f"| emissive plane seen, strength 5 | pixel = strength | {m.mean() / 5.0:.4f} |")


def world_orientation(out):
    """Which way Cycles' equirectangular lookup and the Mapping node's Z rotation turn a map:
    a map of four bands in u (u = 0.5 blue, 0.75 white, 0 and 1 red, 0.25 green; the top half
    twice as bright) is seen by a camera looking along +X, +Y, -X, -Y, 30 degrees up."""
    w, h = 64, 32
    rgb = np.zeros((h, w, 3))
    bands = [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 1)]  # centred on u = 0, .25, .5, .75
    for r in range(h):  # r = 0 is the top row (v = 1)
        for i in range(w):
            c = bands[int((((i + 0.5) / w + 0.125) % 1.0) * 4)]
            rgb[r, i] = np.array(c) * (2.0 if r < h // 2 else 1.0)
    path = os.path.join(out, "bands.hdr")
    write_hdr(path, rgb)
    names = {(1, 0, 0): "red", (0, 1, 0): "green", (0, 0, 1): "blue", (1, 1, 1): "white"}
    for rot in (0.0, 90.0):
        scene = setup(16)
        for o in list(scene.objects):
            if o.type == "MESH":
                bpy.data.objects.remove(o)
        nt = scene.world.node_tree
        env = nt.nodes.new("ShaderNodeTexEnvironment")
        env.image = bpy.data.images.load(path)
        coord = nt.nodes.new("ShaderNodeTexCoord")
        mapping = nt.nodes.new("ShaderNodeMapping")
        mapping.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(rot))
        nt.links.new(coord.outputs["Generated"], mapping.inputs["Vector"])
        nt.links.new(mapping.outputs["Vector"], env.inputs["Vector"])
        nt.links.new(env.outputs["Color"], nt.nodes["Background"].inputs["Color"])
        nt.nodes["Background"].inputs["Strength"].default_value = 1.0
        cam = scene.camera.data
        cam.type = "PERSP"
        cam.lens = 200.0
        seen = []
        for label, yaw in (("+X", 0), ("+Y", 90), ("-X", 180), ("-Y", 270)):
            # Blender cameras look along local -Z: pitch 90 + 30 degrees up, then yaw.
            scene.camera.rotation_euler = (math.radians(120), 0.0, math.radians(yaw - 90))
            scene.camera.location = (0, 0, 0)
            m = render(out, f"bands_{int(rot)}_{yaw}").mean(axis=(0, 1))
            k = max(m)
            colour = names.get(tuple(int(round(c / k)) for c in m), str(m))
            seen.append(f"{label}: {colour} x{k:.2f}")
        ROWS.append(f"| world map, Mapping Z rotation {rot:g} | camera 30 degrees up along | "
                    + ", ".join(seen) + " |")


def main(argv):
    global ARGS
    p = argparse.ArgumentParser()
    p.add_argument("--out", required=True)
    p.add_argument("--spp", type=int, default=512)
    ARGS = p.parse_args(argv)
    os.makedirs(ARGS.out, exist_ok=True)
    for i, (name, build, hyps) in enumerate(cases()):
        setup(ARGS.spp)
        build()
        m = render(ARGS.out, f"case{i}").mean(axis=2)
        for hname, ratio in compare(m, hyps).items():
            ROWS.append(f"| {name} | {hname} | {ratio:.4f} |")
    world_case(ARGS.out)
    emission_seen(ARGS.out)
    world_orientation(ARGS.out)
    # Blender prints its render log on stdout: the table comes last, and into measure.md.
    table = "\n".join(["| case | hypothesis | measured / predicted |", "|---|---|---|"] + ROWS)
    with open(os.path.join(ARGS.out, "measure.md"), "w") as f:
        f.write(table + "\n")
    print("\n" + table)
    return 0


if __name__ == "__main__":
    code = main(sys.argv[1:])
    sys.stdout.flush()
    os._exit(code)
