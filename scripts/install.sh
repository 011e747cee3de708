#!/usr/bin/env bash
# Puts `insgen` on PATH: scripts/setup.sh (idempotent: PROJ, Vulkan, the Python environments and
# Blender's bpy that the commands use), then `cargo install --locked --path .`, which builds the release
# binary into ~/.cargo/bin. Arguments go to `cargo install` (e.g. --root /opt/insgen). The installed
# binary still finds Blender in this checkout's .venv-blender, so keep the checkout.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cargo install --locked --path . "$@"
if bin="$(command -v insgen)"; then
    echo "insgen is $bin ($("$bin" --version))"
else
    echo "insgen is not on PATH yet: add the folder cargo installed it into (above; by default" >&2
    echo "${CARGO_HOME:-$HOME/.cargo}/bin), e.g. export PATH=\"${CARGO_HOME:-$HOME/.cargo}/bin:\$PATH\"" >&2
fi
