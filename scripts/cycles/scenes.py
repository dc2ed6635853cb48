"""Builds the Cycles comparison scenes in Blender (the `bpy` module from PyPI), exports each with
Blender's own glTF exporter, writes a JSON sidecar with what glTF cannot carry, and renders each
with Cycles into a linear float EXR. Run by hand, not in CI (see README.md in this folder).

    /path/to/venv/bin/python scripts/cycles/scenes.py --out /tmp/cycles-cmp [--spp 1024] [--res 320x240]
        [--only box,spheres] [--no-render] [--dof] [--blender-biased]

For every scene NAME, OUT/NAME/ gets:
    NAME.glb            the export (lights on, Lighting Mode Standard, +Y up)
    NAME.json           the sidecar: world, area lights, camera lens, resolution, render settings
    NAME.cycles.exr     the Cycles render (RGBA float, scene-linear; Standard view transform)
    NAME.blend          the scene as rendered (with --dof: depth of field on)
    (sky.hdr)           the environment map, for scenes that use one

Everything is built in code from fixed numbers, so a rerun gives the same files (Cycles' seed is
fixed as well).
"""

import argparse
import json
import math
import os
import sys
import time

import bpy
import numpy as np
from mathutils import Vector

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from common import configure_cycles, write_hdr  # noqa: E402

# ---------------------------------------------------------------------------------------------
# Small helpers


def clear():
    bpy.ops.wm.read_factory_settings(use_empty=True)


def principled(name, color, roughness=0.5, metallic=0.0, transmission=0.0, ior=None,
               emission=None, emission_strength=0.0):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    b = m.node_tree.nodes["Principled BSDF"]
    b.inputs["Base Color"].default_value = (*color, 1.0)
    b.inputs["Roughness"].default_value = roughness
    b.inputs["Metallic"].default_value = metallic
    b.inputs["Transmission Weight"].default_value = transmission
    if ior is not None:
        b.inputs["IOR"].default_value = ior
    if emission is not None:
        b.inputs["Emission Color"].default_value = (*emission, 1.0)
        b.inputs["Emission Strength"].default_value = emission_strength
    return m


def assign(obj, mat):
    obj.data.materials.clear()
    obj.data.materials.append(mat)
    return obj


def plane(size, location, mat, rotation=(0.0, 0.0, 0.0), name=None):
    bpy.ops.mesh.primitive_plane_add(size=size, location=location, rotation=rotation)
    o = bpy.context.object
    if name:
        o.name = name
    return assign(o, mat)


def cube(size, location, mat, rotation=(0.0, 0.0, 0.0), scale=(1.0, 1.0, 1.0)):
    bpy.ops.mesh.primitive_cube_add(size=size, location=location, rotation=rotation, scale=scale)
    return assign(bpy.context.object, mat)


def sphere(radius, location, mat, segments=64, rings=32):
    bpy.ops.mesh.primitive_uv_sphere_add(segments=segments, ring_count=rings, radius=radius,
                                         location=location)
    o = bpy.context.object
    for p in o.data.polygons:
        p.use_smooth = True
    return assign(o, mat)


def look_at(obj, target):
    direction = Vector(target) - obj.location
    obj.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()


def add_light(kind, name, location, energy, target=None, rotation=None, **props):
    data = bpy.data.lights.new(name, type=kind)
    data.energy = energy
    for k, v in props.items():
        setattr(data, k, v)
    o = bpy.data.objects.new(name, data)
    o.location = location
    bpy.context.scene.collection.objects.link(o)
    if target is not None:
        look_at(o, target)
    elif rotation is not None:
        o.rotation_euler = rotation
    return o


