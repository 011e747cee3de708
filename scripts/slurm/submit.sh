#!/usr/bin/env bash
# Submits a whole insgen dataset to Slurm as dependent jobs:
#
#   prep  (1 task)         prepare + sample every area                       → <workdir>
#   masks (array of N)     render-masks --shard auto/N, in node-local scratch → <workdir>/.shards/masks-<i>
#                          (label-only: also export-coco --shard auto/N, a COCO part per task)
#   rgb   (array of N)     render-rgb   --shard auto/N (with --rgb; GPU)      → <workdir>/.shards/rgb-<i>
#   loc   (array of N)     eval-loc --shard auto/N (with --eval-loc), after masks: task i localizes
#                          the queries of masks shard i                     → <workdir>/.shards/loc-<i>
#   merge (1 task)         insgen merge of all shards (combining the COCO parts and the eval-loc
#                          parts), or with --rgb a merge then one export-coco  → <workdir>/coco,
#                                                          <workdir>/<area>/<camera>/loc/<tag>
#
# Each job starts when the ones before it succeeded (afterok). Every task logs to
# <logs>/<job>-<jobid>_<task>.log. Tasks are resumable (finished frames are skipped) and a task marks
# its shard done only when it finished; scripts/slurm/resubmit.sh resubmits the tasks without that
# mark, and a new merge job after them.
#
# Resources: every job asks for 2 CPUs; add what your cluster needs with --resources (all jobs) and
# --rgb-resources (the RGB array). What the stages use, measured on the demo: masks are CPU only
# (wgpu on lavapipe, or a GPU when the node has Vulkan), ~1 GB per task at 1920×1080; RGB is Blender
# Cycles, 2–4 GB per task, and wants one GPU (--rgb-resources "--gres gpu:1"); prep and merge are light.
# eval-loc (--eval-loc oracle, or --eval-loc PREDICTIONS.json for a model's COCO results) is CPU work
# that uses every core it gets (rayon; its renders go through wgpu like the masks), with memory of
# the order of the masks task's (the scene plus a few query-sized images per core): give it cores
# with --loc-resources "--cpus-per-task 8" (not measured on a cluster; the search costs roughly
# hypotheses × render time, see docs/localization.md). --loc-tag names loc/<tag> (default: the
# tag eval-loc derives from its options); --loc-args passes further eval-loc options (e.g. "--cost
# instance --limit 20", or "--coco /path/instances_test.json", which --eval-loc PREDICTIONS needs
# as the COCO file the predictions refer to).
#
# Usage: scripts/slurm/submit.sh --areas "demo demo-val" [--camera cam2] [--count 72] [--tasks 8]
#          [--rgb] [--workdir runs] [--scenes scenes] [--insgen BIN] [--scratch DIR] [--logs DIR]
#          [--partition P] [--resources "--mem 4G"] [--rgb-resources "--gres gpu:1 --mem 8G"]
#          [--eval-loc oracle|PREDICTIONS] [--loc-tag TAG] [--loc-args "ARGS"] [--loc-resources "ARGS"]
#          [--dry-run]
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
areas="" camera="cam2" count=72 tasks=8 rgb=0 workdir="runs" scenes="scenes" insgen="" scratch="" logs=""
partition="" resources="" rgb_resources="" dry=0 loc="" loc_tag="" loc_args="" loc_resources=""
while [ $# -gt 0 ]; do
    case "$1" in
        --areas) areas="$2"; shift 2 ;;
        --camera) camera="$2"; shift 2 ;;
        --count) count="$2"; shift 2 ;;
        --tasks) tasks="$2"; shift 2 ;;
        --rgb) rgb=1; shift ;;
        --workdir) workdir="$2"; shift 2 ;;
        --scenes) scenes="$2"; shift 2 ;;
        --insgen) insgen="$2"; shift 2 ;;
        --scratch) scratch="$2"; shift 2 ;;
        --logs) logs="$2"; shift 2 ;;
        --partition) partition="$2"; shift 2 ;;
        --resources) resources="$2"; shift 2 ;;
        --rgb-resources) rgb_resources="$2"; shift 2 ;;
        --eval-loc) loc="$2"; shift 2 ;;
        --loc-tag) loc_tag="$2"; shift 2 ;;
        --loc-args) loc_args="$2"; shift 2 ;;
        --loc-resources) loc_resources="$2"; shift 2 ;;
        --dry-run) dry=1; shift ;;
        -h|--help) sed -n '2,38p' "$0"; exit 0 ;;
        *) echo "submit.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
    esac
