#!/usr/bin/env bash
# Build dofray against Debian 13's Embree 4 on a Debian 12 machine and run its tests there.
#
# Debian 12 ships Embree 3.13, Debian 13 Embree 4.3. This script checks the Embree 4 path
# (cfg(embree4), src/embree/version.rs) without touching the system:
#
#   1. Fetches Debian 13's libembree-dev and libembree4-4 with the runtime libraries they need
#      (trixie's libc6, libstdc++6, libtbb12, ...; libembree4-4 needs glibc >= 2.38), plus
#      patchelf, through a private apt configuration kept in the cache directory. The mirror is
#      the one the system's own apt sources use for Debian; /etc/apt is only read.
#      The packages are unpacked with dpkg-deb -x into <cache>/root, and <cache>/prefix gets the
#      layout build.rs expects from EMBREE_DIR (include/ and lib/ symlinks into root/usr).
#   2. Builds with EMBREE_DIR=<cache>/prefix in its own target directory (target/embree4), so the
#      normal build is left alone. A new target directory is first seeded with a copy of the
#      normal build's dependencies (under cargo's lock), so only dofray itself is compiled.
#      Runs cargo clippy --all-targets -D warnings against Embree 4 too.
#   3. Runs every unit and integration test binary (found with cargo's JSON messages) under
#      Debian 13's dynamic loader, as <root>/usr/lib/<multiarch>/ld-linux-x86-64.so.2
#      --library-path <root>/usr/lib/<multiarch> <test binary>: the system's glibc (2.36) is too
#      old for libembree4. The CLI tests spawn the dofray binary directly,
#      so its ELF interpreter is pointed at the same loader with trixie's patchelf; if that is
#      not possible they are reported as skipped. Doc tests are not run (rustdoc would run them
#      under the system loader).
#   4. Prints a summary and exits non-zero if anything failed: 3 when the packages could not
#      be fetched (nothing was tested), 1 for any other failure.
#
# Times on the 2-core machine: the fetch takes about 10 s (23 MB of downloads, 80 MB of cache);
# the first build about 3 minutes with seeding (dofray and its tests, then clippy), about
# 12 minutes without (every dependency too: 9.5 for the tests); a second run with nothing
# changed a few seconds.
# The unpacked packages are reused until --refresh. From .ci/run, call it after cargo test so
# that there is a normal build to seed from.
#
# Usage: scripts/embree4-check.sh [--cache-dir DIR] [--target-dir DIR] [--no-clippy]
#                                 [--no-seed] [--refresh] [-j N]
# Environment: DOFRAY_EMBREE4_CACHE (cache dir; default ${XDG_CACHE_HOME:-$HOME/.cache}/dofray/embree4),
#   DOFRAY_EMBREE4_TARGET_DIR (default <repo>/target/embree4), CARGO_BUILD_JOBS (default 2),
#   DOFRAY_DEBIAN_MIRROR (override the mirror taken from the system's apt sources),
#   DOFRAY_EMBREE4_SUITE (default trixie).
# Needs only what Debian 12 has: apt, dpkg, cargo with clippy, libclang-dev (for bindgen).
set -euo pipefail

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cache=${DOFRAY_EMBREE4_CACHE:-${XDG_CACHE_HOME:-${HOME:?HOME or XDG_CACHE_HOME must be set}/.cache}/dofray/embree4}
target=${DOFRAY_EMBREE4_TARGET_DIR:-$repo/target/embree4}
main_target=${CARGO_TARGET_DIR:-$repo/target}
jobs=${CARGO_BUILD_JOBS:-2}
suite=${DOFRAY_EMBREE4_SUITE:-trixie}
run_clippy=1 seed=1 refresh=0

