#!/usr/bin/env bash
# `path` against Mitsuba 3's `llvm_ad_rgb` path tracer on the same scene, at equal spp, in one
# run (issue #16). Usage:
#   scripts/against-mitsuba.sh [--install] [SCENE.json] [--spp N] [--json FILE]
# --install fetches Mitsuba 3.5.2 (pip, into .deps/mitsuba, outside git) and Debian's libllvm15
# (scripts/mitsuba-packages.txt), which its LLVM back end loads; without it the script uses what
# is installed, and says to pass --install when Mitsuba is missing. Why 3.5.2: the latest
# release (3.9.1, tried here) emits `fminimum`, which bookworm's LLVM 15 cannot select; 3.5.2
# runs on it. relume is target/release/relume, built first so it matches the source.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
venv="$root/.deps/mitsuba"
install=0
args=()
for a in "$@"; do
  if [ "$a" = "--install" ]; then install=1; else args+=("$a"); fi
done
if [ "$install" = 1 ]; then
  bash "$root/scripts/setup.sh" "$root/scripts/packages.txt" "$root/scripts/mitsuba-packages.txt"
  if ! "$venv/bin/python" -c "import mitsuba" 2>/dev/null; then
    echo "against-mitsuba: installing mitsuba 3.5.2 into $venv" >&2
    python3 -m venv "$venv"
    "$venv/bin/pip" install --quiet --disable-pip-version-check "mitsuba==3.5.2" "drjit==0.4.6" numpy
  fi
fi
if ! "$venv/bin/python" -c "import mitsuba" 2>/dev/null; then
  echo "against-mitsuba: Mitsuba is not installed; run with --install" >&2
  exit 2
fi
(cd "$root" && cargo build --release --quiet --bin relume)
llvm=$(ldconfig -p | awk '/libLLVM-15.so /{print $NF; exit}')
export DRJIT_LIBLLVM_PATH="${DRJIT_LIBLLVM_PATH:-$llvm}"
exec "$venv/bin/python" "$root/scripts/against_mitsuba.py" --relume "$root/target/release/relume" "${args[@]}"
