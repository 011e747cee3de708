#!/usr/bin/env bash
# The test command: idempotent setup, then the whole test suite (unit, integration, real data, Python
# and Blender checks). Real-data tests use ../shared/data; under CI=true they fail instead of skipping.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/setup_train.sh
# The binary silences Mesa's device-select layer itself; the test binaries render in-process.
export NODEVICE_SELECT=1
export INSGEN_PYTHON="${INSGEN_PYTHON:-$(pwd)/.venv/bin/python}"
cargo fmt --check
cargo clippy --all-targets -- -D warnings
python3 scripts/fn_lengths.py --max 120 src  # no function over 120 lines outside tests (ARCHITECTURE.md)
cargo test --no-fail-fast "$@"