def add_camera(location, target, lens=35.0, sensor=36.0, focus_target=None, f_number=2.0):
    scene = bpy.context.scene
    cam = bpy.data.cameras.new("Camera")
    cam.lens = lens
    cam.sensor_width = sensor
    cam.sensor_fit = "AUTO"
    o = bpy.data.objects.new("Camera", cam)
    o.location = location
    scene.collection.objects.link(o)
    look_at(o, target)
    scene.camera = o
    bpy.context.view_layer.update()
    # The DOF variant: focused on the middle object, along the view axis (as Blender measures it).
    ft = Vector(focus_target if focus_target is not None else target)
    axis = o.matrix_world.to_3x3() @ Vector((0.0, 0.0, -1.0))
    cam.dof.focus_distance = (ft - o.location).dot(axis)
    cam.dof.aperture_fstop = f_number
    cam.dof.use_dof = False
    return o


def world_color(color, strength):
    w = bpy.data.worlds.new("World")
    w.use_nodes = True
    bg = w.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (*color, 1.0)
    bg.inputs["Strength"].default_value = strength
    bpy.context.scene.world = w
    return {"color": list(color), "strength": strength}


def world_map(path, strength, rotation_deg, mean):
    w = bpy.data.worlds.new("World")
    w.use_nodes = True
    nt = w.node_tree
    bg = nt.nodes["Background"]
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(path)
    env.image.colorspace_settings.name = "Linear Rec.709"
    env.interpolation = "Linear"
    env.projection = "EQUIRECTANGULAR"
    coord = nt.nodes.new("ShaderNodeTexCoord")
    mapping = nt.nodes.new("ShaderNodeMapping")
    mapping.vector_type = "POINT"
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(rotation_deg))
    nt.links.new(coord.outputs["Generated"], mapping.inputs["Vector"])
    nt.links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    bg.inputs["Strength"].default_value = strength
    bpy.context.scene.world = w
    return {"map": os.path.basename(path), "strength": strength, "rotation": rotation_deg,
            "map_mean": mean}


def blender_to_gltf(v):
    """Blender (x, y, z), Z up -> glTF / dofray (x, z, -y), Y up."""
    return [v[0], v[2], -v[1]]


def area_light_record(obj):
    d = obj.data
    m = obj.matrix_world
    normal = (m.to_3x3() @ Vector((0.0, 0.0, -1.0))).normalized()
    axis_x = (m.to_3x3() @ Vector((1.0, 0.0, 0.0))).normalized()
    rec = {
        "name": obj.name,
        "power": d.energy,
        "color": list(d.color),
        "shape": d.shape,
        "position": blender_to_gltf(m.translation),
        "direction": blender_to_gltf(normal),
        "axis_x": blender_to_gltf(axis_x),
        "matrix_world_blender": [list(r) for r in m],
        "spread_deg": math.degrees(d.spread),
    }
    if d.shape in ("SQUARE", "RECTANGLE"):
        rec["type"] = "rect"
        sy = d.size if d.shape == "SQUARE" else d.size_y
        rec["size"] = [d.size, sy]
    else:
        rec["type"] = "disk"
        rec["size"] = d.size  # diameter (ELLIPSE with size_y != size is not used here)
    return rec


def punctual_record(obj):
    d = obj.data
    rec = {"name": obj.name, "type": d.type, "power": d.energy, "color": list(d.color)}
    if d.type in ("POINT", "SPOT"):
        rec["radius"] = d.shadow_soft_size
        rec["soft_falloff"] = d.use_soft_falloff
    if d.type == "SPOT":
        rec["spot_size_deg"] = math.degrees(d.spot_size)
        rec["spot_blend"] = d.spot_blend
    if d.type == "SUN":
        rec["angle_deg"] = math.degrees(d.angle)
    return rec


# ---------------------------------------------------------------------------------------------
# The environment map: a sky gradient, a darker ground and a bright sun blob


