#!/usr/bin/env bash
# What can be checked of the Dockerfile without Docker (CI machines have no Docker daemon and
# cannot pull base images):
#
#   1. every stage's base image is of this machine's Debian release (bookworm), so that
#      this machine's apt answers for the packages the stages install;
#   2. every package the Dockerfile installs with apt-get exists in that release's archive
#      (apt-cache show);
#   3. every shared library that the given ELF files load (ldd: the dofray binary, and
#      libdofray.so, which the runtime image also carries) comes from a Debian package
#      (dpkg -S) that the runtime stage has: one it installs, or a dependency of one
#      (apt-cache depends --recurse), or part of the slim base image, taken to be apt and
#      what it depends on (libc6, libgcc-s1, libstdc++6, ...: every Debian image has apt).
#
# Usage: scripts/docker-check.sh [ELF...]   (default: target/debug/dofray, and
#        target/debug/libdofray.so if it exists: what `cargo test` built)
# Environment: DOCKERFILE (default <repo>/Dockerfile).
# Exit status: 0 all passed, 1 a check failed, 3 skipped (no apt-cache, dpkg or ldd, not
# Debian, or no apt package lists: run apt-get update), with the reason on stderr.
set -euo pipefail

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
dockerfile=${DOCKERFILE:-$repo/Dockerfile}
skip() { echo "SKIP: docker-check: $*" >&2; exit 3; }
fail=0
problem() { echo "FAIL: $*" >&2; fail=1; }

for tool in apt-cache dpkg dpkg-query ldd; do
  command -v "$tool" >/dev/null || skip "$tool is not installed (not a Debian machine?)"
done
# shellcheck disable=SC1091
codename=$(. /etc/os-release 2>/dev/null && echo "${VERSION_CODENAME:-}")
[ -n "$codename" ] || skip "no VERSION_CODENAME in /etc/os-release"
# (No grep -q after a pipe here: with pipefail, the writer it stops early would fail.)
apt-cache show --no-all-versions libc6 2>/dev/null | grep '^Package: libc6$' >/dev/null ||
  skip "apt has no package lists (apt-get update first)"

if [ $# -eq 0 ]; then
  set -- "$repo/target/debug/dofray"
  [ -f "$repo/target/debug/libdofray.so" ] && set -- "$@" "$repo/target/debug/libdofray.so"
fi

# The Dockerfile's logical lines (continuations joined), comments dropped, then per line
# "FROM image" or "<stage number> <package>..." for each apt-get install in it.
parsed=$(sed -e 's/^[[:space:]]*#.*$//' "$dockerfile" | awk '
  { line = line $0 }
  /\\$/ { sub(/\\$/, " ", line); next }
  { print line; line = "" }
' | awk '
  toupper($1) == "FROM" { stage++; print "FROM", $2; next }
  {
    for (i = 1; i <= NF; i++) {
      if ($i == "install" && $(i - 1) == "apt-get") {
        out = ""
        for (j = i + 1; j <= NF; j++) {
          if ($j ~ /^(&&|;|\|\||\|)$/ || $j ~ /;$/) break
          if ($j !~ /^-/) out = out " " $j
        }
        if (out != "") print stage out
      }
    }
  }
')
[ -n "$parsed" ] || { echo "FAIL: no FROM in $dockerfile" >&2; exit 1; }

# 1. Base images.
while read -r _ image; do
  case "$image" in
    *"$codename"*) echo "base image $image: $codename" ;;
    *) problem "base image $image is not Debian $codename: this machine's apt cannot check it" ;;
  esac
done < <(printf '%s\n' "$parsed" | grep '^FROM ')
last=$(printf '%s\n' "$parsed" | grep -c '^FROM ')

# 2. Packages.
runtime=()
while read -r stage packages; do
  for pkg in $packages; do
    if apt-cache show --no-all-versions "$pkg" 2>/dev/null | grep "^Package: $pkg\$" >/dev/null; then
      version=$(apt-cache policy "$pkg" | sed -n 's/^ *Candidate: //p')
      echo "stage $stage installs $pkg: in the archive ($version)"
    else
      problem "stage $stage installs $pkg, which apt-cache show does not know"
    fi
    [ "$stage" = "$last" ] && runtime+=("$pkg")
  done
done < <(printf '%s\n' "$parsed" | grep -v '^FROM ')
[ ${#runtime[@]} -gt 0 ] || problem "the runtime stage (the last) installs no packages"

# 3. The runtime stage's packages with everything they depend on, and the base image's.
closure() {
  apt-cache depends --recurse --no-recommends --no-suggests --no-conflicts --no-breaks \
    --no-replaces --no-enhances "$@" 2>/dev/null | grep -v '^[[:space:]<]' | sort -u
}
installed=$(closure "${runtime[@]}")
base=$(closure apt)

# The package that ships PATH (as ldd prints it, resolved, or across the /lib -> /usr/lib
# merge), without its :arch.
owner() {
  local path=$1 real candidates c
  real=$(readlink -f "$path")
  candidates=("$path" "$real" "${path#/usr}" "/usr$path" "${real#/usr}" "/usr$real")
  for c in "${candidates[@]}"; do
    found=$(dpkg -S "$c" 2>/dev/null | sed -n '/^diversion/d; s/^\([^:, ]*\).*: \/.*/\1/p') || continue
    [ -n "$found" ] && { printf '%s\n' "$found" | sed -n 1p; return 0; }
  done
  return 1
}

for elf in "$@"; do
  [ -f "$elf" ] || { problem "$elf does not exist (build it first: cargo test)"; continue; }
  echo "$elf:"
  libs=$(env -u LD_LIBRARY_PATH -u LD_PRELOAD ldd "$elf") || { problem "ldd $elf failed"; continue; }
  while read -r line; do
    case "$line" in
      *"not found"*) problem "$elf: ${line%% *} is not found on this machine"; continue ;;
      *" => "/*) path=${line#* => }; path=${path%% (*} ;;
      /*) path=${line%% (*} ;;
      *) continue ;; # linux-vdso.so.1: the kernel's
    esac
    if ! pkg=$(owner "$path"); then
      problem "$elf loads $path, which no Debian package ships (a private Embree, EMBREE_DIR?)"
    elif printf '%s\n' "${runtime[@]}" | grep -x "$pkg" >/dev/null; then
      echo "  $path: $pkg, installed by the runtime stage"
    elif printf '%s\n' "$installed" | grep -x "$pkg" >/dev/null; then
      echo "  $path: $pkg, a dependency of ${runtime[*]}"
    elif printf '%s\n' "$base" | grep -x "$pkg" >/dev/null; then
      echo "  $path: $pkg, in the base image (apt depends on it)"
    else
      problem "$elf loads $path from $pkg, which the runtime stage neither installs nor gets through ${runtime[*]} or the base image"
    fi
  done <<<"$libs"
done

if [ "$fail" = 0 ]; then
  echo "docker-check: the Dockerfile's packages exist in Debian $codename and provide every library of $*"
fi
exit "$fail"
