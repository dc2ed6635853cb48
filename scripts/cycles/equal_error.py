"""Equal error against Cycles: how long dofray (dense and adaptive) and Cycles (fixed samples,
adaptive sampling, and fixed samples + OpenImageDenoise) take to reach given PSNR levels on the
same exported scene, each against its own converged reference. Run by hand, not in CI (see
README.md in this folder).

    /path/to/venv/bin/python scripts/cycles/scenes.py --out OUT --only spheres --dof --no-render
    /path/to/venv/bin/python scripts/cycles/equal_error.py --out OUT --scene spheres

`scenes.py` saves the scene as OUT/NAME/NAME.blend, which Cycles renders here; dofray renders
OUT/NAME/NAME.dof.toml, written here as `compare.py --dof` writes it (the f/2 depth-of-field
variant, focused on the middle object).

PSNR is dofray's definition (`src/metrics.rs`): every channel clamped to [0, 1], sRGB-encoded,
10 log10(1 / MSE) over all pixels and channels. A method's time for a level is interpolated
between the two rungs that bracket it, linear in PSNR against log seconds, as
`dofray bench --equal-error` does. Cycles' time is the wall time of `bpy.ops.render.render`
minus the same call's time at 1 sample (scene sync, BVH build, film: what dofray's timed render
does not include, as its scene is loaded before the clock starts); both figures are written.
"""

import argparse
import json
import math
import os
import subprocess
import sys
import time

import bpy
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from common import read_rgb  # noqa: E402
from compare import new_toml  # noqa: E402


def srgb(img):
    v = np.clip(img, 0.0, 1.0)
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * np.power(v, 1.0 / 2.4) - 0.055)


def psnr(a, b):
    mse = float(np.mean((srgb(a) - srgb(b)) ** 2))
    return math.inf if mse == 0.0 else 10.0 * math.log10(1.0 / mse)


def time_to_reach(points, level):
    """(seconds, at_first_rung) at which (seconds, psnr) points in ladder order first reach
    `level`; seconds None when none does. As `time_to_reach` in src/bench/equal_error.rs."""
    for i, (t, p) in enumerate(points):
        if p >= level:
            if i == 0:
                return t, True
            t0, p0 = points[i - 1]
            if math.isinf(p) or p == p0:
                return t, False
            f = (level - p0) / (p - p0)
            return math.exp(math.log(t0) + f * (math.log(t) - math.log(t0))), False
    return None, False


class Cycles:
    """Renders the saved scene with Cycles and times it."""

    def __init__(self, blend, work, threads, width=None):
        bpy.ops.wm.open_mainfile(filepath=blend)
        self.scene = bpy.context.scene
        self.work = work
        if width:
            # The same framing at another size, as dofray's --width: the height keeps the aspect.
            r = self.scene.render
            r.resolution_y = round(r.resolution_y * width / r.resolution_x)
            r.resolution_x = width
            r.resolution_percentage = 100
        c = self.scene.cycles
        c.use_denoising = False
        c.use_adaptive_sampling = False
        if threads:
            self.scene.render.threads_mode = "FIXED"
            self.scene.render.threads = threads

    def render(self, name, spp, adaptive=None, denoise=False):
        c = self.scene.cycles
        c.samples = spp
        c.use_adaptive_sampling = adaptive is not None
        if adaptive is not None:
            c.adaptive_threshold = adaptive
            c.adaptive_min_samples = 0  # Cycles' automatic minimum
        c.use_denoising = denoise
        if denoise:
            c.denoiser = "OPENIMAGEDENOISE"
            c.denoising_input_passes = "RGB_ALBEDO_NORMAL"
            c.denoising_prefilter = "ACCURATE"
        path = os.path.join(self.work, name + ".exr")
        self.scene.render.filepath = path
        t0 = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        seconds = time.perf_counter() - t0
        return read_rgb(path), seconds


