#!/usr/bin/env bash
# RGB quality bench (issue 14): seconds per frame of `insgen render-rgb` at its defaults, and PSNR/SSIM
# against a converged reference, for the procedural look on the demo and on Shibuya and for an unlit
# photogrammetry tileset, at render-rgb's defaults (the varied per-frame look, the clutter layers prepare
# writes, insgen's camera effects). The procedural cases are measured for both lightings: the default direct
# and `--lighting path` (the path-traced look, the previous defaults); the settings render-rgb used before
# issue 14 (16 samples, OIDN HIGH, 4 bounces, path-traced) are measured on the same crops. Writes
# bench/rgb_quality.md.
#
#   scripts/bench_rgb.sh   (env: FRAMES=3 REF_FRAMES=2 REF_SPP=128 CROP_W=480 CROP_H=272 BENCH_DIR=target/bench-rgb)
#
# FRAMES full 1920x1080 frames are rendered and timed through the CLI per setting (one Blender process:
# the median is the per-frame cost of a long run, the mean includes the first frame's scene sync). The
# reference and the old settings are rendered on the centred CROP_W x CROP_H window of the first
# REF_FRAMES frames only (Cycles' render border), to fit the bench in minutes on 2 cores; every image is
# compared on that window.
set -euo pipefail
cd "$(dirname "$0")/.."
FRAMES=${FRAMES:-3}
REF_FRAMES=${REF_FRAMES:-2}
REF_SPP=${REF_SPP:-128}
CROP_W=${CROP_W:-480}
CROP_H=${CROP_H:-272}
W=${BENCH_DIR:-target/bench-rgb}
BPY=.venv-blender/bin/python
PY=.venv/bin/python
cargo build --release --quiet
BIN=target/release/insgen
mkdir -p "$W/results"
TIMES="$W/results/times.tsv"
: > "$TIMES"
ig() { "$BIN" --workdir "$W" --no-progress "$@"; }

# render CASE AREA SETTING "REF_MODES" [render-rgb args...]: full frames through the CLI, then the crops
# of each reference mode (reference, old) from the job it wrote.
render() {
  local case=$1 area=$2 setting=$3 modes=$4; shift 4
  local cam="$W/$area/cam2" out="$W/results/$case"
  rm -rf "$out/$setting"; mkdir -p "$out/$setting"
  echo "== $case/$setting: render-rgb $* ($FRAMES frame(s), 1920x1080)"
  local line t0 t1
  t0=$(date +%s.%N)
  line=$(ig render-rgb --area "$area" --camera cam2 --limit "$FRAMES" --force "$@" 2>&1 | tee /dev/stderr | grep "frame(s) rendered")
  t1=$(date +%s.%N)
  # "(12.34 s/frame, 23.45 CPU s/frame in Blender; median 11.00 s, 22.00 CPU s)"
  local nums
  nums=$(sed -E 's/.*\(([0-9.]+) s\/frame, ([0-9.]+) CPU s\/frame in Blender; median ([0-9.]+) s, ([0-9.]+) CPU s\).*/\1 \2 \3 \4/' <<<"$line")
  # The whole command (Blender start, scene build, every frame, insgen's camera effects and PNG writing).
  printf "%s\t%s\t%s\t%s\n" "$case" "$setting" "$(tr ' ' '\t' <<<"$nums")" "$(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.2f", b - a }')" >> "$TIMES"
  local job
  job=$(ls -t "$cam"/blender/job-rgb-*.json | head -1)
  # Quality is judged on Blender's frames as render-rgb got them, before insgen's camera effects (white
  # balance, vignetting, blur, sensor noise: deliberate, not a rendering error): the same job re-rendered.
  mkdir -p "$out/$setting-final"
  cp "$cam"/rgb/*.png "$out/$setting-final/"
  "$BPY" scripts/bench/rgb_reference.py "$job" "$out/$setting" job 0 0 0 "$FRAMES" 2>&1 | grep -c '^REF' >/dev/null
  for mode in $modes; do
    local spp=$REF_SPP tag="$mode"; [ "$mode" = old ] && spp=16
    [ "$mode" = reference ] && [ "$setting" != new ] && tag="$setting-reference"
    echo "== $case/$tag: $spp spp on the ${CROP_W}x${CROP_H} crop of $REF_FRAMES frame(s)"
    "$BPY" scripts/bench/rgb_reference.py "$job" "$out/$tag" "$mode" "$spp" "$CROP_W" "$CROP_H" "$REF_FRAMES" 2>&1 \
      | grep '^REF' | while read -r _ frame wall cpu; do
          printf '%s\t%s\t%s\t%s\t%s\t%s\n' "$case" "$tag" "$wall" "$cpu" "$wall" "$cpu" >> "$TIMES"
        done
  done
}

procedural_case() {
  render "$1" "$2" new reference
  render "$1" "$2" path "reference old" --lighting path
}

ig -q prepare --area demo
ig -q sample --area demo --camera cam2 --count 6
procedural_case demo-procedural demo

if [ -f ../shared/data/jp_tokyo_shibuya_plateau_3dtiles/tileset.json ]; then
  ig -q prepare --area tokyo
  ig -q sample --area tokyo --camera cam2 --count 6
  procedural_case shibuya-procedural tokyo
else
  echo "== skipping Shibuya: the PLATEAU tileset (shared/data/jp_tokyo_shibuya_plateau_3dtiles) is absent"
fi

ig -q export-tiles --area demo --style cesium-ion --out "$W/ion-tileset"
render tileset-unlit demo new reference --tileset "$W/ion-tileset/tileset.json"

"$PY" scripts/bench/rgb_report.py "$W/results" "$REF_SPP" "$CROP_W" "$CROP_H" "$FRAMES" "$REF_FRAMES" > bench/rgb_quality.md.tmp
mv bench/rgb_quality.md.tmp bench/rgb_quality.md
echo "wrote bench/rgb_quality.md"
