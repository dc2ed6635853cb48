#!/usr/bin/env bash
# Builds the dofray Blender add-on (blender/dofray_blender) into an installable Blender 4.2+
# extension zip: OUT_DIR/dofray-blender-VERSION.zip (VERSION from blender_manifest.toml).
# Install it in Blender with Edit > Preferences > Get Extensions > (v) > Install from Disk.
#
#   scripts/build-blender-addon.sh [OUT_DIR]     # default: target/blender-addon
#
# Needs python3 (its zipfile module; no zip tool needed). Prints the zip's path.
set -euo pipefail
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
src="$repo/blender/dofray_blender"
out=${1:-"$repo/target/blender-addon"}
mkdir -p "$out"
out=$(cd "$out" && pwd)
python3 - "$src" "$out" <<'PY'
import os, re, sys, zipfile

src, out = sys.argv[1], sys.argv[2]
manifest = open(os.path.join(src, "blender_manifest.toml"), encoding="utf-8").read()
m = re.search(r'^version\s*=\s*"([^"]+)"', manifest, re.M)
if not m:
    sys.exit(f"no version in {src}/blender_manifest.toml")
path = os.path.join(out, f"dofray-blender-{m.group(1)}.zip")
tmp = path + ".tmp"
files = []
for root, dirs, names in os.walk(src):
    dirs[:] = sorted(d for d in dirs if d != "__pycache__" and not d.startswith("."))
    for n in sorted(names):
        if n.endswith((".pyc", ".pyo")) or n.startswith("."):
            continue
        full = os.path.join(root, n)
        files.append((full, os.path.relpath(full, src).replace(os.sep, "/")))
# The manifest at the archive's root, as Blender's own `extension build` writes it. Fixed
# timestamps, so the same sources give the same zip.
with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
    for full, arc in files:
        info = zipfile.ZipInfo(arc, date_time=(2024, 1, 1, 0, 0, 0))
        info.compress_type = zipfile.ZIP_DEFLATED
        info.external_attr = 0o644 << 16
        with open(full, "rb") as f:
            z.writestr(info, f.read())
os.replace(tmp, path)
print(path)
PY
