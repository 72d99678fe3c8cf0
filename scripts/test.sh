#!/usr/bin/env bash
# The README's test command: installs what is missing (the build's packages plus headless
# Chromium for the viewer test), then builds and runs every test.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh scripts/packages.txt scripts/test-packages.txt
export PATH="$HOME/.cargo/bin:$PATH"
cargo test --locked --no-fail-fast "$@"
