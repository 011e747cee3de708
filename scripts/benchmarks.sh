#!/usr/bin/env bash
# Every benchmark of insgen, then BENCHMARKS.md at the repository root: the machine, and for each stage
# the side-by-side figures against its peer (Blender, pycocotools, pyproj, the paper's search), as each
# report in bench/ gives them (medians or best of several runs; each report says which and how).
#
#   scripts/benchmarks.sh             run everything (about 2 hours on 2 cores), then write BENCHMARKS.md
#   scripts/benchmarks.sh --collect   only rebuild BENCHMARKS.md from the reports already in bench/
#
# Only public tools: cargo bench, the bench scripts in scripts/, Python from .venv, GNU time.
set -euo pipefail
cd "$(dirname "$0")/.."
collect_only=0
[ "${1:-}" = "--collect" ] && collect_only=1
if [ "$collect_only" = 0 ]; then
    bash scripts/setup.sh
    export NODEVICE_SELECT=1
    for b in render_ids rle ecef_enu cpu_raster; do
        cargo bench --bench "$b"
    done
    cargo bench --bench versus_blender -- --rgb
    bash scripts/bench_rgb.sh
    bash scripts/bench_memory.sh
    bash scripts/loc_report.sh
    bash scripts/loc_areas.sh
    bash scripts/bench_align.sh
    bash scripts/bench_occlusion.sh
    bash scripts/bench_closed_loop.sh --size small
    # scripts/loc_issue15.sh compares with a build of the commit before issue 15's search (it takes that
    # binary as its argument): run it by hand when that comparison is wanted.
fi
out="BENCHMARKS.md"
tmp="$(mktemp)"
{
    echo "# insgen benchmarks"
    echo
    echo "Written by \`scripts/benchmarks.sh\` (rerun it to measure your machine; \`--collect\` only gathers the"
    echo "reports in \`bench/\`). Each section below is one report, as its generator wrote it: the command, the"
    echo "build, the machine load, and whether figures are medians or best-of-N runs are stated there."
    echo
    echo "## Machine"
    echo
    echo "- CPU: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //') — $(nproc) threads"
    echo "- memory: $(awk '/MemTotal/ {printf "%.1f GB", $2 / 1048576}' /proc/meminfo)"
    echo "- OS: $(. /etc/os-release && echo "$PRETTY_NAME"); $(rustc --version)"
    echo "- GPU: none used (wgpu on lavapipe, Blender Cycles on the CPU)"
    echo
    echo "## Contents"
    echo
    for f in bench/*.md; do
        title="$(grep -m1 '^# ' "$f" | sed 's/^# //')"
        echo "- [$title](#$(basename "$f" .md)) — \`$f\`"
    done
    for f in bench/*.md; do
        echo
        echo "<a id=\"$(basename "$f" .md)\"></a>"
        echo
        # Demote the report's headings by one level so they nest under this page.
        sed 's/^#/##/' "$f"
    done
} > "$tmp"
mv "$tmp" "$out"
echo "wrote $out ($(wc -l < "$out") lines from $(ls bench/*.md | wc -l) reports)"
