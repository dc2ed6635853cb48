"""Renders every scene that scenes.py built with dofray and compares it with the Cycles render:
mean linear radiance over a 4x4 grid of regions, dofray / Cycles per region, and a side-by-side
PNG (Cycles | dofray | false-colour ratio). Run by hand, not in CI (see README.md here).

    /path/to/venv/bin/python scripts/cycles/compare.py --out /tmp/cycles-cmp
        [--dofray target/release/dofray] [--spp 1024] [--only box,glass] [--dof] [--no-legacy]

Per scene NAME it writes, next to NAME.glb: NAME.toml (the scene for dofray, with the sidecar's
world and area lights in the keys of issue 24), NAME.dofray.exr, NAME.compare.png, and, when dofray
refuses NAME.toml (a dofray without those keys), NAME.legacy.toml: an approximation in today's keys
(world -> ambient + background colour, area light -> a 90-degree spot), marked "legacy" in the
table. Each scene runs on its own: a failure is reported and the others go on.
"""

import argparse
import json
import math
import os
import subprocess
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from common import read_rgb, write_png  # noqa: E402

GRID = 4


# ---------------------------------------------------------------------------------------------
# Scene files for dofray


def fmt(v):
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(fmt(x) for x in v) + "]"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    return repr(float(v)) if isinstance(v, float) else str(v)


def common_tables(side, dof):
    """[image], [render] and (for the depth-of-field variant) [camera] lines."""
    w, h = side["resolution"]
    lines = ["[image]", f"width = {w}", f"height = {h}", "",
             "[render]",
             # Cycles' Blackman-Harris of filter_width w spans +-w (its filter_table doubles
             # the width), so its default 1.5 is dofray's full width 3.
             f"pixel_filter = {fmt('blackman-harris')}",
             f"pixel_filter_width = {fmt(2.0 * side['cycles']['pixel_filter_width'])}"]
    # Cycles' biased defaults (scenes.py --blender-biased), as the add-on carries them.
    cycles = side["cycles"]
    if cycles.get("sample_clamp_indirect", 0.0) > 0.0:
        lines.append(f"clamp_indirect = {fmt(float(cycles['sample_clamp_indirect']))}")
    if cycles.get("blur_glossy", 0.0) > 0.0:
        lines.append(f"filter_glossy = {fmt(float(cycles['blur_glossy']))}")
    lines.append("")
    if dof:
        d = side["camera"]["dof"]
        lines += ["[camera]", f"f_number = {fmt(d['f_number'])}",
                  f"focal_length_mm = {fmt(d['focal_length_mm'])}",
                  f"sensor_width_mm = {fmt(d['sensor_width_mm'])}",
                  f"focus_distance = {fmt(d['focus_distance'])}", ""]
    return lines


def mesh_object(side):
    return ["[[objects]]", 'type = "mesh"', f"file = {fmt(side['glb'])}", "camera = true", ""]


def new_toml(side, dof):
    """The scene in issue 24's keys: [world] and area [[lights]]."""
    area = side["area_lights"]
    lines = [f"name = {fmt(side['name'])}"]
    if not area:
        lines.append("lights = []  # the glTF's own lights only")
    lines.append("")
    lines += common_tables(side, dof)
    world = side["world"]
    lines.append("[world]")
    if "map" in world:
        lines += [f"map = {fmt(world['map'])}", f"strength = {fmt(world['strength'])}",
                  f"rotation = {fmt(world['rotation'])}"]
    else:
        lines += [f"color = {fmt(world['color'])}", f"strength = {fmt(world['strength'])}"]
    lines.append("")
    for a in area:
        lines += ["[[lights]]", f"type = {fmt(a['type'])}", f"position = {fmt(a['position'])}",
                  f"direction = {fmt(a['direction'])}", f"size = {fmt(a['size'])}",
                  f"power = {fmt(a['power'])}", ""]
    return "\n".join(lines + mesh_object(side))


def legacy_toml(side, dof):
    """An approximation in the keys dofray has before issue 24, for a 'before' table."""
    world = side["world"]
    base = world.get("map_mean", world.get("color", [0.0, 0.0, 0.0]))
    radiance = [c * world["strength"] for c in base]
    area = side["area_lights"]
    lines = [f"name = {fmt(side['name'])}", f"ambient = {fmt(radiance)}"]
    if not area:
        lines.append("lights = []")
    lines.append("")
    lines += common_tables(side, dof)
    lines += ["[background]", f"color = {fmt(radiance)}", ""]
    for a in area:
        # A one-sided Lambertian emitter of power P sends P / pi W/sr along its normal.
        lines += ["[[lights]]", 'type = "spot"', f"position = {fmt(a['position'])}",
                  f"direction = {fmt(a['direction'])}",
                  f"intensity = {fmt(a['power'] / math.pi)}", "outer_angle = 90.0",
                  "inner_angle = 0.0", ""]
    return "\n".join(lines + mesh_object(side))