def make_sky(path, width=256, height=128):
    """Writes a small equirectangular float image (Radiance .hdr; row 0 the top, elevation +90
    degrees, as Blender's v = 1) and returns its mean radiance over the sphere (rows weighted by
    their solid angle)."""
    elev = (0.5 - (np.arange(height) + 0.5) / height) * math.pi
    t = np.sin(np.maximum(elev, 0.0))
    sky = np.stack([1.0 - 0.7 * t, 1.1 - 0.6 * t, 1.3 - 0.3 * t], -1)
    rows = np.where((elev > 0)[:, None], sky, [0.25, 0.2, 0.15])
    rgb = np.repeat(rows[:, None, :], width, axis=1)
    # The sun: a disc of 2.5 pixels' radius at u = 0.3, elevation 35 degrees.
    u = (np.arange(width) + 0.5) / width
    du = np.minimum(abs(u - 0.30), 1.0 - abs(u - 0.30)) * width
    dv = (elev - math.radians(35.0)) / math.pi * height
    disc = du[None, :] ** 2 + dv[:, None] ** 2 <= 2.5 ** 2
    rgb[disc] = [400.0, 380.0, 340.0]
    decoded = write_hdr(path, rgb)
    w = np.cos(elev)[:, None]
    return [float((decoded[..., c] * w).sum() / (w.sum() * width)) for c in range(3)]


# ---------------------------------------------------------------------------------------------
# The scenes. Each returns its sidecar's scene-specific part.


def scene_box(out_dir):
    """(a) A closed box (Cornell-like) lit only by an emissive patch under the ceiling."""
    white = principled("White", (0.73, 0.73, 0.73), roughness=1.0)
    red = principled("Red", (0.63, 0.065, 0.05), roughness=1.0)
    green = principled("Green", (0.14, 0.45, 0.091), roughness=1.0)
    lamp = principled("Lamp", (0.0, 0.0, 0.0), roughness=1.0, emission=(1.0, 0.85, 0.6),
                      emission_strength=30.0)
    # Box: x, y in [-1, 1], z in [0, 2]; planes face inward.
    plane(2.0, (0, 0, 0), white, name="Floor")
    plane(2.0, (0, 0, 2), white, rotation=(math.pi, 0, 0), name="Ceiling")
    plane(2.0, (0, 1, 1), white, rotation=(math.pi / 2, 0, 0), name="Back")
    plane(2.0, (0, -1, 1), white, rotation=(-math.pi / 2, 0, 0), name="Front")
    plane(2.0, (-1, 0, 1), red, rotation=(0, math.pi / 2, 0), name="Left")
    plane(2.0, (1, 0, 1), green, rotation=(0, -math.pi / 2, 0), name="Right")
    plane(0.5, (0, 0.3, 1.995), lamp, rotation=(math.pi, 0, 0), name="LampPatch")
    cube(0.6, (0.35, -0.25, 0.3), white, rotation=(0, 0, math.radians(-17)))
    cube(0.6, (-0.35, 0.3, 0.6), white, rotation=(0, 0, math.radians(20)), scale=(1, 1, 2))
    add_camera((0, -0.97, 1.0), (0, 1, 1.2), lens=16.0, focus_target=(0.35, -0.25, 0.3))
    return {"world": world_color((0, 0, 0), 0.0), "area_lights": []}


def scene_spheres(out_dir):
    """(b) Diffuse, glossy dielectric and metal spheres on a diffuse plane; sun + world colour."""
    floor = principled("Floor", (0.5, 0.5, 0.5), roughness=1.0)
    diffuse = principled("Diffuse", (0.8, 0.25, 0.2), roughness=1.0)
    glossy = principled("Glossy", (0.1, 0.3, 0.7), roughness=0.3)
    metal = principled("Metal", (0.95, 0.75, 0.4), roughness=0.2, metallic=1.0)
    plane(20.0, (0, 0, 0), floor)
    sphere(0.5, (-1.2, 0, 0.5), diffuse)
    sphere(0.5, (0, 0, 0.5), glossy)
    sphere(0.5, (1.2, 0, 0.5), metal)
    add_light("SUN", "Sun", (0, 0, 5), 3.0, rotation=(math.radians(40), 0, math.radians(30)),
              angle=0.0)
    add_camera((0, -5, 2.0), (0, 0, 0.45), lens=50.0, focus_target=(0, 0, 0.5))
    return {"world": world_color((0.4, 0.5, 0.7), 1.0), "area_lights": []}


