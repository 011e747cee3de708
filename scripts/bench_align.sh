#!/usr/bin/env bash
# Benchmark of `insgen align` on synthetic pairs (issue 17): for each area, photogrammetry-like reference
# tilesets are made from the prepared scene with a known offset (`export-tiles --style … --offset
# E,N,U,YAW --photogrammetry-noise`: ±5 cm vertex jitter, ground, 40 box trees, a 45 m crane), and
# `align --dry-run` estimates it back. Writes bench/align.md: estimate, error, one-sigma, runtime and
# the agreement before/after per case. Shibuya needs ../shared/data (skipped when absent).
# Usage: scripts/bench_align.sh            (the dev build, as the tests run it; BIN=… to override)
set -euo pipefail
cd "$(dirname "$0")/.."
repo=$PWD
if [ -z "${BIN:-}" ]; then
    nice -n 10 cargo build --quiet
    BIN=$repo/target/debug/insgen
fi
out=$repo/bench/align.md
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mkdir -p "$work/scenes"
# Scene files with their relative source paths made absolute.
for a in demo tokyo; do
    sed "s#^path = \"\\(.*\\)\"#path = \"$repo/scenes/\\1\"#" "scenes/$a.toml" > "$work/scenes/$a.toml"
done
cd "$work"
# area style "E,N,U,YAW" seed
cases=(
    "demo cesium-ion 2.3,-1.7,0.8,0.45 10"
    "demo cesium-ion -4.6,4.1,-2.5,-0.9 11"
    "demo cesium-ion 4.9,4.9,4.9,1.0 12"
    "demo cesium-ion 0,0,0,0 13"
    "tokyo plateau -3.1,4.2,-1.3,-0.7 20"
    "tokyo plateau 1.9,-4.4,3.7,0.95 21"
    "tokyo plateau 0,0,0,0 22"
)
prepared=""
: > results.jsonl
for c in "${cases[@]}"; do
    read -r area style off seed <<< "$c"
    if [ "$area" = tokyo ] && [ ! -f "$repo/../shared/data/jp_tokyo_shibuya_plateau_3dtiles/tileset.json" ]; then
        echo "skipping tokyo: ../shared/data/jp_tokyo_shibuya_plateau_3dtiles is absent" >&2
        continue
    fi
    case " $prepared " in *" $area "*) ;; *)
        "$BIN" -q prepare --area "$area"
        prepared="$prepared $area"
    esac
    "$BIN" -q export-tiles --area "$area" --style "$style" --offset "$off" --photogrammetry-noise --seed "$seed" --out "ref-$area-$seed"
    /usr/bin/time -f '%e %M' -o time.txt "$BIN" -q align --area "$area" --tileset "ref-$area-$seed/tileset.json" --dry-run
    read -r wall kb < time.txt
    python3 - "$area" "$style" "$off" "$wall" "$kb" "runs/$area/align/align.json" >> results.jsonl <<'EOF'
import json, sys
area, style, off, wall, kb, path = sys.argv[1:]
r = json.load(open(path))
print(json.dumps({"area": area, "style": style, "offset": [float(x) for x in off.split(",")],
                  "wall_s": float(wall), "rss_mib": int(kb) // 1024, "report": r}))
EOF
done
python3 - "$(nproc)" > "$out" <<'EOF'
import json, math, sys, datetime
rows = [json.loads(l) for l in open("results.jsonl")]
print("# align on synthetic pairs (issue 17)\n")
print(f"Machine: {sys.argv[1]} cores shared with other builds; {datetime.date.today()}; dev build (as the tests run it).")
print("Reproduce: `scripts/bench_align.sh`. Each reference tileset is the prepared scene moved by the offset, with")
print("±5 cm vertex jitter, a ground surface, 40 box trees and a 45 m crane, written as a textured multi-tile")
print("tileset (demo: Cesium ion style, Draco, rotated/scaled root; Shibuya: PLATEAU style) and read back by")
print("insgen's 3D Tiles reader. Offsets are about the pivot align reports (centre of the LoD footprint).")
print("Bounds (issue 17): horizontal ≤ 0.10 m, vertical ≤ 0.10 m, yaw ≤ 0.05°.\n")
print("| area | offset E, N, U (m), yaw (°) | estimate E, N, U (m), yaw (°) | error horiz / vert (m), yaw (°) | 1σ E, N, U (m), yaw (°) | median \\|Δh\\| roofs before → after (m) | footprint IoU before → after | align wall (s) | estimate (s) | peak RSS (MiB) |")
print("|---|---|---|---|---|---|---|---|---|---|")
ok = True
for r in rows:
    e = r["report"]["estimate"]; c = e["correction"]; s = e["sigma"]; o = r["offset"]
    eh = math.hypot(c["east_m"] - o[0], c["north_m"] - o[1]); ev = abs(c["up_m"] - o[2]); ey = abs(c["yaw_deg"] - o[3])
    ok &= eh <= 0.1 and ev <= 0.1 and ey <= 0.05
    b, a = r["report"]["before"], r["report"]["after"]
    print(f"| {r['area']} | {o[0]:+.2f}, {o[1]:+.2f}, {o[2]:+.2f}, {o[3]:+.2f} "
          f"| {c['east_m']:+.4f}, {c['north_m']:+.4f}, {c['up_m']:+.4f}, {c['yaw_deg']:+.5f} "
          f"| {eh:.4f} / {ev:.4f}, {ey:.5f} "
          f"| {s['east_m']:.4f}, {s['north_m']:.4f}, {s['up_m']:.4f}, {s['yaw_deg']:.5f} "
          f"| {b['median_abs_dh_roofs_m']:.3f} → {a['median_abs_dh_roofs_m']:.3f} "
          f"| {b['footprint_iou']:.4f} → {a['footprint_iou']:.4f} "
          f"| {r['wall_s']:.1f} | {r['report']['estimate_s']:.1f} | {r['rss_mib']} |")
print(f"\n**Result: {'PASS' if ok else 'FAIL'}** (every case within the bounds).\n")
print("The one-sigma values come from the normal matrix of the last Gauss–Newton step scaled by the residual")
print("variance; neighbouring samples' residuals are correlated, so they understate the error (compare the")
print("error column). The footprint IoU after correction stays below 1 because the reference also holds trees,")
print("the crane and ground that the LoD model lacks, and because the \"above ground\" test uses the lowest")
print("tileset height within ±40 m as the ground.")
EOF
cat "$out"
