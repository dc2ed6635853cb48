#!/usr/bin/env bash
# Submit a tiled still to Slurm: the tile array, then the merge as a job that runs only
# when every tile task has succeeded (docs/farm.md). Prints the two job ids.
#
#   examples/slurm/submit.sh [SCENE [OUTPUT.exr [DOFRAY_ARGS...]]]
#   examples/slurm/submit.sh scenes/focus_pull.toml out/still.exr --width 1920 --height 1080
#
# Run it from the shared directory the tasks should work in. Extra sbatch options for both
# jobs: SBATCH_ARGS (e.g. SBATCH_ARGS="--partition=render --time=01:00:00"); the array
# size: ARRAY (default 0-3); the tile grid: TILES (default 2x2, read by render-tiles).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)

scene=${1:-scenes/focus_pull.toml}
output=${2:-out/still.exr}
shift $(($# < 2 ? $# : 2))
read -r -a extra <<<"${SBATCH_ARGS:-}"

# --parsable prints "JOBID" or "JOBID;CLUSTER": keep the id.
tiles_job=$(sbatch --parsable "${extra[@]}" --array="${ARRAY:-0-3}" \
  "$here/render-tiles.sbatch" "$scene" "$output" "$@")
tiles_job=${tiles_job%%;*}
echo "tiles: job array $tiles_job"

# afterok on the array's id: after all of its tasks, and only if all succeeded.
# --kill-on-invalid-dep=yes: if a tile task fails, the merge is cancelled instead of
# staying pending forever.
merge_job=$(sbatch --parsable "${extra[@]}" --dependency=afterok:"$tiles_job" \
  --kill-on-invalid-dep=yes "$here/merge.sbatch" "$output")
merge_job=${merge_job%%;*}
echo "merge: job $merge_job (after $tiles_job succeeds)"
