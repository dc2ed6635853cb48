#!/usr/bin/env bash
# Proves the test cluster of .ci/slurm/cluster.sh runs real job arrays, without dofray:
#
#   .ci/slurm/selftest.sh [WORKDIR]     (default: a new directory under /tmp)
#
# Starts the cluster in WORKDIR/cluster, submits from WORKDIR/jobs a 4-task array
# (sbatch --array=0-3 --wait) whose tasks write their Slurm array variables, working
# directory and PATH to files there and sleep a little, then a job that depends on it
# (--dependency=afterok:ID) and concatenates those files. Checks:
# - every task ran once, with SLURM_ARRAY_TASK_ID = its index and MIN/MAX/COUNT/STEP =
#   0/3/4/1 (what dofray reads to choose its shard);
# - each task's cwd was the submitting directory and its PATH the submitter's;
# - never more tasks at once than the machine has CPUs (one core each: 2 here), and more
#   than one at once on a machine of 2 or more;
# - the dependent job ran after all of them and saw their files.
# Stops the cluster on exit, pass or fail (a WORKDIR it made itself is removed after a pass or a skip). Exit 0: passed; 3: Slurm cannot run here (SKIP);
# anything else: failed.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
made=""
if [ $# -ge 1 ]; then
  work=$1
else
  work=$(mktemp -d /tmp/dofray-slurm-selftest.XXXXXX)
  made=1 # removed again after a pass
fi
mkdir -p "$work"
work=$(cd "$work" && pwd)
cluster="$work/cluster"

rc=0
bash "$here/cluster.sh" start "$cluster" || rc=$?
if [ "$rc" != 0 ]; then
  [ -z "$made" ] || rm -rf "$work"
  exit "$rc"
fi
trap 'cd / && bash "$here/cluster.sh" stop "$cluster" >/dev/null || true' EXIT
# shellcheck disable=SC1091
. "$cluster/env.sh"

jobs="$work/jobs"
rm -rf "$jobs"
mkdir -p "$jobs/out"
cd "$jobs"
cpus=$(nproc)

cat >array.sbatch <<'EOF'
#!/bin/bash
#SBATCH --job-name=selftest-array
#SBATCH --array=0-3
#SBATCH --cpus-per-task=1
#SBATCH --output=out/array_%A_%a.log
set -eu
f=out/task_${SLURM_ARRAY_TASK_ID}.txt
{
  echo "ids $SLURM_ARRAY_TASK_ID $SLURM_ARRAY_TASK_MIN $SLURM_ARRAY_TASK_MAX $SLURM_ARRAY_TASK_COUNT ${SLURM_ARRAY_TASK_STEP:-unset}"
  echo "job $SLURM_ARRAY_JOB_ID $SLURM_JOB_ID"
  echo "cwd $PWD"
  echo "path $PATH"
  echo "start $(date +%s.%N)"
} >"$f.tmp"
sleep 3
echo "end $(date +%s.%N)" >>"$f.tmp"
mv "$f.tmp" "$f"
EOF

cat >gather.sbatch <<'EOF'
#!/bin/bash
#SBATCH --job-name=selftest-gather
#SBATCH --output=out/gather_%j.log
set -eu
cat out/task_0.txt out/task_1.txt out/task_2.txt out/task_3.txt >out/all.txt
echo "gathered by job $SLURM_JOB_ID" >>out/all.txt
EOF

fail() {
  echo "FAIL: $*" >&2
  for f in out/*; do
    echo "----- $f" >&2
    cat "$f" >&2
  done
  squeue >&2 || true
  exit 1
}

# --parsable prints "JOBID" (or "JOBID;CLUSTER"); with --wait, sbatch returns when every
# task has ended, with a non-zero status if any failed.
array_id=$(timeout 120 sbatch --parsable --wait array.sbatch) || fail "array job failed or timed out"
array_id=${array_id%%;*}
echo "array job $array_id done"
gather_id=$(sbatch --parsable --wait --dependency=afterok:"$array_id" gather.sbatch) ||
  fail "dependent job failed"
gather_id=${gather_id%%;*}
echo "dependent job $gather_id done"

[ -f out/all.txt ] || fail "the dependent job wrote no out/all.txt"
starts=()
ends=()
for i in 0 1 2 3; do
  f=out/task_$i.txt
  [ -f "$f" ] || fail "task $i wrote no $f"
  line=$(grep '^ids ' "$f")
  echo "task $i: SLURM_ARRAY_TASK_ID/MIN/MAX/COUNT/STEP = ${line#ids }"
  [ "$line" = "ids $i 0 3 4 1" ] || fail "task $i: array variables '$line', want 'ids $i 0 3 4 1'"
  [ "$(grep '^cwd ' "$f")" = "cwd $jobs" ] || fail "task $i ran in $(grep '^cwd ' "$f"), not $jobs"
  [ "$(grep '^path ' "$f")" = "path $PATH" ] || fail "task $i had another PATH: $(grep '^path ' "$f")"
  [ "$(grep '^job ' "$f" | cut -d' ' -f2)" = "$array_id" ] || fail "task $i: SLURM_ARRAY_JOB_ID is not $array_id"
  starts+=("$(sed -n 's/^start //p' "$f")")
  ends+=("$(sed -n 's/^end //p' "$f")")
done
for i in 0 1 2 3; do
  grep -qx "ids $i 0 3 4 1" out/all.txt || fail "out/all.txt lacks task $i's line"
done

# Most tasks running at any moment: count, at each task's start, the tasks running then.
most=$(
  for i in 0 1 2 3; do
    n=0
    for j in 0 1 2 3; do
      if awk -v s="${starts[$j]}" -v e="${ends[$j]}" -v t="${starts[$i]}" 'BEGIN { exit !(s <= t && t < e) }'; then
        n=$((n + 1))
      fi
    done
    echo "$n"
  done | sort -n | tail -n 1
)
echo "at most $most array tasks ran at once ($cpus CPUs)"
[ "$cpus" -lt 2 ] || [ "$most" -ge 2 ] || fail "tasks ran one at a time on $cpus CPUs"
[ "$most" -le "$cpus" ] || fail "$most tasks ran at once on $cpus CPUs"

echo "PASS: Slurm self-test (4-task array and a dependent job: array variables, cwd, PATH, at most $most at once)"
if [ -n "$made" ]; then
  cd /
  bash "$here/cluster.sh" stop "$cluster" >/dev/null
  rm -rf "$work"
fi