def scene_hdr(out_dir):
    """(c) An object lit by an equirectangular HDR world (sun blob + sky), rotated 30 degrees."""
    path = os.path.join(out_dir, "sky.hdr")
    mean = make_sky(path)
    floor = principled("Floor", (0.6, 0.6, 0.6), roughness=1.0)
    body = principled("Body", (0.8, 0.8, 0.8), roughness=1.0)
    shiny = principled("Shiny", (0.9, 0.9, 0.9), roughness=0.25, metallic=1.0)
    plane(6.0, (0, 0, 0), floor)
    bpy.ops.mesh.primitive_monkey_add(size=1.2, location=(0, 0, 0.75),
                                      rotation=(math.radians(20), 0, math.radians(10)))
    o = bpy.context.object
    o.modifiers.new("subd", "SUBSURF").levels = 2
    for p in o.data.polygons:
        p.use_smooth = True
    assign(o, body)
    sphere(0.35, (1.2, 0.4, 0.35), shiny)
    add_camera((0.5, -4.5, 1.6), (0.2, 0, 0.6), lens=45.0, focus_target=(0, 0, 0.75))
    return {"world": world_map(path, 1.0, 30.0, mean), "area_lights": []}


def scene_lights(out_dir):
    """(d) A 500 W point, a 1000 W spot and a strength-3 sun on diffuse objects; black world."""
    floor = principled("Floor", (0.7, 0.7, 0.7), roughness=1.0)
    red = principled("Red", (0.8, 0.15, 0.1), roughness=1.0)
    blue = principled("Blue", (0.15, 0.25, 0.8), roughness=1.0)
    plane(14.0, (0, 0, 0), floor)
    cube(1.2, (0, 0, 0.6), red, rotation=(0, 0, math.radians(25)))
    sphere(0.7, (1.8, 0.8, 0.7), blue)
    bpy.ops.mesh.primitive_cylinder_add(vertices=48, radius=0.45, depth=1.6,
                                        location=(-1.9, 0.6, 0.8))
    assign(bpy.context.object, floor)
    add_light("POINT", "Point", (-1.5, -1.5, 2.5), 500.0, shadow_soft_size=0.0)
    add_light("SPOT", "Spot", (2.5, -2.5, 3.5), 1000.0, target=(0.5, 0.3, 0.0),
              shadow_soft_size=0.0, spot_size=math.radians(45.0), spot_blend=0.15)
    add_light("SUN", "Sun", (0, 0, 6), 3.0, rotation=(math.radians(55), 0, math.radians(-60)),
              angle=0.0)
    add_camera((0, -7.0, 3.5), (0, 0, 0.6), lens=40.0, focus_target=(0, 0, 0.6))
    return {"world": world_color((0, 0, 0), 0.0), "area_lights": []}


