#!/usr/bin/env bash
# RGB quality bench (issue 14): seconds per frame of `insgen render-rgb` at its defaults, and PSNR/SSIM
# against a converged reference, for the procedural look on the demo and on Shibuya and for an unlit
# photogrammetry tileset; the settings render-rgb used before (16 samples, OIDN HIGH, 4 bounces) are
# measured on the same crops. Writes bench/rgb_quality.md.
#
#   scripts/bench_rgb.sh            (env: FRAMES=1 REF_SPP=128 CROP_W=480 CROP_H=272 BENCH_DIR=target/bench-rgb)
#
# The reference and the old settings are rendered on the centred CROP_W x CROP_H window of each
# 1920x1080 frame only (Cycles' render border), to fit the bench in minutes on 2 cores; the new defaults
# are rendered and timed on full frames through the CLI, and compared on the same window.
set -euo pipefail
cd "$(dirname "$0")/.."
FRAMES=${FRAMES:-1}
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

# bench_case CASE AREA [render-rgb args...]
bench_case() {
  local case=$1 area=$2; shift 2
  local cam="$W/$area/cam2" out="$W/results/$case"
  rm -rf "$out"; mkdir -p "$out/new"
  echo "== $case: render-rgb at the defaults ($FRAMES frame(s), 1920x1080)"
  local line
  line=$(ig render-rgb --area "$area" --camera cam2 --limit "$FRAMES" --force "$@" 2>&1 | tee /dev/stderr | grep "frame(s) rendered")
  # "(12.34 s/frame, 23.45 CPU s/frame in Blender)"
  local s c
  s=$(sed -E 's/.*\(([0-9.]+) s\/frame, ([0-9.]+) CPU.*/\1/' <<<"$line")
  c=$(sed -E 's/.*\(([0-9.]+) s\/frame, ([0-9.]+) CPU.*/\2/' <<<"$line")
  printf "%s\tnew\t%s\t%s\n" "$case" "$s" "$c" >> "$TIMES"
  cp "$cam"/rgb/*.png "$out/new/"
  local job
  job=$(ls -t "$cam"/blender/job-rgb-*.json | head -1)
  for mode in reference old; do
    local spp=$REF_SPP; [ "$mode" = old ] && spp=16
    echo "== $case: $mode ($spp spp) on the ${CROP_W}x${CROP_H} crop"
    "$BPY" scripts/bench/rgb_reference.py "$job" "$out/$mode" "$mode" "$spp" "$CROP_W" "$CROP_H" 2>&1 \
      | grep '^REF' | while read -r _ frame wall cpu; do
          printf '%s\t%s\t%s\t%s\n' "$case" "$mode" "$wall" "$cpu" >> "$TIMES"
        done
  done
}

ig -q prepare --area demo
ig -q sample --area demo --camera cam2 --count 6
bench_case demo-procedural demo

if [ -f ../shared/data/jp_tokyo_shibuya_plateau_3dtiles/tileset.json ]; then
  ig -q prepare --area tokyo
  ig -q sample --area tokyo --camera cam2 --count 6
  bench_case shibuya-procedural tokyo
else
  echo "== skipping Shibuya: the PLATEAU tileset (shared/data/jp_tokyo_shibuya_plateau_3dtiles) is absent"
fi

ig -q export-tiles --area demo --style cesium-ion --out "$W/ion-tileset"
bench_case tileset-unlit demo --tileset "$W/ion-tileset/tileset.json"

"$PY" scripts/bench/rgb_report.py "$W/results" "$REF_SPP" "$CROP_W" "$CROP_H" > bench/rgb_quality.md
echo "wrote bench/rgb_quality.md"
