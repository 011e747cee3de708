#!/usr/bin/env bash
# Resubmits the array tasks of an insgen Slurm submission that did not finish (no .done mark; see
# submit.sh), with the same configuration and shard numbering (--shard auto/N uses the array index),
# and a new merge job after them. Finished tasks are not run again.
#
# Usage: scripts/slurm/resubmit.sh WORKDIR   (partition and resources as given to submit.sh)
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
workdir="${1:?usage: resubmit.sh WORKDIR}"
config="$workdir/slurm/config.env"
[ -f "$config" ] || { echo "resubmit.sh: $config not found (was the dataset submitted with submit.sh?)" >&2; exit 2; }
# shellcheck disable=SC1090
source "$config"
logs="$WORKDIR/slurm/logs"
common=(--parsable --kill-on-invalid-dep=yes --cpus-per-task 2)
[ -n "$PARTITION" ] && common+=(--partition "$PARTITION")
# shellcheck disable=SC2206
common+=($RESOURCES)
missing() { # stage → comma-separated indices without a .done mark
    local out=() i
    for ((i = 0; i < TASKS; i++)); do
        [ -e "$WORKDIR/.shards/$1-$i.done" ] || out+=("$i")
    done
    (IFS=,; echo "${out[*]}")
}
deps=()
stages=(masks)
[ "$RGB" = 1 ] && stages+=(rgb)
[ -n "${LOC:-}" ] && stages+=(loc)
masks_job=""
for stage in "${stages[@]}"; do
    todo="$(missing "$stage")"
    [ -n "$todo" ] || continue
    extra=()
    # shellcheck disable=SC2206
    [ "$stage" = rgb ] && extra=($RGB_RESOURCES)
    # shellcheck disable=SC2206
    [ "$stage" = loc ] && extra=($LOC_RESOURCES)
    # eval-loc tasks read the masks shards: after the resubmitted masks tasks, if any.
    [ "$stage" = loc ] && [ -n "$masks_job" ] && extra+=(--dependency "afterok:$masks_job")
    job=$(sbatch "${common[@]}" --job-name "insgen-$stage" --array "$todo" "${extra[@]}" \
        --output "$logs/%x-%A_%a.log" "$here/task.sh" "$config" "$stage")
    echo "resubmitted $stage tasks $todo as job $job"
    [ "$stage" = masks ] && masks_job="$job"
    deps+=("$job")
done
dep=()
[ ${#deps[@]} -gt 0 ] && dep=(--dependency "afterok:$(IFS=:; echo "${deps[*]}")")
merge=$(sbatch "${common[@]}" --job-name insgen-merge "${dep[@]}" \
    --output "$logs/%x-%j.log" "$here/task.sh" "$config" merge)
echo "merge job $merge"
