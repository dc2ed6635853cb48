"""dofray's settings stored on the scene (`scene.dofray`), shown in the render engine's panel
and written into exported scene files."""

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty


class DofraySceneSettings(bpy.types.PropertyGroup):
    spp: IntProperty(
        name="Samples",
        description="Samples of pixel x lens per sample site that blur reaches (dofray's "
                    "--spp; 16 fill one ray packet)",
        default=16, min=1, max=65536, soft_max=1024,
    )
    aa: IntProperty(
        name="In-Focus Samples",
        description="Samples per in-focus sample site, and per pixel in pinhole mode "
                    "(dofray's --aa, anti-aliasing). 0: dofray's default, the Samples above "
                    "with the path tracer (its light is as noisy in focus as in the blur), 4 "
                    "with the direct integrator",
        default=0, min=0, max=65536, soft_max=256,
    )
    use_cycles_samples: BoolProperty(
        name="Samples from Cycles",
        description="Use Cycles' render samples (Sampling > Render > Max Samples, clamped to "
                    "1024) instead of dofray's own",
        default=False,
    )
    mode: EnumProperty(
        name="Mode",
        description="How dofray places its lens samples (a command-line flag: not stored in "
                    "exported scene files)",
        items=[
            ("ADAPTIVE", "Adaptive", "The seed's sparse sample sites spaced by the circle of "
             "confusion, the pixels between them interpolated (fast)"),
            ("DENSE", "Dense", "Lens samples at every pixel (Cook's distributed ray tracing: "
             "the reference)"),
            ("PINHOLE", "Pinhole", "No depth of field: sampled through the lens centre"),
        ],
        default="ADAPTIVE",
    )
    integrator: EnumProperty(
        name="Integrator",
        description="How light is carried",
        items=[
            ("PATH", "Path", "Path tracing with next-event estimation and MIS: every light "
             "kind, indirect light, glass (agrees with Cycles)"),
            ("DIRECT", "Direct", "The seed's quick shading: direct light from point, spot and "
             "sun lights with hard shadows, ambient, mirrors"),
        ],
        default="PATH",
    )
    tolerance: FloatProperty(
        name="Tolerance",
        description="Adaptive mode: the largest error accepted, in 8-bit sRGB code values "
                    "(0: dofray's default, 4 / sqrt(samples))",
        default=0.0, min=0.0, soft_max=8.0,
    )
    seed: IntProperty(
        name="Seed", description="Random seed of the samples (dofray's --seed)",
        default=0, min=0,
    )


classes = (DofraySceneSettings,)


def register():
    for c in classes:
        bpy.utils.register_class(c)
    bpy.types.Scene.dofray = bpy.props.PointerProperty(type=DofraySceneSettings)


def unregister():
    del bpy.types.Scene.dofray
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
