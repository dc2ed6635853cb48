#!/usr/bin/env bash
# Build dofray's C library and install it under PREFIX (default /usr/local):
#
#   PREFIX/lib/libdofray.so.0.1.0           the shared library (its SONAME: libdofray.so.0)
#   PREFIX/lib/libdofray.so.0 -> libdofray.so.0.1.0   what programs load at run time
#   PREFIX/lib/libdofray.so   -> libdofray.so.0       what -ldofray finds at link time
#   PREFIX/lib/libdofray.a                  the static library
#   PREFIX/include/dofray.h
#   PREFIX/lib/pkgconfig/dofray.pc          prefix=PREFIX; pkg-config --cflags --libs dofray
#
# Usage: scripts/install-capi.sh [PREFIX] [CARGO BUILD ARGS...]
#   e.g. scripts/install-capi.sh /usr/local --locked
#        DESTDIR=/tmp/stage scripts/install-capi.sh /usr   # files under /tmp/stage/usr
# Environment:
#   DESTDIR         staging root, as `make install`: the files go to $DESTDIR$PREFIX, while
#                   dofray.pc still says PREFIX. ldconfig runs only without DESTDIR (and as
#                   root): installing to the real root.
#   DOFRAY_PROFILE  the cargo profile to build and install (default release; debug = dev).
#                   capi/tests/c_api.rs passes the profile `cargo test` built the library
#                   with (dev, or release under --release), so nothing is built again.
#   CARGO           the cargo to run (default cargo); CARGO_TARGET_DIR as cargo reads it.
# Runs `cargo build -p dofray-capi --lib --profile PROFILE` (nothing to do when up to date)
# and takes the library's paths and the pkg-config template (written by capi/build.rs) from
# cargo's JSON messages, so any target directory or --target works.
# Needs cargo, readelf (binutils), install, sed.
set -euo pipefail

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
prefix=${1:-/usr/local}
[ $# -gt 0 ] && shift
case "$prefix" in
  /*) ;;
  *) echo "install-capi.sh: PREFIX must be an absolute path, not '$prefix'" >&2; exit 2 ;;
esac
prefix=${prefix%/}
[ -n "$prefix" ] || prefix=/
profile=${DOFRAY_PROFILE:-release}
[ "$profile" = debug ] && profile=dev
cargo=${CARGO:-cargo}
destdir=${DESTDIR:-}

echo "install-capi.sh: building dofray-capi (profile $profile)" >&2
json=$(cd "$repo" && "$cargo" build -p dofray-capi --lib --profile "$profile" \
  --message-format=json-render-diagnostics "$@")

# One JSON message per line; the package id is "path+file:///.../capi#dofray-capi@0.1.0"
# (or "dofray-capi 0.1.0 (path+file:///...)" from older cargo).
ours=$(printf '%s\n' "$json" | grep -E '"package_id":"[^"]*dofray-capi[@ ]')
out_dir=$(printf '%s\n' "$ours" | grep '"reason":"build-script-executed"' |
  sed -n 's/.*"out_dir":"\([^"]*\)".*/\1/p' | tail -n 1)
artifacts=$(printf '%s\n' "$ours" | grep '"reason":"compiler-artifact"' | grep -o '"filenames":\[[^]]*\]')
so=$(printf '%s\n' "$artifacts" | grep -o '"[^"]*/libdofray\.so"' | tr -d '"' | tail -n 1)
a=$(printf '%s\n' "$artifacts" | grep -o '"[^"]*/libdofray\.a"' | tr -d '"' | tail -n 1)
template=$out_dir/dofray.pc.in
for f in "$so" "$a" "$template"; do
  if [ -z "$f" ] || [ ! -f "$f" ]; then
    echo "install-capi.sh: cargo built no ${f:-libdofray.so / libdofray.a} (see its messages above)" >&2
    exit 1
  fi
done
version=$(sed -n 's/^Version: *//p' "$template")
soname=$(readelf -d "$so" | sed -n 's/.*(SONAME).*\[\(.*\)\].*/\1/p')
if [ -z "$soname" ] || [ -z "$version" ]; then
  echo "install-capi.sh: $so has no SONAME or $template no Version (capi/build.rs sets both)" >&2
  exit 1
fi
real=libdofray.so.$version

root=$destdir$prefix
libdir=$root/lib
echo "install-capi.sh: installing $real ($soname) into $root" >&2
install -d "$libdir/pkgconfig" "$root/include"
install -m 0644 "$so" "$libdir/$real"
ln -sfn "$real" "$libdir/$soname"
ln -sfn "$soname" "$libdir/libdofray.so"
install -m 0644 "$a" "$libdir/libdofray.a"
install -m 0644 "$repo/include/dofray.h" "$root/include/dofray.h"
escaped=$(printf '%s' "$prefix" | sed 's/[\\|&]/\\&/g')
pc=$(mktemp)
trap 'rm -f "$pc"' EXIT
sed "s|@PREFIX@|$escaped|g" "$template" >"$pc"
install -m 0644 "$pc" "$libdir/pkgconfig/dofray.pc"

for f in "$real" "$soname" libdofray.so libdofray.a pkgconfig/dofray.pc; do echo "  $libdir/$f"; done
echo "  $root/include/dofray.h"

# Installed for real: refresh the loader's cache (which finds libdofray.so.0 there if $libdir
# is in /etc/ld.so.conf, as /usr/local/lib is on Debian).
if [ -z "$destdir" ]; then
  why=
  if [ "$(id -u)" != 0 ]; then
    why="not root"
  elif ! command -v ldconfig >/dev/null; then
    why="no ldconfig on PATH"
  else
    ldconfig
  fi
  if [ -n "$why" ]; then
    echo "install-capi.sh: ldconfig not run ($why): if $libdir is not in the loader's path," \
      "run programs with LD_LIBRARY_PATH=$libdir or link them with -Wl,-rpath,$libdir" >&2
  fi
fi
