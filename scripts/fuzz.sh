#!/usr/bin/env bash
# Fuzzing (a benchmark-style run, not part of CI): the property tests of tests/fuzz.rs with
# fresh seeds and many cases. The parsers and validators get FUZZ_CASES cases per property
# (default 1 000 000 each, a few minutes); the real server gets FUZZ_HTTP_CASES requests
# (default 20 000, about ten minutes) and as many WebSocket messages on one socket. Any panic,
# 5xx or hang fails the run and prints the minimal failing input. CI runs the same properties
# on a fixed-seed slice of a few seconds.
set -euo pipefail
cd "$(dirname "$0")/.."
export PATH="$HOME/.cargo/bin:$PATH"
export RELUME_FUZZ_FRESH=1
cases="${FUZZ_CASES:-1000000}"
http_cases="${FUZZ_HTTP_CASES:-20000}"
echo "relume fuzz: $cases cases per parser property, $http_cases HTTP requests"
PROPTEST_CASES="$cases" cargo test --release --locked --test fuzz -- --skip real_server
PROPTEST_CASES="$http_cases" cargo test --release --locked --test fuzz -- real_server
