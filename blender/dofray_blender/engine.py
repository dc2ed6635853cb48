"""The dofray render engine: exports the frame with the add-on's exporter into a temporary
folder, runs `dofray render` on it, and loads dofray's multilayer EXR (Combined, Depth, CoC,
Interval, Samples) into Blender's render result."""

import json
import os
import shutil
import subprocess
import tempfile
import threading
import time

import bpy

from . import exr, export, prefs

# dofray's EXR passes (docs/outputs.md): name, channels, channel ids, type.
PASSES = (
    ("Combined", 4, "RGBA", "COLOR"),
    ("Depth", 1, "Z", "VALUE"),
    ("CoC", 1, "X", "VALUE"),
    ("Interval", 1, "X", "VALUE"),
    ("Samples", 1, "X", "VALUE"),
)
DOFRAY_LAYER = "ViewLayer"  # the layer name in dofray's EXR channels
POLL_SECONDS = 0.1
MAIN_THREAD_TIMEOUT = 3600.0


def on_main_thread(fn):
    """Runs `fn` on Blender's main thread and returns its result. Operators (the glTF
    exporter) must not run in the render job's thread of an interactive render; there, `fn`
    is handed to the main thread by a timer and this thread waits. In background renders
    (`blender -b`, the bpy module) render() already runs on the main thread."""
    if threading.current_thread() is threading.main_thread():
        return fn()
    done = threading.Event()
    box = {}

    def call():
        try:
            box["value"] = fn()
        except BaseException as e:  # handed back to the render thread
            box["error"] = e
        done.set()
        return None

    bpy.app.timers.register(call, first_interval=0.0)
    t0 = time.monotonic()
    while not done.wait(POLL_SECONDS):
        if time.monotonic() - t0 > MAIN_THREAD_TIMEOUT:
            raise RuntimeError("timed out waiting for Blender's main thread to export")
    if "error" in box:
        raise box["error"]
    return box["value"]


def dofray_command(binary, toml, out_exr, settings, threads, region=None):
    cmd = [binary, "render", toml, "-o", out_exr, "--json", "--quiet"]
    if region is not None:
        cmd += ["--region", ",".join(str(v) for v in region)]
    if settings is not None:
        cmd += ["--mode", settings.mode.lower(), "--seed", str(settings.seed)]
    if threads:
        cmd += ["--threads", str(threads)]
    return cmd