usage() { sed -n '/^# Usage:/,/^# Needs/p' "$0" | sed 's/^# \{0,1\}//'; }
while [ $# -gt 0 ]; do
  case "$1" in
    --cache-dir) cache=$2; shift 2 ;;
    --target-dir) target=$2; shift 2 ;;
    -j) jobs=$2; shift 2 ;;
    -j*) jobs=${1#-j}; shift ;;
    --no-clippy) run_clippy=0; shift ;;
    --no-seed) seed=0; shift ;;
    --refresh) refresh=1; shift ;;
    -h|--help) usage; exit 0 ;;
    *) echo "embree4-check: unknown argument: $1" >&2; usage >&2; exit 2 ;;
  esac
done
mkdir -p "$cache" "$target"
cache=$(cd "$cache" && pwd)
target=$(cd "$target" && pwd)

say() { printf '\n==> %s\n' "$*"; }
die() { printf 'embree4-check: error: %s\n' "$*" >&2; exit 1; }
# Exit status 3: the packages could not be fetched (no network to the mirror); nothing was tested.
die_fetch() { printf 'embree4-check: cannot fetch: %s\n' "$*" >&2; exit 3; }
elapsed() { local s=$(($(date +%s) - $1)); printf '%dm%02ds' $((s / 60)) $((s % 60)); }
start_all=$(date +%s)

arch=$(dpkg --print-architecture)
case "$arch" in
  amd64) multiarch=x86_64-linux-gnu ;;
  arm64) multiarch=aarch64-linux-gnu ;;
  *) die "unsupported architecture $arch" ;;
esac

root=$cache/root                      # the unpacked packages
prefix=$cache/prefix                  # EMBREE_DIR: include -> root/usr/include, lib -> root/usr/lib/<multiarch>
libdir=$root/usr/lib/$multiarch
manifest=$cache/manifest              # written last: the packages' names and versions

# --- 1. Debian 13's Embree 4 -------------------------------------------------------------------

# The Debian archive the system's apt already uses: the deb source whose suite is this
# system's codename (or a plain stable/testing/... suite), as apt itself reads the sources.
find_mirror() {
  if [ -n "${DOFRAY_DEBIAN_MIRROR:-}" ]; then
    echo "$DOFRAY_DEBIAN_MIRROR"
    return
  fi
  local codename
  codename=$(. /etc/os-release && echo "${VERSION_CODENAME:-}")
  apt-get indextargets --no-release-info --format '$(TARGET_OF) $(RELEASE) $(REPO_URI)' 2>/dev/null |
    awk -v c="$codename" '
      $1 == "deb" && $2 == c && !exact { exact = $3 }
      $1 == "deb" && $2 ~ /^(stable|oldstable|testing|unstable|sid|bullseye|bookworm|trixie|forky)$/ && !fallback { fallback = $3 }
      END { if (exact) print exact; else if (fallback) print fallback }'
}

prefix_ready() {
  [ -s "$manifest" ] && [ -f "$prefix/include/embree4/rtcore.h" ] &&
    [ -e "$prefix/lib/libembree4.so" ] && [ -n "$(find_loader)" ]
}

find_loader() {
  local l
  for l in "$libdir"/ld-linux*.so.*; do
    [ -x "$l" ] && { echo "$l"; return; }
  done
}

