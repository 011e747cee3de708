#!/usr/bin/env bash
# One task of an insgen Slurm submission (see submit.sh): task.sh CONFIG prep|masks|rgb|loc|merge.
# Array tasks render their shard (--shard auto/TASKS: the array index is the shard) in a work
# directory of their own — node-local scratch when --scratch or $TMPDIR is set — and copy it to
# <workdir>/.shards/<stage>-<index> when done, marking it done with <stage>-<index>.done beside it.
#SBATCH --open-mode=append
set -euo pipefail
config="$1"
stage="$2"
# shellcheck disable=SC1090
source "$config"
log() { echo "[insgen-slurm $(date -u +%FT%TZ)] $*"; }
run() { log "$*"; "$@"; }
# publish WORK SHARDS FINAL INDEX: the shard whole into FINAL (copy, then rename into place, then mark
# it done), and the node-local WORK removed.
publish() {
    mkdir -p "$2"
    rm -rf "$3.partial"
    cp -r "$1" "$3.partial"
    rm -rf "$3"
    mv "$3.partial" "$3"
    touch "$3.done"
    rm -rf "$1"
    log "shard $4 of $TASKS done → $3"
}
log "stage $stage on $(hostname) (job ${SLURM_JOB_ID:-?}, array task ${SLURM_ARRAY_TASK_ID:-none})"
case "$stage" in
    prep)
        for area in $AREAS; do
            run "$INSGEN" --workdir "$WORKDIR" --scenes "$SCENES" --no-progress prepare --area "$area"
            run "$INSGEN" --workdir "$WORKDIR" --scenes "$SCENES" --no-progress sample --area "$area" \
                --camera "$CAMERA" --count "$COUNT"
        done
        ;;
    masks|rgb)
        index="${SLURM_ARRAY_TASK_ID:?task.sh $stage runs as an array task}"
        shards="$WORKDIR/.shards"
        final="$shards/$stage-$index"
        if [ -e "$final.done" ]; then
            log "shard $index already done ($final)"
            exit 0
        fi
        base="${SCRATCH:-${TMPDIR:-/tmp}}"
        work="$base/insgen-$stage-${SLURM_ARRAY_JOB_ID:-0}-$index"
        mkdir -p "$work"
        camera_name="$(basename "$CAMERA" .toml)"
        for area in $AREAS; do
            # The inputs of this area: the prepared scene and the sampled poses.
            mkdir -p "$work/$area/$camera_name"
            cp -r "$WORKDIR/$area/scene" "$work/$area/"
            find "$WORKDIR/$area/$camera_name" -maxdepth 1 -type f -exec cp {} "$work/$area/$camera_name/" \;
            if [ "$stage" = masks ]; then
                run "$INSGEN" --workdir "$work" --no-progress render-masks --area "$area" --camera "$camera_name" \
                    --shard "auto/$TASKS" --preview 0
            else
                run "$INSGEN" --workdir "$work" --no-progress render-rgb --area "$area" --camera "$camera_name" \
                    --shard "auto/$TASKS"
            fi
        done
        if [ "$stage" = masks ] && [ "$RGB" != 1 ]; then
            # A label-only dataset: this task also exports its frames, as a COCO part
            # (coco/parts/<i>-of-<TASKS>/) that the merge combines. With RGB, the export waits for
            # the RGB frames and runs once in the merge job.
            run "$INSGEN" --workdir "$work" --no-progress export-coco --label-only --shard "auto/$TASKS"
        fi
        publish "$work" "$shards" "$final" "$index"
        ;;
    loc)
        # eval-loc on the queries of masks shard i (positions ≡ i mod TASKS of poses.jsonl), reading
        # that shard's published masks; writes the part loc/<tag>/parts/<i>-of-<TASKS>/.
        index="${SLURM_ARRAY_TASK_ID:?task.sh loc runs as an array task}"
        shards="$WORKDIR/.shards"
        final="$shards/loc-$index"
        if [ -e "$final.done" ]; then
            log "shard $index already done ($final)"
            exit 0
        fi
        [ -e "$shards/masks-$index.done" ] || { log "masks shard $index is not done"; exit 1; }
        base="${SCRATCH:-${TMPDIR:-/tmp}}"
        work="$base/insgen-loc-${SLURM_ARRAY_JOB_ID:-0}-$index"
        mkdir -p "$work"
        camera_name="$(basename "$CAMERA" .toml)"
        source_args=(--predictions "$LOC")
        tag_args=()
        [ -n "$LOC_TAG" ] && tag_args=(--tag "$LOC_TAG")
        # shellcheck disable=SC2206
        extra=($LOC_ARGS)
        for area in $AREAS; do
            mkdir -p "$work/$area/$camera_name"
            cp -r "$WORKDIR/$area/scene" "$work/$area/"
            find "$WORKDIR/$area/$camera_name" -maxdepth 1 -type f -exec cp {} "$work/$area/$camera_name/" \;
            [ "$LOC" = oracle ] && source_args=(--oracle --masks "$shards/masks-$index/$area/$camera_name/masks")
            run "$INSGEN" --workdir "$work" --no-progress eval-loc --area "$area" --camera "$camera_name" \
                "${source_args[@]}" "${tag_args[@]}" "${extra[@]}" --shard "auto/$TASKS"
            # Publish the evaluation only: the scene and poses are the prep job's.
            rm -rf "${work:?}/$area/scene"
        done
        publish "$work" "$shards" "$final" "$index"
        ;;
    merge)
        shards=()
        for stage_name in masks rgb loc; do
            [ "$stage_name" = rgb ] && [ "$RGB" != 1 ] && continue
            [ "$stage_name" = loc ] && [ -z "${LOC:-}" ] && continue
            for ((i = 0; i < TASKS; i++)); do
                d="$WORKDIR/.shards/$stage_name-$i"
                [ -e "$d.done" ] || { log "shard $stage_name-$i is not done; resubmit with scripts/slurm/resubmit.sh"; exit 1; }
                shards+=("$d")
            done
        done
        # Label-only: the masks tasks exported COCO parts, which the merge combines into coco/ (ids
        # renumbered, statistics recomputed). With RGB: one export over the merged frames.
        run "$INSGEN" --workdir "$WORKDIR" merge "${shards[@]}"
        if [ "$RGB" = 1 ]; then
            run "$INSGEN" --workdir "$WORKDIR" --no-progress export-coco
        fi
        ;;
    *)
        echo "task.sh: unknown stage $stage (prep, masks, rgb, loc or merge)" >&2
        exit 2
        ;;
esac
log "stage $stage finished"
