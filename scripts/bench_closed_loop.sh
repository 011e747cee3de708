#!/usr/bin/env bash
# The closed loop in one command: insgen makes a dataset from named areas and holds one area out
# entirely; the reference baseline (scripts/train/baseline.py) trains on the rest from scratch,
# predicts the held-out area, pycocotools scores the masks, and `insgen eval-loc --predictions`
# localizes with them (instance, semantic, merged, grouped; defaults and --paper) next to the oracle masks,
# once as predicted and once calibrated: the model's mask zoom, measured on a calibration area (frames
# with known poses, neither trained on nor held out; --calibrate), undone by `--prediction-zoom`.
# Writes this run's section of bench/closed_loop.md and its picture (RGB | truth | prediction).
#
#   scripts/bench_closed_loop.sh [--size small|full] [--train "A B ..."] [--holdout AREA]
#       [--families "unet maskrcnn"] [--minutes M] [--steps N] [--device auto|cpu|cuda]
#       [--queries Q] [--holdout-frames N] [--frames N] [--workdir DIR] [--label NAME]
#       [--train-rgb "FLAGS"] [--calibrate AREA|val] [STAGE ...]
#
# --calibrate AREA measures the model's mask zoom on AREA: an area neither trained on nor held out,
# whose frames the model has never seen. A model can draw the edges of the frames it was trained on
# exactly and still bleed past them on a city it has not seen (bench/closed_loop.md, "More frames, more
# steps"), which the validation split (trained on) cannot measure, and how far it bleeds depends on the
# city. The default is an area like the held-out one that the shared data has and that is neither
# trained on nor held out: komaba (PLATEAU, next to Shibuya) for tokyo, else delft; else the validation
# split, which `--calibrate val` asks for.
#
# --frames sets the frames sampled per training area (the size's default otherwise): a data-scaling
# point at the same steps, with the same held-out frames.
#
# --train-rgb passes extra `render-rgb` flags for the training areas only (e.g. "--no-neighbour-contrast
# --force"): an A/B of a data fix, in which the held-out photos stay the same.
#
# Stages (default: all, in order): data train predict score loc report. Each resumes: the data stages
# redo only what changed, a trained model is kept unless --retrain. So a dataset made here can be
# trained elsewhere (`... train predict` on a GPU machine, then `... score loc report` here).
#
#   small (default; 2 CPU cores, ~30 min): cam2 at 480×270, 16 frames per training area, 12 held-out
#         frames, 8 minutes of training per family, U-Net width 16 on 192×320 crops
#   full  (a GPU): cam2 at 640×360, 60 frames per training area, 40 held-out frames, 4.5 minutes of
#         training, U-Net width 32, batch 16
#
# Training areas default to the procedural districts plus Den Haag and Niiza when ../shared/data has
# them (and Delft for --size full); the held-out area defaults to Shibuya (tokyo) when present, else
# demo-test; Komaba or Delft calibrates (--calibrate).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
export NODEVICE_SELECT=1

SIZE=small TRAIN="" HOLDOUT="" FAMILIES="unet maskrcnn" MINUTES="" STEPS="" DEVICE=auto QUERIES=""
WORKDIR="" LABEL="" RETRAIN=0 TRAIN_RGB="" HOLD_FRAMES="" FRAMES="" CAL="" STAGES=()
while [ $# -gt 0 ]; do
    case "$1" in
        --size) SIZE=$2; shift 2 ;;
        --train) TRAIN=$2; shift 2 ;;
        --holdout) HOLDOUT=$2; shift 2 ;;
        --families) FAMILIES=$2; shift 2 ;;
        --minutes) MINUTES=$2; shift 2 ;;
        --steps) STEPS=$2; shift 2 ;;
        --device) DEVICE=$2; shift 2 ;;
        --queries) QUERIES=$2; shift 2 ;;
        --workdir) WORKDIR=$2; shift 2 ;;
        --label) LABEL=$2; shift 2 ;;
        --retrain) RETRAIN=1; shift ;;
        --train-rgb) TRAIN_RGB=$2; shift 2 ;;
        --holdout-frames) HOLD_FRAMES=$2; shift 2 ;;
        --frames) FRAMES=$2; shift 2 ;;
        --calibrate) CAL=$2; shift 2 ;;
        -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d'; exit 0 ;;
        data|train|predict|score|loc|report) STAGES+=("$1"); shift ;;
        *) echo "bench_closed_loop: unknown argument $1 (see --help)" >&2; exit 2 ;;
    esac