fetch_embree4() {
  local mirror keyring apt_dir debs
  mirror=$(find_mirror)
  [ -n "$mirror" ] || die "no Debian source found in the system's apt sources (/etc/apt/sources.list, /etc/apt/sources.list.d/); set DOFRAY_DEBIAN_MIRROR"
  apt_dir=$cache/apt
  debs=$cache/debs
  rm -rf "$apt_dir" "$debs" "$cache/root.new"
  mkdir -p "$apt_dir/sources.list.d" "$apt_dir/preferences.d" "$apt_dir/lists/partial" \
    "$apt_dir/cache/archives/partial" "$debs" "$cache/root.new"
  : > "$apt_dir/status"
  keyring=/usr/share/keyrings/debian-archive-keyring.gpg
  if [ -f "$keyring" ]; then
    echo "deb [arch=$arch target=Packages signed-by=$keyring] $mirror $suite main" > "$apt_dir/sources.list"
  else
    echo "deb [arch=$arch target=Packages] $mirror $suite main" > "$apt_dir/sources.list"
  fi
  # The system's apt.conf.d is still read (proxies and the like); every directory apt would
  # write to or read sources and pins from is our own.
  local apt_opts=(
    -o "Dir::Etc::SourceList=$apt_dir/sources.list"
    -o "Dir::Etc::SourceParts=$apt_dir/sources.list.d"
    -o "Dir::Etc::Preferences=$apt_dir/preferences"
    -o "Dir::Etc::PreferencesParts=$apt_dir/preferences.d"
    -o "Dir::State::Lists=$apt_dir/lists"
    -o "Dir::State::status=$apt_dir/status"
    -o "Dir::State::extended_states=$apt_dir/extended_states"
    -o "Dir::Cache=$apt_dir/cache"
    -o "Dir::Cache::pkgcache=" -o "Dir::Cache::srcpkgcache="
    -o "APT::Architecture=$arch" -o "APT::Architectures=$arch"
    -o "Acquire::Languages=none"
  )
  # apt's _apt sandbox user cannot reach a cache under root's home directory.
  if [ "$(id -u)" = 0 ]; then apt_opts+=(-o "APT::Sandbox::User=root"); fi
  say "Fetching Debian $suite's Embree 4 from $mirror (private apt state in $apt_dir)"
  if ! apt-get -q "${apt_opts[@]}" update > "$apt_dir/update.log" 2>&1; then
    cat "$apt_dir/update.log" >&2
    die_fetch "apt-get update for $suite failed (bookworm's debian-archive-keyring has $suite's keys)"
  fi
  grep -E '^(Get|Fetched|W:|E:)' "$apt_dir/update.log" || true
  # libembree4-4 and patchelf with everything they depend on (libc6, libstdc++6, libtbb12, ...);
  # libembree-dev for the header and the libembree4.so link (not its libtbb-dev dependency).
  local pkgs
  pkgs=$(apt-cache "${apt_opts[@]}" depends --recurse --no-recommends --no-suggests --no-conflicts \
    --no-breaks --no-replaces --no-enhances libembree4-4 patchelf | grep -v -e '^ ' -e '^<' | sort -u)
  [ -n "$pkgs" ] || die "apt-cache found no libembree4-4 in $suite"
  # shellcheck disable=SC2086
  echo "packages: libembree-dev" $pkgs
  # shellcheck disable=SC2086
  if ! (cd "$debs" && apt-get -q "${apt_opts[@]}" download libembree-dev $pkgs) > "$apt_dir/download.log" 2>&1; then
    cat "$apt_dir/download.log" >&2
    die_fetch "apt-get download failed"
  fi
  grep -E '^(Fetched|W:|E:)' "$apt_dir/download.log" || true
  local deb
  : > "$cache/manifest.new"
  for deb in "$debs"/*.deb; do
    dpkg-deb -x "$deb" "$cache/root.new"
    echo "$(dpkg-deb -f "$deb" Package) $(dpkg-deb -f "$deb" Version)" >> "$cache/manifest.new"
  done
  rm -rf "$root" "$manifest"
  mv "$cache/root.new" "$root"
  mkdir -p "$prefix"
  ln -sfn ../root/usr/include "$prefix/include"
  ln -sfn "../root/usr/lib/$multiarch" "$prefix/lib"
  [ -f "$prefix/include/embree4/rtcore.h" ] || die "libembree-dev has no include/embree4/rtcore.h"
  [ -e "$prefix/lib/libembree4.so" ] || die "libembree-dev has no libembree4.so"
  local loader
  loader=$(find_loader)
  [ -n "$loader" ] || die "no dynamic loader in $libdir (libc6 not fetched?)"
  # Every library libembree4 needs must come from the fetched packages.
  local list
  list=$("$loader" --library-path "$libdir" --list "$libdir/libembree4.so.4" 2>&1) ||
    die "$suite's loader cannot load libembree4: $list"
  if grep -q 'not found' <<< "$list"; then die "libembree4 dependencies missing: $list"; fi
  rm -rf "$debs" "$apt_dir/cache"
  mv "$cache/manifest.new" "$manifest"
}

if [ "$refresh" = 1 ] || ! prefix_ready; then
  fetch_embree4
else
  say "Using the cached Debian $suite Embree 4 in $cache (--refresh to fetch again)"
fi
loader=$(find_loader)
embree_version=$(awk '$1 == "libembree4-4" { print $2 }' "$manifest")
echo "prefix: $prefix (libembree4-4 $embree_version)"
sed 's/^/  /' "$manifest"
time_fetch=$(elapsed "$start_all")

# --- 2. Build against it -----------------------------------------------------------------------

export EMBREE_DIR=$prefix CARGO_TARGET_DIR=$target
cd "$repo"

# A new target directory starts from the normal build's compiled dependencies (copied under
# cargo's lock on it); cargo then recompiles only what EMBREE_DIR changes, dofray itself.
main_target=$(cd "$main_target" 2>/dev/null && pwd || echo "$main_target")
if [ "$seed" = 1 ] && [ "$main_target" != "$target" ] && [ ! -d "$target/debug/.fingerprint" ] &&
  [ -d "$main_target/debug/.fingerprint" ]; then
  say "Seeding $target/debug with the dependencies already built in $main_target/debug"
  mkdir -p "$target/debug"
  if flock -w 600 "$main_target/debug/.cargo-lock" \
    cp -a --reflink=auto "$main_target/debug/.fingerprint" "$main_target/debug/build" \
    "$main_target/debug/deps" "$target/debug/"; then
    echo "seeded ($(du -sh "$target/debug" | cut -f1))"
  else
    echo "could not copy under cargo's lock; building from scratch"
    rm -rf "$target/debug"
  fi
fi

declare -a rows=()
failed=0
row() { rows+=("$(printf '%-30s %-8s %s' "$1" "$2" "$3")"); }

say "Building dofray and its tests against Embree 4 (EMBREE_DIR=$EMBREE_DIR, CARGO_TARGET_DIR=$CARGO_TARGET_DIR, -j $jobs)"
start=$(date +%s)
artifacts=$target/embree4-check-artifacts.json
build_ok=1
if cargo test -j "$jobs" --no-run --message-format=json-render-diagnostics > "$artifacts"; then
  row "build" "ok" "($(elapsed "$start"))"
else
  build_ok=0 failed=1
  row "build" "FAILED" "cargo test --no-run failed against Embree 4 (errors above)"
fi

# --- 3. Test under Debian 13's loader ----------------------------------------------------------

total_passed=0 total_failed=0 total_ignored=0
declare -a skipped_binaries=()

run_tests() { # label log-name exe
  local label=$1 exe=$3 log rc result p f i
  log=$target/embree4-check-$2.log
  say "Testing $label: $loader --library-path $libdir $exe"
  set +e
  "$loader" --library-path "$libdir" "$exe" 2>&1 | tee "$log"
  rc=${PIPESTATUS[0]}
  set -e
  result=$(grep -E '^test result: ' "$log" | tail -1)
  p=$(sed -nE 's/.* ([0-9]+) passed.*/\1/p' <<< "$result")
  f=$(sed -nE 's/.* ([0-9]+) failed.*/\1/p' <<< "$result")
  i=$(sed -nE 's/.* ([0-9]+) ignored.*/\1/p' <<< "$result")
  p=${p:-0} f=${f:-0} i=${i:-0}
  total_passed=$((total_passed + p)) total_failed=$((total_failed + f)) total_ignored=$((total_ignored + i))
  if [ "$rc" = 0 ] && [ -n "$result" ]; then
    row "$label" "ok" "$p passed, $f failed, $i ignored"
  else
    failed=1
    [ "$f" != 0 ] || total_failed=$((total_failed + 1))
    if [ -n "$result" ]; then
      row "$label" "FAILED" "$p passed, $f failed, $i ignored (exit $rc)"
    else
      row "$label" "FAILED" "exit $rc before a test result (log: $log)"
    fi
  fi
}