def scene_glass(out_dir):
    """(e) A glass sphere and a glass cube (transmission 1, IOR 1.45, roughness 0) on a plane,
    lit by a square area light and a sun, with a dim grey world."""
    floor = principled("Floor", (0.7, 0.7, 0.7), roughness=1.0)
    back = principled("Back", (0.2, 0.45, 0.3), roughness=1.0)
    glass = principled("Glass", (1.0, 1.0, 1.0), roughness=0.0, transmission=1.0, ior=1.45)
    plane(12.0, (0, 0, 0), floor)
    plane(12.0, (0, 3, 3), back, rotation=(math.pi / 2, 0, 0))
    sphere(0.6, (-0.5, 0, 0.6), glass)
    # 1 mm above the floor: a face coincident with the floor is z-fighting, which each renderer
    # resolves its own way (Cycles renders the contact black, dofray lights the floor through
    # the glass; README, "The glass cube's contact").
    cube(0.7, (0.9, 0.4, 0.351), glass, rotation=(0, 0, math.radians(30)))
    sphere(0.25, (0.0, 1.4, 0.25), principled("Orange", (0.9, 0.4, 0.05), roughness=0.5))
    area = add_light("AREA", "Area", (-1.5, -1.0, 3.0), 300.0, target=(0, 0, 0.5),
                     shape="SQUARE", size=1.0)
    add_light("SUN", "Sun", (0, 0, 6), 1.5, rotation=(math.radians(35), 0, math.radians(40)),
              angle=0.0)
    add_camera((0, -5.5, 2.2), (0, 0.3, 0.5), lens=50.0, focus_target=(-0.5, 0, 0.6))
    bpy.context.view_layer.update()
    return {"world": world_color((0.2, 0.2, 0.2), 1.0), "area_lights": [area_light_record(area)]}


def scene_defocus(out_dir):
    """(f) The equal-error shot: a row of spheres and boxes receding from 1.5 m to 12 m, 50 mm
    f/1.4 focused on the nearest sphere (with --dof: most of the frame is defocused), lit by a
    sun, a rect area light and a sky-blue world."""
    floor = principled("Floor", (0.6, 0.6, 0.6), roughness=1.0)
    plane(40.0, (0, 8, 0), floor)
    plane(40.0, (0, 16, 4), principled("Wall", (0.7, 0.6, 0.45), roughness=1.0),
          rotation=(math.pi / 2, 0, 0))
    mats = [principled("Red", (0.8, 0.2, 0.15), roughness=1.0),
            principled("Blue", (0.1, 0.3, 0.7), roughness=0.25),
            principled("Gold", (0.95, 0.75, 0.4), roughness=0.15, metallic=1.0),
            principled("Green", (0.2, 0.6, 0.25), roughness=0.5)]
    for i, y in enumerate((1.5, 3.0, 5.0, 7.5, 10.0, 12.0)):
        x = (-0.5 if i % 2 == 0 else 0.6) * (1.0 + 0.25 * i)
        if i % 3 == 2:
            cube(0.7, (x, y, 0.35), mats[i % 4], rotation=(0, 0, math.radians(20 * i)))
        else:
            sphere(0.35, (x, y, 0.35), mats[i % 4])
    add_light("SUN", "Sun", (0, 0, 6), 2.0, rotation=(math.radians(50), 0, math.radians(-35)),
              angle=0.0)
    area = add_light("AREA", "Area", (2.0, 0.0, 2.5), 400.0, target=(0, 4, 0.3),
                     shape="SQUARE", size=1.0)
    add_camera((0.1, -1.0, 0.6), (0.0, 6.0, 0.4), lens=50.0, focus_target=(-0.5, 1.5, 0.35),
               f_number=1.4)
    bpy.context.view_layer.update()
    return {"world": world_color((0.4, 0.5, 0.7), 1.0), "area_lights": [area_light_record(area)]}


SCENES = {
    "box": scene_box,
    "spheres": scene_spheres,
    "hdr": scene_hdr,
    "lights": scene_lights,
    "glass": scene_glass,
    "defocus": scene_defocus,
}


# ---------------------------------------------------------------------------------------------
# Export and render


def export_glb(path):
    bpy.ops.export_scene.gltf(
        filepath=path,
        export_format="GLB",
        export_lights=True,
        export_cameras=True,
        export_apply=True,
        export_yup=True,
        export_materials="EXPORT",
        export_import_convert_lighting_mode="SPEC",  # "Standard", the default, said explicitly
    )


def camera_record(scene):
    cam = scene.camera
    d = cam.data
    return {
        "dof": {
            "f_number": d.dof.aperture_fstop,
            "focus_distance": d.dof.focus_distance,
            "focal_length_mm": d.lens,
            "sensor_width_mm": d.sensor_width,
        },
        "position": blender_to_gltf(cam.matrix_world.translation),
        "sensor_fit": d.sensor_fit,
    }


