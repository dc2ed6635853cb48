"""dofray for Blender: File > Export > dofray scene (.toml), and a render engine that renders
with the dofray binary (Render Properties > Render Engine > dofray).

See docs/blender.md in the dofray repository."""

from . import engine, export, operators, prefs, props, ui

_modules = (props, prefs, operators, engine, ui)


def export_scene(context, toml_path, **options):
    """Exports `context`'s scene to TOML_PATH and NAME.glb next to it; see export.export_scene."""
    return export.export_scene(context, toml_path, **options)


def register():
    for m in _modules:
        m.register()


def unregister():
    for m in reversed(_modules):
        m.unregister()
