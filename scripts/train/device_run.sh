#!/usr/bin/env bash
# The GPU half of the closed loop, for a machine that has torch and a GPU but neither Blender nor
# pycocotools, and takes a few tens of MB (a lent device): train each family on a packed export
# (`baseline.py pack`) and predict the frames the loop scores: the held-out area, the validation split,
# and the calibration area when the pack has one (PACK/calibration, packed from the loop's
# calibration/coco). Writes OUT/model/<family>/{model.json, train_log.jsonl, results_<holdout>.json,
# results_val.json[, results_calibration.json]} (no checkpoint: it is larger than such machines hand
# back). Bring OUT/model into the closed loop's work directory, then run here
# `scripts/bench_closed_loop.sh --size full score loc report`.
#
#   scripts/train/device_run.sh PACK OUT HOLDOUT [MINUTES] [FAMILIES]
#   e.g. scripts/train/device_run.sh pack "$OUT" tokyo 4 "unet maskrcnn"
set -euo pipefail
PACK=$1 OUT=$2 HOLDOUT=$3 MINUTES=${4:-4} FAMILIES=${5:-unet}
PY=${PYTHON:-python3}
DEVICE=${DEVICE:-cuda}
BASE="$(dirname "$0")/baseline.py"
for fam in $FAMILIES; do
    M="$OUT/model/$fam"
    mkdir -p "$M"
    batch=16; [ "$fam" = maskrcnn ] && batch=8
    "$PY" "$BASE" train --coco "$PACK" --split train --split val --out "$M" --family "$fam" --device "$DEVICE" \
        --minutes "$MINUTES" --batch "$batch" --width 32 --crop 352x640 --log-every 20 --checkpoint-every 100000
    "$PY" "$BASE" predict --checkpoint "$M/checkpoint.pt" --coco "$PACK/instances_test.json" --area "$HOLDOUT" \
        --device "$DEVICE" --out "$M/results_$HOLDOUT.json"
    # The validation split and the calibration area, where the pack has them (COCO file:results file).
    for pair in instances_val.json:results_val.json calibration/instances_test.json:results_calibration.json; do
        [ -f "$PACK/${pair%%:*}" ] || continue
        "$PY" "$BASE" predict --checkpoint "$M/checkpoint.pt" --coco "$PACK/${pair%%:*}" \
            --device "$DEVICE" --out "$M/${pair#*:}"
    done
    rm -f "$M/checkpoint.pt"
done
