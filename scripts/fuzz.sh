#!/usr/bin/env bash
# Fuzzes dofray's input parsers with cargo-fuzz (libFuzzer): the targets in fuzz/fuzz_targets/
# (scene files, OBJ + MTL, glTF/GLB, the EXR and PNG tiles of `dofray merge`, frame lists and
# frame-numbered output names; docs/fuzzing.md). Each target runs for SECONDS_PER_TARGET
# (default 20) from its seed corpus in fuzz/corpus/TARGET (read only: what the run finds goes
# to a scratch corpus that is removed), with -rss_limit_mb=2048 and -timeout=10.
#
# Usage: scripts/fuzz.sh [SECONDS_PER_TARGET]
# Environment:
#   FUZZ_TARGETS    the targets to run, space-separated (default: all of them)
#   FUZZ_SANITIZER  cargo fuzz's -s: none (default: safe Rust needs no ASan, and it builds in
#                   half the time) or address (also reports any single allocation over 2 GiB)
#   FUZZ_SEED=N     libFuzzer's random seed (CI fixes it, so its run is repeatable; default
#                   a new one each run)
#   FUZZ_KEEP=DIR   keep the corpora the runs grew in DIR/TARGET (to merge into the seeds)
#   FUZZ_TARGET_DIR build there instead of fuzz/target (CI: a cache outside the checkout, so
#                   the dependencies are built once per machine; dofray and the fuzz crate
#                   are cleaned out of it first, so checkouts in other folders do not pile up)
# Exit status: 0 nothing found; 1 a crash, panic, timeout or out-of-memory (the input is
# saved as fuzz/artifacts/TARGET/crash-* etc., and the command to reproduce it is printed);
# 3 skipped: cargo-fuzz is missing and could not be installed (no network), with a notice.
#
# Stable Rust only here: RUSTC_BOOTSTRAP=1 lets it take the nightly flags cargo-fuzz passes.
set -euo pipefail

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$repo"
secs=${1:-20}
case "$secs" in '' | *[!0-9]*) echo "usage: scripts/fuzz.sh [SECONDS_PER_TARGET]" >&2; exit 2 ;; esac
sanitizer=${FUZZ_SANITIZER:-none}
read -r -a targets <<<"${FUZZ_TARGETS:-scene_file obj_mtl gltf_glb merge_tile frames frame_pattern lens_file}"
export RUSTC_BOOTSTRAP=1
CARGO_FUZZ_VERSION=0.13.2

if ! cargo fuzz --version >/dev/null 2>&1; then
  echo "installing cargo-fuzz $CARGO_FUZZ_VERSION (cargo install)"
  if ! cargo install cargo-fuzz --version "$CARGO_FUZZ_VERSION" --locked; then
    echo "NOTICE: fuzzing skipped: cargo-fuzz could not be installed (no network?)" >&2
    exit 3
  fi
fi

fuzz=(cargo fuzz)
# 16 codegen units instead of cargo-fuzz's 1: dofray builds in 40 s instead of 70 s on two
# cores, and the targets ran no slower here.
build_flags=(--fuzz-dir fuzz -s "$sanitizer" --codegen-units 16)
start=$(date +%s)
if [ -n "${FUZZ_TARGET_DIR:-}" ]; then
  build_flags+=(--target-dir "$FUZZ_TARGET_DIR")
  cargo clean --manifest-path fuzz/Cargo.toml --target-dir "$FUZZ_TARGET_DIR" --release \
    --target "$(rustc -vV | sed -n 's/^host: //p')" -p dofray -p dofray-fuzz >/dev/null 2>&1 || true
fi
"${fuzz[@]}" build "${build_flags[@]}"
echo "fuzz: built the targets in $(($(date +%s) - start)) s (sanitizer: $sanitizer)"

work=$(mktemp -d "${TMPDIR:-/tmp}/dofray-fuzz.XXXXXX")
trap 'rm -rf "$work"' EXIT
# The targets' scratch folders (inputs written as files) go here too, and are removed with it.
mkdir -p "$work/tmp"

failed=()
for t in "${targets[@]}"; do
  grown="$work/corpus/$t"
  mkdir -p "$grown"
  log="$work/$t.log"
  rc=0
  TMPDIR="$work/tmp" "${fuzz[@]}" run "${build_flags[@]}" "$t" "$grown" "fuzz/corpus/$t" -- \
    -max_total_time="$secs" -rss_limit_mb=2048 -timeout=10 -print_final_stats=1 ${FUZZ_SEED:+-seed="$FUZZ_SEED"} \
    >"$log" 2>&1 || rc=$?
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n 1)
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -n 1 || true)
  if [ "$rc" = 0 ]; then
    echo "fuzz: $t: ${execs:-?} runs in $secs s, ${cov:-cov: ?}, corpus $(find "$grown" -type f | wc -l) new inputs; nothing found"
  else
    echo "FAIL: fuzz: $t (exit $rc) after ${execs:-?} runs; the end of its log:" >&2
    grep -v -e '^#[0-9]' -e 'NEW_FUNC' "$log" | tail -n 80 >&2 || true
    failed+=("$t")
  fi
  if [ -n "${FUZZ_KEEP:-}" ]; then
    mkdir -p "$FUZZ_KEEP/$t"
    cp -r "$grown/." "$FUZZ_KEEP/$t/"
  fi
done

echo "fuzz: $(($(date +%s) - start)) s in all"
echo "fuzz: $((${#targets[@]} - ${#failed[@]})) passed, ${#failed[@]} failed"
if [ ${#failed[@]} -gt 0 ]; then
  echo "FAIL: fuzz: found something in: ${failed[*]} (inputs under fuzz/artifacts/; reproduce" \
    "with RUSTC_BOOTSTRAP=1 cargo fuzz run ${build_flags[*]} TARGET ARTIFACT)" >&2
  exit 1
fi
