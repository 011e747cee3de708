#!/usr/bin/env bash
# Tileset-aware masks on the demo city (issue 17, items 2-3): render-masks without a tileset, with a
# photogrammetry-like reference in place, and with one moved 3 m east; prints time, pixel counts and
# consistency scores. Usage: scripts/bench_occlusion.sh [WIDTH HEIGHT FRAMES]  (default 480 270 24)
set -euo pipefail
W=${1:-480}; H=${2:-270}; N=${3:-24}
REPO=$(cd "$(dirname "$0")/.." && pwd)
B=${INSGEN:-$REPO/target/debug/insgen}
D=$(mktemp -d); trap 'rm -rf "$D"' EXIT
mkdir -p "$D/scenes"; cd "$D"
sed "s|^path = \"|path = \"$REPO/scenes/|" "$REPO/scenes/demo.toml" > scenes/demo.toml
printf 'name = "bench"\nwidth_px = %s\nheight_px = %s\nsensor_width_mm = 6.4\nsensor_height_mm = 3.6\nhfov_deg = 40.0\nstrategy = "grid"\n' "$W" "$H" > bench.toml
export RUST_LOG=warn
"$B" prepare --area demo >/dev/null
"$B" sample --area demo --camera bench.toml --count "$N" >/dev/null
"$B" export-tiles --area demo --style cesium-ion --offset 0,0,0,0 --photogrammetry-noise --seed 7 --out ref0 >/dev/null
"$B" export-tiles --area demo --style cesium-ion --offset 3,0,0,0 --photogrammetry-noise --seed 7 --out ref3 >/dev/null
echo "| tileset | seconds | occluded px | behind px | agree px | consistency mean / min / max | see-through buildings |"
echo "|---|---:|---:|---:|---:|---|---:|"
for t in none ref0 ref3; do
  args=(); [ "$t" = none ] || args=(--tileset "$t/tileset.json")
  s0=$(date +%s.%N)
  "$B" render-masks --area demo --camera bench --no-progress --force "${args[@]}"
  s1=$(date +%s.%N)
  python3 - "$t" "$(echo "$s1 - $s0" | bc)" <<'PY'
import json, glob, sys
t, secs = sys.argv[1], float(sys.argv[2])
occ = beh = agr = st = 0; cs = []
for f in sorted(glob.glob('runs/demo/bench/masks/*.instances.json')):
    o = json.load(open(f)).get('occlusion')
    if o:
        occ += o['occluded_px']; beh += o['behind_px']; agr += o['agree_px']; cs.append(o['consistency'])
        st += sum(b['see_through'] for b in o['buildings'])
if cs:
    print(f"| {t} | {secs:.2f} | {occ} | {beh} | {agr} | {sum(cs)/len(cs):.3f} / {min(cs):.3f} / {max(cs):.3f} | {st} |")
else:
    print(f"| {t} | {secs:.2f} | – | – | – | – | – |")
PY
done
