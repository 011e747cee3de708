#!/usr/bin/env bash
# Idempotent setup of the reference baseline's Python environment, .venv-train (git-ignored):
# PyPI's torch and torchvision (the registry's build carries CUDA libraries, so the same venv trains on a
# GPU; ≈ 5.5 GB, ≈ 2 minutes on a fresh machine), numpy, scipy, scikit-image (watershed), pycocotools
# (scoring) and pillow. Nothing else is downloaded at run time: the models start from random weights.
# Called by scripts/test.sh and scripts/bench_closed_loop.sh; scripts/demo.sh does not need it.
set -euo pipefail
cd "$(dirname "$0")/.."
REQS=(torch torchvision numpy scipy scikit-image pycocotools pillow)
DIR=.venv-train
STAMP="${REQS[*]}"
if [ -f "$DIR/.insgen-stamp" ] && [ "$(cat "$DIR/.insgen-stamp")" = "$STAMP" ]; then
    printf '[setup] %s up to date\n' "$DIR" >&2
    exit 0
fi
printf '[setup] creating %s (%s)\n' "$DIR" "$STAMP" >&2
rm -rf "$DIR"
python3 -m venv "$DIR"
"$DIR/bin/python" -m pip install -q --disable-pip-version-check --upgrade pip >/dev/null
"$DIR/bin/python" -m pip install -q --disable-pip-version-check "${REQS[@]}"
printf '%s' "$STAMP" > "$DIR/.insgen-stamp"
