#!/usr/bin/env bash
# Headless test of the dofray Blender add-on (blender/dofray_blender) under Blender 4.2 as a
# Python module: builds the extension zip, then runs blender/tests/test_addon.py, which exports
# a scene built in code, checks the scene file against Blender's values, renders it with dofray,
# renders through the DOFRAY render engine, and installs the zip as an extension; then
# scripts/view-transform-check.py compares dofray's PNG views with Blender's.
#
#   scripts/blender-addon-test.sh [DOFRAY_BIN]     # default: target/release/dofray
#
# Python: $BLENDER_PYTHON if set (a Python that can `import bpy, numpy, OpenEXR`), else the
# virtual environment target/blender-venv (or $BLENDER_VENV), created with python3.11 and
# `pip install 'bpy==4.2.*' numpy OpenEXR` on first use (a few hundred MB).
#
# Exit status: 0 passed, 1 failed, 2 no dofray binary, 3 skipped: no Python 3.11 or bpy cannot
# be installed (no network), with a one-line notice.
set -euo pipefail
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
dofray=${1:-${DOFRAY_BIN:-"$repo/target/release/dofray"}}
if [[ ! -x "$dofray" ]]; then
    echo "blender-addon-test: no dofray binary at $dofray (cargo build --release, or pass its path)" >&2
    exit 2
fi
dofray=$(cd "$(dirname "$dofray")" && pwd)/$(basename "$dofray")

if [[ -n "${BLENDER_PYTHON:-}" ]]; then
    py=$BLENDER_PYTHON
else
    venv=${BLENDER_VENV:-"$repo/target/blender-venv"}
    py="$venv/bin/python"
    if ! "$py" -c "import bpy, numpy, OpenEXR" >/dev/null 2>&1; then
        base=${PYTHON311:-python3.11}
        if ! command -v "$base" >/dev/null 2>&1; then
            echo "blender-addon-test: skipped: no $base (Blender 4.2's bpy module needs Python 3.11)"
            exit 3
        fi
        if [[ ! -x "$py" ]]; then
            "$base" -m venv "$venv" >/dev/null
        fi
        if ! "$py" -m pip install --quiet --disable-pip-version-check 'bpy==4.2.*' numpy OpenEXR \
            >"$venv/pip.log" 2>&1; then
            echo "blender-addon-test: skipped: cannot install bpy 4.2 into $venv (no network?); see $venv/pip.log"
            exit 3
        fi
    fi
fi

zip=$("$repo/scripts/build-blender-addon.sh" "$repo/target/blender-addon")
start=$(date +%s)
status=0
PYTHONDONTWRITEBYTECODE=1 DOFRAY_ADDON_ZIP="$zip" "$py" "$repo/blender/tests/test_addon.py" "$dofray" \
    || status=$?
# dofray's PNG views (AgX, looks, PBR Neutral, exposure, gamma) against Blender's own PNGs of
# the same linear image: at most 1 code value apart on average (a few seconds).
view_out=$(mktemp -d /tmp/dofray-view-check.XXXXXX)
if PYTHONDONTWRITEBYTECODE=1 "$py" "$repo/scripts/view-transform-check.py" "$dofray" --out "$view_out"; then
    rm -rf "$view_out"
else
    echo "blender-addon-test: view transforms differ from Blender's; images in $view_out"
    status=1
fi
echo "blender-addon-test: exit $status in $(( $(date +%s) - start )) s"
exit $status
