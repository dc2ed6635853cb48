#!/usr/bin/env bash
# End-to-end test of dofray's farm rendering on a real single-node Slurm (docs/farm.md):
#
#   scripts/slurm-test.sh DOFRAY_BINARY WORKDIR
#   scripts/slurm-test.sh target/release/dofray /tmp/dofray-slurm-test
#
# 1. Starts the test cluster (.ci/slurm/cluster.sh) in WORKDIR/cluster; where Slurm cannot
#    run, prints "SKIP: ..." and exits 3.
# 2. From WORKDIR/farm (the "shared filesystem"), submits examples/slurm/render-array.sbatch
#    for the scene's frames and waits (sbatch --wait); every frame must be there.
# 3. Resume: deletes two frames, submits the same array again; exactly those two must be
#    rendered again and every other frame left untouched (--skip-existing).
# 4. Submits the tiled still and its merge with examples/slurm/submit.sh (the merge as a
#    job with --dependency=afterok on the tile array); waits for both; every task must
#    have COMPLETED and the merge must have started after the last tile ended.
# 5. Renders the same frames and the still locally in WORKDIR/local, with no SLURM_* nor
#    Kubernetes variables in the environment, and compares every frame and the merged still
#    (and the tiles, where the local render keeps them) pixel for pixel: oiiotool -a
#    --fail 0 --failpercent 0 --hardfail 0 A B --diff, which fails on any difference in
#    any channel of any subimage, a 1-ulp float difference, inf against a number or NaN
#    against a number; metadata (timings) is not compared.
# 6. Checks the sharding itself, without Slurm: the frames rendered with each of the 4 sets
#    of Slurm array variables must split the sequence (disjoint, together all of it, none
#    empty), Kubernetes' JOB_COMPLETION_INDEX + DOFRAY_SHARD_COUNT must split it the same
#    way, and --shard I/N must override the variables.
# Stops the cluster on exit, pass or fail. Exit 0: all passed; 1: a check failed; 2: usage;
# 3: skipped. Settings (environment):
#   DOFRAY_TEST_SCENE   scene file (default: scenes/focus_pull.toml of this repository)
#   DOFRAY_TEST_FRAMES  frames (default 1-8)
#   DOFRAY_TEST_ARGS    extra render flags, for speed (default "--width 160 --height 120")
#   DOFRAY_TEST_TILES   tile grid of the still (default 2x2)
#   DOFRAY_TEST_TIMEOUT seconds each Slurm phase may take (default 900)
set -euo pipefail

