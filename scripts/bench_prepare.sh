#!/usr/bin/env bash
# Benchmark of `insgen prepare` on the real areas: wall time and peak memory (max RSS) per area, written
# to bench/prepare_report.md. Needs ../shared/data. Uses the optimised release build.
# Usage: scripts/bench_prepare.sh tokyo niiza
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
BIN=target/release/insgen
out=bench/prepare_report.md
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
{
    echo "# prepare benchmark"
    echo
    echo "Machine: $(nproc) cores, $(free -g | awk '/Mem:/{print $2}') GiB; $(date -u +%Y-%m-%d)."
    echo "Command: \`insgen prepare --area NAME\` (release build), wall time and peak RSS from GNU time."
    echo
    echo "| area | buildings | triangles | wall (s) | peak RSS (MiB) |"
    echo "|---|---|---|---|---|"
} > "$out"
for area in "$@"; do
    /usr/bin/time -f '%e %M' -o "$work/time" "$BIN" --workdir "$work/runs" prepare --area "$area" -q
    read -r wall kb < "$work/time"
    m="$work/runs/$area/scene/manifest.json"
    read -r nb nt < <(python3 -c "import json; d=json.load(open('$m')); print(d['buildings'], d['triangles'])")
    echo "| $area | $nb | $nt | $wall | $((kb / 1024)) |" >> "$out"
done
cat "$out"
