"""Blender scene -> dofray scene file (NAME.toml) + Blender's own glTF export (NAME.glb).

The glTF carries the meshes, materials, the camera's view and the point, spot and sun lights
(the add-on then keeps only the active camera in it and adds the IOR Blender's exporter drops
for opaque materials: `patch_glb`).
NAME.toml carries what glTF cannot (docs/scene-format.md in the dofray repository): the image
size, the render settings (samples, filter, bounces, clamp, transparency), the camera's depth of
field, the world (colour or equirectangular map, strength, rotation), area lights, and an
animated focus.

Everything that turns Blender values into dofray values is a small pure function here
(`horizontal_sensor_mm`, `focus_distance`, `blade_rotation_deg`, `area_light`, ...), so the
mapping table in docs/blender.md can be checked against the code. `export_scene(context,
toml_path)` does the whole export and returns what it wrote (the tests and the render engine
call it).

Axes: Blender is Z up, glTF and dofray are Y up; a Blender point (x, y, z) is (x, z, -y) in the
exported file (the glTF exporter's +Y Up conversion).
"""

import json
import math
import os
import shutil
import struct

import bpy
from mathutils import Vector

# dofray's own defaults (docs/scene-format.md) and the add-on's limits.
DEFAULT_SPP = 16
MAX_CYCLES_SPP = 1024  # "samples from Cycles" is clamped to this (Cycles' default is 4096)
SPP_RANGE = (1, 65536)
BOUNCE_RANGE = (0, 1024)
MAX_FILTER_WIDTH = 16.0
MAX_ANIMATION_FRAMES = 100000  # frames sampled for an animated focus


BORDER_WARNING = ("the render region (border) is not carried: the whole frame is rendered "
                  "(dofray render --region X0,Y0,X1,Y1 renders a window)")


def border_region(render, width, height):
    """Blender's render border as dofray's --region (x0, y0, x1, y1), pixels, y down from
    the top, x1 and y1 excluded), rounded to the nearest pixel as Blender's render result is
    (0.7 x 160 = 111.99999 in single precision is 112); None without a border."""
    if not render.use_border:
        return None

    def px(f, n):
        return int(math.floor(f * n + 0.5))

    x0, x1 = px(render.border_min_x, width), px(render.border_max_x, width)
    yb0, yb1 = px(render.border_min_y, height), px(render.border_max_y, height)
    x0, x1 = max(0, min(x0, width)), max(0, min(x1, width))
    y0, y1 = height - max(0, min(yb1, height)), height - max(0, min(yb0, height))
    if x1 <= x0 or y1 <= y0:
        return None
    return x0, y0, x1, y1


class ExportError(Exception):
    """The scene cannot be exported (no camera, an orthographic camera, ...)."""


class Warnings(list):
    """What the export could not carry, each message once."""

    def add(self, msg):
        if msg not in self:
            self.append(msg)


# ---------------------------------------------------------------------------------------------
# Conversions (pure functions of Blender values)


def blender_to_gltf(v):
    """Blender (x, y, z), Z up -> glTF / dofray (x, z, -y), Y up."""
    return [float(v[0]), float(v[2]), float(-v[1])]


