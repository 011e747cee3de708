#!/usr/bin/env bash
# Idempotent setup of everything insgen needs on a fresh Debian (bookworm) machine.
#
# What it installs, and why:
#   Debian packages
#     pkg-config, libproj-dev   PROJ 9 (C library) for CRS conversion, linked by the `proj` crate
#     libclang-dev              bindgen (used by proj-sys at build time) needs libclang
#     proj-data                 the EGM96 geoid grid (egm96_15.gtx) for orthometric → ellipsoidal heights
#     mesa-vulkan-drivers,      Mesa's software Vulkan driver (lavapipe) + loader, so wgpu renders
#     libvulkan1                without a GPU
#     chromium                  headless Chromium (SwiftShader WebGL) to open the 3D Tiles export in
#                               CesiumJS, as a user's browser would
#     time                      GNU time, for the peak-memory benchmark (scripts/bench_memory.sh)
#     python3, python3-venv     (only if missing) for the Python checks and Blender's bpy
#     nodejs, npm               (only if missing) for the Khronos glTF validator
#   Python virtual environments (in the repo, git-ignored)
#     .venv                     numpy, pyproj (CRS reference), pycocotools (COCO checks), jsonschema,
#                               pycolmap (loads the COLMAP export), panopticapi-lite (the COCO panoptic
#                               API: rgb2id, pq_compute), pyyaml (reads the YOLO data.yaml), datasets
#                               (Hugging Face: loads export-hf; pandas/pyarrow pinned to what it was tested with)
#     .venv-blender             bpy 5.0.1 (Blender as a Python module, CPython 3.11) for RGB rendering
#   npm (in the repo, git-ignored)
#     node_modules/             gltf-validator (Khronos) to validate the scene GLB; 3d-tiles-tools and
#                               cesium (CesiumJS, with its engine) to read and show the 3D Tiles export.
#                               Installed with --ignore-scripts: no package we use needs its install
#                               script, and two optional ones (better-sqlite3, sharp) would try to
#                               download prebuilt binaries from outside the registry
#
# Each step checks first and does nothing when its result is already there; a stamp file records the
# requirement list each environment was built from, so a changed list rebuilds it.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)

say() { printf '[setup] %s\n' "$*" >&2; }

# --- Debian packages --------------------------------------------------------------------------------
APT_PACKAGES=(pkg-config libproj-dev proj-data libclang-dev mesa-vulkan-drivers libvulkan1 chromium time)
command -v python3 >/dev/null 2>&1 || APT_PACKAGES+=(python3 python3-venv)
command -v node >/dev/null 2>&1 || APT_PACKAGES+=(nodejs)
command -v npm >/dev/null 2>&1 || APT_PACKAGES+=(npm)
missing=()
for p in "${APT_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
    SUDO=""
    [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    say "installing Debian packages: ${missing[*]}"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
else
    say "Debian packages present"
fi

if ! command -v cargo >/dev/null 2>&1; then
    say "error: cargo (Rust ≥ 1.88) is not installed; install a Rust toolchain (rustup) and run this again"
    exit 1
fi

# --- Python environments ----------------------------------------------------------------------------
make_venv() { # dir, stamp text, pip args...
    local dir=$1 stamp=$2
    shift 2
    if [ -f "$dir/.insgen-stamp" ] && [ "$(cat "$dir/.insgen-stamp")" = "$stamp" ]; then
        say "$dir up to date"
        return
    fi
    say "creating $dir ($stamp)"
    rm -rf "$dir"
    python3 -m venv "$dir"
    "$dir/bin/python" -m pip install -q --disable-pip-version-check --upgrade pip >/dev/null
    "$dir/bin/python" -m pip install -q --disable-pip-version-check "$@"
    printf '%s' "$stamp" > "$dir/.insgen-stamp"
}

PY_REQS=(numpy pyproj pycocotools jsonschema pycolmap panopticapi-lite pyyaml "datasets>=3,<4" "pandas>=2,<3" "pyarrow>=15,<20")
make_venv "$ROOT/.venv" "${PY_REQS[*]}" "${PY_REQS[@]}"
# The Citation File Format's own schema (shipped inside cffconvert's wheel; cffconvert itself pins
# jsonschema < 4, so it is not installed): tests validate CITATION.cff against it.
CFF_DIR="$ROOT/.venv/share/insgen-cff"
if ! ls "$CFF_DIR"/cffconvert-2.0.0-*.whl >/dev/null 2>&1; then
    say "fetching the Citation File Format schema (cffconvert 2.0.0 wheel)"
    "$ROOT/.venv/bin/python" -m pip download -q --disable-pip-version-check --no-deps cffconvert==2.0.0 -d "$CFF_DIR"
fi

if [ -f scripts/setup_blender.sh ]; then
    bash scripts/setup_blender.sh
fi

# --- npm --------------------------------------------------------------------------------------------
if [ -f package-lock.json ]; then
    if [ ! -f node_modules/.insgen-stamp ] || ! cmp -s package-lock.json node_modules/.insgen-stamp; then
        say "installing npm packages (gltf-validator, 3d-tiles-tools, cesium)"
        npm ci --silent --no-audit --no-fund --ignore-scripts >/dev/null
        cp package-lock.json node_modules/.insgen-stamp
    else
        say "npm packages up to date"
    fi
fi

say "done"