done
[ ${#STAGES[@]} -gt 0 ] || STAGES=(data train predict score loc report)

[ -z "$HOLD_FRAMES" ] || [ -n "$QUERIES" ] || QUERIES=$HOLD_FRAMES
SHARED=../shared/data
have() { [ -e "$SHARED/$1" ]; }
case "$SIZE" in
    small) CAMERA=cam2-quarter; COUNT=16; HOLD_COUNT=12; WIDTH=16; BATCH=4; CROP=192x320
           : "${MINUTES:=8}" "${QUERIES:=12}" ;;
    full)  CAMERA=cam2-third; COUNT=60; HOLD_COUNT=40; WIDTH=32; BATCH=16; CROP=352x640
           : "${MINUTES:=4.5}" "${QUERIES:=40}" ;;
    *) echo "bench_closed_loop: --size small|full, not $SIZE" >&2; exit 2 ;;
esac
# More held-out frames (and as many localization queries unless --queries says otherwise): a model
# trained once, scored on more of the held-out area.
if [ -n "$HOLD_FRAMES" ]; then
    HOLD_COUNT=$HOLD_FRAMES
fi
if [ -n "$FRAMES" ]; then
    COUNT=$FRAMES
fi
for n in "$COUNT" "$HOLD_COUNT"; do
    case "$n" in
        ''|*[!0-9]*|0) echo "bench_closed_loop: --frames and --holdout-frames take a positive count, not '$n'" >&2; exit 2 ;;
    esac
done
if [ -z "$TRAIN" ]; then
    TRAIN="demo demo-val"
    have nl_denhaag_lod2 && TRAIN+=" denhaag"
    have jp_niiza_plateau_lod1 && TRAIN+=" niiza"
    [ "$SIZE" = full ] && have nl_delft_lod1 && TRAIN+=" delft"
fi
if [ -z "$HOLDOUT" ]; then
    if have jp_tokyo_shibuya_plateau_3dtiles/tileset.json; then HOLDOUT=tokyo; else HOLDOUT=demo-test; fi
fi
for a in $TRAIN; do
    [ "$a" != "$HOLDOUT" ] || { echo "bench_closed_loop: $a is both trained on and held out" >&2; exit 2; }
    [ "$a" != "$CAL" ] || { echo "bench_closed_loop: $a is both trained on and the calibration area" >&2; exit 2; }
done
if [ -z "$CAL" ]; then
    # A calibration area like the held-out one, since how far a model's masks bleed depends on the city
    # (bench/closed_loop.md, "Three thousand more steps"): Komaba (PLATEAU tiles next to Shibuya) for
    # Shibuya, else Delft; an area that is trained on or held out is never one. None found: the
    # validation split.
    candidates="delft komaba"; [ "$HOLDOUT" = tokyo ] && candidates="komaba delft"
    for c in $candidates; do
        case $c in
            delft) have nl_delft_lod1 || continue ;;
            komaba) have jp_tokyo_shibuya_plateau_3dtiles/tileset_komaba_neighbors.json || continue ;;
        esac
        if [ "$HOLDOUT" != "$c" ] && ! [[ " $TRAIN " == *" $c "* ]]; then CAL=$c; break; fi
    done