class DofrayRenderEngine(bpy.types.RenderEngine):
    bl_idname = "DOFRAY"
    bl_label = "dofray"
    bl_use_preview = False
    bl_use_postprocess = True
    bl_use_eevee_viewport = True  # the viewport's Material Preview / Rendered use EEVEE

    def update_render_passes(self, scene=None, renderlayer=None):
        for name, channels, chan_id, kind in PASSES:
            self.register_pass(scene, renderlayer, name, channels, chan_id, kind)

    def render(self, depsgraph):
        scene = depsgraph.scene
        view_layer = depsgraph.view_layer
        width, height = export.render_size(scene.render)
        p = prefs.preferences()
        binary = prefs.find_binary(p)
        if not binary:
            self.report({"ERROR"}, "dofray: no dofray binary (set it in the add-on's "
                                   "preferences, put dofray on PATH, or set DOFRAY_BIN)")
            return
        keep = bool(p and p.keep_files)
        folder = tempfile.mkdtemp(prefix="dofray-render-")
        try:
            self._render(depsgraph, scene, view_layer, width, height, binary, folder,
                         p.threads if p else 0)
        finally:
            if keep:
                print(f"dofray: render files kept in {folder}")
            else:
                shutil.rmtree(folder, ignore_errors=True)

    def _render(self, depsgraph, scene, view_layer, width, height, binary, folder, threads):
        self.update_stats("", "dofray: exporting the scene")
        self.update_progress(0.0)
        toml = os.path.join(folder, "scene.toml")
        out_exr = os.path.join(folder, "render.exr")
        orig_scene = scene.original
        orig_layer = orig_scene.view_layers[view_layer.name]
        frame, subframe = scene.frame_current, scene.frame_subframe
        camera = self.camera_override.original if self.camera_override else None

        def do_export():
            ctx = bpy.context
            with ctx.temp_override(scene=orig_scene, view_layer=orig_layer):
                # The view layer's depsgraph at the frame being rendered (an animation render
                # moves the frame without evaluating the view layer's depsgraph).
                orig_scene.frame_set(frame, subframe=subframe)
                return export.export_scene(bpy.context, toml, visible_only=False,
                                           renderable_only=True, animation=False,
                                           camera_override=camera)

        try:
            info = on_main_thread(do_export)
        except export.ExportError as e:
            self.report({"ERROR"}, f"dofray: {e}")
            return
        # The render border is rendered as dofray's --region: the window, bit for bit as the
        # whole frame has it; Blender's result is the window (cropped or not).
        region = export.border_region(scene.render, width, height)
        for w in info["warnings"]:
            if w != export.BORDER_WARNING:
                self.report({"WARNING"}, f"dofray: {w}")
        if self.test_break():
            return
        cmd = dofray_command(binary, toml, out_exr, getattr(orig_scene, "dofray", None),
                             threads, region)
        self.update_stats("", "dofray: rendering")
        self.update_progress(0.05)
        err_path = os.path.join(folder, "stderr.txt")
        out_path = os.path.join(folder, "stdout.json")
        t0 = time.monotonic()
        with open(err_path, "wb") as err, open(out_path, "wb") as out:
            proc = subprocess.Popen(cmd, stdout=out, stderr=err, cwd=folder)
            while proc.poll() is None:
                if self.test_break():
                    proc.terminate()  # dofray removes its temporary file and exits 143
                    try:
                        proc.wait(5.0)
                    except subprocess.TimeoutExpired:
                        proc.kill()
                        proc.wait()
                    self.update_stats("", "dofray: cancelled")
                    return
                elapsed = time.monotonic() - t0
                # dofray's command line reports no progress into a pipe: show the time.
                self.update_stats("", f"dofray: rendering, {elapsed:.1f} s")
                self.update_progress(min(0.05 + 0.85 * (1.0 - 1.0 / (1.0 + elapsed / 10.0)),
                                         0.9))
                time.sleep(POLL_SECONDS)
        with open(err_path, "rb") as f:
            stderr = f.read().decode("utf-8", "replace").strip()
        with open(out_path, "rb") as f:
            stdout = f.read().decode("utf-8", "replace").strip()
        summary = {}
        try:
            summary = json.loads(stdout) if stdout else {}
        except ValueError:
            pass
        if proc.returncode != 0 or not os.path.isfile(out_exr):
            msg = stderr or summary.get("error", {}).get("message", "") or \
                f"exit status {proc.returncode}"
            self.report({"ERROR"}, f"dofray failed: {msg}")
            return
        warnings = [str(w) for w in summary.get("warnings") or []]
        warnings += [line for line in stderr.splitlines()
                     if "warn" in line.lower() and not any(w in line for w in warnings)]
        for w in warnings:
            self.report({"WARNING"}, f"dofray: {w}")
        self.update_progress(0.95)
        if view_layer.name != DOFRAY_LAYER:
            exr.rename_layer(out_exr, DOFRAY_LAYER, view_layer.name)
        if region is not None:
            width, height = region[2] - region[0], region[3] - region[1]
        result = self.begin_result(0, 0, width, height, layer=view_layer.name)
        try:
            result.load_from_file(out_exr)
        except Exception as e:  # a size mismatch, an unreadable file
            self.end_result(result, cancel=True)
            self.report({"ERROR"}, f"dofray: cannot load {out_exr}: {e}")
            return
        self.end_result(result)
        seconds = summary.get("seconds")
        self.update_stats("", f"dofray: done in {seconds:.2f} s" if isinstance(
            seconds, (int, float)) else "dofray: done")
        self.update_progress(1.0)


# Panels of other engines that dofray's settings live in: the camera's depth of field, the
# light's shape and size, the material's and the world's node surface.
EXTRA_PANELS = {
    "DATA_PT_camera_dof", "DATA_PT_camera_dof_aperture", "DATA_PT_EEVEE_light",
    "EEVEE_MATERIAL_PT_context_material", "EEVEE_MATERIAL_PT_surface", "EEVEE_WORLD_PT_surface",
}
# Left out: the layer passes of the built-in engine, and its light panels (DATA_PT_EEVEE_light
# draws the same and the area light's shape and size).
EXCLUDED_PANELS = {"VIEWLAYER_PT_filter", "VIEWLAYER_PT_layer_passes", "DATA_PT_light",
                   "NODE_DATA_PT_light"}


def get_panels():
    """Blender's generic panels (those listing the built-in 'BLENDER_RENDER' engine: camera,
    light, object, output, ...) and EXTRA_PANELS: shown for dofray too."""
    out = []
    for panel in bpy.types.Panel.__subclasses__():
        engines = getattr(panel, "COMPAT_ENGINES", None)
        if engines is None or panel.__name__ in EXCLUDED_PANELS:
            continue
        if "BLENDER_RENDER" in engines or panel.__name__ in EXTRA_PANELS:
            out.append(panel)
    return out


classes = (DofrayRenderEngine,)


def register():
    for c in classes:
        bpy.utils.register_class(c)
    for panel in get_panels():
        panel.COMPAT_ENGINES.add("DOFRAY")


def unregister():
    for panel in get_panels():
        panel.COMPAT_ENGINES.discard("DOFRAY")
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
