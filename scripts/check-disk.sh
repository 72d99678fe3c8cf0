#!/usr/bin/env bash
# Warns, before a build, when the repository's filesystem has less free space than a cold
# build needs: `scripts/check-disk.sh GIB`. A full disk does not fail cleanly: the linker
# dies with "Bus error" (signal 7) halfway through. The build goes on either way, since a
# warm target/ needs far less.
set -euo pipefail
need_gib=$1
root=$(cd "$(dirname "$0")/.." && pwd)
free_kib=$(df -Pk "$root" | awk 'NR == 2 { print $4 }')
if [ "$free_kib" -lt $((need_gib * 1024 * 1024)) ]; then
  echo "warning: $root has $((free_kib / 1024 / 1024)) GiB free; a cold build needs about" \
    "$need_gib GiB. If the linker dies with 'Bus error', free some space and run again." >&2
fi