def cycles_series(cy, label, rungs, reference, overhead, repeat, **kw):
    out = []
    for value in rungs:
        times = []
        for r in range(repeat):
            if "adaptive" in kw:
                img, s = cy.render(f"{label}-{value}", kw["max_spp"], adaptive=value)
            else:
                img, s = cy.render(f"{label}-{value}", value, denoise=kw.get("denoise", False))
            times.append(s)
        wall = float(np.median(times))
        p = psnr(img, reference)
        out.append({"rung": value, "wall_seconds": wall,
                    "seconds": max(wall - overhead, 1e-3), "psnr": p})
        print(f"  cycles {label} {value}: {wall:.2f} s wall, {p:.2f} dB", file=sys.stderr)
    return out


def run_dofray(args, toml):
    cmd = [args.dofray, "bench", toml, "--equal-error", "--json", "--quiet",
           "--ladder", args.dofray_ladder, "--levels", args.levels,
           "--reference-spp", str(args.dofray_reference_spp), "--repeat", str(args.repeat)]
    if args.width:
        cmd += ["--width", str(args.width)]
    print("  " + " ".join(cmd), file=sys.stderr)
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        raise SystemExit(f"dofray failed ({res.returncode}): {res.stderr.strip()}")
    return json.loads(res.stdout)


def fmt_t(t, first):
    if t is None:
        return "not reached"
    return ("<= " if first else "") + f"{t:.2f} s"


def run_cycles(args, blend, work):
    """Cycles' overhead, reference time and series (fixed, adaptive, OIDN)."""
    print(f"[{args.scene}] Cycles", file=sys.stderr)
    cy = Cycles(blend, work, args.threads, args.width)
    _, overhead = cy.render("overhead", 1)
    _, overhead = cy.render("overhead", 1)  # the second call: caches warm, as for every rung
    saved = os.path.join(work, f"reference-{args.cycles_reference_spp}.exr")
    if args.reuse_reference and os.path.exists(saved):
        reference, ref_seconds = read_rgb(saved), None
    else:
        reference, ref_seconds = cy.render("reference", args.cycles_reference_spp)
        os.replace(os.path.join(work, "reference.exr"), saved)
    ints = lambda s: [int(v) for v in s.split(",")]  # noqa: E731
    series = {
        "cycles": cycles_series(cy, "fixed", ints(args.cycles_ladder), reference, overhead,
                                args.repeat),
        "cycles_adaptive": cycles_series(
            cy, "adaptive", [float(v) for v in args.cycles_adaptive.split(",")], reference,
            overhead, args.repeat, adaptive=True, max_spp=args.cycles_adaptive_max),
        "cycles_oidn": cycles_series(cy, "oidn", ints(args.cycles_denoised), reference,
                                     overhead, args.repeat, denoise=True),
    }
    return overhead, ref_seconds, series