if [ "$build_ok" = 1 ]; then
  # kind name executable, for every test executable cargo built (the lib's and the bin's unit
  # tests, tests/*.rs), and the dofray binary itself (tests/cli.rs runs it).
  tests=$(sed -nE 's/.*"target":\{"kind":\["([^"]+)"\][^}]*"name":"([^"]+)".*"profile":\{[^}]*"test":true\}.*"executable":"([^"]+)".*/\1 \2 \3/p' "$artifacts" | sort -u -k1,2)
  dofray_bin=$(sed -nE 's/.*"target":\{"kind":\["bin"\][^}]*"name":"dofray".*"profile":\{[^}]*"test":false\}.*"executable":"([^"]+)".*/\1/p' "$artifacts" | head -1)
  [ -n "$tests" ] || die "no test executables in cargo's output ($artifacts)"

  # tests/cli.rs spawns the dofray binary, which the kernel would start with the system's
  # loader (glibc 2.36, too old for libembree4). Give it trixie's loader as its interpreter and
  # an RPATH (unlike cargo's RUNPATH, also searched for libembree4's own libstdc++ and libtbb).
  cli_ok=0 cli_why=""
  patchelf=$root/usr/bin/patchelf
  if [ -z "$dofray_bin" ]; then
    cli_why="cargo built no dofray binary"
  elif [ ! -x "$patchelf" ]; then
    cli_why="no patchelf in $root"
  elif ! "$loader" --library-path "$libdir" "$patchelf" --set-interpreter "$loader" \
    --force-rpath --set-rpath "$libdir" "$dofray_bin"; then
    cli_why="patchelf failed on $dofray_bin"
  elif ! out=$("$dofray_bin" --help 2>&1); then
    cli_why="$dofray_bin does not start with $loader as its interpreter: $(head -3 <<< "$out")"
  else
    cli_ok=1
    echo "$dofray_bin: interpreter $loader, RPATH $libdir (for tests/cli.rs)"
  fi

  while read -r kind name exe; do
    case "$kind" in
      lib | bin) label="$name ($kind unit tests)" ;;
      *) label="$name" ;;
    esac
    if [ "$kind" = test ] && [ "$name" = cli ] && [ "$cli_ok" = 0 ]; then
      say "Skipping tests/cli.rs: $cli_why (the CLI tests spawn the dofray binary with the system loader)"
      row "$name" "SKIPPED" "$cli_why"
      skipped_binaries+=("$name")
      continue
    fi
    run_tests "$label" "$kind-$name" "$exe"
  done <<< "$tests"

  if [ "$run_clippy" = 1 ]; then
    say "cargo clippy --all-targets -- -D warnings against Embree 4"
    start=$(date +%s)
    if cargo clippy -j "$jobs" --all-targets -- -D warnings; then
      row "clippy" "ok" "($(elapsed "$start"))"
    else
      failed=1
      row "clippy" "FAILED" "cargo clippy --all-targets -- -D warnings (errors above)"
    fi
  fi
fi

# --- 4. Summary --------------------------------------------------------------------------------

printf '\n==> Embree 4 check: libembree4-4 %s (Debian %s) in %s\n' "$embree_version" "$suite" "$cache"
printf '    fetch %s, total %s; doc tests not run\n' "$time_fetch" "$(elapsed "$start_all")"
printf '    %s\n' "${rows[@]}"
if [ ${#skipped_binaries[@]} -gt 0 ]; then
  echo "    test binaries not run: ${skipped_binaries[*]}"
fi
if [ "$build_ok" = 1 ]; then
  echo "embree4: $total_passed passed, $total_failed failed, $total_ignored skipped"
else
  echo "embree4: the build failed, no test ran"
fi
if [ "$failed" != 0 ]; then
  echo "embree4-check: FAILED" >&2
  exit 1
fi
echo "embree4-check: all passed"
