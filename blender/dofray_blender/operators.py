"""File > Export > dofray scene (.toml)."""

import bpy
from bpy.props import BoolProperty, StringProperty
from bpy_extras.io_utils import ExportHelper

from . import export


class EXPORT_SCENE_OT_dofray(bpy.types.Operator, ExportHelper):
    """Export the scene for dofray: NAME.glb (Blender's glTF exporter) and NAME.toml (image
    size, render settings, depth of field, world, area lights, animated focus)"""

    bl_idname = "export_scene.dofray"
    bl_label = "Export dofray Scene"
    bl_options = {"PRESET"}

    filename_ext = ".toml"
    filter_glob: StringProperty(default="*.toml", options={"HIDDEN"})

    visible_only: BoolProperty(
        name="Visible Objects Only",
        description="Export only the objects visible in the viewport (else every object of "
                    "the scene)",
        default=True,
    )
    renderable_only: BoolProperty(
        name="Renderable Objects Only",
        description="Leave out objects disabled for rendering",
        default=False,
    )
    animation: BoolProperty(
        name="Animation",
        description="Write the frame range and, when the focus, f-stop or focal length is "
                    "animated, per-frame keys of it ([animation])",
        default=True,
    )
    copy_images: BoolProperty(
        name="Copy World Image",
        description="Copy the world's environment image next to the scene file (else the "
                    "file refers to it by its absolute path)",
        default=False,
    )

    def execute(self, context):
        try:
            info = export.export_scene(context, self.filepath, visible_only=self.visible_only,
                                       renderable_only=self.renderable_only,
                                       animation=self.animation, copy_images=self.copy_images)
        except export.ExportError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        for w in info["warnings"]:
            self.report({"WARNING"}, w)
        self.report({"INFO"}, f"Exported {info['toml']} and {info['glb']}"
                              + (f" ({len(info['warnings'])} warnings)" if info["warnings"]
                                 else ""))
        return {"FINISHED"}


def menu_export(self, context):
    self.layout.operator(EXPORT_SCENE_OT_dofray.bl_idname, text="dofray scene (.toml)")


classes = (EXPORT_SCENE_OT_dofray,)


def register():
    for c in classes:
        bpy.utils.register_class(c)
    bpy.types.TOPBAR_MT_file_export.append(menu_export)


def unregister():
    bpy.types.TOPBAR_MT_file_export.remove(menu_export)
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