done
[ -n "$areas" ] || { echo "submit.sh: --areas is required" >&2; exit 2; }
[[ "$tasks" =~ ^[1-9][0-9]*$ ]] || { echo "submit.sh: --tasks must be a positive integer, got $tasks" >&2; exit 2; }
if [ -z "$insgen" ]; then
    insgen="$(command -v insgen || true)"
    [ -n "$insgen" ] || insgen="$(cd "$here/../.." && pwd)/target/release/insgen"
fi
if [ -n "$loc" ] && [ "$loc" != oracle ]; then
    [ -f "$loc" ] || { echo "submit.sh: --eval-loc takes oracle or a predictions file; no file $loc" >&2; exit 2; }
    loc="$(cd "$(dirname "$loc")" && pwd)/$(basename "$loc")"
fi
[ -x "$insgen" ] || { echo "submit.sh: no insgen binary at $insgen (cargo build --release, or --insgen BIN)" >&2; exit 2; }
mkdir -p "$workdir"
workdir="$(cd "$workdir" && pwd)"
scenes="$(cd "$scenes" && pwd)"
# A camera preset file (not a built-in name) is read by the tasks from wherever they start.
[ -f "$camera" ] && camera="$(cd "$(dirname "$camera")" && pwd)/$(basename "$camera")"
logs="${logs:-$workdir/slurm/logs}"
mkdir -p "$logs" "$workdir/slurm"
# The configuration every task reads (one file, so a resubmission runs exactly the same commands).
config="$workdir/slurm/config.env"
{
    printf 'INSGEN=%q\nWORKDIR=%q\nSCENES=%q\nAREAS=%q\nCAMERA=%q\nCOUNT=%q\nTASKS=%q\nRGB=%q\nSCRATCH=%q\n' \
        "$insgen" "$workdir" "$scenes" "$areas" "$camera" "$count" "$tasks" "$rgb" "$scratch"
    printf 'PARTITION=%q\nRESOURCES=%q\nRGB_RESOURCES=%q\n' "$partition" "$resources" "$rgb_resources"
    printf 'LOC=%q\nLOC_TAG=%q\nLOC_ARGS=%q\nLOC_RESOURCES=%q\n' "$loc" "$loc_tag" "$loc_args" "$loc_resources"
} > "$config.tmp" && mv "$config.tmp" "$config"

common=(--parsable --kill-on-invalid-dep=yes --cpus-per-task 2)
[ -n "$partition" ] && common+=(--partition "$partition")
# shellcheck disable=SC2206
common+=($resources)
submit() { # name, extra sbatch args..., -- task.sh args...
    local name="$1"; shift
    local args=()
    while [ "$1" != "--" ]; do args+=("$1"); shift; done
    shift
    if [ "$dry" = 1 ]; then
        echo "sbatch ${common[*]} --job-name insgen-$name ${args[*]} $here/task.sh $*" >&2
        echo "DRY-$name"
    else
        sbatch "${common[@]}" --job-name "insgen-$name" "${args[@]}" "$here/task.sh" "$@"
    fi
}
last=$((tasks - 1))
prep=$(submit prep --output "$logs/%x-%j.log" -- "$config" prep)
masks=$(submit masks --dependency "afterok:$prep" --array "0-$last" --output "$logs/%x-%A_%a.log" -- "$config" masks)
after="$masks"
if [ "$rgb" = 1 ]; then
    # shellcheck disable=SC2206
    extra=($rgb_resources)
    rgbjob=$(submit rgb --dependency "afterok:$prep" --array "0-$last" "${extra[@]}" \
        --output "$logs/%x-%A_%a.log" -- "$config" rgb)
    after="$masks:$rgbjob"
fi
if [ -n "$loc" ]; then
    # Task i reads the masks of masks task i (the same positions of poses.jsonl), so each waits for its
    # own masks task only (aftercorr); the merge waits for all.
    # shellcheck disable=SC2206
    extra=($loc_resources)
    locjob=$(submit loc --dependency "aftercorr:$masks" --array "0-$last" "${extra[@]}" \
        --output "$logs/%x-%A_%a.log" -- "$config" loc)
    after="$after:$locjob"
fi
merge=$(submit merge --dependency "afterok:$after" --output "$logs/%x-%j.log" \
    -- "$config" merge)
printf 'PREP_JOB=%s\nMASKS_JOB=%s\nRGB_JOB=%s\nLOC_JOB=%s\nMERGE_JOB=%s\n' "$prep" "$masks" "${rgbjob:-}" \
    "${locjob:-}" "$merge" > "$workdir/slurm/jobs.env"
echo "submitted: prep $prep, masks $masks${rgbjob:+, rgb $rgbjob}${locjob:+, loc $locjob}, merge $merge (logs in $logs)"