def main(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="the folder scenes.py and compare.py wrote")
    p.add_argument("--scene", default="spheres")
    p.add_argument("--levels", default="35,40", help="PSNR levels, dB (sRGB)")
    repo = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    p.add_argument("--dofray", default=os.path.join(repo, "target", "release", "dofray"))
    p.add_argument("--dofray-ladder", default="4,8,16,32,64,128,256")
    p.add_argument("--dofray-reference-spp", type=int, default=4096)
    p.add_argument("--cycles-ladder", default="4,8,16,32,64,128,256,512")
    p.add_argument("--cycles-adaptive", default="0.1,0.05,0.02,0.01,0.005,0.0025",
                   help="adaptive sampling noise thresholds")
    p.add_argument("--cycles-adaptive-max", type=int, default=4096,
                   help="adaptive sampling's max samples")
    p.add_argument("--cycles-denoised", default="1,2,4,8,16,32,64")
    p.add_argument("--cycles-reference-spp", type=int, default=4096)
    p.add_argument("--repeat", type=int, default=1, help="timed repeats per rung (median)")
    p.add_argument("--threads", type=int, default=0, help="Cycles threads (0: all)")
    p.add_argument("--width", type=int, default=None,
                   help="render both at this width, the height keeping the scene's aspect "
                        "(default: the scene's own size)")
    p.add_argument("--reuse-reference", action="store_true",
                   help="take Cycles' reference from the last run's render at the same spp "
                        "(OUT/SCENE/equal-error*/reference-SPP.exr) instead of rendering it")
    p.add_argument("--reuse-cycles", action="store_true",
                   help="take Cycles' series from the last run's equal-error.json (same scene, "
                        "same machine) and run only dofray")
    args = p.parse_args(argv)
    levels = [float(v) for v in args.levels.split(",")]
    d = os.path.join(args.out, args.scene)
    blend = os.path.join(d, args.scene + ".blend")
    if not os.path.exists(blend):
        raise SystemExit(f"{blend}: missing (run scenes.py --dof first, see --help)")
    with open(os.path.join(d, args.scene + ".json")) as f:
        side = json.load(f)
    if not side["cycles"]["dof"]:
        raise SystemExit(f"{blend}: saved without depth of field (run scenes.py with --dof)")
    toml = os.path.join(d, args.scene + ".dof.toml")
    with open(toml, "w") as f:
        f.write(new_toml(side, True))
    suffix = f"-{args.width}" if args.width else ""
    work = os.path.join(d, "equal-error" + suffix)
    os.makedirs(work, exist_ok=True)

    print(f"[{args.scene}] dofray", file=sys.stderr)
    dof = run_dofray(args, toml)

    if args.reuse_cycles:
        with open(os.path.join(d, f"equal-error{suffix}.json")) as f:
            last = json.load(f)
        overhead = last["cycles_overhead_seconds"]
        ref_seconds = last["cycles_reference_seconds"]
        series = {k: v for k, v in last["series"].items() if k.startswith("cycles")}
    else:
        overhead, ref_seconds, series = run_cycles(args, blend, work)
    for m in ("dense", "adaptive"):
        series["dofray_" + m] = [
            {"rung": r["spp"], "seconds": r["seconds"], "psnr": r["psnr_vs_reference"]
             if r["psnr_vs_reference"] is not None else math.inf}
            for r in dof[m]]

    table = {}
    for name, rungs in series.items():
        pts = [(r["seconds"], r["psnr"]) for r in rungs]
        table[name] = {lv: time_to_reach(pts, lv) for lv in levels}
    cpu = next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo")
                if line.startswith("model name")), "unknown CPU")
    report = {
        "scene": args.scene, "width": args.width, "cpu": cpu, "threads": os.cpu_count(),
        "cycles_version": bpy.app.version_string,
        "cycles_overhead_seconds": overhead, "cycles_reference_spp": args.cycles_reference_spp,
        "cycles_reference_seconds": ref_seconds,
        "dofray_reference_spp": args.dofray_reference_spp,
        "series": series,
        "time_to_level": {n: {str(lv): {"seconds": t, "at_first_rung": f}
                              for lv, (t, f) in v.items()} for n, v in table.items()},
    }
    with open(os.path.join(d, f"equal-error{suffix}.json"), "w") as f:
        json.dump(report, f, indent=2, default=lambda x: None)

    lines = [f"**{args.scene}** ({cpu}, {os.cpu_count()} threads; Cycles {bpy.app.version_string}, "
             f"sync overhead {overhead:.2f} s subtracted)", "",
             "| method | " + " | ".join(f"time to {lv:g} dB" for lv in levels) + " |",
             "|---|" + "---|" * len(levels)]
    for name in series:
        lines.append(f"| {name} | " + " | ".join(fmt_t(*table[name][lv]) for lv in levels) + " |")
    best = table["dofray_adaptive"]
    lines.append("")
    for lv in levels:
        ta = best[lv][0]
        ratios = [f"{n}: {table[n][lv][0] / ta:.2f}x" for n in series
                  if n.startswith("cycles") and table[n][lv][0] is not None and ta]
        lines.append(f"- {lv:g} dB, Cycles' time / dofray adaptive's: " + (", ".join(ratios) or "-"))
    text = "\n".join(lines) + "\n"
    with open(os.path.join(d, f"equal-error{suffix}.md"), "w") as f:
        f.write(text)
    print(text)
    return 0


if __name__ == "__main__":
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    code = main(argv)
    sys.stdout.flush()
    os._exit(code)
