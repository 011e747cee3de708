#!/usr/bin/env bash
# Is a closed loop's localization result real? Its held-out queries are few (12–40) and are the ones
# the costs and modes get compared on. This script checks a loop's model on fresh frames of the same
# held-out area that nothing was chosen on: it samples COUNT other views (another seed), renders their
# masks and photos, predicts them with the loop's first model (not retrained), scores them
# (pycocotools, outline F1) and localizes them in each mode, calibrated with the mask zoom the loop
# measured on its validation split. Prints (and writes to WORKDIR/fresh_report.md) recall at (2 m, 2°)
# per mode and cost and per band of the frames' outline F1, with the sheet of RGB | truth | prediction |
# missed and extra building pixels (WORKDIR/sheet.png).
#
#   scripts/loc_fresh_holdout.sh LOOP_DIR [WORKDIR]
#   (env: COUNT=80 SEED=1 MODES="defaults union pure")
#
# Modes: defaults; union (the polish's second pass on the union's outline, --polish-semantic-weight 1:
# the default against maps coarser than the photos, where the defaults here keep the buildings);
# pure (the paper's costs under eval-loc's search);
# paper (--paper). bench/loc_learned.md has the first run (small-long-40, 80 frames).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
export NODEVICE_SELECT=1
case "${1:-}" in -h|--help|"") sed -n '2,/^set -euo/p' "$0" | sed '$d'; [ -n "${1:-}" ]; exit ;; esac
LOOP=$1
W=${2:-$LOOP-fresh}
COUNT=${COUNT:-80}
SEED=${SEED:-1}
MODES=${MODES:-"defaults union pure"}
PY="${INSGEN_TRAIN_PYTHON:-$ROOT/.venv-train/bin/python}"
[ -f "$LOOP/loop.json" ] || { echo "loc_fresh_holdout: $LOOP/loop.json: not a closed-loop work directory" >&2; exit 2; }
[ -x "$PY" ] || { echo "loc_fresh_holdout: $PY: no training interpreter (run scripts/setup_train.sh)" >&2; exit 2; }
info=$("$PY" -c 'import json, sys
try:
    l = json.load(open(sys.argv[1]))
    print(l["holdout"], l["camera"], l["families"].split()[0])
except (OSError, ValueError, KeyError, IndexError, AttributeError) as e:
    sys.exit(f"loc_fresh_holdout: {sys.argv[1]}: not a closed loop'"'"'s loop.json ({type(e).__name__}: {e})")' \
    "$LOOP/loop.json") || exit 2
read -r HOLDOUT CAMERA FIRST <<< "$info"
M="$LOOP/model/$FIRST"
for f in checkpoint.pt score_val.json; do
    [ -f "$M/$f" ] || { echo "loc_fresh_holdout: $M/$f missing (run the loop's train and score stages)" >&2; exit 2; }
done
ZOOM=$("$PY" -c 'import json, sys; print(json.load(open(sys.argv[1]))["mask_zoom"]["median"] or 1.0)' "$M/score_val.json")
cargo build --release --quiet --bin insgen
IG=("$ROOT/target/release/insgen" --workdir "$W" --no-progress -q)
say() { printf '[fresh %s] %s\n' "$(date -u +%H:%M:%S)" "$*" >&2; }
mode_flags() {
    case "$1" in
        defaults) ;;
        union) echo --polish-semantic-weight 1 ;;
        pure) echo --semantic-weight 0 --polish-semantic-weight 0 --silhouette-offset 0 --polish-spill-weight 1 ;;
        paper) echo --paper ;;
        *) echo "loc_fresh_holdout: unknown mode $1 (defaults union pure paper)" >&2; return 2 ;;
    esac
}
for mode in $MODES; do mode_flags "$mode" > /dev/null; done

mkdir -p "$W"
say "data: $COUNT frames of $HOLDOUT/$CAMERA, seed $SEED"
"${IG[@]}" prepare --area "$HOLDOUT"
"${IG[@]}" sample --area "$HOLDOUT" --camera "scenes/cameras/$CAMERA.toml" --count "$COUNT" --seed "$SEED"
"${IG[@]}" render-masks --area "$HOLDOUT" --camera "$CAMERA"
"${IG[@]}" render-rgb --area "$HOLDOUT" --camera "$CAMERA"
"${IG[@]}" export-coco --holdout "$HOLDOUT"
COCO="$W/coco/instances_test.json"
RESULTS="$W/results_$HOLDOUT.json"
say "predict and score with $M"
"$PY" scripts/train/baseline.py predict --checkpoint "$M/checkpoint.pt" --coco "$COCO" --area "$HOLDOUT" \
    --out "$RESULTS"
"$PY" scripts/train/baseline.py score --coco "$COCO" --results "$RESULTS" --area "$HOLDOUT" \
    --out "$W/score_$HOLDOUT.json" > /dev/null
"$PY" scripts/train/baseline.py sheet --coco "$COCO" --results "$RESULTS" --area "$HOLDOUT" --count 4 \
    --out "$W/sheet.png"
for mode in $MODES; do
    say "loc: $mode (zoom $ZOOM undone)"
    read -r -a extra <<< "$(mode_flags "$mode")"
    "${IG[@]}" eval-loc --area "$HOLDOUT" --camera "$CAMERA" --predictions "$RESULTS" --coco "$COCO" \
        --prediction-zoom "$ZOOM" --cost instance --cost semantic --cost grouped "${extra[@]}" \
        --overlays 0 --tag "fresh-$mode"
done

"$PY" - "$W" "$HOLDOUT" "$CAMERA" "$LOOP" "$ZOOM" $MODES > "$W/fresh_report.md.tmp" <<'EOF'
import json, sys
from pathlib import Path
sys.path.insert(0, "scripts/train")
import scoring  # noqa: E402
from loop_report import OUTLINE_BANDS, by_outline_band, localized  # noqa: E402

w, hold, cam, loop, zoom, modes = Path(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4], sys.argv[5], sys.argv[6:]
score = json.loads((w / f"score_{hold}.json").read_text())
f1 = scoring.outline_f1_per_frame(w / "coco" / "instances_test.json", w / f"results_{hold}.json", [hold])
print(f"# Fresh held-out frames: {loop} on {hold}/{cam}\n")
print(f"{score['images']} frames; AP50 {score['AP50']:.3f}, building IoU {score['building_iou']:.3f}, outline F1 "
      f"{score['outline_f1']['1px']:.2f} / {score['outline_f1']['2px']:.2f} (1 / 2 px); mask zoom undone {zoom} "
      "(the loop's validation split).\n")
print("| mode | cost | recall (2 m, 2°) | largest error (m) | " +
      " | ".join(f"F1 {lo}–{min(hi, 1):g}" for lo, hi in OUTLINE_BANDS) + " |")
print("|---|---|---:|---:|" + "---:|" * len(OUTLINE_BANDS))
for mode in modes:
    rows = [json.loads(l) for l in (w / hold / cam / "loc" / f"fresh-{mode}" / "results.jsonl").read_text().splitlines()
            if l.strip()]
    costs, bands = by_outline_band(rows, f1)
    for cost in costs:
        rs = [r for r in rows if r["cost"] == cost]
        cells = [f"{counts[cost][0]} of {counts[cost][1]}" for _, _, _, counts in bands]
        print(f"| {mode} | {cost} | {100 * sum(map(localized, rs)) / len(rs):.1f} % | "
              f"{max(r['translation_error_m'] for r in rs):.1f} | " + " | ".join(cells) + " |")
EOF
mv "$W/fresh_report.md.tmp" "$W/fresh_report.md"
cat "$W/fresh_report.md"
