#!/usr/bin/env bash
# Creates <repo>/.venv-blender with the bpy module (Blender 5.0.1 as a Python package), for
# `insgen render-rgb`. Idempotent: does nothing when the venv already imports the pinned bpy.
#
# bpy 5.0.1 wheels exist for CPython 3.11 only (linux x86_64, ~374 MB; they pin numpy 1.26), hence a venv
# of its own next to the project's .venv. The interpreter is taken from $INSGEN_BLENDER_PYTHON_BASE, else
# the first of python3.11 / python3 that is version 3.11.
#
# Usage: scripts/setup_blender.sh            (from anywhere; the repo root is this script's parent's parent)
set -euo pipefail

BPY_VERSION="5.0.1"
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv-blender"

have_bpy() {
    [ -x "$VENV/bin/python" ] && "$VENV/bin/python" - "$BPY_VERSION" >/dev/null 2>&1 <<'EOF'
import sys
import bpy
want = tuple(int(x) for x in sys.argv[1].split("."))
sys.exit(0 if tuple(bpy.app.version) == want else 1)
EOF
}

if have_bpy; then
    echo "setup_blender: $VENV already has bpy $BPY_VERSION"
    exit 0
fi

pick_python() {
    local candidates=()
    [ -n "${INSGEN_BLENDER_PYTHON_BASE:-}" ] && candidates+=("$INSGEN_BLENDER_PYTHON_BASE")
    candidates+=(python3.11 python3)
    for c in "${candidates[@]}"; do
        if command -v "$c" >/dev/null 2>&1 &&
            "$c" -c 'import sys; sys.exit(0 if sys.version_info[:2] == (3, 11) else 1)' 2>/dev/null; then
            command -v "$c"
            return 0
        fi
    done
    return 1
}

if ! PY="$(pick_python)"; then
    echo "setup_blender: bpy $BPY_VERSION needs CPython 3.11; none found (set INSGEN_BLENDER_PYTHON_BASE)" >&2
    exit 1
fi

echo "setup_blender: creating $VENV with $PY"
"$PY" -m venv "$VENV"
"$VENV/bin/python" -m pip install --quiet --upgrade pip
"$VENV/bin/python" -m pip install --quiet "bpy==$BPY_VERSION"

if ! have_bpy; then
    echo "setup_blender: bpy $BPY_VERSION was installed but does not import; see the output above" >&2
    "$VENV/bin/python" -c 'import bpy' || true
    exit 1
fi
echo "setup_blender: $VENV has bpy $BPY_VERSION"
