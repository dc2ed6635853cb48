"""Add-on preferences: where the dofray binary is, and how the render engine runs it."""

import os
import shutil

import bpy
from bpy.props import BoolProperty, IntProperty, StringProperty

ADDON_ID = __package__


class DofrayPreferences(bpy.types.AddonPreferences):
    bl_idname = ADDON_ID

    binary: StringProperty(
        name="dofray Binary",
        description="The dofray executable (empty: `dofray` on PATH). The environment variable "
                    "DOFRAY_BIN overrides it",
        subtype="FILE_PATH",
        default="",
    )
    threads: IntProperty(
        name="Threads",
        description="Render threads for dofray (0: all cores)",
        default=0, min=0, max=1024,
    )
    keep_files: BoolProperty(
        name="Keep Render Files",
        description="Keep the temporary scene export and EXR of each render (their folder is "
                    "printed to the console), to debug or to re-run dofray by hand",
        default=False,
    )

    def draw(self, context):
        layout = self.layout
        layout.prop(self, "binary")
        found = find_binary(self)
        if found:
            layout.label(text=f"Using {found}", icon="CHECKMARK")
        else:
            layout.label(text="dofray not found: set its path or put it on PATH", icon="ERROR")
        layout.prop(self, "threads")
        layout.prop(self, "keep_files")


def preferences(context=None):
    """The add-on's preferences, or None when the add-on was registered by hand (tests)."""
    context = context or bpy.context
    addon = context.preferences.addons.get(ADDON_ID)
    return addon.preferences if addon is not None else None


def find_binary(prefs=None):
    """DOFRAY_BIN, else the preferences' path, else `dofray` on PATH; None if none exists."""
    env = os.environ.get("DOFRAY_BIN")
    if env:
        return env if os.path.isfile(env) else shutil.which(env)
    if prefs is not None and prefs.binary:
        path = bpy.path.abspath(prefs.binary)
        return path if os.path.isfile(path) else None
    return shutil.which("dofray")


classes = (DofrayPreferences,)


def register():
    for c in classes:
        bpy.utils.register_class(c)


def unregister():
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
