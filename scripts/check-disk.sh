#!/usr/bin/env bash
# Warns, before a build, when the repository's filesystem has less free space than a cold
# build needs: `scripts/check-disk.sh GIB`. A full disk does not fail cleanly: the linker
# dies with "Bus error" (signal 7) halfway through. The build goes on either way: a warm
# target/ needs far less, and where `df` cannot tell, the check is skipped.
set -euo pipefail
need_gib=${1:?usage: scripts/check-disk.sh GIB}
root=$(cd "$(dirname "$0")/.." && pwd)
free_kib=$(df -Pk "$root" 2>/dev/null | awk 'NR == 2 { print $4 }') || exit 0
case "$free_kib" in '' | *[!0-9]*) exit 0 ;; esac
if [ "$free_kib" -lt $((need_gib * 1024 * 1024)) ]; then
  echo "warning: $root has $((free_kib / 1024 / 1024)) GiB free; a cold build needs about" \
    "$need_gib GiB. If the linker dies with 'Bus error', free some space and run again." >&2
fi
