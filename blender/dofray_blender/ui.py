"""Render Properties panels for the dofray engine."""

import bpy

from . import prefs


class DofrayPanel:
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"
    COMPAT_ENGINES = {"DOFRAY"}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES


class RENDER_PT_dofray_sampling(DofrayPanel, bpy.types.Panel):
    bl_label = "dofray"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        s = context.scene.dofray
        col = layout.column()
        col.prop(s, "mode")
        col.prop(s, "integrator")
        sub = col.column()
        sub.active = not s.use_cycles_samples
        sub.prop(s, "spp")
        col.prop(s, "use_cycles_samples")
        col.prop(s, "aa")
        col.prop(s, "tolerance")
        col.prop(s, "seed")
        if not prefs.find_binary(prefs.preferences(context)):
            layout.label(text="dofray binary not found (add-on preferences)", icon="ERROR")


class RENDER_PT_dofray_light_paths(DofrayPanel, bpy.types.Panel):
    bl_label = "Light Paths"
    bl_parent_id = "RENDER_PT_dofray_sampling"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        c = getattr(context.scene, "cycles", None)
        if c is None:
            layout.label(text="Cycles is disabled: dofray's default bounces")
            return
        col = layout.column(align=True)
        col.prop(c, "max_bounces", text="Total")
        col.prop(c, "diffuse_bounces", text="Diffuse")
        col.prop(c, "glossy_bounces", text="Glossy")
        col.prop(c, "transmission_bounces", text="Transmission")
        layout.prop(c, "sample_clamp_indirect", text="Clamp Indirect")
        layout.prop(c, "blur_glossy", text="Filter Glossy")


class RENDER_PT_dofray_film(DofrayPanel, bpy.types.Panel):
    bl_label = "Film"
    bl_parent_id = "RENDER_PT_dofray_sampling"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        layout.prop(context.scene.render, "film_transparent", text="Transparent")
        c = getattr(context.scene, "cycles", None)
        if c is not None:
            layout.prop(c, "pixel_filter_type", text="Pixel Filter")
            layout.prop(c, "filter_width", text="Width")


classes = (RENDER_PT_dofray_sampling, RENDER_PT_dofray_light_paths, RENDER_PT_dofray_film)


def register():
    for c in classes:
        bpy.utils.register_class(c)


def unregister():
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
