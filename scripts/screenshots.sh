#!/usr/bin/env bash
# The documentation's pictures, from a small run of the demo job (scripts/demo.sh's pipeline: the
# procedural demo city, nothing downloaded) in a scratch work directory:
#
#   OUTDIR/index.png        the export's index.html as headless Chromium shows it (the top of the page;
#                           scripts/index_check.mjs drives Chromium and checks that every image loads)
#   OUTDIR/flight_plan.png  the flight plan `insgen sample` drew for the training district
#   OUTDIR/overlay.png      an `insgen eval-loc --oracle` overlay of a held-out query
#
# Each picture is at most 1200 px wide and under 400 KB (PNG, quantised to 256 colours when a full-colour
# PNG would be larger), ready for docs/img/. Needs what scripts/setup.sh installs (node, Chromium;
# .venv for Pillow; .venv-blender for the photos, else the export is label-only and the page shows
# no photos).
#
#   scripts/screenshots.sh OUTDIR
#
# Environment: INSGEN (an insgen binary; default: `cargo build --release` and target/release/insgen),
# CHROMIUM (default: chromium), PYTHON (default: .venv/bin/python), COUNT (poses per district, default 4),
# KEEP_WORKDIR=1 (keep the scratch work directory and print where it is).
set -euo pipefail
out=${1:?usage: scripts/screenshots.sh OUTDIR}
cd "$(dirname "$0")/.."
mkdir -p "$out"
out=$(cd "$out" && pwd)
python=${PYTHON:-.venv/bin/python}
chromium=${CHROMIUM:-chromium}
count=${COUNT:-4}
insgen=${INSGEN:-}
if [ -z "$insgen" ]; then
  cargo build --quiet --release
  insgen=target/release/insgen
fi

work=$(mktemp -d "${TMPDIR:-/tmp}/insgen-screenshots-XXXXXX")
if [ "${KEEP_WORKDIR:-0}" = 1 ]; then
  echo "work directory: $work" >&2
else
  trap 'rm -rf "$work"' EXIT
fi

# The demo job, small: 3 districts × $count poses of cam2-quarter, photos by Blender when bpy is
# installed, the COCO export with its index.html, and eval-loc --oracle on 2 held-out queries.
"$insgen" --workdir "$work/runs" --no-progress demo --count "$count" --queries 2

camera=cam2-quarter
node scripts/index_check.mjs "$work/runs/coco/index.html" "$work/index_full.png" "$chromium" >"$work/index_check.json" || {
  echo "scripts/index_check.mjs found problems on the page:" >&2
  cat "$work/index_check.json" >&2
  exit 1
}
flight_plan="$work/runs/demo/$camera/flight_plan.png"
overlay=$(find "$work/runs/demo-test/$camera/loc" -path '*/overlays/*.png' | sort | head -n 1)
[ -n "$overlay" ] || { echo "eval-loc wrote no overlay under $work/runs/demo-test/$camera/loc" >&2; exit 1; }

# Downscale to ≤ 1200 px wide (the page: its first 1800 px, the summary, tables and charts) and keep
# each file under 400 KB.
"$python" - "$out" "$work/index_full.png" "$flight_plan" "$overlay" <<'EOF'
import io
import sys

from PIL import Image

out, index, flight_plan, overlay = sys.argv[1:]
MAX_W, MAX_BYTES = 1200, 400 * 1024


def save(src, name, crop_h=None):
    im = Image.open(src).convert("RGB")
    if crop_h and im.height > crop_h:
        im = im.crop((0, 0, im.width, crop_h))
    if im.width > MAX_W:
        im = im.resize((MAX_W, round(im.height * MAX_W / im.width)), Image.LANCZOS)
    for attempt in (im, im.quantize(256, method=Image.MEDIANCUT, dither=Image.NONE)):
        buf = io.BytesIO()
        attempt.save(buf, "PNG", optimize=True)
        if buf.tell() <= MAX_BYTES:
            break
    else:
        sys.exit(f"{name}: {buf.tell()} bytes even with 256 colours")
    with open(f"{out}/{name}", "wb") as f:
        f.write(buf.getvalue())
    print(f"{out}/{name}: {im.width}×{im.height}, {buf.tell() // 1024} KB")


save(index, "index.png", crop_h=1800)
save(flight_plan, "flight_plan.png")
save(overlay, "overlay.png")
EOF