def render_size(render):
    """The image size Blender renders: resolution x percentage (integer, as Blender rounds)."""
    pct = render.resolution_percentage
    return max(1, render.resolution_x * pct // 100), max(1, render.resolution_y * pct // 100)


def horizontal_sensor_mm(cam, width, height, pixel_aspect=(1.0, 1.0)):
    """The sensor width that gives dofray (whose sensor width is always horizontal) Blender's
    field of view: Blender fits its sensor to the image's larger side (AUTO, with
    `sensor_width`), to its width (HORIZONTAL, `sensor_width`) or its height (VERTICAL,
    `sensor_height`)."""
    xa = width * pixel_aspect[0]
    ya = height * pixel_aspect[1]
    fit = cam.sensor_fit
    if fit == "AUTO":
        fit, size = ("HORIZONTAL" if xa >= ya else "VERTICAL"), cam.sensor_width
    elif fit == "HORIZONTAL":
        size = cam.sensor_width
    else:
        size = cam.sensor_height
    return float(size) if fit == "HORIZONTAL" else float(size) * xa / ya


def view_axis(cam_obj):
    """The camera's view direction (its local -Z) in Blender's world, unit length."""
    return (cam_obj.matrix_world.to_3x3() @ Vector((0.0, 0.0, -1.0))).normalized()


def focus_target_position(dof):
    """World position of the focus object's origin (or of its focus bone), else None."""
    target = dof.focus_object
    if target is None:
        return None
    m = target.matrix_world
    sub = getattr(dof, "focus_subtarget", "")
    if sub and target.type == "ARMATURE" and target.pose and sub in target.pose.bones:
        return (m @ target.pose.bones[sub].matrix).translation.copy()
    return m.translation.copy()


def focus_distance(cam_obj):
    """The distance in focus as Cycles computes it: the camera's focus distance, or with a
    focus object the distance along the view axis to the object's origin (absolute)."""
    dof = cam_obj.data.dof
    pos = focus_target_position(dof)
    if pos is None:
        d = float(dof.focus_distance)
    else:
        d = abs(view_axis(cam_obj).dot(pos - cam_obj.matrix_world.translation))
    return max(d, 1e-5)  # Cycles clamps the same way


def blades(aperture_blades):
    """Blender's 0, 1 and 2 blades are a round aperture (Cycles uses a polygon from 3)."""
    return int(aperture_blades) if aperture_blades >= 3 else 0


def blade_rotation_deg(aperture_rotation, n):
    """Cycles' polygon (regular_polygon_sample) has an edge centred on the lens's +x axis at
    rotation 0, its corners at +-180/n degrees; dofray's (`aperture::polygon`) has a corner on
    +x. The same aperture in dofray is rotated by a further 180/n degrees."""
    deg = math.degrees(aperture_rotation)
    if n >= 3:
        deg = (deg + 180.0 / n) % 360.0
    return deg


def anamorphic_lens(f_number, aperture_ratio):
    """Cycles squeezes the aperture's width by 1 / ratio (`bokeh.x *= inv_aperture_ratio`), so
    its aperture is (R / ratio) wide and R tall; dofray's is R wide and R x anamorphic tall (R =
    focal length / (2 f_number)). The same aperture: anamorphic = ratio with the f-number
    multiplied by ratio. Returns (f_number, anamorphic)."""
    r = float(aperture_ratio)
    if abs(r - 1.0) < 1e-6:
        return float(f_number), 1.0
    return float(f_number) * r, r


def pixel_filter(kind, width):
    """Cycles' pixel filter -> dofray's (name, full width in pixels). Cycles' filter_width w is
    not the support: its filter table spans +-w for Blackman-Harris (`width *= 2` in Cycles'
    `filter_table`) and a Gaussian of sigma w / 4 (`width *= 3`, exp(-2 (6 v / 3w)^2)); dofray's
    width is the full support, with sigma = width / 6 for its Gaussian. So Blackman-Harris
    doubles (Cycles' default 1.5 px is dofray's 3 px), the Gaussian gets 1.5 w (same sigma;
    dofray cuts it at 3 sigma, Cycles at 6), the box keeps w."""
    kind = (kind or "BLACKMAN_HARRIS").upper()
    if kind == "BOX":
        name, w = "box", width
    elif kind == "GAUSSIAN":
        name, w = "gaussian", 1.5 * width
    else:
        name, w = "blackman-harris", 2.0 * width
    return name, float(min(max(w, 0.01), MAX_FILTER_WIDTH))


def clamp_int(v, lo_hi):
    lo, hi = lo_hi
    return int(min(max(int(v), lo), hi))


# ---------------------------------------------------------------------------------------------
# Render settings


def render_table(scene, settings, warnings):
    """[render]: samples, pixel filter, transparency, integrator, bounces, clamp."""
    out = {}
    cycles = getattr(scene, "cycles", None)
    if settings is not None and settings.use_cycles_samples and cycles is not None:
        spp = int(cycles.samples)
        if spp > MAX_CYCLES_SPP:
            warnings.add(f"Cycles' {spp} samples clamped to {MAX_CYCLES_SPP} for dofray")
            spp = MAX_CYCLES_SPP
    else:
        spp = settings.spp if settings is not None else DEFAULT_SPP
    out["spp"] = clamp_int(spp, SPP_RANGE)
    if settings is not None:
        if settings.aa > 0:
            # 0 (the default) leaves dofray's own: aa = spp with the path tracer, 4 with the
            # direct integrator. A fixed 4 would leave every in-focus pixel of a path-traced
            # render at 4 samples (dense and pinhole modes take aa there; adaptive sites start
            # from it).
            out["aa"] = clamp_int(settings.aa, SPP_RANGE)
        if settings.tolerance > 0.0:
            out["tolerance"] = float(settings.tolerance)
    if cycles is not None:
        kind, width = cycles.pixel_filter_type, cycles.filter_width
    else:
        kind, width = "BLACKMAN_HARRIS", scene.render.filter_size
    out["pixel_filter"], out["pixel_filter_width"] = pixel_filter(kind, width)
    out["transparent"] = bool(scene.render.film_transparent)
    out["integrator"] = settings.integrator.lower() if settings is not None else "path"
    if cycles is not None:
        out["max_bounces"] = clamp_int(cycles.max_bounces, BOUNCE_RANGE)
        out["diffuse_bounces"] = clamp_int(cycles.diffuse_bounces, BOUNCE_RANGE)
        out["glossy_bounces"] = clamp_int(cycles.glossy_bounces, BOUNCE_RANGE)
        out["transmission_bounces"] = clamp_int(cycles.transmission_bounces, BOUNCE_RANGE)
        if cycles.sample_clamp_indirect > 0.0:
            out["clamp_indirect"] = float(cycles.sample_clamp_indirect)
        if cycles.blur_glossy > 0.0:
            out["filter_glossy"] = float(cycles.blur_glossy)
        if not (cycles.caustics_reflective and cycles.caustics_refractive):
            warnings.add("Cycles' caustics switches are not carried (dofray traces every "
                         "caustic; Filter Glossy is carried)")
        if cycles.sample_clamp_direct > 0.0:
            warnings.add("Cycles' direct light clamp is not carried (dofray clamps indirect "
                         "light only)")
        if getattr(cycles, "volume_bounces", 0) and _scene_has_volumes(scene):
            warnings.add("volume bounces are not carried (dofray renders no volumes)")
    if scene.render.use_motion_blur:
        warnings.add("motion blur is not carried (dofray renders one instant)")
    if scene.render.use_border:
        warnings.add(BORDER_WARNING)
    if abs(scene.unit_settings.scale_length - 1.0) > 1e-6:
        warnings.add(f"unit scale {scene.unit_settings.scale_length:g} is ignored: dofray "
                     "reads Blender units as metres (the f-number's aperture is in metres)")
    return out


# Blender's view transforms and looks that dofray reproduces (docs/outputs.md, "Views").
VIEWS = ("Standard", "AgX", "Khronos PBR Neutral", "Raw")
AGX_LOOKS = ("None", "AgX - Very High Contrast", "AgX - High Contrast",
             "AgX - Medium High Contrast", "AgX - Base Contrast", "AgX - Medium Low Contrast",
             "AgX - Low Contrast", "AgX - Very Low Contrast", "AgX - Greyscale")


def view_table(scene, warnings):
    """[view]: Color Management's view transform, look, exposure and gamma, for PNG outputs
    (EXR stays linear). What dofray cannot reproduce falls back to Standard / no look, with a
    warning."""
    vs, ds = scene.view_settings, scene.display_settings
    out = {}
    view = vs.view_transform
    if view in VIEWS:
        out["transform"] = view
    else:
        warnings.add(f"view transform '{view}' is not available in dofray: its PNGs use "
                     "Standard (AgX, Blender's default, is)")
        view = "Standard"
    look = vs.look
    if look not in ("", "None"):
        if view == "AgX" and look in AGX_LOOKS:
            out["look"] = look
        else:
            warnings.add(f"look '{look}' is not available in dofray: its PNGs have no look")
    if vs.exposure != 0.0:
        out["exposure"] = float(vs.exposure)
    if vs.gamma != 1.0:
        out["gamma"] = float(vs.gamma)
    if vs.use_curve_mapping:
        warnings.add("Color Management's curves are not carried")
    if ds.display_device != "sRGB":
        warnings.add(f"display '{ds.display_device}' is not carried: dofray's PNGs are sRGB")
    cycles = getattr(scene, "cycles", None)
    if cycles is not None and abs(getattr(cycles, "film_exposure", 1.0) - 1.0) > 1e-6:
        warnings.add("Film > Exposure is not carried (use dofray's --exposure, in stops: "
                     f"{math.log2(max(cycles.film_exposure, 1e-9)):.3g})")
    return out


def _scene_has_volumes(scene):
    return any(o.type == "VOLUME" for o in scene.objects)


# ---------------------------------------------------------------------------------------------
# Camera


def check_camera(cam_obj):
    if cam_obj is None:
        raise ExportError("the scene has no active camera (Scene Properties > Camera)")
    if cam_obj.type != "CAMERA":
        raise ExportError(f"the active camera '{cam_obj.name}' is a {cam_obj.type.lower()} "
                          "object, not a camera (dofray renders a camera's view)")
    if cam_obj.data.type != "PERSP":
        raise ExportError(f"camera '{cam_obj.name}' is {cam_obj.data.type.lower()}: dofray "
                          "renders perspective (thin-lens) cameras only")


def camera_table(scene, cam_obj, width, height, warnings):
    """[camera]: the lens when the camera's depth of field is on, else nothing (a pinhole)."""
    cam = cam_obj.data
    if abs(cam.shift_x) > 1e-6 or abs(cam.shift_y) > 1e-6:
        warnings.add(f"camera '{cam_obj.name}': lens shift is not carried (dofray has no "
                     "shift; the view is centred)")
    r = scene.render
    if abs(r.pixel_aspect_x - r.pixel_aspect_y) > 1e-6:
        warnings.add("non-square pixels (pixel aspect) are not carried")
    if not cam.dof.use_dof:
        return {}
    f_number, anamorphic = anamorphic_lens(cam.dof.aperture_fstop, cam.dof.aperture_ratio)
    out = {
        "f_number": f_number,
        "focal_length_mm": float(cam.lens),
        "sensor_width_mm": horizontal_sensor_mm(cam, width, height,
                                                (r.pixel_aspect_x, r.pixel_aspect_y)),
        "focus_distance": focus_distance(cam_obj),
    }
    n = blades(cam.dof.aperture_blades)
    if n:
        out["blades"] = n
        out["blade_rotation"] = blade_rotation_deg(cam.dof.aperture_rotation, n)
    if anamorphic != 1.0:
        out["anamorphic"] = anamorphic
    return out


# ---------------------------------------------------------------------------------------------
# World


def _linked_node(socket):
    """The node feeding `socket`, skipping reroutes; None if unlinked."""
    while socket is not None and socket.is_linked:
        link = socket.links[0]
        if not link.is_valid or link.is_muted:
            return None
        node = link.from_node
        if node.type == "REROUTE":
            socket = node.inputs[0]
            continue
        return node
    return None


def _active_output(tree, kind):
    outs = [n for n in tree.nodes if n.type == kind]
    for n in outs:
        if getattr(n, "is_active_output", False) and getattr(n, "target", "ALL") in ("ALL", "CYCLES"):
            return n
    for n in outs:
        if getattr(n, "target", "ALL") in ("ALL", "CYCLES"):
            return n
    return outs[0] if outs else None


def _image_file(image, folder, warnings):
    """An absolute path dofray can read for `image`: its file, or its packed bytes written
    into `folder`."""
    path = bpy.path.abspath(image.filepath, library=image.library) if image.filepath else ""
    if image.packed_file is not None:
        ext = os.path.splitext(path or image.name)[1] or ".png"
        name = bpy.path.clean_name(os.path.splitext(os.path.basename(path or image.name))[0])
        out = os.path.join(folder, name + ext)
        with open(out, "wb") as f:
            f.write(image.packed_file.data)
        return out
    if path and os.path.isfile(path):
        return os.path.normpath(os.path.abspath(path))
    raise ExportError(f"the world's image '{image.name}' has no file dofray can read "
                      f"({path or 'generated or unsaved'}); save it as .hdr, .exr, .png or .jpg")


def world_table(scene, folder, copy_images, warnings):
    """[world]: the Background colour x strength, or an Environment Texture's image with its
    strength and its Mapping node's Z rotation (degrees)."""
    world = scene.world
    if world is None:
        # Cycles (and EEVEE) render a scene without a world black, not Blender's default grey.
        return {"color": [0.0, 0.0, 0.0], "strength": 1.0}
    if not world.use_nodes or world.node_tree is None:
        return {"color": [float(c) for c in world.color], "strength": 1.0}
    tree = world.node_tree
    out_node = _active_output(tree, "OUTPUT_WORLD")
    if out_node is None:
        return {"color": [0.0, 0.0, 0.0], "strength": 1.0}
    if _linked_node(out_node.inputs["Volume"]) is not None:
        warnings.add("the world's volume is not carried (dofray renders no volumes)")
    bg = _linked_node(out_node.inputs["Surface"])
    if bg is None:
        return {"color": [0.0, 0.0, 0.0], "strength": 1.0}
    if bg.type not in ("BACKGROUND", "EMISSION"):
        warnings.add(f"world: a '{bg.bl_label}' node is not carried (only Background or "
                     "Emission with a colour or an Environment Texture); the world is black")
        return {"color": [0.0, 0.0, 0.0], "strength": 1.0}
    strength_in = bg.inputs["Strength"]
    if strength_in.is_linked:
        warnings.add("world: a linked Strength is not carried; its own value is used")
    strength = max(float(strength_in.default_value), 0.0)
    color_in = bg.inputs["Color"]
    src = _linked_node(color_in)
    if src is None:
        return {"color": [max(float(c), 0.0) for c in color_in.default_value[:3]],
                "strength": strength}
    if src.type != "TEX_ENVIRONMENT" or src.image is None:
        warnings.add(f"world: a '{src.bl_label}' node feeding the colour is not carried (only "
                     "an Environment Texture); its unlinked colour is used")
        return {"color": [max(float(c), 0.0) for c in color_in.default_value[:3]],
                "strength": strength}
    if src.projection != "EQUIRECTANGULAR":
        warnings.add("world: only an equirectangular Environment Texture is carried "
                     f"(not {src.projection.lower().replace('_', ' ')})")
    path = _image_file(src.image, folder, warnings)
    ext = os.path.splitext(path)[1].lower()
    if ext not in (".hdr", ".exr", ".png", ".jpg", ".jpeg"):
        raise ExportError(f"the world's image {path} is not .hdr, .exr, .png or .jpg "
                          "(what dofray reads)")
    if copy_images:
        dest = os.path.join(folder, os.path.basename(path))
        if os.path.abspath(dest) != os.path.abspath(path):
            shutil.copyfile(path, dest)
        path = os.path.basename(dest)
    out = {"map": path, "strength": strength}
    rot = _mapping_rotation_deg(src, warnings)
    if rot:
        out["rotation"] = rot
    return out


def _mapping_rotation_deg(env, warnings):
    """The Z rotation (degrees) of a Mapping node feeding the Environment Texture's vector."""
    m = _linked_node(env.inputs["Vector"])
    if m is None:
        return 0.0
    if m.type == "TEX_COORD":
        return 0.0
    if m.type != "MAPPING":
        warnings.add(f"world: a '{m.bl_label}' node feeding the map's vector is not carried")
        return 0.0
    rot = m.inputs["Rotation"]
    loc = m.inputs["Location"] if "Location" in m.inputs else None
    scale = m.inputs["Scale"] if "Scale" in m.inputs else None
    if rot.is_linked:
        warnings.add("world: a linked Mapping rotation is not carried")
        return 0.0
    r = rot.default_value
    if abs(r[0]) > 1e-6 or abs(r[1]) > 1e-6:
        warnings.add("world: the Mapping node's X and Y rotations are not carried (Z only)")
    if scale is not None and any(abs(s - 1.0) > 1e-6 for s in scale.default_value):
        warnings.add("world: the Mapping node's scale is not carried")
    z = math.degrees(r[2])
    # A Texture-type Mapping applies the inverse transform.
    if m.vector_type == "TEXTURE":
        z = -z
    elif m.vector_type not in ("POINT", "VECTOR"):
        warnings.add(f"world: a Mapping node of type {m.vector_type.lower()} is not carried")
        return 0.0
    return z


# ---------------------------------------------------------------------------------------------
# Lights


def area_light(obj, matrix, warnings):
    """A Blender area light -> a dofray [[lights]] entry (glTF axes, sizes scaled by the
    object's scale as Cycles scales them, power in Blender's watts)."""
    d = obj.data
    m3 = matrix.to_3x3()
    ax, ay = m3.col[0], m3.col[1]
    sx, sy = ax.length, ay.length
    normal = (m3 @ Vector((0.0, 0.0, -1.0))).normalized()
    rec = {
        "type": "rect" if d.shape in ("SQUARE", "RECTANGLE") else "disk",
        "position": blender_to_gltf(matrix.translation),
        "direction": blender_to_gltf(normal),
        "power": float(d.energy),
        "color": [float(c) for c in d.color],
        "visible_to_camera": bool(getattr(obj, "visible_camera", True)),
    }
    shape = d.shape
    if shape in ("SQUARE", "RECTANGLE"):
        w = d.size * sx
        h = (d.size if shape == "SQUARE" else d.size_y) * sy
        if abs(w - h) <= 1e-9 * max(w, h):
            rec["size"] = float(w)
        else:
            rec["size"] = [float(w), float(h)]
            rec["up"] = blender_to_gltf(ay.normalized())
    else:
        w = d.size * sx
        h = (d.size if shape == "DISK" else d.size_y) * sy
        if abs(w - h) > 1e-6 * max(w, h):
            warnings.add(f"light '{obj.name}': an ellipse is carried as a disk of the same area "
                         "(dofray's disks are round)")
        rec["size"] = float(math.sqrt(w * h))
    if min(w, h) <= 0.0:
        warnings.add(f"light '{obj.name}': zero size, skipped")
        return None
    spread = getattr(d, "spread", math.pi)
    if spread < math.pi - 1e-4:
        warnings.add(f"light '{obj.name}': spread {math.degrees(spread):.0f} degrees is not "
                     "carried (dofray's area lights spread 180 degrees)")
    return rec


def sphere_light(obj, matrix):
    """A Blender point light with a radius -> a dofray sphere light: the same power (Blender's
    watts, radiance P / (4 pi^2 r^2) as Cycles' sphere light), soft shadows and a disc in
    glossy reflections. Cycles' default Soft Falloff makes it a disc facing each shading point
    instead of a sphere, which lights a point at distance d by d^2 / (d^2 + r^2) as much: 1%
    less at ten radii. Blender does not scale a point light's radius with its object."""
    d = obj.data
    return {
        "type": "sphere",
        "position": blender_to_gltf(matrix.translation),
        "radius": float(d.shadow_soft_size),
        "power": float(d.energy),
        "color": [float(c) for c in d.color],
        "visible_to_camera": bool(getattr(obj, "visible_camera", True)),
    }


def spot_or_sun(obj, matrix):
    """A Blender spot light with a radius or sun with an angle -> a dofray [[lights]] entry
    that keeps it: the spot's disc (`radius`; as Cycles' spot with its default Soft Falloff)
    or the sun's angular size (`angle`, degrees), which glTF cannot carry. Blender's units:
    a spot of P watts has intensity P / (4 pi) W/sr; a sun's strength is its irradiance."""
    d = obj.data
    axis = (matrix.to_3x3() @ Vector((0.0, 0.0, -1.0))).normalized()
    color = [float(c) for c in d.color]
    if d.type == "SUN":
        return {"type": "directional", "direction": blender_to_gltf(axis),
                "irradiance": [float(d.energy) * c for c in color],
                "angle": math.degrees(d.angle)}
    outer = math.degrees(d.spot_size) / 2.0  # Blender's spot size is at most 180 degrees
    return {"type": "spot", "position": blender_to_gltf(matrix.translation),
            "direction": blender_to_gltf(axis),
            "intensity": [float(d.energy) / (4.0 * math.pi) * c for c in color],
            "outer_angle": outer, "inner_angle": outer * (1.0 - float(d.spot_blend)),
            "radius": float(d.shadow_soft_size)}


def in_scene_file(obj):
    """Whether the add-on writes light `obj` into the scene file instead of leaving it to the
    glTF (which has points and parallel suns only): point and spot lights with a radius, and
    suns with an angle."""
    if obj.type != "LIGHT":
        return False
    d = obj.data
    if d.type in ("POINT", "SPOT"):
        return d.shadow_soft_size > 0.0
    return d.type == "SUN" and d.angle > 0.0


def light_common_warnings(obj, warnings):
    d = obj.data
    if d.use_nodes:
        warnings.add(f"light '{obj.name}': its node tree is not carried (its colour and power "
                     "are)")
    if not getattr(d, "use_shadow", True):
        warnings.add(f"light '{obj.name}': 'cast shadow' off is not carried")
    cyc = getattr(d, "cycles", None)
    if cyc is not None and getattr(cyc, "is_portal", False):
        warnings.add(f"light '{obj.name}': a portal is not carried (skipped)")
        return False
    if abs(getattr(d, "exposure", 0.0)) > 1e-6:
        warnings.add(f"light '{obj.name}': exposure is not carried")
    return True


# ---------------------------------------------------------------------------------------------
# What the glTF cannot carry: said as warnings


UNSUPPORTED_OBJECT_TYPES = {
    "VOLUME": "volumes are not carried",
    "CURVES": "hair curves are not carried",
    "POINTCLOUD": "point clouds are not carried",
    "GPENCIL": "grease pencil is not carried",
    "GREASEPENCIL": "grease pencil is not carried",
    "LIGHT_PROBE": None,
    "SPEAKER": None,
}

PRINCIPLED_UNCARRIED = (
    ("Subsurface Weight", "subsurface scattering"),
    ("Coat Weight", "coat"),
    ("Sheen Weight", "sheen"),
    ("Anisotropic", "anisotropy"),
    ("Thin Film Thickness", "thin film"),
)


def material_warnings(mat, warnings):
    if mat is None or not mat.use_nodes or mat.node_tree is None:
        return
    out = _active_output(mat.node_tree, "OUTPUT_MATERIAL")
    if out is None:
        return
    if _linked_node(out.inputs["Volume"]) is not None:
        warnings.add(f"material '{mat.name}': its volume is not carried (dofray renders no "
                     "volumes)")
    if "Displacement" in out.inputs and _linked_node(out.inputs["Displacement"]) is not None:
        warnings.add(f"material '{mat.name}': displacement is not carried")
    surf = _linked_node(out.inputs["Surface"])
    if surf is None:
        return
    if surf.type == "BSDF_PRINCIPLED":
        for name, what in PRINCIPLED_UNCARRIED:
            s = surf.inputs.get(name)
            if s is not None and (s.is_linked or float(s.default_value) > 0.0):
                warnings.add(f"material '{mat.name}': {what} is not carried (glTF / dofray "
                             "material: base colour, metallic, roughness, transmission, IOR, "
                             "emission, alpha, normal map)")
        level, tint = surf.inputs.get("Specular IOR Level"), surf.inputs.get("Specular Tint")
        if (level is not None and (level.is_linked or abs(level.default_value - 0.5) > 1e-6)) \
                or (tint is not None and (tint.is_linked or any(
                    abs(c - 1.0) > 1e-6 for c in tint.default_value[:3]))):
            # Blender's exporter writes them as KHR_materials_specular, which dofray ignores.
            warnings.add(f"material '{mat.name}': Specular IOR Level and Specular Tint are not "
                         "carried (dofray's specular follows the IOR alone)")
        for name in ("Base Color", "Roughness", "Metallic", "Emission Color", "Alpha"):
            src = _linked_node(surf.inputs[name]) if name in surf.inputs else None
            if src is not None and src.type not in ("TEX_IMAGE", "SEPARATE_COLOR",
                                                     "SEPRGB", "SEPARATE_RGB"):
                warnings.add(f"material '{mat.name}': a '{src.bl_label}' node feeding "
                             f"{name} is not carried (image textures are)")
    elif surf.type not in ("EMISSION", "MIX_SHADER", "BSDF_TRANSPARENT"):
        warnings.add(f"material '{mat.name}': a '{surf.bl_label}' shader is not carried "
                     "(Blender's glTF exporter writes Principled BSDF and Emission materials)")


def object_warnings(obj, warnings):
    msg = UNSUPPORTED_OBJECT_TYPES.get(obj.type, "")
    if msg:
        warnings.add(f"object '{obj.name}': {msg}")
    for ps in getattr(obj, "particle_systems", []):
        if ps.settings.type == "HAIR":
            warnings.add(f"object '{obj.name}': hair particles are not carried")
    for mod in getattr(obj, "modifiers", []):
        if mod.type in ("FLUID", "VOLUME_TO_MESH", "MESH_TO_VOLUME") and mod.show_render:
            warnings.add(f"object '{obj.name}': the {mod.type.lower()} modifier's volume is "
                         "not carried")
    if obj.type == "MESH":
        for slot in obj.material_slots:
            material_warnings(slot.material, warnings)


# ---------------------------------------------------------------------------------------------
# Animation


def _chain_is_animated(objs):
    seen = set()
    stack = [o for o in objs if o is not None]
    while stack:
        o = stack.pop()
        if o is None or o.as_pointer() in seen:
            continue
        seen.add(o.as_pointer())
        ad = getattr(o, "animation_data", None)
        if ad is not None and (ad.action is not None or len(ad.drivers) or len(ad.nla_tracks)):
            return True
        if getattr(o, "constraints", None) and len(o.constraints):
            return True
        data = getattr(o, "data", None)
        if isinstance(data, bpy.types.Camera):
            dad = data.animation_data
            if dad is not None and (dad.action is not None or len(dad.drivers)
                                    or len(dad.nla_tracks)):
                return True
        stack.append(getattr(o, "parent", None))
    return False


def animation_table(scene, cam_obj, camera, warnings):
    """[animation]: per-frame keys of what changes over the frame range: the focus distance,
    the f-number and the focal length (with depth of field on). The camera's own motion is not
    carried (the glTF holds one view; see docs/blender.md)."""
    start, end = scene.frame_start, scene.frame_end
    if end <= start:
        return None
    fps = scene.render.fps / scene.render.fps_base
    table = {"fps": float(fps), "frame_start": int(start), "frame_end": int(end),
             "interpolation": "linear"}
    cam = cam_obj.data
    targets = [cam_obj, cam.dof.focus_object]
    if not _chain_is_animated(targets):
        return table
    if end - start + 1 > MAX_ANIMATION_FRAMES:
        warnings.add(f"animation: more than {MAX_ANIMATION_FRAMES} frames; the focus is not "
                     "animated")
        return table
    frame0, sub0 = scene.frame_current, scene.frame_subframe
    samples = []
    try:
        for f in range(start, end + 1):
            scene.frame_set(f)
            samples.append({
                "frame": f,
                "focus_distance": focus_distance(cam_obj),
                "f_number": anamorphic_lens(cam.dof.aperture_fstop, cam.dof.aperture_ratio)[0],
                "focal_length_mm": float(cam.lens),
                "matrix": [tuple(r) for r in cam_obj.matrix_world],
                "use_dof": bool(cam.dof.use_dof),
            })
    finally:
        scene.frame_set(frame0, subframe=sub0)
    keys = []

    def varies(name, rel=1e-6):
        vals = [s[name] for s in samples]
        return any(abs(v - vals[0]) > rel * max(abs(vals[0]), 1e-12) for v in vals)

    tracks = []
    if camera:  # a lens
        tracks = [n for n in ("focus_distance", "f_number", "focal_length_mm") if varies(n)]
    elif varies("focal_length_mm"):
        warnings.add("animation: a zoom without depth of field is not carried (the glTF "
                     "camera's field of view is fixed)")
    if any(s["use_dof"] != samples[0]["use_dof"] for s in samples):
        warnings.add("animation: switching depth of field on and off is not carried")
    m0 = samples[0]["matrix"]
    if any(any(abs(a - b) > 1e-6 for ra, rb in zip(s["matrix"], m0) for a, b in zip(ra, rb))
           for s in samples):
        warnings.add(f"animation: camera '{cam_obj.name}' moves; its motion is not carried by "
                     "the scene file (the glTF holds its view at the exported frame). The "
                     "dofray render engine renders every frame from its own view")
    if tracks:
        for s in samples:
            keys.append({"frame": s["frame"], **{n: s[n] for n in tracks}})
        table["key"] = keys
    return table


# ---------------------------------------------------------------------------------------------
# TOML


def short_float(v):
    """The fewest digits that read back as the same 32-bit float as `v`: dofray reads scene
    files in single precision, and Blender stores its values as 32-bit floats (0.2 is
    0.20000000298023224 as a double; written 0.2 here)."""
    try:
        f32 = struct.unpack("<f", struct.pack("<f", v))[0]
    except (OverflowError, struct.error):
        return repr(v)
    for digits in range(1, 10):
        text = f"{v:.{digits}g}"
        if struct.unpack("<f", struct.pack("<f", float(text)))[0] == f32:
            return repr(float(text))
    return repr(v)


def toml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        r = short_float(v)
        return r if ("." in r or "e" in r or "n" in r) else r + ".0"
    if isinstance(v, str):
        return json.dumps(v)  # a TOML basic string (\uXXXX escapes are TOML too)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    raise TypeError(f"no TOML for {v!r}")


def _table_lines(header, table):
    lines = [header]
    for k, v in table.items():
        lines.append(f"{k} = {toml_value(v)}")
    lines.append("")
    return lines


def to_toml(data, comment=""):
    """The scene file's text for `data` (the dict `collect` returns)."""
    lines = []
    if comment:
        lines += ["# " + line for line in comment.splitlines()]
    lines.append(f"name = {toml_value(data['name'])}")
    if not data["lights"]:
        lines.append("lights = []  # the glTF's own lights only: no default key light")
    lines.append("")
    lines += _table_lines("[image]", data["image"])
    lines += _table_lines("[render]", data["render"])
    if data.get("view"):
        lines += _table_lines("[view]", data["view"])
    if data["camera"]:
        lines += _table_lines("[camera]", data["camera"])
    lines += _table_lines("[world]", data["world"])
    for light in data["lights"]:
        lines += _table_lines("[[lights]]", light)
    for obj in data["objects"]:
        lines += _table_lines("[[objects]]", obj)
    anim = data.get("animation")
    if anim:
        keys = anim.get("key", [])
        lines += _table_lines("[animation]", {k: v for k, v in anim.items() if k != "key"})
        for key in keys:
            lines += _table_lines("[[animation.key]]", key)
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# glTF


def export_glb(context, glb_path, visible_only=True, renderable_only=False):
    """Blender's own glTF exporter: GLB, cameras and lights (Lighting Mode Standard), +Y up,
    modifiers applied, custom properties as extras, the active scene only, no animation (the
    scene at the current frame)."""
    result = bpy.ops.export_scene.gltf(
        filepath=glb_path,
        export_format="GLB",
        export_cameras=True,
        export_lights=True,
        export_import_convert_lighting_mode="SPEC",
        export_yup=True,
        export_apply=True,
        export_extras=True,
        export_materials="EXPORT",
        use_active_scene=True,
        use_visible=visible_only,
        use_renderable=renderable_only,
        use_selection=False,
        export_animations=False,
        export_current_frame=True,
    )
    if "FINISHED" not in result:
        raise ExportError(f"Blender's glTF exporter did not finish ({result})")


def read_glb(path):
    with open(path, "rb") as f:
        data = f.read()
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    if magic != b"glTF":
        raise ExportError(f"{path} is not a GLB file")
    jlen, jtype = struct.unpack_from("<I4s", data, 12)
    doc = json.loads(data[20:20 + jlen].decode("utf-8"))
    rest = data[20 + jlen:]
    return doc, rest


def write_glb(path, doc, rest):
    js = json.dumps(doc, separators=(",", ":")).encode("utf-8")
    js += b" " * (-len(js) % 4)
    total = 12 + 8 + len(js) + len(rest)
    with open(path, "wb") as f:
        f.write(struct.pack("<4sII", b"glTF", 2, total))
        f.write(struct.pack("<I4s", len(js), b"JSON"))
        f.write(js)
        f.write(rest)


def keep_only_camera(doc, cam_obj):
    """dofray takes the glTF's first perspective camera; Blender's exporter writes every
    camera. Keep the active one only (other camera nodes stay, as empty nodes). Returns
    whether `doc` changed."""
    nodes = doc.get("nodes", [])
    cams = [n for n in nodes if "camera" in n]
    mine = [n for n in cams if n.get("name") == cam_obj.name]
    if not mine:
        raise ExportError(f"the active camera '{cam_obj.name}' is not in the glTF export (is "
                          "it hidden? the export takes visible objects only)")
    if len(cams) <= 1:
        return False
    for n in cams:
        if n is not mine[0]:
            del n["camera"]
    return True


GLTF_IOR = 1.5  # glTF's IOR without KHR_materials_ior (and Blender 4's default)


def principled_ior(mat):
    """The IOR of a material's Principled BSDF (the one its active output's Surface shows),
    or None: no such BSDF, a linked IOR, or a full metal (whose IOR glTF does not use)."""
    if mat is None or not mat.use_nodes or mat.node_tree is None:
        return None
    out = _active_output(mat.node_tree, "OUTPUT_MATERIAL")
    surf = _linked_node(out.inputs["Surface"]) if out is not None else None
    if surf is None or surf.type != "BSDF_PRINCIPLED":
        return None
    ior, metallic = surf.inputs.get("IOR"), surf.inputs.get("Metallic")
    if ior is None or ior.is_linked:
        return None
    if metallic is not None and not metallic.is_linked and metallic.default_value >= 1.0:
        return None
    return float(ior.default_value)


def carry_ior(doc):
    """Blender's glTF exporter writes KHR_materials_ior only with transmission, volume or
    specular (`export_ior` in io_scene_gltf2), so an opaque dielectric's IOR is lost and
    dofray (as glTF) takes 1.5: a glossy plastic of IOR 1.45 reflects 19% more at normal
    incidence than in Cycles (F0 0.040 against 0.034). Adds the extension to every material
    whose Blender Principled BSDF has another IOR. Returns whether `doc` changed."""
    changed = False
    for m in doc.get("materials", []):
        ext = m.get("extensions", {})
        if "KHR_materials_ior" in ext:
            continue
        ior = principled_ior(bpy.data.materials.get(m.get("name", "")))
        if ior is None or abs(ior - GLTF_IOR) < 1e-6:
            continue
        m.setdefault("extensions", {})["KHR_materials_ior"] = {"ior": ior}
        changed = True
    if changed:
        used = doc.setdefault("extensionsUsed", [])
        if "KHR_materials_ior" not in used:
            used.append("KHR_materials_ior")
    return changed


def drop_file_lights(doc):
    """Lights the scene file carries (`in_scene_file`: point and spot lights with a radius,
    suns with an angle) lose their glTF light, so none is there twice. Returns whether `doc`
    changed."""
    changed = False
    for n in doc.get("nodes", []):
        ext = n.get("extensions", {})
        obj = bpy.data.objects.get(n.get("name", ""))
        if "KHR_lights_punctual" in ext and obj is not None and in_scene_file(obj):
            del ext["KHR_lights_punctual"]
            if not ext:
                del n["extensions"]
            changed = True
    return changed


def patch_glb(glb_path, cam_obj):
    """What the add-on changes in the exporter's .glb: the active camera only
    (keep_only_camera), the IOR of opaque dielectrics (carry_ior) and none of the lights the
    scene file carries (drop_file_lights). Rewritten only when something changed. Returns the glTF
    document."""
    doc, rest = read_glb(glb_path)
    changed = keep_only_camera(doc, cam_obj)
    changed = carry_ior(doc) or changed
    changed = drop_file_lights(doc) or changed
    if changed:
        write_glb(glb_path, doc, rest)
    return doc


# ---------------------------------------------------------------------------------------------
# The export


def _include(obj, view_layer, visible_only, renderable_only):
    if visible_only and not obj.visible_get(view_layer=view_layer):
        return False
    if renderable_only and obj.hide_render:
        return False
    return True


def collect(context, toml_path, visible_only=True, renderable_only=False, animation=True,
            copy_images=False, settings=None, camera_override=None):
    """The dofray scene for `context`'s scene as a dict (the tables of the scene file) and the
    warnings. Writes nothing but packed world images."""
    scene = context.scene
    view_layer = context.view_layer
    depsgraph = context.evaluated_depsgraph_get()
    if settings is None:
        settings = getattr(scene, "dofray", None)
    warnings = Warnings()
    folder = os.path.dirname(os.path.abspath(toml_path))
    stem = os.path.splitext(os.path.basename(toml_path))[0]
    cam_obj = camera_override or scene.camera
    check_camera(cam_obj)
    width, height = render_size(scene.render)
    data = {"name": scene.name, "image": {"width": width, "height": height}}
    data["render"] = render_table(scene, settings, warnings)
    data["view"] = view_table(scene, warnings)
    data["camera"] = camera_table(scene, cam_obj, width, height, warnings)
    data["world"] = world_table(scene, folder, copy_images, warnings)
    lights = []
    seen = set()
    for inst in depsgraph.object_instances:
        obj = inst.instance_object if inst.is_instance else inst.object
        orig = obj.original
        parent = inst.parent.original if inst.is_instance and inst.parent else orig
        if not _include(parent, view_layer, visible_only, renderable_only):
            continue
        if not inst.is_instance:
            key = orig.name
            if key in seen:
                continue
            seen.add(key)
            object_warnings(orig, warnings)
        if orig.type != "LIGHT":
            continue
        if not light_common_warnings(orig, warnings):
            continue
        if inst.is_instance and (orig.data.type == "AREA" or in_scene_file(orig)):
            warnings.add(f"light '{orig.name}': instanced lights the scene file carries are "
                         "exported where they are instanced")
        matrix = inst.matrix_world.copy()
        if orig.data.type == "AREA":
            rec = area_light(orig, matrix, warnings)
            if rec is not None:
                lights.append(rec)
        elif in_scene_file(orig):
            point = orig.data.type == "POINT"
            lights.append(sphere_light(orig, matrix) if point else spot_or_sun(orig, matrix))
    data["lights"] = lights
    data["objects"] = [{"type": "mesh", "file": stem + ".glb", "camera": True}]
    data["animation"] = animation_table(scene, cam_obj, data["camera"], warnings) \
        if animation else None
    if data["animation"] is None:
        data.pop("animation")
    return data, warnings


def export_scene(context, toml_path, visible_only=True, renderable_only=False, animation=True,
                 copy_images=False, settings=None, camera_override=None):
    """Exports the context's scene for dofray: NAME.glb (Blender's glTF exporter) and NAME.toml
    next to it. Returns {"toml": path, "glb": path, "data": the scene file's tables,
    "warnings": [what was not carried]}. Raises ExportError when the scene cannot be
    exported."""
    toml_path = os.path.abspath(bpy.path.abspath(toml_path))
    if not toml_path.lower().endswith(".toml"):
        toml_path += ".toml"
    os.makedirs(os.path.dirname(toml_path), exist_ok=True)
    glb_path = os.path.splitext(toml_path)[0] + ".glb"
    data, warnings = collect(context, toml_path, visible_only, renderable_only, animation,
                             copy_images, settings, camera_override)
    cam_obj = camera_override or context.scene.camera
    export_glb(context, glb_path, visible_only, renderable_only)
    patch_glb(glb_path, cam_obj)
    comment = (f"dofray scene exported from Blender {bpy.app.version_string} by the dofray "
               f"add-on.\nMeshes, materials, the camera's view and point and spot lights without a "
               f"radius and suns without an angle: "
               f"{os.path.basename(glb_path)}.")
    if warnings:
        comment += "\nNot carried:\n" + "\n".join("  " + w for w in warnings)
    with open(toml_path, "w", encoding="utf-8") as f:
        f.write(to_toml(data, comment))
    return {"toml": toml_path, "glb": glb_path, "data": data, "warnings": list(warnings)}