def run_dofray(args, toml_path, exr_path, dof):
    mode = ["--mode", "dense", "--spp", str(args.spp)] if dof else \
        ["--mode", "pinhole", "--aa", str(args.spp)]
    cmd = [args.dofray, "render", toml_path, *mode, "-o", exr_path, "-q"]
    r = subprocess.run(cmd, capture_output=True, text=True)
    return r.returncode, (r.stderr or r.stdout).strip()


# ---------------------------------------------------------------------------------------------
# Images


def region_means(img):
    h, w, _ = img.shape
    lum = img.mean(axis=2)
    out = np.zeros((GRID, GRID))
    for r in range(GRID):
        for c in range(GRID):
            out[r, c] = lum[r * h // GRID:(r + 1) * h // GRID,
                            c * w // GRID:(c + 1) * w // GRID].mean()
    return out


def srgb8(img):
    x = np.clip(img, 0.0, 1.0)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
    return (s * 255.0 + 0.5).astype(np.uint8)


def box_blur(a, k=5):
    pad = k // 2
    p = np.pad(a, ((pad, pad), (pad, pad)), mode="edge")
    c = np.cumsum(np.cumsum(p, 0), 1)
    c = np.pad(c, ((1, 0), (1, 0)))
    return (c[k:, k:] - c[:-k, k:] - c[k:, :-k] + c[:-k, :-k]) / (k * k)


def ratio_colour(cyc, dof):
    """log2(dofray / Cycles) of 5x5-blurred luminance: blue darker, white equal, red brighter,
    full colour at +-1 stop; black where both are black."""
    a, b = box_blur(cyc.mean(2)), box_blur(dof.mean(2))
    eps = 1e-6
    t = np.clip(np.log2((b + eps) / (a + eps)), -1.0, 1.0)
    rgb = np.ones(a.shape + (3,))
    pos, neg = np.clip(t, 0, 1), np.clip(-t, 0, 1)
    rgb[..., 1] -= pos + neg
    rgb[..., 2] -= pos
    rgb[..., 0] -= neg
    rgb[(a < eps) & (b < eps)] = 0.0
    return (np.clip(rgb, 0, 1) * 255 + 0.5).astype(np.uint8)


def side_by_side(path, cyc, dof):
    gap = np.full((cyc.shape[0], 4, 3), 255, np.uint8)
    write_png(path, np.concatenate([srgb8(cyc), gap, srgb8(dof), gap, ratio_colour(cyc, dof)], 1))


# ---------------------------------------------------------------------------------------------
# One scene


def compare_scene(name, args):
    folder = os.path.join(args.out, name)
    with open(os.path.join(folder, name + ".json")) as f:
        side = json.load(f)
    suffix = ".dof" if args.dof else ""
    cycles_exr = os.path.join(folder, f"{name}.cycles{suffix}.exr")
    if not os.path.exists(cycles_exr):
        raise RuntimeError(f"no Cycles render {cycles_exr} (run scenes.py{' --dof' if args.dof else ''})")
    res = {"name": name, "notes": []}
    toml = os.path.join(folder, name + ".toml")
    with open(toml, "w") as f:
        f.write(new_toml(side, args.dof))
    exr = os.path.join(folder, f"{name}.dofray{suffix}.exr")
    code, err = run_dofray(args, toml, exr, args.dof)
    res["input"] = "issue-24 keys"
    if code != 0:
        first = err.splitlines()[0] if err else f"exit {code}"
        res["notes"].append(f"dofray refused {name}.toml: {first}")
        if args.no_legacy:
            raise RuntimeError(res["notes"][-1])
        toml = os.path.join(folder, name + ".legacy.toml")
        with open(toml, "w") as f:
            f.write(legacy_toml(side, args.dof))
        code, err = run_dofray(args, toml, exr, args.dof)
        if code != 0:
            raise RuntimeError(f"dofray failed on {name}.legacy.toml too: {err}")
        world = side["world"]
        black = world["strength"] == 0 or ("map" not in world and not any(world["color"]))
        # A black world and no area lights say the same thing in today's keys: exact.
        res["input"] = "today's keys" if black and not side["area_lights"] else "legacy approx"
        if not black:
            res["notes"].append("legacy: world as ambient + background colour")
        if side["area_lights"]:
            res["notes"].append("legacy: area light as a 90-degree spot of P/pi W/sr")
    warn = [l for l in err.splitlines() if "warn" in l.lower()]
    if warn:
        res["notes"].append("dofray: " + warn[0][:200])
    cyc, dof = read_rgb(cycles_exr), read_rgb(exr)
    if cyc.shape != dof.shape:
        raise RuntimeError(f"sizes differ: Cycles {cyc.shape[1]}x{cyc.shape[0]}, dofray "
                           f"{dof.shape[1]}x{dof.shape[0]}")
    side_by_side(os.path.join(folder, f"{name}.compare{suffix}.png"), cyc, dof)
    c, d = region_means(cyc), region_means(dof)
    floor = args.dark * max(c.mean(), 1e-12)
    ratio = np.where(c > floor, d / np.maximum(c, 1e-300), np.nan)
    res.update(cycles=c, dofray=d, ratio=ratio, cycles_mean=cyc.mean(), dofray_mean=dof.mean())
    dev = np.abs(ratio - 1.0)
    if np.all(np.isnan(dev)):
        res["worst"] = None
    else:
        i = int(np.nanargmax(dev))
        res["worst"] = (i // GRID, i % GRID, float(ratio.flat[i]))
    dark = int(np.isnan(ratio).sum())
    if dark:
        res["notes"].append(f"{dark} region(s) darker than {args.dark:g} x the mean: not judged")
    res["ok"] = bool(np.nanmax(dev) <= args.tolerance) if res["worst"] else True
    return res


# ---------------------------------------------------------------------------------------------
# Report


def report(results, failures, args):
    tol = f"{args.tolerance * 100:g}%"
    print(f"| scene | dofray input | Cycles mean | dofray mean | dofray/Cycles min | max | "
          f"worst region (row, col): ratio | all within {tol} |")
    print("|---|---|---|---|---|---|---|---|")
    for r in results:
        w = r["worst"]
        worst = f"({w[0]}, {w[1]}): {w[2]:.3f}" if w else "-"
        print(f"| {r['name']} | {r['input']} | {r['cycles_mean']:.4f} | {r['dofray_mean']:.4f} | "
              f"{np.nanmin(r['ratio']):.3f} | {np.nanmax(r['ratio']):.3f} | {worst} | "
              f"{'yes' if r['ok'] else 'NO'} |")
    for name, why in failures:
        print(f"| {name} | FAILED | - | - | - | - | - | {why} |")
    for r in results:
        print(f"\n**{r['name']}** ({r['input']}): per region `Cycles -> dofray (ratio)`, "
              f"row 0 at the top")
        if r["notes"]:
            print("; ".join(r["notes"]))
        print()
        print("| row | " + " | ".join(f"col {c}" for c in range(GRID)) + " |")
        print("|---" * (GRID + 1) + "|")
        for i in range(GRID):
            cells = []
            for j in range(GRID):
                q = r["ratio"][i, j]
                qs = "dark" if np.isnan(q) else f"{q:.3f}"
                cells.append(f"{r['cycles'][i, j]:.4g} -> {r['dofray'][i, j]:.4g} ({qs})")
            print(f"| {i} | " + " | ".join(cells) + " |")


def main(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="the folder scenes.py wrote")
    repo = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    p.add_argument("--dofray", default=os.path.join(repo, "target", "release", "dofray"),
                   help="the dofray binary (default: this checkout's release build)")
    p.add_argument("--spp", type=int, default=1024, help="dofray samples per pixel")
    p.add_argument("--only", default="", help="comma-separated scene names (default: all)")
    p.add_argument("--dof", action="store_true", help="compare the f/2 depth-of-field variant")
    p.add_argument("--no-legacy", action="store_true",
                   help="do not fall back to today's keys when dofray refuses the new ones")
    p.add_argument("--tolerance", type=float, default=0.03, help="allowed |ratio - 1|")
    p.add_argument("--dark", type=float, default=0.01,
                   help="regions whose Cycles mean is below this fraction of the image mean "
                        "are shown but not judged")
    args = p.parse_args(argv)
    if not os.access(args.dofray, os.X_OK):
        print(f"no dofray binary at {args.dofray}: build it (cargo build --release) or give "
              f"--dofray", file=sys.stderr)
        return 2
    names = [n for n in args.only.split(",") if n] or sorted(
        d for d in os.listdir(args.out)
        if os.path.exists(os.path.join(args.out, d, d + ".json")))
    results, failures = [], []
    for name in names:
        try:
            results.append(compare_scene(name, args))
        except Exception as e:  # one scene failing must not stop the others
            print(f"[{name}] FAILED: {e}", file=sys.stderr)
            failures.append((name, str(e).splitlines()[0][:160]))
    report(results, failures, args)
    return 1 if failures or not all(r["ok"] for r in results) else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