fi
[ "$CAL" != val ] || CAL=""
[ "$CAL" != "$HOLDOUT" ] || { echo "bench_closed_loop: $CAL is both held out and the calibration area" >&2; exit 2; }
: "${WORKDIR:=runs/closed_loop_$SIZE}"
: "${LABEL:=$SIZE}"
W=$WORKDIR
if [ -z "${INSGEN_TRAIN_PYTHON:-}" ]; then
    bash scripts/setup_train.sh  # idempotent: the training venv (torch), once
fi
PY="${INSGEN_TRAIN_PYTHON:-$ROOT/.venv-train/bin/python}"
BASE="$ROOT/scripts/train/baseline.py"
INSGEN="$ROOT/target/release/insgen"
B=("$INSGEN" --workdir "$W" --no-progress --log-every 20)
mkdir -p "$W"
say() { printf '[closed-loop %s] %s\n' "$(date -u +%H:%M:%S)" "$*" >&2; }
stage_on() { local s; for s in "${STAGES[@]}"; do [ "$s" = "$1" ] && return 0; done; return 1; }
FIRST=${FAMILIES%% *}

cat > "$W/loop.json.tmp" <<EOF
{"size": "$SIZE", "label": "$LABEL", "camera": "$CAMERA", "train_areas": "$TRAIN", "holdout": "$HOLDOUT",
 "frames_per_area": $COUNT, "holdout_frames": $HOLD_COUNT, "families": "$FAMILIES", "minutes": "$MINUTES",
 "steps": "${STEPS:-}", "queries": $QUERIES, "width": $WIDTH, "batch": $BATCH, "crop": "$CROP",
 "train_rgb": "$TRAIN_RGB", "calibration": "${CAL:-val}",
 "command": "scripts/bench_closed_loop.sh --size $SIZE --train '$TRAIN' --holdout $HOLDOUT --families '$FAMILIES' --minutes $MINUTES${STEPS:+ --steps $STEPS} --device $DEVICE --queries $QUERIES${HOLD_FRAMES:+ --holdout-frames $HOLD_FRAMES}${FRAMES:+ --frames $FRAMES}${TRAIN_RGB:+ --train-rgb '$TRAIN_RGB'} --calibrate ${CAL:-val}"}
EOF
mv "$W/loop.json.tmp" "$W/loop.json"

if stage_on data; then
    cargo build --release --quiet --bin insgen
    [ -x "$ROOT/.venv-blender/bin/python" ] || bash scripts/setup.sh
    cam_file=scenes/cameras/$CAMERA.toml
    for a in $TRAIN $HOLDOUT; do
        n=$COUNT; [ "$a" = "$HOLDOUT" ] && n=$HOLD_COUNT
        say "data: $a ($n frames of $CAMERA)"
        "${B[@]}" -q prepare --area "$a"
        "${B[@]}" -q sample --area "$a" --camera "$cam_file" --count "$n"
        "${B[@]}" -q render-masks --area "$a" --camera "$CAMERA"
        rgb=(); [ "$a" != "$HOLDOUT" ] && [ -n "$TRAIN_RGB" ] && read -r -a rgb <<< "$TRAIN_RGB"
        "${B[@]}" -q render-rgb --area "$a" --camera "$CAMERA" "${rgb[@]}"
    done
    say "data: export-coco (held out: $HOLDOUT)"
    "${B[@]}" -q export-coco --holdout "$HOLDOUT"
    if [ -n "$CAL" ]; then
        # The calibration area in a work directory of its own, so that no split of the loop holds it.
        say "data: calibration area $CAL ($HOLD_COUNT frames of $CAMERA)"
        C=("$INSGEN" --workdir "$W/calibration" --no-progress --log-every 20 -q)
        "${C[@]}" prepare --area "$CAL"
        "${C[@]}" sample --area "$CAL" --camera "$cam_file" --count "$HOLD_COUNT"
        "${C[@]}" render-masks --area "$CAL" --camera "$CAMERA"
        "${C[@]}" render-rgb --area "$CAL" --camera "$CAMERA"
        "${C[@]}" export-coco --holdout "$CAL"
    fi
