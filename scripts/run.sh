#!/usr/bin/env bash
# The README's run command: installs what is missing, builds the release binary and runs relume
# on the bundled Cornell box. Extra arguments go to `relume`.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
export PATH="$HOME/.cargo/bin:$PATH"
cargo build --release --locked
if [ $# -gt 0 ]; then
  exec target/release/relume "$@"
fi
exec target/release/relume render scenes/cornell-box.json --technique path --spp 256 --out cornell-box.png