if [ $# -ne 2 ]; then
  sed -n '2,6p' "$0" >&2
  exit 2
fi
repo=$(cd "$(dirname "$0")/.." && pwd)
bin=$1
work=$2
[ -x "$bin" ] || { echo "not an executable: $bin" >&2; exit 2; }
bin=$(cd "$(dirname "$bin")" && pwd)/$(basename "$bin")
scene=${DOFRAY_TEST_SCENE:-$repo/scenes/focus_pull.toml}
[ -f "$scene" ] || { echo "no scene $scene (set DOFRAY_TEST_SCENE)" >&2; exit 2; }
scene=$(cd "$(dirname "$scene")" && pwd)/$(basename "$scene")
frames=${DOFRAY_TEST_FRAMES:-1-8}
read -r -a args <<<"${DOFRAY_TEST_ARGS:---width 160 --height 120}"
tiles=${DOFRAY_TEST_TILES:-2x2}
limit=${DOFRAY_TEST_TIMEOUT:-900}
command -v oiiotool >/dev/null || { echo "SKIP: no oiiotool to compare images (apt-get install openimageio-tools)"; exit 3; }

mkdir -p "$work"
work=$(cd "$work" && pwd)
cluster=$work/cluster farm=$work/farm local=$work/local shards=$work/shards
rm -rf "$farm" "$local" "$shards"
mkdir -p "$farm" "$local" "$shards"

passed=0
failures=()
ok() {
  passed=$((passed + 1))
  echo "ok: $*"
}
bad() {
  failures+=("$*")
  echo "FAILED: $*"
}
# A failure after which the rest cannot run: say what failed, show the job logs, exit.
fatal() {
  echo "FAILED: $*"
  local f
  for f in "$farm"/*.log; do
    [ -f "$f" ] || continue
    echo "----- $f"
    tail -n 30 "$f"
  done
  echo "FAIL: slurm-test stopped at: $* ($passed checks had passed; work in $work)"
  exit 1
}

# The frame numbers, one a line: "1-8,10" -> 1..8, 10.
frame_list() {
  local part parts
  IFS=, read -r -a parts <<<"$frames"
  for part in "${parts[@]}"; do
    if [[ $part =~ ^([0-9]+)-([0-9]+)$ ]]; then
      seq "${BASH_REMATCH[1]}" "${BASH_REMATCH[2]}"
    else
      echo "$part"
    fi
  done
}
mapfile -t frame_numbers < <(frame_list)
frame_file() { printf '%s/frames_%04d.png' "$1" "$2"; }
[[ $tiles =~ ^([0-9]+)x([0-9]+)$ ]] || { echo "DOFRAY_TEST_TILES wants CxR" >&2; exit 2; }
ntiles=$((BASH_REMATCH[1] * BASH_REMATCH[2]))

# dofray with none of the variables it reads its shard from (nor any other SLURM_*).
local_dofray() {
  local unset=() v
  for v in $(compgen -e); do
    case "$v" in
      SLURM_* | JOB_COMPLETION_INDEX | DOFRAY_SHARD_COUNT) unset+=(-u "$v") ;;
    esac
  done
  env "${unset[@]}" "$@"
}

same_pixels() { # A B -> 0 when every pixel value of every channel and subimage is equal
  oiiotool -a --fail 0 --failpercent 0 --hardfail 0 "$1" "$2" --diff >"$work/diff.txt" 2>&1
}

echo "== dofray farm test: $bin, scene $scene, frames $frames, tiles $tiles, flags ${args[*]}"

# --- 1. the cluster -------------------------------------------------------------------------
rc=0
bash "$repo/.ci/slurm/cluster.sh" start "$cluster" || rc=$?
if [ "$rc" = 3 ]; then
  echo "SKIP: slurm-test: the Slurm test cluster cannot run here (see above)"
  exit 3
fi
[ "$rc" = 0 ] || exit "$rc"
trap 'cd / && bash "$repo/.ci/slurm/cluster.sh" stop "$cluster" >/dev/null 2>&1 || true' EXIT
# shellcheck disable=SC1091
. "$cluster/env.sh"
export DOFRAY="$bin"
cd "$farm"

# --- 2. the frame sequence as a job array --------------------------------------------------
# One CPU per task instead of the script's 2, so that two tasks share this 2-core node.
submit_frames() { # sets job
  job=$(timeout "$limit" sbatch --parsable --wait --cpus-per-task=1 \
    "$repo/examples/slurm/render-array.sbatch" "$scene" "out/frames_####.png" \
    --frames "$frames" "${args[@]}") || fatal "the frame array failed or timed out (sbatch --wait: $?)"
  job=${job%%;*}
}
submit_frames
frames_job=$job
missing=()
for f in "${frame_numbers[@]}"; do
  [ -f "$(frame_file out "$f")" ] || missing+=("$f")
done
[ ${#missing[@]} -eq 0 ] || fatal "array $frames_job left frames missing: ${missing[*]}"
ok "array $frames_job (render-array.sbatch, 4 tasks) rendered all ${#frame_numbers[@]} frames"
for i in 0 1 2 3; do
  [ -f "dofray-frames-${frames_job}_$i.log" ] || bad "no log dofray-frames-${frames_job}_$i.log"
done

# --- 3. resume with --skip-existing ----------------------------------------------------------
first=${frame_numbers[0]}
last=${frame_numbers[${#frame_numbers[@]} - 1]}
declare -A stamp
for f in "${frame_numbers[@]}"; do
  stamp[$f]=$(stat -c '%i %y' "$(frame_file out "$f")")
done
rm -f "$(frame_file out "$first")" "$(frame_file out "$last")"
submit_frames
resume_job=$job
resumed_ok=1
for f in "${frame_numbers[@]}"; do
  file=$(frame_file out "$f")
  if [ ! -f "$file" ]; then
    bad "resume: array $resume_job did not render the deleted frame $f"
    resumed_ok=0
  elif [ "$f" != "$first" ] && [ "$f" != "$last" ] && [ "$(stat -c '%i %y' "$file")" != "${stamp[$f]}" ]; then
    bad "resume: array $resume_job rewrote frame $f, which existed (--skip-existing)"
    resumed_ok=0
  fi
done
[ "$resumed_ok" = 0 ] || ok "resume: array $resume_job rendered only the deleted frames $first and $last"

# --- 4. the tiled still and the dependent merge ----------------------------------------------
submitted=$(TILES=$tiles SBATCH_ARGS="--cpus-per-task=1" \
  bash "$repo/examples/slurm/submit.sh" "$scene" out/still.exr "${args[@]}") ||
  fatal "examples/slurm/submit.sh failed"
echo "$submitted"
tiles_job=$(sed -n 's/^tiles: job array \([0-9]*\).*/\1/p' <<<"$submitted")
merge_job=$(sed -n 's/^merge: job \([0-9]*\).*/\1/p' <<<"$submitted")
[ -n "$tiles_job" ] && [ -n "$merge_job" ] || fatal "could not read the job ids from submit.sh"
for ((s = 0; s < limit; s++)); do
  [ -z "$(squeue -h -j "$tiles_job,$merge_job" -o %i 2>/dev/null)" ] && break
  sleep 1
done
[ "$s" -lt "$limit" ] || fatal "tiles $tiles_job / merge $merge_job not done after $limit s"
# Finished jobs stay in scontrol for MinJobAge (300 s): their states and times.
job_field() { # JOB FIELD -> one value per job record (an array gives one per task)
  scontrol -o show job "$1" | grep -o " $2=[^ ]*" | cut -d= -f2
}
mapfile -t tile_states < <(job_field "$tiles_job" JobState)
mapfile -t tile_ends < <(job_field "$tiles_job" EndTime | sort)
merge_state=$(job_field "$merge_job" JobState)
merge_start=$(job_field "$merge_job" StartTime)
if [ "${#tile_states[@]}" -ne 4 ] || printf '%s\n' "${tile_states[@]}" | grep -qv '^COMPLETED$'; then
  fatal "tile array $tiles_job: task states ${tile_states[*]}"
fi
[ "$merge_state" = COMPLETED ] || fatal "merge job $merge_job: $merge_state"
ok "tile array $tiles_job: 4 tasks COMPLETED; merge job $merge_job COMPLETED"
last_end=${tile_ends[${#tile_ends[@]} - 1]}
if [[ ! $merge_start < $last_end ]]; then
  ok "merge started $merge_start, after the last tile ended $last_end (afterok)"
else
  bad "merge started $merge_start before the last tile ended $last_end"
fi
[ -f out/still.exr ] || fatal "the merge wrote no out/still.exr"

# --- 5. local renders and the pixel comparison ---------------------------------------------
cd "$work"
local_dofray "$bin" render "$scene" -o "local/frames_####.png" --frames "$frames" "${args[@]}" \
  >"$work/local-frames.log" 2>&1 || fatal "local render of the frames failed: $(tail -n 5 "$work/local-frames.log")"
local_dofray "$bin" render "$scene" --tiles "$tiles" -o local/still.exr "${args[@]}" \
  >"$work/local-still.log" 2>&1 || fatal "local render of the still failed: $(tail -n 5 "$work/local-still.log")"
# The same still in one piece: tiles must assemble into exactly the untiled render.
local_dofray "$bin" render "$scene" -o local/whole.exr "${args[@]}" \
  >"$work/local-whole.log" 2>&1 || fatal "local render of the untiled still failed: $(tail -n 5 "$work/local-whole.log")"
same=0
for f in "${frame_numbers[@]}"; do
  a=$(frame_file farm/out "$f") b=$(frame_file local "$f")
  if [ ! -f "$b" ]; then
    bad "local render wrote no $b"
  elif same_pixels "$a" "$b"; then
    same=$((same + 1))
  else
    bad "frame $f: farm and local renders differ: $(tail -n 4 "$work/diff.txt" | tr '\n' ' ')"
  fi
done
[ "$same" -ne "${#frame_numbers[@]}" ] || ok "all $same frames from Slurm are pixel-identical to the local render"
if [ ! -f local/still.exr ]; then
  bad "the local tiled render wrote no local/still.exr"
elif same_pixels farm/out/still.exr local/still.exr; then
  ok "the merged still from Slurm is pixel-identical to the local tiled render"
else
  bad "the merged still differs from the local render: $(tail -n 4 "$work/diff.txt" | tr '\n' ' ')"
fi
if same_pixels farm/out/still.exr local/whole.exr; then
  ok "the merged still from Slurm is pixel-identical to the untiled local render"
else
  bad "the merged still differs from the untiled render: $(tail -n 4 "$work/diff.txt" | tr '\n' ' ')"
fi
same=0 compared=0
for ((t = 0; t < ntiles; t++)); do
  tile=$(printf 'still.tile-%03d.exr' "$t")
  [ -f "farm/out/$tile" ] || { bad "no tile farm/out/$tile"; continue; }
  [ -f "local/$tile" ] || continue # a local (unsharded) render may merge and keep no tiles
  compared=$((compared + 1))
  if same_pixels "farm/out/$tile" "local/$tile"; then
    same=$((same + 1))
  else
    bad "tile $t: farm and local differ"
  fi
done
[ "$compared" = 0 ] || [ "$same" -ne "$compared" ] || ok "all $same tiles from Slurm are pixel-identical to the local ones"

# --- 6. how the shard is chosen --------------------------------------------------------------
# Renders into shards/NAME/ and sets got to the frame numbers written, space-separated.
shard_frames() { # NAME then env assignments and dofray flags
  local name=$1 dir="$shards/$1" a assign=() flags=()
  shift
  for a in "$@"; do
    if [[ $a == *=* && $a != -* ]]; then assign+=("$a"); else flags+=("$a"); fi
  done
  got=""
  mkdir -p "$dir"
  (cd "$dir" && local_dofray "${assign[@]}" "$bin" render "$scene" -o "frames_####.png" \
    --frames "$frames" "${flags[@]}" "${args[@]}") >"$dir.log" 2>&1 || {
    bad "shard render $name failed: $(tail -n 3 "$dir.log" | tr '\n' ' ')"
    return 0
  }
  local f out=()
  for f in "${frame_numbers[@]}"; do
    [ -f "$(frame_file "$dir" "$f")" ] && out+=("$f")
  done
  got="${out[*]}"
}
declare -A slurm_set k8s_set
for i in 0 1 2 3; do
  shard_frames "slurm-$i" SLURM_ARRAY_TASK_ID=$((i + 10)) SLURM_ARRAY_TASK_MIN=10 \
    SLURM_ARRAY_TASK_MAX=13 SLURM_ARRAY_TASK_COUNT=4 SLURM_ARRAY_TASK_STEP=1 SLURM_ARRAY_JOB_ID=99
  slurm_set[$i]=$got
  shard_frames "k8s-$i" JOB_COMPLETION_INDEX=$i DOFRAY_SHARD_COUNT=4
  k8s_set[$i]=$got
  echo "shard $i/4: Slurm task $((i + 10)) of 10-13 -> frames [${slurm_set[$i]}]; JOB_COMPLETION_INDEX=$i -> [${k8s_set[$i]}]"
done
all=$(printf '%s\n' "${slurm_set[@]}" | tr ' ' '\n' | grep . | sort -n | tr '\n' ' ')
want=$(printf '%s\n' "${frame_numbers[@]}" | sort -n | tr '\n' ' ')
empty=0
for i in 0 1 2 3; do
  [ -n "${slurm_set[$i]}" ] || empty=1
done
if [ "$all" = "$want" ] && { [ "$empty" = 0 ] || [ ${#frame_numbers[@]} -lt 4 ]; }; then
  ok "the 4 Slurm array shards split the frames: disjoint, all covered, none empty"
else
  bad "the 4 Slurm array shards do not split the frames: together [$all], want [$want]"
fi
k8s_same=1
for i in 0 1 2 3; do
  [ "${k8s_set[$i]}" = "${slurm_set[$i]}" ] || k8s_same=0
done
if [ "$k8s_same" = 1 ]; then
  ok "JOB_COMPLETION_INDEX + DOFRAY_SHARD_COUNT give the same shards as the Slurm variables"
else
  bad "Kubernetes shards differ from the Slurm shards"
fi
shard_frames override SLURM_ARRAY_TASK_ID=0 SLURM_ARRAY_TASK_MIN=0 SLURM_ARRAY_TASK_MAX=3 \
  SLURM_ARRAY_TASK_COUNT=4 SLURM_ARRAY_TASK_STEP=1 --shard 1/4
override=$got
if [ "$override" = "${slurm_set[1]}" ]; then
  ok "--shard 1/4 overrides the Slurm variables (task 0): frames [$override]"
else
  bad "--shard 1/4 with SLURM_ARRAY_TASK_ID=0 rendered [$override], want [${slurm_set[1]}]"
fi

# --- result ----------------------------------------------------------------------------------
if [ ${#failures[@]} -gt 0 ]; then
  echo "FAIL: slurm-test: ${#failures[@]} checks failed, $passed passed (work in $work):"
  printf '  - %s\n' "${failures[@]}"
  exit 1
fi
echo "PASS: slurm-test: all $passed checks passed (Slurm array, resume, tiles + dependent merge, pixel-identical to local, sharding)"
