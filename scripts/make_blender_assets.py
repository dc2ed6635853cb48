"""Builds small test scenes in Blender (the `bpy` module) and exports them with Blender's own
glTF exporter (io_scene_gltf2), lights on, into tests/scene_assets/blender/.

    python3 -m venv /tmp/bpyvenv && /tmp/bpyvenv/bin/pip install bpy==4.2.0
    /tmp/bpyvenv/bin/python scripts/make_blender_assets.py

Outputs (committed, so the tests do not need Blender):
- lights.glb / lights.gltf + lights.bin: a ground plane, a cube, a sphere and a cone; an emissive
  sphere (strength 5, so KHR_materials_emissive_strength); a 1000 W point light, a 2000 W spot
  light (spot_size 40 degrees, blend 0.25) aimed at the cube, a strength-2 sun; a perspective
  camera (50 mm, DOF focus distance 6 m) looking at the objects. Lighting mode "Standard"
  (the exporter's default): W -> lm with 683 lm/W, point and spot divided by 4 pi.
- ortho.gltf + ortho.bin: one cube, an orthographic camera only, a point light with a custom
  cut-off distance (glTF `range`).
"""

import math
import os
import sys

import bpy
from mathutils import Vector

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "scene_assets", "blender")


def clear():
    bpy.ops.wm.read_factory_settings(use_empty=True)


def material(name, color, emission=None, strength=0.0):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    bsdf = m.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.6
    if emission is not None:
        bsdf.inputs["Emission Color"].default_value = (*emission, 1.0)
        bsdf.inputs["Emission Strength"].default_value = strength
    return m


def assign(obj, mat):
    obj.data.materials.append(mat)


def look_at(obj, target):
    direction = Vector(target) - obj.location
    obj.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()


def export(name, fmt):
    path = os.path.join(OUT, name)
    bpy.ops.export_scene.gltf(
        filepath=path,
        export_format=fmt,
        export_lights=True,
        export_cameras=True,
        export_apply=True,
        export_materials="EXPORT",
        export_yup=True,
    )
    print("wrote", path)


def lights_scene():
    clear()
    scene = bpy.context.scene
    grey = material("Ground", (0.7, 0.7, 0.7))
    red = material("Red", (0.8, 0.1, 0.08))
    blue = material("Blue", (0.1, 0.2, 0.8))
    lamp = material("Lamp", (1.0, 0.9, 0.6), emission=(1.0, 0.8, 0.4), strength=5.0)

    bpy.ops.mesh.primitive_plane_add(size=12, location=(0, 0, 0))
    assign(bpy.context.object, grey)
    bpy.ops.mesh.primitive_cube_add(size=1.5, location=(0, 0, 0.75))
    assign(bpy.context.object, red)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8, radius=0.8, location=(2.2, -1.0, 0.8))
    assign(bpy.context.object, blue)
    bpy.ops.mesh.primitive_cone_add(vertices=12, radius1=0.6, depth=1.5, location=(-2.2, -0.5, 0.75))
    assign(bpy.context.object, grey)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=12, ring_count=6, radius=0.25, location=(-1.0, 2.0, 1.8))
    assign(bpy.context.object, lamp)

    point = bpy.data.lights.new("Point", type="POINT")
    point.energy = 1000.0
    point.color = (1.0, 0.85, 0.7)
    o = bpy.data.objects.new("Point", point)
    o.location = (-1.0, 2.0, 2.5)
    scene.collection.objects.link(o)

    spot = bpy.data.lights.new("Spot", type="SPOT")
    spot.energy = 2000.0
    spot.spot_size = math.radians(40.0)
    spot.spot_blend = 0.25
    o = bpy.data.objects.new("Spot", spot)
    o.location = (3.0, -3.0, 4.0)
    scene.collection.objects.link(o)
    look_at(o, (0.0, 0.0, 0.75))

    sun = bpy.data.lights.new("Sun", type="SUN")
    sun.energy = 2.0
    o = bpy.data.objects.new("Sun", sun)
    o.rotation_euler = (math.radians(40.0), 0.0, math.radians(30.0))
    scene.collection.objects.link(o)

    cam = bpy.data.cameras.new("Camera")
    cam.lens = 50.0
    cam.sensor_width = 36.0
    cam.dof.use_dof = True
    cam.dof.focus_distance = 6.0
    cam.dof.aperture_fstop = 2.8
    o = bpy.data.objects.new("Camera", cam)
    o.location = (0.0, -8.0, 4.0)
    scene.collection.objects.link(o)
    look_at(o, (0.0, 0.0, 0.6))
    scene.camera = o
    scene.render.resolution_x = 320
    scene.render.resolution_y = 240

    export("lights.glb", "GLB")
    export("lights.gltf", "GLTF_SEPARATE")


def ortho_scene():
    clear()
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, 0.5))
    assign(bpy.context.object, material("Grey", (0.6, 0.6, 0.6)))
    point = bpy.data.lights.new("Ranged", type="POINT")
    point.energy = 100.0
    point.use_custom_distance = True
    point.cutoff_distance = 5.0
    o = bpy.data.objects.new("Ranged", point)
    o.location = (1.0, -1.0, 2.0)
    scene.collection.objects.link(o)
    cam = bpy.data.cameras.new("Ortho")
    cam.type = "ORTHO"
    cam.ortho_scale = 4.0
    o = bpy.data.objects.new("Ortho", cam)
    o.location = (0.0, -6.0, 2.0)
    scene.collection.objects.link(o)
    look_at(o, (0.0, 0.0, 0.5))
    scene.camera = o
    export("ortho.gltf", "GLTF_SEPARATE")


if __name__ == "__main__":
    os.makedirs(OUT, exist_ok=True)
    lights_scene()
    ortho_scene()
    sys.exit(0)
