#!/usr/bin/env bash
# From an empty work directory and a folder of files to a verified export, as README "Your own city"
# runs it: a town of 36 LoD1 buildings in four CityJSON tiles in EPSG:25832 (the fixture of
# tests/it/onboard.rs, written here by a few lines of Python), then init → prepare → sample (cam2 at a
# quarter resolution, --count N) → render-masks → render-rgb (Blender, CPU) → export-coco → verify. Wall
# time per step and in total, median of RUNS runs, written to bench/onboard.md.
# Usage: scripts/bench_onboard.sh [RUNS=3] [FRAMES=8]    (the debug build `cargo build` makes)
set -euo pipefail
cd "$(dirname "$0")/.."
runs=${1:-3}
frames=${2:-8}
cargo build --quiet
bin="$PWD/target/debug/insgen"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
python3 - "$work/town" <<'PY'
import json, os, sys
root = sys.argv[1]
for ti, tj in [(0, 0), (1, 0), (0, 1), (1, 1)]:
    objs, verts = {}, []
    for i in range(3):
        for j in range(3):
            e0, n0 = (ti * 300 + i * 100 + 25) * 1000, (tj * 300 + j * 100 + 25) * 1000
            h = (12 + ((ti * 3 + i) * 7 + (tj * 3 + j) * 11) % 34) * 1000
            b = len(verts)
            for dz in (0, h):
                for de, dn in [(0, 0), (1, 0), (1, 1), (0, 1)]:
                    verts.append([e0 + de * 50000, n0 + dn * 50000, 520000 + dz])
            faces = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
            objs[f"town_{ti}{tj}_{i}{j}"] = {"type": "Building", "geometry": [{"type": "Solid", "lod": "1",
                "boundaries": [[[[k + b for k in f]] for f in faces]]}]}
    d = os.path.join(root, "south" if tj == 0 else "north")
    os.makedirs(d, exist_ok=True)
    json.dump({"type": "CityJSON", "version": "2.0",
               "metadata": {"referenceSystem": "https://www.opengis.net/def/crs/EPSG/0/25832"},
               "transform": {"scale": [0.001] * 3, "translate": [690000.0, 5335000.0, 0.0]},
               "CityObjects": objs, "vertices": verts}, open(os.path.join(d, f"tile_{ti}{tj}.city.json"), "w"))
PY
steps=(init prepare sample render-masks render-rgb export-coco verify)
step_cmd() {
    case $1 in
        init) echo "init town $work/town/" ;;
        prepare) echo "prepare --area town" ;;
        sample) echo "sample --area town --camera scenes/cameras/cam2-quarter.toml --count $frames" ;;
        render-masks) echo "render-masks --area town --camera cam2-quarter" ;;
        render-rgb) echo "render-rgb --area town --camera cam2-quarter" ;;
        export-coco) echo "export-coco" ;;
        verify) echo "verify runs/coco" ;;
    esac
}
declare -A times
for r in $(seq 1 "$runs"); do
    rm -rf "$work/run" && mkdir -p "$work/run/scenes" && cp -r scenes/cameras "$work/run/scenes/"
    for s in "${steps[@]}"; do
        t0=$(date +%s.%N)
        (cd "$work/run" && $bin -q --no-progress $(step_cmd "$s") >/dev/null)
        t1=$(date +%s.%N)
        times[$s]+="$(echo "$t1 - $t0" | bc) "
    done
done
median() { tr ' ' '\n' | grep . | sort -g | awk '{a[NR]=$1} END {print (NR % 2) ? a[(NR+1)/2] : (a[NR/2] + a[NR/2+1]) / 2}'; }
out=bench/onboard.md
{
    echo "# From a folder of files to a verified dataset (README \"Your own city\")"
    echo
    echo "Machine: $(nproc) cores (shared with other jobs), $(date -u +%Y-%m-%d); debug build (opt-level 1/2)."
    echo "Fixture: 36 LoD1 buildings, four CityJSON tiles in EPSG:25832 (tests/it/onboard.rs's town)."
    echo "$frames frames of cam2 at 480 × 270 (scenes/cameras/cam2-quarter.toml), Blender on the CPU."
    echo "Median wall time of $runs runs: \`scripts/bench_onboard.sh $runs $frames\`."
    echo
    echo "| step | command | median (s) |"
    echo "|---|---|---|"
    total=0
    for s in "${steps[@]}"; do
        m=$(printf '%.2f' "$(echo "${times[$s]}" | median)")
        total=$(echo "$total + $m" | bc)
        echo "| $s | \`insgen $(step_cmd "$s" | sed "s|$work|…|g")\` | $m |"
    done
    echo "| **total** | | **$(printf '%.2f' "$total")** |"
} > "$out"
cat "$out"
