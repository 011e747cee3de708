#!/usr/bin/env bash
# The main job on the embedded default: idempotent setup, then the whole pipeline on the procedural,
# geo-referenced demo city (scenes/demo.toml) — nothing is downloaded. Outputs go to runs/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cargo run --quiet -- demo "$@"