fi
# The frames the mask zoom is measured on: the calibration area's (score_calibration.json), else the
# validation split's (score_val.json).
CAL_COCO="$W/calibration/coco/instances_test.json"
ZOOM_FROM=val; [ -z "$CAL" ] || ZOOM_FROM=calibration

for fam in $FAMILIES; do
    M="$W/model/$fam"
    if stage_on train; then
        if [ "$RETRAIN" = 1 ] || [ ! -f "$M/model.json" ]; then
            say "train: $fam, ${MINUTES} min${STEPS:+ or $STEPS steps}, device $DEVICE"
            rm -f "$M/train_log.jsonl"
            width=$WIDTH; batch=$BATCH
            [ "$fam" = maskrcnn ] && batch=$(( BATCH / 2 > 0 ? BATCH / 2 : 1 ))
            "$PY" "$BASE" train --coco "$W/coco" --split train --split val --out "$M" --family "$fam" \
                --device "$DEVICE" --minutes "$MINUTES" ${STEPS:+--steps "$STEPS"} --batch "$batch" \
                --width "$width" --crop "$CROP" --log-every 30
        else
            say "train: $fam kept ($M/model.json; --retrain to redo)"
        fi
    fi
    if stage_on predict; then
        "$PY" "$BASE" predict --checkpoint "$M/checkpoint.pt" --coco "$W/coco/instances_test.json" \
            --area "$HOLDOUT" --device "$DEVICE" --out "$M/results_$HOLDOUT.json"
        "$PY" "$BASE" predict --checkpoint "$M/checkpoint.pt" --coco "$W/coco/instances_val.json" \
            --device "$DEVICE" --out "$M/results_val.json"
        if [ -n "$CAL" ]; then
            "$PY" "$BASE" predict --checkpoint "$M/checkpoint.pt" --coco "$CAL_COCO" \
                --device "$DEVICE" --out "$M/results_calibration.json"
        fi
    fi
    if stage_on score; then
        "$PY" "$BASE" score --coco "$W/coco/instances_test.json" --results "$M/results_$HOLDOUT.json" \
            --area "$HOLDOUT" --out "$M/score_$HOLDOUT.json" > /dev/null
        # The validation split: the scores' honesty, and the mask zoom where no calibration area is run.
        "$PY" "$BASE" score --coco "$W/coco/instances_val.json" --results "$M/results_val.json" \
            --out "$M/score_val.json" > /dev/null
        if [ -n "$CAL" ]; then
            "$PY" "$BASE" score --coco "$CAL_COCO" --results "$M/results_calibration.json" \
                --out "$M/score_calibration.json" > /dev/null
        fi
        "$PY" "$BASE" sheet --coco "$W/coco/instances_test.json" --results "$M/results_$HOLDOUT.json" \
            --area "$HOLDOUT" --count 4 --out "$M/sheet_$HOLDOUT.png"
    fi
done