def build_one(name, args):
    out_dir = os.path.join(args.out, name)
    os.makedirs(out_dir, exist_ok=True)
    clear()
    width, height = args.res
    configure_cycles(bpy.context.scene, args.spp, width, height, args.blender_biased)
    extra = SCENES[name](out_dir)
    scene = bpy.context.scene
    bpy.context.view_layer.update()
    lights = [punctual_record(o) for o in scene.objects
              if o.type == "LIGHT" and o.data.type != "AREA"]
    glb = os.path.join(out_dir, name + ".glb")
    export_glb(glb)
    sidecar = {
        "name": name,
        "glb": name + ".glb",
        "resolution": [width, height],
        "world": extra["world"],
        "area_lights": extra["area_lights"],
        "punctual_lights": lights,
        "camera": camera_record(scene),
        "cycles": {
            "version": bpy.app.version_string,
            "spp": args.spp,
            "dof": args.dof,
            "biased_defaults": args.blender_biased,
            "pixel_filter": scene.cycles.pixel_filter_type,
            "pixel_filter_width": scene.cycles.filter_width,
            "max_bounces": scene.cycles.max_bounces,
            "diffuse_bounces": scene.cycles.diffuse_bounces,
            "glossy_bounces": scene.cycles.glossy_bounces,
            "transmission_bounces": scene.cycles.transmission_bounces,
            "transparent_max_bounces": scene.cycles.transparent_max_bounces,
            "sample_clamp_indirect": scene.cycles.sample_clamp_indirect,
            "blur_glossy": scene.cycles.blur_glossy,
        },
        "exr": name + (".cycles.dof.exr" if args.dof else ".cycles.exr"),
    }
    with open(os.path.join(out_dir, name + ".json"), "w") as f:
        json.dump(sidecar, f, indent=2)
    scene.camera.data.dof.use_dof = args.dof
    # The scene as Cycles renders it, for equal_error.py.
    bpy.ops.wm.save_as_mainfile(filepath=os.path.join(out_dir, name + ".blend"), copy=True)
    if args.no_render:
        return
    scene.render.filepath = os.path.join(out_dir, sidecar["exr"])
    t0 = time.time()
    bpy.ops.render.render(write_still=True)
    print(f"[{name}] Cycles {args.spp} spp {width}x{height}: {time.time() - t0:.1f} s",
          file=sys.stderr)


def parse_res(s):
    w, h = s.lower().split("x")
    return int(w), int(h)


def main(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="output folder (one subfolder per scene)")
    p.add_argument("--spp", type=int, default=1024, help="Cycles samples per pixel")
    p.add_argument("--res", type=parse_res, default=(320, 240), help="WIDTHxHEIGHT")
    p.add_argument("--only", default="", help="comma-separated scene names (default: all)")
    p.add_argument("--no-render", action="store_true", help="export and sidecar only")
    p.add_argument("--dof", action="store_true", help="render the f/2 depth-of-field variant")
    p.add_argument("--blender-biased", action="store_true",
                   help="keep Cycles' biased defaults (indirect clamp 10, filter glossy 1, "
                        "light threshold 0.01) instead of turning them off")
    args = p.parse_args(argv)
    names = [n for n in args.only.split(",") if n] or list(SCENES)
    failed = []
    for name in names:
        if name not in SCENES:
            print(f"[{name}] unknown scene; known: {', '.join(SCENES)}", file=sys.stderr)
            failed.append(name)
            continue
        try:
            build_one(name, args)
        except Exception as e:  # one scene failing must not stop the others
            print(f"[{name}] FAILED: {e!r}", file=sys.stderr)
            failed.append(name)
    if failed:
        print("failed: " + ", ".join(failed), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    code = main(argv)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)  # bpy 4.2 can crash in the interpreter's exit; the files are written by now
