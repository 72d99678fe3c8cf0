#!/usr/bin/env bash
# The README's run command: installs what is missing, builds the release binary and runs
# `relume serve` on loopback with the bundled scenes (viewer at http://127.0.0.1:8080/).
# Extra arguments replace `serve`, e.g. `bash scripts/run.sh render scenes/cornell-box.json ...`.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/check-disk.sh 2
scripts/setup.sh
export PATH="$HOME/.cargo/bin:$PATH"
cargo build --release --locked
if [ $# -gt 0 ]; then
  exec target/release/relume "$@"
fi
exec target/release/relume serve
