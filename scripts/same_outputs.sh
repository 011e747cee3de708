#!/usr/bin/env bash
# Refactoring check: runs the pipeline with one insgen binary into a fresh directory, so that two
# binaries (before and after a change that must not change results) can be compared byte for byte.
#
#   scripts/same_outputs.sh BIN OUT            # run BIN's pipeline into OUT (OUT is emptied first)
#   scripts/same_outputs.sh --compare A B      # diff two such directories, timings left out
#
# Areas: the demo and, when its data is present, Shibuya (tokyo). Stages: prepare → sample →
# render-masks → render-rgb (Blender, a few small frames) → export-coco (+ panoptic, YOLO) →
# export-tiles → eval-loc (oracle; instance and semantic; and the demo's export as predictions).
# Environment: COUNT (frames per area, default 6), AREAS (default "demo tokyo").
set -euo pipefail
cd "$(dirname "$0")/.."

# Files whose content is a timing, a date, provenance (binary path, commit) or Blender's job
# scheduling, which follows the machine's load: left out. Everything else must match byte for byte,
# JSON without its timing and provenance keys, Markdown without its timing and commit lines.
TIMING_FILES='(timing\.json|timings\.json|\.log|benchmark.*\.json|commands\.jsonl|blender/job-[^/]*\.json)$'
TIMING_LINE='[0-9.]+ ?(s|ms|min) (per|each)|[0-9.]+ ?[a-z]+/s\b|elapsed|wall|commit `|^/.*insgen.* --workdir '

if [[ "${1:-}" == "--compare" ]]; then
  a="$2"; b="$3"; status=0
  while IFS= read -r rel; do
    if [[ "$rel" =~ $TIMING_FILES ]]; then continue; fi
    if [[ ! -e "$b/$rel" ]]; then echo "only in $a: $rel"; status=1; continue; fi
    if ! cmp -s "$a/$rel" "$b/$rel"; then
      # JSON reports carry timings next to results: compare them without the timing keys.
      if [[ "$rel" == *.json || "$rel" == *.jsonl ]] && python3 - "$a/$rel" "$b/$rel" <<'EOF'
import json, sys
TIMING = ("seconds", "_s", "_ms", "elapsed", "timing", "created", "date", "host", "per_second", "fps",
          "git_commit", "argv", "commands")
def strip(v):
    if isinstance(v, dict):
        return {k: strip(x) for k, x in v.items() if not any(t in k.lower() for t in TIMING)}
    if isinstance(v, list):
        return [strip(x) for x in v]
    return v
def load(p):
    text = open(p).read()
    try:
        return strip(json.loads(text))
    except json.JSONDecodeError:
        return [strip(json.loads(l)) for l in text.splitlines() if l.strip()]
sys.exit(0 if load(sys.argv[1]) == load(sys.argv[2]) else 1)
EOF
      then echo "same except timings: $rel"; continue; fi
      # Reports in Markdown state timings in prose: compare them without the lines that do.
      if [[ "$rel" == *.md ]] && cmp -s <(grep -Ev "$TIMING_LINE" "$a/$rel") <(grep -Ev "$TIMING_LINE" "$b/$rel"); then
        echo "same except timing lines: $rel"; continue
      fi
      echo "differs: $rel"; status=1
    fi
  done < <(cd "$a" && find . -type f | sort)
  while IFS= read -r rel; do
    [[ -e "$a/$rel" ]] || { echo "only in $b: $rel"; status=1; }
  done < <(cd "$b" && find . -type f | sort)
  [[ $status == 0 ]] && echo "identical (timings left out): $a $b"
  exit $status
fi

BIN="$(realpath "$1")"; FINAL="$2"
COUNT=${COUNT:-6}
AREAS=${AREAS:-"demo tokyo"}
# Outputs name their own paths (manifests, data.yaml, fingerprints): every run writes at the same place
# and is moved to FINAL afterwards.
OUT="${TMPDIR:-/tmp}/insgen-same-outputs"
# One run at a time at that place: a second one waits for the first.
exec 9>"$OUT.lock"
flock 9
rm -rf "$OUT" "$FINAL"; mkdir -p "$OUT"
IG=("$BIN" --no-progress -q --workdir "$OUT/work")
for area in $AREAS; do
  src=$(sed -n 's/^path = "\(.*\)"/\1/p' "scenes/$area.toml" | head -1)
  if [[ -n "$src" && "$src" == ../* && ! -e "$OUT/work/$src" && ! -e "scenes/$src" ]]; then
    echo "skipping $area: its data ($src) is absent"; continue
  fi
  "${IG[@]}" prepare --area "$area"
  "${IG[@]}" sample --area "$area" --camera cam2 --count "$COUNT" --seed 7
  "${IG[@]}" render-masks --area "$area" --camera cam2
  "${IG[@]}" render-rgb --area "$area" --camera cam2 --samples 2 --limit "$COUNT" --seed 7
  "${IG[@]}" export-tiles --area "$area" --out "$OUT/tiles-$area"
  "${IG[@]}" eval-loc --area "$area" --camera cam2 --oracle --cost instance --cost semantic \
    --out "$OUT/loc-$area"
done
"${IG[@]}" export-coco --out "$OUT/coco" --holdout tokyo
"${IG[@]}" export-panoptic --coco "$OUT/coco" --out "$OUT/panoptic"
"${IG[@]}" export-yolo --coco "$OUT/coco" --out "$OUT/yolo"
mkdir -p "$(dirname "$FINAL")"; mv "$OUT" "$FINAL"
echo "outputs in $FINAL"
