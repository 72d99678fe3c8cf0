#!/usr/bin/env bash
# The README's test command: installs what is missing (the build's packages plus headless
# Chromium for the viewer test), builds the release binary users run, and runs every test
# against it. The suite is built with `--release`, so the tests exercise the same optimised
# code (and `tests/release_e2e.rs` drives the same binary) that `scripts/run.sh` serves.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/check-disk.sh 5
scripts/setup.sh scripts/packages.txt scripts/test-packages.txt
scripts/pytools.sh
scripts/nodetools.sh
export PATH="$HOME/.cargo/bin:$PATH"
cargo build --release --locked
# Which of Embree's kernel families this CPU runs, and which it skips.
cargo test --release --locked --test embree_isa -- --nocapture 2>&1 | grep -E "Embree's|test result"
cargo test --release --locked --no-fail-fast "$@"
# A build without the `denoise` feature still builds, serves, and refuses denoising by name.
# That build replaces target/release/relume, so the full binary is put back after it (cargo
# keeps both builds, so this only relinks).
cargo test --release --locked --no-default-features --test denoise_server
cargo build --release --locked