if stage_on loc; then
    costs=(--cost instance --cost semantic --cost merged --cost grouped)
    results="$W/model/$FIRST/results_$HOLDOUT.json"
    # The mask zoom to undo, from the calibration frames (the calibration area's, else the validation
    # split's), and from the validation split whether the scores rank the masks well enough to weight
    # the instances by them (area × score).
    read -r zoom honest < <("$PY" -c 'import json, sys; z, s = (json.load(open(f)) for f in sys.argv[1:])
print(z["mask_zoom"]["median"] or 1.0, str(s["score_honesty"]["honest"]).lower())' \
        "$W/model/$FIRST/score_$ZOOM_FROM.json" "$W/model/$FIRST/score_val.json")
    for mode in defaults paper; do
        extra=(); [ "$mode" = paper ] && extra=(--paper)
        say "loc: oracle and $FIRST predictions, $mode (calibrated: --prediction-zoom $zoom)"
        "${B[@]}" -q eval-loc --area "$HOLDOUT" --camera "$CAMERA" --oracle --limit "$QUERIES" \
            "${costs[@]}" "${extra[@]}" --tag "loop-oracle-$mode" --overlays 0
        "${B[@]}" -q eval-loc --area "$HOLDOUT" --camera "$CAMERA" --predictions "$results" \
            --limit "$QUERIES" "${costs[@]}" "${extra[@]}" --tag "loop-$FIRST-$mode" --overlays 2
        "${B[@]}" -q eval-loc --area "$HOLDOUT" --camera "$CAMERA" --predictions "$results" \
            --prediction-zoom "$zoom" --limit "$QUERIES" "${costs[@]}" "${extra[@]}" \
            --tag "loop-$FIRST-$mode-calibrated" --overlays 0
        if [ "$honest" = true ]; then
            "${B[@]}" -q eval-loc --area "$HOLDOUT" --camera "$CAMERA" --predictions "$results" \
                --prediction-zoom "$zoom" --limit "$QUERIES" --cost instance --cost grouped "${extra[@]}" \
                --weighting area-conf --tag "loop-$FIRST-$mode-calibrated-area-conf" --overlays 0
        fi
    done
    # The loop's photos are rendered from the map itself, so the defaults keep the buildings in the
    # polish's second pass; for comparison, the union's outline there (the default against coarser
    # maps; bench/loc_learned.md).
    "${B[@]}" -q eval-loc --area "$HOLDOUT" --camera "$CAMERA" --predictions "$results" \
        --prediction-zoom "$zoom" --limit "$QUERIES" --cost instance --cost grouped --polish-semantic-weight 1 \
        --tag "loop-$FIRST-defaults-calibrated-union-polish" --overlays 0
fi

if stage_on report; then
    # The data fix of this round, in a picture: rooftop units as occluders (the old default) punched holes
    # in the roof masks; now they belong to their building. Same poses, masks rendered both ways.
    fa=${TRAIN%% *}
    alt="$W/$fa/$CAMERA-rooftop-occluders"
    mkdir -p "$alt"
    cp "$W/$fa/$CAMERA/poses.jsonl" "$W/$fa/$CAMERA/camera.json" "$alt/"
    "${B[@]}" -q render-masks --area "$fa" --camera "$CAMERA-rooftop-occluders" --occluders trees,cars,rooftop
    "$PY" "$ROOT/scripts/train/fix_figure.py" --rgb "$W/$fa/$CAMERA/rgb" --before "$alt/masks" \
        --after "$W/$fa/$CAMERA/masks" --out "bench/closed_loop_fix_rooftop.png" \
        --title "$fa: photo | rooftop units as occluders (before) | units part of their building (now)"
    # And the neighbour contrast: the same poses rendered without and with it (a few frames each, into
    # cameras of their own, so the loop's photos are untouched).
    for v in off on; do
        alt="$W/$fa/$CAMERA-contrast-$v"
        mkdir -p "$alt"
        cp "$W/$fa/$CAMERA/poses.jsonl" "$W/$fa/$CAMERA/camera.json" "$alt/"
        flag=(); [ "$v" = off ] && flag=(--no-neighbour-contrast)
        "${B[@]}" -q render-rgb --area "$fa" --camera "$CAMERA-contrast-$v" --limit 3 "${flag[@]}"
    done
    "$PY" "$ROOT/scripts/train/contrast_figure.py" --before "$W/$fa/$CAMERA-contrast-off/rgb" \
        --after "$W/$fa/$CAMERA-contrast-on/rgb" --masks "$W/$fa/$CAMERA/masks" \
        --out "bench/closed_loop_fix_contrast.jpg" \
        --title "$fa: photo without neighbour contrast (before) | with (now) | touching boundaries"
    "$PY" "$ROOT/scripts/train/loop_report.py" --workdir "$W" --report bench/closed_loop.md
fi
say "done"
