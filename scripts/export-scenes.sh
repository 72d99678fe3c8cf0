#!/usr/bin/env bash
# Writes every bundled scene (scenes/NAME.json, with scenes/NAME.anim.json when there is one)
# as scenes/NAME.glb through `relume export`. tests/gltf.rs checks the committed files are
# what this writes, so run it after changing a bundled scene or the exporter.
set -euo pipefail
cd "$(dirname "$0")/.."
relume=${RELUME:-target/release/relume}
for scene in scenes/*.json; do
  case "$scene" in *.anim.json) continue ;; esac
  name=$(basename "$scene" .json)
  anim=()
  if [ -f "scenes/$name.anim.json" ]; then anim=(--anim "scenes/$name.anim.json"); fi
  "$relume" export "$scene" --out "scenes/$name.glb" "${anim[@]}"
done
